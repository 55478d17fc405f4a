"""`python -m rendiff_harness compare --run RUN [--expectations FILE]`: buffers -> results.json.

Reads RUN/manifest.json (docs/run-format.md, written by `rendiff check`), compares every
backend's buffers with the reference's (`reference`, normally "raster") for the `id` and
`Z` buffers, writes RUN/results.json atomically and RUN/scenes/<scene>/diff/*.png, and
prints a compact table. The Rust side decides pass/fail from results.json, so this exits
0 whenever it could write results; 2 when the manifest (or the expectations file, or
results.json itself) cannot be read/written, with one line naming the file.

What is compared (docs/DESIGN.md "Comparing"):

* `id`: id.prim read exactly as u32. A mismatch is a pixel whose prim differs
  (background 0xFFFFFFFF is a value). Each mismatch is *edge* when the pixel center lies
  within the backend's edge tolerance (tolerance.py) of an edge of the reference's or
  the test's triangle (classify.py), else *interior*. An ID naming no triangle, and an
  id.object that differs where id.prim agrees, are interior mismatches.
* `Z`: the hit/miss masks (finite vs not) must agree exactly: a mask mismatch at a pixel
  that is an ID edge mismatch counts as edge, elsewhere as interior. Depth is compared
  where both sides hit the same prim, against the backend's tolerance model
  (tolerance.py); pixels beyond it are interior mismatches.
* `RGB` (scenes that require `lambert`, `emission` or `global_illumination` only):
  radiance.py. Deterministic renders (no var.* channels): |a - b| <= abs + rel |b| with
  the test backend's precision (tolerance.rgb_model); failing pixels at ID edge
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
import json
import math
import re
import sys
import time
import traceback
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import atomic, diffimages, expectations, exrbuf, lighting, radiance, resolved, tolerance, verify, vocab

MANIFEST_FORMAT = "rendiff-manifest/1"
RESULTS_FORMAT = "rendiff-results/1"
BUFFERS = ("id", "Z")
SHADED_BUFFERS = ("id", "Z", "RGB")
SHADING_FEATURES = frozenset(f.value for f in vocab.SHADED_FEATURES)
CACHED_REFERENCE_BACKEND = "mitsuba_ref"
RGB_FIELDS = ("failing_pixels", "min_p", "alpha", "cluster_failures", "flip_mean")
BACKGROUND_ID = exrbuf.BACKGROUND_ID
EXAMPLES = 3  # example pixels quoted in a failure's reason
EXIT_OK, EXIT_ERROR = 0, 2
_SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._+-]*$")


class ManifestError(Exception):
    """manifest.json cannot be used at all; the message names the file."""


class EntryError(Exception):
    """One scene/backend cannot be compared; becomes `error` entries with this reason."""


# --------------------------------------------------------------------------- manifest


def load_manifest(run: Path) -> dict[str, Any]:
    """Read and structurally validate RUN/manifest.json; ManifestError names the file."""
    path = run / "manifest.json"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ManifestError(f"{path}: missing (run `rendiff check` first)") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ManifestError(f"{path}: unreadable: {exc}") from None
    except json.JSONDecodeError as exc:
        raise ManifestError(f"{path}: not valid JSON: {exc}") from None
    if not isinstance(data, dict):
        raise ManifestError(f"{path}: must be a JSON object")
    if data.get("format") != MANIFEST_FORMAT:
        raise ManifestError(f"{path}: format is {data.get('format')!r}, expected {MANIFEST_FORMAT!r}")
    reference = data.get("reference", "raster")
    if not isinstance(reference, str) or not reference:
        raise ManifestError(f"{path}: 'reference' must be a backend name, got {reference!r}")
    scenes = data.get("scenes")
    if not isinstance(scenes, list):
        raise ManifestError(f"{path}: 'scenes' must be a list")
    for i, sc in enumerate(scenes):
        if not isinstance(sc, dict) or not isinstance(sc.get("scene"), str) or not sc["scene"]:
            raise ManifestError(f"{path}: scenes[{i}] must be an object with a 'scene' name")
        renders = sc.get("renders", [])
        if not isinstance(renders, list):
            raise ManifestError(f"{path}: scenes[{i}] ({sc['scene']}): 'renders' must be a list")
        for j, r in enumerate(renders):
            if not isinstance(r, dict) or not isinstance(r.get("backend"), str) or not r["backend"]:
                raise ManifestError(
                    f"{path}: scenes[{i}] ({sc['scene']}).renders[{j}] must be an object with a 'backend' name"
                )
            if r.get("status") not in ("ok", "skipped", "error"):
                raise ManifestError(
                    f"{path}: scenes[{i}] ({sc['scene']}).renders[{j}] ({r['backend']}): "
                    f"status must be ok, skipped or error, got {r.get('status')!r}"
                )
    return data


def run_path(run: Path, rel: Any, what: str) -> Path:
    """A manifest path (relative to RUN, never escaping it) as a real path; EntryError if bad."""
    if not isinstance(rel, str) or not rel:
        raise EntryError(f"{what}: no path in manifest.json")
    p = Path(rel)
    if p.is_absolute() or ".." in p.parts:
        raise EntryError(f"{what}: path {rel!r} in manifest.json must be relative to the run folder")
    return run / p


# --------------------------------------------------------------------------- entries


def _finite(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def base_entry(scene: str, backend: str, buffer: str, render: Mapping[str, Any]) -> dict[str, Any]:
    """A results.json entry with every field present and the render's time/version/command.

    Counts start at 0; `blank_if_not_compared` nulls them when the entry ends skipped/error.
    """
    t = render.get("time_s")
    return {
        "scene": scene,
        "backend": backend,
        "buffer": buffer,
        "status": "error",
        "reason": "",
        "pixels": 0,
        "edge_mismatches": 0,
        "tie_mismatches": 0,
        "crack_mismatches": 0,
        "interior_mismatches": 0,
        "mask_mismatches": 0,
        "max_abs_error": 0.0,
        "mean_abs_error": 0.0,
        "max_rel_error": 0.0,
        "compared_pixels": 0,
        "tolerance": "",
        "bound": None,
        "time_s": _finite(t) if isinstance(t, (int, float)) and not isinstance(t, bool) else None,
        "version": render.get("version") if isinstance(render.get("version"), str) else None,
        "command": render.get("command") if isinstance(render.get("command"), str) else None,
        "images": {},
    }


NUMERIC_FIELDS = (
    "pixels",
    "edge_mismatches",
    "tie_mismatches",
    "crack_mismatches",
    "interior_mismatches",
    "mask_mismatches",
    "max_abs_error",
    "mean_abs_error",
    "max_rel_error",
    "compared_pixels",
)


def blank_if_not_compared(entry: dict[str, Any]) -> dict[str, Any]:
    """Skipped and error entries carry null counts: "not compared", never "0 mismatches"."""
    if entry["status"] in ("skipped", "error"):
        for k in NUMERIC_FIELDS:
            entry[k] = None
        if entry["buffer"] == "RGB":
            for k in RGB_FIELDS:
                entry[k] = None
    return entry


def is_shaded(requires: Any) -> bool:
    """A scene whose buffers include radiance (docs/radiance.md)."""
    return isinstance(requires, (list, tuple, set, frozenset)) and vocab.needs_shading(requires)


def buffers_for(scene_entry: Mapping[str, Any]) -> tuple[str, ...]:
    return SHADED_BUFFERS if is_shaded(scene_entry.get("requires")) else BUFFERS


def rgb_entry(scene: str, backend: str, render: Mapping[str, Any]) -> dict[str, Any]:
    e = base_entry(scene, backend, "RGB", render)
    e.update(mode=None, failing_pixels=0, min_p=None, alpha=None, cluster_failures=None, flip_mean=None, flip_note="")
    return e


def status_entries(
    scene: str, render: Mapping[str, Any], status: str, reason: str, buffers: Sequence[str] = BUFFERS
) -> list[dict[str, Any]]:
    out = []
    for buf in buffers:
        if buf == "RGB":
            e = rgb_entry(scene, str(render.get("backend", "?")), render)
            e["status"] = status
            e["reason"] = reason
            out.append(e)
            continue
        e = base_entry(scene, str(render.get("backend", "?")), buf, render)
        e["status"] = status
        e["reason"] = reason
        out.append(e)
    return out


def _render_reason(render: Mapping[str, Any]) -> str:
    if render.get("status") == "skipped":
        return str(render.get("reason") or "skipped (no reason given)")
    return str(render.get("message") or render.get("reason") or "error (no message given)")


# --------------------------------------------------------------------------- reference data


@dataclass
class Reference:
    scene: resolved.ResolvedScene
    buffers: dict[str, np.ndarray]
    shape: tuple[int, int]
    _normals: np.ndarray | None = field(default=None, repr=False)
    attrs: dict[str, Any] = field(default_factory=dict)
    path: Path | None = None
    topology_cache: dict[str, Any] = field(default_factory=dict, repr=False)

    def unit_normals(self) -> np.ndarray:
        """(N, 3) float64 unit normals of every triangle (zero for degenerate ones)."""
        if self._normals is None:
            t = self.scene.triangles.astype(np.float64)
            n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
            length = np.linalg.norm(n, axis=1)
            with np.errstate(all="ignore"):
                self._normals = np.where(length[:, None] > 0, n / np.where(length > 0, length, 1.0)[:, None], 0.0)
        return self._normals

    def ray_cos(self, rows: np.ndarray, cols: np.ndarray, prims: np.ndarray) -> np.ndarray:
        """|cos| between the pixel rays and the triangles' normals, (K,) float64 in [0, 1]."""
        cam = self.scene.camera
        w, h = cam.width, cam.height
        sx = (2.0 * (cols + 0.5) / w - 1.0) * cam.tan_half_vfov * (w / h)
        sy = (1.0 - 2.0 * (rows + 0.5) / h) * cam.tan_half_vfov
        d = cam.forward[None, :] + sx[:, None] * cam.right[None, :] + sy[:, None] * cam.up_ortho[None, :]
        n = self.unit_normals()[prims.astype(np.int64)]
        cos: np.ndarray = np.clip(np.abs(np.einsum("ij,ij->i", d, n)) / np.linalg.norm(d, axis=1), 0.0, 1.0)
        return cos


def load_reference(run: Path, scene_entry: Mapping[str, Any], reference: str) -> Reference:
    """Resolved scene + reference buffers for one scene; EntryError with the reason otherwise."""
    name = scene_entry["scene"]
    refs = [r for r in scene_entry.get("renders", []) if r.get("backend") == reference]
    if not refs:
        raise EntryError(f"reference {reference} has no render for scene {name} in manifest.json")
    ref = refs[0]
    if ref.get("status") != "ok":
        raise EntryError(f"reference {reference} {ref.get('status')}: {_render_reason(ref)}")
    try:
        scene = resolved.load(run_path(run, scene_entry.get("resolved"), "resolved scene"))
    except EntryError:
        raise
    except Exception as exc:  # noqa: BLE001 - SceneError or a malformed scene.json
        raise EntryError(f"cannot load the resolved scene: {type(exc).__name__}: {exc}") from None
    exr = run_path(run, ref.get("exr"), f"reference {reference} EXR")
    try:
        buffers = exrbuf.read_buffers(exr)
    except exrbuf.BufferError as exc:
        raise EntryError(f"reference {reference} unreadable: {exc}") from None
    try:
        attrs = dict(exrbuf.read_attrs(exr))
    except exrbuf.BufferError:
        attrs = {}
    cam = scene.camera
    shape = (cam.height, cam.width)
    for key, arr in buffers.items():
        if arr.shape[:2] != shape:
            raise EntryError(
                f"reference {reference} {exr}: {key} is {arr.shape[1]}x{arr.shape[0]}, "
                f"the scene's camera is {cam.width}x{cam.height}"
            )
    return Reference(scene, buffers, shape, attrs=attrs, path=exr)


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
    return 2.0 * ref.scene.camera.tan_half_vfov / ref.scene.camera.height


def point_norm(ref: Reference, rows: np.ndarray, cols: np.ndarray, z: np.ndarray) -> np.ndarray:
    """|X| of the points at planar depth z along pixel rays (distance from the world origin)."""
    cam = ref.scene.camera
    w, h = cam.width, cam.height
    sx = (2.0 * (cols + 0.5) / w - 1.0) * cam.tan_half_vfov * (w / h)
    sy = (1.0 - 2.0 * (rows + 0.5) / h) * cam.tan_half_vfov
    d = cam.forward[None, :] + sx[:, None] * cam.right[None, :] + sy[:, None] * cam.up_ortho[None, :]
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
                    "class": "interior",
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
        info=_info(render),
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
            info=_info(render),
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
    hr, ht = np.isfinite(zr), np.isfinite(zt)
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


def _info(render: Mapping[str, Any]) -> Mapping[str, Any]:
    info = render.get("info")
    return info if isinstance(info, dict) else {}


# --------------------------------------------------------------------------- one backend


def _declared_buffers(render: Mapping[str, Any]) -> set[str] | None:
    b = render.get("buffers")
    if isinstance(b, list) and all(isinstance(x, str) for x in b):
        return set(b)
    return None


def _apply_verdict(entry: dict[str, Any], exps: expectations.Expectations, details: list[str]) -> None:
    exp = exps.lookup(entry["scene"], entry["backend"], entry["buffer"])
    counts = {k: int(entry.get(k) or 0) for k in expectations.COUNT_KEYS}
    declared = exps.declared(entry["backend"], "crack")
    verdict = expectations.evaluate(counts, exp, cracks_allowed=declared is not None)
    entry["status"] = verdict.status
    if exp is not None:
        entry["bound"] = exp.bound_json()
    parts = [verdict.reason] if verdict.reason else []
    if verdict.status in (vocab.Status.FAIL, vocab.Status.EXPECTED_FAIL, vocab.Status.UNEXPECTED_PASS):
        parts += details
    if declared is not None and int(entry.get("crack_mismatches") or 0) > 0:
        parts.append(f"cracks allowed: {declared.reason} (declaration {declared.index})")
    entry["reason"] = "; ".join(parts)


def _add_reason(entry: dict[str, Any], note: str) -> None:
    entry["reason"] = f"{entry['reason']}; {note}" if entry["reason"] else note


def compare_backend(
    run: Path,
    scene_name: str,
    render: Mapping[str, Any],
    ref: Reference,
    exps: expectations.Expectations,
    images: bool,
) -> list[dict[str, Any]]:
    """The entries (id, Z, and RGB for shaded scenes) for one ok render of one backend."""
    backend = render["backend"]
    model = tolerance.model_for(backend)
    exr = run_path(run, render.get("exr"), f"{backend} EXR")
    try:
        test = exrbuf.read_buffers(exr)
    except exrbuf.BufferError as exc:
        raise EntryError(f"{backend} buffers unreadable: {exc}") from None
    try:
        attrs: Mapping[str, Any] = exrbuf.read_attrs(exr)
    except exrbuf.BufferError:
        attrs = {}
    for key, arr in test.items():
        if arr.shape[:2] != ref.shape:
            raise EntryError(
                f"{exr}: {key} is {arr.shape[1]}x{arr.shape[0]}, the reference is {ref.shape[1]}x{ref.shape[0]}"
            )
    declared = _declared_buffers(render)
    pixels = ref.shape[0] * ref.shape[1]
    diff_dir = None
    if images and _SAFE_NAME.match(scene_name) and _SAFE_NAME.match(backend):
        diff_dir = run / "scenes" / scene_name / "diff"
    out: list[dict[str, Any]] = []

    # ---- id
    e_id = base_entry(scene_name, backend, "id", render)
    e_id["pixels"] = pixels
    id_res: IdResult | None = None
    if "id.prim" not in test:
        e_id["status"] = "skipped" if declared is None or "id" not in declared else "error"
        e_id["reason"] = (
            f"{backend} does not produce id"
            if e_id["status"] == "skipped"
            else f"{exr}: manifest lists buffer id but the EXR has no id.prim channel"
        )
    elif "id.prim" not in ref.buffers:
        e_id["reason"] = "reference has no id.prim channel"
    else:
        id_res = compare_ids(ref, test, model, depth_tol=depth_tolerance_fn(ref, model, render, attrs), backend=backend)
        e_id["edge_mismatches"] = id_res.edge
        e_id["tie_mismatches"] = id_res.tie
        e_id["crack_mismatches"] = id_res.crack
        e_id["interior_mismatches"] = id_res.interior
        e_id["tolerance"] = id_res.tolerance
        e_id["explanations"] = id_res.explanations
        _apply_verdict(e_id, exps, id_res.details)
        if not model.known:
            _add_reason(e_id, f"no precision model for {backend} in tolerance.py: compared exactly")
        if diff_dir is not None:
            path = diff_dir / f"{backend}.id.png"
            try:
                diffimages.write_id_diff(
                    path, ref.buffers["id.prim"], test["id.prim"], id_res.edge_mask, id_res.interior_mask
                )
                e_id["images"] = {"heat": path.relative_to(run).as_posix()}
            except diffimages.DiffImageError as exc:
                _add_reason(e_id, f"diff image not written: {exc}")
    out.append(e_id)

    # ---- Z
    e_z = base_entry(scene_name, backend, "Z", render)
    e_z["pixels"] = pixels
    if "Z" not in test:
        e_z["status"] = "skipped" if declared is None or "Z" not in declared else "error"
        e_z["reason"] = (
            f"{backend} does not produce Z"
            if e_z["status"] == "skipped"
            else f"{exr}: manifest lists buffer Z but the EXR has no Z channel"
        )
    elif "Z" not in ref.buffers:
        e_z["reason"] = "reference has no Z channel"
    else:
        try:
            z_res = compare_depth(
                ref,
                test,
                model,
                render,
                attrs,
                id_res.edge_mask if id_res is not None else None,
                id_res.classes if id_res is not None else None,
            )
        except tolerance.ToleranceError as exc:
            e_z["reason"] = str(exc)
            z_res = None
        if z_res is not None:
            e_z["edge_mismatches"] = z_res.edge
            e_z["tie_mismatches"] = z_res.tie
            e_z["crack_mismatches"] = z_res.crack
            e_z["interior_mismatches"] = z_res.interior
            e_z["mask_mismatches"] = z_res.mask
            e_z["compared_pixels"] = z_res.compared
            e_z["max_abs_error"] = _finite(z_res.max_abs)
            e_z["mean_abs_error"] = _finite(z_res.mean_abs)
            e_z["max_rel_error"] = _finite(z_res.max_rel)
            e_z["tolerance"] = z_res.tolerance
            _apply_verdict(e_z, exps, z_res.details)
            if diff_dir is not None:
                path = diff_dir / f"{backend}.Z.png"
                try:
                    diffimages.write_depth_diff(path, ref.buffers["Z"], test["Z"], z_res.max_abs)
                    e_z["images"] = {"heat": path.relative_to(run).as_posix()}
                except diffimages.DiffImageError as exc:
                    _add_reason(e_z, f"diff image not written: {exc}")
    out.append(e_z)

    # ---- N (where the backend writes normals)
    if "N" in test:
        out.append(compare_normals(scene_name, backend, render, ref, test, exps))

    # ---- RGB
    if is_shaded(ref.scene.requires):
        e_rgb = rgb_entry(scene_name, backend, render)
        e_rgb["pixels"] = pixels
        own = str(render.get("reason") or "")
        if "RGB" not in test:
            e_rgb["status"] = "skipped" if declared is None or "RGB" not in declared else "error"
            e_rgb["reason"] = (
                (own or f"{backend} does not produce RGB")
                if e_rgb["status"] == "skipped"
                else f"{exr}: manifest lists buffer RGB but the EXR has no R,G,B channels"
            )
        elif "RGB" not in ref.buffers:
            e_rgb["reason"] = "reference has no R,G,B channels (the scene requires shading)"
        else:
            try:
                res = compare_rgb(ref, test, attrs, backend, render, id_res.edge_mask if id_res is not None else None)
            except (tolerance.ToleranceError, radiance.RadianceError) as exc:
                e_rgb["reason"] = str(exc)
                res = None
            if res is not None:
                fill_rgb_entry(e_rgb, res, ref.buffers["RGB"], test["RGB"])
                _apply_verdict(e_rgb, exps, res.details)
                for note in res.notes:
                    _add_reason(e_rgb, note)
                _rgb_image(e_rgb, run, diff_dir, backend, res)
        out.append(e_rgb)
    return out


def compare_normals(
    scene_name: str,
    backend: str,
    render: Mapping[str, Any],
    ref: Reference,
    buffers: Mapping[str, np.ndarray],
    exps: expectations.Expectations,
) -> dict[str, Any]:
    """A backend's N against the documented winding convention: N = normalize((b-a) x (c-a)).

    Judged at every pixel where the backend's own id.prim names a triangle (its
    visibility is judged by its id entry), so the reference's normals are checked too:
    a flipped, unnormalized or wrong-triangle normal is an interior mismatch.
    """
    e = base_entry(scene_name, backend, "N", render)
    h, w = ref.shape
    e["pixels"] = h * w
    e["max_angle_rad"] = None
    n = buffers.get("N")
    ids = buffers.get("id.prim")
    if n is None or ids is None:
        e["status"] = "skipped"
        e["reason"] = f"{backend} writes no N" if n is None else f"{backend} writes N but no id.prim to judge it by"
        return e
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
    tol, text = tolerance.normal_tolerance(backend, np.where(np.isfinite(cond), cond, np.inf))
    unit_ok = np.abs(got_len - 1.0) <= 4.0 * tolerance.F32_U + tol
    bad = ~(angle <= tol) | ~unit_ok
    e["compared_pixels"] = int(valid.size)
    e["interior_mismatches"] = int(bad.sum())
    e["max_angle_rad"] = (
        float(angle.max()) if valid.size and np.isfinite(angle.max()) else (0.0 if not valid.size else None)
    )
    e["tolerance"] = f"N: {text}; |N| = 1 within 4 * 2^-24; facing per the winding (b-a) x (c-a)"
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
        e["explanations"] = [
            {
                "class": "interior",
                "ref_prim": int(prims[first]),
                "test_prim": int(prims[first]),
                "pixels": int(bad.sum()),
                "example": [int(first % w), int(first // w)],
                "why": f"N is {angle[k[0]]:.3g} rad from normalize((b-a) x (c-a)) of the prim it names"
                + (" (flipped)" if cosang[k[0]] < 0 else ""),
            }
        ]
    _apply_verdict(e, exps, details)
    return e


def _side_dof(attrs: Mapping[str, Any], info: Mapping[str, Any] | None = None) -> float:
    return radiance.degrees_of_freedom({**(info or {}), **attrs})


def compare_rgb(
    ref: Reference,
    test: Mapping[str, np.ndarray],
    attrs: Mapping[str, Any],
    backend: str,
    render: Mapping[str, Any],
    id_edge_mask: np.ndarray | None,
) -> radiance.RgbResult:
    """Deterministic or statistical comparison of R,G,B (radiance.py decides by the var channels)."""
    a, b = test["RGB"], ref.buffers["RGB"]
    var_a, var_b = test.get("var"), ref.buffers.get("var")
    if var_a is not None or var_b is not None:
        test_attrs = {**_info(render), **attrs}
        res = radiance.compare_statistical(
            b,
            var_b,
            _side_dof(ref.attrs) if var_b is not None else math.inf,
            a,
            var_a,
            _side_dof(attrs, _info(render)) if var_a is not None else math.inf,
            ref_n=radiance.samples_per_pixel(ref.attrs),
            test_n=radiance.samples_per_pixel(test_attrs),
        )
        if var_a is None or var_b is None:
            side = backend if var_a is None else "the reference"
            res.notes.append(f"{side} has no var channels: its values count as exact in the statistical test")
        return res
    model = tolerance.rgb_model(backend, b, attrs, _info(render))
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


def fill_rgb_entry(e: dict[str, Any], res: radiance.RgbResult, ref_rgb: np.ndarray, test_rgb: np.ndarray) -> None:
    e["mode"] = res.mode
    e["edge_mismatches"] = res.edge
    e["interior_mismatches"] = res.interior
    e["failing_pixels"] = res.failing_pixels
    e["compared_pixels"] = res.pixels
    e["max_abs_error"] = _finite(res.max_abs)
    e["mean_abs_error"] = _finite(res.mean_abs)
    e["max_rel_error"] = _finite(res.max_rel)
    e["tolerance"] = res.tolerance
    e["min_p"] = None if res.min_p is None else float(res.min_p)
    e["alpha"] = res.alpha
    e["cluster_failures"] = res.cluster_failures
    flip, note = radiance.flip_mean(ref_rgb, test_rgb)
    e["flip_mean"] = flip
    e["flip_note"] = note


def _rgb_image(e: dict[str, Any], run: Path, diff_dir: Path | None, backend: str, res: radiance.RgbResult) -> None:
    if diff_dir is None:
        return
    path = diff_dir / f"{backend}.RGB.png"
    try:
        diffimages.write_rgb_diff(path, res.score, res.edge_mask, res.fail_mask & ~res.edge_mask)
        e["images"] = {"heat": path.relative_to(run).as_posix()}
    except diffimages.DiffImageError as exc:
        _add_reason(e, f"diff image not written: {exc}")


# --------------------------------------------------------------------------- one scene


def compare_scene(
    run: Path,
    scene_entry: Mapping[str, Any],
    reference: str,
    exps: expectations.Expectations,
    images: bool = True,
    references_dir: Path | None = None,
) -> list[dict[str, Any]]:
    name = scene_entry["scene"]
    renders = [r for r in scene_entry.get("renders", []) if r.get("backend") != reference]
    bufs = buffers_for(scene_entry)
    try:
        ref = load_reference(run, scene_entry, reference)
    except EntryError as exc:
        out = []
        own_ref = [r for r in scene_entry.get("renders", []) if r.get("backend") == reference]
        if not renders or (own_ref and own_ref[0].get("status") == "error"):
            # The scene itself failed (it could not be loaded, or the reference could not
            # render it): one `scene` entry, so a broken scene can never look like a pass.
            e = base_entry(name, reference, "scene", own_ref[0] if own_ref else {})
            e["status"] = "error"
            e["reason"] = str(exc)
            out.append(e)
        for r in renders:
            own = "" if r.get("status") == "ok" else f" ({r['backend']} itself {r.get('status')}: {_render_reason(r)})"
            out += status_entries(name, r, "error", f"{exc}{own}", bufs)
        return [blank_if_not_compared(e) for e in out]
    if is_shaded(ref.scene.requires):
        bufs = SHADED_BUFFERS
    results: list[dict[str, Any]] = []
    if "N" in ref.buffers:  # the reference's own normals, against the winding convention
        own = [r for r in scene_entry.get("renders", []) if r.get("backend") == reference][0]
        results.append(compare_normals(name, reference, own, ref, ref.buffers, exps))
    for r in renders:
        status = r.get("status")
        if status in ("skipped", "error"):
            results += status_entries(name, r, status, _render_reason(r), bufs)
            continue
        try:
            results += compare_backend(run, name, r, ref, exps, images)
        except EntryError as exc:
            results += status_entries(name, r, "error", str(exc), bufs)
        except Exception as exc:  # noqa: BLE001 - a bug must not lose the other results
            traceback.print_exc(file=sys.stderr)
            results += status_entries(
                name, r, "error", f"internal error in compare (a rendiff bug): {type(exc).__name__}: {exc}", bufs
            )
    if references_dir is not None and "global_illumination" in ref.scene.requires:
        results.append(compare_cached_reference(run, name, ref, references_dir, exps, images))
    return [blank_if_not_compared(e) for e in results]


def compare_cached_reference(
    run: Path, name: str, ref: Reference, references_dir: Path, exps: expectations.Expectations, images: bool
) -> dict[str, Any]:
    """The reference render's RGB against the cached Mitsuba reference DIR/<name>.exr (references.py)."""
    from . import references

    exr = references_dir / f"{name}.exr"
    render = {"backend": CACHED_REFERENCE_BACKEND, "command": references.regenerate_command(ref.scene.directory, exr)}
    e = rgb_entry(name, CACHED_REFERENCE_BACKEND, render)
    e["pixels"] = ref.shape[0] * ref.shape[1]
    try:
        cached = references.load(exr, ref.scene)
    except references.ReferenceError as exc:
        e["reason"] = str(exc)
        return e
    e["version"] = cached.provenance.get("renderer")
    if "RGB" not in ref.buffers:
        e["reason"] = "reference has no R,G,B channels (the scene requires shading)"
        return e
    test = {"RGB": cached.rgb, "var": cached.var}
    try:
        res = compare_rgb(ref, test, cached.attrs, CACHED_REFERENCE_BACKEND, render, None)
    except (tolerance.ToleranceError, radiance.RadianceError) as exc:
        e["reason"] = str(exc)
        return e
    fill_rgb_entry(e, res, ref.buffers["RGB"], cached.rgb)
    _apply_verdict(e, exps, res.details)
    for note in res.notes:
        _add_reason(e, note)
    diff_dir = run / "scenes" / name / "diff" if images and _SAFE_NAME.match(name) else None
    _rgb_image(e, run, diff_dir, CACHED_REFERENCE_BACKEND, res)
    return e


# --------------------------------------------------------------------------- output


def write_results(run: Path, doc: Mapping[str, Any], name: str = "results.json") -> Path:
    """Write RUN/<name> (default results.json) atomically (temp file in RUN + os.replace)."""
    path = run / name
    text = json.dumps(doc, indent=1, allow_nan=False) + "\n"
    atomic.write_text_atomically(path, text, prefix=".results.", suffix=".json.tmp")
    return path


def format_table(results: Sequence[Mapping[str, Any]]) -> str:
    """A compact, fixed-width table: one row per entry, then a count per status."""
    header = ("scene", "backend", "buf", "status", "edge", "interior", "mask", "max_rel", "reason")
    rows = []
    for r in results:
        compared = r["status"] not in ("skipped", "error")
        rel = r.get("max_rel_error")
        if r["buffer"] == "RGB" and r.get("mode") == "statistical":
            rel = None  # the means' relative difference is noise here; min_p is in results.json
        rows.append(
            (
                str(r["scene"]),
                str(r["backend"]),
                str(r["buffer"]),
                str(r["status"]),
                str(r["edge_mismatches"]) if compared else "-",
                str(r["interior_mismatches"]) if compared else "-",
                str(r["mask_mismatches"]) if compared and r["buffer"] == "Z" else "-",
                f"{rel:.2g}" if compared and r["buffer"] in ("Z", "RGB") and rel is not None else "-",
                _short(str(r.get("reason", ""))),
            )
        )
    widths = [max(len(header[i]), *(len(row[i]) for row in rows)) if rows else len(header[i]) for i in range(8)]
    lines = []
    for row in [header, *rows]:
        cells = [row[i].ljust(widths[i]) if i < 4 else row[i].rjust(widths[i]) for i in range(8)]
        lines.append("  ".join(cells + [row[8]]).rstrip())
    counts: dict[str, int] = {}
    for r in results:
        counts[r["status"]] = counts.get(r["status"], 0) + 1
    summary = ", ".join(f"{k} {v}" for k, v in sorted(counts.items())) or "no entries"
    lines.append(f"{len(results)} entries: {summary}")
    return "\n".join(lines)


def _short(text: str, limit: int = 90) -> str:
    text = text.replace("\n", " ")
    return text if len(text) <= limit else text[: limit - 3] + "..."


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
        "--references",
        default=None,
        help="folder of cached Mitsuba references (<scene>.exr + <scene>.json, e.g. tests/references): "
        "global-illumination scenes are also compared with them, as backend mitsuba_ref",
    )
    return p


def calibrate(run: Path, manifest: Mapping[str, Any], results: list[dict[str, Any]]) -> dict[str, Any]:
    """Camera calibration from the run's probe scenes (calibration.py): adds the `camera`
    entries to `results` and returns the summary for results.json's `calibration`.

    A backend whose camera fails calibration has a convention error in its exporter, not a
    renderer bug in every scene: its failing verdicts elsewhere become `error` entries that
    say so, by name, instead of fails blamed on the renderer.
    """
    from . import calibration

    try:
        rep = calibration.calibrate_run(run, manifest)
    except Exception as exc:  # noqa: BLE001 - a bug must not lose the other results
        traceback.print_exc(file=sys.stderr)
        e = base_entry("calibration", str(manifest.get("reference", "raster")), "camera", {})
        e["status"] = "error"
        e["reason"] = f"internal error in calibration (a rendiff bug): {type(exc).__name__}: {exc}"
        results.append(blank_if_not_compared(e))
        return {}
    probes = {str(sc["scene"]) for sc in manifest["scenes"] if sc.get("role") == "calibration"}
    bad = {b: v for b, v in rep.summary.items() if v.get("status") == "fail"}
    for e in results:
        cal = bad.get(e["backend"])
        if cal is None or e["scene"] in probes or e["status"] not in (vocab.Status.FAIL, vocab.Status.UNEXPECTED_PASS):
            continue
        e["status"] = "error"
        e["reason"] = (
            f"not judged: {e['backend']}'s camera failed calibration ({cal.get('reason', '')}); was: {e['reason']}"
        )
    results.extend(rep.entries)
    return rep.summary


def run_compare(
    run: Path,
    expectations_path: str | Path | None,
    images: bool = True,
    references_dir: str | Path | None = None,
) -> dict[str, Any]:
    """Compare everything in RUN and write results.json; returns the results document.

    Raises ManifestError / expectations.ExpectationsError for unusable inputs.
    """
    manifest = load_manifest(run)
    exps = expectations.load(expectations_path)
    reference = manifest.get("reference", "raster")
    refs = Path(references_dir) if references_dir is not None else None
    results: list[dict[str, Any]] = []
    for sc in manifest["scenes"]:
        results += compare_scene(run, sc, reference, exps, images, refs)
    summary = calibrate(run, manifest, results)
    unused = exps.unused()
    doc = {
        "format": RESULTS_FORMAT,
        "reference": reference,
        "calibration": summary,
        "expectations": str(expectations_path) if expectations_path is not None else None,
        "unused_expectations": [
            {"entry": e.index, "scene": e.scene, "backend": e.backend, "buffer": e.buffer} for e in unused
        ],
        "results": results,
    }
    write_results(run, doc)
    return doc


def main(argv: Sequence[str] | None = None) -> int:
    args_in = list(sys.argv[1:] if argv is None else argv)
    if args_in[:1] == ["--"]:  # `python -m rendiff_harness compare -- --run RUN`
        args_in = args_in[1:]
    args = build_parser().parse_args(args_in)
    run = Path(args.run)
    t0 = time.monotonic()
    if not run.is_dir():
        print(f"rendiff_harness compare: {run}: run folder does not exist", file=sys.stderr)
        return EXIT_ERROR
    try:
        doc = run_compare(run, args.expectations, images=not args.no_images, references_dir=args.references)
    except (ManifestError, expectations.ExpectationsError) as exc:
        print(f"rendiff_harness compare: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except OSError as exc:
        print(f"rendiff_harness compare: {run / 'results.json'}: cannot write: {exc}", file=sys.stderr)
        return EXIT_ERROR
    print(format_table(doc["results"]))
    unused = doc["unused_expectations"]
    if unused:
        listed = ", ".join(f"{u['entry']} ({u['scene']}/{u['backend']}/{u['buffer']})" for u in unused)
        print(f"note: expectations matched by no compared result: {listed}", file=sys.stderr)
    print(f"results: {run / 'results.json'} ({time.monotonic() - t0:.1f} s)")
    return EXIT_OK
