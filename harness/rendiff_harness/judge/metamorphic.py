"""`python -m rendiff_harness metamorphic --run RUN --spec SPEC [--expectations FILE] [--out FILE]`.

Metamorphic relations on every backend (docs/metamorphic.md): a transformed scene (the
*variant*) rendered by a backend must give that same backend's render of the *base* scene,
IDs mapped back, within the bound stated for the relation and the backend. RUN is a
`rendiff check` run holding both scenes (tests/metamorphic_backends.rs makes it); SPEC
(JSON, format rendiff-metamorphic-spec/1) lists the cases:

    {"relation": "split", "base": "meta_base", "variant": "meta_split",
     "prim_map": [...],    # variant prim -> base prim (split: both halves -> the parent)
     "object_map": [...],  # variant object -> base object
     "depth_scale": 64.0}  # variant Z = base Z x this (a power of two)

The comparison is the judge's own (judge/ids.py, judge/depth.py), with the base render as the reference:

* `id`: variant IDs are mapped to base IDs, then compared exactly. A mismatch is *edge*
  when the pixel center lies within the backend's `edge_px` (tolerance.py), plus twice its
  per-edge growth where it has one (Embree's products, `product_distance`), of an edge of a
  triangle involved, in either scene: the base prim, the variant prim, the base
  triangle the variant prim maps to, and the variant triangles that map to the base prim
  (so a split's new edge counts). Anything else is *interior*.
* `Z`: variant Z / depth_scale against base Z where both show the same (mapped) prim;
  hit/miss masks exact except at ID edge mismatches. Each side is a rounded answer, so
  the allowed difference is the backend's own tolerance model evaluated for each side
  (with that side's render parameters) and summed: |Z_v/s - Z_b| <= tol_b + tol_v/s.
* The core (raster, trace) is held to its own bounds (`CORE_BOUNDS`): exact where the
  arithmetic is exact, else the bound tests/metamorphic.rs states.

Verdicts: edge mismatches are within every relation's stated bound (they are counted,
not limited); interior mismatches fail, unless FILE (tests/metamorphic_expectations.toml,
expectations.py's format with `scene` = the relation) records them as a known failure.
Writes OUT (default RUN/metamorphic.json) atomically and prints a table; exits 0 when it
could write results, 2 when an input is unusable (one line naming the file).

Inputs are checked before any work: RUN must be a finished run (a RUN/INCOMPLETE entry of
any kind is refused, as `rendiff gate`, `report` and `bless` do: src/check/run_folder.rs
`ensure_complete`); OUT must be in an existing folder and not a FIFO, device, socket or folder
(atomic.py). SPEC is a user file (userfile.py: regular, at most MAX_SPEC_BYTES, opened
without blocking); unparsable, too deeply nested or out-of-range content is one line naming it.
"""

from __future__ import annotations

import argparse
import math
import os
import stat
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..contract import atomic, exrbuf, resolved
from ..contract import results as results_table
from ..contract.manifest import (
    EntryError,
    ManifestError,
    load_manifest,
    load_reference,
    render_info,
    render_reason,
    run_path,
)
from ..contract.results import finite, write_results
from ..contract.text import printable
from ..contract.userfile import JsonFileError, open_regular, read_json
from ..contract.vocab import BACKGROUND_ID, RenderStatus, Status
from ..renderers.spec import SpecLookup
from . import expectations, geometry, outline, precision, tolerance
from .depth import compare_depth
from .ids import EdgeDistance, compare_ids

SPEC_FORMAT = "rendiff-metamorphic-spec/1"
RESULTS_FORMAT = "rendiff-metamorphic/1"
EXIT_OK, EXIT_ERROR = 0, 2
# Largest SPEC read: 64 MiB. A spec is a few cases, each with one prim_map entry per variant
# triangle (under 10 bytes of JSON each): about 7M triangles of maps.
MAX_SPEC_BYTES = 1 << 26
# Map entries are triangle and object IDs: u32, below the background ID.
MAX_MAP_ENTRY = BACKGROUND_ID - 1
# The marker `rendiff check` keeps in a run folder until the run is finished
# (INCOMPLETE_MARKER in src/check/manifest.rs), and how much of it is read for the message
# (MARKER_READ_BYTES in src/check/run_folder.rs).
INCOMPLETE_MARKER = "INCOMPLETE"
MARKER_READ_BYTES = 4096


@dataclass(frozen=True)
class CoreBound:
    """The core's bound for one relation: edge band in px and relative depth difference."""

    edge_px: float
    depth_rel: float
    why: str


EXACT = CoreBound(0.0, 0.0, "exact: the transform is exact in f32 and the core's arithmetic commutes with it")
CORE_BOUNDS: dict[str, CoreBound] = {
    "flip_winding": CoreBound(
        0.0, 0.0, "exact: orientation signs flip together and the tie rule does not depend on winding"
    ),
    "reorder": CoreBound(0.0, 0.0, "exact: IDs permute; only exact depth ties could change the winner"),
    "scale": CoreBound(
        0.0, 0.0, "exact: a power-of-two scale about the eye scales every product and P = eye + d exactly"
    ),
    "split": CoreBound(
        0.0,
        1e-6,
        "coverage exact (the halves' edges lie on the parent's edge planes); depth within 1e-6 relative, "
        "as the halves' f64 planes differ by rounding (tests/metamorphic.rs)",
    ),
    "translate": CoreBound(
        1e-6,
        1e-6,
        "P = eye + d is rounded at the eye's magnitude: IDs may change within 1e-6 px of an edge and depth by "
        "1e-6 relative (tests/metamorphic.rs); the band grows with |eye| x 2^-53 / pixel size",
    ),
}


class SpecError(Exception):
    """The spec file is unusable; the message names the file."""


class RunError(Exception):
    """The run folder is unusable (incomplete); the message names it."""


def ensure_complete(run: Path) -> None:
    """RunError when RUN holds an INCOMPLETE entry of any kind (src/check/run_folder.rs `ensure_complete`)."""
    marker = run / INCOMPLETE_MARKER
    try:
        mode = os.lstat(marker).st_mode
    except FileNotFoundError:
        return
    except OSError as exc:
        why = f"its {INCOMPLETE_MARKER} marker cannot be examined: {exc.strerror or exc}"
    else:
        why = f"its {INCOMPLETE_MARKER} marker is not a regular file"
        if stat.S_ISREG(mode):
            try:
                with open_regular(marker) as fh:
                    why = fh.read(MARKER_READ_BYTES).decode("utf-8", errors="replace")
            except (OSError, ValueError):
                pass
    raise RunError(
        f"{run}: incomplete run ({printable(why.strip(), 200)}); its verdicts are not trustworthy: "
        "run rendiff check again"
    )


@dataclass(frozen=True)
class Case:
    relation: str
    description: str
    base: str
    variant: str
    prim_map: np.ndarray  # (N_variant,) int64
    object_map: np.ndarray  # (O_variant,) int64
    depth_scale: float


def load_spec(path: Path) -> list[Case]:
    """Read and validate SPEC; SpecError names the file and the case."""
    try:
        doc = read_json(path, MAX_SPEC_BYTES)
    except JsonFileError as exc:
        if exc.cause == "missing":
            raise SpecError(f"{path}: spec file not found") from None
        raise SpecError(f"{path}: unreadable spec: {exc.detail}") from None
    if not isinstance(doc, dict) or doc.get("format") != SPEC_FORMAT:
        raise SpecError(f"{path}: format must be {SPEC_FORMAT!r}")
    raw = doc.get("cases")
    if not isinstance(raw, list):
        raise SpecError(f"{path}: 'cases' must be a list")
    cases = []
    for i, c in enumerate(raw):
        where = f"{path}: cases[{i}]"
        if not isinstance(c, dict):
            raise SpecError(f"{where} must be an object")
        for key in ("relation", "base", "variant"):
            if not isinstance(c.get(key), str) or not c[key]:
                raise SpecError(f"{where}: {key!r} must be a non-empty string")
        maps = {}
        for key in ("prim_map", "object_map"):
            v = c.get(key)
            if not isinstance(v, list) or not all(
                isinstance(x, int) and not isinstance(x, bool) and 0 <= x <= MAX_MAP_ENTRY for x in v
            ):
                raise SpecError(
                    f"{where} ({c['relation']}): {key!r} must be a list of integers from 0 to {MAX_MAP_ENTRY} (IDs)"
                )
            maps[key] = np.asarray(v, dtype=np.int64)
        s = c.get("depth_scale", 1.0)
        try:
            scale = float(s) if isinstance(s, (int, float)) and not isinstance(s, bool) else math.nan
        except OverflowError:  # an int beyond float's range
            scale = math.inf
        if isinstance(s, bool) or not isinstance(s, (int, float)):
            shown = f"a {type(s).__name__}"
        elif isinstance(s, int) and abs(s) >= 10**30:
            shown = f"an integer of {len(str(abs(s)))} digits"
        else:
            shown = repr(s)
        if not math.isfinite(scale) or scale <= 0:
            raise SpecError(f"{where} ({c['relation']}): 'depth_scale' must be a positive number, got {shown}")
        if math.frexp(scale)[0] != 0.5 or (isinstance(s, int) and s != int(scale)):
            raise SpecError(f"{where} ({c['relation']}): 'depth_scale' must be a power of two (exact), got {shown}")
        cases.append(
            Case(
                c["relation"],
                str(c.get("description", "")),
                c["base"],
                c["variant"],
                maps["prim_map"],
                maps["object_map"],
                scale,
            )
        )
    return cases


def load_expectations(path: str | Path | None) -> expectations.Expectations:
    """expectations.py's format (which refuses bounds on the allowed edge and tie classes)."""
    return expectations.load(path)


# --------------------------------------------------------------------------- bounds


def stated_bound(relation: str, backend: str, m: tolerance.Model, core: bool, depth_scale: float = 1.0) -> str:
    """The bound this relation holds `backend` to, in words (results.json and docs/metamorphic.md)."""
    s = "" if depth_scale == 1.0 else f"/{depth_scale:g}"
    if core:
        b = CORE_BOUNDS.get(relation, EXACT)
        ids = "identical IDs" if b.edge_px == 0 else f"IDs may differ only within {b.edge_px:g} px of an edge"
        z = "bit-identical Z" if b.depth_rel == 0 else f"|Z_v{s} - Z_b| <= {b.depth_rel:g} Z_b"
        return f"{ids}; {z} ({b.why})"
    products = "" if m.edge_products is None else " plus, on each edge, twice its per-edge growth (both renders)"
    return (
        f"IDs may differ only within {m.edge_px:.3g} px{products} of an edge of a triangle involved ({backend}'s edge "
        f"tolerance); |Z_v{s} - Z_b| <= tol_{backend}(base) + tol_{backend}(variant){s} where both show the same "
        "mapped prim; hit/miss only at ID edge mismatches"
    )


def core_model(relation: str, backend: str) -> tolerance.Model:
    b = CORE_BOUNDS.get(relation, EXACT)

    def depth(ctx: tolerance.DepthContext) -> tuple[np.ndarray, str]:
        if b.depth_rel == 0.0:
            return np.zeros_like(ctx.z_ref), "exact: Z bit-identical (after the power-of-two depth scale)"
        return np.abs(ctx.z_ref) * b.depth_rel, f"|dZ| <= {b.depth_rel:g} Z ({relation}: {b.why})"

    return tolerance.Model(backend, b.edge_px, f"{relation}: {b.why}", depth)


def summed_model(
    m: tolerance.Model,
    backend: str,
    base_render: Mapping[str, Any],
    base_attrs: Mapping[str, Any],
    var_render: Mapping[str, Any],
    var_attrs: Mapping[str, Any],
    scale: float,
) -> tolerance.Model:
    """The backend's own model `m` for each side, each with its render's parameters, summed."""
    base_info, var_info = render_info(base_render), render_info(var_render)

    def depth(ctx: tolerance.DepthContext) -> tuple[np.ndarray, str]:
        tb, text_b = m.depth(replace(ctx, info=base_info, attrs=base_attrs))
        tv, text_v = m.depth(replace(ctx, z_ref=ctx.z_ref * scale, info=var_info, attrs=var_attrs))
        s = "" if scale == 1.0 else f" / {scale:g}"
        return tb + tv / scale, f"sum of both sides' tolerances: base [{text_b}] + variant [{text_v}]{s}"

    return tolerance.Model(backend, m.edge_px, m.edge_reason, depth, m.known)


# --------------------------------------------------------------------------- mapping and geometry


def map_buffers(test: Mapping[str, np.ndarray], case: Case, base_count: int) -> dict[str, np.ndarray]:
    """Variant buffers in the base's terms: IDs through the maps, Z divided by depth_scale.

    An ID beyond the map becomes `base_count` (names no triangle: an interior mismatch).
    """
    out = dict(test)

    def through(ids: np.ndarray, table: np.ndarray, invalid: int) -> np.ndarray:
        ids64 = ids.astype(np.int64)
        ok = (ids != BACKGROUND_ID) & (ids64 < table.size)
        res = np.where(ids == BACKGROUND_ID, BACKGROUND_ID, invalid).astype(np.int64)
        res[ok] = table[ids64[ok]]
        return res.astype(np.uint32)

    if "id.prim" in test:
        out["id.prim"] = through(test["id.prim"], case.prim_map, base_count)
    if "id.object" in test:
        out["id.object"] = through(test["id.object"], case.object_map, int(case.object_map.max(initial=-1)) + 1)
    if "Z" in test:
        out["Z"] = (test["Z"].astype(np.float64) / case.depth_scale).astype(np.float32)
    return out


def preimage(prim_map: np.ndarray, base_count: int) -> np.ndarray:
    """(base_count, K) table: the variant prims mapping to each base prim, padded with -1."""
    k = int(np.bincount(prim_map, minlength=base_count).max(initial=0)) if prim_map.size else 0
    table = np.full((base_count, max(k, 1)), -1, dtype=np.int64)
    order = np.argsort(prim_map, kind="stable")
    sorted_map = prim_map[order]
    starts = np.searchsorted(sorted_map, np.arange(base_count))
    for j in range(k):
        pos = starts + j
        inside = pos < sorted_map.size
        hit = inside & (sorted_map[np.minimum(pos, sorted_map.size - 1)] == np.arange(base_count))
        table[hit, j] = order[pos[hit]]
    return table


def product_distance(
    scene: resolved.ResolvedScene,
    prims: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    products: tolerance.EdgeProducts | None,
) -> np.ndarray:
    """`geometry.prim_edge_distance`, less on each edge twice the model's per-edge growth of the band
    there (`Model.edge_products`: Embree's edge functions' products): each of the two renders may move
    that edge by as much. The products depend on the vertices relative to the ray origin and on the
    ray, which every relation keeps (a translation moves both, a power-of-two scale about the eye scales
    both, winding and order leave them); a split half's outer edge lies on its parent's line, and the
    smaller of the two distances (parent's, half's) is at least as lenient as their sum."""
    d = geometry.prim_edge_distance(scene, prims, rows, cols)
    p = np.asarray(prims, dtype=np.int64).ravel()
    idx = np.nonzero((p >= 0) & (p < scene.triangle_count))[0]
    if products is None or idx.size == 0:
        return d
    cam = scene.camera
    r, c = np.asarray(rows).ravel()[idx], np.asarray(cols).ravel()[idx]
    edge_d = outline.edge_distances(scene, p[idx], r, c)
    origin = np.asarray(cam.eye, dtype=np.float64).astype(np.float32).astype(np.float64)
    grown = 2.0 * products(
        scene.triangles[p[idx]].astype(np.float64), origin, cam.center_directions(r, c), cam.pixel_size()
    )
    with np.errstate(invalid="ignore"):
        less = np.where(np.isfinite(edge_d), edge_d - grown, np.inf).min(axis=1)
    d[idx] = np.minimum(d[idx], less)
    return d


def relation_edge_distance(
    base: resolved.ResolvedScene,
    variant: resolved.ResolvedScene,
    case: Case,
    variant_prims: np.ndarray,
    products: tolerance.EdgeProducts | None = None,
) -> EdgeDistance:
    """Distance to the nearest edge of any triangle involved, in either scene (module docstring), less
    the per-edge growth of the band where the model has one (`product_distance`)."""
    table = preimage(case.prim_map, base.triangle_count)

    def distance(r_ids: np.ndarray, t_ids: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        raw = variant_prims[rows, cols]
        d: np.ndarray = np.minimum(
            product_distance(base, r_ids, rows, cols, products),
            product_distance(variant, raw, rows, cols, products),
        )
        d = np.minimum(d, product_distance(base, t_ids, rows, cols, products))
        r = np.asarray(r_ids, dtype=np.int64)
        known = (r_ids != BACKGROUND_ID) & (r < base.triangle_count)
        for j in range(table.shape[1]):
            pre = np.full(r.size, -1, dtype=np.int64)
            pre[known] = table[r[known], j]
            pre = np.where(pre >= 0, pre, BACKGROUND_ID)
            d = np.minimum(d, product_distance(variant, pre, rows, cols, products))
        return d

    return distance


# --------------------------------------------------------------------------- one case, one backend


def _entry(case: Case, backend: str, buffer: str, m: tolerance.Model, core: bool) -> dict[str, Any]:
    return {
        "relation": case.relation,
        "description": case.description,
        "base": case.base,
        "variant": case.variant,
        "backend": backend,
        "buffer": buffer,
        "status": Status.ERROR,
        "reason": "",
        "pixels": None,
        "edge_mismatches": None,
        "interior_mismatches": None,
        "mask_mismatches": None,
        "compared_pixels": None,
        "max_abs_error": None,
        "max_rel_error": None,
        "stated_bound": stated_bound(case.relation, backend, m, core, case.depth_scale),
        "tolerance": "",
    }


def _verdict(e: dict[str, Any], exps: expectations.Expectations, details: list[str]) -> None:
    exp = exps.lookup(e["relation"], e["backend"], e["buffer"])
    v = expectations.evaluate({"interior_mismatches": int(e["interior_mismatches"])}, exp)
    e["status"] = v.status
    e["bound"] = exp.bound_json() if exp is not None else None
    parts = [v.reason] if v.reason else []
    if v.status != Status.PASS:
        parts += details
    e["reason"] = "; ".join(parts)


def _render(scene_entry: Mapping[str, Any], backend: str) -> Mapping[str, Any] | None:
    renders: list[Mapping[str, Any]] = scene_entry.get("renders", [])
    for r in renders:
        if r.get("backend") == backend:
            return r
    return None


def compare_case(
    run: Path,
    scenes: Mapping[str, Mapping[str, Any]],
    case: Case,
    backend: str,
    exps: expectations.Expectations,
    specs: SpecLookup,
) -> list[dict[str, Any]]:
    """The `id` and `Z` entries of one (relation, backend); its precision is its spec's (`specs`)."""
    spec = specs(backend)
    m = precision.depth_model(spec, backend)
    core = spec is not None and spec.core_loop  # the core's loops are held to the core's own bounds
    e_id, e_z = _entry(case, backend, "id", m, core), _entry(case, backend, "Z", m, core)

    def all_as(status: str, reason: str) -> list[dict[str, Any]]:
        for e in (e_id, e_z):
            e["status"], e["reason"] = status, reason
        return [e_id, e_z]

    for name in (case.base, case.variant):
        if name not in scenes:
            return all_as(Status.ERROR, f"scene {name} is not in the run's manifest.json")
    renders = {}
    for side, name in (("base", case.base), ("variant", case.variant)):
        r = _render(scenes[name], backend)
        if r is None:
            return all_as(Status.ERROR, f"{backend} did not render the {side} scene {name}")
        if r.get("status") != RenderStatus.OK:
            status = Status.SKIPPED if r.get("status") == RenderStatus.SKIPPED else Status.ERROR
            return all_as(status, f"{side} scene {name}: {render_reason(r)}")
        renders[side] = r
    try:
        ref = load_reference(run, scenes[case.base], backend)
        var_scene = resolved.load(run_path(run, scenes[case.variant].get("resolved"), "variant resolved scene"))
        exr = run_path(run, renders["variant"].get("exr"), f"{backend} variant EXR")
        test_raw = exrbuf.read_buffers(exr)
        var_attrs: Mapping[str, Any] = exrbuf.read_attrs(exr)
        base_attrs: Mapping[str, Any] = ref.attrs
    except EntryError as exc:
        return all_as(Status.ERROR, str(exc))
    except (resolved.SceneError, exrbuf.BufferError) as exc:
        return all_as(Status.ERROR, str(exc))
    problem = _check_maps(case, ref.scene, var_scene)
    if problem is None and any(a.shape[:2] != ref.shape for a in test_raw.values()):
        problem = f"{exr}: buffers are not {ref.shape[1]}x{ref.shape[0]} like the base"
    if problem is None and not {"id.prim", "Z"} <= set(test_raw):
        problem = f"{exr}: needs id.prim and Z channels"
    if problem is not None:
        return all_as(Status.ERROR, problem)
    test = map_buffers(test_raw, case, ref.scene.triangle_count)
    if core:
        model = core_model(case.relation, backend)
    else:
        model = summed_model(m, backend, renders["base"], base_attrs, renders["variant"], var_attrs, case.depth_scale)
    pixels = ref.shape[0] * ref.shape[1]
    distance = relation_edge_distance(
        ref.scene, var_scene, case, test_raw["id.prim"], None if core else m.edge_products
    )
    ids = compare_ids(ref, test, model, edge_distance=distance)
    e_id.update(pixels=pixels, edge_mismatches=ids.edge, interior_mismatches=ids.interior, tolerance=ids.tolerance)
    _verdict(e_id, exps, ids.details)
    try:
        z = compare_depth(ref, test, model, renders["variant"], var_attrs, ids.edge_mask)
    except tolerance.ToleranceError as exc:
        e_z["reason"] = str(exc)
        return [e_id, e_z]
    e_z.update(
        pixels=pixels,
        edge_mismatches=z.edge,
        interior_mismatches=z.interior,
        mask_mismatches=z.mask,
        compared_pixels=z.compared,
        max_abs_error=finite(z.max_abs),
        max_rel_error=finite(z.max_rel),
        tolerance=z.tolerance,
    )
    _verdict(e_z, exps, z.details)
    return [e_id, e_z]


def _check_maps(case: Case, base: resolved.ResolvedScene, variant: resolved.ResolvedScene) -> str | None:
    if case.prim_map.size != variant.triangle_count:
        n = variant.triangle_count
        return f"prim_map has {case.prim_map.size} entries, the variant {case.variant} has {n} triangles"
    if case.prim_map.size and int(case.prim_map.max()) >= base.triangle_count:
        return f"prim_map names prim {int(case.prim_map.max())}, the base {case.base} has {base.triangle_count}"
    if case.object_map.size != len(variant.objects):
        n = len(variant.objects)
        return f"object_map has {case.object_map.size} entries, the variant {case.variant} has {n} objects"
    if case.object_map.size and int(case.object_map.max()) >= len(base.objects):
        return f"object_map names object {int(case.object_map.max())}, the base {case.base} has {len(base.objects)}"
    return None


# --------------------------------------------------------------------------- run


def run_metamorphic(
    run: Path, spec: Path, expectations_path: str | Path | None, out: Path, specs: SpecLookup
) -> dict[str, Any]:
    """Every case on every backend that rendered the base scene; writes OUT and returns the document.
    `specs`: the backends' specs by name (the registry's lookup).

    RunError for an incomplete run, before anything is read."""
    ensure_complete(run)
    manifest = load_manifest(run)
    cases = load_spec(spec)
    exps = load_expectations(expectations_path)
    scenes = {sc["scene"]: sc for sc in manifest["scenes"]}
    results: list[dict[str, Any]] = []
    for case in cases:
        base = scenes.get(case.base)
        backends = [r["backend"] for r in base.get("renders", [])] if base is not None else ["?"]
        for backend in backends:
            results += compare_case(run, scenes, case, backend, exps, specs)
    doc = {
        "format": RESULTS_FORMAT,
        "spec": str(spec),
        "expectations": str(expectations_path) if expectations_path is not None else None,
        "unused_expectations": [
            {"entry": e.index, "relation": e.scene, "backend": e.backend, "buffer": e.buffer} for e in exps.unused()
        ],
        "results": results,
    }
    write_results(out.parent, doc, out.name)
    return doc


def _cell(r: Mapping[str, Any], k: str) -> str:
    v = r.get(k)
    return "-" if v is None else (f"{v:.2g}" if isinstance(v, float) else str(v))


def format_table(results: Sequence[Mapping[str, Any]]) -> str:
    """One row per relation, backend and buffer, in the layout of the verdict table
    (`results.fixed_width`), then a count per status."""
    header = ("relation", "backend", "buf", "status", "edge", "interior", "mask", "max_rel")
    rows = [
        (
            r["relation"],
            r["backend"],
            r["buffer"],
            r["status"],
            _cell(r, "edge_mismatches"),
            _cell(r, "interior_mismatches"),
            _cell(r, "mask_mismatches") if r["buffer"] == "Z" else "-",
            _cell(r, "max_rel_error") if r["buffer"] == "Z" else "-",
        )
        for r in results
    ]
    return "\n".join([*results_table.fixed_width(header, rows, range(4, 8)), results_table.count_line(results)])


def main(argv: Sequence[str] | None, specs: SpecLookup) -> int:
    p = argparse.ArgumentParser(
        prog="python -m rendiff_harness metamorphic",
        description="Compare each backend's variant renders with its base renders (metamorphic relations).",
    )
    p.add_argument("--run", required=True, help="check run holding the base and variant scenes")
    p.add_argument("--spec", required=True, help="cases: JSON, format rendiff-metamorphic-spec/1")
    p.add_argument("--expectations", default=None, help="known failures (e.g. tests/metamorphic_expectations.toml)")
    p.add_argument("--out", default=None, help="results file (default RUN/metamorphic.json)")
    args = p.parse_args(list(sys.argv[1:] if argv is None else argv))
    run = Path(args.run)
    out = Path(args.out) if args.out else run / "metamorphic.json"
    if not run.is_dir():
        print(f"rendiff_harness metamorphic: --run {run}: run folder does not exist", file=sys.stderr)
        return EXIT_ERROR
    problem = None
    try:
        ensure_complete(run)
    except RunError as exc:
        problem = f"--run {exc}"
    if problem is None and not out.parent.is_dir():
        problem = f"--out {out}: output folder {out.parent} does not exist"
    kind = atomic.special_entry(out) if problem is None else None
    if kind is not None:
        problem = f"--out {out}: {kind}; results are written to regular files only: choose another --out"
    if problem is not None:
        print(f"rendiff_harness metamorphic: {problem}", file=sys.stderr)
        return EXIT_ERROR
    try:
        doc = run_metamorphic(run, Path(args.spec), args.expectations, out, specs)
    except (SpecError, RunError, ManifestError, expectations.ExpectationsError) as exc:
        print(f"rendiff_harness metamorphic: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except OSError as exc:
        print(f"rendiff_harness metamorphic: {out}: cannot write: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_ERROR
    print(format_table(doc["results"]))
    for u in doc["unused_expectations"]:
        print(
            f"note: expectation {u['entry']} ({u['relation']}/{u['backend']}/{u['buffer']}) matched nothing",
            file=sys.stderr,
        )
    print(f"results: {out}")
    return EXIT_OK
