"""`python -m rendiff_harness serve`: one long-lived process that answers many `render` requests.

Why: a fresh harness process per (scene, backend) pays Python's start-up and the backend's
imports (numpy, OpenImageIO, pyrender's OpenGL context, Mitsuba) every time: 0.3-1 s per
render, most of a small scene's cost. `rendiff check` keeps one worker per backend and job
slot instead and sends it every scene.

Protocol (`rendiff check`'s `check/worker.rs` is the other side), one JSON object per line:

* request on stdin: ``{"argv": ["render", "--backend", "povray", "--scene", ...]}``, the same
  arguments as a one-shot ``python -m rendiff_harness render ...``;
* reply on stdout: ``{"code": int, "stdout": str, "stderr": str}``, what the one-shot process
  would have exited with and printed.

So a render through a worker records exactly what the one-shot command records, and the
reproduction command in the manifest stays the one-shot one. Only `render` is served.

Native code that writes to file descriptor 1 (a C library's diagnostics) must not corrupt the
replies: the protocol keeps a private duplicate of the original stdout, and descriptor 1 is
pointed at stderr for everything else. A crash or a hang of a backend takes the worker with
it (the caller kills its process group on timeout and starts a new worker): the same fault
isolation as one process per render, paid only when something goes wrong.
"""

from __future__ import annotations

import contextlib
import gc
import io
import json
import os
import sys
import traceback
from collections.abc import Callable, Sequence
from typing import IO

SERVED = ("render",)
"""The commands a worker answers; anything else is refused with exit code 2."""


def answer(line: str, run: Callable[[Sequence[str]], int]) -> dict[str, object]:
    """One request line -> its reply: `run(argv)`'s exit code and what it printed."""
    out, err = io.StringIO(), io.StringIO()
    try:
        request = json.loads(line)
        argv = request["argv"] if isinstance(request, dict) else None
        if not isinstance(argv, list) or not all(isinstance(a, str) for a in argv):
            raise ValueError("expected {'argv': [str, ...]}")
    except (ValueError, KeyError) as exc:
        return {"code": 2, "stdout": "", "stderr": f"rendiff_harness serve: bad request: {exc}\n"}
    if not argv or argv[0] not in SERVED:
        return {"code": 2, "stdout": "", "stderr": f"rendiff_harness serve: only {', '.join(SERVED)} is served\n"}
    code: int
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = int(run(argv) or 0)
        except SystemExit as exc:  # argparse's usage errors
            code = exc.code if isinstance(exc.code, int) else 2
        except Exception:  # a bug in rendiff: the traceback a one-shot process would print
            traceback.print_exc()
            code = 1
    return {"code": code, "stdout": out.getvalue(), "stderr": err.getvalue()}


def serve(run: Callable[[Sequence[str]], int], requests: IO[str] | None = None) -> int:
    """Answer requests until stdin closes; returns the process's exit code (0)."""
    replies = os.fdopen(os.dup(sys.stdout.fileno()), "w", encoding="utf-8")
    sys.stdout.flush()
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())  # stray native writes go to stderr
    source = sys.stdin if requests is None else requests
    with replies:
        for line in source:
            if not line.strip():
                continue
            replies.write(json.dumps(answer(line, run)) + "\n")
            replies.flush()
            settle_heap()
    return 0


def settle_heap() -> None:
    """Collect the request's garbage, then freeze what survives out of later collections.

    Why: pyrender's `OffscreenRenderer.delete` runs a full `gc.collect()` after every pass,
    and in a process holding numpy, trimesh and pyrender that scans some 125,000 objects:
    50 ms of CPU per pass, several passes per scene. Objects alive between requests are the
    worker's own (modules, imports, caches), so after this request's garbage is collected
    they are frozen (`gc.freeze`), and the next request's collections scan only what it
    creates (2-3 ms). What a render computes does not change; cyclic garbage of a request is
    still collected, here if not before.
    """
    gc.collect()
    gc.freeze()
