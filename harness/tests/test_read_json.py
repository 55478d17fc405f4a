"""`userfile.read_json`, the one reader of a JSON run record or user file, and its four callers:
each refusal is one line naming the file, whichever reader met it."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path

import pytest

import backend_cases as cases
from rendiff_harness.contract import manifest, references, resolved
from rendiff_harness.contract.userfile import JsonFileError, read_json, read_record
from rendiff_harness.judge import metamorphic

# (bytes written, the cause read_json gives, words its message holds)
BAD: list[tuple[bytes, str, str]] = [
    (b"\xef\xbb\xbf{}", "json", "byte order mark"),
    (b'{"a": "\xff"}', "unreadable", "not UTF-8 text (invalid byte 0xff at offset 7)"),
    (b"{not json", "json", "not valid JSON"),
    (b"[" * 30_000 + b"]" * 30_000, "json", "nested too deeply"),
    (b"[" + b"9" * 5000 + b"]", "json", "digits"),
    (b"x" * 101, "file", "is larger than 100 bytes"),
]


@pytest.mark.parametrize(("raw", "cause", "says"), BAD, ids=["bom", "utf8", "syntax", "deep", "digits", "size"])
def test_each_refusal_is_one_line_naming_the_file(tmp_path: Path, raw: bytes, cause: str, says: str) -> None:
    path = tmp_path / "x.json"
    path.write_bytes(raw)
    limit = 100 if cause == "file" else len(raw)
    with pytest.raises(JsonFileError) as info:
        read_json(path, limit)
    assert info.value.cause == cause
    assert str(info.value).startswith(f"{path}: ") and says in str(info.value) and "\n" not in str(info.value)


def test_missing_and_special_files(tmp_path: Path) -> None:
    with pytest.raises(JsonFileError) as info:
        read_json(tmp_path / "none.json", 100, " (run it first)")
    assert info.value.cause == "missing" and str(info.value) == f"{tmp_path / 'none.json'}: missing (run it first)"
    fifo = tmp_path / "f.json"
    os.mkfifo(fifo)
    with pytest.raises(JsonFileError, match="is not a regular file"):
        read_json(fifo, 100)
    with pytest.raises(JsonFileError, match="is not a regular file"):
        read_json(tmp_path, 100)


def test_valid_json_at_the_limit_is_read(tmp_path: Path) -> None:
    path = tmp_path / "x.json"
    text = json.dumps({"format": "f", "list": [1, 2.5, "é"]}).encode("utf-8")
    path.write_bytes(text)
    assert read_json(path, len(text)) == {"format": "f", "list": [1, 2.5, "é"]}


@pytest.mark.parametrize(
    ("doc", "says"), [([1], "must be a JSON object"), ({"format": "other/1"}, "format is 'other/1', expected 'mine/1'")]
)
def test_a_record_is_an_object_of_its_format(tmp_path: Path, doc: object, says: str) -> None:
    path = tmp_path / "x.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(JsonFileError) as info:
        read_record(path, 1000, "mine/1")
    assert info.value.cause == "format" and str(info.value) == f"{path}: {says}"
    path.write_text(json.dumps({"format": "mine/1", "a": 1}))
    assert read_record(path, 1000, "mine/1") == {"format": "mine/1", "a": 1}


def _manifest(tmp_path: Path) -> tuple[Path, Callable[[], object]]:
    return tmp_path / "manifest.json", lambda: manifest.load_manifest(tmp_path)


def _scene(tmp_path: Path) -> tuple[Path, Callable[[], object]]:
    return tmp_path / "scene.json", lambda: resolved.load(tmp_path)


def _spec(tmp_path: Path) -> tuple[Path, Callable[[], object]]:
    return tmp_path / "spec.json", lambda: metamorphic.load_spec(tmp_path / "spec.json")


def _provenance(tmp_path: Path) -> tuple[Path, Callable[[], object]]:
    scene_dir = cases.cornell(tmp_path / "scene", width=8, height=8)
    exr = tmp_path / "box.exr"
    exr.write_bytes(b"not read: the provenance is read after the EXR's checksum")
    return references.provenance_path(exr), lambda: references.load(exr, resolved.load(scene_dir))


@pytest.mark.parametrize("reader", [_manifest, _scene, _spec, _provenance], ids=["manifest", "scene", "spec", "prov"])
@pytest.mark.parametrize(("raw", "says"), [(b"\xef\xbb\xbf{}", "byte order mark"), (b"{x", "Expecting")])
def test_every_reader_refuses_through_read_json(
    tmp_path: Path, reader: Callable[[Path], tuple[Path, Callable[[], object]]], raw: bytes, says: str
) -> None:
    """The four readers word their own context around the same checks, each one line naming the file."""
    path, read = reader(tmp_path)
    path.write_bytes(raw)
    with pytest.raises(
        (manifest.ManifestError, resolved.SceneError, metamorphic.SpecError, references.ReferenceError)
    ) as info:
        read()
    msg = str(info.value)
    assert msg.startswith(f"{path}: ") and says in msg and "\n" not in msg
