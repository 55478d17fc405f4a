"""User files from a probe: the references folder (`compare --references DIR`), expectations files
and renderers files, read as regular files within a limit, and bad content as one line, never a
traceback, a hang or a run out of memory.

The cases that hung or ran out of memory before their fix run in a child process under a
timeout and an address-space limit (`_isolated`), so that a regression fails the test instead of
hanging or exhausting the machine that runs the suite.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import backend_cases as cases
from rendiff_harness import __main__ as cli
from rendiff_harness import compare
from rendiff_harness.contract import exrbuf, references, resolved, vocab
from rendiff_harness.contract.userfile import UserFileError
from rendiff_harness.judge import expectations
from rendiff_harness.renderers import command as command_renderers
from rendiff_harness.renderers import registry
from rendiff_harness.renderers.mitsuba import backend as mb
from rendiff_harness.renderers.mitsuba import reference as mitsuba_reference

HARNESS = Path(__file__).resolve().parents[1]
REPO = HARNESS.parent
COMMITTED_EXR = REPO / "tests" / "references" / "cornell_gi.exr"
DEEP_JSON = "[" * 30_000 + "]" * 30_000  # within MAX_PROVENANCE_BYTES, far past the recursion limit
DEEP_TOML_ARRAY = "[" * 5000 + "]" * 5000
HUGE_INT = "1" * 5000  # past Python's 4300-digit limit for int <-> str
HUGE_HEX = "0x" + "f" * 5000  # parsed (powers of two are exempt from that limit), then unprintable
ADDRESS_SPACE = 3 << 30  # enough for numpy and OpenImageIO, not for reading /dev/zero whole


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))


def _isolated(*argv: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    """`python ARGV...` in a child with the harness on its path, a timeout and a memory limit;
    a child still running at the timeout fails the test (it hung)."""
    env = {k: v for k, v in os.environ.items() if k != command_renderers.ENV_VAR}
    env["PYTHONPATH"] = f"{HARNESS}{os.pathsep}{HARNESS / 'tests'}"
    try:
        return subprocess.run(
            [sys.executable, *argv],
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout,
            preexec_fn=_limit_memory,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"hung: still running after {timeout} s")


def _refs(tmp_path: Path) -> tuple[Path, Path]:
    """A resolved Cornell scene and a references folder holding a copy of a committed reference EXR."""
    scene_dir = cases.cornell(tmp_path / "scene", width=16, height=16)
    refs = tmp_path / "refs"
    refs.mkdir()
    shutil.copyfile(COMMITTED_EXR, refs / "box.exr")
    shutil.copyfile(COMMITTED_EXR.with_suffix(".json"), refs / "box.json")
    return scene_dir, refs


LOAD = """
import sys
from rendiff_harness.contract import references
from rendiff_harness.contract import resolved
print(references.regenerate_command(sys.argv[1], sys.argv[2]))
try:
    references.load(sys.argv[2], resolved.load(sys.argv[1]))
except references.ReferenceError as exc:
    print(exc)
else:
    print("loaded")
"""


def _special(path: Path, kind: str) -> None:
    path.unlink(missing_ok=True)
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "dev-zero":
        path.symlink_to("/dev/zero")
    else:
        path.mkdir()


# --------------------------------------------------------------------------- the references folder


@pytest.mark.parametrize("kind", ["fifo", "dev-zero", "folder"])
def test_provenance_that_is_not_a_regular_file_is_one_error(tmp_path: Path, kind: str) -> None:
    """<scene>.json a FIFO hung compare (regenerate_command read it first), a link to /dev/zero read
    until memory ran out: now regenerate_command keeps its defaults and load refuses the file."""
    scene_dir, refs = _refs(tmp_path)
    _special(refs / "box.json", kind)
    proc = _isolated("-c", LOAD, str(scene_dir), str(refs / "box.exr"))
    assert proc.returncode == 0, proc.stderr[-2000:]
    command, message = proc.stdout.splitlines()
    assert "--spp 4096 --seed 0" in command
    assert message.startswith(
        f"{refs / 'box.json'}: cached reference corrupt (the provenance file is not a regular file)"
    )
    assert "regenerate with python -m rendiff_harness reference" in message


@pytest.mark.parametrize("kind", ["fifo", "dev-zero", "folder"])
def test_reference_exr_that_is_not_a_regular_file_is_one_error(tmp_path: Path, kind: str) -> None:
    """The EXR itself is hashed and read only when it is a regular file (it was called missing)."""
    scene_dir, refs = _refs(tmp_path)
    _special(refs / "box.exr", kind)
    proc = _isolated("-c", LOAD, str(scene_dir), str(refs / "box.exr"))
    assert proc.returncode == 0, proc.stderr[-2000:]
    message = proc.stdout.splitlines()[1]
    assert message.startswith(f"{refs / 'box.exr'}: cached reference corrupt (the EXR is not a regular file)")


def test_oversized_provenance_is_not_read(tmp_path: Path) -> None:
    scene_dir, refs = _refs(tmp_path)
    doc = json.loads((refs / "box.json").read_text())
    doc["spp_requested"] = 7
    (refs / "box.json").write_text(json.dumps(doc) + " " * (1 << 20))
    assert "--spp 4096 --seed 0" in references.regenerate_command(scene_dir, refs / "box.exr")
    with pytest.raises(
        references.ReferenceError, match=f"the provenance file is larger than {references.MAX_PROVENANCE_BYTES} bytes"
    ):
        references.load(refs / "box.exr", resolved.load(scene_dir))


def test_oversized_reference_exr_is_not_read(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    scene_dir, refs = _refs(tmp_path)
    size = (refs / "box.exr").stat().st_size
    monkeypatch.setattr(
        references, "MAX_EXR_BYTES", size - 1, raising=False
    )  # a file of 64 MiB is not worth writing here
    with pytest.raises(references.ReferenceError, match=f"corrupt \\(the EXR is larger than {size - 1} bytes\\)"):
        references.load(refs / "box.exr", resolved.load(scene_dir))
    with pytest.raises(UserFileError, match=f"is larger than {size - 1} bytes"):
        references.file_sha256(refs / "box.exr")
    assert references.file_sha256(refs / "box.exr", limit=size) == references.file_sha256(
        refs / "box.exr", limit=size + 1
    )


@pytest.mark.skipif(mb.unavailable_reason() is not None, reason=f"{mb.unavailable_reason()}")
def test_generate_refuses_a_reference_load_would_refuse(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    scene_dir = cases.cornell(tmp_path / "scene", width=8, height=8)
    monkeypatch.setattr(references, "MAX_EXR_BYTES", 100, raising=False)
    with pytest.raises(references.ReferenceError, match="the written reference is larger than 100 bytes"):
        mitsuba_reference.generate(scene_dir, tmp_path / "box.exr", spp=2, seed=0)


def test_deeply_nested_provenance_is_one_error(tmp_path: Path) -> None:
    """`[`*100000 in <scene>.json: a RecursionError traceback stopped the whole comparison."""
    scene_dir, refs = _refs(tmp_path)
    (refs / "box.json").write_text(DEEP_JSON)
    assert "--spp 4096 --seed 0" in references.regenerate_command(scene_dir, refs / "box.exr")
    with pytest.raises(references.ReferenceError) as info:
        references.load(refs / "box.exr", resolved.load(scene_dir))
    msg = str(info.value)
    assert msg.startswith(f"{refs / 'box.json'}: cached reference corrupt (provenance unreadable: nested too deeply)")
    assert "\n" not in msg


def test_provenance_format_is_shown_short(tmp_path: Path) -> None:
    scene_dir, refs = _refs(tmp_path)
    (refs / "box.json").write_text(json.dumps({"format": "x\n" * 10_000}))
    with pytest.raises(references.ReferenceError, match="corrupt .*format") as info:
        references.load(refs / "box.exr", resolved.load(scene_dir))
    assert "\n" not in str(info.value) and len(str(info.value)) < 1000


def _zeros_run(tmp_path: Path) -> tuple[Path, Path]:
    """A run folder with one global-illumination scene `box` whose reference render is all zeros."""
    run = tmp_path / "run"
    sd = cases.cornell(run / "scenes/box/resolved", width=16, height=16)
    scene = resolved.load(sd)
    shape = (scene.camera.height, scene.camera.width)
    exr = run / "scenes/box/raster.exr"
    z = np.full(shape, np.inf, dtype=np.float32)
    prim = np.zeros(shape, dtype=np.uint32)
    rgb = np.zeros((*shape, 3), dtype=np.float32)
    exrbuf.write_buffers(exr, Z=z, prim=prim, obj=prim, RGB=rgb, var=rgb, attrs={"spp": "64", "integrator": "path"})
    render: dict[str, Any] = {
        "backend": "raster",
        "status": "ok",
        "exr": "scenes/box/raster.exr",
        "time_s": 0.1,
        "version": "raster 1",
        "command": "render raster",
        "buffers": ["Z", "id", "RGB"],
        "info": {},
    }
    manifest = {
        "format": "rendiff-manifest/1",
        "reference": "raster",
        "created": "x",
        "rendiff_version": "0",
        "scenes": [
            {"scene": "box", "resolved": "scenes/box/resolved", "requires": sorted(scene.requires), "renders": [render]}
        ],
    }
    (run / "manifest.json").write_text(json.dumps(manifest))
    refs = tmp_path / "refs"
    refs.mkdir()
    shutil.copyfile(COMMITTED_EXR, refs / "box.exr")
    return run, refs


def test_bad_reference_is_that_scenes_error_entry(tmp_path: Path) -> None:
    """A deeply nested <scene>.json is the cached reference's error entry; the comparison goes on."""
    run, refs = _zeros_run(tmp_path)
    (refs / "box.json").write_text(DEEP_JSON)
    doc = compare.run_compare(run, None, images=False, references_dir=refs)
    entry = {(r["scene"], r["backend"], r["buffer"]): r for r in doc["results"]}[
        ("box", vocab.CACHED_REFERENCE_BACKEND, "RGB")
    ]
    assert entry["status"] == "error"
    assert entry["reason"].startswith(f"{refs / 'box.json'}: cached reference corrupt (provenance unreadable")
    assert (run / "results.json").is_file()


# --------------------------------------------------------------------------- expectations files


def _expect(**extra: str) -> str:
    keys = {"scene": '"a"', "backend": '"x"', "buffer": '"id"', "status": '"expected_fail"', "reason": '"r"'}
    keys.update(extra)
    return "[[expect]]\n" + "".join(f"{k} = {v}\n" for k, v in keys.items())


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        (f"a = {DEEP_TOML_ARRAY}\n", "invalid TOML: nested too deeply"),
        (_expect(interior_mismatches=f"[0, {DEEP_TOML_ARRAY}]"), "invalid TOML: nested too deeply"),
        (f"a = {HUGE_INT}\n", "invalid TOML: Exceeds the limit (4300 digits)"),
        (_expect(interior_mismatches=f"[0, {HUGE_HEX}]"), "hi must be at most 9223372036854775807"),
        (
            _expect(interior_mismatches=f"[{HUGE_HEX}, 0]"),
            "must satisfy 0 <= lo <= hi, got [<int too large to show>, 0]",
        ),
        (
            _expect(interior_mismatches=f"[0, {2**63}]"),
            "hi must be at most 9223372036854775807, got 9223372036854775808",
        ),
        (_expect(scene='"a\\nb"', buffer='"q"'), "entry 1 ('a\\nb'/x/q): key 'buffer'"),
        (_expect(buffer='"' + "q\\n" * 10_000 + '"'), "key 'buffer' must be one of"),
        (_expect(reason="[" + "1, " * 10_000 + "]"), "key 'reason' must be a non-empty string, got [1, 1, 1, 1, ...]"),
    ],
    ids=["deep", "deep-bound", "long-int", "huge-hi", "huge-lo", "hi-2**63", "newline-name", "long-value", "long-list"],
)
def test_bad_expectations_are_one_short_line(tmp_path: Path, text: str, needle: str) -> None:
    path = tmp_path / "e.toml"
    path.write_text(text)
    with pytest.raises(expectations.ExpectationsError) as info:
        expectations.load(path)
    msg = str(info.value)
    assert msg.startswith(f"{path}: ") and needle in msg, msg
    assert "\n" not in msg and len(msg) < 1000, msg


def test_the_largest_bound_is_accepted(tmp_path: Path) -> None:
    path = tmp_path / "e.toml"
    path.write_text(_expect(interior_mismatches=f"[0, {2**63 - 1}]"))
    assert expectations.load(path).entries[0].bound("interior_mismatches") == (0, 2**63 - 1)


# --------------------------------------------------------------------------- `expectations FILE`


def test_expectations_command_is_silent_for_a_valid_file(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["expectations", str(REPO / "tests" / "expectations.toml")]) == 0
    out, err = capsys.readouterr()
    assert out == "" and err == ""


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("[[expect]\n", "invalid TOML"),
        (_expect(buffer='"q"'), "[[expect]] entry 1 (a/x/q): key 'buffer'"),
        (_expect(edge_mismatches="[0, 5]"), "allowed classes"),
        (f"a = {DEEP_TOML_ARRAY}\n", "invalid TOML: nested too deeply"),
    ],
    ids=["toml", "buffer", "allowed-class", "deep"],
)
def test_expectations_command_refuses_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, needle: str
) -> None:
    path = tmp_path / "e.toml"
    path.write_text(text)
    assert cli.main(["expectations", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.startswith(f"rendiff_harness: {path}: ") and needle in err and err.count("\n") == 1, err


def test_expectations_command_refuses_special_and_missing_files(tmp_path: Path) -> None:
    """Through `python -m`, as `rendiff check` will call it: a FIFO is refused at once."""
    fifo = tmp_path / "e.toml"
    os.mkfifo(fifo)
    for path, needle in (
        (fifo, "the expectations file is not a regular file"),
        (Path("/dev/zero"), "the expectations file is not a regular file"),
        (tmp_path / "none.toml", "expectations file not found"),
    ):
        proc = _isolated(
            "-m",
            "rendiff_harness",
            "expectations",
            str(path),
            timeout=30,
        )
        assert proc.returncode == 2 and proc.stdout == "", proc.stderr
        assert proc.stderr == f"rendiff_harness: {path}: {needle}\n"


# --------------------------------------------------------------------------- renderers files


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        (f"a = {DEEP_TOML_ARRAY}\n", "not valid TOML: nested too deeply"),
        ("a = " + "{b = " * 2000 + "1" + "}" * 2000 + "\n", "not valid TOML: nested too deeply"),
        (f"a = {HUGE_INT}\n", "not valid TOML: Exceeds the limit (4300 digits)"),
    ],
    ids=["deep-array", "deep-table", "long-int"],
)
def test_bad_renderers_files_are_one_line(tmp_path: Path, text: str, needle: str) -> None:
    path = tmp_path / "renderers.toml"
    path.write_text(text)
    with pytest.raises(command_renderers.RenderersError) as info:
        command_renderers.load(path, registry.RESERVED_NAMES)
    msg = str(info.value)
    assert msg.startswith(f"{path}: ") and needle in msg and "\n" not in msg, msg


def test_renderer_number_too_large_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / "renderers.toml"
    path.write_text(
        '[[renderer]]\nname = "mine"\ncommand = ["mine", "{scene}", "{out}"]\nfeatures = []\nbuffers = ["Z"]\n'
        f"timeout_s = {HUGE_HEX}\n[renderer.precision]\ndepth_relative = 1e-6\n"
    )
    with pytest.raises(
        command_renderers.RenderersError, match="timeout_s must be a finite number >= 0, got an integer of 20000 bits"
    ):
        command_renderers.load(path, registry.RESERVED_NAMES)
