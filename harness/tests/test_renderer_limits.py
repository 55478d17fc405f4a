"""Limits on what a renderer declared by a command can make the harness keep or accept.

What it prints is drained and kept bounded (children.OUTPUT_KEEP_BYTES at each end), so is
its version command's output (command_renderers.VERSION_MAX_BYTES); its scratch space lies
beside the output (the run folder rendiff check removes when interrupted), never under /tmp;
and its name has a length limit (command_renderers.MAX_NAME_CHARS) checked at load time.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fixtures import cli, write_scene
from rendiff_harness.contract import exrbuf, vocab
from rendiff_harness.renderers import command as command_renderers
from rendiff_harness.renderers import registry
from rendiff_harness.renderers.children import OUTPUT_KEEP_BYTES, Capture, run_in_group
from rendiff_harness.renderers.command import ENV_VAR, MAX_NAME_CHARS, VERSION_MAX_BYTES, RenderersError

HARNESS = Path(__file__).resolve().parents[1]
MiB = 1 << 20
W = H = 8


def script(tmp_path: Path, name: str, body: str) -> Path:
    path = tmp_path / "bin" / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(body)
    return path


def entry(name: str, command: list[str], extra: str = "") -> str:
    """One [[renderer]] entry writing Z and id (depth, ids)."""
    return (
        f"[[renderer]]\nname = {json.dumps(name)}\ncommand = {json.dumps(command)}\n"
        f'features = ["depth", "ids"]\nbuffers = ["Z", "id"]\n{extra}\n'
        "[renderer.precision]\nedge_px = 0.004\ndepth_relative = 1e-6\n"
    )


def declare(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "renderers.toml"
    path.write_text(text)
    return path


def scene_and_answer(tmp_path: Path) -> tuple[Path, Path]:
    """A one-triangle scene and an EXR of the right size and channels (its content is not judged here)."""
    sdir = write_scene(tmp_path / "scene", [[[-1, -1, 0], [1, -1, 0], [0, 1, 0]]], [0], width=W, height=H)
    z = np.full((H, W), np.inf, dtype=np.float32)
    ids = np.full((H, W), vocab.BACKGROUND_ID, dtype=np.uint32)
    answer = tmp_path / "answer.exr"
    exrbuf.write_buffers(answer, Z=z, prim=ids, obj=ids)
    return sdir, answer


# --------------------------------------------------------------------------- output


def test_a_capture_keeps_the_first_and_last_bytes_and_marks_the_rest() -> None:
    c = Capture(head_limit=4, tail_limit=3)
    for chunk in (b"ab", b"cdefgh", b"ij", b"", b"klmnop"):
        c.add(chunk)
    assert (c.total, c.head, c.tail, c.omitted) == (16, b"abcd", b"nop", 9)
    assert c.kept().startswith(b"abcd\n[rendiff: 9 bytes omitted here; the stream had 16 bytes")
    assert c.kept().endswith(b"]\nnop")
    small = Capture(head_limit=4, tail_limit=3)
    small.add(b"abcdefg")
    assert (small.kept(), small.omitted) == (b"abcdefg", 0)
    version = Capture(head_limit=5, tail_limit=0)
    version.add(b"v1.0\nmore")
    assert (version.head, version.tail, version.omitted) == (b"v1.0\n", b"", 4)


def test_a_flood_of_output_is_drained_and_only_its_ends_are_kept(tmp_path: Path) -> None:
    flood = script(
        tmp_path,
        "flood.py",
        "import os\n"
        "os.write(1, b'first out\\n')\n"
        "for _ in range(48): os.write(1, b'o' * (1 << 20))\n"  # 48 MiB, far beyond a pipe's buffer
        "os.write(1, b'\\nlast out\\n')\n"
        "for _ in range(16): os.write(2, b'e' * (1 << 20))\n"
        "os.write(2, b'\\nlast words\\n')\n",
    )
    tracemalloc.start()
    try:
        ran = run_in_group([sys.executable, str(flood)], cwd=tmp_path, env=os.environ, timeout_s=120)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert not ran.timed_out and ran.returncode == 0  # never blocked on a full pipe
    assert ran.stdout.total == 48 * MiB + 20 and ran.stderr.total == 16 * MiB + 12
    for stream, first, last in ((ran.stdout, b"first out\n", b"last out\n"), (ran.stderr, b"e", b"last words\n")):
        assert len(stream.head) == len(stream.tail) == OUTPUT_KEEP_BYTES
        assert stream.head.startswith(first) and stream.tail.endswith(last)
        assert b"bytes omitted here" in stream.kept() and len(stream.kept()) < 2 * OUTPUT_KEEP_BYTES + 200
    assert peak < 5 * OUTPUT_KEEP_BYTES + 4 * MiB, f"{peak} bytes at the peak for 64 MiB of output"


def test_a_flooding_renderer_keeps_bounded_logs_and_its_error_says_so(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    sdir, _ = scene_and_answer(tmp_path)
    flood = script(
        tmp_path,
        "flood.py",
        "import os, sys\n"
        "for _ in range(24): os.write(1, b'o' * (1 << 20))\n"
        "for _ in range(24): os.write(2, b'e' * (1 << 20))\n"
        "os.write(2, b'\\nboom: out of patience\\n')\n"
        "sys.exit(1)\n",
    )
    monkeypatch.setenv(ENV_VAR, str(declare(tmp_path, entry("flood", [sys.executable, str(flood), "{out}"]))))
    logs: dict[str, int] = {}
    marked: list[str] = []
    rmtree = shutil.rmtree

    def spy(path: Any, *args: Any, **kw: Any) -> None:  # sizes of the logs just before the scratch goes
        for log in Path(path).rglob("*.log"):
            logs[log.name] = log.stat().st_size
            if b"bytes omitted here" in log.read_bytes():
                marked.append(log.name)
        rmtree(path, *args, **kw)

    monkeypatch.setattr(shutil, "rmtree", spy)
    rc, _, err = cli("render", "--backend", "flood", "--scene", str(sdir), "--out", str(tmp_path / "o.exr"))
    assert rc == 2 and "flood: exited with status 1; stderr (" in err, err
    assert f"({24 * MiB + 23} bytes, only its first and last {OUTPUT_KEEP_BYTES} kept)" in err, err
    assert err.rstrip().endswith("boom: out of patience"), err
    assert set(logs) == {"stdout.log", "stderr.log"} and sorted(marked) == ["stderr.log", "stdout.log"]
    assert max(logs.values()) < 2 * OUTPUT_KEEP_BYTES + 200, logs


def test_a_renderers_own_output_sizes_are_in_its_render_info(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    sdir, answer = scene_and_answer(tmp_path)
    chatty = script(
        tmp_path,
        "chatty.py",
        "import shutil, sys\nprint('x' * 99)\nprint('note', file=sys.stderr)\n"
        f"shutil.copyfile({str(answer)!r}, sys.argv[1])\n",
    )
    monkeypatch.setenv(ENV_VAR, str(declare(tmp_path, entry("chatty", [sys.executable, str(chatty), "{out}"]))))
    rc, out, err = cli("render", "--backend", "chatty", "--scene", str(sdir), "--out", str(tmp_path / "o.exr"))
    assert rc == 0, err
    info = json.loads(out.strip().splitlines()[-1])["info"]
    assert (info["stdout_bytes"], info["stderr_bytes"]) == (100, 5)


# --------------------------------------------------------------------------- scratch space


def test_scratch_space_is_beside_the_output_never_in_the_temp_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    sdir, answer = scene_and_answer(tmp_path)
    temp = tmp_path / "tmp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))  # where mkdtemp() without dir= would go
    seen = tmp_path / "seen"
    seen.mkdir()
    spy = script(
        tmp_path,
        "spy.py",
        f"import os, shutil, sys\nopen({str(seen)!r} + '/' + sys.argv[1], 'w').write(os.getcwd())\n"
        f"if sys.argv[1] == 'render': shutil.copyfile({str(answer)!r}, sys.argv[2])\n"
        "else: print('Spy 1.0')\n",
    )
    path = declare(
        tmp_path,
        entry(
            "spy",
            [sys.executable, str(spy), "render", "{out}"],
            f"version = {json.dumps([sys.executable, str(spy), 'version'])}",
        ),
    )
    monkeypatch.setenv(ENV_VAR, str(path))
    out = tmp_path / "run" / "scenes" / "one" / "spy.exr"
    out.parent.mkdir(parents=True)
    rc, line, err = cli("render", "--backend", "spy", "--scene", str(sdir), "--out", str(out))
    assert rc == 0, err
    assert json.loads(line.strip().splitlines()[-1])["version"] == "Spy 1.0"
    render_cwd, version_cwd = Path((seen / "render").read_text()), Path((seen / "version").read_text())
    assert render_cwd.is_relative_to(out.parent), render_cwd  # inside the run folder
    assert version_cwd == path.parent  # the renderers file's folder: nothing made for it
    assert not any(p.is_relative_to(temp) for p in (render_cwd, version_cwd))
    assert list(temp.iterdir()) == [] and sorted(p.name for p in out.parent.iterdir()) == ["spy.exr"]


def test_a_scratch_folder_that_cannot_be_made_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    sdir, _ = scene_and_answer(tmp_path)
    monkeypatch.setenv(ENV_VAR, str(declare(tmp_path, entry("mine", [sys.executable]))))

    def refuse(*args: Any, **kw: Any) -> str:
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(tempfile, "mkdtemp", refuse)
    rc, out, err = cli("render", "--backend", "mine", "--scene", str(sdir), "--out", str(tmp_path / "o.exr"))
    assert (rc, out) == (2, "")
    assert err == f"rendiff_harness: mine: cannot create a scratch folder in {tmp_path}: Permission denied\n"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_a_killed_harness_leaves_its_scratch_in_the_run_folder_not_in_tmp(tmp_path: Path) -> None:
    sdir, _ = scene_and_answer(tmp_path)
    temp = tmp_path / "tmp"
    temp.mkdir()
    started = tmp_path / "started"
    hang = script(
        tmp_path,
        "hang.py",
        "import os, sys, time\n"
        "print('x' * 1000, flush=True)\n"
        f"open({str(started)!r}, 'w').write(os.getcwd())\n"
        "time.sleep(600)\n",
    )
    path = declare(tmp_path, entry("hang", [sys.executable, str(hang), "{out}"]))
    out = tmp_path / "run" / "hang.exr"
    out.parent.mkdir()
    env = dict(os.environ, PYTHONPATH=str(HARNESS), TMPDIR=str(temp), **{ENV_VAR: str(path)})
    argv = ["render", "--backend", "hang", "--scene", str(sdir), "--out", str(out)]
    harness = subprocess.Popen([sys.executable, "-m", "rendiff_harness", *argv], env=env, stderr=subprocess.PIPE)
    try:
        end = time.monotonic() + 60
        while not started.exists() and time.monotonic() < end and harness.poll() is None:
            time.sleep(0.05)
        assert started.exists(), harness.stderr.read() if harness.stderr else ""
    finally:
        harness.kill()  # SIGKILL, as rendiff check's interrupt does: no `finally` of the harness runs
        harness.communicate()
    assert list(temp.iterdir()) == []
    left = Path(started.read_text())
    assert left.is_relative_to(out.parent), left  # the run's staging folder, which rendiff check removes


# --------------------------------------------------------------------------- version


def test_a_huge_version_output_costs_a_bounded_read(tmp_path: Path) -> None:
    ver = script(
        tmp_path,
        "ver.py",
        "import os\nos.write(1, b'\\n  MyRender 2.0  \\n')\nfor _ in range(64): os.write(1, b'v' * (1 << 20))\n",
    )
    long = script(tmp_path, "long.py", "import os\nfor _ in range(8): os.write(1, b'w' * (1 << 20))\n")
    path = declare(
        tmp_path,
        entry("ver", [sys.executable], f"version = {json.dumps([sys.executable, str(ver)])}")
        + entry("long", [sys.executable], f"version = {json.dumps([sys.executable, str(long)])}"),
    )
    ver_spec, long_spec = command_renderers.load(path, registry.RESERVED_NAMES)
    tracemalloc.start()
    try:
        t0 = time.monotonic()
        version = command_renderers.CommandBackend(ver_spec).version()
        elapsed = time.monotonic() - t0
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert version == "MyRender 2.0" and elapsed < command_renderers.VERSION_TIMEOUT_S
    assert peak < 4 * MiB, f"{peak} bytes at the peak for a 64 MiB version output"
    assert command_renderers.CommandBackend(long_spec).version() == "w" * VERSION_MAX_BYTES  # one line, cut


# --------------------------------------------------------------------------- names


def test_a_renderer_name_longer_than_the_limit_is_one_clear_load_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    longest = "r" * MAX_NAME_CHARS
    assert (
        command_renderers.parse(tmp_path / "ok.toml", entry(longest, ["x"]), registry.RESERVED_NAMES)[0].name == longest
    )
    text = entry("fine", ["x"]) + entry("n" * 300, ["x"])
    path = declare(tmp_path, text)
    with pytest.raises(RenderersError) as caught:
        command_renderers.parse(path, text, registry.RESERVED_NAMES)
    msg = str(caught.value)
    assert msg.startswith(f"{path}: [[renderer]] #2: name 'nnnnnnnnnnnnnnnnnnnn...' is 300 characters long")
    assert f"at most {MAX_NAME_CHARS}" in msg and "\n" not in msg and len(msg) < 300
    monkeypatch.setenv(ENV_VAR, str(path))
    rc, out, err = cli("info", "--json")
    assert rc == 2 and out == "" and err == f"rendiff_harness: {msg}\n"
