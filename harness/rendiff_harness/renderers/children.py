"""Child processes that cannot outlive the harness.

rendiff runs the harness in a process group of its own and, on a timeout or an
interruption, kills that whole group. A renderer the harness starts (POV-Ray)
therefore stays in the harness's group, and is also started with Linux's
``PR_SET_PDEATHSIG``, so it is killed even when the harness dies by a signal
nobody can catch (SIGKILL). Without both, an interrupted ``rendiff check`` left
POV-Ray running and writing into a run folder that no longer existed.

A user's renderer declared by a command (renderers/command.py) is different: it may start
processes of its own, which a timeout must end too, so `run_in_group` runs it in a process
group of its own (stdin from /dev/null) and kills that whole group when it exits, when the
timeout passes, and when the harness is interrupted while waiting. A group of its own is
out of reach of rendiff's kill of the harness's group, so the group's leader is a small
supervisor (`SUPERVISOR`, this Python without site packages) that starts the renderer and
waits for it: ``PR_SET_PDEATHSIG`` sends it SIGTERM when the harness dies, by any signal,
and it then kills its whole group, the renderer's children included. The supervisor's
process id stays the group's id until the harness reaps it, so the harness's group kill can
never reach a group that reused the number.

Its stdout and stderr come back through pipes that the harness drains while it waits (so the
program never blocks on a full pipe), keeping only a bounded `Capture` of each: the first and
the last `OUTPUT_KEEP_BYTES`, the middle counted and dropped. A renderer that prints gigabytes
costs neither memory nor disk (it once filled 2.1 GB of log files under /tmp, and passed).
"""

from __future__ import annotations

import ctypes
import os
import selectors
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

_PR_SET_PDEATHSIG = 1


def _load_prctl() -> Callable[..., int] | None:
    if not sys.platform.startswith("linux"):
        return None
    try:
        prctl: Callable[..., int] = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None
    return prctl


# Looked up once, before any fork: the hook below runs between fork and exec,
# where only async-signal-safe work belongs.
_PRCTL = _load_prctl()


def die_with_parent() -> None:
    """``preexec_fn`` for ``subprocess``: the child gets SIGKILL when the harness dies."""
    if _PRCTL is not None:
        _PRCTL(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)


def _term_with_parent() -> None:
    """``preexec_fn`` for the supervisor: SIGTERM when the harness dies (it then kills its group)."""
    if _PRCTL is not None:
        _PRCTL(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)


SUPERVISOR = """
import os, signal, sys
parent, argv = int(sys.argv[1]), sys.argv[2:]
def end(signum, frame):
    os.killpg(0, signal.SIGKILL)
signal.signal(signal.SIGTERM, end)
if os.getppid() != parent:
    end(0, None)
pid = os.fork()
if pid == 0:
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    for name in ("SIGPIPE", "SIGXFSZ"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), signal.SIG_DFL)
    try:
        os.execv(argv[0], argv)
    except OSError as exc:
        sys.stderr.write(f"cannot execute {argv[0]}: {exc.strerror}\\n")
        sys.stderr.flush()
    os._exit(127)
while True:
    try:
        status = os.waitpid(pid, 0)[1]
        break
    except InterruptedError:
        continue
if os.WIFSIGNALED(status):
    sig = os.WTERMSIG(status)
    try:
        signal.signal(sig, signal.SIG_DFL)
    except (OSError, ValueError):
        pass
    try:
        import resource
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    except (ImportError, OSError, ValueError):
        pass
    os.kill(os.getpid(), sig)
    os._exit(128 + sig)
os._exit(os.waitstatus_to_exitcode(status))
"""
"""The group leader of `run_in_group`: `python -I -S -c SUPERVISOR HARNESS_PID PROGRAM ARGS...`
runs PROGRAM ARGS (execv, no shell), exits with its status (or dies by its signal), and kills
its whole group when the harness dies (SIGTERM from ``PR_SET_PDEATHSIG``; also when the
harness is already gone at its start).

PROGRAM starts with SIGPIPE and SIGXFSZ at their defaults, as `subprocess` gives (Python
ignores them, and an ignored signal stays ignored across exec: a renderer writing into a
closed pipe would otherwise spin on EPIPE instead of dying). Passing a signal death on, the
supervisor resets that signal's handler where one can be set (SIGKILL, the out-of-memory
killer's, has none: setting it raised, and the renderer's death read as "exited with status
1" under the supervisor's traceback) and dumps no core of its own; the renderer's core, if
any, is the one that matters."""


# What is kept of each output stream of a `run_in_group` program: its first and its last
# 1 MiB (thousands of lines of context at either end). The output is read for its last stderr
# lines (an error's message, a skip's reason) and its start (a version line); a renderer left
# printing a debug dump wrote 2 GB to stdout and 0.5 GB to stderr in one render, and keeping
# all of it filled the disk (or memory) for nothing. The middle is counted, not kept.
OUTPUT_KEEP_BYTES = 1 << 20

# Bytes read from a pipe at a time: the size of Linux's default pipe buffer, so one read
# usually empties it.
READ_CHUNK_BYTES = 1 << 16

# How long the pipes are still read after the group is killed: what its processes wrote
# before they died is in the pipe buffers (64 KiB each) and takes microseconds to read; the
# bound only stops a process that left the group (setsid) from keeping the harness reading.
FINAL_DRAIN_S = 1.0


@dataclass
class Capture:
    """What is kept of one output stream: its first `head_limit` and last `tail_limit` bytes,
    and how many bytes it had in all (`total`); the middle is dropped."""

    head_limit: int = OUTPUT_KEEP_BYTES
    tail_limit: int = OUTPUT_KEEP_BYTES
    total: int = 0
    _head: bytearray = field(default_factory=bytearray, repr=False)
    _tail: bytearray = field(default_factory=bytearray, repr=False)

    def add(self, data: bytes) -> None:
        """Take the next bytes of the stream."""
        self.total += len(data)
        room = self.head_limit - len(self._head)
        if room > 0:
            self._head += data[:room]
            data = data[room:]
        if data and self.tail_limit > 0:
            self._tail += data
            if len(self._tail) > 2 * self.tail_limit:  # trimmed in batches: amortized O(1) a byte
                del self._tail[: len(self._tail) - self.tail_limit]

    @property
    def head(self) -> bytes:
        """The first bytes kept (at most `head_limit`)."""
        return bytes(self._head)

    @property
    def tail(self) -> bytes:
        """The last bytes kept after the head (at most `tail_limit`)."""
        return bytes(self._tail[-self.tail_limit :]) if self.tail_limit > 0 else b""

    @property
    def omitted(self) -> int:
        """Bytes of the stream that were dropped (0: `kept()` is all of it)."""
        return self.total - len(self._head) - len(self.tail)

    def kept(self) -> bytes:
        """The kept bytes; where bytes were dropped, a line in their place says how many."""
        if not self.omitted:
            return self.head + self.tail
        note = (
            f"\n[rendiff: {self.omitted} bytes omitted here; the stream had {self.total} bytes, "
            f"of which the first {len(self._head)} and the last {len(self.tail)} are kept]\n"
        )
        return self.head + note.encode() + self.tail


@dataclass(frozen=True)
class GroupRun:
    """How a `run_in_group` process ended, and what is kept of its output."""

    returncode: int | None  # None when it timed out (killed); negative: killed by that signal
    timed_out: bool
    elapsed_s: float
    stdout: Capture
    stderr: Capture


def _exited(pid: int) -> bool:
    """True when `pid` (a child of ours) has exited; it is *not* reaped (WNOWAIT)."""
    return os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is not None


def kill_group(pgid: int) -> None:
    """SIGKILL every process of the group `pgid`; a group already gone is fine."""
    try:
        os.killpg(pgid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def _read(sel: selectors.BaseSelector, fd: int, sink: Capture) -> bool:
    """Read once from the non-blocking pipe `fd` into `sink`; False when there was nothing to
    read now. At its end the pipe is unregistered."""
    try:
        data = os.read(fd, READ_CHUNK_BYTES)
    except BlockingIOError:
        return False
    if not data:
        sel.unregister(fd)
        return False
    sink.add(data)
    return True


def run_in_group(
    argv: Sequence[str],
    *,
    cwd: Path,
    env: Mapping[str, str],
    timeout_s: float,
    stdout: Capture | None = None,
    stderr: Capture | None = None,
) -> GroupRun:
    """Run `argv` (no shell; argv[0] a path) in a new process group, killing the group at the end.

    The group's leader is `SUPERVISOR`, which runs `argv` and passes its exit status (or
    signal) through; a program that cannot be executed exits 127 with the reason on stderr.
    stdin is /dev/null; stdout and stderr are pipes, drained while it runs into `stdout` and
    `stderr` (default: `Capture()`, the first and last `OUTPUT_KEEP_BYTES` of each), which
    come back in the `GroupRun`. The wait ends with the leader's exit, not with the pipes':
    a process that keeps a pipe open past the group's kill cannot make us wait.
    """
    out = Capture() if stdout is None else stdout
    err = Capture() if stderr is None else stderr
    t0 = time.monotonic()
    deadline = t0 + timeout_s
    proc = subprocess.Popen(
        [sys.executable, "-I", "-S", "-c", SUPERVISOR, str(os.getpid()), *argv],
        cwd=cwd,
        env=dict(env),
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        process_group=0,
        preexec_fn=_term_with_parent,
    )
    assert proc.stdout is not None and proc.stderr is not None
    sinks = {proc.stdout.fileno(): out, proc.stderr.fileno(): err}
    timed_out = False
    with selectors.DefaultSelector() as sel, proc.stdout, proc.stderr:
        for fd in sinks:
            os.set_blocking(fd, False)
            sel.register(fd, selectors.EVENT_READ)
        try:
            delay = 0.002
            while not _exited(proc.pid):
                now = time.monotonic()
                if now >= deadline:
                    timed_out = True
                    break
                wait = min(delay, deadline - now)
                delay = min(delay * 2.0, 0.05)
                if not sel.get_map():  # both pipes closed: only the exit is left to wait for
                    time.sleep(wait)
                    continue
                for key, _ in sel.select(wait):
                    _read(sel, key.fd, sinks[key.fd])
        finally:
            # The leader is not reaped yet (running or a zombie), so its pid still names this group.
            kill_group(proc.pid)
            proc.wait()
            # What the group wrote before it died is still in the pipes.
            end = time.monotonic() + FINAL_DRAIN_S
            for fd, sink in sinks.items():
                while fd in sel.get_map() and time.monotonic() < end and _read(sel, fd, sink):
                    pass
    elapsed = time.monotonic() - t0
    return GroupRun(None if timed_out else proc.returncode, timed_out, elapsed, out, err)
