"""The long-lived worker (`serve`): replies equal what a one-shot process prints, and stray
native writes to file descriptor 1 never corrupt the reply stream."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

from rendiff_harness.renderers import worker

HARNESS = Path(__file__).resolve().parents[1]


def _echo(argv: Sequence[str]) -> int:
    print("out:" + " ".join(argv))
    print("err line", file=sys.stderr)
    return 3


def _serve(script: str, requests: int) -> subprocess.CompletedProcess[str]:
    """Runs `script` (which calls `worker.serve`) in a process of its own, sending it
    `requests` render requests numbered from 0; what it printed."""
    lines = "".join(json.dumps({"argv": ["render", str(i)]}) + "\n" for i in range(requests))
    return subprocess.run(
        [sys.executable, "-c", script],
        input=lines,
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": str(HARNESS)},
        timeout=60,
        check=True,
    )


def test_answer_captures_what_the_command_prints_and_its_code() -> None:
    reply = worker.answer(json.dumps({"argv": ["render", "--x", "a b"]}), _echo)
    assert reply == {"code": 3, "stdout": "out:render --x a b\n", "stderr": "err line\n"}


def test_answer_refuses_bad_requests_and_other_commands() -> None:
    for line in ("not json", json.dumps(["render"]), json.dumps({"argv": [1]}), json.dumps({})):
        reply = worker.answer(line, _echo)
        assert reply["code"] == 2 and "bad request" in str(reply["stderr"]), line
    reply = worker.answer(json.dumps({"argv": ["compare", "--run", "x"]}), _echo)
    assert reply["code"] == 2 and "only render" in str(reply["stderr"])


def test_a_bug_becomes_exit_1_with_its_traceback_and_the_worker_goes_on() -> None:
    def broken(argv: Sequence[str]) -> int:
        raise ZeroDivisionError("boom")

    reply = worker.answer(json.dumps({"argv": ["render"]}), broken)
    assert reply["code"] == 1 and "ZeroDivisionError: boom" in str(reply["stderr"])

    def exits(argv: Sequence[str]) -> int:
        raise SystemExit(2)  # argparse's way out

    assert worker.answer(json.dumps({"argv": ["render"]}), exits)["code"] == 2


def test_serve_process_answers_in_order_and_native_stdout_goes_to_stderr(tmp_path: Path) -> None:
    # A real `serve` process, asked for an unknown backend twice and a bad line once; a
    # write to fd 1 by native code (simulated with os.write) must land in stderr.
    script = (
        "import os, sys\n"
        "from rendiff_harness.renderers import worker\n"
        "def run(argv):\n"
        "    os.write(1, b'native noise\\n')\n"
        "    print('reply for ' + argv[-1])\n"
        "    return 0\n"
        "sys.exit(worker.serve(run))\n"
    )
    proc = _serve(script, 3)
    replies = [json.loads(line) for line in proc.stdout.splitlines()]
    assert [r["stdout"] for r in replies] == [f"reply for {i}\n" for i in range(3)]
    assert proc.stderr.count("native noise") == 3


def test_serve_collects_each_requests_cycles_and_freezes_what_lives_on() -> None:
    # Automatic collection is off, so only `settle_heap` can free the request's cycle:
    # freezing without collecting first would keep it (frozen objects are never collected).
    # What the worker keeps (the `kept` list) ends up frozen, so a later request's
    # `gc.collect()` (pyrender runs one per pass) does not scan it again.
    script = (
        "import gc, json, sys, weakref\n"
        "from rendiff_harness.renderers import worker\n"
        "gc.disable()\n"
        "class Node:\n"
        "    pass\n"
        "refs, kept = [], []\n"
        "def run(argv):\n"
        "    a, b = Node(), Node()\n"
        "    a.other, b.other = b, a\n"
        "    refs.append(weakref.ref(a))\n"
        "    kept.extend(Node() for _ in range(5000))\n"
        "    return 0\n"
        "worker.serve(run)\n"
        "print(json.dumps({'alive': sum(r() is not None for r in refs),\n"
        "                  'frozen': gc.get_freeze_count()}), file=sys.stderr)\n"
    )
    proc = _serve(script, 2)
    state = json.loads(proc.stderr.strip().splitlines()[-1])
    assert state["alive"] == 0, state
    assert state["frozen"] >= 10000, state
