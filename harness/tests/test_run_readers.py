"""The readers of a run's and an export's own files refuse special files, wrong sizes and
paths out of their folder in one line (a FIFO among them hung `metamorphic` or `compare`,
`/dev/zero` ran them out of memory, and scene.json could name a data file anywhere)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fixtures import write_scene
from rendiff_harness.contract import manifest, resolved

HARNESS = Path(__file__).resolve().parents[1]

TRI = [[[0, 0, 0], [1, 0, 0], [0, 1, 0]]]


def _in_child(code: str, *args: str) -> subprocess.CompletedProcess[str]:
    """Run `code` in a child with a timeout: a reader that blocks fails the test, never hangs it."""
    env = dict(os.environ, PYTHONPATH=f"{HARNESS}{os.pathsep}{HARNESS / 'tests'}")
    try:
        return subprocess.run([sys.executable, "-c", code, *args], env=env, capture_output=True, text=True, timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail("hung: the reader blocked")


LOAD_SCENE = """
import sys
from rendiff_harness.contract import resolved
try:
    resolved.load(sys.argv[1])
except resolved.SceneError as e:
    print(e)
"""


@pytest.mark.parametrize("name", ["triangles.f32", "object_ids.u32", "scene.json"])
def test_a_fifo_in_a_resolved_scene_is_refused(tmp_path: Path, name: str) -> None:
    sdir = write_scene(tmp_path / "s", TRI, [0])
    (sdir / name).unlink()
    os.mkfifo(sdir / name)
    r = _in_child(LOAD_SCENE, str(sdir))
    assert f"{name}: is not a regular file" in r.stdout, r


def test_data_files_of_the_wrong_size_or_outside_the_folder_are_refused(tmp_path: Path) -> None:
    sdir = write_scene(tmp_path / "s", TRI, [0])
    meta = json.loads((sdir / "scene.json").read_text())
    (sdir / "scene.json").write_text(json.dumps({**meta, "triangle_count": 1 << 40}))
    with pytest.raises(resolved.SceneError, match=r"triangles.f32: is 36 bytes, expected"):
        resolved.load(sdir)
    for bad in ["../elsewhere.f32", "/etc/hostname", ".."]:
        (sdir / "scene.json").write_text(json.dumps({**meta, "files": {"triangles": bad}}))
        with pytest.raises(resolved.SceneError, match=r"files.triangles must be a file name"):
            resolved.load(sdir)


def test_a_vertex_ids_file_of_the_wrong_size_or_kind_or_place_is_refused(tmp_path: Path) -> None:
    """vertex_ids.u32 is read on demand (only the verifier needs it), with the same checks as the
    other data files: a name outside the folder at load, a wrong size or a FIFO when read."""
    sdir = write_scene(tmp_path / "s", TRI, [0])
    meta = json.loads((sdir / "scene.json").read_text())
    files = {**meta["files"], "vertex_ids": "vertex_ids.u32"}
    (sdir / "scene.json").write_text(json.dumps({**meta, "files": files}))
    np.array([0, 1], dtype="<u4").tofile(sdir / "vertex_ids.u32")
    with pytest.raises(resolved.SceneError, match=r"vertex_ids.u32: is 8 bytes, expected 12"):
        resolved.load(sdir).corner_vertex_ids()
    (sdir / "vertex_ids.u32").unlink()
    os.mkfifo(sdir / "vertex_ids.u32")
    with pytest.raises(resolved.SceneError, match=r"vertex_ids.u32: is not a regular file"):
        resolved.load(sdir).corner_vertex_ids()
    (sdir / "scene.json").write_text(json.dumps({**meta, "files": {**files, "vertex_ids": "../v.u32"}}))
    with pytest.raises(resolved.SceneError, match=r"files.vertex_ids must be a file name"):
        resolved.load(sdir)
    (sdir / "scene.json").write_text(json.dumps(meta))
    assert resolved.load(sdir).corner_vertex_ids() is None  # none written: the verifier numbers them


def test_a_special_manifest_is_refused(tmp_path: Path) -> None:
    (tmp_path / "run").mkdir()
    os.symlink("/dev/zero", tmp_path / "run" / "manifest.json")
    with pytest.raises(manifest.ManifestError, match=r"manifest.json: is not a regular file"):
        manifest.load_manifest(tmp_path / "run")


def test_harness_messages_stay_one_line_whatever_paths_they_quote(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A newline in --scene forged a second message line ("FAKE: injected line/scene.json: missing").
    from rendiff_harness.__main__ import main

    scene = str(tmp_path / "nope\nFAKE: injected line")
    rc = main(["render", "--backend", "povray", "--scene", scene, "--out", str(tmp_path / "o.exr")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1, err
    assert err.startswith("rendiff_harness: ") and "nope\\nFAKE: injected line" in err, err
