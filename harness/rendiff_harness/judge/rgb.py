"""The `RGB` buffer: deterministic renders against the backend's RGB tolerance, Monte Carlo ones
statistically (radiance.py decides by the var channels), with the FLIP score for people."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..contract import lighting
from ..contract.manifest import Reference, render_info
from ..contract.results import Entry
from ..contract.vocab import BACKGROUND_ID
from ..renderers.spec import BackendSpec
from . import diffimages, precision, radiance, verify
from .moved_point import moved_point_tolerance
from .verdict import Judged

RGB_ENTRY_FIELDS = (
    "mode",
    "failing_pixels",
    "min_p",
    "alpha",
    "cluster_failures",
    "flip_mean",
    "flip_note",
    "explanations",
    "interior_max_abs_error",
)
"""An RGB entry's own fields (results.Entry.own_fields)."""


def explain_rgb(
    interior: np.ndarray, score: np.ndarray, ref_prim: np.ndarray | None, test_prim: np.ndarray | None
) -> list[dict[str, Any]] | None:
    """The interior failing pixels grouped by the prims each side saw there, largest groups
    first (at most `verify.MAX_EXPLANATIONS`, as id's), each with its worst pixel as the example: where an RGB failure
    is, in the terms of id's `explanations`, so that `rendiff reduce` can hold a reduction near
    the same triangles. None without interior pixels or without a side's id.prim."""
    if ref_prim is None or test_prim is None or not interior.any():
        return None
    ys, xs = np.nonzero(interior)
    rp, tp = ref_prim[ys, xs].astype(np.int64), test_prim[ys, xs].astype(np.int64)
    s = score[ys, xs]
    groups: dict[tuple[int, int], list[int]] = {}
    for k in np.argsort(-s, kind="stable"):
        groups.setdefault((int(rp[k]), int(tp[k])), []).append(int(k))
    ordered = sorted(groups.items(), key=lambda g: -len(g[1]))[: verify.MAX_EXPLANATIONS]

    def prim(p: int) -> int | None:
        return None if p == BACKGROUND_ID else p

    return [
        {
            "class": "interior",
            "ref_prim": prim(r),
            "test_prim": prim(t),
            "pixels": len(ks),
            "example": [int(xs[ks[0]]), int(ys[ks[0]])],
            "why": f"RGB beyond tolerance ({float(s[ks[0]]):.3g}x the tolerance at the example)",
        }
        for (r, t), ks in ordered
    ]


def interior_size(interior: np.ndarray, ref_rgb: np.ndarray, test_rgb: np.ndarray) -> float | None:
    """The failure's size: the largest |test - reference| (any channel, finite values only) at an
    interior failing pixel; None without one. `rendiff reduce` holds an RGB reduction to failures of
    a size comparable to its first one's (src/fuzz/reduce.rs), so that it cannot drift to an
    unrelated failure of the same class (a cosine near 0 within rounding, 4e-15 against 0)."""
    if not interior.any():
        return None
    err = np.abs(np.asarray(test_rgb, dtype=np.float64)[interior] - np.asarray(ref_rgb, dtype=np.float64)[interior])
    err = err[np.isfinite(err)]
    return float(err.max()) if err.size else None


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
    abs_tol, text = model.abs_tol, model.text
    moved = moved_point_tolerance(ref, spec, render, attrs)
    if moved is not None:
        abs_tol, text = abs_tol + moved[0], text + moved[1]
    shadow_edges: radiance.ShadowEdges | None = None
    offset = None
    scene = ref.scene
    if "shadows" in scene.requires and "id.prim" in ref.buffers and "Z" in ref.buffers:
        eps = radiance.SHADOW_EDGE_REL * lighting.scene_size(scene)

        offset = spec.shadow_ray_offset if spec is not None else None

        def ambiguous(rows: np.ndarray, cols: np.ndarray) -> np.ndarray | None:
            return lighting.shadow_ambiguity(
                scene, ref.buffers["id.prim"], ref.buffers["Z"], rows, cols, eps, ray_offset=offset
            )

        shadow_edges = ambiguous

    if shadow_edges is not None:
        text += (
            f"; failing pixels at ID edge mismatches, or whose shadow ray passes within "
            f"{radiance.SHADOW_EDGE_REL:g} x scene size"
            + (" (or the backend's own shadow-ray offset / cos(pi/8), if larger)" if offset is not None else "")
            + " of an occluder edge or end, count as edge"
        )
    else:
        text += "; failing pixels at ID edge mismatches count as edge"
    return radiance.compare_deterministic(b, a, abs_tol, model.rel, text, id_edge_mask, shadow_edges)


def record_rgb(e: Entry, res: radiance.RgbResult, ref_rgb: np.ndarray, test_rgb: np.ndarray) -> Judged:
    """Fill an RGB entry from radiance.py's result (FLIP too); the heat map shows |a-b|/tol."""
    e.mode = res.mode
    e.edge_mismatches = res.edge
    e.interior_mismatches = res.interior
    e.failing_pixels = res.failing_pixels
    e.compared_pixels = res.pixels
    e.record_errors(res.max_abs, res.mean_abs, res.max_rel)
    e.tolerance = res.tolerance
    e.min_p = None if res.min_p is None else float(res.min_p)
    e.alpha = res.alpha
    e.cluster_failures = res.cluster_failures
    e.flip_mean, e.flip_note = radiance.flip_mean(ref_rgb, test_rgb)
    e.interior_max_abs_error = interior_size(res.fail_mask & ~res.edge_mask, ref_rgb, test_rgb)

    def heat_map(path: Path) -> None:
        diffimages.write_rgb_diff(path, res.score, res.edge_mask, res.fail_mask & ~res.edge_mask)

    return Judged(res.details, res.notes, heat_map)
