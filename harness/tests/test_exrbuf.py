"""Buffer EXR round trips: IDs must come back bit-exact, writes must be atomic."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest

from rendiff_harness.contract import exrbuf, vocab
from rendiff_harness.contract.exrbuf import BufferError

DATA = Path(__file__).parent / "data"
EDGE_IDS = [0, 1, 2**24 - 1, 2**24, 2**24 + 1, 2**31 - 1, 2**31, 2**31 + 1, 2**32 - 2, 2**32 - 1]


def _random_ids(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    ids = rng.integers(0, 2**32, size=(h, w), dtype=np.uint64).astype(np.uint32)
    ids.ravel()[: len(EDGE_IDS)] = EDGE_IDS
    return ids


@pytest.mark.parametrize("compression", ["none", "zip"])
def test_round_trip_is_bit_exact(tmp_path: Path, compression: str) -> None:
    rng = np.random.default_rng(7)
    h, w = 37, 53  # odd sizes: partial ZIP chunks, odd byte counts
    prim, obj = _random_ids(rng, h, w), _random_ids(rng, h, w)
    z = rng.standard_normal((h, w)).astype(np.float32)
    z.ravel()[:5] = [np.inf, np.nan, -0.0, 1e-45, np.float32(3.4e38)]
    n = rng.standard_normal((h, w, 3)).astype(np.float32)
    rgb = rng.random((h, w, 3)).astype(np.float32)
    path = tmp_path / "b.exr"
    exrbuf.write_buffers(path, Z=z, prim=prim, obj=obj, N=n, RGB=rgb, compression=compression)
    got = exrbuf.read_buffers(path, require=["Z", "id.prim", "id.object", "N", "RGB"])
    assert got["id.prim"].dtype == np.uint32 and got["id.object"].dtype == np.uint32
    assert np.array_equal(got["id.prim"], prim)
    assert np.array_equal(got["id.object"], obj)
    assert np.array_equal(got["Z"].view(np.uint32), z.view(np.uint32))  # inf/nan/-0 bits too
    assert np.array_equal(got["N"], n) and np.array_equal(got["RGB"], rgb)


def test_ids_are_uint_channels_in_the_file(tmp_path: Path) -> None:
    path = tmp_path / "b.exr"
    exrbuf.write_buffers(path, Z=np.zeros((2, 3)), prim=np.zeros((2, 3), np.uint32), obj=np.ones((2, 3), np.int64))
    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    types = {n: str(f) for n, f in zip(spec.channelnames, spec.channelformats, strict=True)}
    inp.close()
    assert types == {"Z": "float", "id.object": "uint", "id.prim": "uint"}


def test_zip_compresses_typical_buffers(tmp_path: Path) -> None:
    h, w = 120, 160
    z = np.full((h, w), np.inf, np.float32)
    z[20:80, 40:120] = 5.0
    prim = np.where(np.isfinite(z), 7, vocab.BACKGROUND_ID).astype(np.uint32)
    raw, zipped = tmp_path / "raw.exr", tmp_path / "zip.exr"
    exrbuf.write_buffers(raw, Z=z, prim=prim, compression="none")
    exrbuf.write_buffers(zipped, Z=z, prim=prim, compression="zip")
    assert zipped.stat().st_size < raw.stat().st_size / 10
    assert np.array_equal(exrbuf.read_buffers(zipped)["id.prim"], prim)


def test_attrs_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "b.exr"
    attrs = {
        "backend": "povray",
        "version": "POV-Ray 3.7",
        "time_s": 1.0 / 3.0,
        "threads": 2,
        "x" * 40: "long name",
    }
    exrbuf.write_buffers(path, Z=np.ones((1, 1)), attrs=attrs)
    assert exrbuf.read_attrs(path) == attrs


def test_reads_files_written_by_the_rust_exr_crate() -> None:
    """tests/data/exr_crate_5x3.exr was written by the `exr` crate 1.73 as the Rust core does."""
    got = exrbuf.read_buffers(DATA / "exr_crate_5x3.exr", require=["Z", "id.prim", "id.object", "N"])
    i = np.arange(15, dtype=np.uint64)
    prim = np.where(i == 0, 0xFFFFFFFF, (1 << 24) + i * 7919 + 1).astype(np.uint32).reshape(3, 5)
    obj = np.where(i == 0, 0xFFFFFFFF, i % 3).astype(np.uint32).reshape(3, 5)
    z = np.where(i == 0, np.inf, np.float32(1.0) + i.astype(np.float32) / np.float32(3.0)).astype(np.float32)
    nx = (i.astype(np.float32) * np.float32(0.1)).reshape(3, 5)
    assert np.array_equal(got["id.prim"], prim)
    assert np.array_equal(got["id.object"], obj)
    assert np.array_equal(got["Z"], z.reshape(3, 5))
    assert np.array_equal(got["N"], np.stack([nx, nx, nx], axis=-1))


def _leftovers(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir())


def test_failed_write_leaves_no_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "b.exr"

    def boom(fd: int) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "fsync", boom)
    with pytest.raises(BufferError, match="write failed"):
        exrbuf.write_buffers(path, Z=np.ones((4, 4)))
    assert _leftovers(tmp_path) == []


def test_failed_write_keeps_the_previous_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "b.exr"
    exrbuf.write_buffers(path, Z=np.full((4, 4), 2.0))
    before = path.read_bytes()

    def boom(src: str, dst: str) -> None:
        raise OSError(5, "I/O error")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(BufferError):
        exrbuf.write_buffers(path, Z=np.full((4, 4), 3.0))
    assert path.read_bytes() == before
    assert _leftovers(tmp_path) == ["b.exr"]


def test_interrupted_write_leaves_no_temp_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def interrupt(fd: int) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "fsync", interrupt)
    with pytest.raises(KeyboardInterrupt):
        exrbuf.write_buffers(tmp_path / "b.exr", Z=np.ones((2, 2)))
    assert _leftovers(tmp_path) == []


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({}, "no buffer given"),
        ({"Z": np.ones((2, 2)), "prim": np.ones((3, 2), np.uint32)}, "differ in size"),
        ({"prim": np.ones((2, 2), np.float32)}, "integer array"),
        ({"prim": np.full((2, 2), -1, np.int64)}, "outside"),
        ({"prim": np.full((2, 2), 2**32, np.int64)}, "outside"),
        ({"N": np.ones((2, 2))}, r"\(H, W, 3\)"),
        ({"Z": np.ones(4)}, "2-D"),
        ({"Z": np.ones((2, 2)), "attrs": {"flag": True}}, "bool"),
        ({"Z": np.ones((2, 2)), "attrs": {"big": 2**40}}, "32 bits"),
    ],
)
def test_invalid_input_is_refused_before_writing(tmp_path: Path, kwargs: dict, message: str) -> None:
    path = tmp_path / "b.exr"
    with pytest.raises(BufferError, match=message):
        exrbuf.write_buffers(path, **kwargs)
    assert _leftovers(tmp_path) == []


def test_missing_and_unreadable_files(tmp_path: Path) -> None:
    missing = tmp_path / "nope.exr"
    with pytest.raises(BufferError, match=r"nope\.exr: missing"):
        exrbuf.read_buffers(missing)
    garbage = tmp_path / "garbage.exr"
    garbage.write_bytes(b"not an exr at all")
    with pytest.raises(BufferError, match=r"garbage\.exr: unreadable"):
        exrbuf.read_buffers(garbage)
    with pytest.raises(BufferError, match="missing"):
        exrbuf.read_attrs(missing)


def test_missing_channels_are_reported(tmp_path: Path) -> None:
    path = tmp_path / "b.exr"
    exrbuf.write_buffers(path, Z=np.ones((2, 2)))
    assert set(exrbuf.read_buffers(path)) == {"Z"}
    with pytest.raises(BufferError, match=r"b\.exr: missing channels for \['id.prim'\]"):
        exrbuf.read_buffers(path, require=["Z", "id.prim"])


def test_ids_stored_as_float_are_refused(tmp_path: Path) -> None:
    """An ID channel that went through float cannot be exact; never read it as if it were."""
    path = tmp_path / "float_ids.exr"
    spec = oiio.ImageSpec(2, 2, 1, oiio.FLOAT)
    spec.channelnames = ("id.prim",)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec)
    out.write_image(np.zeros((2, 2, 1), np.float32))
    out.close()
    with pytest.raises(BufferError, match="expected uint"):
        exrbuf.read_buffers(path)
