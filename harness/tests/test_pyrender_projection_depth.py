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

from rendiff_harness.judge import tolerance as tl
from rendiff_harness.renderers.pyrender import backend as pb

SCENE = Path(__file__).resolve().parents[2] / "scenes" / "fuzz_pyrender_near_clip.toml"
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
