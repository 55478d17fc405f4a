"""Capabilities per buffer: a backend lacking only shading features still renders Z and IDs.

`registry.plan` decides; `render --visibility-only` (what `rendiff check` passes when a
backend lacks a shading feature the scene needs) carries it out; POV-Ray and pyrender then
skip their radiance passes, and a backend whose render() has no `visibility_only` keyword
is skipped as before.
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

import fixtures
from rendiff_harness import __main__ as cli
from rendiff_harness import renderers
from rendiff_harness.contract import exrbuf, resolved, vocab
from rendiff_harness.renderers import registry

REPO = Path(__file__).resolve().parents[2]
needs_povray = pytest.mark.skipif(shutil.which("povray") is None, reason="povray binary not on PATH")

QUAD = [
    [[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]],
    [[-1.5, -0.5, -1.0], [1.5, -0.5, -1.0], [0.0, 1.5, -1.0]],
]
SUN = [{"kind": "directional", "direction": [0.0, 0.0, -1.0], "irradiance": [1.0, 1.0, 1.0]}]
# Shaded, with features both POV-Ray (one_sided) and pyrender (shadows, one_sided) lack.
SHADED = ("depth", "ids", "lambert", "directional_light", "shadows", "one_sided")

FAKE = """
NAME = "{name}"
FEATURES = frozenset({{"depth", "ids", "lambert"}})
BUFFERS = frozenset({{"Z", "id", "RGB"}})
def version(): return "fake 1"
def unavailable_reason(): return None
def render(scene, out_exr, workdir, timeout_s{kw}):
    from rendiff_harness.contract import exrbuf
    import numpy as np
    h, w = scene.camera.height, scene.camera.width
    prim = np.zeros((h, w), dtype=np.uint32)
    rgb = None if {no_rgb} else np.zeros((h, w, 3), dtype=np.float32)
    exrbuf.write_buffers(out_exr, Z=np.ones((h, w), dtype=np.float32), prim=prim, obj=prim, RGB=rgb)
    return {{"visibility_only": {no_rgb}}}
from rendiff_harness.judge.tolerance import Model, exact_depth
from rendiff_harness.renderers.spec import BackendSpec
SPEC = BackendSpec(
    NAME, FEATURES, BUFFERS, Model(NAME, 0.0, "", exact_depth),
    render=render, version=version, unavailable_reason=unavailable_reason,
)
"""


def _fake_backends(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`vis_backend` takes visibility_only; `full_backend` (like Mitsuba's) does not."""
    files = {
        "vis": FAKE.format(name="vis", kw=", *, visibility_only=False", no_rgb="visibility_only"),
        "full": FAKE.format(name="full", kw="", no_rgb="False"),
    }
    for name, text in files.items():
        (tmp_path / name).mkdir()
        (tmp_path / name / "backend.py").write_text(text)
        for mod in (f"rendiff_harness.renderers.{name}", f"rendiff_harness.renderers.{name}.backend"):
            monkeypatch.delitem(sys.modules, mod, raising=False)
    monkeypatch.setattr(renderers, "__path__", [*renderers.__path__, str(tmp_path)])
    monkeypatch.setattr(registry, "BUILT_IN", (*registry.BUILT_IN, *files))


def _scene(tmp_path: Path, requires: tuple[str, ...]) -> Path:
    return fixtures.write_scene(tmp_path / "scene", QUAD, [0, 1], requires=requires, lights=SUN)


def test_visibility_features_come_from_the_vocabulary() -> None:
    """One list, mirrored from Rust's vocab (tests/vocab_drift.rs compares the two)."""
    assert registry.VISIBILITY_FEATURES == {f.value for f in vocab.VISIBILITY_FEATURES}
    assert registry.VISIBILITY_FEATURES == {"depth", "ids", "normals"}


def test_plan_per_buffer(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _fake_backends(tmp_path, monkeypatch)
    vis, full = registry.get("vis"), registry.get("full")
    assert vis.accepts("visibility_only") and not full.accepts("visibility_only")

    shaded = resolved.load(_scene(tmp_path / "a", ("depth", "ids", "lambert", "shadows", "one_sided")))
    p = registry.plan(vis, shaded, visibility_only=True)
    assert (p.render, p.visibility_only, p.missing) == (True, True, ("one_sided", "shadows"))
    assert p.reason == "RGB not rendered: missing features: one_sided, shadows"
    # Without the flag, or for a backend without the keyword: skipped as a whole, as before.
    for backend, flag in ((vis, False), (full, True), (full, False)):
        p = registry.plan(backend, shaded, visibility_only=flag)
        assert (p.render, p.reason) == (False, "missing features: one_sided, shadows"), (backend.name, flag)

    # A missing visibility feature skips the backend whatever the flag.
    normals = resolved.load(_scene(tmp_path / "b", ("depth", "ids", "normals", "lambert", "shadows")))
    p = registry.plan(vis, normals, visibility_only=True)
    assert not p.render and p.reason == "missing features: normals, shadows"

    # Everything supported: a full render; the flag still drops RGB where it is accepted.
    lit = resolved.load(_scene(tmp_path / "c", ("depth", "ids", "lambert")))
    assert registry.plan(vis, lit) == registry.Plan(True, False, (), "")
    assert registry.plan(full, lit, visibility_only=True) == registry.Plan(True, False, (), "")
    assert registry.plan(vis, lit, visibility_only=True) == registry.Plan(True, True, (), "")


def test_cli_visibility_only(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    _fake_backends(tmp_path, monkeypatch)
    d = _scene(tmp_path, ("depth", "ids", "lambert", "shadows"))
    out = tmp_path / "vis.exr"
    assert cli.main(["render", "--backend", "vis", "--scene", str(d), "--out", str(out), "--visibility-only"]) == 0
    msg = json.loads(capsys.readouterr().out)
    assert msg["status"] == "ok" and msg["visibility_only"] is True and msg["buffers"] == ["Z", "id"]
    assert msg["reason"] == "RGB not rendered: missing features: shadows"
    assert msg["info"] == {"visibility_only": True}
    assert "R" not in exrbuf.read_buffers(out)

    # A backend without the keyword keeps today's behaviour: skipped, exit 3.
    out = tmp_path / "full.exr"
    assert cli.main(["render", "--backend", "full", "--scene", str(d), "--out", str(out), "--visibility-only"]) == 3
    msg = json.loads(capsys.readouterr().out)
    assert msg["status"] == "skipped" and msg["reason"] == "missing features: shadows" and not out.exists()
    # And so does the accepting one without the flag.
    assert cli.main(["render", "--backend", "vis", "--scene", str(d), "--out", str(out)]) == 3
    assert json.loads(capsys.readouterr().out)["missing"] == ["shadows"]


def _check_visibility(scene_dir: Path, out: Path) -> None:
    """Z and IDs present and plausible (both triangles seen), no RGB channels."""
    buf = exrbuf.read_buffers(out, require=["Z", "id.prim", "id.object"])
    assert "RGB" not in buf and "R" not in buf
    prim = buf["id.prim"]
    assert set(np.unique(prim).tolist()) == {0, 1, vocab.BACKGROUND_ID}
    assert np.isfinite(buf["Z"][prim != vocab.BACKGROUND_ID]).all()
    assert np.isinf(buf["Z"][prim == vocab.BACKGROUND_ID]).all()


@needs_povray
def test_povray_visibility_only_on_a_scene_it_cannot_shade(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    d = _scene(tmp_path, SHADED)
    out = tmp_path / "pov.exr"
    rc = cli.main(["render", "--backend", "povray", "--scene", str(d), "--out", str(out), "--visibility-only"])
    assert rc == 0, capsys.readouterr().err
    msg = json.loads(capsys.readouterr().out)
    assert msg["reason"] == "RGB not rendered: missing features: one_sided" and msg["buffers"] == ["Z", "id"]
    assert set(msg["info"]["passes"]) == {"ids", "depth"}  # no lit or emission pass
    _check_visibility(d, out)


@pytest.mark.parametrize(
    ("module", "requires", "missing"),
    [
        ("pyrender", SHADED, "one_sided, shadows"),
        ("mitsuba", ("depth", "ids", "lambert", "directional_light", "shadowless", "one_sided"), "shadowless"),
    ],
)
def test_in_process_backends_render_visibility_on_a_scene_they_cannot_shade(
    tmp_path: Path, module: str, requires: tuple[str, ...], missing: str
) -> None:
    import importlib

    mod = importlib.import_module(f"rendiff_harness.renderers.{module}.backend")
    reason = mod.unavailable_reason()
    if reason is not None:
        pytest.skip(f"{module} unavailable: {reason}")
    d = _scene(tmp_path, requires)
    scene = resolved.load(d)
    backend = registry.get(mod.NAME)
    p = registry.plan(backend, scene, visibility_only=True)
    assert p.visibility_only and p.reason == f"RGB not rendered: missing features: {missing}"
    out = tmp_path / "vis.exr"
    info = backend.render(scene, out, tmp_path, 60.0, visibility_only=True)
    assert info["visibility_only"] is True and "radiance" not in info
    _check_visibility(d, out)
