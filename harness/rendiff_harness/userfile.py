"""Reading a file a user names (a renderers file, an expectations file): regular files only,
within a size limit, opened non-blocking, so that a FIFO is refused instead of waited on and
a device (`/dev/zero`) or a huge file is refused instead of read until memory runs out."""

from __future__ import annotations

import os
import stat
from pathlib import Path


class UserFileError(ValueError):
    """What is wrong with the file, in words (the caller names the file and its role)."""


def read_regular(path: Path, limit: int) -> bytes:
    """The bytes of the regular file `path`, at most `limit` of them (UserFileError otherwise;
    FileNotFoundError and other OSErrors from opening pass through)."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    with os.fdopen(fd, "rb") as fh:
        if not stat.S_ISREG(os.fstat(fh.fileno()).st_mode):
            raise UserFileError("is not a regular file")
        raw = fh.read(limit + 1)
    if len(raw) > limit:
        raise UserFileError(f"is larger than {limit} bytes")
    return raw
