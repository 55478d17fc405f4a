"""The shared precision machinery (judge/tolerance.py) at its boundaries: every cap, every
fallback and every derived constant, from both sides (issue 37 item 6, docs/mutation.md).

The expected values are the formulas the module documents (u = 2^-24, MAX_REL, |dZ| = moved / |cos|
capped by the depth span, moved / (z pixel) on the image), evaluated here on chosen inputs.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from rendiff_harness.judge import tolerance as tl

U = 2.0**-24


def _ctx(z: list[float], cos: list[float], **kw: Any) -> tl.DepthContext:
    kw.setdefault("info", {})
    kw.setdefault("attrs", {})
    return tl.DepthContext(z_ref=np.array(z, dtype=np.float64), cos=np.array(cos, dtype=np.float64), **kw)


def test_the_constants_are_the_documented_ones() -> None:
    assert tl.F32_U == U and tl.MAX_REL == 1e-3 and tl.F32_RGB_REL == 4 * 2.0**-24


# --------------------------------------------------------------------------- depth helpers


def test_relative_grazing_grows_as_one_over_cos_until_the_cap() -> None:
    rel = 1e-5
    # cos at which rel / cos reaches MAX_REL: rel / MAX_REL = 0.01.
    c = rel / tl.MAX_REL
    got = tl.relative_grazing(_ctx([-8.0, 8.0, 8.0, 8.0], [1.0, 0.5, c, 0.0]), rel)
    assert got[:3].tolist() == [8.0 * rel, 8.0 * rel / 0.5, 8.0 * rel / c]
    # at and beyond the cap: MAX_REL of the depth (to the rounding of rel / (rel / MAX_REL))
    assert got[2:].tolist() == pytest.approx([8.0 * tl.MAX_REL] * 2, rel=1e-15)


def test_shift_depth_is_moved_over_cos_capped_by_the_span() -> None:
    moved = np.array([1e-3, 1e-3, 1e-3, 1e-3])
    span = np.array([1.0, 1e-4, 1e-4, 1.0])
    ctx = _ctx([5.0] * 4, [0.5, 0.5, 1e-6, 0.0], depth_span=span)
    got = tl.shift_depth(ctx, moved)
    # 2e-3 under a span of 1; capped at the span 1e-4, never below `moved` itself (1e-3);
    # edge-on (cos 0): moved / 1e-300 is huge, capped at the span 1.
    assert got.tolist() == [2e-3, 1e-3, 1e-3, 1.0]


def test_shift_depth_without_a_span_caps_at_max_rel_of_depth() -> None:
    ctx = _ctx([-5.0, 5.0, 5.0], [0.0, 0.5, 1e-9])
    got = tl.shift_depth(ctx, np.array([1e-6, 1e-6, 1e-9]))
    # edge-on: capped at MAX_REL * |z|; 2e-6 below the cap; cos 1e-9 would give 1, capped too
    assert got.tolist() == [5.0 * tl.MAX_REL, 2e-6, 5.0 * tl.MAX_REL]
    # a move larger than the cap is the floor of the cap
    assert tl.shift_depth(_ctx([5.0], [0.0]), np.array([1.0])).tolist() == [1.0]
    # a move so large that dividing by the floor of |cos| overflows: capped, quietly
    assert tl.shift_depth(_ctx([5.0], [0.0]), np.array([1e10])).tolist() == [1e10]
    # non-finite results (an infinite depth) count as nothing rather than poisoning the tolerance
    assert tl.shift_depth(_ctx([math.inf], [0.5]), np.array([math.inf])).tolist() == [0.0]


def test_shift_edge_is_moved_times_off_axis_over_the_moved_depth_times_pixel() -> None:
    # sqrt(1 + |q|^2) |d| / ((z - |d|) pixel): on the axis, 45 degrees off it, with the point able
    # to reach the eye (z <= |d|: unbounded) and with no depth (no term)
    ctx = tl.EdgeContext(
        z=np.array([-5.0, 5.0, 1.0, 0.0, math.inf]),
        point_norm=np.zeros(5),
        pixel_size=0.125,
        origin_offset=0.0,
        off_axis=np.array([1.0, math.sqrt(2.0), 1.0, 1.0, 1.0]),
    )
    got = tl.shift_edge(np.full(5, 1.0), ctx)
    assert got.tolist() == [2.0, math.sqrt(2.0) * 2.0, math.inf, math.inf, 0.0]
    # just past the eye's reach the shift is finite, at it unbounded
    near = tl.EdgeContext(
        z=np.array([float(np.nextafter(1.0, 2.0)), 1.0]),
        point_norm=np.zeros(2),
        pixel_size=1.0,
        origin_offset=0.0,
        off_axis=np.ones(2),
    )
    far_side, at = tl.shift_edge(np.ones(2), near).tolist()
    assert math.isfinite(far_side) and at == math.inf
    # a caller that leaves the off-axis factor out is refused, not given the on-axis value
    with pytest.raises(tl.ToleranceError, match="off-axis"):
        bare = tl.EdgeContext(z=np.ones(1), point_norm=np.zeros(1), pixel_size=1.0, origin_offset=0.0)
        tl.shift_edge(np.ones(1), bare)


def test_position_helpers() -> None:
    assert tl.f32_origin(0.25, 9.0, np.zeros(3)).tolist() == [0.25, 0.25, 0.25]
    seen: list[tuple[float, float, list[float]]] = []

    def pos(offset: float, eye: float, point: np.ndarray) -> np.ndarray:
        seen.append((offset, eye, point.tolist()))
        return offset + eye * point

    ectx = tl.EdgeContext(
        z=np.array([20.0]),
        point_norm=np.array([3.0]),
        pixel_size=0.5,
        origin_offset=0.5,
        eye_norm=2.0,
        off_axis=np.array([2.0]),
    )
    px, text = tl.position_edge(pos, "T")(ectx)
    moved = 0.5 + 2.0 * 3.0
    assert px.tolist() == [2.0 * moved / ((20.0 - moved) * 0.5)]
    assert text == "T * sqrt(1 + |q|^2) / ((z - moved) * pixel)"
    assert seen[-1] == (0.5, 2.0, [3.0])
    # |X| unknown: estimated as |z| + |eye|
    ctx = _ctx([-3.0], [1.0], origin_offset=0.5, eye_norm=2.0)
    assert tl.position_error(ctx, pos).tolist() == [0.5 + 2.0 * 5.0]
    ctx = _ctx([3.0], [1.0], origin_offset=0.5, eye_norm=2.0, point_norm=np.array([7.0]))
    assert tl.position_error(ctx, pos).tolist() == [0.5 + 2.0 * 7.0]


# --------------------------------------------------------------------------- Model


def _model(**kw: Any) -> tl.Model:
    return tl.Model("b", 0.25, "why", tl.exact_depth, **kw)


def test_edge_eps_adds_the_extra_keeps_its_infinities_and_drops_its_nans() -> None:
    ctx = tl.EdgeContext(z=np.array([1.0, 2.0, 3.0]), point_norm=np.zeros(3), pixel_size=1.0, origin_offset=0.0)
    eps, text = _model().edge_eps(ctx)
    assert eps.tolist() == [0.25] * 3
    assert text == "edge: pixel center within 0.25 px of a triangle edge (why)" == _model().edge_text()

    def extra(c: tl.EdgeContext) -> tuple[np.ndarray, str]:
        return np.array([0.5, math.inf, math.nan]), "X"

    eps, text = _model(edge_extra=extra).edge_eps(ctx)
    # NaN: no term at that pixel; +inf: rounding may carry the point past the eye, anything goes
    assert eps.tolist() == [0.75, math.inf, 0.25]
    assert text == "edge: pixel center within 0.25 px of a triangle edge (why) + X"


def test_eye_uncertainty_is_the_largest_position_error() -> None:
    def pos(offset: float, eye: float, point: np.ndarray) -> np.ndarray:
        return offset + eye * point

    m = _model(position=pos)
    assert m.eye_uncertainty(0.5, 2.0, np.array([1.0, 3.0, 2.0])) == 6.5
    assert m.eye_uncertainty(0.5, 2.0, np.zeros(0)) == 0.0
    assert m.eye_uncertainty(0.5, 2.0, np.array([1.0])) == 2.5
    assert _model().eye_uncertainty(0.5, 2.0, np.array([1.0])) == 0.0
    neg = _model(position=lambda o, e, p: -np.ones_like(p))
    assert neg.eye_uncertainty(0.0, 0.0, np.array([1.0])) == 0.0  # max(..., initial=0)


def test_embree_adds_room_for_its_f32_ray_origin() -> None:
    """Its intersection's relative term, plus the shift of rays starting at the f32-rounded eye."""
    base = tl.embree_depth(_ctx([5.0], [1.0], ray_norm=1.0))[0]
    moved = tl.embree_depth(_ctx([5.0], [1.0], origin_offset=1e-3, depth_span=np.array([1.0]), ray_norm=1.0))[0]
    assert base[0] > 0.0 and moved[0] > base[0]


def test_embree_adds_its_f32_ray_direction_as_a_moved_point() -> None:
    """The f32 direction moves the point at depth Z by u |d| Z: over |cos|, capped by the span.
    Found by the fuzzer (seed 7, s7_01212): an eye 6.2e-5 from a triangle's plane, |cos| 1.18e-5,
    Embree's Z 5.123518 against 5.118345; rounding the direction alone moves the hit by 0.00224."""
    z, cos, d = 5.118345, 1.18e-5, 1.0000137
    rel = tl.relative_grazing(_ctx([z], [cos]), tl.EMBREE_REL)[0]
    big = np.array([10.0])
    tol = tl.embree_depth(_ctx([z], [cos], depth_span=big, ray_norm=np.array([d])))[0][0]
    # u |d| Z for the direction, as much again for the triangle's copy at the origin (its vertex
    # |v0 - org| <= |d| Z; no extent given, so no edge term)
    assert tol - rel == pytest.approx(2.0 * U * d * z / cos, rel=1e-12)
    assert tol > abs(5.123518 - z)  # the finding is inside it
    assert rel < abs(5.123518 - z)  # and was outside it without these terms
    # Capped by the triangle's depth span (a hit stays on its triangle), not by 1/|cos|.
    small = tl.embree_depth(_ctx([z], [cos], depth_span=np.array([1e-3]), ray_norm=np.array([d])))[0][0]
    assert small - rel == pytest.approx(1e-3, rel=1e-12)
    # The longer the pixel ray, the larger the move.
    wide = tl.embree_depth(_ctx([z], [cos], depth_span=big, ray_norm=np.array([1.5])))[0][0]
    assert wide - rel == pytest.approx(2.0 * U * 1.5 * z / cos, rel=1e-12)
    with pytest.raises(tl.ToleranceError, match="ray_norm"):
        tl.embree_depth(_ctx([z], [cos], depth_span=big))


def test_embree_counts_its_f32_copy_of_the_triangle_at_the_ray_origin() -> None:
    """Both Embree tests intersect the triangle moved to the (f32) ray origin in f32: its vertices
    move by u (|v0 - org| + E), |v0 - org| <= |d| Z + |f32(eye) - eye| + E. A huge triangle near
    the eye (E = 1e4 at Z = 1) moves its plane by about 2 u E, far beyond the measured 1e-5 Z."""
    z, e, off = 1.0, 1e4, 1e-6
    span = np.array([1e6])
    ctx = _ctx([z], [1.0], depth_span=span, ray_norm=1.0, extent=np.array([e]), origin_offset=off)
    tol = tl.embree_depth(ctx)[0][0]
    rel = tl.relative_grazing(ctx, tl.EMBREE_REL)[0]
    origin = off  # the f32 origin's own shift of the ray (f32_origin), at |cos| = 1
    assert tol - rel - origin == pytest.approx(U * (2.0 * z + off + 2.0 * e), rel=1e-9)
    assert tol > 2.0 * U * e > 100.0 * rel
    # Seen at |cos| = 0.5 the move doubles; a span of 1e-3 caps it.
    half = tl.embree_depth(replace(ctx, cos=np.array([0.5])))[0][0]
    assert half - tl.relative_grazing(replace(ctx, cos=np.array([0.5])), tl.EMBREE_REL)[0] == pytest.approx(
        2.0 * (origin + U * (2.0 * z + off + 2.0 * e)), rel=1e-9
    )
    # At |cos| = 0.01 a span of 1e-4 caps it, never below the move itself (shift_depth).
    grazing = replace(ctx, cos=np.array([0.01]), depth_span=np.array([1e-4]))
    capped = tl.embree_depth(grazing)[0][0] - tl.relative_grazing(grazing, tl.EMBREE_REL)[0]
    assert capped == pytest.approx(1e-4 + U * (2.0 * z + off + 2.0 * e), rel=1e-9)  # origin: off / 0.01


def test_exact_and_strict_models() -> None:
    tol, text = tl.exact_depth(_ctx([3.0, 4.0], [1.0, 1.0]))
    assert tol.tolist() == [0.0, 0.0] and text.startswith("exact: Z must be bit-identical")
    m = tl.strict_model("nova")
    assert (m.backend, m.edge_px, m.known) == ("nova", 0.0, False)
    assert m.edge_reason == "no precision model for backend 'nova' in the registry (renderers/registry.py)"
    tol, text = m.depth(_ctx([3.0], [1.0]))
    assert tol.tolist() == [0.0]
    assert text == "exact: no precision model for backend 'nova' in the registry (renderers/registry.py)"
    assert tl.Model("x", 0.0, "", tl.exact_depth).known


# --------------------------------------------------------------------------- render parameters


def test_render_param_prefers_attributes_and_accepts_only_finite_numbers() -> None:
    assert tl.render_param({"k": 2}, {"k": 3.0}, "k") == 2.0
    assert tl.render_param({}, {"k": 3.0}, "k") == 3.0
    assert tl.render_param({"k": "1.5"}, {}, "k") == 1.5
    assert tl.render_param({"k": True}, {"k": 4}, "k") == 4.0  # a bool is no number
    assert tl.render_param({"k": "nan"}, {"k": "2"}, "k") == 2.0
    assert tl.render_param({"k": math.inf}, {"k": "x"}, "k") is None
    assert tl.render_param({"k": "abc"}, {"k": [1]}, "k") is None
    assert tl.render_param({"k": "abc"}, {"k": 3}, "k") == 3.0
    assert tl.render_param({}, {}, "k") is None
    assert tl.param(_ctx([1.0], [1.0], attrs={"a": "7"}, info={"a": 8}), "a") == 7.0
    assert tl.param(_ctx([1.0], [1.0], info={"a": 8}), "a") == 8.0


def test_exposure_scale_falls_back_to_the_radiance_block() -> None:
    assert tl.exposure_scale({"s": 2.0}, {"s": 3.0, "radiance": {"s": 4.0}}, "s") == 2.0
    assert tl.exposure_scale({}, {"radiance": {"s": 4.0}}, "s") == 4.0
    assert tl.exposure_scale({}, {"radiance": 5}, "s") is None
    assert tl.exposure_scale({}, {}, "s") is None


# --------------------------------------------------------------------------- normals and RGB


def test_normal_models() -> None:
    cond = np.array([1.0, 16.0])
    tol, text = tl.core_normals(cond)
    assert tol.tolist() == [4 * U, 4 * U] and text.startswith("angle <= 4 * 2^-24")
    tol, text = tl.f32_normals(cond)
    assert tol.tolist() == [8 * U + 6 * U, 8 * U * 16.0 + 6 * U]
    assert text == (
        "angle <= 8 * 2^-24 * |e1||e2|/|e1 x e2| + 6 * 2^-24 (cross product, normalization and storage in f32; "
        "slivers amplify the cross product's rounding)"
    )


def test_rgb_models() -> None:
    t = tl.exact_rgb(np.zeros(1), {}, {})
    assert (t.abs_tol, t.rel) == (0.0, 0.0) and t.text.startswith("exact")
    t = tl.f32_rgb(np.zeros(1), {}, {})
    assert (t.abs_tol, t.rel, t.text) == (0.0, 4 * U, "float32: |dL| <= 2.38e-07*|L| (4 ulps)")
    t = tl.rgb_fallback("nova", {"rgb_encoding": "float32"})
    assert (t.abs_tol, t.rel) == (0.0, 4 * U)
    assert t.text == "float32: |dL| <= 2.38e-07*|L| (4 ulps) (no RGB model for 'nova'; its EXR says float32)"
    t = tl.rgb_fallback("nova", ["rgb_encoding"])  # type: ignore[arg-type]  # attributes unreadable
    assert (t.abs_tol, t.rel) == (0.0, 0.0)
    t = tl.rgb_fallback("nova", {"rgb_encoding": "half"})
    assert (t.abs_tol, t.rel) == (0.0, 0.0)
    assert t.text == "exact: no RGB precision model for backend 'nova' in the registry (renderers/registry.py)"
