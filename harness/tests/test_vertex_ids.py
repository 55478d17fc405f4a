"""contract/vertex_ids.py numbers vertices exactly as the np.unique / np.lexsort code it replaced."""

from __future__ import annotations

import numpy as np
import pytest

from rendiff_harness.contract import vertex_ids


def _old_unique_bytes(bits: np.ndarray) -> np.ndarray:
    """The verifier's numbering before: np.unique on 12-byte rows (memcmp order)."""
    packed = np.ascontiguousarray(bits, dtype=np.uint32).view(np.dtype((np.void, 12))).ravel()
    _, inverse = np.unique(packed, return_inverse=True)
    out: np.ndarray = inverse.ravel().astype(np.int64)
    return out


def _old_lexsort(bits: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """POV-Ray's shared vertices before: lexsort on (x << 32 | y, z)."""
    wide = bits.astype(np.uint64)
    hi, lo = (wide[:, 0] << np.uint64(32)) | wide[:, 1], wide[:, 2]
    order = np.lexsort((lo, hi))
    kh, kl = hi[order], lo[order]
    first = np.ones(order.size, dtype=bool)
    first[1:] = (kh[1:] != kh[:-1]) | (kl[1:] != kl[:-1])
    inverse = np.empty(order.size, dtype=np.int64)
    inverse[order] = np.cumsum(first) - 1
    return bits[order[first]], inverse


def _rows(seed: int) -> np.ndarray:
    """f32 rows with many exact repeats, +0 and -0, and rows equal in x and y but not z
    (ties in the first key that the second must break), as uint32 bits."""
    rng = np.random.default_rng(seed)
    pool = rng.choice(np.array([0.0, -0.0, 1.0, -1.0, 0.5, 3.0e-39, 1e30, 2.0], dtype=np.float32), size=(40, 3))
    pool = np.concatenate([pool, rng.standard_normal((60, 3)).astype(np.float32)])
    pool[-5:, :2] = pool[-10:-5, :2]  # same x, y; other z
    rows = pool[rng.integers(0, pool.shape[0], size=3000)]
    return np.ascontiguousarray(rows).view(np.uint32)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_bytewise_numbering_equals_np_unique_on_rows(seed: int) -> None:
    bits = _rows(seed)
    _, inverse = vertex_ids.group(*vertex_ids.keys(bits, bytewise=True))
    assert np.array_equal(inverse, _old_unique_bytes(bits))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_numeric_numbering_and_representatives_equal_lexsort(seed: int) -> None:
    bits = _rows(seed)
    first, inverse = vertex_ids.group(*vertex_ids.keys(bits))
    old_rows, old_inverse = _old_lexsort(bits)
    assert np.array_equal(inverse, old_inverse)
    assert np.array_equal(bits[first], old_rows)  # a representative of each key: the same bits
    assert np.array_equal(bits[first][inverse], bits)  # every row gets its own value back


def test_empty() -> None:
    first, inverse = vertex_ids.group(*vertex_ids.keys(np.zeros((0, 3), dtype=np.uint32)))
    assert first.size == 0 and inverse.size == 0
