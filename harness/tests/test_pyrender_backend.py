"""pyrender backend: conversions checked against closed forms and a float64 pixel-center ray cast."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import backend_cases as cases
from rendiff_harness.contract import exrbuf, resolved
from rendiff_harness.contract.resolved import ResolvedScene
from rendiff_harness.renderers.errors import BackendError
from rendiff_harness.renderers.pyrender import backend as pb

REASON = pb.unavailable_reason()
pytestmark = pytest.mark.skipif(REASON is not None, reason=f"pyrender backend unavailable: {REASON}")
BG = pb.BACKGROUND_ID

Rendered = tuple[ResolvedScene, dict[str, np.ndarray], dict[str, Any]]


def _render(tmp_path: Path, build: Callable[[Path], Path]) -> Rendered:
    scene = resolved.load(build(tmp_path / "scene"))
    buffers, info = pb.render_arrays(scene)
    return scene, buffers, info


def test_version_names_the_gl_renderer() -> None:
    """What it declares: test_registry.py's DECLARED."""
    assert "pyrender 0.1.45" in pb.version() and "llvmpipe" in pb.version()


def test_msaa_is_off_and_info_has_depth_model(tmp_path: Path) -> None:
    _, _, info = _render(tmp_path, cases.three_triangles_two_objects)
    assert info["gl_samples"] == 0
    model = info["depth_model"]
    assert model["bits"] == 24 and model["near"] == info["znear"] and model["far"] == info["zfar"]
    assert 0 < info["znear"] < info["zfar"] < np.inf


@pytest.mark.parametrize("distance", [5.0, 123.25])
def test_facing_plane_depth_is_its_distance(tmp_path: Path, distance: float) -> None:
    _, buf, info = _render(tmp_path, lambda d: cases.facing_quad(d, distance))
    assert np.all(buf["prim"] != BG), "the quad fills the view"
    err = np.abs(buf["Z"].astype(np.float64) - distance)
    tol = pb.depth_tolerance(np.full(err.shape, distance), info["znear"], info["zfar"])
    assert np.all(err <= tol), f"max error {err.max():.3g}, tolerance {tol.max():.3g}"


def test_tilted_plane_depth_matches_ray_plane_intersection(tmp_path: Path) -> None:
    scene, buf, info = _render(tmp_path, cases.tilted_quad)
    want = cases.plane_depth(scene, cases.TILTED_POINT, cases.TILTED_NORMAL)
    assert np.all(buf["prim"] != BG)
    err = np.abs(buf["Z"].astype(np.float64) - want)
    tol = pb.depth_tolerance(want, info["znear"], info["zfar"])
    # Steep enough that sampling 0.01 px away from the pixel center would break the tolerance.
    assert 0.01 * np.abs(np.diff(want, axis=1)).min() > tol.max()
    assert np.all(err <= tol), f"max error/tolerance {np.max(err / tol):.3g}"


def test_depth_matches_ray_cast_where_ids_agree(tmp_path: Path) -> None:
    scene, buf, info = _render(tmp_path, cases.three_triangles_two_objects)
    ref = cases.cast(scene)
    same = (buf["prim"] == ref.prim) & (ref.prim != BG)
    err = np.abs(buf["Z"][same].astype(np.float64) - ref.z[same])
    assert np.all(err <= pb.depth_tolerance(ref.z[same], info["znear"], info["zfar"]))


def test_id_colour_code_round_trips_every_byte() -> None:
    count = 70001
    rgba = pb.encode_ids(count)[::3]  # one vertex per triangle
    assert np.all(rgba[:, 3] == 255)
    image = rgba[None, :, :3]
    assert np.array_equal(pb.decode_ids(image, count)[0], np.arange(count, dtype=np.uint32))
    assert pb.decode_ids(np.zeros((1, 1, 3), np.uint8), count)[0, 0] == BG


def test_refuses_more_triangles_than_24_bits() -> None:
    with pytest.raises(BackendError, match="24-bit"):
        pb.encode_ids(2**24)


def test_depth_range_hugs_the_geometry(tmp_path: Path) -> None:
    scene = resolved.load(cases.three_triangles_two_objects(tmp_path / "s"))
    near, far = pb.choose_depth_range(scene)
    depths = pb.vertex_depths(scene)
    assert near == pytest.approx(0.5 * depths.min()) and far == pytest.approx(1.5 * depths.max())
    assert scene.camera.near < near


def test_depth_tolerance_is_four_steps_plus_an_ulp() -> None:
    z = np.array([1.0, 10.0, 100.0])
    step = z**2 * (1000.0 - 0.01) / (1000.0 * 0.01) * 2.0**-24
    got = pb.depth_tolerance(z, 0.01, 1000.0)
    assert np.allclose(got, 4 * step + np.spacing(z.astype(np.float32)), rtol=1e-12)


def test_render_writes_exr_with_depth_planes(tmp_path: Path) -> None:
    scene = resolved.load(cases.three_triangles_two_objects(tmp_path / "s"))
    out = tmp_path / "out.exr"
    info = pb.render(scene, out, tmp_path, timeout_s=60.0)
    got = exrbuf.read_buffers(out, require=["Z", "id.prim", "id.object"])
    attrs = exrbuf.read_attrs(out)
    assert attrs["znear"] == info["znear"] and attrs["zfar"] == info["zfar"]
    buf, _ = pb.render_arrays(scene)
    assert np.array_equal(got["id.prim"], buf["prim"]) and np.array_equal(got["id.object"], buf["obj"])
    assert np.array_equal(got["Z"], buf["Z"])
    assert "N" not in got and "RGB" not in got
    timings = info["timings_s"]
    assert isinstance(timings, dict) and set(timings) >= {"render", "write"}


def test_scene_near_plane_clips(tmp_path: Path) -> None:
    _, buf, info = _render(tmp_path, cases.near_clipped)
    assert np.all((buf["prim"] == 2) | (buf["prim"] == 3))
    assert np.all(np.abs(buf["Z"] - 1.0) <= pb.depth_tolerance(1.0, info["znear"], info["zfar"]))


def test_second_pass_tightens_planes_when_geometry_is_behind_the_eye(tmp_path: Path) -> None:
    scene, _, info = _render(tmp_path, cases.tilted_quad)
    assert pb.vertex_depths(scene).min() < 0, "the quad must reach behind the camera"
    first, second = info["depth_passes"]
    assert first["near"] == scene.camera.near
    assert second["near"] > 1000 * first["near"] and info["znear"] == second["near"]
