"""Depth judged everywhere both hit (judge/depth.py `own_plane_depths`): where the test renderer
sees another triangle than the reference, its depth must lie on that triangle's own plane at the
pixel center; a pixel it cannot be judged at is counted as not comparable, with its reason.

Scene "quads" of test_compare: two quads meet on the shared edge at column 16 (prims 0-1 left,
2-3 right, all in the plane z = 0 seen from z = 5), a triangle (prim 4) in front at z = 1."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import test_compare as tc
from fixtures import write_scene
from rendiff_harness.contract.manifest import Reference, load_reference
from rendiff_harness.judge.depth import DepthResult, compare_depth
from rendiff_harness.renderers import registry


def reference(tmp_path: Path) -> tuple[Reference, dict[str, np.ndarray]]:
    run = tmp_path / "run"
    sdir = write_scene(
        run / "scenes/quads/resolved", tc.TRIS, tc.OIDS, vfov_deg=90.0, width=32, height=32, name="quads"
    )
    _, ref = tc._ref(sdir)
    exr = tc._write_exr(run / "scenes/quads/raster.exr", ref)
    entry = {
        "scene": "quads",
        "resolved": "scenes/quads/resolved",
        "renders": [tc._ok("raster", Path(exr).relative_to(run).as_posix())],
    }
    (run / "manifest.json").write_text(json.dumps({"scenes": [entry]}))
    return load_reference(run, entry, "raster"), ref


def judge(ref: Reference, test: dict[str, np.ndarray]) -> DepthResult:
    model = registry.spec("mitsuba")
    assert model is not None
    buffers = {"Z": test["Z"], "id.prim": test["prim"]}
    return compare_depth(ref, buffers, model.precision, tc._ok("mitsuba", "x"), {}, None, own_plane=True)


@pytest.fixture
def quads(tmp_path: Path) -> tuple[Reference, dict[str, np.ndarray]]:
    return reference(tmp_path)


def test_a_depth_off_its_own_plane_fails_where_the_ids_differ(quads: tuple[Reference, dict[str, np.ndarray]]) -> None:
    ref, base = quads
    x, y = tc.EDGE_PX
    test = tc._copy(base)
    test["prim"][y, x] = 3  # the right quad's triangle across the edge: an allowed edge pixel
    test["Z"][y, x] = np.float32(5.0 * (1 + 1e-3))  # but its depth is off that triangle's plane (z = 5)
    res = judge(ref, test)
    assert res.own_plane == 1 and res.own_plane_beyond == 1
    assert res.interior == 1
    assert any("off their own triangle's plane" in d for d in res.details)
    # On its plane, the same pixel passes: judged, not skipped.
    test["Z"][y, x] = np.float32(5.0)
    res = judge(ref, test)
    assert res.own_plane == 1 and res.interior == 0


def test_a_front_triangle_seen_through_is_judged_on_its_own_plane(
    quads: tuple[Reference, dict[str, np.ndarray]],
) -> None:
    ref, base = quads
    x, y = tc.INTERIOR_PX  # the reference sees prim 4 (z = 1, depth 4); the test sees prim 2 behind it
    test = tc._copy(base)
    test["prim"][y, x] = 2
    test["Z"][y, x] = np.float32(4.0)  # prim 4's depth written for prim 2: off prim 2's plane (depth 5)
    res = judge(ref, test)
    assert res.own_plane_beyond == 1 and res.own_plane_max_abs == pytest.approx(1.0)


def test_pixels_judged_neither_way_are_counted_with_their_reason(
    quads: tuple[Reference, dict[str, np.ndarray]],
) -> None:
    ref, base = quads
    x, y = tc.PLAIN_PX
    test = tc._copy(base)
    test["prim"][y, x] = 99  # no such triangle
    res = judge(ref, test)
    assert res.not_comparable == {"the test's id.prim names no triangle of the scene": 1}
    assert "not comparable" in res.tolerance


def test_a_radial_depth_is_named_without_calibration(quads: tuple[Reference, dict[str, np.ndarray]]) -> None:
    ref, base = quads
    test = tc._copy(base)
    hit = np.isfinite(base["Z"])
    rows, cols = np.nonzero(hit)
    d = ref.scene.camera.center_directions(rows, cols)
    test["Z"][hit] = (base["Z"][hit].astype(np.float64) * np.linalg.norm(d, axis=1)).astype(np.float32)
    res = judge(ref, test)
    assert res.interior > 0
    assert res.details[0].split(" depths beyond tolerance")[1].startswith(" equal the radial distance"), res.details
