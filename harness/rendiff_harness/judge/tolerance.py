"""Per-backend precision models: how far a renderer may legitimately differ from the reference.

Two numbers per backend, both derived from what the renderer computes in
(docs/external-renderers.md, docs/DESIGN.md "Comparing"):

* `edge_px`: an ID mismatch is an *edge* mismatch when the pixel center lies within
  this many pixels of an edge of one of the triangles involved (geometry.py). Inside
  that band the renderer's own rounding may put the center on either side.
* `depth(ctx)`: the allowed |Z_test - Z_reference| per compared pixel, plus a sentence
  saying how it was derived (it goes into results.json as `tolerance`).

Depth is compared only where both sides see the same triangle, so `ctx.cos` (|cos| of
the angle between the pixel ray and that triangle's normal) is known. A ray-plane
intersection whose plane is perturbed by a relative eps moves t by about
eps * t / |cos|: at grazing angles the same vertex rounding costs more depth. Every
relative model below therefore scales with 1/|cos|, capped at MAX_REL (1e-3) so that a
triangle seen exactly edge-on does not make the tolerance infinite.

Where the models live: every backend's sits in its `BackendSpec` (renderers/spec.py), the
core's in renderers/core.py, each external backend's beside its exporter in its folder
(renderers/povray/backend.py, ...) with the derivations in their docstrings, a declared
renderer's built from the numbers it declares (renderers/command.py). This module holds the
shared machinery (the contexts, `Model`, `param`, the grazing and position-shift helpers and the
models several backends share); judge/precision.py finds a backend's through its spec, and a
backend without one is compared exactly (`strict_model`, `edge_px = 0`, depth tolerance 0), and
the tolerance text says so: a new backend fails loudly until its model is written.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import embree_products

MAX_REL = 1e-3
"""Cap on every relative depth tolerance (reached only within ~1/1000 of edge-on)."""


class ToleranceError(Exception):
    """A tolerance cannot be derived (e.g. the render lacks the parameters it depends on)."""


@dataclass(frozen=True)
class DepthContext:
    """What a depth model may look at, for the K compared pixels."""

    z_ref: np.ndarray  # (K,) float64 reference planar depth (finite, > 0 for visible hits)
    cos: np.ndarray  # (K,) float64 |cos| between the pixel ray and the triangle normal, in [0, 1]
    info: Mapping[str, Any]  # the render's `info` from manifest.json
    attrs: Mapping[str, Any]  # the test EXR's rendiff attributes (exrbuf.read_attrs)
    pixel_size: float = 0.0  # side of one pixel on the image plane at distance 1 (2 tan(vfov/2) / H)
    point_norm: np.ndarray | None = None  # (K,) |X|: distance of the hit point from the world origin
    extent: np.ndarray | None = None  # (K,) longest edge of the triangle seen
    origin_offset: float = 0.0  # |f32(eye) - eye|: how far an f32 camera origin moves the rays
    eye_norm: float = 0.0  # |eye|: distance of the eye from the world origin
    depth_span: np.ndarray | None = None  # (K,) max - min planar depth of the triangle's vertices
    # (K,) or a bound for all: |d| of the pixel ray d = (q, 1) in camera axes, sqrt(1 + |q|^2); how far
    # a rounded ray direction moves the point at depth Z is proportional to it (`embree_depth`)
    ray_norm: np.ndarray | float | None = None
    # (K,) 1/sin of the triangle's smallest angle (the largest |e_a| |e_b| / |e_a x e_b| over its corners):
    # how much an f32 cross product of two of its edges can be off relative to its length (`moeller_t_depth`)
    corner_cond: np.ndarray | None = None


@dataclass(frozen=True)
class EdgeContext:
    """What an edge model may look at, for the K mismatched pixels (the verifier's `eps`)."""

    z: np.ndarray  # (K,) planar depth at the pixel (the reference's, else the test's; inf: none)
    point_norm: np.ndarray  # (K,) |X| of that point from the world origin
    pixel_size: float  # one pixel on the image plane at distance 1
    origin_offset: float  # |f32(eye) - eye|
    eye_norm: float = 0.0  # |eye|
    # (K,) sqrt(1 + sx^2 + sy^2) of the pixel center (sx, sy on the image plane at distance 1): how
    # much more than |moved| / z a moved point's image may move off the optical axis (`shift_edge`)
    off_axis: np.ndarray | None = None
    # (K,) the triangles involved (the reference's and the test's prim at the pixel, either may be
    # background): their largest |v - eye| over the vertices, longest edge and largest height
    # (twice the area over the shortest edge); the Embree models round coordinates of that size
    vertex_distance: np.ndarray | None = None
    extent: np.ndarray | None = None
    height: np.ndarray | None = None
    attrs: Mapping[str, Any] = field(default_factory=dict)  # the test EXR's rendiff attributes


DepthModel = Callable[[DepthContext], tuple[np.ndarray, str]]
EdgeModel = Callable[[EdgeContext], tuple[np.ndarray, str]]
PositionError = Callable[[float, float, np.ndarray], np.ndarray]
"""(|f32(eye) - eye|, |eye|, |X| (K,)) -> how far the renderer's f32 arithmetic may move the
point X it renders relative to its camera, world units (K,)."""
EdgeProducts = Callable[[np.ndarray, np.ndarray, np.ndarray, float], np.ndarray]
"""(triangles (M, 3, 3) world f64, the f32 ray origin (3,), pixel ray directions (M, 3) in world axes
with forward component 1, pixel size) -> (M, 3) px that a renderer's per-edge arithmetic adds to
`Model.edge_eps` on edge j (corner j to j + 1) at that pixel; inf where unbounded. Per edge because it
grows without bound for an edge that points at the eye (judge/embree_products.py)."""
PlaneMove = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""(triangles (M, 3, 3) world f64, the f32 ray origin (3,)) -> (M,) world distance by which the renderer's
copy of each triangle may lie off it: the crack test adds it to the eye's uncertainty for that triangle."""
Placement = Callable[[Mapping[str, Any]], float]
"""A render's EXR attributes -> the world distance by which it placed every vertex away from the
resolved scene's (`Model.placement`)."""

F32_U = 2.0**-24
"""Unit roundoff of f32: rounding to nearest moves a value by at most this times its size."""


@dataclass(frozen=True)
class Model:
    backend: str
    edge_px: float
    edge_reason: str
    depth: DepthModel
    known: bool = True  # False: a strict fallback for a backend without a model
    edge_extra: EdgeModel | None = None  # per-pixel growth of edge_px (f32 camera origin, plane offsets)
    position: PositionError | None = None  # how far f32 arithmetic moves a point relative to the camera
    edge_products: EdgeProducts | None = None  # per-edge growth of the edge band (verify.py takes it per edge)
    plane_move: PlaneMove | None = None  # per-triangle growth of `eye_uncertainty` (the crack test's)
    placement: Placement | None = None
    """How far the renderer itself placed every vertex from the resolved scene's, read from its
    render: a renderer that loads the user's mesh file and applies the objects' transforms in its
    own arithmetic (renderers/mitsuba_file). Edges and the eye's uncertainty add it here; its depth
    model adds it itself (`shift_depth`)."""

    def eye_uncertainty(
        self, origin_offset: float, eye_norm: float, point_norm: np.ndarray, attrs: Mapping[str, Any] | None = None
    ) -> float:
        """World distance by which the renderer may see the eye moved relative to the geometry.

        The verifier calls an edge closed only if the eye is farther than this from both
        triangles' planes (verify.py): closer, either may turn edge-on and the edge become
        an outline for this renderer.
        """
        placed = self.placement(attrs or {}) if self.placement is not None else 0.0
        if self.position is None or point_norm.size == 0:
            return placed
        return float(np.max(self.position(origin_offset, eye_norm, point_norm), initial=0.0)) + placed

    def edge_text(self) -> str:
        return f"edge: pixel center within {self.edge_px:.3g} px of a triangle edge ({self.edge_reason})"

    def edge_eps(self, ctx: EdgeContext) -> tuple[np.ndarray, str]:
        """Per-pixel rounding distance (px) and the sentence that derives it."""
        base = np.full(ctx.z.shape, self.edge_px, dtype=np.float64)
        text = self.edge_text()
        if self.edge_extra is not None:
            extra, extra_text = self.edge_extra(ctx)
            # NaN: no term at that pixel; +inf (rounding may carry the point past the eye) stays
            base = base + np.where(np.isnan(extra), 0.0, extra)
            text = f"{text} + {extra_text}"
        if self.edge_products is not None:
            text = f"{text} + per edge: the rounding of its edge functions' products (judge/embree_products.py)"
        if self.placement is not None:
            placed = self.placement(ctx.attrs)
            base = base + shift_edge(np.full(ctx.z.shape, placed), ctx)
            text = f"{text} + vertex placement {placed:.3g} * sqrt(1 + |q|^2) / ((z - placed) * pixel)"
        return base, text


def render_param(attrs: Mapping[str, Any], info: Mapping[str, Any], key: str) -> float | None:
    """A finite float parameter of a render: from its EXR attributes (they travel with the pixels),
    else from its info; a number or a numeric string, never a bool."""
    for source in (attrs, info):
        value = source.get(key)
        if isinstance(value, bool):
            continue
        if isinstance(value, (int, float)) and math.isfinite(float(value)):
            return float(value)
        if isinstance(value, str):
            try:
                f = float(value)
            except ValueError:
                continue
            if math.isfinite(f):
                return f
    return None


def param(ctx: DepthContext, key: str) -> float | None:
    """`render_param` of the render a depth model is judging."""
    return render_param(ctx.attrs, ctx.info, key)


def relative_grazing(ctx: DepthContext, rel: float) -> np.ndarray:
    """|z| * min(rel / |cos|, MAX_REL), without dividing by zero."""
    tol: np.ndarray = np.abs(ctx.z_ref) * (rel / np.maximum(ctx.cos, rel / MAX_REL))
    return tol


def f32_origin(offset: float, eye_norm: float, point: np.ndarray) -> np.ndarray:
    """Rays that start at the f32-rounded eye (Embree: `org` is `eye.as_vec3()`): exactly that offset."""
    return np.full(point.shape, offset)


def shift_depth(ctx: DepthContext, moved: np.ndarray) -> np.ndarray:
    """|dZ| from a point moved by `moved` relative to the camera: moved / |cos| along the plane.

    A hit on the same triangle stays inside it, so the change is also at most the triangle's
    planar-depth span (when known); that bounds edge-on triangles without a fitted cap.
    """
    with np.errstate(all="ignore"):
        d = moved / np.maximum(ctx.cos, 1e-300)
    if ctx.depth_span is not None:
        d = np.minimum(d, np.maximum(ctx.depth_span, moved))
    else:
        d = np.minimum(d, np.maximum(MAX_REL * np.abs(ctx.z_ref), moved))
    return np.where(np.isfinite(d), d, 0.0)


def off_axis(ctx: EdgeContext) -> np.ndarray:
    """`ctx.off_axis`, which every image-plane shift needs; a caller that leaves it out is refused."""
    if ctx.off_axis is None:
        raise ToleranceError("an edge model needs each pixel center's off-axis factor (EdgeContext.off_axis)")
    return ctx.off_axis


def shift_edge(moved: np.ndarray, ctx: EdgeContext) -> np.ndarray:
    """How far (px) the image of a point at planar depth z moves when the point moves by `moved`.

    In camera coordinates a point (x, y, z) is seen at q = (x, y) / z. Moved by d it is seen at
    (x + dx, y + dy) / (z + dz), so q moves by exactly ((dx, dy) - q dz) / (z + dz). The 2x3 map
    d -> (dx, dy) - q dz has norm sqrt(1 + |q|^2) (its Gram matrix has eigenvalues 1 and
    1 + |q|^2), and |dz| <= |d|: the shift is at most sqrt(1 + |q|^2) |d| / (z - |d|) on the image
    plane at distance 1, over `pixel_size` in px. Off the axis (|q| is tan of the angle off
    the axis) that is up to 1.4 times moved / z at a 45-degree corner. Where the point could reach
    the eye (z <= |d|) the shift is unbounded (inf); where z is unknown (inf) there is no term (0).
    """
    z = np.abs(ctx.z)
    with np.errstate(all="ignore"):
        px = off_axis(ctx) * moved / ((z - moved) * ctx.pixel_size)
    px = np.where(z - moved > 0, px, np.inf)
    return np.where(np.isfinite(z), np.where(np.isnan(px), 0.0, px), 0.0)


def position_edge(position: PositionError, text: str) -> EdgeModel:
    """An edge model from a backend's position error."""

    def edge(ctx: EdgeContext) -> tuple[np.ndarray, str]:
        moved = position(ctx.origin_offset, ctx.eye_norm, ctx.point_norm)
        return shift_edge(moved, ctx), f"{text} * sqrt(1 + |q|^2) / ((z - moved) * pixel)"

    return edge


def position_error(ctx: DepthContext, position: PositionError) -> np.ndarray:
    """A backend's position error at the compared pixels' points (|X| estimated when unknown)."""
    point = ctx.point_norm if ctx.point_norm is not None else np.abs(ctx.z_ref) + ctx.eye_norm
    return position(ctx.origin_offset, ctx.eye_norm, point)


# --------------------------------------------------------------------------- models


def exact_depth(ctx: DepthContext) -> tuple[np.ndarray, str]:
    """The rendiff loops share one depth function (docs/DESIGN.md): equal inputs give equal bits."""
    return np.zeros_like(ctx.z_ref), "exact: Z must be bit-identical (one shared depth function)"


EMBREE_REL = 1e-5


def embree_direction_depth(ctx: DepthContext) -> np.ndarray:
    """|dZ| from Embree's f32 ray direction and its f32 copy of the triangle (docs/verifier.md,
    "Embree's arithmetic"): `f32_ray_depth` with the direction rounded once, fl(D) within u |D| of D
    (u = 2^-24 per coordinate), and the ray from f32(eye)."""
    return f32_ray_depth(ctx, 1.0, ctx.origin_offset)


def f32_ray_depth(ctx: DepthContext, direction_roundings: float, origin: np.ndarray | float) -> np.ndarray:
    """|dZ| from an f32 ray direction off by `direction_roundings` u |D| and Embree's f32 copy of the
    triangle at a ray origin `origin` from the eye, one move of the hit relative to the plane,
    `shift_depth` of it away (1/|cos|, at most the triangle's depth span):

    * the point at planar depth Z along the rounded ray is within direction_roundings u |D| Z of the
      exact ray's point;
    * both of Embree's tests intersect the triangle moved to the ray origin in f32 (Moeller: C = fl(v0 - org)
      and the stored edges fl(v0 - v1), fl(v2 - v0); ROBUST: fl(v - org) and edges of those), whose
      vertices, and so its plane at every point of it, are off by <= u (|v0 - org| + longest edge),
      and |v0 - org| <= |X - eye| + origin + longest edge with |X - eye| = |D| Z.

    A caller without each pixel's |D| is refused; without the triangle's extent (the triangle is
    unknown, and the models fall back to their 1/|cos| cap) the edges are not counted."""
    if ctx.ray_norm is None:
        raise ToleranceError("the Embree depth model needs each pixel ray's length (DepthContext.ray_norm)")
    along = ctx.ray_norm * np.abs(ctx.z_ref)
    edges = 0.0 if ctx.extent is None else 2.0 * ctx.extent
    return shift_depth(ctx, F32_U * (direction_roundings * along + along + origin + edges))


MOELLER_DOT = 5.0 * F32_U / (1.0 - 5.0 * F32_U) * math.sqrt(2.0)
"""gamma_5 sqrt(2): an f32 dot product of a vector with an f32 cross product, `dot(cross(a, b), c)`, errs by at
most this times |a| |b| |c| (the cross product's components <= gamma_2 (|a_y b_z| + |a_z b_y|) each, sqrt(2) |a| |b|
on the vector, the dot <= gamma_3 of its terms; Embree's common/math/vec3.h, docs/verifier.md)."""

MOELLER_DIVIDE = 4.0 * F32_U
"""t = T * rcp(den): the reciprocal (refined by a Newton step) and the product, at most 4 u relative."""


MOELLER_TEXT = (
    "(eps Z + gamma5 sqrt(2) cond (|d| Z + |f32(eye) - eye| + longest edge) / |cos|) / (1 - eps) + 4 2^-24 Z, "
    "eps = gamma5 sqrt(2) cond / |cos|, cond = 1/sin of the triangle's smallest angle (f32 t = T / den, uncapped)"
)
"""The tolerance text of `moeller_t_depth`."""


def moeller_t_depth(ctx: DepthContext) -> np.ndarray:
    """|dZ| from the f32 arithmetic of t = T / den in Embree's triangle tests (docs/verifier.md, "Depth"):
    den = dot(Ng, D) and T = dot(Ng, C), Ng the f32 cross product of two edges of the triangle, C its vertex
    relative to the ray origin (Moeller; Pluecker's stable normal and moved vertex have the same form).

    * den errs by <= MOELLER_DOT |e_a| |e_b| |D| and |den| = |D| |e_a x e_b| |cos|: relative
      eps_den = MOELLER_DOT * cond / |cos| (cond = 1/sin of the angle between the two edges, at most
      `corner_cond`);
    * T errs by <= MOELLER_DOT |e_a| |e_b| |C|: divided by |den|, a move of t (along D, |D| >= 1, so of Z at
      most as much) of MOELLER_DOT * cond * |C| / |cos|, with |C| <= |X - org| + E <= |D| Z + offset + E;
    * so |dZ| <= (eps_den Z + MOELLER_DOT cond (|D| Z + offset + E) / |cos|) / (1 - eps_den) + MOELLER_DIVIDE Z.

    Unlike the measured 1e-5 / |cos| it is not capped: near edge-on the arithmetic itself is off by that much
    (the fuzzer's `s13_02458`: Mitsuba, whose CPU variants intersect through Embree's default test, was off by
    1.02 u cond / |cos| of Z, three times the measured cap). Where eps_den >= 1 the sign of den, and so t, is not
    bounded: the tolerance is infinite there (the ray runs along the plane within rounding). Without the
    triangle (no `corner_cond` or `extent`) or the pixel's |D|, nothing is added: the models keep their cap."""
    z = np.abs(ctx.z_ref)
    if ctx.corner_cond is None or ctx.extent is None or ctx.ray_norm is None:
        return np.zeros_like(z)
    reach = ctx.ray_norm * z + ctx.origin_offset + ctx.extent
    with np.errstate(all="ignore"):
        per_cos = MOELLER_DOT * ctx.corner_cond / ctx.cos
        eps_den = per_cos
        tol = (eps_den * z + per_cos * reach) / (1.0 - eps_den) + MOELLER_DIVIDE * z
    tol = np.where(np.isfinite(tol) & (eps_den < 1.0), tol, np.inf)
    result: np.ndarray = tol
    return result


def embree_depth(ctx: DepthContext) -> tuple[np.ndarray, str]:
    """Embree 3: float32 watertight/Moeller intersection.

    Measured t on the same triangle: mean relative difference 2e-8, max 9e-6 at grazing
    angles (notes, "Agreement"). Relative 1e-5 / |cos|, capped at 1e-3; plus the moves of the
    ray it is given and of its copy of the triangle, derived: its f32 origin, its f32 direction
    and the triangle's vertices moved to that origin in f32.
    """
    tol = (
        relative_grazing(ctx, EMBREE_REL)
        + moeller_t_depth(ctx)
        + shift_depth(ctx, position_error(ctx, f32_origin))
        + embree_direction_depth(ctx)
    )
    return tol, (
        f"embree: |dZ| <= Z*min({EMBREE_REL:g}/|cos|, {MAX_REL:g}) (float32 ray tracing) + {MOELLER_TEXT} "
        f"+ min(|f32(eye) - eye| ({ctx.origin_offset:.3g}) / |cos|, depth span) (rays start at the f32 eye) "
        "+ min(2^-24 (2 |d| Z + |f32(eye) - eye| + 2 longest edge) / |cos|, depth span) "
        "(f32 ray direction; the triangle moved to the ray origin in f32)"
    )


EMBREE_ROBUST_EPS = 2.0**-23 * (1.0 + 2.0**-21)
"""Embree's ROBUST triangle test accepts a ray up to this fraction of U + V + W outside each edge:
`eps = float(ulp) * abs(UVW)` with `ulp` = FLT_EPSILON = 2^-23 (kernels/geometry/triangle_intersector_pluecker.h,
common/math/constants.h, Embree 3.13.5), computed in f32 from the sum: (1 + gamma3) < 1 + 2^-21 of itself
(the products' own errors in it are embree_products.MARGIN_ROUNDING's)."""


def embree_moved(ctx: EdgeContext, robust: bool) -> np.ndarray:
    """How far Embree's f32 arithmetic may move an edge relative to the ray origin, world units (K,).

    Embree 3.13.5's triangle tests (docs/verifier.md, "Embree's arithmetic", derives each term):

    * both: rays start at f32(eye): every point moves by `origin_offset` relative to the ray.
    * default (`Triangle4`, Moeller-Trumbore): the build stores v0, e1 = fl(v0 - v1),
      e2 = fl(v2 - v0); the test takes C = fl(v0 - org). So the triangle tested is
      (C, C - e1, C + e2) relative to org: rounding C moves it rigidly by <= u |v0 - org|, the
      edges move v1 and v2 by <= u |e| more: u (max |v - eye| + longest edge) with u = 2^-24.
    * ROBUST (`Triangle4v`, Pluecker): each vertex is moved to the origin, v' = fl(v - org)
      (<= u |v - org|), then each edge function is D . (e x s) with e = fl(vj' - vi') and
      s = fl(vj' + vi'). (x - y) x (x + y) = 2 x x y for any x, y, so the computed e and s are
      exactly the edge of the endpoints x = (e + s) / 2, y = (s - e) / 2, each within
      u max(|vi'_c|, |vj'_c|) per coordinate of vj', vi': <= sqrt(2) u (1 + u) max |v - org|.
      And the test accepts U >= -eps with eps = 2^-23 |U + V + W|, i.e. barycentric >= -2^-23:
      each edge moved out, in the triangle's plane, by 2^-23 times the height over it (at most the
      triangle's largest height).

    An edge point is a convex combination of its endpoints, so it moves no more than they do.
    """
    for name in ("vertex_distance", "extent", "height"):
        if getattr(ctx, name) is None:
            raise ToleranceError(f"the Embree edge model needs the triangles involved (EdgeContext.{name})")
    far = np.asarray(ctx.vertex_distance, dtype=np.float64) + ctx.origin_offset  # |v - org| <= |v - eye| + offset
    if robust:
        return (
            ctx.origin_offset
            + F32_U * far
            + math.sqrt(2.0) * F32_U * (1.0 + F32_U) * far
            + EMBREE_ROBUST_EPS * np.asarray(ctx.height, dtype=np.float64)
        )
    return ctx.origin_offset + F32_U * (far + np.asarray(ctx.extent, dtype=np.float64))


def embree_direction_px(ctx: EdgeContext) -> np.ndarray:
    """The f32 ray direction (px): D32 = fl(D) moves D by <= u |D|, and D = (q, 1) in camera axes,
    so the ray crosses the image plane at distance 1 moved by <= sqrt(1 + |q|^2) u |D| / (1 - u)
    = u (1 + |q|^2) / (1 - u) (the map of `shift_edge`)."""
    q2 = off_axis(ctx) ** 2
    px: np.ndarray = F32_U * q2 / ((1.0 - F32_U) * ctx.pixel_size)
    return px


def embree_edge(robust: bool) -> EdgeModel:
    """Embree's per-pixel edge rounding distance: `embree_moved` seen from the pixel (`shift_edge`), plus
    the f32 direction (`embree_direction_px`). The edge functions' own products are bounded per edge
    (`Model.edge_products`, judge/embree_products.py), since they grow without bound for an edge that
    points at the eye."""

    def edge(ctx: EdgeContext) -> tuple[np.ndarray, str]:
        px = shift_edge(embree_moved(ctx, robust), ctx) + embree_direction_px(ctx)
        moved = (
            "|f32(eye) - eye| + 2^-24 (1 + sqrt(2)) |v - org| + 2^-23 h (vertices moved to the f32 ray origin, "
            "edge and sum vectors rounded, the ROBUST test's 2^-23 (U + V + W) margin over the largest height h)"
            if robust
            else "|f32(eye) - eye| + 2^-24 (|v - org| + longest edge) (v0 moved to the f32 ray origin, "
            "edges stored in f32)"
        )
        return px, (
            f"({moved}) * sqrt(1 + |q|^2) / ((z - moved) * pixel) + 2^-24 (1 + |q|^2) / pixel (f32 ray direction)"
        )

    return edge


def embree_edge_products(robust: bool) -> EdgeProducts:
    """Embree's edge functions' own f32 products, per edge (judge/embree_products.py)."""

    def products(tris: np.ndarray, origin: np.ndarray, d: np.ndarray, pixel: float) -> np.ndarray:
        return embree_products.product_px(tris, origin, d, pixel, robust)

    return products


def embree_plane_move(robust: bool) -> PlaneMove:
    """Embree's copy of each triangle at the ray origin, for the crack test (judge/embree_products.py)."""

    def plane(tris: np.ndarray, origin: np.ndarray) -> np.ndarray:
        return embree_products.plane_move(tris, origin, robust)

    return plane


def strict_model(backend: str) -> Model:
    """The model of a backend that has none: exact (`known` False), and the texts say so."""

    def strict(ctx: DepthContext) -> tuple[np.ndarray, str]:
        tol, _ = exact_depth(ctx)
        return tol, f"exact: no precision model for backend {backend!r} in the registry (renderers/registry.py)"

    return Model(
        backend,
        0.0,
        f"no precision model for backend {backend!r} in the registry (renderers/registry.py)",
        strict,
        known=False,
    )


# --------------------------------------------------------------------------- normals (N)

NormalModel = Callable[[np.ndarray], tuple[np.ndarray, str]]
"""cond = |e1| |e2| / |e1 x e2| >= 1 per pixel (K,) -> allowed angle (radians) between a backend's N
and normalize((b - a) x (c - a)) (K,), and the sentence that derives it."""


def core_normals(cond: np.ndarray) -> tuple[np.ndarray, str]:
    """The core's N (and Embree's, whose buffers the core fills from its hit keys): `geometric_normal`
    of the prim hit (frame.rs), the cross product taken in f64 from the f32 vertices and the unit
    vector rounded to f32: each component moves by <= u = 2^-24 of its size, the vector by
    <= sqrt(3) u, and with the f64 terms 4u bounds the angle."""
    tol = np.full(cond.shape, 4.0 * F32_U)
    return tol, "angle <= 4 * 2^-24 (f64 cross product of the f32 vertices, unit vector rounded to f32)"


def f32_normals(cond: np.ndarray) -> tuple[np.ndarray, str]:
    """A renderer that works in f32 (Mitsuba's `geo_normal`) rounds the edges (<= u |e| each:
    2u |e1||e2| on the cross product), each cross component (two products and a difference:
    3u |e1||e2|, sqrt(3) of that on the vector) and normalizes and stores (about 3u + sqrt(3) u):
    angle <= 8u cond + 6u (cond is large for slivers)."""
    tol = 8.0 * F32_U * cond + 6.0 * F32_U
    return tol, (
        "angle <= 8 * 2^-24 * |e1||e2|/|e1 x e2| + 6 * 2^-24 (cross product, normalization and storage in f32; "
        "slivers amplify the cross product's rounding)"
    )


# --------------------------------------------------------------------------- the shaded point's move (RGB)


MovedPoint = Callable[[DepthContext, np.ndarray], np.ndarray]
"""(the depth context of the pixels the reference hits, each one's triangle's farthest vertex from the
world origin max |v| (K,)) -> (K,) how far the backend's arithmetic may move the point it shades from the
reference's hit, world units (judge/moved_point.py adds the direct light's change over that move)."""


@dataclass(frozen=True)
class ShadingMove:
    """A backend's model of where it shades (`BackendSpec.rgb_moved_point`): its own move of the
    shading point, derived from its arithmetic in its backend module, and whether it rounds its
    point lights' positions to f32 (then each light moves by |f32(L) - L|, known exactly)."""

    point: MovedPoint
    text: str
    f32_lights: bool = False


def along_ray_move(ctx: DepthContext, m: np.ndarray) -> np.ndarray:
    """(K,) the move of a hit that stays on its exact pixel ray while the surface moves by `m` relative
    to it (POV-Ray's f32 plane): `shift_depth` bounds its planar depth's move (m/|cos|, at most the
    triangle's depth span) and along the ray d (unit planar depth) the point moves |d| times that.
    A caller without each pixel's |d| is refused (|d| >= 1 may not be guessed low)."""
    if ctx.ray_norm is None:
        raise ToleranceError("the moved shading point needs each pixel ray's length (DepthContext.ray_norm)")
    moved: np.ndarray = ctx.ray_norm * shift_depth(ctx, m)
    return moved


def in_plane_move(ctx: DepthContext, lateral: np.ndarray, extra: np.ndarray | float = 0.0) -> np.ndarray:
    """(K,) the move of a hit that stays in its triangle's plane when the ray (or the triangle) moves
    sideways by `lateral`, plus `extra` (a move the renderer makes in the plane), at most the triangle's
    longest edge (4 u over it for barycentrics rounded past 1).

    A ray moved by e = a n + b (n the plane's normal, b in the plane) meets the plane at
    b - a tan(theta) t from the old hit (t the unit in-plane direction of the ray), so
    |move| <= |b| + |a| tan <= |e| sqrt(1 + tan^2) = |e| / |cos| (Cauchy-Schwarz); a triangle moved by e
    against a fixed ray is the same. Both the reference's hit and the renderer's point lie in the
    triangle (an interior pixel of the same triangle), so no two are farther apart than its longest
    edge. Without the triangle's extent there is no cap."""
    with np.errstate(all="ignore"):
        move = lateral / np.maximum(ctx.cos, 0.0) + extra
    move = np.where(np.isnan(move), np.inf, move)  # 0 / 0 edge-on: unknown, so unbounded
    if ctx.extent is not None:
        move = np.minimum(move, (1.0 + 4.0 * F32_U) * ctx.extent)
    result: np.ndarray = move
    return result


def embree_barycentric_move(ctx: DepthContext, origin: np.ndarray) -> np.ndarray:
    """(K,) how far Embree's f32 barycentrics (u, v) of a hit may place the point (1 - u - v) v0 + u v1 + v v2
    from the exact barycentric point of its own f32 ray (origin off by `origin`), in the triangle's plane
    (docs/verifier.md, "Radiance: the moved shading point"): Moeller's u = U / den with U = dot(cross(C, D),
    e_b) errs by <= MOELLER_DOT |C| |D| |e_b| (as T does in `moeller_t_depth`) and den by eps |den|,
    eps = MOELLER_DOT cond / |cos|, |den| = |D| |e_a x e_b| |cos|. Times the edge |e_a| it multiplies:
    (MOELLER_DOT cond |C| / |cos| + |u| eps |e_a|) / (1 - eps), and rcp and product 2 u |u| |e_a|; the
    stored f32 edges e_a, e_b (<= u |e| each) move the point by |u| u |e_a| more. Over u and v, both in
    [0, 1] for an accepted hit: (2 MOELLER_DOT cond |C| / |cos| + 2 eps E) / (1 - eps) + 6 u E, with
    |C| <= |D| Z + origin + E. Infinite where eps >= 1; without the triangle, infinite."""
    z = np.abs(ctx.z_ref)
    if ctx.corner_cond is None or ctx.extent is None or ctx.ray_norm is None:
        return np.full(z.shape, np.inf)
    e = ctx.extent
    reach = ctx.ray_norm * z + origin + e
    with np.errstate(all="ignore"):
        eps = MOELLER_DOT * ctx.corner_cond / ctx.cos
        move = (2.0 * eps * reach + 2.0 * eps * e) / (1.0 - eps) + 6.0 * F32_U * e
    result: np.ndarray = np.where(np.isfinite(move) & (eps < 1.0), move, np.inf)
    return result


# --------------------------------------------------------------------------- radiance (RGB)


@dataclass(frozen=True)
class RgbTolerance:
    """Deterministic RGB tolerance: |a - b| <= abs_tol(b) + rel * |b| per channel."""

    abs_tol: np.ndarray | float  # scalar or (H, W, 3), evaluated at the reference values
    rel: float
    text: str


F32_RGB_REL = 4 * 2.0**-24


def exposure_scale(attrs: Mapping[str, Any], info: Mapping[str, Any], key: str) -> float | None:
    """An RGB exposure scale (e.g. `rgb_scale`) from the EXR attributes, else the info, else info's `radiance`."""
    v = render_param(attrs, info, key)
    if v is None:
        radiance = info.get("radiance") if isinstance(info, Mapping) else None
        if isinstance(radiance, Mapping):
            v = render_param({}, radiance, key)
    return v


def exact_rgb(ref: np.ndarray, attrs: Mapping[str, Any], info: Mapping[str, Any]) -> RgbTolerance:
    return RgbTolerance(0.0, 0.0, "exact: the rendiff loops share visibility and shading code")


def f32_rgb(ref: np.ndarray, attrs: Mapping[str, Any], info: Mapping[str, Any]) -> RgbTolerance:
    return RgbTolerance(0.0, F32_RGB_REL, f"float32: |dL| <= {F32_RGB_REL:.3g}*|L| (4 ulps)")


RgbModel = Callable[[np.ndarray, Mapping[str, Any], Mapping[str, Any]], RgbTolerance]
"""(reference values (H, W, 3), EXR attributes, render info) -> the deterministic RGB tolerance."""


def rgb_fallback(backend: str, attrs: Mapping[str, Any]) -> RgbTolerance:
    """The RGB tolerance of a backend without an RGB model: f32 output at 4 ulps when the EXR
    says rgb_encoding = float32, else exact, and the text says there is no model (so a new
    backend fails loudly)."""
    enc = attrs.get("rgb_encoding") if isinstance(attrs, Mapping) else None
    if enc == "float32":
        t = f32_rgb(np.zeros(0), attrs, {})
        return RgbTolerance(t.abs_tol, t.rel, t.text + f" (no RGB model for {backend!r}; its EXR says float32)")
    return RgbTolerance(
        0.0, 0.0, f"exact: no RGB precision model for backend {backend!r} in the registry (renderers/registry.py)"
    )
