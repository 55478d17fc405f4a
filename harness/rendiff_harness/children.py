"""Child processes that cannot outlive the harness.

rendiff runs the harness in a process group of its own and, on a timeout or an
interruption, kills that whole group. A renderer the harness starts (POV-Ray)
therefore stays in the harness's group, and is also started with Linux's
``PR_SET_PDEATHSIG``, so it is killed even when the harness dies by a signal
nobody can catch (SIGKILL). Without both, an interrupted ``rendiff check`` left
POV-Ray running and writing into a run folder that no longer existed.

A user's renderer declared by a command (command_renderers.py) is different: it may start
processes of its own, which a timeout must end too, so `run_in_group` runs it in a process
group of its own (stdin from /dev/null) and kills that whole group when it exits, when the
timeout passes, and when the harness is interrupted while waiting. A group of its own is
out of reach of rendiff's kill of the harness's group, so the group's leader is a small
supervisor (`SUPERVISOR`, this Python without site packages) that starts the renderer and
waits for it: ``PR_SET_PDEATHSIG`` sends it SIGTERM when the harness dies, by any signal,
and it then kills its whole group, the renderer's children included. The supervisor's
process id stays the group's id until the harness reaps it, so the harness's group kill can
never reach a group that reused the number.
"""

from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO

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
    signal.signal(os.WTERMSIG(status), signal.SIG_DFL)
    os.kill(os.getpid(), os.WTERMSIG(status))
os._exit(os.waitstatus_to_exitcode(status))
"""
"""The group leader of `run_in_group`: `python -I -S -c SUPERVISOR HARNESS_PID PROGRAM ARGS...`
runs PROGRAM ARGS (execv, no shell), exits with its status (or dies by its signal), and kills
its whole group when the harness dies (SIGTERM from ``PR_SET_PDEATHSIG``; also when the
harness is already gone at its start)."""


@dataclass(frozen=True)
class GroupRun:
    """How a `run_in_group` process ended."""

    returncode: int | None  # None when it timed out (killed); negative: killed by that signal
    timed_out: bool
    elapsed_s: float


def _exited(pid: int) -> bool:
    """True when `pid` (a child of ours) has exited; it is *not* reaped (WNOWAIT)."""
    return os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is not None


def kill_group(pgid: int) -> None:
    """SIGKILL every process of the group `pgid`; a group already gone is fine."""
    try:
        os.killpg(pgid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def run_in_group(
    argv: Sequence[str],
    *,
    cwd: Path,
    env: Mapping[str, str],
    stdout: IO[bytes],
    stderr: IO[bytes],
    timeout_s: float,
) -> GroupRun:
    """Run `argv` (no shell; argv[0] a path) in a new process group, killing the group at the end.

    The group's leader is `SUPERVISOR`, which runs `argv` and passes its exit status (or
    signal) through; a program that cannot be executed exits 127 with the reason on stderr.
    stdin is /dev/null; stdout/stderr go to the given files (files, not pipes: a grandchild
    that keeps a pipe open cannot make us wait past the process's own exit).
    """
    t0 = time.monotonic()
    deadline = t0 + timeout_s
    proc = subprocess.Popen(
        [sys.executable, "-I", "-S", "-c", SUPERVISOR, str(os.getpid()), *argv],
        cwd=cwd,
        env=dict(env),
        stdin=subprocess.DEVNULL,
        stdout=stdout,
        stderr=stderr,
        process_group=0,
        preexec_fn=_term_with_parent,
    )
    timed_out = False
    try:
        delay = 0.002
        while not _exited(proc.pid):
            now = time.monotonic()
            if now >= deadline:
                timed_out = True
                break
            time.sleep(min(delay, deadline - now))
            delay = min(delay * 2.0, 0.05)
    finally:
        # The leader is not reaped yet (running or a zombie), so its pid still names this group.
        kill_group(proc.pid)
        proc.wait()
    elapsed = time.monotonic() - t0
    return GroupRun(None if timed_out else proc.returncode, timed_out, elapsed)
