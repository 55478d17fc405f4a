"""The ID buffers of the in-process backends that draw rendiff's resolved triangles (mitsuba,
pyrender), each checked the same way against backend_cases.cast, the float64 pixel-center ray cast:
IDs away from edges, the background, orientation, back faces, IDs past 16 bits, an empty scene.
Each backend's depth and normal conversions have their own tests (test_mitsuba_backend.py,
test_pyrender_backend.py): their tolerances differ."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest

import backend_cases as cases
from rendiff_harness.contract import resolved
from rendiff_harness.contract.resolved import ResolvedScene
from rendiff_harness.contract.vocab import BACKGROUND_ID as BG
from rendiff_harness.renderers.mitsuba import backend as mb
from rendiff_harness.renderers.pyrender import backend as pb

SAFE_EDGE_PX = 0.01  # pixel centers farther than this from every edge must match exactly
EDGE_PX = {
    "mitsuba": 1e-3,  # measured: Embree's f32 edge tests flip centers within ~4e-5 px only
    "pyrender": pb.EDGE_TOLERANCE_PX,
}
"""How far from an edge a pixel center may take the other side's ID."""


def _backend(module: ModuleType) -> Any:
    reason = module.unavailable_reason()
    return pytest.param(module, id=module.NAME, marks=pytest.mark.skipif(reason is not None, reason=f"{reason}"))


BACKENDS = [_backend(mb), _backend(pb)]


def _render(tmp_path: Path, backend: ModuleType, build: Callable[[Path], Path]) -> tuple[ResolvedScene, Any]:
    scene = resolved.load(build(tmp_path / "scene"))
    buffers, _ = backend.render_arrays(scene)
    return scene, buffers


@pytest.mark.parametrize("backend", BACKENDS)
def test_ids_match_float64_ray_cast_away_from_edges(tmp_path: Path, backend: ModuleType) -> None:
    scene, buf = _render(tmp_path, backend, cases.three_triangles_two_objects)
    ref = cases.cast(scene)
    safe = ref.edge_dist > SAFE_EDGE_PX
    assert safe.mean() > 0.9
    assert np.array_equal(buf["prim"][safe], ref.prim[safe])
    assert np.array_equal(buf["obj"][safe], ref.obj[safe])
    assert {int(v) for v in np.unique(ref.obj)} == {0, 1, BG}, "fixture must show both objects and background"
    mismatch = buf["prim"] != ref.prim
    assert np.all(ref.edge_dist[mismatch] <= EDGE_PX[backend.NAME])


@pytest.mark.parametrize("backend", BACKENDS)
def test_background_maps_to_inf_and_all_ones(tmp_path: Path, backend: ModuleType) -> None:
    scene, buf = _render(tmp_path, backend, cases.three_triangles_two_objects)
    bg = cases.cast(scene).prim == BG
    assert bg[0, 0] and bg.sum() > 100
    assert np.all(np.isposinf(buf["Z"][bg]))
    assert np.all(buf["prim"][bg] == BG) and np.all(buf["obj"][bg] == BG)
    assert np.array_equal(np.isinf(buf["Z"]), buf["prim"] == BG)


@pytest.mark.parametrize("backend", BACKENDS)
def test_orientation_left_is_left_and_up_is_top(tmp_path: Path, backend: ModuleType) -> None:
    scene, buf = _render(tmp_path, backend, cases.orientation_scene)
    w, h = scene.camera.width, scene.camera.height
    cols0 = np.nonzero(buf["prim"] == 0)[1]
    rows1 = np.nonzero(buf["prim"] == 1)[0]
    assert cols0.size and cols0.max() < w // 2, "a triangle at -x must land in the left columns"
    assert rows1.size and rows1.max() < h // 2, "a triangle at +y must land in the top rows"


@pytest.mark.parametrize("backend", BACKENDS)
def test_back_facing_triangle_is_visible(tmp_path: Path, backend: ModuleType) -> None:
    scene, buf = _render(tmp_path, backend, cases.back_facing)
    ref = cases.cast(scene)
    safe = ref.edge_dist > SAFE_EDGE_PX
    assert np.count_nonzero(ref.prim == 0) > 20
    assert np.array_equal(buf["prim"][safe], ref.prim[safe])


@pytest.mark.parametrize("backend", BACKENDS)
def test_prim_ids_above_65535_decode(tmp_path: Path, backend: ModuleType) -> None:
    scene, buf = _render(tmp_path, backend, cases.high_ids)
    ref = cases.cast(scene)
    safe = ref.edge_dist > SAFE_EDGE_PX
    assert {int(v) for v in np.unique(ref.prim)} == {*cases.HIGH_IDS, BG}
    assert np.array_equal(buf["prim"][safe], ref.prim[safe])
    assert np.array_equal(buf["obj"][safe], ref.obj[safe])


@pytest.mark.parametrize("backend", BACKENDS)
def test_empty_scene_is_all_background(tmp_path: Path, backend: ModuleType) -> None:
    _, buf = _render(tmp_path, backend, cases.empty_scene)
    assert np.all(buf["prim"] == BG) and np.all(np.isposinf(buf["Z"]))
