"""classify.py: pixel distance from a center to a triangle's projected (clipped) edges."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from fixtures import write_scene
from rendiff_harness.contract import resolved, vocab
from rendiff_harness.contract.camera import Camera
from rendiff_harness.judge import geometry as classify

# Camera of every test here: eye (0, 0, 5) looking down -z, vfov 90 (tan_half = 1), W = H = 16.
# For a point at planar depth z: px = (x/z + 1) * 8, py = (1 - y/z) * 8.


def _camera(
    tmp_path: Path, width: int = 16, height: int = 16, near: float = 1e-3, far: float | None = None, vfov: float = 90.0
) -> Camera:
    d = write_scene(
        tmp_path / "cam",
        [[[0, 0, 0], [1, 0, 0], [0, 1, 0]]],
        vfov_deg=vfov,
        width=width,
        height=height,
        near=near,
        far=far,
    )
    return resolved.load(d).camera


def _dist(cam: Camera, tri: list[list[float]], cx: float, cy: float) -> float:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no RuntimeWarning may escape
        with np.errstate(all="raise"):
            d = classify.edge_distance(cam, np.array([tri]), np.array([cx]), np.array([cy]))
    assert d.shape == (1,)
    return float(d[0])


# Triangle at world z = 4 (depth 1): A=(-0.5, 1/16), B=(0.5, 1/16), C=(0, 0.75).
# Projected: A=(4, 7.5), B=(12, 7.5), C=(8, 2); edge AB is the horizontal line py = 7.5.
TRI = [[-0.5, 0.0625, 4.0], [0.5, 0.0625, 4.0], [0.0, 0.75, 4.0]]


def test_center_exactly_on_an_edge_has_distance_zero(tmp_path: Path) -> None:
    cam = _camera(tmp_path)
    assert _dist(cam, TRI, 8.5, 7.5) == 0.0  # pixel (8, 7)'s center
    assert _dist(cam, TRI, 4.0, 7.5) == 0.0  # a vertex


@pytest.mark.parametrize("offset", [1e-6, 1e-4, 1e-3, 0.25, 1.0])
def test_distance_to_a_horizontal_edge_is_the_offset(tmp_path: Path, offset: float) -> None:
    cam = _camera(tmp_path)
    for sign in (+1.0, -1.0):  # inside and outside the triangle
        assert _dist(cam, TRI, 8.5, 7.5 + sign * offset) == pytest.approx(offset, rel=1e-9, abs=1e-12)


def test_distance_beyond_a_segment_end_is_the_vertex_distance(tmp_path: Path) -> None:
    cam = _camera(tmp_path)
    assert _dist(cam, TRI, 13.5, 7.5) == pytest.approx(1.5)  # B = (12, 7.5)
    assert _dist(cam, TRI, 15.0, 11.5) == pytest.approx(5.0)  # 3-4-5 from B


def test_slanted_edge_closed_form(tmp_path: Path) -> None:
    """Distance to edge AC (from (4, 7.5) to (8, 2)) = |cross| / length."""
    cam = _camera(tmp_path)
    ax, ay, qx, qy = 4.0, 7.5, 8.0, 2.0
    cx, cy = 5.5, 5.5  # inside near AC
    expected = abs((qx - ax) * (cy - ay) - (qy - ay) * (cx - ax)) / math.hypot(qx - ax, qy - ay)
    assert _dist(cam, TRI, cx, cy) == pytest.approx(expected, rel=1e-12)


def test_shifted_edge_in_f32_matches_closed_form(tmp_path: Path) -> None:
    """Move AB by s px (vertices rounded to f32, as in the resolved scene): distance = |7.5 - py|."""
    cam = _camera(tmp_path)
    for s in (1e-4, 1e-3, 0.3):
        y0 = np.float32(0.0625 + s / 8.0)
        tri = [[-0.5, float(y0), 4.0], [0.5, float(y0), 4.0], [0.0, 0.75, 4.0]]
        py = (1.0 - float(y0) / 1.0) * 8.0
        assert _dist(cam, tri, 8.5, 7.5) == pytest.approx(abs(7.5 - py), rel=1e-9)


def test_vectorized_matches_one_by_one(tmp_path: Path) -> None:
    cam = _camera(tmp_path)
    rng = np.random.default_rng(1)
    tris = rng.uniform(-2, 2, (50, 3, 3))
    tris[..., 2] = rng.uniform(-3, 3, (50, 3))
    cx, cy = rng.uniform(0, 16, 50), rng.uniform(0, 16, 50)
    all_at_once = classify.edge_distance(cam, tris, cx, cy)
    one_by_one = [_dist(cam, tris[i].tolist(), cx[i], cy[i]) for i in range(50)]
    np.testing.assert_array_equal(all_at_once, one_by_one)


def _brute_force(cam: Camera, poly3d: list[np.ndarray], cx: float, cy: float, n: int = 400_001) -> float:
    """Min distance from (cx, cy) to densely sampled projected edges of a 3-D polygon in front of the eye."""
    best = math.inf
    t = np.linspace(0.0, 1.0, n)[:, None]
    for i in range(len(poly3d)):
        a, b = poly3d[i], poly3d[(i + 1) % len(poly3d)]
        x, y, z = np.moveaxis(cam.to_camera(a + t * (b - a)), -1, 0)
        px, py = np.moveaxis(cam.to_pixel(x, y, z), -1, 0)
        best = min(best, float(np.hypot(px - cx, py - cy).min()))
    return best


def test_triangle_crossing_the_eye_plane_is_clipped_at_near(tmp_path: Path) -> None:
    """A ground triangle reaching behind the camera: distance equals the clipped polygon's."""
    cam = _camera(tmp_path, width=32, height=24, vfov=45.0, near=1e-3)
    a, b, c = np.array([-1.0, -1.0, 0.0]), np.array([1.0, -1.0, 0.0]), np.array([0.0, -1.0, 10.0])  # c: depth -5
    zc = cam.eye[2] - cam.near  # world z of the near plane
    p_bc = b + (zc - b[2]) / (c[2] - b[2]) * (c - b)
    p_ca = a + (zc - a[2]) / (c[2] - a[2]) * (c - a)
    poly = [a, b, p_bc, p_ca]
    for cx, cy in [(16.5, 20.5), (12.5, 22.5), (25.5, 23.5), (3.5, 17.5)]:
        got = _dist(cam, [a.tolist(), b.tolist(), c.tolist()], cx, cy)
        assert math.isfinite(got)
        assert got == pytest.approx(_brute_force(cam, poly, cx, cy), abs=1e-3)


def test_far_plane_clip_line_is_an_edge(tmp_path: Path) -> None:
    cam = _camera(tmp_path, width=32, height=24, vfov=45.0, far=6.0)
    tri = [[-2.0, -1.0, 1.0], [2.0, -1.0, 1.0], [0.0, -1.0, -5.0]]  # depths 4, 4, 10; far = 6
    py_far = (1.0 + 1.0 / 6.0 / cam.tan_half_vfov) * 12.0
    assert _dist(cam, tri, 16.0, py_far - 0.01) == pytest.approx(0.01, rel=1e-6)


def test_edge_on_and_collinear_triangles_have_distance_zero(tmp_path: Path) -> None:
    cam = _camera(tmp_path)
    edge_on = [[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -3.0]]  # plane y = 0 holds the eye
    assert _dist(cam, edge_on, 3.5, 9.5) == 0.0
    collinear = [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [2.0, 2.0, 0.0]]
    assert _dist(cam, collinear, 1.5, 14.5) == 0.0
    point = [[0.5, 0.5, 0.0]] * 3
    assert _dist(cam, point, 1.5, 14.5) == 0.0


def test_triangle_behind_the_eye_or_beyond_far_is_infinitely_far(tmp_path: Path) -> None:
    cam = _camera(tmp_path, far=20.0)
    assert _dist(cam, [[-1, -1, 6.0], [1, -1, 6.0], [0, 1, 7.0]], 8.0, 8.0) == math.inf
    assert _dist(cam, [[-1, -1, -30.0], [1, -1, -30.0], [0, 1, -40.0]], 8.0, 8.0) == math.inf


def test_prim_distances_ignore_background_and_unknown_ids(tmp_path: Path) -> None:
    d = write_scene(tmp_path / "s", [TRI], width=16, height=16, vfov_deg=90.0)
    scene = resolved.load(d)
    bg = vocab.BACKGROUND_ID
    rows, cols = np.array([7, 7, 7, 7]), np.array([8, 8, 8, 8])
    ref = np.array([0, bg, bg, 5], dtype=np.uint32)
    test = np.array([bg, 0, bg, bg], dtype=np.uint32)
    got = classify.mismatch_edge_distance(scene, ref, test, rows, cols)
    assert got[0] == 0.0 and got[1] == 0.0
    assert got[2] == math.inf and got[3] == math.inf  # nothing / an ID naming no triangle


def test_no_warnings_on_large_random_batches(tmp_path: Path) -> None:
    cam = _camera(tmp_path, width=64, height=48, vfov=60.0)
    rng = np.random.default_rng(7)
    tris = rng.normal(0, 4, (20_000, 3, 3))
    tris[:100] = tris[:100, :1]  # degenerate points
    tris[100:200, :, 1] = 0.0  # edge-on (plane y = 0 holds the eye)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        d = classify.edge_distance(cam, tris, rng.uniform(0, 64, 20_000), rng.uniform(0, 48, 20_000))
    assert not np.isnan(d).any()
    assert np.all((d[:200] == 0.0) | (d[:200] == np.inf))  # inf: entirely behind the eye
    assert np.count_nonzero(d[:200] == 0.0) > 50
