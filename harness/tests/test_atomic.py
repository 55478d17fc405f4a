"""atomic.py, the one home of the atomic writes, and the temp files each caller uses."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import numpy as np
import pytest

from rendiff_harness import compare
from rendiff_harness.contract import atomic, exrbuf
from rendiff_harness.judge import diffimages
from rendiff_harness.renderers.mitsuba import reference as mitsuba_reference


def _names(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir())


def _temp_names(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Record the temp file of every os.replace (the rename still happens)."""
    seen: list[str] = []
    real = os.replace

    def spy(src: str | Path, dst: str | Path) -> None:
        seen.append(Path(src).name)
        real(src, dst)

    monkeypatch.setattr(os, "replace", spy)
    return seen


def test_write_bytes_and_text(tmp_path: Path) -> None:
    atomic.write_bytes_atomically(tmp_path / "a.bin", b"\x00\x01")
    atomic.write_text_atomically(tmp_path / "b.txt", "π\n")
    assert (tmp_path / "a.bin").read_bytes() == b"\x00\x01"
    assert (tmp_path / "b.txt").read_bytes() == "π\n".encode()
    assert _names(tmp_path) == ["a.bin", "b.txt"]


def test_written_files_have_the_mode_a_plain_write_gives(tmp_path: Path) -> None:
    # mkstemp's 0600 stayed on every result: results.json was unreadable to all but its writer.
    atomic.write_text_atomically(tmp_path / "r.json", "{}\n")
    (tmp_path / "plain.json").write_text("{}\n")
    mode = stat.S_IMODE((tmp_path / "r.json").stat().st_mode)
    assert mode == stat.S_IMODE((tmp_path / "plain.json").stat().st_mode) == atomic.FILE_MODE


def test_temp_name_defaults_and_overrides(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    seen = _temp_names(monkeypatch)
    atomic.write_bytes_atomically(tmp_path / "a.bin", b"1")
    atomic.write_text_atomically(tmp_path / "b.txt", "2", prefix=".x.", suffix=".y.tmp")
    assert seen[0].startswith(".a.bin.") and seen[0].endswith(".tmp")
    assert seen[1].startswith(".x.") and seen[1].endswith(".y.tmp")


@pytest.mark.parametrize("error", [OSError(28, "No space left on device"), KeyboardInterrupt()])
def test_failure_keeps_the_previous_file_and_no_temp(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, error: BaseException
) -> None:
    path = tmp_path / "a.bin"
    atomic.write_bytes_atomically(path, b"old")

    def boom(fd: int) -> None:
        raise error

    monkeypatch.setattr(os, "fsync", boom)
    with pytest.raises(type(error)):
        atomic.write_bytes_atomically(path, b"new")
    with pytest.raises(type(error)):
        atomic.write_text_atomically(path, "new")
    assert path.read_bytes() == b"old"
    assert _names(tmp_path) == ["a.bin"]


def test_missing_folder_raises_before_writing(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        atomic.AtomicFile(tmp_path / "nope" / "a.bin")
    assert _names(tmp_path) == []


def test_renamed_into_place(tmp_path: Path) -> None:
    path, temp = tmp_path / "a.png", tmp_path / ".a.tmp.png"
    with atomic.renamed_into_place(temp, path) as name:
        assert name == temp
        temp.write_bytes(b"new")
    assert path.read_bytes() == b"new" and _names(tmp_path) == ["a.png"]
    with pytest.raises(RuntimeError), atomic.renamed_into_place(temp, path):
        temp.write_bytes(b"half")
        raise RuntimeError("writer failed")
    assert path.read_bytes() == b"new" and _names(tmp_path) == ["a.png"]


def test_renamed_into_place_removes_the_temp_when_the_rename_fails(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def boom(src: str, dst: str) -> None:
        raise OSError(5, "I/O error")

    monkeypatch.setattr(os, "replace", boom)
    temp = tmp_path / ".a.tmp.png"
    with pytest.raises(OSError, match="I/O error"), atomic.renamed_into_place(temp, tmp_path / "a.png"):
        temp.write_bytes(b"new")
    assert _names(tmp_path) == []


# ------------------------------------------------------------------ each caller's temp files


def test_results_json_temp_name(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    seen = _temp_names(monkeypatch)
    path = compare.write_results(tmp_path, {"b": 1, "a": [1.5]})
    assert path == tmp_path / "results.json"
    assert path.read_text(encoding="utf-8") == '{\n "b": 1,\n "a": [\n  1.5\n ]\n}\n'
    assert seen[0].startswith(".results.") and seen[0].endswith(".json.tmp")
    assert stat.S_IMODE(path.stat().st_mode) == atomic.FILE_MODE  # a plain write's mode, not mkstemp's 0600


def test_reference_provenance_temp_name(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    seen = _temp_names(monkeypatch)
    mitsuba_reference._write_json_atomically(tmp_path / "ref.json", {"spp": 4})
    assert (tmp_path / "ref.json").read_text(encoding="utf-8") == '{\n "spp": 4\n}\n'
    assert seen[0].startswith(".ref.json.") and seen[0].endswith(".tmp")


def test_buffer_exr_temp_name_and_errors(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    seen = _temp_names(monkeypatch)
    exrbuf.write_buffers(tmp_path / "b.exr", Z=np.ones((2, 2)))
    assert seen[0].startswith(".b.exr.") and seen[0].endswith(".tmp")
    with pytest.raises(exrbuf.BufferError, match="cannot create a temp file in"):
        exrbuf.write_buffers(tmp_path / "nope" / "b.exr", Z=np.ones((2, 2)))
    assert _names(tmp_path) == ["b.exr"]


def test_diff_png_temp_name_and_permissions(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    seen = _temp_names(monkeypatch)
    path = tmp_path / "povray.id.png"
    diffimages._write_png(path, np.zeros((2, 3, 3)))
    assert seen == [f".povray.id.{os.getpid()}.tmp.png"]
    assert _names(tmp_path) == ["povray.id.png"]
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask  # created by OpenImageIO, not mkstemp


def test_diff_png_failure_leaves_no_temp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def boom(src: str, dst: str) -> None:
        raise OSError(5, "I/O error")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(diffimages.DiffImageError, match="I/O error"):
        diffimages._write_png(tmp_path / "a.png", np.zeros((2, 3, 3)))
    assert _names(tmp_path) == []
