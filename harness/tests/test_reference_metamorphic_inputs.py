"""`reference` and `metamorphic` refuse bad inputs and outputs before any work, in one line (exit 2).

The render is replaced by a stand-in that fails the test if reached: a refused request must be
refused before it, not by the EXR writer afterwards.
"""

from __future__ import annotations

import json
import os
import re
import socket
import stat
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

import backend_cases as cases
from fixtures import write_scene
from rendiff_harness import __main__ as cli
from rendiff_harness.contract import atomic, references
from rendiff_harness.judge import metamorphic
from rendiff_harness.renderers import registry
from rendiff_harness.renderers.mitsuba import backend as mb
from rendiff_harness.renderers.mitsuba import reference as mitsuba_reference

HARNESS = Path(__file__).resolve().parents[1]
REPO = HARNESS.parent
TRI = [[[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]]]


def _one_line(err: str) -> str:
    assert "Traceback" not in err and err.strip() and "\n" not in err.strip(), err
    return err.strip()


@pytest.fixture()
def no_render(monkeypatch: pytest.MonkeyPatch) -> None:
    def render(*_a: Any, **_k: Any) -> Any:
        raise AssertionError("rendered: the request should have been refused before the render")

    monkeypatch.setattr(mb, "render_radiance", render)


@pytest.fixture()
def scene(tmp_path: Path) -> Path:
    return cases.cornell(tmp_path / "scene", width=4, height=4)


def _reference(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    rc = cli.main(["reference", *args])
    return rc, capsys.readouterr().err


# --------------------------------------------------------------------------- reference


@pytest.mark.usefixtures("no_render")
def test_reference_out_whose_provenance_is_itself_is_refused(
    scene: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "ref.json"
    out.write_text("keep")
    rc, err = _reference(capsys, "--scene", str(scene), "--spp", "2", "--out", str(out))
    assert rc == 2 and _one_line(err).startswith(f"rendiff_harness reference: --out {out}: must be a file name ending")
    assert out.read_text() == "keep"
    assert references.check_request(scene, tmp_path / "ref.EXR", 2, 0) is None  # the suffix in any case


@pytest.mark.usefixtures("no_render")
@pytest.mark.parametrize(
    ("args", "option"),
    [
        (["--seed", "2147483648"], "--seed"),
        (["--seed", "-1"], "--seed"),
        (["--spp", "65537"], "--spp"),
        (["--spp", "100000000"], "--spp"),
        (["--spp", "1"], "--spp"),
    ],
)
def test_reference_spp_and_seed_are_bounded_before_rendering(
    scene: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], option: str
) -> None:
    out = tmp_path / "ref.exr"
    rc, err = _reference(capsys, "--scene", str(scene), "--spp", "2", *args, "--out", str(out))
    assert rc == 2 and _one_line(err).startswith(f"rendiff_harness reference: {option} must be between")
    assert not out.exists() and not references.provenance_path(out).exists()


def test_reference_limits_are_the_largest_accepted(scene: Path, tmp_path: Path) -> None:
    out = tmp_path / "ref.exr"
    assert references.check_request(scene, out, references.MAX_SPP, references.MAX_SEED) is None
    assert references.MAX_SEED == 2**31 - 1


def test_reference_max_spp_mirrors_rendiff() -> None:
    src = REPO / "crates/rendiff-core/src/scene/mod.rs"
    if not src.is_file():
        pytest.skip(f"{src} not in this checkout")
    m = re.search(r"pub const MAX_SPP: u32 = 1 << (\d+);", src.read_text())
    assert m is not None, "MAX_SPP's definition changed: update references.MAX_SPP and this test"
    assert references.MAX_SPP == 1 << int(m.group(1))


@pytest.mark.usefixtures("no_render")
@pytest.mark.parametrize("kind", ["fifo", "folder", "socket"])
@pytest.mark.parametrize("which", ["exr", "provenance"])
def test_reference_refuses_special_outputs(
    scene: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], kind: str, which: str
) -> None:
    out = tmp_path / "ref.exr"
    target = out if which == "exr" else references.provenance_path(out)
    made = _special(target, kind)
    try:
        rc, err = _reference(capsys, "--scene", str(scene), "--spp", "2", "--out", str(out))
        assert rc == 2 and f"{target}: is a" in _one_line(err) and "--out" in err
        assert _kind(target) == kind
    finally:
        if made is not None:
            made.close()


@pytest.mark.usefixtures("no_render")
def test_reference_scene_that_is_a_file_is_one_line(
    scene: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for bad in (scene / "scene.json", tmp_path / "missing"):
        rc, err = _reference(capsys, "--scene", str(bad), "--spp", "2", "--out", str(tmp_path / "ref.exr"))
        assert rc == 2 and _one_line(err).startswith(f"rendiff_harness reference: --scene {bad}: ")
    assert not (tmp_path / "ref.exr").exists()


def test_generate_checks_the_request_too(scene: Path, tmp_path: Path, no_render: None) -> None:
    with pytest.raises(references.ReferenceError, match="--seed"):
        mitsuba_reference.generate(scene, tmp_path / "ref.exr", 2, 2**31)


@pytest.mark.skipif(mb.unavailable_reason() is not None, reason=f"{mb.unavailable_reason()}")
def test_reference_at_the_seed_limit_renders(scene: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "ref.exr"
    rc, err = _reference(capsys, "--scene", str(scene), "--spp", "2", "--seed", str(2**31 - 1), "--out", str(out))
    assert rc == 0, err
    assert json.loads(references.provenance_path(out).read_text())["seed"] == 2**31 - 1


# --------------------------------------------------------------------------- atomic outputs


def _special(path: Path, kind: str) -> socket.socket | None:
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "folder":
        path.mkdir()
    else:
        s = socket.socket(socket.AF_UNIX)
        cwd = os.getcwd()
        os.chdir(path.parent)  # a short name: a socket's path is limited to about 100 bytes
        try:
            s.bind(path.name)
        finally:
            os.chdir(cwd)
        return s
    return None


def _kind(path: Path) -> str:
    mode = os.lstat(path).st_mode
    return (
        "fifo" if stat.S_ISFIFO(mode) else "folder" if stat.S_ISDIR(mode) else "socket" if stat.S_ISSOCK(mode) else "?"
    )


@pytest.mark.parametrize("kind", ["fifo", "folder", "socket"])
def test_atomic_writes_never_replace_special_files(tmp_path: Path, kind: str) -> None:
    target = tmp_path / "out"
    made = _special(target, kind)
    try:
        with pytest.raises(atomic.OutputError) as info:
            atomic.write_text_atomically(target, "x")
        assert info.value.strerror is not None and info.value.strerror.startswith("is a")
        with pytest.raises(atomic.OutputError), atomic.renamed_into_place(tmp_path / ".tmp", target) as tmp:
            tmp.write_text("x")
        assert _kind(target) == kind and sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    finally:
        if made is not None:
            made.close()


def test_atomic_writes_replace_a_symlink_itself(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "fifo")
    (tmp_path / "link").symlink_to(tmp_path / "fifo")
    assert atomic.special_entry(tmp_path / "link") is None
    atomic.write_text_atomically(tmp_path / "link", "x")
    assert (tmp_path / "link").read_text() == "x" and _kind(tmp_path / "fifo") == "fifo"


# --------------------------------------------------------------------------- metamorphic


def _run(tmp_path: Path) -> tuple[Path, Path]:
    """A finished run with one scene and no renders, and an empty spec."""
    run = tmp_path / "run"
    write_scene(run / "scenes/base/resolved", TRI, [0], name="base")
    (run / "manifest.json").write_text(
        json.dumps(
            {
                "format": "rendiff-manifest/1",
                "scenes": [{"scene": "base", "resolved": "scenes/base/resolved", "renders": []}],
            }
        )
    )
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({"format": metamorphic.SPEC_FORMAT, "cases": []}))
    return run, spec


def _metamorphic(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    rc = cli.main(["metamorphic", *args])
    return rc, capsys.readouterr().err


@pytest.mark.parametrize("kind", ["file", "folder", "fifo", "dangling-link"])
def test_metamorphic_refuses_an_incomplete_run(tmp_path: Path, capsys: pytest.CaptureFixture[str], kind: str) -> None:
    run, spec = _run(tmp_path)
    assert _metamorphic(capsys, "--run", str(run), "--spec", str(spec))[0] == 0  # complete: accepted
    (run / "metamorphic.json").unlink()
    marker = run / "INCOMPLETE"
    if kind == "file":
        marker.write_text("rendiff check started\x1b[2J\n")
    elif kind == "folder":
        marker.mkdir()
    elif kind == "fifo":
        os.mkfifo(marker)
    else:
        marker.symlink_to(tmp_path / "nowhere")
    rc, err = _metamorphic(capsys, "--run", str(run), "--spec", str(spec))
    line = _one_line(err)
    assert rc == 2 and line.startswith(f"rendiff_harness metamorphic: --run {run}: incomplete run (")
    assert "run rendiff check again" in line and "\x1b" not in line
    if kind == "file":
        assert "rendiff check started\\u{1b}[2J)" in line
    else:
        assert "marker is not a regular file" in line
    assert not (run / "metamorphic.json").exists()
    with pytest.raises(metamorphic.RunError):
        metamorphic.run_metamorphic(run, spec, None, tmp_path / "m.json", registry.spec)
    assert not (tmp_path / "m.json").exists()


def _case(**over: Any) -> dict[str, Any]:
    return {"relation": "reorder", "base": "base", "variant": "base", "prim_map": [0], "object_map": [0], **over}


@pytest.mark.parametrize(
    ("text", "says"),
    [
        (json.dumps({"format": metamorphic.SPEC_FORMAT, "cases": [_case(prim_map=[2**70, 0])]}), "'prim_map'"),
        (json.dumps({"format": metamorphic.SPEC_FORMAT, "cases": [_case(object_map=[2**32])]}), "'object_map'"),
        (json.dumps({"format": metamorphic.SPEC_FORMAT, "cases": [_case(depth_scale=2**1100)]}), "'depth_scale'"),
        (json.dumps({"format": metamorphic.SPEC_FORMAT, "cases": [_case(depth_scale=2**60 + 1)]}), "power of two"),
        ('{"format": "rendiff-metamorphic-spec/1", "cases": ' + "[" * 100_000 + "]" * 100_000 + "}", "nested"),
        ('{"format": "rendiff-metamorphic-spec/1", "cases": [' + "9" * 5000 + "]}", "digits"),
        (b"\xff\xfe", "unreadable spec"),
    ],
    ids=["prim_map-2**70", "object_map-2**32", "depth_scale-huge", "depth_scale-inexact", "deep", "digits", "utf8"],
)
def test_metamorphic_bad_spec_content_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str | bytes, says: str
) -> None:
    run, spec = _run(tmp_path)
    if isinstance(text, bytes):
        spec.write_bytes(text)
    else:
        spec.write_text(text)
    rc, err = _metamorphic(capsys, "--run", str(run), "--spec", str(spec))
    line = _one_line(err)
    assert rc == 2 and line.startswith(f"rendiff_harness metamorphic: {spec}: ") and says in line
    assert not (run / "metamorphic.json").exists()


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    """The harness in a child process, with a timeout: a FIFO read by mistake would block forever."""
    env = {**os.environ, "PYTHONPATH": str(HARNESS)}
    return subprocess.run(
        [sys.executable, "-m", "rendiff_harness", *args], capture_output=True, text=True, timeout=60, env=env
    )


def test_metamorphic_spec_that_is_a_fifo_is_refused_without_blocking(tmp_path: Path) -> None:
    run, _ = _run(tmp_path)
    fifo = tmp_path / "spec.fifo"
    os.mkfifo(fifo)
    r = _cli("metamorphic", "--run", str(run), "--spec", str(fifo))
    assert r.returncode == 2 and _one_line(r.stderr) == (
        f"rendiff_harness metamorphic: {fifo}: unreadable spec: is not a regular file"
    )


@pytest.mark.parametrize("kind", ["fifo", "folder", "socket"])
def test_metamorphic_refuses_special_outputs(tmp_path: Path, capsys: pytest.CaptureFixture[str], kind: str) -> None:
    run, spec = _run(tmp_path)
    out = tmp_path / "out.json"
    made = _special(out, kind)
    try:
        rc, err = _metamorphic(capsys, "--run", str(run), "--spec", str(spec), "--out", str(out))
        assert rc == 2 and _one_line(err).startswith(f"rendiff_harness metamorphic: --out {out}: is a")
        assert _kind(out) == kind
    finally:
        if made is not None:
            made.close()


def test_metamorphic_out_in_a_missing_folder_is_refused_first(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run, spec = _run(tmp_path)
    spec.write_text("not json")  # the output is checked before the spec is read
    out = tmp_path / "missing" / "m.json"
    rc, err = _metamorphic(capsys, "--run", str(run), "--spec", str(spec), "--out", str(out))
    assert (
        rc == 2
        and _one_line(err) == f"rendiff_harness metamorphic: --out {out}: output folder {out.parent} does not exist"
    )
