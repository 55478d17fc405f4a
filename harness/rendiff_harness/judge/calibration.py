"""Camera calibration: where does each backend really sample its pixels? (docs/DESIGN.md "Comparing").

Entry point (the only one): `calibrate_run(run, manifest, scenes=None) -> CalibrationReport`.
It reads the probe scenes of a `rendiff check` run (manifest scenes with
`"role": "calibration"`, or the names given in `scenes`), measures every backend that
rendered a Z buffer of them (the reference included) and returns

* `report.entries`: results.json entries (`results.Entry`'s shape, buffer "camera"), one
  per (probe, backend), with the measured fields below;
* `report.summary`: `{backend: {...measured fields..., "status", "reason", "bound_px",
  "probes"}}` for results.json's top-level `calibration` key (the worst probe of each
  backend when there are several);
* `report.measurements`: the same as typed `Calibration` records.

How it measures (docs/calibration.md has the derivations)
---------------------------------------------------------
A probe scene shows planes tilted every way, none touching another or the image border.
On a plane with unit normal n through a point P, the planar depth Z along the
unnormalized ray d = f + sx r + sy u (docs/DESIGN.md) satisfies

    h / Z = n.d = n.f + (n.r) sx + (n.u) sy,        h = n.(P - eye),

so 1/Z is affine in the image-plane point (sx, sy) that was sampled. A backend that
samples elsewhere, with a camera of its own, casts d_b = G (1, sx, sy) in the (f, r, u)
basis (any pinhole camera at the eye reporting planar depth along its own axis), and
then h / Z_b = (n.f, n.r, n.u) G (1, sx, sy): linear in the nine entries of G. Every pixel
whose 3x3 neighbourhood shows one object (its own `id.prim`, so that a flipped image is
read correctly) gives one such equation, scaled so that its residual is in pixels; G is
fitted by least squares. G = identity is the convention. Writing G = k [[1, -t], [c, M]]:

* `offset_x_px`, `offset_y_px`: where the image center's sample lies, minus the
  convention (px, +x right, +y down): c / pixel;
* `scale_x`, `scale_y`: M's diagonal (1 = the convention's field of view; a field of view
  on the wrong axis shows as H/W on both; a y flip is scale_y = -1, a mirrored x
  (handedness) scale_x = -1), with `flipped_y`, `mirrored_x` as booleans;
* `rotation` (radians, counter-clockwise as seen in the image) and `shear`: M's
  antisymmetric and symmetric off-diagonal parts;
* `turn_x`, `turn_y`: t, how far the backend's view axis is turned (radians, towards
  right and up). A turned camera offsets the image center by t / pixel (and bends the
  rest slightly); a principal-point offset (half-pixel shifts) has t = 0;
* `depth_scale` (1/k: a depth scale is not read as a camera error), `rms_px` (fit
  residual), `pixels` used, `plane_mismatches` (pixels whose object differs from the
  reference's: the ID sanity check);
* `max_shift_px`: the largest displacement of the fitted camera at the image center and
  the four image corners; `bound_px`: what that may reach from the backend's own rounding.

The bound is derived, never fitted: each backend's model (its spec's `calibration`) bounds, per pixel, the
error its arithmetic can put into that pixel's equation (f32 depth storage, depth-buffer
quantization, f32 ray setup and camera transforms), and, per triangle vertex, how far its
plane may sit from the true one (f32 plane equations, f32 vertex transforms). Through the
least-squares solution P = pinv(A), each displacement D = L P e is then at most
sum_i |L P_i| b_i + sum over triangles and vertices of e_v |sum_{i in T} L P_i lambda_v(i) w_i|
(a plane offset is the barycentric blend of its vertices' offsets): the worst case, with no
assumption that roundings are independent (f32 rounding of a smooth depth is not: on the
probe, raster's Z rounding errors average to -0.036 ulp over 4212 pixels, 8 standard errors
from zero). bound_px is the largest of these over the image center and corners. The
residual is held to the per-pixel bounds themselves: rms_px <= rms(b) (a least-squares
residual is a projection of the errors, never longer than them).

Verdict: pass when max_shift_px <= bound_px and rms_px <= rms_bound_px; otherwise fail
with a reason naming the exporter's convention error, e.g. "convention error in the
mitsuba exporter: camera turned by (0.0004597, -0.0001798) rad off its view direction,
pixel centers offset by (0.03555, 0.01388) px (bound 0.001428 px)", "... y flipped (scale_y -1)",
"... vertical FOV scale 1.01x"; a failure's reason is led by the hypothesis it follows
(judge/hypotheses.py: planar, radial, window, NDC or reversed-Z depth; pixel-center offset,
field of view, aspect, handedness, y flip), every hypothesis's residual after it.
"""

from __future__ import annotations

import math
import sys
import traceback
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..contract import exrbuf, resolved
from ..contract.camera import Camera
from ..contract.manifest import EntryError, render_reason, run_path
from ..contract.results import Entry
from ..contract.vocab import BACKGROUND_ID, Buffer, RenderStatus, Status
from ..renderers.spec import SpecLookup
from . import hypotheses, precision
from .camera_budget import CalibrationError, ProbePixels

ROLE = "calibration"
"""`role` of a probe scene in manifest.json (docs/run-format.md)."""
BUFFER = "camera"
"""The results.json `buffer` of a calibration entry."""
NOT_JUDGED_FIELD = "not_judged"
"""The results.json field of an entry left unjudged because its backend's camera failed
calibration (value "calibration"): the report groups such entries under that one cause."""
MIN_PIXELS = 64
"""Fewer usable pixels than this cannot identify the nine entries of G with any precision."""
MAX_CONDITION = 1e8
"""A design matrix worse conditioned than this means the planes seen cannot separate the
parameters (too few plane orientations): the probe, not the backend, is at fault."""
FOV_AXIS_TOL = 1e-3
"""How close a scale must be to H/W (or W/H) to be named a field of view on the wrong axis."""
MEASURED_FIELDS = (
    "offset_x_px",
    "offset_y_px",
    "scale_x",
    "scale_y",
    "rotation",
    "shear",
    "turn_x",
    "turn_y",
    "depth_scale",
    "flipped_y",
    "mirrored_x",
    "rms_px",
    "rms_bound_px",
    "max_shift_px",
    "bound_px",
    "pixels",
    "plane_mismatches",
)


# --------------------------------------------------------------------------- the fit


@dataclass(frozen=True)
class Calibration:
    """One backend measured on one probe; numbers are None when it was not measured."""

    scene: str
    backend: str
    status: str  # pass | fail | skipped | error
    reason: str
    offset_x_px: float | None = None
    offset_y_px: float | None = None
    scale_x: float | None = None
    scale_y: float | None = None
    rotation: float | None = None
    shear: float | None = None
    turn_x: float | None = None
    turn_y: float | None = None
    depth_scale: float | None = None
    flipped_y: bool | None = None
    mirrored_x: bool | None = None
    rms_px: float | None = None
    rms_bound_px: float | None = None
    max_shift_px: float | None = None
    bound_px: float | None = None
    pixels: int = 0
    plane_mismatches: int | None = None
    bound_text: str = ""
    width: int = 0  # the probe's image size (what a scale or rotation does at the edges)
    height: int = 0
    pixel: float = 0.0  # one pixel on the image plane at distance 1
    owner: str = ""  # whose convention a failure blames (judge.precision.camera_owner)
    hypotheses: Mapping[str, Any] | None = None  # a failure's diagnosis (judge/hypotheses.py)
    render: Mapping[str, Any] = field(default_factory=dict, repr=False)

    def fields(self) -> dict[str, Any]:
        """The measured fields as JSON values (MEASURED_FIELDS)."""
        out: dict[str, Any] = {}
        for key in MEASURED_FIELDS:
            v = getattr(self, key)
            if isinstance(v, float) and not math.isfinite(v):
                v = None
            out[key] = v
        return out

    @property
    def ratio(self) -> float:
        """max_shift / bound: how close to (or beyond) its bound the backend is."""
        if self.max_shift_px is None or self.bound_px is None:
            return -1.0
        return self.max_shift_px / self.bound_px if self.bound_px > 0 else math.inf


@dataclass(frozen=True)
class CalibrationReport:
    """What `calibrate_run` returns: results.json entries, the `calibration` summary, the records."""

    entries: list[dict[str, Any]]
    summary: dict[str, dict[str, Any]]
    measurements: list[Calibration]


def _screen_points(cam: Camera) -> np.ndarray:
    """(5, 2) image-plane points where the displacement is judged: the center and the four corners."""
    a = cam.tan_half_vfov * cam.width / cam.height
    t = cam.tan_half_vfov
    return np.array([[0.0, 0.0], [-a, t], [a, t], [-a, -t], [a, -t]])


def _mapped(g: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(numerator x, numerator y, denominator) of the sampled point s' = (G_r v, G_u v) / G_f v, v = (1, s)."""
    v = np.concatenate([np.ones((s.shape[0], 1)), s], axis=1)
    return v @ g[1], v @ g[2], v @ g[0]


def _displacement(g: np.ndarray, s: np.ndarray, pixel: float) -> np.ndarray:
    """(P, 2) displacement in px (+x right, +y down) of the fitted camera at image-plane points s (P, 2)."""
    a, b, c = _mapped(g, s)
    return np.stack([(a / c - s[:, 0]) / pixel, -(b / c - s[:, 1]) / pixel], axis=1)


def _displacement_jacobian(g: np.ndarray, s: np.ndarray, pixel: float) -> np.ndarray:
    """(P, 2, 9) derivative of `_displacement` with respect to G's entries (row-major)."""
    a, b, c = _mapped(g, s)
    v = np.concatenate([np.ones((s.shape[0], 1)), s], axis=1)
    jac = np.zeros((s.shape[0], 2, 3, 3))
    jac[:, 0, 0] = -(a / c**2)[:, None] * v
    jac[:, 0, 1] = v / c[:, None]
    jac[:, 1, 0] = (b / c**2)[:, None] * v
    jac[:, 1, 2] = -v / c[:, None]
    return jac.reshape(s.shape[0], 2, 9) / pixel


def _planes(scene: resolved.ResolvedScene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(unit normals (N, 3), h = n.(a - eye) (N,), longest edge (N,)) of every triangle, float64."""
    t = scene.triangles.astype(np.float64)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    length = np.linalg.norm(n, axis=1)
    with np.errstate(all="ignore"):
        n = np.where(length[:, None] > 0, n / np.where(length > 0, length, 1.0)[:, None], 0.0)
    h = np.einsum("ij,ij->i", n, t[:, 0] - scene.camera.eye[None, :])
    edges = np.stack([t[:, 1] - t[:, 0], t[:, 2] - t[:, 1], t[:, 0] - t[:, 2]], axis=1)
    extent = np.linalg.norm(edges, axis=2).max(axis=1)
    return n, h, extent


def _barycentrics(tri: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(K, 3) barycentric coordinates of points x (K, 3) in the planes of triangles tri (K, 3, 3)."""
    e1, e2, q = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], x - tri[:, 0]
    d11, d12, d22 = (np.einsum("ij,ij->i", a, b) for a, b in ((e1, e1), (e1, e2), (e2, e2)))
    q1, q2 = np.einsum("ij,ij->i", q, e1), np.einsum("ij,ij->i", q, e2)
    det = d11 * d22 - d12 * d12
    with np.errstate(all="ignore"):
        b = np.where(det > 0, (d22 * q1 - d12 * q2) / det, 0.0)
        c = np.where(det > 0, (d11 * q2 - d12 * q1) / det, 0.0)
    return np.stack([1.0 - b - c, b, c], axis=1)


def usable_pixels(obj: np.ndarray, z: np.ndarray, prim: np.ndarray, count: int) -> np.ndarray:
    """(H, W) bool: pixels that hit a valid triangle with finite depth, inside a 3x3 block of one object."""
    h, w = obj.shape
    ok: np.ndarray = np.isfinite(z) & (z > 0) & (prim != BACKGROUND_ID) & (prim.astype(np.int64) < count)
    pad = np.pad(obj, 1, constant_values=BACKGROUND_ID)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            ok &= pad[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w] == obj
    return ok


def measure(
    scene: resolved.ResolvedScene,
    backend: str,
    z: np.ndarray,
    prim: np.ndarray,
    *,
    info: Mapping[str, Any] | None = None,
    attrs: Mapping[str, Any] | None = None,
    reference_obj: np.ndarray | None = None,
    render: Mapping[str, Any] | None = None,
    specs: SpecLookup,
) -> Calibration:
    """Fit and judge one backend's Z (and its own id.prim) on one probe scene; its camera-error
    model is its spec's (`specs`, the registry's lookup).

    `calibrate_run` calls this for every render; tests call it with synthetic buffers.
    Raises CalibrationError when the buffers cannot identify the camera.
    """
    cam = scene.camera
    shape = (cam.height, cam.width)
    if z.shape != shape or prim.shape != shape:
        raise CalibrationError(f"buffers are {z.shape[::-1]}, the probe's camera is {cam.width}x{cam.height}")
    count = scene.triangle_count
    prim = prim.astype(np.uint32)
    valid_prim = (prim != BACKGROUND_ID) & (prim.astype(np.int64) < count)
    if np.any((prim != BACKGROUND_ID) & ~valid_prim):
        raise CalibrationError("id.prim names triangles the probe does not have")
    obj = np.full(shape, BACKGROUND_ID, dtype=np.uint32)
    obj[valid_prim] = scene.object_ids[prim[valid_prim]]
    z64 = z.astype(np.float64)
    ok = usable_pixels(obj, z64, prim, count)
    k_px = int(ok.sum())
    if k_px < MIN_PIXELS:
        raise CalibrationError(
            f"only {k_px} pixels show a probe plane away from its outline (need {MIN_PIXELS}): "
            "the backend saw (almost) none of the probe"
        )
    n, h, extent = _planes(scene)
    p = prim[ok].astype(np.int64)
    nf, nr, nu = n[p] @ cam.forward, n[p] @ cam.right, n[p] @ cam.up_ortho
    sx_all, sy_all = cam.screen_coords()
    sx, sy = sx_all[ok], sy_all[ok]
    zk = z64[ok]
    pixel = cam.pixel_size()
    n_perp = np.hypot(nr, nu)
    if np.any(n_perp * pixel <= 0.0):
        raise CalibrationError(
            "a probe plane faces the camera exactly: its depth says nothing about where it was sampled"
        )
    g = pixel * n_perp  # d(h/Z) per pixel of displacement along the plane's tilt
    # h/Z = n.d_b with the backend's ray d_b = G (1, sx, sy) in the (f, r, u) basis: linear in G.
    v = np.stack([np.ones_like(sx), sx, sy], axis=1)
    nb = np.stack([nf, nr, nu], axis=1)
    design = (nb[:, :, None] * v[:, None, :]).reshape(-1, 9) / g[:, None]
    g0 = np.eye(3).ravel()
    rhs = (h[p] / zk) / g - design @ g0
    sv = np.linalg.svd(design, compute_uv=False)
    if not sv[-1] > 0 or sv[0] / sv[-1] > MAX_CONDITION:
        planes = len({tuple(np.round(row, 6)) for row in n[np.unique(p)]})
        raise CalibrationError(
            f"the probe cannot identify the camera (condition {sv[0] / max(sv[-1], 1e-300):.3g}; "
            f"{planes} plane orientations seen, at least 3 independent ones are needed)"
        )
    pinv = np.linalg.pinv(design)
    delta = pinv @ rhs
    gm = (g0 + delta).reshape(3, 3)
    residual = rhs - design @ delta

    # The backend's error bounds, per pixel, in px.
    d = cam.forward[None, :] + sx[:, None] * cam.right[None, :] + sy[:, None] * cam.up_ortho[None, :]
    d_norm = np.linalg.norm(d, axis=1)
    n_dot_d = np.abs(np.einsum("ij,ij->i", n[p], d))
    eye = np.asarray(cam.eye, dtype=np.float64)
    hit = eye[None, :] + zk[:, None] * d
    tris = scene.triangles.astype(np.float64)
    rel = tris - eye[None, None, :]
    vertex_depth = rel @ cam.forward
    with np.errstate(all="ignore"):
        vertex_dir = rel / vertex_depth[..., None]
    ctx = ProbePixels(
        z=zk,
        n_dot_d=n_dot_d,
        n_perp=n_perp,
        d=d,
        d_norm=d_norm,
        cos=np.clip(n_dot_d / d_norm, 1e-12, 1.0),
        point_norm=np.linalg.norm(hit, axis=1),
        extent=extent[p],
        vertex_norm=np.linalg.norm(tris, axis=2),
        vertex_depth=np.abs(vertex_depth),
        vertex_d_norm=np.nan_to_num(np.linalg.norm(vertex_dir, axis=2), nan=0.0, posinf=0.0),
        tri_extent=extent,
        eye=eye,
        origin_offset=float(np.linalg.norm(eye.astype(np.float32).astype(np.float64) - eye)),
        pixel=pixel,
        width=cam.width,
        height=cam.height,
        info=info or {},
        attrs=attrs or {},
    )
    spec = specs(backend)
    model, known = precision.camera_model(spec)
    budget = model(ctx)
    pixel_bound = np.abs(budget.pixel) / g
    if not gm[0, 0] > 0:
        # No planar depth of these planes: which depth is it? (the per-pixel bound only: the
        # per-vertex terms need the fitted camera)
        diag = hypotheses.diagnose(
            design, h[p] / g, zk, d_norm, cam.near, cam.far, float(np.sqrt(np.mean(pixel_bound**2))), False
        )
        planar = f"depth scale came out {1.0 / gm[0, 0]:.3g}: the Z buffer is not a planar depth of these planes"
        if diag.depth == hypotheses.PLANAR:
            raise CalibrationError(f"{planar}; {diag.summary()}")
        owner = precision.camera_owner(spec, backend)
        return Calibration(
            scene=scene.name,
            backend=backend,
            status=Status.FAIL,
            reason=f"convention error in {owner}: {diag.lead()}; {planar}; {diag.summary()}",
            pixels=k_px,
            width=cam.width,
            height=cam.height,
            pixel=pixel,
            owner=owner,
            hypotheses=diag.as_json(),
            render=render or {},
        )
    text = (
        budget.text
        if known
        else f"no camera precision model for {backend!r}: judged as exact f32 depth ({budget.text})"
    )

    points = _screen_points(cam)
    shift = _displacement(gm, points, pixel)  # (5, 2)
    lp = np.einsum("pak,kn->pan", _displacement_jacobian(gm, points, pixel), pinv)  # (5, 2, K)
    bounds: np.ndarray = np.abs(lp) @ pixel_bound
    if budget.vertex is not None:
        lam = _barycentrics(tris[p], hit)  # (K, 3)
        w = lam / (zk * g)[:, None]  # px per world unit of plane offset at each vertex
        vb = np.abs(budget.vertex)
        for vert in range(3):
            per_tri = np.stack(
                [np.bincount(p, weights=row * w[:, vert], minlength=count) for row in lp.reshape(-1, k_px)]
            ).reshape(lp.shape[0], lp.shape[1], count)
            bounds = bounds + np.asarray(np.abs(per_tri) @ vb[:, vert])
        pixel_bound = pixel_bound + np.einsum("kv,kv->k", np.abs(w), vb[p])
    bound = float(bounds.max())
    rms = float(np.sqrt(np.mean(residual * residual)))
    rms_bound = float(np.sqrt(np.mean(pixel_bound**2)))

    k = gm[0, 0]
    m = gm[1:, 1:] / k
    turn = -gm[0, 1:] / k
    mismatches = None
    if reference_obj is not None and reference_obj.shape == shape:
        mismatches = int(np.count_nonzero(reference_obj != obj))
    cal = Calibration(
        scene=scene.name,
        backend=backend,
        owner=precision.camera_owner(spec, backend),
        status=Status.PASS,
        reason="",
        offset_x_px=float(shift[0, 0]),
        offset_y_px=float(shift[0, 1]),
        scale_x=float(m[0, 0]),
        scale_y=float(m[1, 1]),
        rotation=float(0.5 * (m[1, 0] - m[0, 1])),
        shear=float(0.5 * (m[1, 0] + m[0, 1])),
        turn_x=float(turn[0]),
        turn_y=float(turn[1]),
        depth_scale=float(1.0 / k),
        flipped_y=bool(m[1, 1] < 0),
        mirrored_x=bool(m[0, 0] < 0),
        rms_px=rms,
        rms_bound_px=rms_bound,
        max_shift_px=float(np.abs(shift).max()),
        bound_px=bound,
        pixels=k_px,
        plane_mismatches=mismatches,
        width=cam.width,
        height=cam.height,
        pixel=pixel,
        bound_text=(
            f"bound {bound:.3g} px: the worst case of the per-pixel and per-vertex error bounds through the fit, "
            f"at the image center and corners (rms residual <= {rms_bound:.3g} px); {backend}: {text}"
        ),
        render=render or {},
    )
    cal = judge(cal)
    if cal.status != Status.FAIL:
        return cal
    diag = hypotheses.diagnose(design, h[p] / g, zk, d_norm, cam.near, cam.far, rms_bound, False)
    return _replace(cal, reason=diagnosed(cal, diag), hypotheses=diag.as_json())


def diagnosed(cal: Calibration, diag: hypotheses.Diagnosis) -> str:
    """A failing calibration's reason led by the best hypothesis (judge/hypotheses.py), every
    hypothesis's residual after it. Under a depth other than planar the fitted camera numbers
    (fitted to the wrong depth) are left out of the words; results.json keeps them."""
    prefix = f"convention error in {cal.owner}: "
    if diag.depth != hypotheses.PLANAR:
        return f"{prefix}{diag.lead()}; {diag.summary()}"
    rest = cal.reason.removeprefix(prefix)
    return f"{prefix}{diag.lead()}: {rest}; {diag.summary()}"


def _num(x: float) -> str:
    return f"{x:.4g}"


def judge(cal: Calibration) -> Calibration:
    """pass, or fail with the convention error(s) named (module docstring)."""
    assert cal.bound_px is not None and cal.max_shift_px is not None
    b = cal.bound_px
    problems: list[str] = []
    sx, sy = cal.scale_x or 0.0, cal.scale_y or 0.0
    w, h = cal.width, cal.height
    if cal.mirrored_x:
        problems.append(f"x mirrored (handedness: scale_x {_num(sx)})")
    if cal.flipped_y:
        problems.append(f"y flipped (scale_y {_num(sy)})")
    if not problems and w and h:
        ex, ey = abs(sx - 1.0) * w / 2.0 > b, abs(sy - 1.0) * h / 2.0 > b
        wrong_axis = any(abs(v - r) < FOV_AXIS_TOL for v in (sx, sy) for r in (h / w, w / h)) if w != h else False
        if ex and ey:
            note = " (the field of view is applied to the wrong axis)" if wrong_axis else ""
            same = abs(sx - sy) * max(w, h) / 2.0 <= b
            if same:
                problems.append(f"field of view scale {_num(0.5 * (sx + sy))}x on both axes{note}")
            else:
                problems.append(f"horizontal FOV scale {_num(sx)}x, vertical FOV scale {_num(sy)}x{note}")
        elif ex:
            problems.append(f"horizontal FOV scale {_num(sx)}x")
        elif ey:
            problems.append(f"vertical FOV scale {_num(sy)}x")
    dx, dy = cal.offset_x_px or 0.0, cal.offset_y_px or 0.0
    if abs(dx) > b or abs(dy) > b:
        offset = f"pixel centers offset by ({_num(dx)}, {_num(dy)}) px"
        tx, ty = cal.turn_x or 0.0, cal.turn_y or 0.0
        if cal.pixel > 0 and math.hypot(tx / cal.pixel - dx, -ty / cal.pixel - dy) <= 0.5 * math.hypot(dx, dy):
            offset = f"camera turned by ({_num(tx)}, {_num(ty)}) rad off its view direction, {offset}"
        problems.append(offset)
    if w and h:
        half_diag = 0.5 * math.hypot(w, h)
        rot, shear = cal.rotation or 0.0, cal.shear or 0.0
        if abs(rot) * half_diag > b:
            problems.append(f"image rotated by {_num(rot)} rad ({_num(abs(rot) * half_diag)} px at the corners)")
        if abs(shear) * half_diag > b:
            problems.append(f"image axes sheared by {_num(shear)} ({_num(abs(shear) * half_diag)} px at the corners)")
    if cal.max_shift_px > b and not problems:
        problems.append(f"pixel centers displaced by up to {_num(cal.max_shift_px)} px")
    rms_bad = cal.rms_px is not None and cal.rms_bound_px is not None and cal.rms_px > cal.rms_bound_px
    if not problems and not rms_bad:
        return _replace(cal, status=Status.PASS, reason="")
    parts = []
    if problems:
        parts.append(f"convention error in {cal.owner}: {'; '.join(problems)} (bound {_num(b)} px)")
    if rms_bad:
        parts.append(
            f"its samples fit no pinhole camera at its precision: rms residual {_num(cal.rms_px or 0.0)} px > "
            f"{_num(cal.rms_bound_px or 0.0)} px (lens distortion, jittered samples, or a depth that is not planar)"
        )
    return _replace(cal, status=Status.FAIL, reason="; ".join(parts))


def _replace(cal: Calibration, **changes: Any) -> Calibration:
    from dataclasses import replace

    return replace(cal, **changes)


# --------------------------------------------------------------------------- a run


def probe_scenes(manifest: Mapping[str, Any], scenes: Collection[str] | None = None) -> list[Mapping[str, Any]]:
    """The manifest's probe scene entries: `role == "calibration"`, or exactly the names given."""
    entries = [sc for sc in manifest.get("scenes", []) if isinstance(sc, Mapping)]
    if scenes is not None:
        wanted = set(scenes)
        return [sc for sc in entries if sc.get("scene") in wanted]
    return [sc for sc in entries if sc.get("role") == ROLE]


def _reason(render: Mapping[str, Any]) -> str:
    return render_reason(render)


def _run_path(run: Path, rel: Any, what: str) -> Path:
    """manifest.run_path, with its error as a CalibrationError."""
    try:
        return run_path(run, rel, what)
    except EntryError as exc:
        raise CalibrationError(str(exc)) from None


def _read(run: Path, render: Mapping[str, Any]) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    exr = _run_path(run, render.get("exr"), f"{render.get('backend')} EXR")
    try:
        buffers, attrs = exrbuf.read_render(exr)
    except exrbuf.BufferError as exc:
        raise CalibrationError(f"unreadable: {exc}") from None
    return buffers, dict(attrs)


def _has_z(render: Mapping[str, Any]) -> bool | None:
    """Whether the render declares a Z buffer (None: it does not say)."""
    bufs = render.get("buffers")
    if isinstance(bufs, list):
        return "Z" in bufs
    return None


def calibrate_scene(run: Path, scene_entry: Mapping[str, Any], reference: str, specs: SpecLookup) -> list[Calibration]:
    """Every backend (the reference included) measured on one probe scene of a run."""
    name = str(scene_entry.get("scene"))
    renders = [
        r for r in scene_entry.get("renders", []) if isinstance(r, Mapping) and isinstance(r.get("backend"), str)
    ]
    try:
        scene = resolved.load(_run_path(run, scene_entry.get("resolved"), "resolved scene"))
    except (CalibrationError, resolved.SceneError, KeyError, ValueError, TypeError) as exc:
        return [
            Calibration(name, str(r["backend"]), Status.ERROR, f"cannot load the probe: {exc}", render=r)
            for r in renders
        ]

    def unmeasured(backend: str, status: str, reason: str, render: Mapping[str, Any]) -> Calibration:
        return Calibration(
            name, backend, status, reason, width=scene.camera.width, height=scene.camera.height, render=render
        )

    ref_obj: np.ndarray | None = None
    for r in renders:
        if r["backend"] == reference and r.get("status") == RenderStatus.OK:
            try:
                buf, _ = _read(run, r)
                prim = buf["id.prim"]
                valid = (prim != BACKGROUND_ID) & (prim.astype(np.int64) < scene.triangle_count)
                ref_obj = np.full(prim.shape, BACKGROUND_ID, dtype=np.uint32)
                ref_obj[valid] = scene.object_ids[prim[valid]]
            except (CalibrationError, KeyError):
                ref_obj = None
    out: list[Calibration] = []
    for r in renders:
        backend = str(r["backend"])
        if r.get("status") != RenderStatus.OK:
            skipped = r.get("status") == RenderStatus.SKIPPED
            out.append(unmeasured(backend, Status.SKIPPED if skipped else Status.ERROR, _reason(r), r))
            continue
        if _has_z(r) is False:
            out.append(unmeasured(backend, Status.SKIPPED, f"{backend} renders no Z buffer", r))
            continue
        try:
            buf, attrs = _read(run, r)
            if "Z" not in buf:
                out.append(unmeasured(backend, Status.SKIPPED, f"{backend} wrote no Z buffer", r))
                continue
            if "id.prim" not in buf:
                raise CalibrationError("no id.prim buffer: which plane each pixel saw is unknown")
            info = r.get("info") if isinstance(r.get("info"), Mapping) else {}
            out.append(
                measure(
                    scene,
                    backend,
                    buf["Z"],
                    buf["id.prim"],
                    info=info or {},
                    attrs=attrs,
                    reference_obj=ref_obj,
                    render=r,
                    specs=specs,
                )
            )
        except CalibrationError as exc:
            out.append(unmeasured(backend, Status.ERROR, str(exc), r))
    return out


def entry(cal: Calibration) -> dict[str, Any]:
    """The results.json entry of one measurement (a `results.Entry`, buffer "camera")."""
    e = Entry.for_render(cal.scene, cal.backend, BUFFER, cal.render, status=cal.status, reason=cal.reason)
    e.pixels = cal.pixels
    e.compared_pixels = cal.pixels
    e.tolerance = cal.bound_text
    e.extra = cal.fields()
    if cal.hypotheses is not None:
        e.extra["hypotheses"] = dict(cal.hypotheses)
    return e.blank_if_not_compared().to_json()


_STATUS_RANK: dict[str, int] = {Status.FAIL: 0, Status.ERROR: 1, Status.PASS: 2, Status.SKIPPED: 3}


def summarize(measurements: Sequence[Calibration]) -> dict[str, dict[str, Any]]:
    """results.json `calibration`: per backend, one probe's fields, status and reason.

    The probe shown is a failing one (the farthest beyond its bound), else an erroring one,
    else the passing probe with the tightest bound (the backend's most precise calibration);
    `probes` lists every probe measured.
    """
    by_backend: dict[str, list[Calibration]] = {}
    for m in measurements:
        by_backend.setdefault(m.backend, []).append(m)
    out: dict[str, dict[str, Any]] = {}
    for backend, ms in by_backend.items():

        def rank(m: Calibration) -> tuple[int, float]:
            status = _STATUS_RANK.get(m.status, 1)
            if m.status == Status.FAIL:
                return status, -m.ratio
            return status, m.bound_px if m.bound_px is not None else math.inf

        worst = min(ms, key=rank)
        item = worst.fields()
        item.update(
            status=worst.status,
            reason=worst.reason,
            scene=worst.scene,
            probes=[m.scene for m in ms],
            tolerance=worst.bound_text,
        )
        if worst.hypotheses is not None:
            item["hypotheses"] = dict(worst.hypotheses)
        out[backend] = item
    return out


def calibrate_run(
    run: Path, manifest: Mapping[str, Any], specs: SpecLookup, scenes: Collection[str] | None = None
) -> CalibrationReport:
    """Measure every backend's camera on the run's probe scenes (module docstring).

    `manifest` is RUN/manifest.json as loaded (manifest.load_manifest). Probes are its scenes
    with `"role": "calibration"`, or exactly `scenes` when given. No probe: an empty report.
    """
    run = Path(run)
    reference = str(manifest.get("reference", "raster"))
    measurements: list[Calibration] = []
    for sc in probe_scenes(manifest, scenes):
        measurements += calibrate_scene(run, sc, reference, specs)
    return CalibrationReport(
        entries=[entry(m) for m in measurements],
        summary=summarize(measurements),
        measurements=measurements,
    )


# --------------------------------------------------------------------------- a run's verdicts


def calibrate_and_blame(
    run: Path, manifest: Mapping[str, Any], results: list[Entry], specs: SpecLookup
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Camera calibration from the run's probe scenes (`calibrate_run`): returns the summary
    for results.json's `calibration` and the `camera` entries that follow `results`.

    A backend whose camera fails calibration has a convention error (in its exporter, or in the
    renderer declared by command), not a
    renderer bug in every scene: its failing verdicts elsewhere become `error` entries that
    say so, by name, instead of fails blamed on the renderer.
    """
    try:
        rep = calibrate_run(run, manifest, specs)
    except Exception as exc:  # noqa: BLE001 - a bug must not lose the other results
        traceback.print_exc(file=sys.stderr)
        e = Entry.for_render(
            "calibration",
            str(manifest.get("reference", "raster")),
            Buffer.CAMERA,
            {},
            reason=f"internal error in calibration (a rendiff bug): {type(exc).__name__}: {exc}",
        )
        return {}, [e.blank_if_not_compared().to_json()]
    probes = {str(sc["scene"]) for sc in manifest["scenes"] if sc.get("role") == "calibration"}
    bad = {b: v for b, v in rep.summary.items() if v.get("status") == Status.FAIL}
    for e in results:
        cal = bad.get(e.backend)
        if cal is None or e.scene in probes or e.status not in (Status.FAIL, Status.UNEXPECTED_PASS):
            continue
        e.status = Status.ERROR
        e.reason = f"not judged: {e.backend}'s camera failed calibration ({cal.get('reason', '')}); was: {e.reason}"
        # What made it unjudged, by name: the report hangs it under that cause (docs/run-format.md).
        e.extra[NOT_JUDGED_FIELD] = ROLE
    return rep.summary, rep.entries
