"""contract/vertex_ids.py numbers vertices exactly as the np.unique / np.lexsort code it replaced,
and proves the export's numbering (vertex_ids.u32) is that numbering before the verifier uses it."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from fixtures import REPO, rendiff_binary
from rendiff_harness.contract import resolved, vertex_ids
from rendiff_harness.judge import verify


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


# --------------------------------------------------------------------------- the export's numbers


def _checked(bits: np.ndarray, numbers: np.ndarray) -> np.ndarray:
    return vertex_ids.checked(*vertex_ids.keys(bits, bytewise=True), numbers)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_checked_accepts_the_numbering_group_gives(seed: int) -> None:
    bits = _rows(seed)
    _, inverse = vertex_ids.group(*vertex_ids.keys(bits, bytewise=True))
    assert np.array_equal(_checked(bits, inverse.astype(np.uint32)), inverse)
    assert _checked(bits[:0], np.zeros(0, np.uint32)).size == 0


def _wrong_numberings(bits: np.ndarray) -> dict[str, tuple[np.ndarray, str]]:
    """Each way a numbering can differ from `group`'s, with the words its refusal must say."""
    _, good = vertex_ids.group(*vertex_ids.keys(bits, bytewise=True))
    v = int(good.max()) + 1
    swapped = good.copy()
    swapped[good == 0], swapped[good == 1] = 1, 0  # two vertices' numbers exchanged: order broken
    merged = np.where(good == 1, 0, good)  # two different vertices under one number...
    merged = np.where(merged > 1, merged - 1, merged)  # ...and the numbers kept dense
    split = good.copy()
    split[np.flatnonzero(good == 0)[0]] = v  # one vertex under two numbers
    gap = np.where(good > 0, good + 1, good)  # number 1 names no corner
    return {
        "swapped": (swapped, "increasing byte order"),
        "merged": (merged, "differs from another corner"),
        "split": (split, "increasing byte order"),
        "gap": (gap, "names no corner"),
        "short": (good[:-1], "numbers for"),
        "beyond": (np.full(good.size, good.size), "above the"),
    }


@pytest.mark.parametrize("case", ["swapped", "merged", "split", "gap", "short", "beyond"])
def test_checked_refuses_every_other_numbering(case: str) -> None:
    """Each class of wrong numbering is refused, by the check meant for it: so a check that
    stops looking (order, equality, density or size) fails its own case here."""
    bits = _rows(0)
    numbers, words = _wrong_numberings(bits)[case]
    with pytest.raises(ValueError, match=words):
        _checked(bits, numbers.astype(np.uint32))


def test_the_export_writes_the_verifiers_numbering(tmp_path: Path) -> None:
    """`rendiff export`'s vertex_ids.u32 (the core's scene/vertex_ids.rs) is `group`'s bytewise
    numbering of triangles.f32, on a mesh with shared vertices, and the verifier's topology is
    the same with it as without it."""
    binary = rendiff_binary()
    if binary is None:
        pytest.skip("no built rendiff (cargo build first): the file comes from its export")
    out = tmp_path / "out"
    subprocess.run([str(binary), "export", str(REPO / "scenes/obj_mesh.toml"), "-o", str(out)], check=True)
    scene = resolved.load(out)
    numbers = scene.corner_vertex_ids()
    assert numbers is not None and numbers.shape == (scene.triangle_count, 3)
    _, want = vertex_ids.group(*vertex_ids.corner_keys(scene.triangles))
    assert int(want.max()) + 1 < want.size  # the mesh shares vertices
    assert np.array_equal(numbers.ravel(), want)
    with_file, without = verify.scene_topology(scene), verify.topology(scene.triangles)
    for name in ("corner_vid", "keys", "key_tri", "key_local", "vertices"):
        assert np.array_equal(getattr(with_file, name), getattr(without, name)), name
    # A tampered file is the scene's error, naming the file, not a verdict.
    bad = numbers.ravel().copy()
    bad[[0, 1]] = bad[[1, 0]] if bad[0] != bad[1] else (bad[0], bad[0] + 1)
    bad.astype("<u4").tofile(out / "vertex_ids.u32")
    with pytest.raises(resolved.SceneError, match="vertex_ids.u32"):
        verify.scene_topology(resolved.load(out))
