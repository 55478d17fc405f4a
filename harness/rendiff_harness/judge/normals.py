"""The `N` buffer: a backend's normals (and the reference's own) against the winding convention
N = normalize((b-a) x (c-a)) of the prim its id.prim names."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ..contract import vocab
from ..contract.manifest import Reference
from ..contract.results import Entry
from ..contract.vocab import Buffer, Status
from ..renderers.spec import BackendSpec
from . import expectations, precision, tolerance
from .verdict import EXAMPLES, Judged

N_FIELDS = ("max_angle_rad", "explanations")
"""An N entry's own fields (results.Entry.own_fields)."""


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


def placement_angle(p: float, e1: np.ndarray, e2: np.ndarray, length: np.ndarray) -> np.ndarray:
    """How far moving every vertex by at most p (world units) can turn a triangle's normal: each edge
    moves by <= 2p, so the cross product by <= 2p (|e1| + |e2|) + 4p^2, and a vector c turns by at
    most asin(|dc| / |c|) (pi when |dc| >= |c|: any direction)."""
    if p <= 0.0:
        return np.zeros(length.shape)
    dc = 2.0 * p * (np.linalg.norm(e1, axis=1) + np.linalg.norm(e2, axis=1)) + 4.0 * p * p
    with np.errstate(all="ignore"):
        ratio = dc / length
    out: np.ndarray = np.where(ratio < 1.0, np.arcsin(np.minimum(ratio, 1.0)), np.pi)
    return out


def judge_normals(
    ref: Reference,
    backend: str,
    buffers: Mapping[str, np.ndarray],
    e: Entry,
    spec: BackendSpec | None,
    attrs: Mapping[str, Any] | None = None,
) -> Judged | None:
    """N against the documented winding convention: N = normalize((b-a) x (c-a)).

    Judged at every pixel where the backend's own id.prim names a triangle (its
    visibility is judged by its id entry), so the reference's normals are checked too:
    a flipped, unnormalized or wrong-triangle normal is an interior mismatch. A backend
    that placed the vertices itself (`Model.placement`, read from its `attrs`) gets the
    angle its placement can turn the triangle by on top (`placement_angle`).
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
    if spec is not None and spec.precision.placement is not None:
        placed = spec.precision.placement(attrs or {})
        tol = tol + placement_angle(placed, e1, e2, length)
        text += (
            f" + the turn of vertices placed {placed:.3g} apart: asin(min(1, (2p (|e1| + |e2|) + 4p^2) / |e1 x e2|))"
        )
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
        # A zero (or non-finite) N has no direction: its angle is recorded as pi, which
        # must not read as "reversed" (a Mitsuba finding was first described that way).
        no_dir = ~(got_len > 0) | ~np.isfinite(got_len)
        zero = int(np.count_nonzero(bad & no_dir))
        details.append(
            f"{int(bad.sum())} normals off, {flipped} of them facing the other way, "
            f"{zero} zero or not finite (angle shown as pi); e.g. {ex}"
        )
        first = valid[k[0]]
        e.explanations = [
            {
                "class": vocab.MismatchClass.INTERIOR,
                "ref_prim": int(prims[first]),
                "test_prim": int(prims[first]),
                "pixels": int(bad.sum()),
                "example": [int(first % w), int(first // w)],
                "why": (
                    f"N is the zero vector or not finite (|N| = {got_len[k[0]]:.3g}), not normalize((b-a) x (c-a))"
                    if no_dir[k[0]]
                    else f"N is {angle[k[0]]:.3g} rad from normalize((b-a) x (c-a)) of the prim it names"
                    + (" (flipped)" if cosang[k[0]] < 0 else "")
                ),
            }
        ]
    return Judged(details)
