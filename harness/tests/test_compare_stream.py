"""compare.py's `--stream`: scenes judged before manifest.json is read give the results a plain
comparison gives, and a streamed record that is not exactly the manifest's is never what is judged."""

from __future__ import annotations

import copy
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import backend_cases as cases
from rendiff_harness import compare
from rendiff_harness.contract import exrbuf, resolved
from rendiff_harness.contract.manifest import ManifestError

HARNESS = Path(__file__).resolve().parents[1]


def _scene(run: Path, name: str, shift: int) -> dict[str, Any]:
    """A scene whose `other` backend misses `shift` pixels of the reference's ids (0: none)."""
    d = cases.lit_plane(run / f"scenes/{name}/resolved", [], requires=("depth", "ids"))
    scene = resolved.load(d)
    z = cases.plane_depth(scene, np.zeros(3), np.array([0.0, 0.0, 1.0])).astype(np.float32)
    prim = np.zeros(z.shape, dtype=np.uint32)
    renders: list[dict[str, Any]] = []
    for backend in ("raster", "other"):
        p = prim.copy()
        if backend == "other" and shift:
            p[20, 10 : 10 + shift] = 1  # a prim the reference never shows: interior id mismatches
        exr = run / f"scenes/{name}/{backend}.exr"
        exrbuf.write_buffers(exr, Z=z, prim=p, obj=np.zeros_like(p))
        renders.append(
            {
                "backend": backend,
                "status": "ok",
                "exr": exr.relative_to(run).as_posix(),
                "time_s": 0.1,
                "version": f"{backend} 1",
                "command": f"render {backend}",
                "buffers": ["Z", "id"],
                "info": {},
            }
        )
    return {"scene": name, "resolved": f"scenes/{name}/resolved", "requires": ["depth", "ids"], "renders": renders}


def _run(tmp_path: Path) -> tuple[Path, list[dict[str, Any]]]:
    run = tmp_path / "run"
    run.mkdir()
    scenes = [_scene(run, "clean", 0), _scene(run, "faulty", 3)]
    doc = {"format": "rendiff-manifest/1", "reference": "raster", "created": "x", "rendiff_version": "0"}
    (run / "manifest.json").write_text(json.dumps({**doc, "scenes": scenes}))
    return run, scenes


def _line(entry: dict[str, Any], reference: str = "raster") -> str:
    return json.dumps({"reference": reference, "scene": entry}) + "\n"


def _statuses(doc: dict[str, Any]) -> dict[tuple[str, str, str], str]:
    return {(r["scene"], r["backend"], r["buffer"]): r["status"] for r in doc["results"]}


@pytest.mark.parametrize("jobs", [1, 2])
def test_streamed_scenes_give_the_plain_results(tmp_path: Path, jobs: int) -> None:
    run, scenes = _run(tmp_path)
    plain = compare.run_compare(run, None, images=False)
    streamed = compare.run_compare(run, None, images=False, jobs=jobs, stream=[_line(s) for s in scenes[::-1]])
    assert streamed == plain
    statuses = _statuses(plain)
    assert statuses[("clean", "other", "id")] == "pass" and statuses[("faulty", "other", "id")] == "fail"


def test_a_streamed_record_unlike_the_manifest_is_judged_again(tmp_path: Path) -> None:
    run, scenes = _run(tmp_path)
    plain = compare.run_compare(run, None, images=False)
    # The faulty scene streamed as if its test render had failed, and the clean one under
    # another reference name: neither is the manifest's record, so both are judged again.
    changed = copy.deepcopy(scenes[1])
    changed["renders"][1]["status"] = "error"
    changed["renders"][1]["message"] = "streamed, not the manifest"
    lines = [_line(scenes[0], reference="other"), _line(changed)]
    assert compare.run_compare(run, None, images=False, stream=lines) == plain


def test_a_malformed_stream_line_is_refused_naming_it(tmp_path: Path) -> None:
    run, scenes = _run(tmp_path)
    with pytest.raises(ManifestError, match="stdin line 2: not JSON"):
        compare.run_compare(run, None, images=False, stream=[_line(scenes[0]), "{oops\n"])
    with pytest.raises(ManifestError, match=r"stdin line 1: expected \{"):
        compare.run_compare(run, None, images=False, stream=['{"scene": {"scene": "clean"}}\n'])


def test_the_command_reads_its_stdin(tmp_path: Path) -> None:
    run, scenes = _run(tmp_path)
    plain = compare.run_compare(run, None, images=False)
    (run / "results.json").unlink()
    cmd = [sys.executable, "-m", "rendiff_harness", "compare", "--run", str(run), "--no-images", "--stream"]
    stdin = "".join(_line(s) for s in scenes)
    proc = subprocess.run(cmd, input=stdin, text=True, capture_output=True, cwd=HARNESS, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((run / "results.json").read_text())
    assert _statuses(doc) == _statuses(plain)
