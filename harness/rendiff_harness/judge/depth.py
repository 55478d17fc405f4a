"""The `Z` buffer: hit/miss masks exactly, depth where both sides see the same prim within the
backend's tolerance model (tolerance.py), the rest interior mismatches.

Where both hit but see different prims (an allowed edge or tie pixel, or an ID mismatch the `id`
entry fails), there is no reference depth to compare with, yet the test renderer's depth is
still judged: it must lie on the plane of the triangle its own `id.prim` names, at the pixel
center, within the same model (`own_plane`). A renderer whose depths were wrong only where IDs
differed used to pass Z with "max |dZ| 0" beside a histogram of 0.1 errors. Pixels that cannot
be judged either way are counted by reason (`not_comparable`): the test names no valid prim, or
wrote no id.prim, or the ray runs along its triangle's plane."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..contract import exrbuf
from ..contract.manifest import Reference, render_info
from ..contract.vocab import BACKGROUND_ID
from . import tolerance, verify
from .ids import eye_norm, origin_offset, pixel_size, point_norm
from .verdict import EXAMPLES


@dataclass
class DepthResult:
    edge: int
    interior: int
    mask: int
    compared: int
    max_abs: float
    mean_abs: float
    max_rel: float
    tolerance: str
    details: list[str]
    tie: int = 0
    crack: int = 0
    own_plane: int = 0  # pixels of different prims judged against the test's own triangle's plane
    own_plane_beyond: int = 0  # of those, depths beyond the model (counted as interior)
    own_plane_max_abs: float = 0.0
    not_comparable: dict[str, int] = field(default_factory=dict)  # both hit, judged neither way: reason -> pixels
    # The interior pixels grouped by (ref prim, test prim), as the id buffer's (verify.explain);
    # empty when there are none or a side has no id.prim (where they are is then not known).
    explanations: list[dict[str, Any]] = field(default_factory=list)


@dataclass
class OwnPlane:
    """The test renderer's depths where it sees another prim than the reference, against its own
    triangle's plane at the pixel center (module docstring)."""

    idx: np.ndarray  # flat pixel indices judged
    beyond: np.ndarray  # flat pixel indices beyond the model
    max_abs: float
    not_comparable: dict[str, int]
    details: list[str]
    tolerance: str


def own_plane_depths(
    ref: Reference,
    test: Mapping[str, np.ndarray],
    both: np.ndarray,
    same: np.ndarray,
    model: tolerance.Model,
    render: Mapping[str, Any],
    attrs: Mapping[str, Any],
) -> OwnPlane:
    """Judge the test's depth at pixels where both hit and `same` is False against the plane of
    the triangle its id.prim names there: t = n.(a - eye) / n.d, d the contract's pixel-center ray
    (planar depth, as d's forward component is 1), held to the test's own depth model."""
    h, w = both.shape
    other = both & ~same
    skipped: dict[str, int] = {}
    if "id.prim" not in test:
        n_other = int(other.sum())
        if n_other:
            skipped["the test wrote no id.prim: its triangle there is unknown"] = n_other
        return OwnPlane(np.zeros(0, np.int64), np.zeros(0, np.int64), 0.0, skipped, [], "")
    tp = test["id.prim"]
    valid = (tp != BACKGROUND_ID) & (tp.astype(np.uint64) < np.uint64(ref.scene.triangle_count))
    bad_prim = int((other & ~valid).sum())
    if bad_prim:
        skipped["the test's id.prim names no triangle of the scene"] = bad_prim
    idx = np.flatnonzero(other & valid)
    rows, cols = idx // w, idx % w
    prims = tp.ravel()[idx].astype(np.int64)
    tri = ref.scene.triangles[prims].astype(np.float64)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    d = ref.scene.camera.center_directions(rows, cols)
    eye = np.asarray(ref.scene.camera.eye, dtype=np.float64)
    with np.errstate(all="ignore"):
        z_plane = np.einsum("ij,ij->i", n, tri[:, 0] - eye[None, :]) / np.einsum("ij,ij->i", n, d)
        # Rounded once to f32, as the contract's depth is stored: the depth models bound a renderer's
        # distance from that stored value (an exact model: bit-identical to it).
        z_plane = z_plane.astype(np.float32).astype(np.float64)
    ok = np.isfinite(z_plane) & (z_plane > 0)
    if (~ok).any():
        skipped["the pixel ray runs along (or away from) the test's triangle's plane"] = int((~ok).sum())
    idx, rows, cols, prims, z_plane = idx[ok], rows[ok], cols[ok], prims[ok], z_plane[ok]
    z_test = test["Z"].astype(np.float64).ravel()[idx]
    ctx = depth_context(ref, rows, cols, z_plane, prims, render, attrs)
    tol, tol_text = model.depth(ctx)
    tol = np.broadcast_to(np.asarray(tol, dtype=np.float64), z_plane.shape)
    err = np.abs(z_test - z_plane)
    beyond = ~(err <= tol)
    details: list[str] = []
    bi = np.nonzero(beyond)[0]
    if bi.size:
        worst = bi[np.argsort(-(err[bi] / np.maximum(tol[bi], 1e-300)))[:EXAMPLES]]
        ex = ", ".join(
            f"({cols[k]},{rows[k]}) prim {prims[k]} plane {z_plane[k]:.9g} test {z_test[k]:.9g} "
            f"|d| {err[k]:.3g} > tol {tol[k]:.3g}"
            for k in worst
        )
        details.append(
            f"{bi.size} depths off their own triangle's plane (where the test sees another prim than the "
            f"reference), worst {ex}"
        )
    return OwnPlane(idx, idx[beyond], float(err.max()) if idx.size else 0.0, skipped, details, tol_text)


def triangle_extent_span(ref: Reference, prims: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each triangle's longest edge and its planar-depth span (max - min of its vertices' Z):
    what bounds a depth error on it that 1/|cos| alone would overstate (tolerance.shift_depth)."""
    t = ref.scene.triangles[prims.astype(np.int64)].astype(np.float64)
    extent = np.max(np.linalg.norm(t - np.roll(t, 1, axis=1), axis=2), axis=1)
    vz = (t - ref.scene.camera.eye[None, None, :]) @ ref.scene.camera.forward
    return extent, vz.max(axis=1) - vz.min(axis=1)


def triangle_corner_cond(ref: Reference, prims: np.ndarray) -> np.ndarray:
    """Each triangle's largest |e_a| |e_b| / |e_a x e_b| over its three corners (1/sin of its smallest
    angle; inf for a degenerate one): what an f32 cross product of any two of its edges may lose
    relative to its length (tolerance.moeller_t_depth)."""
    t = ref.scene.triangles[prims.astype(np.int64)].astype(np.float64)
    worst = np.ones(len(t))
    with np.errstate(all="ignore"):
        for k in range(3):
            a = t[:, (k + 1) % 3] - t[:, k]
            b = t[:, (k + 2) % 3] - t[:, k]
            c = np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1) / np.linalg.norm(np.cross(a, b), axis=1)
            worst = np.maximum(worst, np.where(np.isnan(c), np.inf, c))
    return worst


def depth_context(
    ref: Reference,
    rows: np.ndarray,
    cols: np.ndarray,
    z_ref: np.ndarray,
    prims: np.ndarray | None,
    render: Mapping[str, Any],
    attrs: Mapping[str, Any],
) -> tolerance.DepthContext:
    """Everything a depth model may look at for the K pixels (rows, cols) seen at z_ref."""
    span = None
    cond = None
    if prims is not None:
        cos = ref.ray_cos(rows, cols, prims)
        extent, span = triangle_extent_span(ref, prims)
        cond = triangle_corner_cond(ref, prims)
    else:  # cannot know the triangle: assume the worst angle (models cap at MAX_REL)
        cos = np.zeros(z_ref.size)
        extent = None
    return tolerance.DepthContext(
        z_ref=z_ref,
        cos=cos,
        info=render_info(render),
        attrs=attrs,
        pixel_size=pixel_size(ref),
        point_norm=point_norm(ref, rows, cols, z_ref),
        extent=extent,
        origin_offset=origin_offset(ref),
        eye_norm=eye_norm(ref),
        depth_span=span,
        ray_norm=np.linalg.norm(ref.scene.camera.center_directions(rows, cols), axis=1),
        corner_cond=cond,
    )


def depth_tolerance_fn(
    ref: Reference, model: tolerance.Model, render: Mapping[str, Any], attrs: Mapping[str, Any]
) -> verify.DepthTolerance:
    """The test renderer's depth tolerance at (z, cos) on the triangles `prims`, for the verifier's
    tie test: the same model and context as the depth verdict's (`depth_context`), the triangle's
    extent and depth span included, so an edge-on triangle's bound is min(e/|cos|, span) there too
    (without them the tie test fell back to the fixed cap, and a correct renderer that ranked two
    crossing triangles by its own f32 plane was called interior: docs/verifier.md)."""

    # The tie test does not say which pixel: the longest pixel ray bounds every one (|d| is
    # convex in the image position, so largest at a corner pixel's center).
    cam = ref.scene.camera
    corner_rows = np.array([0, 0, cam.height - 1, cam.height - 1])
    corner_cols = np.array([0, cam.width - 1, 0, cam.width - 1])
    longest_ray = float(np.max(np.linalg.norm(cam.center_directions(corner_rows, corner_cols), axis=1)))

    def tol(z: np.ndarray, cos: np.ndarray, prims: np.ndarray) -> np.ndarray:
        extent, span = triangle_extent_span(ref, prims)
        ctx = tolerance.DepthContext(
            z_ref=z,
            cos=cos,
            info=render_info(render),
            attrs=attrs,
            pixel_size=pixel_size(ref),
            point_norm=np.abs(z) + eye_norm(ref),
            extent=extent,
            origin_offset=origin_offset(ref),
            eye_norm=eye_norm(ref),
            depth_span=span,
            ray_norm=longest_ray,
            corner_cond=triangle_corner_cond(ref, prims),
        )
        try:
            t, _ = model.depth(ctx)
        except tolerance.ToleranceError:
            return np.zeros_like(z)
        return np.broadcast_to(np.asarray(t, dtype=np.float64), z.shape)

    return tol


def radial_hint(
    ref: Reference,
    rows: np.ndarray,
    cols: np.ndarray,
    z_ref: np.ndarray,
    z_test: np.ndarray,
    tol: np.ndarray,
    beyond: np.ndarray,
) -> str:
    """Names the commonest depth-convention bug when it explains the failing depths: a renderer
    that writes the distance from the eye, Z |d| (d the contract's pixel ray, forward component 1),
    instead of planar depth. Said only when most pixels beyond tolerance are within it of Z |d|
    (the calibration tests this and the other depth conventions properly: judge/hypotheses.py)."""
    if not beyond.any():
        return ""
    k = np.flatnonzero(beyond)
    d_norm = np.linalg.norm(ref.scene.camera.center_directions(rows[k], cols[k]), axis=1)
    radial = np.abs(z_test[k] - z_ref[k] * d_norm) <= tol[k] * d_norm
    if radial.mean() < 0.9:
        return ""
    return (
        f"{int(radial.sum())} of the {k.size} depths beyond tolerance equal the radial distance from the eye "
        "(Z |d|), not the planar depth the contract asks for (docs/DESIGN.md, Buffers)"
    )


def compare_depth(
    ref: Reference,
    test: Mapping[str, np.ndarray],
    model: tolerance.Model,
    render: Mapping[str, Any],
    attrs: Mapping[str, Any],
    id_edge_mask: np.ndarray | None,
    id_classes: np.ndarray | None = None,
    own_plane: bool = False,
) -> DepthResult:
    """Hit/miss masks exact except at allowed ID classes; depth within the backend's model.

    With `id_classes` (the verifier's classes of the ID mismatches), a mask mismatch at an
    edge or tie pixel is allowed, at a crack pixel it is a crack, elsewhere interior.
    Without it, `id_edge_mask` marks the allowed pixels (the metamorphic comparison).
    With `own_plane` (the verifier's comparison with the reference), pixels where both hit other
    prims are judged against the test's own triangle's plane (`own_plane_depths`); the
    metamorphic comparison, whose variant buffers are mapped back onto the base scene and whose
    core models are exact, does not ask for it.
    """
    zr = ref.buffers["Z"].astype(np.float64)
    zt = test["Z"].astype(np.float64)
    h, w = zr.shape
    hr, ht = exrbuf.depth_hits(zr), exrbuf.depth_hits(zt)
    mask_mm = hr != ht
    tie_mask = np.zeros_like(mask_mm)
    crack_mask = np.zeros_like(mask_mm)
    if id_classes is not None:
        edge_mask = mask_mm & (id_classes == verify.EDGE)
        tie_mask = mask_mm & (id_classes == verify.TIE)
        crack_mask = mask_mm & (id_classes == verify.CRACK)
    else:
        edge_mask = mask_mm & id_edge_mask if id_edge_mask is not None else np.zeros_like(mask_mm)
    interior_mask = mask_mm & ~edge_mask & ~tie_mask & ~crack_mask
    details: list[str] = []
    notes: list[str] = []

    have_ref_ids = "id.prim" in ref.buffers
    if have_ref_ids and "id.prim" in test:
        rp = ref.buffers["id.prim"]
        same = hr & ht & (rp == test["id.prim"]) & (rp != BACKGROUND_ID)
        same &= rp.astype(np.uint64) < np.uint64(ref.scene.triangle_count)
        scope = "where both hit the same prim"
    else:
        same = hr & ht
        scope = "where both hit (no id.prim on the test side: prims not checked)"
        if have_ref_ids:
            rp = ref.buffers["id.prim"]
            same &= (rp != BACKGROUND_ID) & (rp.astype(np.uint64) < np.uint64(ref.scene.triangle_count))
    idx = np.flatnonzero(same)
    rows, cols = idx // w, idx % w
    z_ref = zr.ravel()[idx]
    z_test = zt.ravel()[idx]
    prims = ref.buffers["id.prim"].ravel()[idx] if have_ref_ids else None
    if prims is None:
        notes.append("reference has no id.prim: grazing factor at its cap")
    ctx = depth_context(ref, rows, cols, z_ref, prims, render, attrs)
    tol, tol_text = model.depth(ctx)
    tol = np.broadcast_to(np.asarray(tol, dtype=np.float64), z_ref.shape)
    err = np.abs(z_test - z_ref)
    beyond = ~(err <= tol)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(z_ref != 0.0, err / np.abs(z_ref), np.where(err == 0.0, 0.0, np.inf))
    interior_mask.ravel()[idx[beyond]] = True
    # Not asked for: every common hit counts as judged above, so none is left for the own-plane test.
    own = own_plane_depths(ref, test, hr & ht, same if own_plane else np.ones_like(same), model, render, attrs)
    interior_mask.ravel()[own.beyond] = True

    if mask_mm.any():
        mi = np.flatnonzero(interior_mask & mask_mm)[:EXAMPLES]
        if mi.size:
            ex = ", ".join(f"({k % w},{k // w}) ref {zr.ravel()[k]:.7g} test {zt.ravel()[k]:.7g}" for k in mi)
            details.append(f"hit/miss mask mismatches e.g. {ex}")
    hint = radial_hint(ref, rows, cols, z_ref, z_test, tol, beyond)
    if hint:
        details.append(hint)
    bi = np.nonzero(beyond)[0]
    if bi.size:
        worst = bi[np.argsort(-(err[bi] / np.maximum(tol[bi], 1e-300)))[:EXAMPLES]]
        ex = ", ".join(
            f"({cols[k]},{rows[k]}) ref {z_ref[k]:.9g} test {z_test[k]:.9g} |d| {err[k]:.3g} > tol {tol[k]:.3g}"
            for k in worst
        )
        details.append(f"{bi.size} depths beyond tolerance, worst {ex}")
    details += own.details
    own_text = (
        f"; where both hit other prims, the test's depth against its own triangle's plane at the pixel center "
        f"({own.idx.size} pixels)"
        if own_plane
        else ""
    )
    text = (
        f"{tol_text}; compared {scope}{own_text}; hit/miss masks exact except where the ID mismatch is an "
        "allowed class (edge, tie; crack only where declared)"
    )
    if own.not_comparable:
        notes.append("not comparable: " + ", ".join(f"{k} ({v} px)" for k, v in sorted(own.not_comparable.items())))
    if notes:
        text += "; " + "; ".join(notes)
    explanations: list[dict[str, Any]] = []
    bad = np.flatnonzero(interior_mask)
    if bad.size and have_ref_ids and "id.prim" in test:
        whys = [
            "a hit on one side only, where the ID mismatch is no allowed class"
            if m
            else "a depth beyond the backend's depth model"
            for m in mask_mm.ravel()[bad]
        ]
        explanations = verify.explain(
            np.full(bad.size, verify.INTERIOR, dtype=np.int8),
            whys,
            ref.buffers["id.prim"].ravel()[bad],
            test["id.prim"].ravel()[bad],
            bad // w,
            bad % w,
        )
    return DepthResult(
        edge=int(edge_mask.sum()),
        interior=int(interior_mask.sum()),
        mask=int(mask_mm.sum()),
        compared=int(idx.size),
        max_abs=float(err.max()) if idx.size else 0.0,
        mean_abs=float(err.mean()) if idx.size else 0.0,
        max_rel=float(rel.max()) if idx.size else 0.0,
        tolerance=text,
        details=details,
        tie=int(tie_mask.sum()),
        crack=int(crack_mask.sum()),
        own_plane=int(own.idx.size),
        own_plane_beyond=int(own.beyond.size),
        own_plane_max_abs=own.max_abs,
        not_comparable=own.not_comparable,
        explanations=explanations,
    )
