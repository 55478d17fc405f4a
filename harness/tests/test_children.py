"""Renderers the harness starts die with it, and stay in its process group."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any, cast

import pytest

from fixtures import process_gone
from rendiff_harness.contract.camera import Camera
from rendiff_harness.renderers.children import die_with_parent, run_in_group
from rendiff_harness.renderers.povray import backend as povray

HARNESS = Path(__file__).resolve().parents[1]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_a_child_dies_when_the_harness_is_killed() -> None:
    script = (
        "import subprocess\n"
        "from rendiff_harness.renderers.children import die_with_parent\n"
        "p = subprocess.Popen(['sleep', '600'], preexec_fn=die_with_parent)\n"
        "print(p.pid, flush=True)\n"
        "p.wait()\n"
    )
    env = dict(os.environ, PYTHONPATH=str(HARNESS))
    harness = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True, env=env)
    assert harness.stdout is not None
    child = int(harness.stdout.readline())
    harness.kill()  # SIGKILL: no handler runs
    harness.wait()
    assert process_gone(child, 5.0), f"process {child} outlived the harness that started it"


def test_povray_runs_in_the_harness_group_and_dies_with_it(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    seen: dict[str, Any] = {}

    class Stop(Exception):
        pass

    def fake_popen(cmd: list[str], **kw: Any) -> None:
        seen.update(kw)
        raise Stop

    monkeypatch.setattr(subprocess, "Popen", fake_popen)  # the module povray calls through
    cam = cast(Camera, SimpleNamespace(width=4, height=4))  # _start reads only the size
    with pytest.raises(Stop):
        povray._start("povray", tmp_path, cam, "t", "// sdl", time.monotonic() + 60, 60.0)
    # A new session or group would put POV-Ray out of reach of rendiff's group kill.
    assert not seen.get("start_new_session")
    assert seen.get("process_group") is None
    assert seen.get("preexec_fn") is die_with_parent


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGPIPE, signal.SIGSEGV], ids=lambda s: s.name)
def test_a_renderer_killed_by_a_signal_is_reported_as_that_signal_with_its_own_stderr(
    tmp_path: Path, sig: signal.Signals
) -> None:
    # SIGKILL is what the out-of-memory killer sends; the supervisor once tried to reset its
    # handler (which Python refuses), died with a traceback and exited 1 instead. SIGPIPE is
    # one Python ignores, so the supervisor must restore its default before passing it on.
    ran = run_in_group(
        ["/bin/sh", "-c", f"echo 'renderer: out of memory soon' >&2; kill -{sig.name[3:]} $$; echo alive >&2"],
        cwd=tmp_path,
        env=os.environ,
        timeout_s=60,
    )
    err = ran.stderr.kept().decode()
    assert not ran.timed_out
    assert ran.returncode == -int(sig), (ran.returncode, err)
    assert err == "renderer: out of memory soon\n", err
