"""Atomic file writes: a temp file in the target's folder, renamed onto the target.

A reader (rendiff, the report, a person) sees either the previous file or the complete new
one, never a half-written file, and a crashed writer can never be mistaken for a result. A
failure at any point, an interrupt included, leaves no temp file behind and an existing
file at the target as it was. Exceptions reach the caller unchanged (the callers turn them
into their own messages).

* `write_bytes_atomically` / `write_text_atomically`: the whole content at once; the temp
  file is a new `tempfile.mkstemp` file, given the mode a plainly created file would have
  (0666 less the umask; mkstemp's 0600 made results.json unreadable to anyone but its
  writer), flushed and fsynced before the rename.
* `AtomicFile`: the same in two steps, for a caller that tells a temp file that cannot be
  created apart from a write that fails (exrbuf).
* `renamed_into_place`: for a writer that needs a file name and creates the file itself
  (OpenImageIO): the caller names the temp file; no fsync.

An output is only ever a regular file (or nothing yet, or a symlink: the rename replaces
the link itself, never its target). A FIFO, device, socket or folder at the target is
refused (`OutputError`, an OSError) before the temp file is made and again just before the
rename, as Rust's `exr_io::check_output` does: a rename would otherwise put the result in
place of the node. Commands call `special_entry` / `check_output` on their output paths
before any long work, so that the refusal comes first.
"""

from __future__ import annotations

import errno
import os
import stat
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, AnyStr

DEFAULT_SUFFIX = ".tmp"


def _umask() -> int:
    """The process's umask (read by setting it and back: there is no other way)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


FILE_MODE = 0o666 & ~_umask()
"""The mode of every file written here: what `open(path, "w")` would give, read once at import."""


class OutputError(OSError):
    """An output path that names a FIFO, device, socket or folder; `strerror` says which."""


def special_entry(path: str | Path) -> str | None:
    """What the entry at `path` is, in words, when it exists and is neither a regular file nor a
    symlink (as Rust's `scene::special_entry`); None when it may be written over."""
    try:
        mode = os.lstat(path).st_mode
    except (OSError, ValueError):  # absent (or a name no file can have): nothing is replaced
        return None
    if stat.S_ISREG(mode) or stat.S_ISLNK(mode):
        return None
    if stat.S_ISDIR(mode):
        return "is a folder, not a file"
    if stat.S_ISFIFO(mode):
        return "is a FIFO (named pipe), not a regular file"
    if stat.S_ISSOCK(mode):
        return "is a socket, not a regular file"
    if stat.S_ISCHR(mode):
        return "is a character device, not a regular file"
    if stat.S_ISBLK(mode):
        return "is a block device, not a regular file"
    return "is not a regular file"


def check_output(path: str | Path) -> None:
    """Raise OutputError when `path` is a FIFO, device, socket or folder (`special_entry`)."""
    kind = special_entry(path)
    if kind is not None:
        raise OutputError(
            errno.EEXIST, f"{kind}; results are written to regular files only: choose another output", str(path)
        )


def _remove(name: str | Path) -> None:
    try:
        os.unlink(name)
    except FileNotFoundError:
        pass


class AtomicFile:
    """A new content for `path`: `AtomicFile(path)` creates the temp file, `commit*` writes it
    and renames it onto `path`.

    The temp file is `<prefix>XXXXXXXX<suffix>` in `path`'s folder, by default `.<name>.XXXXXXXX.tmp`
    (hidden, and never a name the harness reads). Commit exactly once: a temp file that is
    never committed stays behind.
    """

    def __init__(self, path: str | Path, *, prefix: str | None = None, suffix: str = DEFAULT_SUFFIX) -> None:
        """Create the temp file; raises OSError (nothing was written) when it cannot, OutputError
        when `path` is a FIFO, device, socket or folder."""
        self.path = Path(path)
        check_output(self.path)
        fd, name = tempfile.mkstemp(
            prefix=f".{self.path.name}." if prefix is None else prefix, suffix=suffix, dir=self.path.parent
        )
        try:
            os.fchmod(fd, FILE_MODE)
        except OSError:
            os.close(fd)
            os.unlink(name)
            raise
        self._fd = fd
        self.temp = Path(name)

    def commit(self, data: bytes) -> None:
        """Write `data`, flush and fsync it, and rename the temp file onto `path`.

        On any failure (OSError, or an interrupt) the temp file is removed and the exception
        re-raised; `path` is then as it was before.
        """
        self._commit(lambda: os.fdopen(self._fd, "wb"), data)

    def commit_text(self, text: str, encoding: str = "utf-8") -> None:
        """`commit` for text, written through a text-mode file in `encoding`."""
        self._commit(lambda: os.fdopen(self._fd, "w", encoding=encoding), text)

    def _commit(self, open_temp: Callable[[], IO[AnyStr]], data: AnyStr) -> None:
        try:
            with open_temp() as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
            check_output(self.path)
            os.replace(self.temp, self.path)
        except BaseException:
            _remove(self.temp)
            raise


def write_bytes_atomically(
    path: str | Path, data: bytes, *, prefix: str | None = None, suffix: str = DEFAULT_SUFFIX
) -> None:
    """Replace `path` with `data` atomically (`AtomicFile`: temp file in the same folder + os.replace)."""
    AtomicFile(path, prefix=prefix, suffix=suffix).commit(data)


def write_text_atomically(
    path: str | Path, text: str, *, encoding: str = "utf-8", prefix: str | None = None, suffix: str = DEFAULT_SUFFIX
) -> None:
    """Replace `path` with `text` atomically (`AtomicFile`: temp file in the same folder + os.replace)."""
    AtomicFile(path, prefix=prefix, suffix=suffix).commit_text(text, encoding)


@contextmanager
def renamed_into_place(temp: Path, path: Path) -> Iterator[Path]:
    """Yield `temp` for the block to write; when the block completes, rename it onto `path`.

    For a writer that creates the file itself, by name (so the file gets the writer's usual
    permissions): `temp` must be in `path`'s folder and is the caller's choice of name. It is
    removed whatever happens: after a failure in the block or in the rename, and an exception
    is re-raised unchanged. A FIFO, device, socket or folder at `path` is refused (OutputError)
    before the block runs and again before the rename.
    """
    try:
        check_output(path)
        yield temp
        check_output(path)
        os.replace(temp, path)
    finally:
        if temp.exists():
            temp.unlink()
