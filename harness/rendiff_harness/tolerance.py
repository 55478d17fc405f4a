"""Per-backend precision models: how far a renderer may legitimately differ from the reference.

Two numbers per backend, both derived from what the renderer computes in
(docs/external-renderers.md, docs/DESIGN.md "Comparing"):

* `edge_px`: an ID mismatch is an *edge* mismatch when the pixel center lies within
  this many pixels of an edge of one of the triangles involved (classify.py). Inside
  that band the renderer's own rounding may put the center on either side.
* `depth(ctx)`: the allowed |Z_test - Z_reference| per compared pixel, plus a sentence
  saying how it was derived (it goes into results.json as `tolerance`).

Depth is compared only where both sides see the same triangle, so `ctx.cos` (|cos| of
the angle between the pixel ray and that triangle's normal) is known. A ray-plane
intersection whose plane is perturbed by a relative eps moves t by about
eps * t / |cos|: at grazing angles the same vertex rounding costs more depth. Every
relative model below therefore scales with 1/|cos|, capped at MAX_REL (1e-3) so that a
triangle seen exactly edge-on does not make the tolerance infinite.

Backends without a model here are compared exactly (`edge_px = 0`, depth tolerance 0),
and the tolerance text says so: a new backend fails loudly until its model is written.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

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


@dataclass(frozen=True)
class EdgeContext:
    """What an edge model may look at, for the K mismatched pixels (classify's `eps`)."""

    z: np.ndarray  # (K,) planar depth at the pixel (the reference's, else the test's; inf: none)
    point_norm: np.ndarray  # (K,) |X| of that point from the world origin
    pixel_size: float  # one pixel on the image plane at distance 1
    origin_offset: float  # |f32(eye) - eye|
    eye_norm: float = 0.0  # |eye|


DepthModel = Callable[[DepthContext], tuple[np.ndarray, str]]
EdgeModel = Callable[[EdgeContext], tuple[np.ndarray, str]]
PositionError = Callable[[float, float, np.ndarray], np.ndarray]
"""(|f32(eye) - eye|, |eye|, |X| (K,)) -> how far the renderer's f32 arithmetic may move the
point X it renders relative to its camera, world units (K,)."""

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

    def eye_uncertainty(self, origin_offset: float, eye_norm: float, point_norm: np.ndarray) -> float:
        """World distance by which the renderer may see the eye moved relative to the geometry.

        The verifier calls an edge closed only if the eye is farther than this from both
        triangles' planes (verify.py): closer, either may turn edge-on and the edge become
        an outline for this renderer.
        """
        if self.position is None or point_norm.size == 0:
            return 0.0
        return float(np.max(self.position(origin_offset, eye_norm, point_norm), initial=0.0))

    def edge_text(self) -> str:
        return f"edge: pixel center within {self.edge_px:.3g} px of a triangle edge ({self.edge_reason})"

    def edge_eps(self, ctx: EdgeContext) -> tuple[np.ndarray, str]:
        """Per-pixel rounding distance (px) and the sentence that derives it."""
        base = np.full(ctx.z.shape, self.edge_px, dtype=np.float64)
        if self.edge_extra is None:
            return base, self.edge_text()
        extra, text = self.edge_extra(ctx)
        extra = np.where(np.isfinite(extra), extra, 0.0)
        return base + extra, f"{self.edge_text()} + {text}"


def _param(ctx: DepthContext, key: str) -> float | None:
    """A float parameter from the EXR attributes (they travel with the pixels), else from info."""
    for source in (ctx.attrs, ctx.info):
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


def relative_grazing(ctx: DepthContext, rel: float) -> np.ndarray:
    """|z| * min(rel / |cos|, MAX_REL), without dividing by zero."""
    tol: np.ndarray = np.abs(ctx.z_ref) * (rel / np.maximum(ctx.cos, rel / MAX_REL))
    return tol


def f32_origin(offset: float, eye_norm: float, point: np.ndarray) -> np.ndarray:
    """Rays that start at the f32-rounded eye (Embree: `org` is `eye.as_vec3()`): exactly that offset."""
    return np.full(point.shape, offset)


def f32_sensor(offset: float, eye_norm: float, point: np.ndarray) -> np.ndarray:
    """Mitsuba: the sensor's to_world is f32, so its origin is f32(eye), and each ray starts at
    to_world applied to a near-plane point, then moved by near * d, in f32: two more roundings
    of every coordinate of a point about |eye| from the origin (<= u |eye| each, sqrt(3) on
    the vector): offset + 2 sqrt(3) u |eye|."""
    return np.full(point.shape, offset + 2.0 * math.sqrt(3.0) * F32_U * eye_norm)


def f32_view_transform(offset: float, eye_norm: float, point: np.ndarray) -> np.ndarray:
    """GL (pyrender): the vertex shader takes each vertex X to eye space with an f32 4x4 view
    matrix (unit rotation rows, translation about |eye|): each component is a 4-term dot
    product, off by <= 4u (|X| + |eye|) (gamma_4), sqrt(3) of that on the vector."""
    tol: np.ndarray = 4.0 * math.sqrt(3.0) * F32_U * (np.abs(point) + eye_norm)
    return tol


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


def shift_edge(moved: np.ndarray, ctx: EdgeContext) -> np.ndarray:
    """A point moved by `moved` at depth z moves by moved / (z pixel) px on the image."""
    with np.errstate(all="ignore"):
        px = moved / (np.abs(ctx.z) * ctx.pixel_size)
    return np.where(np.isfinite(px), px, 0.0)


def position_edge(position: PositionError, text: str) -> EdgeModel:
    """An edge model from a backend's position error."""

    def edge(ctx: EdgeContext) -> tuple[np.ndarray, str]:
        moved = position(ctx.origin_offset, ctx.eye_norm, ctx.point_norm)
        return shift_edge(moved, ctx), f"{text} / (z * pixel)"

    return edge


def _position(ctx: DepthContext, position: PositionError) -> np.ndarray:
    point = ctx.point_norm if ctx.point_norm is not None else np.abs(ctx.z_ref) + ctx.eye_norm
    return position(ctx.origin_offset, ctx.eye_norm, point)


# --------------------------------------------------------------------------- models


def exact_depth(ctx: DepthContext) -> tuple[np.ndarray, str]:
    """The rendiff loops share one depth function (docs/DESIGN.md): equal inputs give equal bits."""
    return np.zeros_like(ctx.z_ref), "exact: Z must be bit-identical (one shared depth function)"


def povray_plane_error(point_norm: np.ndarray, extent: np.ndarray | float = 0.0) -> np.ndarray:
    """Offset e of POV-Ray's mesh2 plane from the true one at a point X, world units.

    POV-Ray keeps each mesh triangle's unit normal n and plane offset d = n.P1 in single
    precision (`SnglVector3d` normals, `SNGL Distance`; source/core/shape/mesh.h) and
    intersects with t = (d - n.O) / (n.D) in double. Rounding n to f32 moves each
    component by <= u|n_i| (u = 2^-24), so n.X moves by <= u|X| (Cauchy-Schwarz, |n| = 1);
    rounding d moves it by <= u|d| <= u|X - P1| + u|X|. Whether d is computed from the
    rounded or the unrounded normal, the plane's offset at X is within
    u (|X| + |P1|) + u|X| <= u (3|X| + extent), with extent >= |X - P1| the triangle's
    longest edge. It grows with the distance from the origin, not with depth.
    """
    error: np.ndarray = F32_U * (3.0 * np.abs(point_norm) + extent)
    return error


def povray_depth(ctx: DepthContext) -> tuple[np.ndarray, str]:
    """POV-Ray: 32-bit fixed point, single-precision plane offsets, two f32 roundings.

    The depth pass encodes planar depth as 32-bit fixed point split over two 16-bit PNG
    channels; one step is R / (65536 * 65535) ~ R / 2^32 (`depth_step`, written by the
    backend into info and the EXR attributes). The plane's offset error e at the hit point
    (`povray_plane_error`) moves the hit along the ray by e / |cos|, and planar depth by
    at most that (D.f <= |D|), and never beyond the triangle's own depth span (the hit
    stays on it; `shift_depth`). Both sides' Z are stored as f32: 2 x 2^-24 |Z|. When
    `depth_step` is missing it is derived as R / 2^32 with R = `depth_range` if present,
    else from the reference's largest depth times the backend's margin 1+2^-6.
    """
    step = _param(ctx, "depth_step")
    source = "depth_step from the render"
    if step is None:
        r = _param(ctx, "depth_range")
        source = "R/2^32 with R = depth_range from the render"
        if r is None:
            zmax = float(np.max(np.abs(ctx.z_ref))) if ctx.z_ref.size else 1.0
            r = zmax * (1.0 + 2.0**-6)
            source = "R/2^32 with R estimated from the reference's largest depth (render gave no depth_step)"
        step = r / 65536.0 / 65535.0
    point = ctx.point_norm if ctx.point_norm is not None else np.abs(ctx.z_ref)
    extent = ctx.extent if ctx.extent is not None else 0.0
    plane = povray_plane_error(point, extent)
    slope = shift_depth(ctx, plane)
    tol = step + slope + 2.0 * F32_U * np.abs(ctx.z_ref)
    text = (
        f"povray: |dZ| <= depth_step ({step:.3g}, {source}; 32-bit fixed point) "
        "+ min(e / |cos|, the triangle's depth span), e = 2^-24 (3|X| + extent) "
        "(mesh2 keeps plane normal and offset in f32; "
        "|X| = hit point's distance from the origin) + 2^-23 Z (both sides stored as f32)"
    )
    return tol, text


def povray_edge(ctx: EdgeContext) -> tuple[np.ndarray, str]:
    """POV-Ray's inside test runs on the hit point, which its f32 plane moves along the ray.

    A hit moved by e / |cos| along the ray lands up to e / |cos| off the plane; its
    dominant-axis projection then shifts sideways by at most sqrt(3) e / |cos| x |cos|
    = sqrt(3) e, which a point at depth z sees as sqrt(3) e / (z pixel) px.
    """
    e = povray_plane_error(ctx.point_norm)
    with np.errstate(all="ignore"):
        px = np.sqrt(3.0) * e / (np.abs(ctx.z) * ctx.pixel_size)
    return np.where(np.isfinite(px), px, 0.0), "sqrt(3) 2^-24 3|X| / (z pixel) (f32 plane offset moves the hit)"


def pyrender_depth(ctx: DepthContext) -> tuple[np.ndarray, str]:
    """pyrender: the backend's own 24-bit depth-buffer model at the GL planes it chose.

    GL stores window depth in 24 bits; its resolution at depth z is
    z^2 (f-n)/(f n) 2^-24 for GL planes n, f. The backend picks n, f per scene and writes
    them as `znear`/`zfar` (info and EXR attributes); its `depth_tolerance(z, n, f)`
    (4 steps + 1 f32 ulp, measured) is used as is. Without the planes the tolerance is
    unknown (the scene's own near would be far too loose), so the comparison errors.
    """
    znear, zfar = _param(ctx, "znear"), _param(ctx, "zfar")
    if znear is None or zfar is None or not (0.0 < znear < zfar):
        raise ToleranceError(
            "pyrender render gives no valid GL planes (znear/zfar in its info or EXR attributes "
            f"rendiff:znear/rendiff:zfar; got znear={znear}, zfar={zfar}): depth tolerance unknown"
        )
    try:
        from .backends.pyrender_backend import depth_tolerance
    except ImportError as exc:  # pragma: no cover - the module imports only numpy at top level
        raise ToleranceError(f"cannot import pyrender_backend.depth_tolerance: {exc}") from None
    tol = np.asarray(depth_tolerance(ctx.z_ref, znear, zfar), dtype=np.float64)
    # Slope term: llvmpipe snaps vertices to a 1/256 px grid (GL subpixel precision), which
    # moves the triangle's plane sideways by up to sqrt(2)/256 px. Depth then changes by the
    # plane's screen-space slope times that shift; on a plane z(sx) with unit normal n,
    # |dz/dsx| = z |n.r| / |n.d| <= z / |cos| per image-plane unit, i.e. z * pixel_size / |cos|
    # per pixel. Capped like the other grazing-angle models.
    snap = np.sqrt(2.0) / 256.0
    slope = np.abs(ctx.z_ref) * np.minimum(ctx.pixel_size * snap / np.maximum(ctx.cos, 1e-300), MAX_REL)
    tol = tol + slope + shift_depth(ctx, _position(ctx, f32_view_transform))
    text = (
        f"pyrender: |dZ| <= pyrender_backend.depth_tolerance(z, znear={znear:.6g}, zfar={zfar:.6g}) "
        "(4 steps of the 24-bit GL depth buffer z^2(f-n)/(f n)2^-24 + 1 f32 ulp) "
        f"+ Z*min(pixel {ctx.pixel_size:.3g} * sqrt(2)/256 / |cos|, {MAX_REL:g}) (1/256 px vertex snapping) "
        "+ min(4 sqrt(3) 2^-24 (|X| + |eye|) / |cos|, depth span) (f32 view transform of the vertices)"
    )
    return tol, text


MITSUBA_REL = 1e-5


def mitsuba_depth(ctx: DepthContext) -> tuple[np.ndarray, str]:
    """Mitsuba 3 (scalar_rgb / llvm): float32 ray tracing.

    Rays start on the near plane in f32, the intersection is f32 and the depth AOV is
    converted back to planar depth (Z = t/|d| + near). Measured relative error <= 6e-7
    facing the camera; the f32 ray-triangle t loses more at grazing angles (Embree,
    same arithmetic: 9e-6). Relative 1e-5 / |cos|, capped at 1e-3.
    """
    tol = relative_grazing(ctx, MITSUBA_REL) + shift_depth(ctx, _position(ctx, f32_sensor))
    return tol, (
        f"mitsuba: |dZ| <= Z*min({MITSUBA_REL:g}/|cos|, {MAX_REL:g}) (float32 ray tracing) "
        f"+ min(o / |cos|, depth span), o = |f32(eye) - eye| ({ctx.origin_offset:.3g}) + 2 sqrt(3) 2^-24 |eye| "
        "(f32 sensor transform)"
    )


EMBREE_REL = 1e-5


def embree_depth(ctx: DepthContext) -> tuple[np.ndarray, str]:
    """Embree 3: float32 watertight/Moeller intersection.

    Measured t on the same triangle: mean relative difference 2e-8, max 9e-6 at grazing
    angles (notes, "Agreement"). Relative 1e-5 / |cos|, capped at 1e-3.
    """
    tol = relative_grazing(ctx, EMBREE_REL) + shift_depth(ctx, _position(ctx, f32_origin))
    return tol, (
        f"embree: |dZ| <= Z*min({EMBREE_REL:g}/|cos|, {MAX_REL:g}) (float32 ray tracing) "
        f"+ min(|f32(eye) - eye| ({ctx.origin_offset:.3g}) / |cos|, depth span) (rays start at the f32 eye)"
    )


# llvmpipe snaps vertices to a 1/256 px grid (8 subpixel bits); rounding to nearest moves
# each coordinate by <= 2^-9 px, so a vertex moves by <= sqrt(2) * 2^-9 px. A point of an
# edge is a convex combination of its endpoints, so the edge moves by no more than that.
# Pixel centers (k + 0.5) lie on the grid, so the fixed-point edge function itself is exact:
# only centers within this distance of the true edge can change side.
PYRENDER_EDGE_PX = math.sqrt(2.0) * 2.0**-9  # 2.76e-3 px; measured max 2.1e-3 px

MODELS: dict[str, Model] = {
    "trace": Model(
        "trace",
        0.0,
        "the rendiff tracer shares the coverage predicate with raster: must be identical",
        exact_depth,
    ),
    "raster": Model(
        "raster",
        0.0,
        "the rendiff rasterizer shares the coverage predicate with trace: must be identical",
        exact_depth,
    ),
    "povray": Model(
        "povray",
        1e-3,
        "POV-Ray mesh2 stores f32 vertices and picks its own tie winners for centers on edges; "
        "measured differences lie within ~1e-6 of an edge",
        povray_depth,
        edge_extra=povray_edge,
        position=lambda offset, eye, point: povray_plane_error(point),
    ),
    "pyrender": Model(
        "pyrender",
        PYRENDER_EDGE_PX,
        "GL fixed-point rasterization: llvmpipe snaps vertices to 1/256 px, moving an edge by "
        "<= sqrt(2)*2^-9 px; measured max 2.1e-3 px",
        pyrender_depth,
        edge_extra=position_edge(f32_view_transform, "4 sqrt(3) 2^-24 (|X| + |eye|) (f32 view transform)"),
        position=f32_view_transform,
    ),
    "mitsuba": Model(
        "mitsuba",
        1e-4,
        "float32 ray-triangle tests decide centers within f32 rounding of an edge",
        mitsuba_depth,
        edge_extra=position_edge(f32_sensor, "(|f32(eye) - eye| + 2 sqrt(3) 2^-24 |eye|) (f32 sensor transform)"),
        position=f32_sensor,
    ),
    "embree": Model(
        "embree",
        1e-4,
        "float32 ray-triangle tests: measured ID differences within 1e-4 of shared edges",
        embree_depth,
        edge_extra=position_edge(f32_origin, "|f32(eye) - eye| (rays start at the f32 eye)"),
        position=f32_origin,
    ),
    "embree_robust": Model(
        "embree_robust",
        1e-4,
        "float32 watertight ray-triangle tests (ROBUST): measured ID differences within 1e-4 of shared edges",
        embree_depth,
        edge_extra=position_edge(f32_origin, "|f32(eye) - eye| (rays start at the f32 eye)"),
        position=f32_origin,
    ),
}


def model_for(backend: str) -> Model:
    """The precision model of `backend`; unknown backends get a strict, exact one."""
    model = MODELS.get(backend)
    if model is not None:
        return model

    def strict(ctx: DepthContext) -> tuple[np.ndarray, str]:
        tol, _ = exact_depth(ctx)
        return tol, f"exact: no precision model for backend {backend!r} in tolerance.py"

    return Model(backend, 0.0, f"no precision model for backend {backend!r} in tolerance.py", strict, known=False)


# --------------------------------------------------------------------------- normals (N)

CORE_NORMAL_BACKENDS = frozenset({"raster", "trace", "embree", "embree_robust"})
"""Backends whose N is the core's `geometric_normal` of the prim they hit (frame.rs)."""


def normal_tolerance(backend: str, cond: np.ndarray) -> tuple[np.ndarray, str]:
    """Allowed angle (radians) between a backend's N and normalize((b - a) x (c - a)).

    `cond` = |e1| |e2| / |e1 x e2| >= 1 per pixel (1 / sin of the triangle's angle at a:
    large for slivers). The core (and Embree, whose buffers the core fills from its hit
    keys) takes the cross product in f64 from the f32 vertices and rounds the unit vector
    to f32: each component moves by <= u = 2^-24 of its size, the vector by <= sqrt(3) u,
    and with the f64 terms 4u bounds the angle. A renderer that works in f32 (Mitsuba's
    `geo_normal`) rounds the edges (<= u |e| each: 2u |e1||e2| on the cross product), each
    cross component (two products and a difference: 3u |e1||e2|, sqrt(3) of that on the
    vector) and normalizes and stores (about 3u + sqrt(3) u): angle <= 8u cond + 6u.
    """
    if backend in CORE_NORMAL_BACKENDS:
        tol = np.full(cond.shape, 4.0 * F32_U)
        return tol, "angle <= 4 * 2^-24 (f64 cross product of the f32 vertices, unit vector rounded to f32)"
    tol = 8.0 * F32_U * cond + 6.0 * F32_U
    return tol, (
        "angle <= 8 * 2^-24 * |e1||e2|/|e1 x e2| + 6 * 2^-24 (cross product, normalization and storage in f32; "
        "slivers amplify the cross product's rounding)"
    )


# --------------------------------------------------------------------------- radiance (RGB)


@dataclass(frozen=True)
class RgbTolerance:
    """Deterministic RGB tolerance: |a - b| <= abs_tol(b) + rel * |b| per channel."""

    abs_tol: np.ndarray | float  # scalar or (H, W, 3), evaluated at the reference values
    rel: float
    text: str


POVRAY_RGB_REL = 1e-5
PYRENDER_RGB_REL = 1e-5
PYRENDER_CODE_SLACK = 0.01
MITSUBA_RGB_REL = 5e-5
MITSUBA_RGB_ABS_REL_TO_MAX = 1e-6
F32_RGB_REL = 4 * 2.0**-24


def _scale(attrs: Mapping[str, Any], info: Mapping[str, Any], key: str) -> float | None:
    ctx = DepthContext(z_ref=np.zeros(0), cos=np.zeros(0), info=info, attrs=attrs)
    v = _param(ctx, key)
    if v is None:
        radiance = info.get("radiance") if isinstance(info, Mapping) else None
        if isinstance(radiance, Mapping):
            v = _param(DepthContext(np.zeros(0), np.zeros(0), radiance, {}), key)
    return v


def povray_rgb(ref: np.ndarray, attrs: Mapping[str, Any], info: Mapping[str, Any]) -> RgbTolerance:
    """POV-Ray: two 16-bit linear passes, L = S k/65535 + S_e k_e/65535 (backends/povray.py).

    Each pass rounds to the nearest code (measured: max 0.502 codes on a point-lit plane,
    the excess being POV-Ray's float32 colour arithmetic), so abs = (S + S_e)/65535/2;
    rel 1e-5 covers the float32 arithmetic (measured 3e-8) and both sides' f32 storage.
    """
    s = _scale(attrs, info, "rgb_scale")
    se = _scale(attrs, info, "emission_scale")
    if s is None or se is None:
        raise ToleranceError(
            "povray render gives no exposure scales (rendiff:rgb_scale / rendiff:emission_scale): RGB tolerance unknown"
        )
    abs_tol = (s + se) / 65535.0 / 2.0
    text = (
        f"povray: |dL| <= (S {s:.6g} + S_e {se:.6g})/65535/2 = {abs_tol:.3g} (half a code of each 16-bit linear pass) "
        f"+ {POVRAY_RGB_REL:g}*|L| (float32 colour arithmetic)"
    )
    return RgbTolerance(abs_tol, POVRAY_RGB_REL, text)


def pyrender_rgb(ref: np.ndarray, attrs: Mapping[str, Any], info: Mapping[str, Any]) -> RgbTolerance:
    """pyrender: 8-bit (L/S)^(1/2.2) from rendiff's Lambert shader (backends/pyrender_backend.py).

    GL rounds to the nearest code (measured: max 0.49997 codes), so at the reference value
    b, with c = 255 (b/S)^(1/2.2), the decoded value may be off by
    S (((c + 0.5 + 0.01)/255)^2.2 - (c/255)^2.2): half a code through the inverse transfer
    (the larger, upper side), plus 0.01 code for the shader's float32 arithmetic at a
    rounding boundary; plus rel 1e-5.
    """
    s = _scale(attrs, info, "rgb_scale")
    if s is None:
        raise ToleranceError("pyrender render gives no exposure scale (rendiff:rgb_scale): RGB tolerance unknown")
    gamma = 2.2
    b = np.clip(np.abs(np.asarray(ref, dtype=np.float64)) / s if s > 0 else np.zeros_like(ref), 0.0, 1.0)
    c = 255.0 * b ** (1.0 / gamma)
    hi = np.minimum((c + 0.5 + PYRENDER_CODE_SLACK) / 255.0, 1.0)
    abs_tol = s * (hi**gamma - (c / 255.0) ** gamma)
    text = (
        f"pyrender: |dL| <= S*(((c+0.5+{PYRENDER_CODE_SLACK:g})/255)^2.2 - (c/255)^2.2), c = 255 (L/S)^(1/2.2), "
        f"S {s:.6g} (half an 8-bit code through the inverse gamma-2.2 transfer at the reference's value; "
        f"+{PYRENDER_CODE_SLACK:g} code for float32 shading) + {PYRENDER_RGB_REL:g}*|L|"
    )
    return RgbTolerance(abs_tol, PYRENDER_RGB_REL, text)


def mitsuba_rgb(ref: np.ndarray, attrs: Mapping[str, Any], info: Mapping[str, Any]) -> RgbTolerance:
    """Mitsuba `direct` at pixel centers, float32 throughout.

    Measured against the float64 closed form on a lit plane: 5e-8 relative (directional)
    and up to 1e-5 (point lights: f32 hit position, r^2 and cos). rel 5e-5, plus
    1e-6 x the image's largest value for cancellation in cos at grazing light.
    """
    top = float(np.max(np.abs(ref), initial=0.0)) if np.size(ref) else 0.0
    abs_tol = MITSUBA_RGB_ABS_REL_TO_MAX * top
    text = (
        f"mitsuba: |dL| <= {MITSUBA_RGB_ABS_REL_TO_MAX:g}*max|L| ({abs_tol:.3g}) + {MITSUBA_RGB_REL:g}*|L| "
        "(float32 ray tracing and shading; measured <= 1e-5 relative)"
    )
    return RgbTolerance(abs_tol, MITSUBA_RGB_REL, text)


def exact_rgb(ref: np.ndarray, attrs: Mapping[str, Any], info: Mapping[str, Any]) -> RgbTolerance:
    return RgbTolerance(0.0, 0.0, "exact: the rendiff loops share visibility and shading code")


def f32_rgb(ref: np.ndarray, attrs: Mapping[str, Any], info: Mapping[str, Any]) -> RgbTolerance:
    return RgbTolerance(0.0, F32_RGB_REL, f"float32: |dL| <= {F32_RGB_REL:.3g}*|L| (4 ulps)")


RGB_MODELS: dict[str, Callable[[np.ndarray, Mapping[str, Any], Mapping[str, Any]], RgbTolerance]] = {
    "raster": exact_rgb,
    "trace": exact_rgb,
    "povray": povray_rgb,
    "pyrender": pyrender_rgb,
    "mitsuba": mitsuba_rgb,
}


def rgb_model(backend: str, ref: np.ndarray, attrs: Mapping[str, Any], info: Mapping[str, Any]) -> RgbTolerance:
    """Deterministic RGB tolerance of `backend` at the reference values `ref` (H, W, 3).

    Unknown backends: f32 output at 4 ulps when the EXR says rgb_encoding = float32, else
    exact, and the text says there is no model (so a new backend fails loudly).
    """
    model = RGB_MODELS.get(backend)
    if model is not None:
        return model(ref, attrs, info)
    enc = attrs.get("rgb_encoding") if isinstance(attrs, Mapping) else None
    if enc == "float32":
        t = f32_rgb(ref, attrs, info)
        return RgbTolerance(t.abs_tol, t.rel, t.text + f" (no RGB model for {backend!r}; its EXR says float32)")
    return RgbTolerance(0.0, 0.0, f"exact: no RGB precision model for backend {backend!r} in tolerance.py")
