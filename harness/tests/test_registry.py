"""Registry and CLI: lazy imports, capability checks, and the exit-code/JSON contract."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import fixtures
from rendiff_harness import __main__ as cli
from rendiff_harness import renderers
from rendiff_harness.contract import exrbuf, resolved, vocab
from rendiff_harness.renderers import registry

HARNESS = Path(__file__).resolve().parents[1]
needs_povray = pytest.mark.skipif(shutil.which("povray") is None, reason="povray binary not on PATH")


def test_registry_lists_one_folder_per_backend() -> None:
    assert registry.BUILT_IN[0] == "povray"
    assert len(set(registry.BUILT_IN)) == len(registry.BUILT_IN)
    for name in registry.BUILT_IN:
        assert (HARNESS / "rendiff_harness" / "renderers" / name / "backend.py").is_file(), name
    pov = registry.load("povray")
    assert pov.spec is not None and pov.name == "povray"
    assert registry.get("povray").key == "povray"


DECLARED = {
    "povray": ("depth ids emission lambert point_light directional_light shadows shadowless two_sided", "Z id RGB"),
    "pyrender": ("depth ids emission lambert point_light directional_light shadowless two_sided", "Z id RGB"),
    # Never shadowless: Mitsuba always traces shadow rays.
    "mitsuba": (
        "depth ids emission lambert point_light directional_light shadows area_light global_illumination "
        "two_sided one_sided",
        "Z id N RGB",
    ),
    "mitsuba_file": ("depth ids normals", "Z id N"),
    "pyrender_file": ("depth ids normals", "Z id N"),
}
"""What each built-in backend declares in its renderers/<name>/backend.py (features, buffers): the
scenes and buffers it is compared on, so a change to it is a deliberate change here too."""


@pytest.mark.parametrize("name", DECLARED)
def test_each_built_in_backend_declares_its_features_and_buffers(name: str) -> None:
    backend = registry.load(name)
    if backend.spec is None:
        pytest.skip(f"{name} does not load here: {backend.import_error}")
    features, buffers = DECLARED[name]
    assert backend.name == name
    assert backend.features == frozenset(features.split())
    assert backend.buffers == frozenset(buffers.split())


def test_every_registered_module_loads_or_says_why() -> None:
    for backend in registry.all_backends():
        if backend.spec is None:
            assert backend.import_error, backend.key
        else:
            assert backend.buffers <= registry.KNOWN_BUFFERS


def test_missing_module_is_unavailable_not_an_exception(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(registry, "BUILT_IN", ("povray", "nosuch"))
    b = registry.load("nosuch")
    assert b.spec is None and b.name == "nosuch"
    assert "not found" in (b.unavailable_reason() or "")
    assert registry.get("nosuch").key == "nosuch"


def _extra_backends_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, files: dict[str, str]) -> None:
    """Backend folders <name>/backend.py in tmp_path, found as renderers.<name> for this test."""
    for name, text in files.items():
        (tmp_path / name).mkdir()
        (tmp_path / name / "backend.py").write_text(text)
    monkeypatch.setattr(renderers, "__path__", [*renderers.__path__, str(tmp_path)])
    for name in files:
        for mod in (f"rendiff_harness.renderers.{name}", f"rendiff_harness.renderers.{name}.backend"):
            monkeypatch.delitem(sys.modules, mod, raising=False)


def test_import_error_of_a_dependency_becomes_the_reason(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _extra_backends_dir(tmp_path, monkeypatch, {"broken": "import definitely_not_installed_pkg\n"})
    b = registry.load("broken")
    reason = b.unavailable_reason() or ""
    assert b.spec is None and "definitely_not_installed_pkg" in reason and "setup.sh" in reason
    with pytest.raises(registry.BackendUnavailable):
        b.version()


HALF = """
from rendiff_harness.judge.tolerance import exact_depth, Model
from rendiff_harness.renderers.spec import BackendSpec
SPEC = BackendSpec("half", frozenset(), frozenset(), Model("half", 0.0, "", exact_depth))
"""


def test_incomplete_module_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """No SPEC, or a spec the harness cannot run (no render, version or probe), is unavailable."""
    _extra_backends_dir(tmp_path, monkeypatch, {"nospec": "NAME = 'half'\n", "half": HALF})
    for name in ("nospec", "half"):
        b = registry.load(name)
        assert b.spec is None and "lacks" in (b.unavailable_reason() or ""), name


def test_missing_features(tmp_path: Path) -> None:
    d = fixtures.write_scene(
        tmp_path / "s", fixtures_quad(), requires=("ids", "one_sided", "lambert", "depth", "area_light")
    )
    scene = resolved.load(d)
    pov = registry.load("povray")
    assert registry.missing_features(pov, scene) == ["area_light", "one_sided"]


def fixtures_quad() -> list[list[list[float]]]:
    return [[[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]]]


# --------------------------------------------------------------------------- CLI


def test_info_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["info", "--json"]) == 0
    rows = {r["name"]: r for r in json.loads(capsys.readouterr().out)["backends"]}
    assert set(rows) >= {"povray"}
    for row in rows.values():
        keys = {
            "name",
            "module",
            "version",
            "features",
            "buffers",
            "peak_memory",
            "waits_below",
            "available",
            "reason",
            "declared_in",
        }
        assert set(row) == keys
        # None for the built-in ones; a declared renderer's file (tests/test_command_renderers.py)
        assert row["declared_in"] is None or row["module"].startswith("command:")
        assert row["available"] == (row["reason"] is None)


def test_info_text(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["info"]) == 0
    assert "povray" in capsys.readouterr().out


def test_render_skips_missing_features(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    d = fixtures.write_scene(tmp_path / "s", fixtures_quad(), requires=("depth", "ids", "global_illumination"))
    out = tmp_path / "o.exr"
    assert cli.main(["render", "--backend", "povray", "--scene", str(d), "--out", str(out)]) == 3
    msg = json.loads(capsys.readouterr().out)
    assert msg["status"] == "skipped" and "global_illumination" in msg["reason"] and msg["backend"] == "povray"
    assert not out.exists()


def test_render_unknown_backend(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    d = fixtures.three_triangles(tmp_path / "s")
    assert cli.main(["render", "--backend", "nope", "--scene", str(d), "--out", str(tmp_path / "o.exr")]) == 2
    err = capsys.readouterr().err
    assert "unknown backend 'nope'" in err and "povray" in err


def test_render_bad_scene(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rc = cli.main(
        ["render", "--backend", "povray", "--scene", str(tmp_path / "none"), "--out", str(tmp_path / "o.exr")]
    )
    assert rc == 2 and "scene.json: missing" in capsys.readouterr().err


def test_render_unavailable_backend(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    d = fixtures.three_triangles(tmp_path / "s")
    empty = tmp_path / "empty"
    empty.mkdir()
    monkeypatch.setenv("PATH", str(empty))
    assert cli.main(["render", "--backend", "povray", "--scene", str(d), "--out", str(tmp_path / "o.exr")]) == 2
    err = capsys.readouterr().err
    assert "povray unavailable" in err and "apt-get install povray" in err and "Traceback" not in err


def _render_povray(scene: Path, out: Path, *extra: str) -> list[str]:
    """The harness's `render` arguments for POV-Ray on `scene` into `out`."""
    return ["render", "--backend", "povray", "--scene", str(scene), "--out", str(out), *extra]


def test_render_backend_error_exit_2_without_traceback(tmp_path: Path) -> None:
    """Through `python -m`, a crashing renderer gives one stderr message and exit 2."""
    d = fixtures.three_triangles(tmp_path / "s")
    fake = tmp_path / "bin"
    fake.mkdir()
    (fake / "povray").write_text("#!/bin/sh\necho 'POV-Ray 3.7.0.10' >&2\necho 'Fatal: boom' >&2\nexit 1\n")
    (fake / "povray").chmod(0o755)
    env = {"PATH": f"{fake}:/usr/bin:/bin", "PYTHONPATH": str(HARNESS)}
    proc = subprocess.run(
        [sys.executable, "-m", "rendiff_harness", *_render_povray(d, tmp_path / "o.exr", "--timeout", "30")],
        check=False,
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
    )
    assert proc.returncode == 2, proc.stderr
    assert "povray:" in proc.stderr and "Fatal: boom" in proc.stderr and "Traceback" not in proc.stderr
    assert proc.stdout == ""
    assert not (tmp_path / "o.exr").exists()


@needs_povray
def test_render_success_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    d = fixtures.three_triangles(tmp_path / "s")
    out = tmp_path / "o.exr"
    rc = cli.main(_render_povray(d, out, "--workdir", str(tmp_path / "w")))
    assert rc == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 1
    msg = json.loads(lines[0])
    assert msg["backend"] == "povray" and msg["version"].startswith("POV-Ray 3.7")
    assert msg["time_s"] > 0 and "passes" in msg["info"]
    buf = exrbuf.read_buffers(out, require=["Z", "id.prim", "id.object"])
    assert (buf["id.prim"] != vocab.BACKGROUND_ID).any() and np.isfinite(buf["Z"]).any()


def test_every_shipped_backend_declares_its_measured_peak_memory() -> None:
    # check/pool.rs budgets memory with these; a backend without a measurement gets the guess.
    for name in registry.BUILT_IN:
        backend = registry.load(name)
        assert backend.spec is not None, backend.import_error
        fixed, per_triangle = backend.peak_memory
        assert backend.peak_memory != registry.UNMEASURED_MEMORY, name
        assert 0 < fixed < registry.UNMEASURED_MEMORY[0] and 0 < per_triangle < registry.UNMEASURED_MEMORY[1]
    missing = registry.Backend("gone", None, "not installed")
    assert missing.peak_memory == registry.UNMEASURED_MEMORY
