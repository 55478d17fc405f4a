"""`python -m rendiff_harness compare --run RUN [--expectations FILE]`: buffers -> results.json.

Reads RUN/manifest.json (docs/run-format.md, written by `rendiff check`; manifest.py), compares
every backend's buffers with the reference's (`reference`, normally "raster"), writes
RUN/results.json atomically (results.py) and RUN/scenes/<scene>/diff/*.png, and prints a
compact table. The Rust side decides pass/fail from results.json, so this exits 0 whenever it
could write results; 2 when the manifest (or the expectations file, or results.json itself)
cannot be read/written, with one line naming the file.

What is compared (docs/DESIGN.md "Comparing"); `BUFFER_TABLE` below says, per buffer, when it
applies, which function compares it and which fields its entry has:

* `id`: id.prim read exactly as u32. A mismatch is a pixel whose prim differs
  (background 0xFFFFFFFF is a value). Each mismatch is *edge* when the pixel center lies
  within the backend's edge tolerance (tolerance.py) of an edge of the reference's or
  the test's triangle (classify.py), else *interior*. An ID naming no triangle, and an
  id.object that differs where id.prim agrees, are interior mismatches.
* `Z`: the hit/miss masks (finite vs not) must agree exactly: a mask mismatch at a pixel
  that is an ID edge mismatch counts as edge, elsewhere as interior. Depth is compared
  where both sides hit the same prim, against the backend's tolerance model
  (tolerance.py); pixels beyond it are interior mismatches.
* `N` (where the backend writes normals, and the reference's own): against the winding
  convention N = normalize((b-a) x (c-a)) of the prim the backend's id.prim names.
* `RGB` (scenes that require `lambert`, `emission` or `global_illumination` only):
  radiance.py. Deterministic renders (no var.* channels): |a - b| <= abs + rel |b| with
  the test backend's precision (its spec's rgb_tolerance, judge/precision.py); failing pixels at ID edge
  mismatches or on ambiguous shadow rays are edge, the rest interior. Monte Carlo renders
  (var.* channels): Welch t per pixel-channel and a 3x3 cluster test, Sidak-corrected at
  family-wise alpha 0.01; every failure is interior. Extra fields on RGB entries:
  `mode`, `failing_pixels`, `min_p`, `alpha`, `cluster_failures`, `flip_mean` (FLIP, for
  people only), `flip_note`.
* cached references (`--references DIR`, references.py): every scene whose reference
  render has RGB and that requires `global_illumination` is also compared with
  DIR/<scene>.exr (a high-spp Mitsuba render whose provenance must match the resolved
  scene), as backend `mitsuba_ref`, buffer `RGB`. A missing, stale or corrupt cached
  reference is an `error` entry that says how to regenerate it.
* status: expectations.py turns (edge, interior) counts and the matching expectation
  into pass / fail / expected_fail / unexpected_pass. Skipped and error renders are
  copied through; a missing reference makes every entry of its scene an error.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import re
import sys
import time
import traceback
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np

from . import diffimages, expectations, radiance, verify
from .contract import exrbuf, lighting, vocab
from .contract.manifest import MANIFEST_FORMAT as MANIFEST_FORMAT
from .contract.manifest import EntryError as EntryError
from .contract.manifest import ManifestError as ManifestError
from .contract.manifest import Reference as Reference
from .contract.manifest import declared_buffers, read_test_buffers, render_info, render_reason
from .contract.manifest import load_manifest as load_manifest
from .contract.manifest import load_reference as load_reference
from .contract.manifest import run_path as run_path
from .contract.results import NUMERIC_FIELDS as NUMERIC_FIELDS
from .contract.results import RESULTS_FORMAT as RESULTS_FORMAT
from .contract.results import RGB_FIELDS as RGB_FIELDS
from .contract.results import Entry, document, finite
from .contract.results import base_entry as base_entry
from .contract.results import blank_if_not_compared as blank_if_not_compared
from .contract.results import format_table as format_table
from .contract.results import write_results as write_results
from .contract.text import printable
from .contract.vocab import BACKGROUND_ID, Buffer, Status
from .judge import precision, tolerance
from .renderers import registry
from .renderers.spec import BackendSpec, SpecLookup

SHADING_FEATURES = frozenset(f.value for f in vocab.SHADED_FEATURES)
CACHED_REFERENCE_BACKEND = vocab.CACHED_REFERENCE_BACKEND
EXAMPLES = 3  # example pixels quoted in a failure's reason
EXIT_OK, EXIT_ERROR = 0, 2
_SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._+-]*$")


def is_shaded(requires: Any) -> bool:
    """A scene whose buffers include radiance (docs/radiance.md)."""
    return isinstance(requires, (list, tuple, set, frozenset)) and vocab.needs_shading(requires)


# --------------------------------------------------------------------------- ID comparison


@dataclass
class IdResult:
    edge: int
    interior: int
    edge_mask: np.ndarray  # (H, W) bool: allowed ID differences (edge, tie, declared-or-not crack)
    interior_mask: np.ndarray  # (H, W) bool
    tolerance: str
    details: list[str]
    tie: int = 0
    crack: int = 0
    classes: np.ndarray | None = None  # (H, W) int8: verify.EDGE..INTERIOR, -1 where the IDs agree
    explanations: list[dict[str, Any]] = field(default_factory=list)


EdgeDistance = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]
"""(ref ids, test ids, rows, cols) of the mismatched pixels -> pixel distance to an edge involved."""


def origin_offset(ref: Reference) -> float:
    """|f32(eye) - eye|: how far a renderer whose camera origin is f32 moves every ray."""
    eye = np.asarray(ref.scene.camera.eye, dtype=np.float64)
    return float(np.linalg.norm(eye.astype(np.float32).astype(np.float64) - eye))


def eye_norm(ref: Reference) -> float:
    """|eye|: the size of the camera's coordinates, which f32 arithmetic rounds relative to."""
    return float(np.linalg.norm(np.asarray(ref.scene.camera.eye, dtype=np.float64)))


def pixel_size(ref: Reference) -> float:
    """One pixel on the image plane at distance 1."""
    return ref.scene.camera.pixel_size()


def point_norm(ref: Reference, rows: np.ndarray, cols: np.ndarray, z: np.ndarray) -> np.ndarray:
    """|X| of the points at planar depth z along pixel rays (distance from the world origin)."""
    cam = ref.scene.camera
    d = cam.center_directions(rows, cols)
    zz = np.where(np.isfinite(z), z, 0.0)
    norms: np.ndarray = np.linalg.norm(cam.eye[None, :] + zz[:, None] * d, axis=1)
    return norms


def compare_ids(
    ref: Reference,
    test: Mapping[str, np.ndarray],
    model: tolerance.Model,
    edge_distance: EdgeDistance | None = None,
    depth_tol: verify.DepthTolerance | None = None,
    backend: str = "the test renderer",
) -> IdResult:
    """Exact id.prim / id.object comparison; every mismatch gets a class (verify.py).

    With `edge_distance` (the metamorphic comparison, metamorphic.py, which also looks at
    the variant's scene) a mismatch is only edge (within `model.edge_px` of an edge
    involved) or interior. Otherwise the verifier classifies each mismatch as edge, tie,
    crack or interior, with the test renderer's per-pixel rounding distance
    (`model.edge_eps`) and depth tolerance `depth_tol` (for ties; default: exact).
    """
    rp, tp = ref.buffers["id.prim"], test["id.prim"]
    h, w = rp.shape
    mism = rp != tp
    idx = np.flatnonzero(mism)
    rows, cols = idx // w, idx % w
    r_ids, t_ids = rp.ravel()[idx], tp.ravel()[idx]
    n = ref.scene.triangle_count
    details: list[str] = []
    classes = np.full((h, w), -1, dtype=np.int8)
    explanations: list[dict[str, Any]] = []
    if edge_distance is not None:
        dist = edge_distance(r_ids, t_ids, rows, cols)
        invalid = (t_ids != BACKGROUND_ID) & (t_ids.astype(np.uint64) >= np.uint64(n))
        cls = np.where((dist <= model.edge_px) & ~invalid, verify.EDGE, verify.INTERIOR).astype(np.int8)
        tol_text = model.edge_text()
        bad = np.nonzero(cls == verify.INTERIOR)[0][:EXAMPLES]
        if invalid.any():
            details.append(f"{int(invalid.sum())} pixels carry IDs naming no triangle (scene has {n})")
        if bad.size:
            ex = ", ".join(
                f"({cols[k]},{rows[k]}) ref {_id(r_ids[k])} test {_id(t_ids[k])} d={_dist(dist[k])}" for k in bad
            )
            details.append(f"interior e.g. {ex}")
    else:
        zr = ref.buffers.get("Z")
        zt = test.get("Z")
        z_here = np.full(idx.size, np.inf)
        if zr is not None:
            z_here = zr.ravel()[idx].astype(np.float64)
        if zt is not None:
            zt_here = zt.ravel()[idx].astype(np.float64)
            z_here = np.where(np.isfinite(z_here), z_here, zt_here)
        ectx = tolerance.EdgeContext(
            z=z_here,
            point_norm=point_norm(ref, rows, cols, z_here),
            pixel_size=pixel_size(ref),
            origin_offset=origin_offset(ref),
            eye_norm=eye_norm(ref),
        )
        eps, tol_text = model.edge_eps(ectx)

        def exact(z: np.ndarray, cos: np.ndarray) -> np.ndarray:
            return np.zeros_like(z)

        slack = model.eye_uncertainty(ectx.origin_offset, ectx.eye_norm, ectx.point_norm)
        result = verify.classify_mismatches(
            ref.scene, r_ids, t_ids, rows, cols, eps, depth_tol or exact, ref.topology_cache, backend, slack
        )
        cls = result.cls
        explanations = result.groups
        tol_text += (
            "; tie: both triangles cover the center and their depths agree within the depth tolerance; "
            "crack: a leak through a closed edge (allowed only where the backend declares it)"
        )
        bad = np.nonzero(cls == verify.INTERIOR)[0][:EXAMPLES]
        if bad.size:
            details.append(
                "interior e.g. "
                + "; ".join(
                    f"({cols[k]},{rows[k]}) ref {_id(r_ids[k])} test {_id(t_ids[k])}: {result.why[k]}" for k in bad
                )
            )
        cracks = np.nonzero(cls == verify.CRACK)[0][:EXAMPLES]
        if cracks.size:
            details.append(
                "crack e.g. "
                + "; ".join(
                    f"({cols[k]},{rows[k]}) ref {_id(r_ids[k])} test {_id(t_ids[k])}: {result.why[k]}" for k in cracks
                )
            )
    classes.ravel()[idx] = cls
    edge_mask = (classes == verify.EDGE) | (classes == verify.TIE) | (classes == verify.CRACK)
    interior_mask = classes == verify.INTERIOR
    # id.object must follow id.prim: where the prims agree the objects must too.
    if "id.object" in ref.buffers and "id.object" in test:
        obj_bad = ~mism & (ref.buffers["id.object"] != test["id.object"])
        if obj_bad.any():
            interior_mask |= obj_bad
            oi = np.flatnonzero(obj_bad)
            y, x = oi[0] // w, oi[0] % w
            details.append(
                f"{oi.size} pixels with the same id.prim but a different id.object, e.g. ({x},{y}) "
                f"ref {_id(ref.buffers['id.object'][y, x])} test {_id(test['id.object'][y, x])}"
            )
            explanations.insert(
                0,
                {
                    "class": vocab.MismatchClass.INTERIOR,
                    "ref_prim": None,
                    "test_prim": None,
                    "pixels": int(oi.size),
                    "example": [int(x), int(y)],
                    "why": f"same prim, different object id (ref {_id(ref.buffers['id.object'][y, x])}, "
                    f"test {_id(test['id.object'][y, x])}): the exporter or renderer mislabels objects",
                },
            )
        tol_text += "; id.object must match wherever id.prim does"
    else:
        tol_text += "; id.object not compared (missing on one side)"
    return IdResult(
        int(np.count_nonzero(classes == verify.EDGE)),
        int(interior_mask.sum()),
        edge_mask,
        interior_mask,
        tol_text,
        details,
        tie=int(np.count_nonzero(classes == verify.TIE)),
        crack=int(np.count_nonzero(classes == verify.CRACK)),
        classes=classes,
        explanations=explanations,
    )


def _id(v: Any) -> str:
    v = int(v)
    return "bg" if v == BACKGROUND_ID else str(v)


def _dist(d: float) -> str:
    return "inf" if not math.isfinite(d) else f"{d:.3g}px"


# --------------------------------------------------------------------------- depth comparison


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
    if prims is not None:
        cos = ref.ray_cos(rows, cols, prims)
        t = ref.scene.triangles[prims.astype(np.int64)].astype(np.float64)
        extent = np.max(np.linalg.norm(t - np.roll(t, 1, axis=1), axis=2), axis=1)
        vz = (t - ref.scene.camera.eye[None, None, :]) @ ref.scene.camera.forward
        span = vz.max(axis=1) - vz.min(axis=1)
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
    )


def depth_tolerance_fn(
    ref: Reference, model: tolerance.Model, render: Mapping[str, Any], attrs: Mapping[str, Any]
) -> verify.DepthTolerance:
    """The test renderer's depth tolerance at (z, cos), for the verifier's tie test."""

    def tol(z: np.ndarray, cos: np.ndarray) -> np.ndarray:
        ctx = tolerance.DepthContext(
            z_ref=z,
            cos=cos,
            info=render_info(render),
            attrs=attrs,
            pixel_size=pixel_size(ref),
            point_norm=np.abs(z) + eye_norm(ref),
            origin_offset=origin_offset(ref),
            eye_norm=eye_norm(ref),
        )
        try:
            t, _ = model.depth(ctx)
        except tolerance.ToleranceError:
            return np.zeros_like(z)
        return np.broadcast_to(np.asarray(t, dtype=np.float64), z.shape)

    return tol


def compare_depth(
    ref: Reference,
    test: Mapping[str, np.ndarray],
    model: tolerance.Model,
    render: Mapping[str, Any],
    attrs: Mapping[str, Any],
    id_edge_mask: np.ndarray | None,
    id_classes: np.ndarray | None = None,
) -> DepthResult:
    """Hit/miss masks exact except at allowed ID classes; depth within the backend's model.

    With `id_classes` (the verifier's classes of the ID mismatches), a mask mismatch at an
    edge or tie pixel is allowed, at a crack pixel it is a crack, elsewhere interior.
    Without it, `id_edge_mask` marks the allowed pixels (the metamorphic comparison).
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

    if mask_mm.any():
        mi = np.flatnonzero(interior_mask & mask_mm)[:EXAMPLES]
        if mi.size:
            ex = ", ".join(f"({k % w},{k // w}) ref {zr.ravel()[k]:.7g} test {zt.ravel()[k]:.7g}" for k in mi)
            details.append(f"hit/miss mask mismatches e.g. {ex}")
    bi = np.nonzero(beyond)[0]
    if bi.size:
        worst = bi[np.argsort(-(err[bi] / np.maximum(tol[bi], 1e-300)))[:EXAMPLES]]
        ex = ", ".join(
            f"({cols[k]},{rows[k]}) ref {z_ref[k]:.9g} test {z_test[k]:.9g} |d| {err[k]:.3g} > tol {tol[k]:.3g}"
            for k in worst
        )
        details.append(f"{bi.size} depths beyond tolerance, worst {ex}")
    text = (
        f"{tol_text}; compared {scope}; hit/miss masks exact except where the ID mismatch is an allowed class "
        "(edge, tie; crack only where declared)"
    )
    if notes:
        text += "; " + "; ".join(notes)
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
    )


# --------------------------------------------------------------------------- normal comparison


def compare_normals(
    scene_name: str,
    backend: str,
    render: Mapping[str, Any],
    ref: Reference,
    buffers: Mapping[str, np.ndarray],
    exps: expectations.Expectations,
    spec: BackendSpec | None,
) -> Entry:
    """A backend's N (or the reference's own) against the winding convention: see `judge_normals`."""
    e = Entry.for_render(scene_name, backend, Buffer.N, render, N_FIELDS)
    e.pixels = ref.pixels
    judged = judge_normals(ref, backend, buffers, e, spec)
    if judged is not None:
        expectations.apply_verdict(e, exps, judged.details)
    return e


def judge_normals(
    ref: Reference, backend: str, buffers: Mapping[str, np.ndarray], e: Entry, spec: BackendSpec | None
) -> Judged | None:
    """N against the documented winding convention: N = normalize((b-a) x (c-a)).

    Judged at every pixel where the backend's own id.prim names a triangle (its
    visibility is judged by its id entry), so the reference's normals are checked too:
    a flipped, unnormalized or wrong-triangle normal is an interior mismatch.
    """
    h, w = ref.shape
    n = buffers.get("N")
    ids = buffers.get("id.prim")
    if n is None or ids is None:
        e.status = Status.SKIPPED
        e.reason = f"{backend} writes no N" if n is None else f"{backend} writes N but no id.prim to judge it by"
        return None
    prims = ids.ravel()
    valid = np.flatnonzero(prims.astype(np.uint64) < np.uint64(ref.scene.triangle_count))
    tris = ref.scene.triangles[prims[valid].astype(np.int64)].astype(np.float64)
    e1, e2 = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    cross = np.cross(e1, e2)
    length = np.linalg.norm(cross, axis=1)
    with np.errstate(all="ignore"):
        expect = cross / np.where(length > 0, length, 1.0)[:, None]
        cond = np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1) / length
    got = np.asarray(n, dtype=np.float64).reshape(-1, 3)[valid]
    got_len = np.linalg.norm(got, axis=1)
    with np.errstate(all="ignore"):
        cosang = np.einsum("ij,ij->i", got, expect) / got_len
        # atan2 of |cross| and dot is accurate at small angles, where acos is not.
        angle = np.arctan2(np.linalg.norm(np.cross(got, expect), axis=1) / got_len, cosang)
    angle = np.where(np.isfinite(angle) & (length > 0), angle, np.pi)
    tol, text = precision.normal_tolerance(spec, np.where(np.isfinite(cond), cond, np.inf))
    unit_ok = np.abs(got_len - 1.0) <= 4.0 * tolerance.F32_U + tol
    bad = ~(angle <= tol) | ~unit_ok
    e.compared_pixels = int(valid.size)
    e.interior_mismatches = int(bad.sum())
    e.max_angle_rad = (
        float(angle.max()) if valid.size and np.isfinite(angle.max()) else (0.0 if not valid.size else None)
    )
    e.tolerance = f"N: {text}; |N| = 1 within 4 * 2^-24; facing per the winding (b-a) x (c-a)"
    details = []
    if bad.any():
        k = np.nonzero(bad)[0][:EXAMPLES]
        ex = ", ".join(
            f"({valid[j] % w},{valid[j] // w}) prim {prims[valid[j]]} angle {angle[j]:.3g} rad (tol {tol[j]:.2g})"
            for j in k
        )
        flipped = int(np.count_nonzero(bad & (cosang < 0)))
        details.append(f"{int(bad.sum())} normals off, {flipped} of them facing the other way; e.g. {ex}")
        first = valid[k[0]]
        e.explanations = [
            {
                "class": vocab.MismatchClass.INTERIOR,
                "ref_prim": int(prims[first]),
                "test_prim": int(prims[first]),
                "pixels": int(bad.sum()),
                "example": [int(first % w), int(first // w)],
                "why": f"N is {angle[k[0]]:.3g} rad from normalize((b-a) x (c-a)) of the prim it names"
                + (" (flipped)" if cosang[k[0]] < 0 else ""),
            }
        ]
    return Judged(details)


# --------------------------------------------------------------------------- radiance comparison


def _side_dof(attrs: Mapping[str, Any], info: Mapping[str, Any] | None = None) -> float:
    return radiance.degrees_of_freedom({**(info or {}), **attrs})


def compare_rgb(
    ref: Reference,
    test: Mapping[str, np.ndarray],
    attrs: Mapping[str, Any],
    backend: str,
    render: Mapping[str, Any],
    id_edge_mask: np.ndarray | None,
    spec: BackendSpec | None,
) -> radiance.RgbResult:
    """Deterministic or statistical comparison of R,G,B (radiance.py decides by the var channels)."""
    a, b = test["RGB"], ref.buffers["RGB"]
    var_a, var_b = test.get("var"), ref.buffers.get("var")
    if var_a is not None or var_b is not None:
        test_attrs = {**render_info(render), **attrs}
        res = radiance.compare_statistical(
            b,
            var_b,
            _side_dof(ref.attrs) if var_b is not None else math.inf,
            a,
            var_a,
            _side_dof(attrs, render_info(render)) if var_a is not None else math.inf,
            ref_n=radiance.samples_per_pixel(ref.attrs),
            test_n=radiance.samples_per_pixel(test_attrs),
        )
        if var_a is None or var_b is None:
            side = backend if var_a is None else "the reference"
            res.notes.append(f"{side} has no var channels: its values count as exact in the statistical test")
        return res
    model = precision.rgb_tolerance(spec, backend, b, attrs, render_info(render))
    shadow_edges: radiance.ShadowEdges | None = None
    scene = ref.scene
    if "shadows" in scene.requires and "id.prim" in ref.buffers and "Z" in ref.buffers:
        eps = radiance.SHADOW_EDGE_REL * lighting.scene_size(scene)

        def ambiguous(rows: np.ndarray, cols: np.ndarray) -> np.ndarray | None:
            return lighting.shadow_ambiguity(scene, ref.buffers["id.prim"], ref.buffers["Z"], rows, cols, eps)

        shadow_edges = ambiguous

    text = model.text
    if shadow_edges is not None:
        text += (
            f"; failing pixels at ID edge mismatches, or whose shadow ray passes within "
            f"{radiance.SHADOW_EDGE_REL:g} x scene size of an occluder edge or end, count as edge"
        )
    else:
        text += "; failing pixels at ID edge mismatches count as edge"
    return radiance.compare_deterministic(b, a, model.abs_tol, model.rel, text, id_edge_mask, shadow_edges)


def record_rgb(e: Entry, res: radiance.RgbResult, ref_rgb: np.ndarray, test_rgb: np.ndarray) -> Judged:
    """Fill an RGB entry from radiance.py's result (FLIP too); the heat map shows |a-b|/tol."""
    e.mode = res.mode
    e.edge_mismatches = res.edge
    e.interior_mismatches = res.interior
    e.failing_pixels = res.failing_pixels
    e.compared_pixels = res.pixels
    e.max_abs_error = finite(res.max_abs)
    e.mean_abs_error = finite(res.mean_abs)
    e.max_rel_error = finite(res.max_rel)
    e.tolerance = res.tolerance
    e.min_p = None if res.min_p is None else float(res.min_p)
    e.alpha = res.alpha
    e.cluster_failures = res.cluster_failures
    e.flip_mean, e.flip_note = radiance.flip_mean(ref_rgb, test_rgb)

    def heat_map(path: Path) -> None:
        diffimages.write_rgb_diff(path, res.score, res.edge_mask, res.fail_mask & ~res.edge_mask)

    return Judged(res.details, res.notes, heat_map)


# --------------------------------------------------------------------------- the buffer table


@dataclass
class BackendRender:
    """One ok render of one backend, read and ready to compare buffer by buffer."""

    run: Path
    scene: str
    backend: str
    render: Mapping[str, Any]
    ref: Reference
    test: Mapping[str, np.ndarray]
    attrs: Mapping[str, Any]
    exr: Path
    model: tolerance.Model
    spec: BackendSpec | None  # its precision (None: it has none, and is compared exactly)
    declared: set[str] | None  # the buffers the manifest says it wrote (None: it does not say)
    diff_dir: Path | None  # where heat maps go (None: none are written)
    id_result: IdResult | None = None  # the id comparison, once done (Z and RGB use its classes)


@dataclass
class Judged:
    """A buffer compared, its counts already in its entry: what the verdict and the heat map need."""

    details: list[str]  # examples of mismatches, for the reason of a failing verdict
    notes: list[str] = field(default_factory=list)  # always added to the reason, after the verdict
    heat_map: Callable[[Path], None] | None = None  # writes the diff PNG at the path given


Judge = Callable[[BackendRender, Entry], Judged | None]
"""Compares one buffer of a render and fills the entry's counts; None: the entry is final
(its reason says why it was not compared)."""


def judge_ids(r: BackendRender, e: Entry) -> Judged:
    res = compare_ids(
        r.ref, r.test, r.model, depth_tol=depth_tolerance_fn(r.ref, r.model, r.render, r.attrs), backend=r.backend
    )
    r.id_result = res
    e.edge_mismatches = res.edge
    e.tie_mismatches = res.tie
    e.crack_mismatches = res.crack
    e.interior_mismatches = res.interior
    e.tolerance = res.tolerance
    e.explanations = res.explanations
    notes = (
        []
        if r.model.known
        else [f"no precision model for {r.backend} in the registry (renderers/registry.py): compared exactly"]
    )
    ref_ids, test_ids = r.ref.buffers["id.prim"], r.test["id.prim"]

    def heat_map(path: Path) -> None:
        diffimages.write_id_diff(path, ref_ids, test_ids, res.edge_mask, res.interior_mask)

    return Judged(res.details, notes, heat_map)


def judge_depth(r: BackendRender, e: Entry) -> Judged | None:
    ids = r.id_result
    try:
        res = compare_depth(
            r.ref,
            r.test,
            r.model,
            r.render,
            r.attrs,
            ids.edge_mask if ids is not None else None,
            ids.classes if ids is not None else None,
        )
    except tolerance.ToleranceError as exc:
        e.reason = str(exc)
        return None
    e.edge_mismatches = res.edge
    e.tie_mismatches = res.tie
    e.crack_mismatches = res.crack
    e.interior_mismatches = res.interior
    e.mask_mismatches = res.mask
    e.compared_pixels = res.compared
    e.max_abs_error = finite(res.max_abs)
    e.mean_abs_error = finite(res.mean_abs)
    e.max_rel_error = finite(res.max_rel)
    e.tolerance = res.tolerance
    ref_z, test_z = r.ref.buffers["Z"], r.test["Z"]

    def heat_map(path: Path) -> None:
        diffimages.write_depth_diff(path, ref_z, test_z, res.max_abs)

    return Judged(res.details, heat_map=heat_map)


def judge_rendered_normals(r: BackendRender, e: Entry) -> Judged | None:
    return judge_normals(r.ref, r.backend, r.test, e, r.spec)


def judge_rgb(r: BackendRender, e: Entry) -> Judged | None:
    ids = r.id_result
    try:
        res = compare_rgb(
            r.ref, r.test, r.attrs, r.backend, r.render, ids.edge_mask if ids is not None else None, r.spec
        )
    except (tolerance.ToleranceError, radiance.RadianceError) as exc:
        e.reason = str(exc)
        return None
    return record_rgb(e, res, r.ref.buffers["RGB"], r.test["RGB"])


class When(StrEnum):
    """When a buffer has an entry for a render."""

    ALWAYS = "always"  # every render of every scene
    SHADED = "shaded"  # scenes that require shading (vocab.SHADED_FEATURES)
    WRITTEN = "written"  # renders whose EXR has the buffer's channel


@dataclass(frozen=True)
class BufferSpec:
    """How one buffer is compared: a row of `BUFFER_TABLE`."""

    buffer: Buffer
    when: When
    channel: str  # the exrbuf key that holds it, in the test EXR (and the reference's)
    channel_text: str  # that channel in "the EXR has no ..." when a declared buffer lacks it
    ref_missing: str | None  # the reason when the reference lacks `channel`; None: not read from the reference
    judge: Judge
    fields: tuple[str, ...] = ()  # its entry's own fields after `images` (results.Entry.own_fields)
    skip_reason_from_render: bool = False  # a skipped entry gives the render's own reason, if any


N_FIELDS = ("max_angle_rad", "explanations")
RGB_ENTRY_FIELDS = ("mode", "failing_pixels", "min_p", "alpha", "cluster_failures", "flip_mean", "flip_note")

BUFFER_TABLE: tuple[BufferSpec, ...] = (
    BufferSpec(
        Buffer.ID,
        When.ALWAYS,
        "id.prim",
        "id.prim channel",
        "reference has no id.prim channel",
        judge_ids,
        fields=("explanations",),
    ),
    BufferSpec(Buffer.Z, When.ALWAYS, "Z", "Z channel", "reference has no Z channel", judge_depth),
    BufferSpec(Buffer.N, When.WRITTEN, "N", "N channel", None, judge_rendered_normals, fields=N_FIELDS),
    BufferSpec(
        Buffer.RGB,
        When.SHADED,
        "RGB",
        "R,G,B channels",
        "reference has no R,G,B channels (the scene requires shading)",
        judge_rgb,
        fields=RGB_ENTRY_FIELDS,
        skip_reason_from_render=True,
    ),
)
"""Every buffer compared, in the order of its entries for each render."""

BUFFER_FIELDS: dict[str, tuple[str, ...]] = {spec.buffer: spec.fields for spec in BUFFER_TABLE}
BUFFERS = tuple(spec.buffer for spec in BUFFER_TABLE if spec.when == When.ALWAYS)
"""The entries of a render that was not compared (skipped, error) in a scene without shading."""
SHADED_BUFFERS = tuple(spec.buffer for spec in BUFFER_TABLE if spec.when in (When.ALWAYS, When.SHADED))
"""The same in a scene that requires shading."""


def applies(spec: BufferSpec, r: BackendRender) -> bool:
    if spec.when == When.SHADED:
        return is_shaded(r.ref.scene.requires)
    if spec.when == When.WRITTEN:
        return spec.channel in r.test
    return True


def compare_buffer(spec: BufferSpec, r: BackendRender, exps: expectations.Expectations) -> Entry:
    """One buffer's entry: skipped/error when a side lacks it, else compared and judged."""
    e = Entry.for_render(r.scene, r.backend, spec.buffer, r.render, spec.fields)
    e.pixels = r.ref.pixels
    if spec.channel not in r.test:
        if r.declared is not None and spec.buffer in r.declared:
            e.reason = f"{r.exr}: manifest lists buffer {spec.buffer} but the EXR has no {spec.channel_text}"
        else:
            e.status = Status.SKIPPED
            own = str(r.render.get("reason") or "") if spec.skip_reason_from_render else ""
            e.reason = own or f"{r.backend} does not produce {spec.buffer}"
    elif spec.ref_missing is not None and spec.channel not in r.ref.buffers:
        e.reason = spec.ref_missing
    else:
        judged = spec.judge(r, e)
        if judged is not None:
            finish(e, judged, exps, r.run, r.diff_dir)
    return e


def finish(e: Entry, judged: Judged, exps: expectations.Expectations, run: Path, diff_dir: Path | None) -> None:
    """The verdict, the notes, and the heat map RUN/scenes/<scene>/diff/<backend>.<buffer>.png."""
    expectations.apply_verdict(e, exps, judged.details)
    for note in judged.notes:
        e.add_reason(note)
    if diff_dir is None or judged.heat_map is None:
        return
    path = diff_dir / f"{e.backend}.{e.buffer}.png"
    try:
        judged.heat_map(path)
        e.images = {"heat": path.relative_to(run).as_posix()}
    except diffimages.DiffImageError as exc:
        e.add_reason(f"diff image not written: {exc}")


# --------------------------------------------------------------------------- one backend


def compare_backend(
    run: Path,
    scene_name: str,
    render: Mapping[str, Any],
    ref: Reference,
    exps: expectations.Expectations,
    images: bool,
    spec: BackendSpec | None,
) -> list[Entry]:
    """The entries of one ok render of one backend: one per applicable row of BUFFER_TABLE."""
    backend = render["backend"]
    model = precision.depth_model(spec, backend)
    got = read_test_buffers(run, render, ref)
    diff_dir = None
    if images and _SAFE_NAME.match(scene_name) and _SAFE_NAME.match(backend):
        diff_dir = run / "scenes" / scene_name / "diff"
    r = BackendRender(
        run,
        scene_name,
        backend,
        render,
        ref,
        got.buffers,
        got.attrs,
        got.exr,
        model,
        spec,
        declared_buffers(render),
        diff_dir,
    )
    return [compare_buffer(spec, r, exps) for spec in BUFFER_TABLE if applies(spec, r)]


def buffers_for(scene_entry: Mapping[str, Any]) -> tuple[str, ...]:
    return SHADED_BUFFERS if is_shaded(scene_entry.get("requires")) else BUFFERS


def status_entries(
    scene: str, render: Mapping[str, Any], status: str, reason: str, buffers: Sequence[str] = BUFFERS
) -> list[Entry]:
    """A render that was not compared: one entry per buffer, each with its status and reason."""
    backend = str(render.get("backend", "?"))
    return [
        Entry.for_render(scene, backend, buf, render, BUFFER_FIELDS.get(buf, ()), status=status, reason=reason)
        for buf in buffers
    ]


# --------------------------------------------------------------------------- one scene


def compare_scene(
    run: Path,
    scene_entry: Mapping[str, Any],
    reference: str,
    exps: expectations.Expectations,
    specs: SpecLookup,
    images: bool = True,
    references_dir: Path | None = None,
) -> list[Entry]:
    """Every entry of one scene; each backend judged with its spec (`specs`)."""
    name = scene_entry["scene"]
    renders = [r for r in scene_entry.get("renders", []) if r.get("backend") != reference]
    bufs = buffers_for(scene_entry)
    try:
        ref = load_reference(run, scene_entry, reference)
    except EntryError as exc:
        out = []
        own_ref = [r for r in scene_entry.get("renders", []) if r.get("backend") == reference]
        if not renders or (own_ref and own_ref[0].get("status") == vocab.RenderStatus.ERROR):
            # The scene itself failed (it could not be loaded, or the reference could not
            # render it): one `scene` entry, so a broken scene can never look like a pass.
            out.append(Entry.for_render(name, reference, Buffer.SCENE, own_ref[0] if own_ref else {}, reason=str(exc)))
        for r in renders:
            own = (
                ""
                if r.get("status") == vocab.RenderStatus.OK
                else f" ({r['backend']} itself {r.get('status')}: {render_reason(r)})"
            )
            out += status_entries(name, r, Status.ERROR, f"{exc}{own}", bufs)
        return [e.blank_if_not_compared() for e in out]
    if is_shaded(ref.scene.requires):
        bufs = SHADED_BUFFERS
    results: list[Entry] = []
    if "N" in ref.buffers:  # the reference's own normals, against the winding convention
        own = [r for r in scene_entry.get("renders", []) if r.get("backend") == reference][0]
        results.append(compare_normals(name, reference, own, ref, ref.buffers, exps, specs(reference)))
    for r in renders:
        status = r.get("status")
        if status in (vocab.RenderStatus.SKIPPED, vocab.RenderStatus.ERROR):
            results += status_entries(name, r, status, render_reason(r), bufs)
            continue
        try:
            results += compare_backend(run, name, r, ref, exps, images, specs(r["backend"]))
        except EntryError as exc:
            results += status_entries(name, r, Status.ERROR, str(exc), bufs)
        except Exception as exc:  # noqa: BLE001 - a bug must not lose the other results
            traceback.print_exc(file=sys.stderr)
            results += status_entries(
                name, r, Status.ERROR, f"internal error in compare (a rendiff bug): {type(exc).__name__}: {exc}", bufs
            )
    if references_dir is not None and vocab.Feature.GLOBAL_ILLUMINATION in ref.scene.requires:
        results.append(compare_cached_reference(run, name, ref, references_dir, exps, images, specs))
    return [e.blank_if_not_compared() for e in results]


def compare_cached_reference(
    run: Path,
    name: str,
    ref: Reference,
    references_dir: Path,
    exps: expectations.Expectations,
    images: bool,
    specs: SpecLookup,
) -> Entry:
    """The reference render's RGB against the cached Mitsuba reference DIR/<name>.exr (references.py)."""
    from . import references

    exr = references_dir / f"{name}.exr"
    render = {"backend": CACHED_REFERENCE_BACKEND, "command": references.regenerate_command(ref.scene.directory, exr)}
    e = Entry.for_render(name, CACHED_REFERENCE_BACKEND, Buffer.RGB, render, RGB_ENTRY_FIELDS)
    e.pixels = ref.pixels
    try:
        cached = references.load(exr, ref.scene)
    except references.ReferenceError as exc:
        e.reason = str(exc)
        return e
    e.version = cached.provenance.get("renderer")
    if "RGB" not in ref.buffers:
        e.reason = "reference has no R,G,B channels (the scene requires shading)"
        return e
    test = {"RGB": cached.rgb, "var": cached.var}
    try:
        res = compare_rgb(
            ref, test, cached.attrs, CACHED_REFERENCE_BACKEND, render, None, specs(CACHED_REFERENCE_BACKEND)
        )
    except (tolerance.ToleranceError, radiance.RadianceError) as exc:
        e.reason = str(exc)
        return e
    judged = record_rgb(e, res, ref.buffers["RGB"], cached.rgb)
    diff_dir = run / "scenes" / name / "diff" if images and _SAFE_NAME.match(name) else None
    finish(e, judged, exps, run, diff_dir)
    return e


# --------------------------------------------------------------------------- a run


def calibrate(
    run: Path, manifest: Mapping[str, Any], results: list[Entry]
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Camera calibration from the run's probe scenes (calibration.py): returns the summary
    for results.json's `calibration` and the `camera` entries that follow `results`.

    A backend whose camera fails calibration has a convention error in its exporter, not a
    renderer bug in every scene: its failing verdicts elsewhere become `error` entries that
    say so, by name, instead of fails blamed on the renderer.
    """
    from .judge import calibration

    try:
        rep = calibration.calibrate_run(run, manifest, registry.spec)
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
    return rep.summary, rep.entries


_PROCESS_EXPECTATIONS: dict[str, expectations.Expectations] = {}
"""A comparing process's own copy of the expectations, loaded once per process (`_scene_task`)."""


def _scene_task(
    run: Path,
    scene_entry: Mapping[str, Any],
    reference: str,
    expectations_path: str | Path | None,
    images: bool,
    references_dir: Path | None,
) -> tuple[list[Entry], set[int]]:
    """One scene in a pool process: its entries and the expectations it used."""
    key = str(expectations_path)
    if key not in _PROCESS_EXPECTATIONS:
        _PROCESS_EXPECTATIONS[key] = expectations.load(expectations_path)
    exps = _PROCESS_EXPECTATIONS[key]
    exps.used.clear()
    entries = compare_scene(run, scene_entry, reference, exps, registry.spec, images, references_dir)
    return entries, set(exps.used)


def _scene_cost(scene_entry: Mapping[str, Any]) -> float:
    """How long a scene took to render (all backends): its comparison grows with the same size."""
    return float(sum(float(r.get("time_s") or 0.0) for r in scene_entry.get("renders", [])))


def compare_scenes(
    run: Path,
    scenes: Sequence[Mapping[str, Any]],
    reference: str,
    expectations_path: str | Path | None,
    exps: expectations.Expectations,
    images: bool,
    references_dir: Path | None,
    jobs: int,
) -> list[Entry]:
    """Every scene's entries, in manifest order. Scenes are independent, so with `jobs` > 1
    they are compared in that many processes (fresh interpreters: `spawn`, never a fork of a
    process holding OpenImageIO's threads), the costliest first; `exps.used` gathers what
    each process matched, so unused expectations are reported as in a sequential run."""
    if jobs <= 1 or len(scenes) <= 1:
        out: list[Entry] = []
        for sc in scenes:
            out += compare_scene(run, sc, reference, exps, registry.spec, images, references_dir)
        return out
    order = sorted(range(len(scenes)), key=lambda i: -_scene_cost(scenes[i]))
    done: dict[int, list[Entry]] = {}
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=min(jobs, len(scenes)), mp_context=context) as pool:
        futures = {
            i: pool.submit(_scene_task, run, scenes[i], reference, expectations_path, images, references_dir)
            for i in order
        }
        for i, future in futures.items():
            entries, used = future.result()
            done[i] = entries
            exps.used |= used
    return [e for i in range(len(scenes)) for e in done[i]]


def run_compare(
    run: Path,
    expectations_path: str | Path | None,
    images: bool = True,
    references_dir: str | Path | None = None,
    jobs: int = 1,
) -> dict[str, Any]:
    """Compare everything in RUN and write results.json; returns the results document.

    Raises ManifestError / expectations.ExpectationsError for unusable inputs.
    """
    manifest = load_manifest(run)
    exps = expectations.load(expectations_path)
    reference = manifest.get("reference", "raster")
    refs = Path(references_dir) if references_dir is not None else None
    entries = compare_scenes(run, manifest["scenes"], reference, expectations_path, exps, images, refs, jobs)
    summary, camera = calibrate(run, manifest, entries)
    doc = document(reference, summary, expectations_path, exps.unused(), [e.to_json() for e in entries] + camera)
    write_results(run, doc)
    return doc


# --------------------------------------------------------------------------- CLI


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m rendiff_harness compare",
        description="Compare a check run's buffers with the reference; write RUN/results.json.",
    )
    p.add_argument("--run", required=True, help="run folder holding manifest.json (written by `rendiff check`)")
    p.add_argument(
        "--expectations", default=None, help="expectations TOML (e.g. tests/expectations.toml); default: none"
    )
    p.add_argument("--no-images", action="store_true", help="do not write diff PNGs")
    p.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="compare this many scenes at a time, in processes of their own (default 1: all in this "
        "process; `rendiff check` passes its --jobs)",
    )
    p.add_argument(
        "--references",
        default=None,
        help="folder of cached Mitsuba references (<scene>.exr + <scene>.json, e.g. tests/references): "
        "global-illumination scenes are also compared with them, as backend mitsuba_ref",
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args_in = list(sys.argv[1:] if argv is None else argv)
    if args_in[:1] == ["--"]:  # `python -m rendiff_harness compare -- --run RUN`
        args_in = args_in[1:]
    args = build_parser().parse_args(args_in)
    run = Path(args.run)
    t0 = time.monotonic()
    if not run.is_dir():
        print(f"rendiff_harness compare: {printable(str(run))}: run folder does not exist", file=sys.stderr)
        return EXIT_ERROR
    try:
        doc = run_compare(
            run, args.expectations, images=not args.no_images, references_dir=args.references, jobs=max(args.jobs, 1)
        )
    except (ManifestError, expectations.ExpectationsError) as exc:
        print(f"rendiff_harness compare: {printable(str(exc))}", file=sys.stderr)
        return EXIT_ERROR
    except OSError as exc:
        where = run / "results.json"
        print(f"rendiff_harness compare: {printable(f'{where}: cannot write: {exc}')}", file=sys.stderr)
        return EXIT_ERROR
    print(format_table(doc["results"]))
    unused = doc["unused_expectations"]
    if unused:
        listed = ", ".join(f"{u['entry']} ({u['scene']}/{u['backend']}/{u['buffer']})" for u in unused)
        print(f"note: expectations matched by no compared result: {listed}", file=sys.stderr)
    # stdout holds the verdict table alone (`rendiff check` prints it); this line is a message.
    print(f"results: {run / 'results.json'} ({time.monotonic() - t0:.1f} s)", file=sys.stderr)
    return EXIT_OK
