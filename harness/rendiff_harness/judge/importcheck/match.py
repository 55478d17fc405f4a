"""One rendiff object's resolved triangles against one decoder's reading of the same part, as sets
of triangles: counts, positions within the derived rounding bound, winding (docs/verifier.md,
"The import verdict")."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...contract.meshfile import OPS_OBJECT, object_matrix
from .parts import Part

U64 = 2.0**-53
"""float64's unit roundoff."""


def gamma(k: int) -> float:
    """Higham's gamma_k = k u / (1 - k u): the relative bound of k float64 roundings."""
    return k * U64 / (1.0 - k * U64)


@dataclass
class Placed:
    """A decoded part in world space with each coordinate's allowed distance from rendiff's."""

    part: Part
    tris: np.ndarray  # (n, 3, 3) float64
    slack: np.ndarray  # (n, 3, 3): the decoders' float64 errors and input difference, not rendiff's f32 rounding


def place(part: Part, transform: Any) -> Placed:
    """The part under the scene object's transform, with the float64 part of the bound:
    2 gamma_k |M| |v| (both decoders' roundings) + input_rel |M| |v|."""
    m, t = object_matrix(transform)
    tris = part.tris @ m.T + t
    mag = part.mag @ np.abs(m).T + np.abs(t)
    k = part.ops + OPS_OBJECT
    return Placed(part, tris, (2.0 * gamma(k) + part.input_rel * (1.0 + gamma(k))) * mag)


def half_ulp(r: np.ndarray) -> np.ndarray:
    """Half a float32 unit at each of rendiff's values: the most its one rounding moved it (the unit
    above the value's binade start covers a value rounded up to a power of two)."""
    return np.abs(np.spacing(r.astype(np.float32))).astype(np.float64) / 2.0


@dataclass
class Outcome:
    """What one object's comparison found."""

    ok: bool
    compared: int
    max_error: float
    bound: float
    note: str = ""
    problem: str = ""


def _fmt(t: np.ndarray) -> str:
    return "(" + ", ".join("[" + ", ".join(f"{float(x):.9g}" for x in v) + "]" for v in t) + ")"


def _rotations(a: np.ndarray) -> list[np.ndarray]:
    return [np.roll(a, -k, axis=1) for k in range(3)]


def _fits(r: np.ndarray, d: np.ndarray, slack: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per triangle: whether some cyclic rotation of d is within the bound of r, and its worst error."""
    tol_r = half_ulp(r)
    errs, oks = [], []
    for dk, sk in zip(_rotations(d), _rotations(slack), strict=True):
        err = np.abs(r - dk)
        oks.append(np.all(err <= tol_r + sk, axis=(1, 2)))
        errs.append(err.max(axis=(1, 2)) if r.shape[0] else np.zeros(0))
    e, o = np.stack(errs), np.stack(oks)
    best_ok: np.ndarray = np.asarray(o.any(axis=0))
    best_err: np.ndarray = np.where(best_ok, np.where(o, e, np.inf).min(axis=0), e.min(axis=0))
    return best_ok, best_err


def _canonical(t: np.ndarray) -> list[bytes]:
    """A key per float32 triangle, the same for its three cyclic rotations (winding kept)."""
    keys = []
    for tri in t.astype(np.float32):
        rows = [tri[k].tobytes() for k in range(3)]
        k = min(range(3), key=lambda i: rows[i])
        keys.append(b"".join(rows[k:] + rows[:k]))
    return keys


def _unmatched(r: np.ndarray, placed: Placed) -> tuple[list[int], list[int]]:
    """Triangles of each side without a counterpart in the other, as multisets: exact float32 keys
    first, then what is left within the bound (nearest centroid)."""
    pool: dict[bytes, list[int]] = defaultdict(list)
    for j, key in enumerate(_canonical(placed.tris)):
        pool[key].append(j)
    left_r = []
    for i, key in enumerate(_canonical(r)):
        if pool.get(key):
            pool[key].pop()
        else:
            left_r.append(i)
    left_d = sorted(j for js in pool.values() for j in js)
    if left_r and left_d:
        still_r = []
        free = list(left_d)
        for i in left_r:
            if not free:
                still_r.append(i)
                continue
            cand = np.asarray(free)
            ok, _ = _fits(np.repeat(r[i : i + 1], len(cand), axis=0), placed.tris[cand], placed.slack[cand])
            hits = np.nonzero(ok)[0]
            if hits.size:
                free.remove(int(cand[hits[0]]))
            else:
                still_r.append(i)
        left_r, left_d = still_r, free
    return left_r, left_d


def compare(name: str, first_prim: int, r: np.ndarray, placed: Placed, decoder: str) -> Outcome:
    """rendiff's triangles `r` (n, 3, 3, float32 values) of object `name` against the decoder's."""
    part = placed.part
    d = placed.tris
    n_r, n_d = r.shape[0], d.shape[0]
    r64 = r.astype(np.float64)
    m = min(n_r, n_d)
    ok, err = _fits(r64[:m], d[:m], placed.slack[:m])
    bound = float((half_ulp(r64[:m]) + placed.slack[:m]).max()) if m else 0.0
    max_err = float(err[ok].max()) if ok.any() else 0.0
    if n_r == n_d and ok.all():
        return Outcome(True, n_r, max_err, bound)
    left_r, left_d = _unmatched(r64, placed)
    if not left_r and not left_d:
        return Outcome(True, n_r, max_err, bound, note=f"{name}: the same triangles in another order")
    where = f"object {name!r} ({part.where})"
    if n_r != n_d:
        head = f"{where}: rendiff has {n_r} triangles, {decoder} {n_d}"
    else:
        head = f"{where}: {len(left_r)} of {n_r} triangles differ"
    bad = int(np.argmin(ok)) if not ok.all() else m
    if bad < n_d:
        prim = part.prims[int(part.prim[bad])]
        j = int(part.prim_tri[bad])
        detail = f"first at {prim} triangle {j} (prim_id {first_prim + bad}): "
        if bad < n_r:
            rev = d[bad][[0, 2, 1]]
            flipped, _ = _fits(r64[bad : bad + 1], rev[None], placed.slack[bad][[0, 2, 1]][None])
            if flipped[0]:
                detail += "the same vertices with the winding reversed; "
            detail += f"rendiff {_fmt(r[bad])}, {decoder} {_fmt(d[bad])}"
        else:
            detail += f"missing from rendiff; {decoder} {_fmt(d[bad])}"
    else:
        detail = f"first extra rendiff triangle at prim_id {first_prim + bad}: {_fmt(r[bad])}"
    return Outcome(False, n_r, max_err, bound, problem=f"{head}, {detail}")
