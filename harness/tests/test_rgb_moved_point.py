"""The RGB tolerance's moved-shading-point term (judge/moved_point.py; docs/verifier.md, "Radiance: the
moved shading point"), on the POV-Ray finding it was derived for (scenes/fuzz_povray_far_light.toml)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import backend_cases as cases
from fixtures import write_scene
from rendiff_harness.contract import lighting, resolved
from rendiff_harness.contract.manifest import Reference
from rendiff_harness.judge import moved_point, tolerance
from rendiff_harness.judge.depth import depth_context
from rendiff_harness.judge.rgb import compare_rgb
from rendiff_harness.renderers import registry
from rendiff_harness.renderers.povray import backend as pov
from rendiff_harness.renderers.spec import BackendSpec

OFFSET = np.array([1024.0, -1024.0, 1024.0])
"""The fuzzer's `translate` offset for scenes/two_lights_shadowless.toml."""

# scenes/fuzz_povray_far_light.toml, as the reducer wrote it (one side of the block, one light).
FOUND_TRI = [[1023.5, -1024.0, 1023.875], [1023.875, -1024.0, 1024.5], [1023.875, -1023.25, 1024.5]]
FOUND_EYE = (1025.5, -1021.5, 1028.0)
FOUND_LOOK = (1024.0, -1023.8, 1024.0)
FOUND_VFOV = 1.977527745565561
FOUND_LIGHT = {"kind": "point", "position": [1022.5, -1022.5, 1023.5], "intensity": [2.0, 3.0, 4.0]}
REQUIRES = ("depth", "ids", "lambert", "point_light", "shadowless", "two_sided")


def _povray() -> BackendSpec:
    spec = registry.spec("povray")
    assert spec is not None
    return spec


def _scene(
    directory: Path,
    shift: np.ndarray,
    tris: list[list[float]] | None = None,
    light: dict[str, Any] | None = None,
    size: tuple[int, int] = (10, 2),
    vfov: float = FOUND_VFOV,
    requires: tuple[str, ...] = REQUIRES,
) -> resolved.ResolvedScene:
    """The found scene moved by `shift` (zero: where the fuzzer found it)."""
    lit = dict(light or FOUND_LIGHT)
    if lit["kind"] == "point":
        lit["position"] = (np.asarray(lit["position"]) + shift).tolist()
    write_scene(
        directory,
        [(np.asarray(tris or FOUND_TRI) + shift).tolist()],
        eye=tuple(np.asarray(FOUND_EYE) + shift),
        look_at=tuple(np.asarray(FOUND_LOOK) + shift),
        vfov_deg=vfov,
        width=size[0],
        height=size[1],
        near=1e-3,
        requires=requires,
        materials=[{"name": "m0", "albedo": [0.2, 0.7, 0.3], "emission": [0.0, 0.0, 0.0]}],
        lights=[lit],
    )
    return resolved.load(directory)


def _reference(scene: resolved.ResolvedScene) -> Reference:
    """The contract's pixel-center hits (backend_cases.cast) and local shading, in f32 like a render."""
    hit = cases.cast(scene)
    rgb = lighting.local_radiance(scene, hit.prim, hit.z).astype(np.float32)
    buffers = {"Z": hit.z.astype(np.float32), "id.prim": hit.prim, "RGB": rgb}
    return Reference(scene, buffers, hit.prim.shape)


def _attrs(ref: Reference) -> dict[str, Any]:
    """POV-Ray's exposure for this reference: the largest upper bound times its margin."""
    s = float(lighting.upper_bound(ref.scene, ref.buffers["id.prim"], ref.buffers["Z"]).max()) * pov.EXPOSURE_MARGIN
    return {"rgb_scale": s, "emission_scale": 0.0, "rgb_encoding": "png16-linear"}


def _compare(ref: Reference, test_rgb: np.ndarray, spec: BackendSpec, attrs: dict[str, Any]) -> Any:
    return compare_rgb(ref, {"RGB": test_rgb}, attrs, "povray", {"info": {}}, None, spec)


def _povray_f32_plane(scene: resolved.ResolvedScene, ref: Reference) -> tuple[np.ndarray, np.ndarray]:
    """POV-Ray 3.7's mesh2 arithmetic at each hit pixel, written out: the unit normal of the f32
    vertices in double, stored as f32 (`SnglVector3d`), the offset -n.P1 stored as f32 (`SNGL
    Distance`), t = -(d + n.O)/(n.D) in double along the unit ray, and the light from that point
    with the stored normal. Returns (|X' - X| (H, W), the lit radiance (H, W, 3))."""
    cam = scene.camera
    prim, z = ref.buffers["id.prim"], ref.buffers["Z"].astype(np.float64)
    moved = np.zeros(prim.shape)
    out = np.zeros((*prim.shape, 3))
    albedo, _ = scene.material_arrays()
    (pos, intensity), *_ = lighting.lights_of(scene)[0]
    for y, x in zip(*np.nonzero(prim != cases.BACKGROUND_ID), strict=True):
        p1, p2, p3 = scene.triangles[int(prim[y, x])].astype(np.float64)
        n = np.cross(p1 - p2, p3 - p2)
        n /= np.linalg.norm(n)
        n32 = n.astype(np.float32).astype(np.float64)
        d32 = float(np.float32(-(n @ p1)))
        d = cam.center_directions(np.array([y]), np.array([x]))[0]
        unit = d / np.linalg.norm(d)
        t = -(d32 + n32 @ cam.eye) / (n32 @ unit)
        xp = cam.eye + t * unit
        moved[y, x] = np.linalg.norm(xp - (cam.eye + z[y, x] * d))
        ns = n32 / np.linalg.norm(n32)
        ns = ns if ns @ unit < 0 else -ns  # two-sided: toward the viewer
        w = pos - xp
        r = float(np.linalg.norm(w))
        out[y, x] = albedo[0] / math.pi * intensity * max(0.0, float(ns @ w) / r) / r**2
    return moved, out


def _quantized(rgb: np.ndarray, scale: float) -> np.ndarray:
    """A 16-bit linear pass read back: the nearest code of `scale`/65535."""
    return (np.rint(rgb / scale * 65535.0) * (scale / 65535.0)).astype(np.float32)


def test_povray_f32_plane_explains_the_finding_and_the_term_bounds_it(tmp_path: Path) -> None:
    scene = _scene(tmp_path / "found", np.zeros(3))
    ref = _reference(scene)
    hit = ref.buffers["id.prim"] != cases.BACKGROUND_ID
    assert hit.sum() == 2  # the reduced 10x2 image sees the block's side in its first column
    attrs = _attrs(ref)
    moved, lit = _povray_f32_plane(scene, ref)
    # The hypothesis, on the numbers: the f32 plane moves the point 4.4e-4 along the ray and the
    # light's 1/r^2 (r = 1.8) by 1.3e-4 to 1.8e-4 relative: about 10 codes of POV-Ray's output.
    assert 3e-4 < moved[hit].max() < 6e-4
    b = ref.buffers["RGB"].astype(np.float64)
    rel = np.abs(lit - b)[hit] / b[hit]
    assert 1e-4 < rel.max() < 3e-4
    spec = _povray()
    extra, _ = moved_point.moved_point_tolerance(ref, spec, {"info": {}}, attrs) or (None, "")
    assert extra is not None
    # The bound holds the move and the radiance change at every pixel (the derivation's own test).
    rows, cols = np.nonzero(hit)
    prims = ref.buffers["id.prim"][rows, cols].astype(np.int64)
    ctx = depth_context(ref, rows, cols, ref.buffers["Z"][rows, cols].astype(np.float64), prims, {"info": {}}, attrs)
    farthest = np.linalg.norm(scene.triangles[prims].astype(np.float64), axis=2).max(axis=1)
    assert spec.rgb_moved_point is not None
    delta = spec.rgb_moved_point.point(ctx, farthest)
    assert np.all(moved[rows, cols] <= delta)
    assert np.all(np.abs(lit - b)[hit] <= extra[hit])
    # As POV-Ray writes it (16-bit codes): the old tolerance fails every pixel, the new one passes.
    seen = _quantized(lit, attrs["rgb_scale"])
    before = _compare(ref, seen, dataclasses.replace(spec, rgb_moved_point=None), attrs)
    assert before.interior == 2 and "moved shading point" not in before.tolerance
    after = _compare(ref, seen, spec, attrs)
    assert after.interior == 0 and after.failing_pixels == 0 and "moved shading point" in after.tolerance


@pytest.mark.parametrize("over", [0.99, 1.01])
def test_a_pixel_just_inside_and_just_outside_the_moved_point_bound(tmp_path: Path, over: float) -> None:
    scene = _scene(tmp_path / "found", np.zeros(3))
    ref = _reference(scene)
    attrs = _attrs(ref)
    spec = _povray()
    base = spec.rgb_tolerance(ref.buffers["RGB"], attrs, {}) if spec.rgb_tolerance else None
    assert base is not None
    extra, _ = moved_point.moved_point_tolerance(ref, spec, {"info": {}}, attrs) or (None, "")
    assert extra is not None
    b = ref.buffers["RGB"].astype(np.float64)
    y, x = 1, 0
    old = base.abs_tol + base.rel * b[y, x, 1]
    full = old + extra[y, x, 1]
    assert full > 20 * old  # the pixel is decided by the new term, not by the old tolerance
    test = b.copy()
    test[y, x, 1] = b[y, x, 1] + over * full
    res = _compare(ref, test, spec, attrs)
    assert (res.interior, res.failing_pixels) == ((0, 0) if over < 1 else (1, 1))


def test_the_term_shrinks_with_the_distance_from_the_origin(tmp_path: Path) -> None:
    """Near the origin the term is below POV-Ray's own relative term (1e-5 |L|, its colour
    arithmetic): it hides nothing the old tolerance caught there. It grows with |X|."""
    spec = _povray()
    terms = {}
    for name, shift in (("far", np.zeros(3)), ("origin", -OFFSET)):
        ref = _reference(_scene(tmp_path / name, shift))
        extra, _ = moved_point.moved_point_tolerance(ref, spec, {"info": {}}, _attrs(ref)) or (None, "")
        assert extra is not None
        b = ref.buffers["RGB"].astype(np.float64)
        hit = ref.buffers["id.prim"] != cases.BACKGROUND_ID
        terms[name] = (extra[hit] / b[hit]).max()
    assert terms["origin"] < pov.POVRAY_RGB_REL
    # |X| 1773 against about 1.2 (the farthest vertex): the position model's ratio, 3 orders.
    assert terms["far"] > 500 * terms["origin"]


def test_a_light_in_the_triangles_plane_is_within_the_moved_point(tmp_path: Path) -> None:
    """The drifted reduction's failure: the light in the triangle's plane, the core's f64 cosine
    1.2e-14 (radiance 1.2e-14), POV-Ray's 0. n.w = 0 exactly, so only the cosine's change counts."""
    tri = [[1023.0, -1024.0, 1024.0], [1024.0, -1024.0, 1025.0], [1024.0, -1023.0, 1025.0]]
    scene = _scene(tmp_path / "grazing", np.zeros(3), tris=tri, size=(64, 48), vfov=45.0)
    ref = _reference(scene)
    hit = ref.buffers["id.prim"] != cases.BACKGROUND_ID
    assert hit.any() and float(np.abs(ref.buffers["RGB"][hit]).max()) < 1e-12
    b = np.where(hit[..., None], 1.2e-14, np.zeros((*hit.shape, 3)))
    ref.buffers["RGB"] = b.astype(np.float32)
    attrs = {"rgb_scale": 1.78639e-11, "emission_scale": 0.0, "rgb_encoding": "png16-linear"}
    spec = _povray()
    zero = np.zeros_like(b)
    assert _compare(ref, zero, dataclasses.replace(spec, rgb_moved_point=None), attrs).interior == int(hit.sum())
    assert _compare(ref, zero, spec, attrs).interior == 0


def test_point_light_change_bounds_every_move_and_is_not_loose_by_more_than_the_derivation(
    tmp_path: Path,
) -> None:
    """Random points, normals, lights and moves: the exact change of rho/pi I max(0, n.w)/r^2 never
    exceeds the bound, and the worst sampled move reaches at least a third of it (the bound sums
    the worst move across the light and the worst move along it, which no single move has)."""
    rng = np.random.default_rng(7)
    k = 64
    n = rng.normal(size=(k, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    light = np.array([1024.3, -1022.9, 1023.6])
    lights = [(light, np.array([3.0, 2.0, 1.0]))]
    # Put every point 0.5 to 3 from the light, in any direction (lit or not).
    away = rng.normal(size=(k, 3))
    x = light - rng.uniform(0.5, 3.0, size=(k, 1)) * away / np.linalg.norm(away, axis=1, keepdims=True)
    rho = np.full((k, 3), 0.5)
    delta = rng.uniform(1e-4, 5e-2, size=k)
    bound = moved_point.point_light_change(x, n, rho, lights, delta, np.zeros(k))

    def radiance(p: np.ndarray) -> np.ndarray:
        w = light[None, :] - p
        r = np.linalg.norm(w, axis=1)
        c = np.maximum(np.einsum("ij,ij->i", n, w) / r, 0.0)
        value: np.ndarray = rho * (lights[0][1] / math.pi)[None, :] * (c / r**2)[:, None]
        return value

    base = radiance(x)
    worst = np.zeros((k, 3))
    for _ in range(400):
        step = rng.normal(size=(k, 3))
        step *= (delta * rng.uniform(0.0, 1.0, size=k) ** 0.1 / np.linalg.norm(step, axis=1))[:, None]
        worst = np.maximum(worst, np.abs(radiance(x + step) - base))
    assert np.all(worst <= bound)
    lit = base[:, 0] > 0
    assert np.all(worst[lit, 0] >= bound[lit, 0] / 3.0)


def test_no_term_without_the_backends_model_or_a_point_light(tmp_path: Path) -> None:
    ref = _reference(_scene(tmp_path / "found", np.zeros(3)))
    attrs = _attrs(ref)
    assert moved_point.moved_point_tolerance(ref, registry.spec("raster"), {"info": {}}, attrs) is None
    assert moved_point.moved_point_tolerance(ref, None, {"info": {}}, attrs) is None
    sun = {"kind": "directional", "direction": [0.0, -1.0, -0.2], "irradiance": [1.0, 1.0, 1.0]}
    req = tuple(f.replace("point_light", "directional_light") for f in REQUIRES)
    sunlit = _scene(tmp_path / "sun", np.zeros(3), light=sun, requires=req)
    hit = cases.cast(sunlit)
    sref = Reference(sunlit, {"Z": hit.z.astype(np.float32), "id.prim": hit.prim}, hit.prim.shape)
    assert moved_point.moved_point_tolerance(sref, _povray(), {"info": {}}, attrs) is None


def test_a_light_just_behind_the_surface_may_come_in_front_and_one_far_behind_may_not() -> None:
    """c = n.w within the move's turn of 0: the moved point may see the light (the bound must
    allow it); far behind, nothing changes and the bound is exactly 0."""
    x = np.zeros((2, 3))
    n = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    lights = [(np.array([1.0, 0.0, -0.001]), np.array([1.0, 1.0, 1.0]))]
    rho = np.ones((2, 3))
    delta = np.array([0.01, 0.01])
    bound = moved_point.point_light_change(x, n, rho, lights, delta, np.zeros(2))
    moved = np.array([0.0, 0.0, -0.01])  # down by delta: the light is now 0.009 above the plane
    w = lights[0][0] - moved
    seen = float(n[0] @ w) / np.linalg.norm(w) ** 3 / math.pi
    assert 0.0 < seen <= bound[0, 0]
    behind = [(np.array([1.0, 0.0, -0.5]), np.array([1.0, 1.0, 1.0]))]
    assert np.all(moved_point.point_light_change(x, n, rho, behind, delta, np.zeros(2)) == 0.0)


def test_the_move_is_the_position_error_at_the_farthest_vertex_over_cos_along_the_ray() -> None:
    """delta = |d| min(m/|cos|, max(depth span, m)) with m the backend's position error at the
    triangle's farthest vertex (not at the hit point, which is nearer the origin)."""
    ctx = tolerance.DepthContext(
        z_ref=np.array([2.0, 2.0]),
        cos=np.array([0.5, 1e-9]),
        info={},
        attrs={},
        point_norm=np.array([1000.0, 1000.0]),
        extent=np.array([3.0, 3.0]),
        depth_span=np.array([0.25, 0.25]),
        ray_norm=np.array([1.2, 1.2]),
    )
    farthest = np.array([1002.0, 1002.0])
    delta = pov.povray_shading_move(ctx, farthest)
    m = 3.0 * tolerance.F32_U * 1002.0
    assert delta[0] == pytest.approx(1.2 * m / 0.5, rel=1e-12)
    assert delta[1] == pytest.approx(1.2 * 0.25, rel=1e-12)  # edge-on: at most the depth span
