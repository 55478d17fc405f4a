"""Child processes that cannot outlive the harness.

rendiff runs the harness in a process group of its own and, on a timeout or an
interruption, kills that whole group. A renderer the harness starts (POV-Ray)
therefore stays in the harness's group, and is also started with Linux's
``PR_SET_PDEATHSIG``, so it is killed even when the harness dies by a signal
nobody can catch (SIGKILL). Without both, an interrupted ``rendiff check`` left
POV-Ray running and writing into a run folder that no longer existed.
"""

from __future__ import annotations

import ctypes
import signal
import sys
from collections.abc import Callable

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
