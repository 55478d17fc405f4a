"""Reading a file a user names (a renderers file, an expectations file, a cached reference):
regular files only, within a size limit, opened non-blocking, so that a FIFO is refused
instead of waited on and a device (`/dev/zero`) or a huge file is refused instead of read
until memory runs out. `read_json` is the one reader of a JSON file (a run record, a resolved
scene, a metamorphic spec, a reference's provenance) with those checks and UTF-8."""

from __future__ import annotations

import hashlib
import json
import os
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, BinaryIO


class UserFileError(ValueError):
    """What is wrong with the file, in words (the caller names the file and its role)."""


@contextmanager
def open_regular(path: Path) -> Iterator[BinaryIO]:
    """`path` opened for reading, if it is a regular file (UserFileError otherwise; FileNotFoundError
    and other OSErrors from opening pass through). Opening never blocks: a FIFO without a writer
    is opened at once, then refused."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    try:
        # checked before fdopen, which refuses a folder with an OSError of its own
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise UserFileError("is not a regular file")
        fh = os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise
    with fh:
        yield fh


def read_regular(path: Path, limit: int) -> bytes:
    """The bytes of the regular file `path`, at most `limit` of them (UserFileError otherwise;
    FileNotFoundError and other OSErrors from opening pass through)."""
    with open_regular(path) as fh:
        raw = fh.read(limit + 1)
    if len(raw) > limit:
        raise UserFileError(f"is larger than {limit} bytes")
    return raw


def sha256_regular(path: Path, limit: int) -> str:
    """The sha256 (hex) of the regular file `path`, read in blocks, refused past `limit` bytes
    (UserFileError; OSErrors from opening pass through, as in read_regular)."""
    h = hashlib.sha256()
    total = 0
    with open_regular(path) as fh:
        while block := fh.read(min(1 << 20, limit + 1 - total)):
            total += len(block)
            if total > limit:
                raise UserFileError(f"is larger than {limit} bytes")
            h.update(block)
    return h.hexdigest()


class JsonFileError(ValueError):
    """A JSON file that cannot be read, in one line: `str()` is `PATH: problem`.

    `cause` says which check refused it (`missing`, `file`: not a regular file or too large,
    `unreadable`: an OS error or bytes that are not UTF-8, `json`: not valid JSON, `format`: not
    the record `read_record` expects) and `detail`
    the problem without its label, so a caller that words the message itself (a cached
    reference's provenance) keeps one source of truth for the checks."""

    def __init__(self, path: Path, cause: str, detail: str, hint: str = "") -> None:
        label = {"missing": "missing", "unreadable": "unreadable: ", "json": "not valid JSON: "}.get(cause, "")
        problem = f"{label}{hint}" if cause == "missing" else f"{label}{detail}"
        super().__init__(f"{path}: {problem}")
        self.path = path
        self.cause = cause
        self.detail = detail
        self.problem = problem


UTF8_BOM = b"\xef\xbb\xbf"


def read_json(path: Path, limit: int, missing_hint: str = "") -> object:
    """The parsed JSON of the regular file `path` (a run record, a resolved scene, a user's spec):
    at most `limit` bytes, UTF-8 without a byte order mark (RFC 8259: a JSON text has none, and
    rendiff's own reader refuses one too), anything else a JsonFileError naming the file.
    `missing_hint` follows `missing` when the file does not exist (what to run first)."""
    try:
        raw = read_regular(path, limit)
    except FileNotFoundError:
        raise JsonFileError(path, "missing", "not found", missing_hint) from None
    except UserFileError as exc:
        raise JsonFileError(path, "file", str(exc)) from None
    except OSError as exc:
        raise JsonFileError(path, "unreadable", str(exc.strerror or exc)) from None
    if raw.startswith(UTF8_BOM):
        raise JsonFileError(path, "json", "starts with a byte order mark (JSON has none)")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise JsonFileError(
            path, "unreadable", f"not UTF-8 text (invalid byte 0x{raw[exc.start]:02x} at offset {exc.start})"
        ) from None
    try:
        return json.loads(text)
    except RecursionError:
        raise JsonFileError(path, "json", "nested too deeply") from None
    except ValueError as exc:  # JSONDecodeError, or an integer with too many digits
        raise JsonFileError(path, "json", str(exc)) from None


def read_record(path: Path, limit: int, fmt: str, missing_hint: str = "") -> dict[str, Any]:
    """`read_json` of one of rendiff's records (manifest.json, a resolved scene's scene.json): a
    JSON object whose `format` is `fmt`, else a JsonFileError saying which."""
    data = read_json(path, limit, missing_hint)
    if not isinstance(data, dict):
        raise JsonFileError(path, "format", "must be a JSON object")
    if data.get("format") != fmt:
        raise JsonFileError(path, "format", f"format is {data.get('format')!r}, expected {fmt!r}")
    return data
