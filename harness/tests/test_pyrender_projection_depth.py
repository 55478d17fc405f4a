"""pyrender's f32 clip coordinates (`f32_projection_depth`): its vertex shader evaluates
P * V * M * inst_m * v left to right, so P·V is an f32 matrix product and clip z and w are
rounded independently far from the origin. The fuzzer's finding (seed 14, `s14_00516`, reduced to
scenes/fuzz_pyrender_near_clip.toml) replayed in numpy, and the model on both sides of it
(docs/verifier.md, "Depth": pyrender)."""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rendiff_harness.judge import tolerance as tl
from rendiff_harness.renderers.pyrender import backend as pb

# The checkout's root: the nearest folder above with scenes/ (two up here; further under mutmut's
# mutants/ copy of the tests).
REPO = next(p for p in Path(__file__).resolve().parents if (p / "scenes").is_dir())
SCENE = REPO / "scenes" / "fuzz_pyrender_near_clip.toml"
PIXEL = (41, 33)  # the failing pixel of the reduced scene (prim 0, the triangle facing the camera)
TEST_Z = 68.6808014  # pyrender's depth there (its EXR), reproduced below from its arithmetic


def _finding() -> dict[str, Any]:
    """The reduced scene's camera and triangles, and the GL planes pyrender chose for it."""
    scene = tomllib.loads(SCENE.read_text())
    cam = scene["camera"]
    eye, look = np.array(cam["eye"]), np.array(cam["look_at"])
    fwd = (look - eye) / np.linalg.norm(look - eye)
    right = np.cross(fwd, cam["up"])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    tris = np.array([o["shape"]["vertices"] for o in scene["objects"]], dtype=np.float64)
    depths = (tris - eye) @ fwd
    near = float(cam["near"])  # choose_depth_range: a vertex behind the eye keeps the scene's near
    far = pb.FAR_FACTOR * float(depths.max())
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = right, up, -fwd, eye
    return {"cam": cam, "eye": eye, "fwd": fwd, "tris": tris, "near": near, "far": far, "pose": pose}


def _f32_dot_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a @ b in f32, each entry a sequential 4-term sum of rounded products (a GLSL dot)."""
    out = np.zeros((a.shape[0], b.shape[1]), dtype=np.float32)
    for k in range(4):
        out = (out + (a[:, k : k + 1] * b[k : k + 1, :]).astype(np.float32)).astype(np.float32)
    return out


def _pyrender_window_z(f: dict[str, Any], vertex: np.ndarray, left_to_right: bool) -> float:
    """Planar depth from the 24-bit window depth pyrender stores for a vertex: its matrices
    (pyrender.camera.PerspectiveCamera, V = inv(pose)) in f32, P·V first or V·v first."""
    n, fa, cam = f["near"], f["far"], f["cam"]
    t = math.tan(math.radians(cam["vfov"]) / 2.0)
    proj = np.zeros((4, 4))
    proj[0, 0], proj[1, 1], proj[3, 2] = 1.0 / (cam["width"] / cam["height"] * t), 1.0 / t, -1.0
    proj[2, 2], proj[2, 3] = (fa + n) / (n - fa), 2.0 * fa * n / (n - fa)
    p32, v32 = proj.astype(np.float32), np.linalg.inv(f["pose"]).astype(np.float32)
    x = np.append(vertex, 1.0).astype(np.float32).reshape(4, 1)
    clip = _f32_dot_rows(_f32_dot_rows(p32, v32), x) if left_to_right else _f32_dot_rows(p32, _f32_dot_rows(v32, x))
    ndc = np.float32(clip[2, 0] / clip[3, 0])
    top = (1 << pb.DEPTH_BITS) - 1
    code = np.round(float(np.float32(0.5) * ndc + np.float32(0.5)) * top)
    return float(pb.linearize_depth(np.array([code], dtype=np.uint32), n, fa)[0])


def _ctx(f: dict[str, Any], offset: np.ndarray | None = None) -> tl.DepthContext:
    """The depth model's context at the failing pixel, the scene moved by `offset`."""
    shift = np.zeros(3) if offset is None else offset
    tri, eye = f["tris"][0] + shift, f["eye"] + shift
    z = float((tri[0] - eye) @ f["fwd"])  # the triangle faces the camera: one depth
    cam = f["cam"]
    pixel = 2.0 * math.tan(math.radians(cam["vfov"]) / 2.0) / cam["height"]
    q = np.array([(PIXEL[0] + 0.5 - cam["width"] / 2) * pixel, (PIXEL[1] + 0.5 - cam["height"] / 2) * pixel])
    ray = np.append(q, 1.0)
    hit = eye + z * (q[0] * np.cross(f["fwd"], cam["up"]) - q[1] * np.array(cam["up"]) + f["fwd"])
    edges = [np.linalg.norm(tri[i] - tri[(i + 1) % 3]) for i in range(3)]
    return tl.DepthContext(
        z_ref=np.array([z]),
        cos=np.array([1.0 / np.linalg.norm(ray)]),
        info={"znear": f["near"], "zfar": f["far"]},
        attrs={},
        pixel_size=pixel,
        point_norm=np.array([np.linalg.norm(hit)]),
        extent=np.array([max(edges)]),
        eye_norm=float(np.linalg.norm(eye)),
        depth_span=np.array([0.0]),
    )


def test_pyrender_s_depth_is_its_f32_p_times_v_product() -> None:
    f = _finding()
    vertex = f["tris"][0, 0]
    exact = float((vertex - f["eye"]) @ f["fwd"])
    assert _pyrender_window_z(f, vertex, left_to_right=True) == np.float32(TEST_Z)
    # V·v first (the eye-space point the view-transform term models) stays within 4 steps
    right_first = _pyrender_window_z(f, vertex, left_to_right=False)
    assert abs(right_first - exact) <= float(pb.depth_tolerance(exact, f["near"], f["far"]))
    assert abs(TEST_Z - exact) > 10 * float(pb.depth_tolerance(exact, f["near"], f["far"]))


def test_the_finding_fails_without_the_term_and_passes_with_it() -> None:
    f = _finding()
    ctx = _ctx(f)
    error = abs(TEST_Z - float(ctx.z_ref[0]))
    tol = float(pb.pyrender_depth(ctx)[0][0])
    term = float(pb.f32_projection_depth(ctx, f["near"], f["far"])[0])
    assert tol - term < error <= tol
    # still a bound: a 1% depth error (1.3 times the bound there) fails
    assert tol < 0.01 * float(ctx.z_ref[0])


def test_the_term_grows_with_the_distance_from_the_origin_and_the_nearest_vertex() -> None:
    f = _finding()
    far_ctx = _ctx(f)
    near_ctx = _ctx(f, offset=-f["eye"])  # the same view with the eye at the origin
    error = abs(TEST_Z - float(far_ctx.z_ref[0]))
    assert float(pb.pyrender_depth(near_ctx)[0][0]) < error  # the same error there fails
    far_term = float(pb.f32_projection_depth(far_ctx, f["near"], f["far"])[0])
    near_term = float(pb.f32_projection_depth(near_ctx, f["near"], f["far"])[0])
    assert near_term < far_term / 100
    # a triangle reaching to the near plane: its nearest vertex's NDC error spreads over it
    z = float(far_ctx.z_ref[0])
    for nearest in (2.0 * f["near"], 0.5 * f["near"]):  # the nearest vertex, or the near plane clipping it
        span = dataclasses.replace(far_ctx, depth_span=np.array([z - nearest]))
        ratio = float(pb.f32_projection_depth(span, f["near"], f["far"])[0]) / far_term
        assert math.isclose(ratio, z / max(nearest, f["near"]), rel_tol=1e-9)


U = 2.0**-24


def _plain_ctx(z: float, **kw: Any) -> tl.DepthContext:
    return tl.DepthContext(z_ref=np.array([z]), cos=np.array([1.0]), info={}, attrs={}, **kw)


def test_the_term_is_the_derivation_s_sum_over_the_nearest_vertex() -> None:
    """docs/verifier.md, "Depth": pyrender, written out again: |dZ| <= Z^2 u (15(A s + B) + 11 s) /
    (B max(n, Z - span)), s = |X| + extent + |eye|, A = (f+n)/(f-n), B = 2fn/(f-n)."""
    n, f, z, x, extent, eye, span = 0.7, 300.0, 40.0, 5000.0, 3.0, 4990.0, 12.0
    a, b = (f + n) / (f - n), 2.0 * f * n / (f - n)
    s = x + extent + eye
    want = z * z * U * (15.0 * (a * s + b) + 11.0 * s) / (b * max(n, z - span))
    ctx = _plain_ctx(z, point_norm=np.array([x]), extent=np.array([extent]), eye_norm=eye, depth_span=np.array([span]))
    assert float(pb.f32_projection_depth(ctx, n, f)[0]) == pytest.approx(want, rel=1e-12)


def test_each_missing_input_takes_its_documented_stand_in() -> None:
    """Without |X| the hit is taken at Z + |eye| from the origin; without the edge nothing is added
    to it; without the depth span the nearest vertex is taken at the near plane."""
    n, f, z, eye = 0.5, 200.0, 30.0, 800.0
    a, b = (f + n) / (f - n), 2.0 * f * n / (f - n)

    def want(s: float, nearest: float) -> float:
        return z * z * U * (15.0 * (a * s + b) + 11.0 * s) / (b * nearest)

    bare = float(pb.f32_projection_depth(_plain_ctx(z, eye_norm=eye), n, f)[0])
    assert bare == pytest.approx(want(z + 2.0 * eye, n), rel=1e-12)
    with_x = float(pb.f32_projection_depth(_plain_ctx(z, eye_norm=eye, point_norm=np.array([100.0])), n, f)[0])
    assert with_x == pytest.approx(want(100.0 + eye, n), rel=1e-12)
    with_span = float(pb.f32_projection_depth(_plain_ctx(z, eye_norm=eye, depth_span=np.array([10.0])), n, f)[0])
    assert with_span == pytest.approx(want(z + 2.0 * eye, z - 10.0), rel=1e-12)


def test_pyrender_s_replayed_depth_stays_within_the_model_far_from_the_origin() -> None:
    """Soundness on random views: pyrender's own arithmetic (f32 P·V, then the vertex, then the
    24-bit code) replayed for vertices 1e2 to 1e6 from the origin stays within the 24-bit steps
    plus this term; V·v-first arithmetic (what the old model assumed) is not what is checked."""
    rng = np.random.default_rng(37)
    worst, checked = 0.0, 0
    for _ in range(300):
        far = 10.0 ** rng.uniform(2.0, 6.0)
        eye = rng.normal(size=3) * far
        fwd = rng.normal(size=3)
        fwd /= np.linalg.norm(fwd)
        up = np.cross(fwd, rng.normal(size=3))
        up /= np.linalg.norm(up)
        right = np.cross(fwd, up)
        z = rng.uniform(2.0, 200.0)
        vertex = eye + z * fwd + rng.uniform(-0.2, 0.2) * z * right
        near, far_plane = rng.uniform(0.05, 1.0), pb.FAR_FACTOR * z
        pose = np.eye(4)
        pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = right, up, -fwd, eye
        cam = {"vfov": 60.0, "width": 64, "height": 48}
        f = {"near": near, "far": far_plane, "cam": cam, "pose": pose}
        exact = float((vertex - eye) @ fwd)
        seen = _pyrender_window_z(f, vertex, left_to_right=True)
        if not math.isfinite(seen):
            continue  # rounded out of the clip volume: a missing hit, for the ID buffer's verdict
        ctx = _plain_ctx(
            exact,
            point_norm=np.array([np.linalg.norm(vertex)]),
            extent=np.array([0.0]),
            eye_norm=float(np.linalg.norm(eye)),
            depth_span=np.array([0.0]),
        )
        bound = float(pb.depth_tolerance(exact, near, far_plane)) + float(
            pb.f32_projection_depth(ctx, near, far_plane)[0]
        )
        assert abs(seen - exact) <= bound, (far, z, seen - exact, bound)
        worst = max(worst, abs(seen - exact) / bound)
        checked += 1
    assert checked >= 250
    assert worst > 0.01  # the replay does exercise the term, not only the 24-bit steps
