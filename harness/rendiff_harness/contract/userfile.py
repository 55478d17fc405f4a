"""Reading a file a user names (a renderers file, an expectations file, a cached reference):
regular files only, within a size limit, opened non-blocking, so that a FIFO is refused
instead of waited on and a device (`/dev/zero`) or a huge file is refused instead of read
until memory runs out."""

from __future__ import annotations

import hashlib
import os
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO


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
