"""Each backend's own shading move (`BackendSpec.rgb_moved_point`, `tolerance.ShadingMove`) and Mitsuba's
shadow-ray offset (`BackendSpec.shadow_ray_offset`), on the shaded `translate` findings they were derived
for (scenes/fuzz_mitsuba_far_light.toml, fuzz_pyrender_far_light.toml, fuzz_mitsuba_shadow_offset.toml;
docs/verifier.md, "Radiance: the moved shading point" and "shadow edges")."""

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
from rendiff_harness.renderers.mitsuba import backend as mb
from rendiff_harness.renderers.pyrender import backend as pb
from rendiff_harness.renderers.spec import BackendSpec

U = tolerance.F32_U
MITSUBA = mb.unavailable_reason()
PYRENDER = pb.unavailable_reason()
needs_mitsuba = pytest.mark.skipif(MITSUBA is not None, reason=f"mitsuba backend unavailable: {MITSUBA}")
needs_pyrender = pytest.mark.skipif(PYRENDER is not None, reason=f"pyrender backend unavailable: {PYRENDER}")

# scenes/fuzz_mitsuba_far_light.toml (the reducer's F1 of lambert_point's translate variant)
FLOOR_TRI = [[1020.0, -1024.0, 1028.0], [1028.0, -1024.0, 1028.0], [1028.0, -1024.0, 1020.0]]
FLOOR_LIGHT = {"kind": "point", "position": [1024.3, -1022.0, 1023.8], "intensity": [10.0, 10.0, 10.0]}
# scenes/fuzz_pyrender_far_light.toml (fuzz_povray_far_light moved again, by 2^19)
FAR = 525312.0 - 1024.0
SIDE_TRI = [[1023.5, -1024.0, 1023.875], [1023.875, -1024.0, 1024.5], [1023.875, -1023.25, 1024.5]]
SIDE_LIGHT = [1022.5, -1022.5, 1023.5]


def _spec(name: str) -> BackendSpec:
    spec = registry.spec(name)
    assert spec is not None
    return spec


def _lit_triangle(
    directory: Path, tri: Any, light: dict[str, Any], albedo: list[float], view: dict[str, Any], shadows: str
) -> resolved.ResolvedScene:
    """One shaded triangle under one point light, as the reducer leaves a shaded finding: `view`
    holds the camera's keywords, `shadows` the scene's shadow feature."""
    write_scene(
        directory,
        [np.asarray(tri).tolist()],
        requires=("depth", "ids", "lambert", "point_light", shadows, "two_sided"),
        materials=[{"name": "m0", "albedo": albedo, "emission": [0.0, 0.0, 0.0]}],
        lights=[light],
        **view,
    )
    return resolved.load(directory)


def _floor_scene(directory: Path) -> resolved.ResolvedScene:
    view: dict[str, Any] = {
        "eye": (1024.0, -1021.0, 1028.0),
        "look_at": (1024.0, -1024.0, 1024.0),
        "vfov_deg": 13.298703259196719,
    }
    view |= {"width": 2, "height": 12, "near": 0.001131370849898476}
    return _lit_triangle(directory, FLOOR_TRI, FLOOR_LIGHT, [0.5, 0.6, 0.7], view, "shadows")


def _side_scene(directory: Path, shift: float) -> resolved.ResolvedScene:
    s = np.array([shift, -shift, shift])
    view: dict[str, Any] = {
        "eye": tuple(np.array([1025.5, -1021.5, 1028.0]) + s),
        "look_at": tuple(np.array([1024.0, -1023.8, 1024.0]) + s),
    }
    view |= {"vfov_deg": 1.977527745565561, "width": 10, "height": 2, "near": 0.0008522910302183962}
    light = {"kind": "point", "position": (np.asarray(SIDE_LIGHT) + s).tolist(), "intensity": [2.0, 3.0, 4.0]}
    return _lit_triangle(directory, np.asarray(SIDE_TRI) + s, light, [0.2, 0.7, 0.3], view, "shadowless")


def _reference(scene: resolved.ResolvedScene) -> Reference:
    """The contract's pixel-center hits (backend_cases.cast) and local shading, in f32 like a render."""
    hit = cases.cast(scene)
    rgb = lighting.local_radiance(scene, hit.prim, hit.z).astype(np.float32)
    return Reference(scene, {"Z": hit.z.astype(np.float32), "id.prim": hit.prim, "RGB": rgb}, hit.prim.shape)


def _hits(ref: Reference) -> tuple[np.ndarray, np.ndarray, np.ndarray, tolerance.DepthContext, np.ndarray]:
    prim = ref.buffers["id.prim"]
    rows, cols = np.nonzero(prim != cases.BACKGROUND_ID)
    prims = prim[rows, cols].astype(np.int64)
    ctx = depth_context(ref, rows, cols, ref.buffers["Z"][rows, cols].astype(np.float64), prims, {"info": {}}, {})
    farthest = np.linalg.norm(ref.scene.triangles[prims].astype(np.float64), axis=2).max(axis=1)
    return rows, cols, prims, ctx, farthest


def _ctx(**kw: Any) -> tolerance.DepthContext:
    base: dict[str, Any] = dict(
        z_ref=np.array([4.0]),
        cos=np.array([0.5]),
        info={},
        attrs={},
        pixel_size=0.01,
        extent=np.array([10.0]),
        origin_offset=3e-5,
        eye_norm=1776.0,
        depth_span=np.array([2.0]),
        ray_norm=np.array([1.1]),
        corner_cond=np.array([1.5]),
    )
    base.update(kw)
    return tolerance.DepthContext(**base)


# --------------------------------------------------------------------------- the derivations, term by term


def test_mitsuba_move_is_its_ray_over_cos_plus_embrees_barycentrics_plus_the_interpolation() -> None:
    ctx = _ctx()
    far = np.array([1780.0])
    o = 3e-5 + 2.0 * math.sqrt(3.0) * U * 1776.0
    along = 1.1 * 4.0
    lateral = o + (math.sqrt(3.0) + 6.0) * U * along + U * (along + o + 10.0)
    eps = tolerance.MOELLER_DOT * 1.5 / 0.5
    bary = (2.0 * eps * (along + o + 10.0) + 2.0 * eps * 10.0) / (1.0 - eps) + 6.0 * U * 10.0
    want = lateral / 0.5 + bary + 5.0 * U * (1.0 + 10.0 * U) * 1780.0
    assert mb.mitsuba_shading_move(ctx, far)[0] == pytest.approx(want, rel=1e-12)
    # Edge-on: the in-plane part is capped at the triangle's longest edge, the interpolation is not.
    flat = mb.mitsuba_shading_move(_ctx(cos=np.array([0.0])), far)[0]
    assert flat == pytest.approx(10.0 * (1.0 + 4.0 * U) + 5.0 * U * (1.0 + 10.0 * U) * 1780.0, rel=1e-12)


def test_a_move_along_or_off_the_ray_needs_the_pixels_ray_length() -> None:
    """|d| >= 1 scales the move along the ray: without it the models refuse rather than guess 1."""
    ctx = _ctx(ray_norm=None)
    far = np.array([1780.0])
    with pytest.raises(
        tolerance.ToleranceError,
        match=r"^the moved shading point needs each pixel ray's length \(DepthContext\.ray_norm\)$",
    ):
        tolerance.along_ray_move(ctx, np.array([1e-4]))
    with pytest.raises(tolerance.ToleranceError, match=r"needs each pixel ray's length \(DepthContext.ray_norm\)"):
        mb.mitsuba_shading_move(ctx, far)
    assert tolerance.along_ray_move(_ctx(), np.array([1e-4]))[0] == pytest.approx(1.1 * 1e-4 / 0.5, rel=1e-12)


def test_pyrender_move_is_its_view_transform_over_cos_plus_the_interpolation() -> None:
    ctx = _ctx()
    far = np.array([1780.0])
    lateral = 4.0 * math.sqrt(3.0) * U * (1780.0 + 1776.0)
    want = lateral / 0.5 + 8.0 * U * 1780.0
    assert pb.pyrender_shading_move(ctx, far)[0] == pytest.approx(want, rel=1e-12)


def test_in_plane_move_is_the_lateral_move_over_cos_and_at_most_the_longest_edge() -> None:
    """A ray moved sideways by e meets a plane at most e / |cos| from its old hit; at cos 0.5 that is
    2 e, just below the 10 edge; at cos 0.1 it would be 10.5 and the edge caps it."""
    assert tolerance.in_plane_move(_ctx(), np.array([4.9]))[0] == pytest.approx(9.8)
    assert tolerance.in_plane_move(_ctx(cos=np.array([0.1])), np.array([1.05]))[0] == pytest.approx(
        10.0 * (1.0 + 4.0 * U)
    )
    # The lateral bound is tight: a ray moved by e along the in-plane direction of its own tilt.
    n = np.array([0.0, 0.0, 1.0])
    d = np.array([math.sqrt(1.0 - 0.25), 0.0, -0.5])  # |cos| = 0.5
    e = 1e-3 * np.array([0.5, 0.0, math.sqrt(0.75)])  # perpendicular to d
    hit0 = -(n @ np.array([0.0, 0.0, 1.0])) / (n @ d) * d + np.array([0.0, 0.0, 1.0])
    o1 = np.array([0.0, 0.0, 1.0]) + e
    hit1 = o1 - (n @ o1) / (n @ d) * d
    assert np.linalg.norm(hit1 - hit0) == pytest.approx(1e-3 / 0.5, rel=1e-9)


def test_embree_barycentrics_are_unbounded_where_den_is_within_its_own_error() -> None:
    eps_one = tolerance.MOELLER_DOT * 1.5
    near_edge_on = _ctx(cos=np.array([eps_one * 1.01, eps_one * 0.99]), z_ref=np.array([4.0, 4.0]))
    near_edge_on = dataclasses.replace(
        near_edge_on, extent=np.array([10.0, 10.0]), ray_norm=np.array([1.1, 1.1]), corner_cond=np.array([1.5, 1.5])
    )
    move = tolerance.embree_barycentric_move(near_edge_on, np.zeros(2))
    assert np.isfinite(move[0]) and np.isinf(move[1])


@pytest.mark.parametrize("missing", ["corner_cond", "extent", "ray_norm"])
def test_embree_barycentrics_without_the_triangle_or_the_ray_are_unbounded(missing: str) -> None:
    ctx = _ctx(z_ref=np.array([4.0, 2.0]), cos=np.array([0.5, 0.5]), **{missing: None})
    move = tolerance.embree_barycentric_move(ctx, np.zeros(2))
    assert move.shape == (2,) and np.all(np.isinf(move))


def test_an_edge_on_ray_with_no_lateral_move_is_unbounded_but_for_the_triangle() -> None:
    """0 / |cos| = 0 / 0 edge-on: the move is not known, so it is the longest edge, or unbounded."""
    zero = np.array([0.0])
    assert tolerance.in_plane_move(_ctx(cos=zero), zero)[0] == pytest.approx(10.0 * (1.0 + 4.0 * U))
    assert np.isinf(tolerance.in_plane_move(_ctx(cos=zero, extent=None), zero)[0])
    assert tolerance.in_plane_move(_ctx(extent=None), np.array([1.0]), 0.5)[0] == pytest.approx(2.5)


def test_a_light_rounded_to_f32_counts_as_the_point_moved_by_as_much() -> None:
    x = np.array([[0.0, 0.0, 0.0]])
    n = np.array([[0.0, 1.0, 0.0]])
    rho = np.full((1, 3), 0.5)
    light = [(np.array([0.3, 2.0, -0.2]), np.array([10.0, 10.0, 10.0]))]
    moved = moved_point.point_light_change(x, n, rho, light, np.array([1e-3]), np.zeros(1))
    by_light = moved_point.point_light_change(x, n, rho, light, np.zeros(1), np.zeros(1), [1e-3])
    both = moved_point.point_light_change(x, n, rho, light, np.array([5e-4]), np.zeros(1), [5e-4])
    assert np.allclose(moved, by_light, rtol=1e-15) and np.allclose(moved, both, rtol=1e-15)
    assert moved_point.f32_move(np.array([1024.3, -1022.0, 1023.8])) == pytest.approx(
        math.hypot(1024.3 - float(np.float32(1024.3)), 1023.8 - float(np.float32(1023.8))), rel=1e-9
    )
    assert moved_point.f32_move(np.array([1024.5, -1.0, 0.25])) == 0.0


def test_which_backends_move_their_point_and_round_their_lights() -> None:
    """POV-Ray places lights in f64; Mitsuba (ScalarPoint3f) and pyrender (f32 uniforms) in f32."""
    assert {
        n: (s.rgb_moved_point.f32_lights if (s := _spec(n)).rgb_moved_point else None)
        for n in ("povray", "mitsuba", "pyrender", "raster")
    } == {
        "povray": False,
        "mitsuba": True,
        "pyrender": True,
        "raster": None,
    }


# --------------------------------------------------------------------------- the findings


def _light_at(scene: resolved.ResolvedScene, point: np.ndarray, light: np.ndarray) -> np.ndarray:
    """rho/pi I |n.w| / r^2 at `point` (K, 3) from a light at `light` (two-sided, one triangle)."""
    albedo, _ = scene.material_arrays()
    (_, intensity), *_ = lighting.lights_of(scene)[0]
    n = lighting.face_normals(scene.triangles[:1].astype(np.float64))[0]
    w = light[None, :] - point
    r = np.linalg.norm(w, axis=1)
    value: np.ndarray = albedo[0][None, :] / math.pi * intensity[None, :] * (np.abs(w @ n) / r**3)[:, None]
    return value


@needs_mitsuba
def test_mitsuba_shades_its_own_point_and_light_within_the_move(tmp_path: Path) -> None:
    """The found F1: Mitsuba's own shading point (its `position` AOV, the radiance pass's sensor and
    sampler) lies within the derived move of the reference's hit at every pixel, and the light at that
    point from f32(L) reproduces Mitsuba's radiance to f32 rounding; the old tolerance fails, the new
    one passes."""
    scene = _floor_scene(tmp_path / "floor")
    ref = _reference(scene)
    spec = _spec("mitsuba")
    assert spec.rgb_moved_point is not None
    rgb, _, _ = mb.render_radiance(scene)
    mi = mb._import_mitsuba()
    near, far = mb.clip_range(scene)
    sampler = {"type": "stratified", "sample_count": 1, "jitter": False}
    shapes = mb.radiance_shapes(mi, scene, emitters=False)
    aov = mb._radiance_scene(mi, scene, near, far, {"type": "aov", "aovs": "p:position"}, sampler, shapes, [])
    position = np.array(mi.render(aov, spp=1, seed=0), dtype=np.float64)[..., :3]
    rows, cols, _, ctx, farthest = _hits(ref)
    assert rows.size == 12  # the triangle fills the lower half of the 2x12 image
    delta = spec.rgb_moved_point.point(ctx, farthest)
    cam = scene.camera
    x = cam.eye[None, :] + ref.buffers["Z"][rows, cols].astype(np.float64)[:, None] * cam.center_directions(rows, cols)
    moved = np.linalg.norm(position[rows, cols] - x, axis=1)
    assert np.all(moved <= delta) and moved.max() > 2e-5  # Mitsuba moved it: up to 1.9e-4 (bound 1.1e-3)
    (light, _), *_ = lighting.lights_of(scene)[0]
    light32 = light.astype(np.float32).astype(np.float64)
    mine = _light_at(scene, position[rows, cols], light32)
    assert np.allclose(mine, rgb[rows, cols], rtol=2e-6, atol=0.0)
    b = ref.buffers["RGB"].astype(np.float64)[rows, cols]
    assert np.max(np.abs(rgb[rows, cols] - b) / b) > mb.MITSUBA_RGB_REL  # 5.8e-5, beyond Mitsuba's own 5e-5
    test = {"RGB": rgb.astype(np.float32)}
    old = compare_rgb(ref, test, {}, "mitsuba", {"info": {}}, None, dataclasses.replace(spec, rgb_moved_point=None))
    new = compare_rgb(ref, test, {}, "mitsuba", {"info": {}}, None, spec)
    assert old.interior >= 1 and "moved shading point" not in old.tolerance
    assert (new.interior, new.failing_pixels) == (0, 0) and "f32(L)" in new.tolerance


@needs_mitsuba
@pytest.mark.parametrize("over", [0.99, 1.01])
def test_a_mitsuba_pixel_just_inside_and_just_outside_its_moved_point_bound(tmp_path: Path, over: float) -> None:
    scene = _floor_scene(tmp_path / "floor")
    ref = _reference(scene)
    spec = _spec("mitsuba")
    assert spec.rgb_tolerance is not None
    b = ref.buffers["RGB"].astype(np.float64)
    base = spec.rgb_tolerance(b, {}, {})
    extra, _ = moved_point.moved_point_tolerance(ref, spec, {"info": {}}, {}) or (None, "")
    assert extra is not None
    y, x = 11, 1
    old = float(np.asarray(base.abs_tol)) + base.rel * b[y, x, 2]
    full = old + extra[y, x, 2]
    assert full > 5 * old  # decided by the new term
    test = b.copy()
    test[y, x, 2] += over * full
    res = compare_rgb(ref, {"RGB": test}, {}, "mitsuba", {"info": {}}, None, spec)
    assert (res.interior, res.failing_pixels) == ((0, 0) if over < 1 else (1, 1))


@needs_pyrender
def test_pyrender_far_from_the_origin_moves_its_point_as_far_as_the_light(tmp_path: Path) -> None:
    """The found F2 (|X| 9.1e5): the view transform alone may move the point 0.75, so the move reaches
    the light 1.8 away and the bound is unbounded there. At the origin the term is below half of one of
    its 8-bit codes (it grows with |X|: 1024 from the origin, at |cos| 0.07, it is 5.6 codes)."""
    spec = _spec("pyrender")
    assert spec.rgb_moved_point is not None and spec.rgb_tolerance is not None
    far = _side_scene(tmp_path / "far", FAR)
    ref = _reference(far)
    buffers, info = pb.render_arrays(far)
    rgb, rinfo = pb.render_radiance(far, buffers["prim"], buffers["Z"], float(info["znear"]), float(info["zfar"]))
    attrs = {"rgb_scale": float(rinfo["rgb_scale"]), "rgb_encoding": "png8-gamma2.2"}
    test = {"RGB": rgb.astype(np.float32)}
    old = compare_rgb(ref, test, attrs, "pyrender", {"info": {}}, None, dataclasses.replace(spec, rgb_moved_point=None))
    new = compare_rgb(ref, test, attrs, "pyrender", {"info": {}}, None, spec)
    assert old.interior == 2
    assert (new.interior, new.failing_pixels) == (0, 0)
    rows, cols, _, ctx, farthest = _hits(ref)
    assert np.all(spec.rgb_moved_point.point(ctx, farthest) > 0.5)
    near = _side_scene(tmp_path / "near", -1024.0)
    nref = _reference(near)
    extra, _ = moved_point.moved_point_tolerance(nref, spec, {"info": {}}, attrs) or (None, "")
    assert extra is not None
    hit = nref.buffers["id.prim"] != cases.BACKGROUND_ID
    b = nref.buffers["RGB"].astype(np.float64)
    nattrs = {"rgb_scale": float(b.max()) * pb.EXPOSURE_MARGIN, "rgb_encoding": "png8-gamma2.2"}
    code = np.asarray(spec.rgb_tolerance(b, nattrs, {}).abs_tol)
    assert np.all(extra[hit] < code[hit])


# --------------------------------------------------------------------------- Mitsuba's shadow-ray offset


def test_mitsubas_shadow_offset_is_ray_epsilon_times_one_plus_the_largest_coordinate() -> None:
    got = mb.mitsuba_shadow_offset(np.array([[1024.5, -1024.0, 1025.0], [0.0, 0.0, 0.0]]))
    assert got[0] == pytest.approx(1026.0 * 1500.0 * U * (1.0 + 4.0 * U), rel=1e-15)
    assert got[1] == pytest.approx(1500.0 * U * (1.0 + 4.0 * U), rel=1e-15)
    assert _spec("mitsuba").shadow_ray_offset is mb.mitsuba_shadow_offset
    assert _spec("povray").shadow_ray_offset is None


def _wall_scene(directory: Path) -> resolved.ResolvedScene:
    """A floor at y = 0 and a wall x = 0 from y = 0 to 1 (z in [-2, 2]) under a light travelling along +x
    and down at 45 degrees: the wall's top edge casts the shadow's edge at x = 1 on the floor."""
    floor = [
        [[-3.0, 0.0, -3.0], [3.0, 0.0, 3.0], [3.0, 0.0, -3.0]],
        [[-3.0, 0.0, -3.0], [-3.0, 0.0, 3.0], [3.0, 0.0, 3.0]],
    ]
    wall = [[[0.0, 0.0, -2.0], [0.0, 1.0, -2.0], [0.0, 1.0, 2.0]], [[0.0, 0.0, -2.0], [0.0, 1.0, 2.0], [0.0, 0.0, 2.0]]]
    write_scene(
        directory,
        floor + wall,
        eye=(1.0, 3.0, 0.01),
        look_at=(1.0, 0.0, 0.0),
        vfov_deg=20.0,
        width=8,
        height=8,
        requires=("depth", "ids", "lambert", "directional_light", "shadows", "two_sided"),
        materials=[{"name": "m0", "albedo": [0.5, 0.5, 0.5], "emission": [0.0, 0.0, 0.0]}],
        lights=[{"kind": "directional", "direction": [1.0, -1.0, 0.0], "irradiance": [1.0, 1.0, 1.0]}],
    )
    return resolved.load(directory)


@pytest.mark.parametrize(("gap", "ambiguous"), [(0.99, True), (1.1, False)])
def test_a_shadow_ray_within_the_backends_offset_of_an_occluders_edge_is_a_shadow_edge(
    tmp_path: Path, gap: float, ambiguous: bool
) -> None:
    """A floor point at x = 1 - s (in the shadow) has its shadow ray pass the wall's top edge at a
    distance s / sqrt(2). With an offset a and s / sqrt(2) = 0.99 a it is a shadow edge (the offset ray
    may pass above the wall); at 1.1 a (beyond a / cos(pi/8) = 1.082 a) it is not; the contract's own
    band (1e-3 of the scene size, 0.0085 here) classifies neither."""
    scene = _wall_scene(tmp_path / "wall")
    offset = 0.05
    s = gap * offset * math.sqrt(2.0)
    cam = scene.camera
    # The floor point and the pixel that sees it: move the eye so that its center ray meets (1 - s, 0, 0).
    point = np.array([1.0 - s, 0.0, 0.0])
    rows, cols = np.array([3]), np.array([3])
    d = cam.center_directions(rows, cols)[0]
    z = float(-cam.eye[1] / d[1])
    shift = point - (cam.eye + z * d)
    scene = dataclasses.replace(scene, camera=dataclasses.replace(cam, eye=cam.eye + shift))
    prim = np.full((cam.height, cam.width), cases.BACKGROUND_ID, dtype=np.uint32)
    zbuf = np.full((cam.height, cam.width), np.inf, dtype=np.float32)
    prim[3, 3], zbuf[3, 3] = 0, z
    eps = 1e-3 * lighting.scene_size(scene)
    assert eps < offset * 0.2
    plain = lighting.shadow_ambiguity(scene, prim, zbuf, rows, cols, eps)
    got = lighting.shadow_ambiguity(scene, prim, zbuf, rows, cols, eps, ray_offset=lambda x: np.full(len(x), offset))
    assert plain is not None and got is not None
    assert not plain[0]
    assert bool(got[0]) is ambiguous


@needs_mitsuba
def test_mitsuba_lights_the_floor_under_a_far_shadow_edge_within_its_offset(tmp_path: Path) -> None:
    """The found shadow finding, on a wall: 1024 from the origin Mitsuba raises its shadow rays by 0.092, so
    floor points whose shadow ray meets the wall less than that below its top edge are lit; with its
    offset counted they are shadow edges, without it interior failures. At the origin (offset 9e-5)
    every pixel agrees."""
    spec = _spec("mitsuba")
    counts = {}
    for name, shift in (("far", 1024.0), ("origin", 0.0)):
        base = _wall_scene(tmp_path / name)
        cam = base.camera
        moved = dataclasses.replace(
            base,
            triangles=(base.triangles.astype(np.float64) + shift).astype(np.float32),
            camera=dataclasses.replace(cam, eye=cam.eye + shift, width=16, height=16),
        )
        ref = _reference(moved)
        rgb, _, _ = mb.render_radiance(moved)
        test = {"RGB": rgb.astype(np.float32)}
        old = compare_rgb(
            ref, test, {}, "mitsuba", {"info": {}}, None, dataclasses.replace(spec, shadow_ray_offset=None)
        )
        new = compare_rgb(ref, test, {}, "mitsuba", {"info": {}}, None, spec)
        counts[name] = (old.interior, new.interior, new.edge)
    assert counts["far"][0] >= 1 and counts["far"][1] == 0 and counts["far"][2] >= counts["far"][0]
    assert counts["origin"][:2] == (0, 0)
