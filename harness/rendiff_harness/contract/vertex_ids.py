"""Vertices grouped by exact f32 identity: one numbering shared by whoever needs it fast.

A scene is a triangle soup; the POV-Ray backend writes each distinct vertex once
(renderers/povray/backend.py) and the verifier finds shared edges by vertex identity
(judge/verify.py). Both sort the vertices' raw bits. `np.unique` on 12-byte rows and
`np.lexsort` on two keys gave them their order before; this module gives the very same
numbering from two unstable argsorts of one 64-bit key each (`group`), faster than both
(at 1.31M triangles, warm, on a shared 2-core machine: lexsort 0.40 s, np.unique 1.6-2.6 s).
"""

from __future__ import annotations

import numpy as np


def group(hi: np.ndarray, lo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows keyed by (hi, lo) (uint64, `lo` < 2^32) numbered in key order: (one row of each key, each row's number).

    Equal keys share a number; numbers run 0.. in increasing (hi, lo) order, as
    `np.unique(..., return_inverse=True)` numbers its sorted values. Two unstable sorts of
    one uint64 key each (`hi`, then `hi`'s dense rank << 32 | `lo`) instead of a stable sort
    per key: which of a key's equal rows stands for it may differ, nothing else can.
    """
    n = hi.size
    inverse = np.empty(n, dtype=np.int64)
    if n == 0:
        return np.zeros(0, dtype=np.int64), inverse
    by_hi = np.argsort(hi)
    sorted_hi = hi[by_hi]
    starts = np.ones(n, dtype=bool)
    starts[1:] = sorted_hi[1:] != sorted_hi[:-1]
    rank = np.empty(n, dtype=np.uint64)
    rank[by_hi] = np.cumsum(starts) - 1
    key = (rank << np.uint64(32)) | lo.astype(np.uint64)
    order = np.argsort(key)
    sorted_key = key[order]
    first = np.ones(n, dtype=bool)
    first[1:] = sorted_key[1:] != sorted_key[:-1]
    inverse[order] = np.cumsum(first) - 1
    out: np.ndarray = order[first]
    return out, inverse


def keys(bits: np.ndarray, *, bytewise: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(hi, lo) uint64 keys of (M, 3) uint32 rows: hi = x << 32 | y, lo = z.

    `bytewise` swaps each word's bytes first, so the keys sort as the rows' little-endian
    bytes compare (memcmp order: what `np.unique` on 12-byte void rows sorts by).
    """
    b = np.ascontiguousarray(bits, dtype=np.uint32)
    if bytewise:
        b = b.byteswap()
    wide = b.astype(np.uint64)
    return (wide[:, 0] << np.uint64(32)) | wide[:, 1], wide[:, 2]
