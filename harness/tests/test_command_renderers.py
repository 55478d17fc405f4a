"""Renderers declared by a command (command_renderers.py): the TOML file, the run protocol, the verdicts.

The renderers here are tiny Python scripts run with this interpreter (an absolute path in
`command`); most copy an EXR the test prepared (the float64 cast of backend_cases, the
core's answer in the end-to-end test) to {out}.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import backend_cases as cases
import fixtures
from fixtures import QUADS_OIDS as OIDS
from fixtures import QUADS_TRIS as TRIS
from fixtures import cli, manifest_scene, process_gone, write_manifest, write_scene
from rendiff_harness.contract import exrbuf, resolved, vocab
from rendiff_harness.judge import calibration, camera_budget, precision, tolerance
from rendiff_harness.renderers import command as command_renderers
from rendiff_harness.renderers import registry
from rendiff_harness.renderers.command import ENV_VAR, RenderersError
from rendiff_harness.renderers.errors import BackendError, BackendSkipped

HARNESS = Path(__file__).resolve().parents[1]
RENDIFF = fixtures.rendiff_binary()
NOT_BUILT = "rendiff binary not built (cargo build --release -p rendiff; scripts/test.sh does)"
PY = json.dumps(sys.executable)
BG = vocab.BACKGROUND_ID

# The quads of fixtures.py: two quads share the edge x = 5/32, whose projection is exactly
# the centers of column 16 (W = H = 32, vfov 90, eye (0, 0, 5)).
EDGE_PX = (16, 8)  # on the shared edge: reference prim 0, prim 3 across it
W = H = 32

COPY = """
import shutil, sys
shutil.copyfile(sys.argv[1], sys.argv[2])
"""


def script(tmp_path: Path, name: str, body: str) -> Path:
    path = tmp_path / "bin" / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(body)
    return path


def declare(tmp_path: Path, text: str, name: str = "renderers.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def entry(
    name: str,
    command: list[str],
    extra: str = "",
    precision: str = "edge_px = 0.004\ndepth_relative = 1e-6",
    features: tuple[str, ...] = ("depth", "ids"),
    buffers: tuple[str, ...] = ("Z", "id"),
) -> str:
    """One [[renderer]] entry, by default writing Z and id (depth, ids)."""
    return (
        f"[[renderer]]\nname = {json.dumps(name)}\ncommand = {json.dumps(command)}\n"
        f"features = {json.dumps(list(features))}\nbuffers = {json.dumps(list(buffers))}\n{extra}\n"
        f"[renderer.precision]\n{precision}\n"
    )


def quads(directory: Path) -> tuple[Path, dict[str, np.ndarray]]:
    """The quads scene and its float64 pixel-center cast (the reference)."""
    sdir = write_scene(directory, TRIS, OIDS, vfov_deg=90.0, width=W, height=H, name="quads")
    ref = cases.cast(resolved.load(sdir))
    return sdir, {"Z": ref.z.astype(np.float32), "prim": ref.prim, "obj": ref.obj}


def write_exr(path: Path, bufs: dict[str, np.ndarray], **kw: Any) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    exrbuf.write_buffers(path, Z=bufs.get("Z"), prim=bufs.get("prim"), obj=bufs.get("obj"), **kw)
    return path


def render(scene: Path, out: Path, backend: str = "mine", *extra: str) -> tuple[int, dict[str, Any], str]:
    rc, stdout, stderr = cli("render", "--backend", backend, "--scene", str(scene), "--out", str(out), *extra)
    line = stdout.strip().splitlines()[-1] if stdout.strip() else "{}"
    return rc, json.loads(line), stderr


@pytest.fixture()
def scene(tmp_path: Path) -> tuple[Path, dict[str, np.ndarray]]:
    return quads(tmp_path / "scene")


@pytest.fixture()
def answered(tmp_path: Path, scene: tuple[Path, dict[str, np.ndarray]]) -> tuple[Path, Path]:
    """The quads scene's folder and its reference written as a renderer's EXR (tmp_path/answer.exr)."""
    sdir, ref = scene
    return sdir, write_exr(tmp_path / "answer.exr", ref)


# --------------------------------------------------------------------------- the file


def _documented_example() -> str:
    """The renderers file in renderers/command.py's docstring, as a user would copy it."""
    doc = command_renderers.__doc__ or ""
    start = doc.index("    [[renderer]]")
    return textwrap.dedent(doc[start : doc.index("\n\n", start)]) + "\n"


def test_the_documented_example_parses(tmp_path: Path) -> None:
    path = declare(tmp_path, _documented_example())
    (r,) = command_renderers.load(path, registry.RESERVED_NAMES)
    assert r.name == "myrender" and r.source == path and r.index == 0
    assert r.command[0] == "./bin/myrender" and r.version_command == ("./bin/myrender", "--version")
    assert r.features == {"depth", "ids"} and r.buffers == {"Z", "id"} and r.timeout_s == 60.0
    assert r.precision == command_renderers.Precision(edge_px=0.004, depth_relative=1e-6)
    values = {"scene": "/s p", "out": "/o.exr", "width": "96", "height": "72"}
    assert [command_renderers.expand(a, values) for a in r.command[1:]] == ["--scene", "/s p", "--out", "/o.exr"]
    assert command_renderers.expand("{width}x{height}", values) == "96x72"
    assert command_renderers.expand("{{literal}}", values) == "{literal}"


GOOD = entry("good", ["/bin/true", "{out}"])


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("[[renderer]\nname = 1", "not valid TOML"),
        ("", "declares no renderer"),
        ("[other]\nx = 1\n" + GOOD, "unknown top-level key 'other'"),
        ("renderer = 3", "declares no renderer"),
        (GOOD.replace('name = "good"\n', ""), "#1: name must be a string"),
        (GOOD.replace('name = "good"', 'name = "Good"'), "#1: name must be a string matching"),
        (GOOD.replace('name = "good"', 'name = "my render"'), "name must be a string matching"),
        (GOOD.replace('name = "good"', 'name = "povray"'), "#1 (povray): name 'povray' is taken by a built-in"),
        (GOOD.replace('name = "good"', 'name = "raster"'), "taken by a built-in backend"),
        (GOOD + GOOD, "#2 (good): name 'good' is already declared by [[renderer]] #1"),
        (GOOD.replace('command = ["/bin/true", "{out}"]\n', ""), "#1 (good): missing key 'command'"),
        (GOOD.replace('command = ["/bin/true", "{out}"]', 'command = "/bin/true {out}"'), "command must be an array"),
        (GOOD.replace('command = ["/bin/true", "{out}"]', "command = []"), "command must not be empty"),
        (GOOD.replace('"{out}"]', '"{output}"]'), "command[1] '{output}': unknown placeholder {output}"),
        (GOOD.replace('"{out}"]', '"{out"]'), "command[1] '{out': unmatched '{'"),
        (GOOD.replace('"/bin/true"', '"{scene}/r"'), "command[0] '{scene}/r': unknown placeholder"),
        (GOOD.replace("buffers =", 'version = ["v", "{out}"]\nbuffers ='), "version[1] '{out}': unknown placeholder"),
        (GOOD.replace('["depth", "ids"]', '["depth", "idz"]'), "unknown feature 'idz'"),
        (GOOD.replace('["Z", "id"]', '["Z", "ID"]'), "unknown buffer 'ID'"),
        (GOOD.replace('["Z", "id"]', "[]"), "buffers must not be empty"),
        (GOOD.replace('["Z", "id"]', '"Z"'), "buffers must be an array of strings"),
        (GOOD.replace("buffers =", "colour = 1\nbuffers ="), "unknown key 'colour'"),
        (GOOD.replace("buffers =", "timeout_s = 0\nbuffers ="), "timeout_s must be > 0"),
        (GOOD.replace("buffers =", 'timeout_s = "60"\nbuffers ='), "timeout_s must be a number"),
        (GOOD.replace("edge_px = 0.004", "edge_px = -0.004"), "precision.edge_px must be a finite number >= 0"),
        (GOOD.replace("edge_px = 0.004", "edge_px = nan"), "precision.edge_px must be a finite number >= 0"),
        (GOOD.replace("edge_px = 0.004", "edge_px = true"), "precision.edge_px must be a number"),
        (GOOD.replace("depth_relative = 1e-6", ""), "it writes Z but precision has no depth_relative"),
        (GOOD.replace("edge_px = 0.004", "edge = 0.004"), "unknown precision key 'edge'"),
        (GOOD + "depth_grazing = 1\n", "depth_grazing must be true or false"),
        (GOOD.split("[renderer.precision]")[0], "missing key 'precision'"),
    ],
)
def test_a_malformed_file_is_one_line_naming_the_file_and_entry(tmp_path: Path, text: str, expected: str) -> None:
    path = declare(tmp_path, text)
    with pytest.raises(RenderersError) as err:
        command_renderers.load(path, registry.RESERVED_NAMES)
    message = str(err.value)
    assert message.startswith(f"{path}: ") and "\n" not in message, message
    assert expected in message, message


def test_info_fails_clearly_on_a_malformed_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = declare(tmp_path, GOOD.replace('"ids"', '"idz"'))
    monkeypatch.setenv(ENV_VAR, str(path))
    for argv in (["info", "--json"], ["render", "--backend", "good", "--scene", "x", "--out", "y.exr"]):
        rc, out, err = cli(*argv)
        assert rc == 2 and out == ""
        assert err.strip().count("\n") == 0 and str(path) in err and "unknown feature 'idz'" in err
    with pytest.raises(RenderersError):
        registry.all_backends()
    monkeypatch.setenv(ENV_VAR, "relative/renderers.toml")
    rc, _, err = cli("info", "--json")
    assert rc == 2 and "must be an absolute path" in err
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "absent.toml"))
    rc, _, err = cli("info", "--json")
    assert rc == 2 and "absent.toml: cannot read the renderers file" in err


def test_a_renderers_file_is_a_regular_file_within_the_limit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A FIFO, a device or an oversized file is refused in one line (never waited on or read whole)."""
    fifo = tmp_path / "pipe.toml"
    os.mkfifo(fifo)
    big = tmp_path / "big.toml"
    big.write_bytes(b"#" * (command_renderers.MAX_FILE_BYTES + 1))
    for path, needle in ((fifo, "not a regular file"), (Path("/dev/zero"), "not a regular file"), (big, "larger than")):
        monkeypatch.setenv(ENV_VAR, str(path))
        rc, out, err = cli("info", "--json")
        assert rc == 2 and out == "", err
        assert err.strip().count("\n") == 0 and str(path) in err and needle in err, err


def test_reserved_names_cover_every_built_in_backend() -> None:
    builtin = {b.name for b in registry.all_backends()} | set(registry.BUILT_IN)
    core = {name for name in ("raster", "trace", "embree", "embree_robust") if registry.spec(name) is not None}
    assert core == {"raster", "trace", "embree", "embree_robust"}
    assert builtin | core | {vocab.CACHED_REFERENCE_BACKEND} <= registry.RESERVED_NAMES


def test_loading_imports_no_heavy_module(tmp_path: Path) -> None:
    path = declare(tmp_path, GOOD)
    code = (
        "import sys\nfrom rendiff_harness.renderers import command as c\n"
        f"assert c.load({str(path)!r}, ('povray',))[0].name == 'good'\n"
        "print(sorted(m for m in ('numpy', 'OpenImageIO', 'mitsuba', 'pyrender') if m in sys.modules))\n"
    )
    env = dict(os.environ, PYTHONPATH=str(HARNESS))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout
    assert out.strip() == "[]"


# --------------------------------------------------------------------------- info and availability


def test_info_lists_declared_renderers_with_version_and_availability(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    ver = script(tmp_path, "version.py", "print('\\nMyRender 1.2 (abc)')\nprint('second line')\n")
    local = script(tmp_path, "local.py", "#!" + sys.executable + "\n")
    local.chmod(0o755)
    noexec = script(tmp_path, "noexec.py", "")
    path = declare(
        tmp_path,
        entry("mine", [sys.executable, "{out}"], f"version = [{PY}, {json.dumps(str(ver))}]")
        + entry("noversion", [sys.executable, "{out}"])
        + entry("relative", ["./bin/local.py", "{out}"])
        + entry("absent", ["./bin/absent", "{out}"])
        + entry("notexec", [str(noexec), "{out}"])
        + entry("nopath", ["no-such-renderer-here", "{out}"]),
    )
    monkeypatch.setenv(ENV_VAR, str(path))
    rc, out, _ = cli("info", "--json")
    assert rc == 0
    rows = {r["name"]: r for r in json.loads(out)["backends"]}
    assert {"povray", "pyrender", "mitsuba"} <= set(rows)  # the built-in ones are still there
    mine = rows["mine"]
    assert mine["available"] and mine["version"] == "MyRender 1.2 (abc)" and mine["reason"] is None
    assert mine["features"] == ["depth", "ids"] and mine["buffers"] == ["Z", "id"]
    assert mine["declared_in"] == str(path) and rows["povray"]["declared_in"] is None
    assert rows["noversion"]["version"] == "unknown"
    assert rows["relative"]["available"]  # ./bin/local.py, from the TOML file's folder
    for name, why in (
        ("absent", f"{tmp_path}/bin/absent does not exist"),
        ("notexec", f"{noexec} is not executable"),
        ("nopath", "'no-such-renderer-here' not found on PATH"),
    ):
        row = rows[name]
        assert not row["available"] and row["version"] is None
        assert row["reason"].startswith(f"{path} (renderer {name!r}): command ") and why in row["reason"], row
    assert registry.get("mine").name == "mine" and "mine" in registry.known_names()
    rc, out, _ = cli("info")
    assert rc == 0 and f"declared in {path}" in out


# --------------------------------------------------------------------------- rendering


def test_a_correct_renderer_renders_and_passes_the_comparison(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, scene: tuple[Path, dict[str, np.ndarray]]
) -> None:
    sdir, ref = scene
    copy = script(tmp_path, "copy.py", COPY)
    exact = write_exr(tmp_path / "answers/exact.exr", ref, attrs={"spp": 1})
    near = {k: v.copy() for k, v in ref.items()}
    hit = np.isfinite(near["Z"])
    near["Z"][hit] *= np.float32(1 + 5e-7)  # within the declared 1e-6 Z
    x, y = EDGE_PX
    near["prim"][y, x], near["obj"][y, x] = 3, 1  # the quad across the shared edge: edge, allowed
    nearly = write_exr(tmp_path / "answers/near.exr", near)
    path = declare(
        tmp_path,
        entry("mine", [sys.executable, str(copy), str(exact), "{out}"])
        + entry("close", [sys.executable, str(copy), str(nearly), "{out}"])
        + entry(
            "strict", [sys.executable, str(copy), str(nearly), "{out}"], precision="edge_px = 0\ndepth_relative = 0"
        ),
    )
    monkeypatch.setenv(ENV_VAR, str(path))

    run = tmp_path / "run"
    run_scene = run / "scenes/quads"
    shutil.copytree(sdir, run_scene / "resolved")
    renders = [{"backend": "raster", "status": "ok", "exr": "scenes/quads/raster.exr", "buffers": ["Z", "id"]}]
    write_exr(run_scene / "raster.exr", ref)
    for name in ("mine", "close", "strict"):
        out = run_scene / f"{name}.exr"
        rc, line, err = render(run_scene / "resolved", out, name)
        assert rc == 0 and err == "", err
        assert line["status"] == "ok" and line["backend"] == name and line["version"] == "unknown"
        assert line["info"]["declared_in"] == str(path) and line["info"]["exit_status"] == 0
        assert line["info"]["command"][-1].endswith(f"{name}.exr") and line["info"]["command"][-1] != str(out)
        assert sorted(line["buffers"]) == ["Z", "id"]
        renders.append({**line, "exr": f"scenes/quads/{name}.exr", "command": name, "time_s": 0.1})
        assert not [p for p in run_scene.iterdir() if p.name.startswith(".")]  # no temp file left
    got = exrbuf.read_buffers(run_scene / "mine.exr")
    assert np.array_equal(got["Z"], ref["Z"]) and np.array_equal(got["id.prim"], ref["prim"])
    attrs = exrbuf.read_attrs(run_scene / "mine.exr")
    assert attrs["backend"] == "mine" and attrs["declared_in"] == str(path) and attrs["spp"] == 1

    write_manifest(run, [manifest_scene("quads", renders)])
    rc, _, err = cli("compare", "--run", str(run), "--no-images")
    assert rc == 0, err
    results = {(r["backend"], r["buffer"]): r for r in json.loads((run / "results.json").read_text())["results"]}
    for buf in ("id", "Z"):
        assert results[("mine", buf)]["status"] == "pass", results[("mine", buf)]
        assert results[("close", buf)]["status"] == "pass", results[("close", buf)]
    assert results[("close", "id")]["edge_mismatches"] == 1
    assert str(path) in results[("close", "Z")]["tolerance"] and "1e-06*Z" in results[("close", "Z")]["tolerance"]
    assert results[("strict", "Z")]["status"] == "fail"  # the same pixels, judged at its declared 0
    assert results[("strict", "Z")]["interior_mismatches"] > 0


def test_declared_precision_reaches_every_model(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = declare(
        tmp_path,
        "[[renderer]]\nname = 'full'\ncommand = ['/bin/true']\nfeatures = ['depth', 'ids', 'normals', 'lambert']\n"
        "buffers = ['Z', 'id', 'N', 'RGB']\n[renderer.precision]\nedge_px = 0.01\ndepth_relative = 1e-5\n"
        "depth_absolute = 1e-7\ndepth_grazing = true\nnormal_relative = 3e-6\nrgb_relative = 1e-4\n"
        "rgb_absolute = 0.002\n",
    )
    monkeypatch.setenv(ENV_VAR, str(path))
    full = registry.spec("full")
    model = precision.depth_model(full, "full")
    assert model.known and model.edge_px == 0.01 and str(path) in model.edge_reason
    ctx = tolerance.DepthContext(z_ref=np.array([2.0, 2.0]), cos=np.array([1.0, 0.01]), info={}, attrs={})
    tol, text = model.depth(ctx)
    assert np.allclose(tol, [1e-7 + 2e-5, 1e-7 + 2e-3]) and str(path) in text and "/|cos|" in text
    angle, ntext = precision.normal_tolerance(full, np.array([1.0, 50.0]))
    assert np.array_equal(angle, [3e-6, 3e-6]) and str(path) in ntext
    rgb = precision.rgb_tolerance(full, "full", np.zeros((2, 2, 3)), {}, {})
    assert (rgb.abs_tol, rgb.rel) == (0.002, 1e-4) and str(path) in rgb.text
    cal, known = precision.camera_model(full)
    assert known and cal is not camera_budget.core_camera
    assert registry.spec("undeclared") is None
    assert precision.depth_model(None, "undeclared").known is False  # unknown names stay strict


def test_scene_path_with_spaces_and_shell_characters_arrives_as_one_argument(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    weird = tmp_path / "a scene; $(touch pwned) `id` 'q' \"d\" * & | > {x}"
    sdir, ref = quads(weird)
    answer = write_exr(tmp_path / "answer.exr", ref)
    seen = tmp_path / "argv.json"
    spy = script(
        tmp_path,
        "spy.py",
        "import json, os, shutil, sys\n"
        f"json.dump({{'argv': sys.argv[1:], 'cwd': os.getcwd()}}, open({str(seen)!r}, 'w'))\n"
        f"shutil.copyfile({str(answer)!r}, sys.argv[2])\n",
    )
    path = declare(
        tmp_path, entry("mine", [sys.executable, str(spy), "{scene}", "{out}", "{width}x{height}", "{{scene}}"])
    )
    monkeypatch.setenv(ENV_VAR, str(path))
    work = tmp_path / "work"
    rc, line, err = render(sdir, tmp_path / "out.exr", "mine", "--workdir", str(work))
    assert rc == 0, err
    got = json.loads(seen.read_text())
    assert got["argv"][0] == str(sdir.absolute()) and got["argv"][2:] == ["32x32", "{scene}"]
    assert Path(got["argv"][1]).parent.parent == work  # {out} is a temporary name in the scratch folder
    assert Path(got["cwd"]).parent.parent == work  # ... and it ran in a scratch folder of its own
    assert not list(tmp_path.rglob("pwned")) and not list(work.iterdir())  # no shell; scratch removed


def _hanging(tmp_path: Path, pids: Path, then: str = "") -> Path:
    """A renderer that starts a child sleeping 600 s, writes its pid, the child's and its process
    group to `pids` (whole: by rename), runs the lines `then`, and sleeps 600 s."""
    return script(
        tmp_path,
        "hang.py",
        "import os, subprocess, sys, time\n"
        "child = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(600)'])\n"
        f"open({str(pids)!r} + '.tmp', 'w').write(f'{{os.getpid()}} {{child.pid}} {{os.getpgid(0)}}')\n"
        f"os.rename({str(pids)!r} + '.tmp', {str(pids)!r})\n" + then + "time.sleep(600)\n",
    )


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_hanging_renderer_is_killed_with_its_whole_group(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, scene: tuple[Path, dict[str, np.ndarray]]
) -> None:
    pids = tmp_path / "pids.txt"
    hang = _hanging(
        tmp_path, pids, "print('working', file=sys.stderr, flush=True)\nopen(sys.argv[1], 'wb').write(b'half an EXR')\n"
    )
    path = declare(tmp_path, entry("mine", [sys.executable, str(hang), "{out}"], "timeout_s = 1.5"))
    monkeypatch.setenv(ENV_VAR, str(path))
    out = tmp_path / "out.exr"
    t0 = time.monotonic()
    rc, _, err = render(scene[0], out, "mine", "--timeout", "60")  # the declared 1.5 s caps it
    assert time.monotonic() - t0 < 30
    assert rc == 2 and "mine: timed out after 1.5 s; its process group was killed; stderr: working" in err
    leader, child, group = (int(v) for v in pids.read_text().split())
    assert group not in (os.getpgid(0), leader)  # a group of its own, led by the supervisor
    gone = process_gone(leader, 5.0) and process_gone(child, 5.0)
    assert gone, "a process of the renderer's group outlived the timeout"
    assert not out.exists()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_a_renderer_and_its_children_die_when_the_harness_is_killed(
    tmp_path: Path, scene: tuple[Path, dict[str, np.ndarray]]
) -> None:
    pids = tmp_path / "pids.txt"
    hang = _hanging(tmp_path, pids)
    path = declare(tmp_path, entry("mine", [sys.executable, str(hang), "{out}"]))
    env = dict(os.environ, PYTHONPATH=str(HARNESS), **{ENV_VAR: str(path)})
    argv = ["render", "--backend", "mine", "--scene", str(scene[0]), "--out", str(tmp_path / "o.exr")]
    harness = subprocess.Popen([sys.executable, "-m", "rendiff_harness", *argv], env=env, stderr=subprocess.PIPE)
    try:
        end = time.monotonic() + 30
        while not pids.exists() and time.monotonic() < end and harness.poll() is None:
            time.sleep(0.05)
        assert pids.exists(), harness.stderr.read() if harness.stderr else ""
    finally:
        harness.kill()  # SIGKILL: no handler of the harness runs
        harness.communicate()
    renderer, child, _ = (int(v) for v in pids.read_text().split())
    assert process_gone(renderer, 5.0) and process_gone(child, 5.0), "the renderer's group outlived the harness"


def test_a_crash_is_an_error_with_its_status_and_stderr(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, scene: tuple[Path, dict[str, np.ndarray]]
) -> None:
    crash = script(
        tmp_path, "crash.py", "import sys\nprint('loading', file=sys.stderr)\nsys.exit('boom: bad triangle 7')\n"
    )
    segv = script(tmp_path, "segv.py", "import os, signal\nos.kill(os.getpid(), signal.SIGSEGV)\n")
    path = declare(
        tmp_path,
        entry("crash", [sys.executable, str(crash), "{out}"]) + entry("segv", [sys.executable, str(segv), "{out}"]),
    )
    monkeypatch.setenv(ENV_VAR, str(path))
    out = tmp_path / "out.exr"
    rc, _, err = render(scene[0], out, "crash")
    assert rc == 2 and "crash: exited with status 1; stderr: loading | boom: bad triangle 7" in err, err
    rc, _, err = render(scene[0], out, "segv")
    assert rc == 2 and "segv: killed by SIGSEGV; nothing on stderr" in err, err
    assert not out.exists()


def test_exit_3_is_a_skip_with_the_last_stderr_line_as_reason(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, scene: tuple[Path, dict[str, np.ndarray]]
) -> None:
    skip = script(
        tmp_path,
        "skip.py",
        "import sys\nprint('probing adapters', file=sys.stderr)\n"
        "print('no Vulkan adapter\\n\\n', file=sys.stderr)\nsys.exit(3)\n",
    )
    silent = script(tmp_path, "silent.py", "import sys\nsys.exit(3)\n")
    path = declare(
        tmp_path,
        entry("skip", [sys.executable, str(skip), "{out}"]) + entry("silent", [sys.executable, str(silent), "{out}"]),
    )
    monkeypatch.setenv(ENV_VAR, str(path))
    rc, line, err = render(scene[0], tmp_path / "out.exr", "skip")
    assert rc == 3 and err == ""  # rendiff check reads the reason from stderr first: keep it empty
    assert line == {"backend": "skip", "status": "skipped", "reason": "no Vulkan adapter", "missing": []}
    rc, line, _ = render(scene[0], tmp_path / "out.exr", "silent")
    assert rc == 3 and "without a reason" in line["reason"]
    with pytest.raises(BackendSkipped, match="no Vulkan adapter"):
        registry.get("skip").render(resolved.load(scene[0]), tmp_path / "o.exr", tmp_path / "w", 10.0)


def _oiio_exr(path: Path, channels: dict[str, str], width: int = W, height: int = H) -> None:
    import OpenImageIO as oiio

    spec = oiio.ImageSpec(width, height, len(channels), oiio.FLOAT)
    spec.channelnames = tuple(channels)
    spec.channelformats = tuple(oiio.TypeDesc(t) for t in channels.values())
    out = oiio.ImageOutput.create(str(path))
    assert out is not None and out.open(str(path), spec)
    assert out.write_image(np.zeros((height, width, len(channels)), np.float32))
    out.close()


def test_a_wrong_output_is_an_error_naming_what_is_wrong(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, scene: tuple[Path, dict[str, np.ndarray]]
) -> None:
    sdir, ref = scene
    answers = tmp_path / "answers"
    answers.mkdir()
    write_exr(answers / "small.exr", {k: v[:24, :30] for k, v in ref.items()})
    write_exr(answers / "no_obj.exr", {"Z": ref["Z"], "prim": ref["prim"]})
    write_exr(answers / "no_z.exr", {"prim": ref["prim"], "obj": ref["obj"]})
    _oiio_exr(answers / "half_z.exr", {"Z": "half", "id.object": "uint", "id.prim": "uint"})
    _oiio_exr(answers / "float_ids.exr", {"Z": "float", "id.object": "float", "id.prim": "uint"})
    (answers / "junk.exr").write_bytes(b"not an image at all")
    copy = script(tmp_path, "copy.py", COPY)
    nothing = script(tmp_path, "nothing.py", "")
    cases_ = {
        "small": "its EXR is 30x24, expected 32x32 (the scene camera's size)",
        "no_obj": "wrote no id.object channel",
        "no_z": "wrote no Z channel",
        "half_z": "Z is half, expected float",
        "float_ids": "id.object is float, expected uint",
        "junk": "wrote an unreadable image at {out}",
    }
    text = "".join(
        entry(name.replace("_", "-"), [sys.executable, str(copy), str(answers / f"{name}.exr"), "{out}"])
        for name in cases_
    )
    path = declare(tmp_path, text + entry("nothing", [sys.executable, str(nothing), "{out}"]))
    monkeypatch.setenv(ENV_VAR, str(path))
    out = tmp_path / "out.exr"
    for name, why in [*cases_.items(), ("nothing", "wrote no file at {out}")]:
        backend = name.replace("_", "-")
        rc, _, err = render(sdir, out, backend)
        assert rc == 2 and f"{backend}: exited 0 but {why}" in err and str(path) in err, err
        assert not out.exists()
    # A failed render leaves an earlier file at the output path as it was.
    out.write_bytes(b"previous")
    assert render(sdir, out, "no-obj")[0] == 2 and out.read_bytes() == b"previous"


def test_visibility_only_neither_requires_nor_keeps_rgb(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    sdir = write_scene(
        tmp_path / "lit",
        TRIS,
        OIDS,
        vfov_deg=90.0,
        width=W,
        height=H,
        requires=("depth", "ids", "lambert", "point_light"),
        lights=[{"kind": "point", "position": [0, 4, 4], "intensity": [10, 10, 10]}],
        materials=[{"name": "grey", "albedo": [0.5, 0.5, 0.5], "emission": [0, 0, 0]}],
    )
    ref = cases.cast(resolved.load(sdir))
    rgb = np.ones((H, W, 3), np.float32)
    answer = tmp_path / "with_rgb.exr"
    exrbuf.write_buffers(answer, Z=ref.z.astype(np.float32), prim=ref.prim, obj=ref.obj, RGB=rgb)
    copy = script(tmp_path, "copy.py", COPY)
    command = [sys.executable, str(copy), str(answer), "{out}"]
    exact = "edge_px = 0\ndepth_relative = 0\nrgb_relative = 1e-6"
    path = declare(tmp_path, entry("lit", command, "", exact, ("depth", "ids", "lambert"), ("Z", "id", "RGB")))
    monkeypatch.setenv(ENV_VAR, str(path))
    out = tmp_path / "out.exr"
    rc, line, _ = render(sdir, out, "lit")
    assert rc == 3 and line["missing"] == ["point_light"]  # without the flag: skipped, as for any backend
    rc, line, err = render(sdir, out, "lit", "--visibility-only")
    assert rc == 0, err
    assert line["visibility_only"] and line["buffers"] == ["Z", "id"] and line["info"]["visibility_only"]
    assert set(exrbuf.read_buffers(out)) == {"Z", "id.prim", "id.object"}


def test_programs_relative_to_the_file_and_a_missing_program(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, answered: tuple[Path, Path]
) -> None:
    sdir, answer = answered
    conf = tmp_path / "conf"
    local = script(
        conf, "render.py", f"#!{sys.executable}\nimport shutil, sys\nshutil.copyfile({str(answer)!r}, sys.argv[1])\n"
    )
    local.chmod(0o755)
    path = declare(conf, entry("local", ["./bin/render.py", "{out}"]) + entry("gone", ["../elsewhere/render", "{out}"]))
    monkeypatch.setenv(ENV_VAR, str(path))
    monkeypatch.chdir(tmp_path)  # not the file's folder
    rc, _, err = render(sdir, tmp_path / "out.exr", "local")
    assert rc == 0, err
    rc, _, err = render(sdir, tmp_path / "out2.exr", "gone")
    assert (
        rc == 2
        and f"gone unavailable: {path} (renderer 'gone'): command {conf}/../elsewhere/render does not exist" in err
    )
    with pytest.raises(BackendError):
        registry.get("gone").render(resolved.load(sdir), tmp_path / "o.exr", tmp_path / "w", 10.0)


# --------------------------------------------------------------------------- with the rendiff binary


def _icosphere_run(run: Path) -> tuple[Path, Path]:
    """scenes/icosphere.toml exported into the run folder `run`, and the core's raster render of it:
    (resolved scene folder, raster EXR)."""
    root = HARNESS.parent
    toml = root / "scenes/icosphere.toml"
    sdir = run / "scenes/icosphere/resolved"
    ref = run / "scenes/icosphere/raster.exr"
    assert RENDIFF is not None
    for argv in (["export", str(toml), "-o", str(sdir)], ["render", "--renderer", "raster", str(toml), "-o", str(ref)]):
        subprocess.run([str(RENDIFF), *argv], check=True, capture_output=True, cwd=root, timeout=120)
    return sdir, ref


@pytest.mark.skipif(RENDIFF is None, reason=NOT_BUILT)
def test_the_cores_own_answer_through_a_command_passes_every_buffer(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    run = tmp_path / "run"
    sdir, ref = _icosphere_run(run)
    copy = script(tmp_path, "copy.py", COPY)
    command = [sys.executable, str(copy), str(ref), "{out}"]
    version = f"version = {json.dumps([str(RENDIFF), '--version'])}"
    exact = "edge_px = 0\ndepth_relative = 0\nnormal_relative = 2.4e-7"
    path = declare(tmp_path, entry("copycat", command, version, exact, ("depth", "ids", "normals"), ("Z", "id", "N")))
    monkeypatch.setenv(ENV_VAR, str(path))
    out = run / "scenes/icosphere/copycat.exr"
    rc, line, err = render(sdir, out, "copycat")
    assert rc == 0, err
    assert line["version"].startswith("rendiff")
    requires = json.loads((sdir / "scene.json").read_text())["requires"]
    renders = [
        {"backend": "raster", "status": "ok", "exr": "scenes/icosphere/raster.exr", "buffers": ["Z", "id", "N"]},
        {**line, "exr": "scenes/icosphere/copycat.exr", "command": "copycat", "time_s": 0.1},
    ]
    results = [r for (backend, _), r in _compare(run, "icosphere", requires, renders).items() if backend == "copycat"]
    assert {r["buffer"] for r in results} >= {"id", "Z", "N"}
    assert all(r["status"] == "pass" for r in results), results


def test_the_group_kill_leaves_nothing_after_a_normal_exit(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, answered: tuple[Path, Path]
) -> None:
    sdir, answer = answered
    pids = tmp_path / "pids.txt"
    daemon = script(
        tmp_path,
        "daemon.py",
        "import shutil, subprocess, sys\n"
        "child = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(600)'])\n"
        f"open({str(pids)!r}, 'w').write(str(child.pid))\n"
        f"shutil.copyfile({str(answer)!r}, sys.argv[1])\n",
    )
    path = declare(tmp_path, entry("mine", [sys.executable, str(daemon), "{out}"]))
    monkeypatch.setenv(ENV_VAR, str(path))
    rc, _, err = render(sdir, tmp_path / "out.exr", "mine")
    assert rc == 0, err
    child = int(pids.read_text())
    try:
        assert process_gone(child, 5.0), "a process the renderer left behind survived it"
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(child, signal.SIGKILL)


# --------------------------------------------------------------------------- the worked example

EXAMPLES = HARNESS / "examples"


def _compare(run: Path, scene: str, requires: list[str], renders: list[dict[str, Any]]) -> dict[tuple[str, str], Any]:
    write_manifest(run, [manifest_scene(scene, renders, requires)])
    rc, _, err = cli("compare", "--run", str(run), "--no-images")
    assert rc == 0, err
    return {(r["backend"], r["buffer"]): r for r in json.loads((run / "results.json").read_text())["results"]}


def _use_examples(monkeypatch: pytest.MonkeyPatch) -> None:
    """examples/renderers.toml as it is; its script's `python3` is this interpreter (it has numpy)."""
    monkeypatch.setenv(ENV_VAR, str(EXAMPLES / "renderers.toml"))
    monkeypatch.setenv("PATH", f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")


def test_the_worked_example_renders_the_fixture_and_passes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    _use_examples(monkeypatch)
    (tiny,) = command_renderers.from_env(registry.RESERVED_NAMES)
    assert tiny.name == "tiny" and tiny.precision.depth_relative == 1.2e-7
    run = tmp_path / "run"
    sdir, ref = quads(run / "scenes/quads/resolved")
    write_exr(run / "scenes/quads/raster.exr", ref)
    rc, line, err = render(sdir, run / "scenes/quads/tiny.exr", "tiny")
    assert rc == 0, err
    got = exrbuf.read_buffers(run / "scenes/quads/tiny.exr")
    assert set(got) == {"Z", "id.prim", "id.object", "N"}
    renders = [
        {"backend": "raster", "status": "ok", "exr": "scenes/quads/raster.exr", "buffers": ["Z", "id"]},
        {**line, "exr": "scenes/quads/tiny.exr", "command": "tiny", "time_s": 0.1},
    ]
    results = _compare(run, "quads", ["depth", "ids"], renders)
    for buf in ("id", "Z", "N"):
        assert results[("tiny", buf)]["status"] == "pass", results[("tiny", buf)]


@pytest.mark.skipif(RENDIFF is None, reason=NOT_BUILT)
def test_the_worked_example_agrees_with_the_core_at_its_declared_precision(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _use_examples(monkeypatch)
    run = tmp_path / "run"
    sdir, ref = _icosphere_run(run)
    rc, line, err = render(sdir, run / "scenes/icosphere/tiny.exr", "tiny")
    assert rc == 0, err
    requires = json.loads((sdir / "scene.json").read_text())["requires"]
    renders = [
        {"backend": "raster", "status": "ok", "exr": "scenes/icosphere/raster.exr", "buffers": ["Z", "id", "N"]},
        {**line, "exr": "scenes/icosphere/tiny.exr", "command": "tiny", "time_s": 0.1},
    ]
    results = _compare(run, "icosphere", requires, renders)
    for buf in ("id", "Z", "N"):
        r = results[("tiny", buf)]
        assert r["status"] == "pass", r


def test_calibration_judges_a_declared_renderer_at_its_declared_precision(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import test_calibration as probes  # the committed probe scene and its exact cast, without the core

    path = declare(
        tmp_path,
        entry("coarse", ["/bin/true"], precision="edge_px = 0.01\ndepth_relative = 1e-7")
        + entry("fine", ["/bin/true"], precision="edge_px = 0\ndepth_relative = 0"),
    )
    monkeypatch.setenv(ENV_VAR, str(path))
    scene = probes.probe_scene(tmp_path / "probe")
    g = np.eye(3)
    g[1, 0] = 0.004 * probes.pixel(scene)  # samples 0.004 px right of the centers
    z, prim = probes.cast(scene, g)
    coarse = calibration.measure(scene, "coarse", z, prim, specs=registry.spec)
    assert coarse.status == "pass", coarse.reason
    assert str(path) in coarse.bound_text and coarse.bound_px is not None and coarse.bound_px > 0.004
    fine = calibration.measure(scene, "fine", z, prim, specs=registry.spec)
    assert fine.status == "fail" and "pixel centers offset by (0.004" in fine.reason, fine.reason


def test_interpreter_run_commands_and_here_work_from_the_files_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, scene: tuple[Path, dict[str, np.ndarray]]
) -> None:
    """`["python", "./my_renderer.py", ...]` and `{here}` in any argument (issue 42, item 5): the
    docs' Python and shell examples, from a folder whose name has spaces, braces and `$`."""
    sdir, ref = scene
    answer = write_exr(tmp_path / "answer.exr", ref)
    conf = tmp_path / "my renderers {out} $HOME; x"
    seen = tmp_path / "argv.json"
    (conf / "data").mkdir(parents=True)
    (conf / "my_renderer.py").write_text(
        "import json, os, shutil, sys\n"
        "if sys.argv[1] == '--version':\n    print('mine 1.0')\n    sys.exit(0)\n"
        f"json.dump({{'argv': sys.argv[1:], 'cwd': os.getcwd()}}, open({str(seen)!r}, 'w'))\n"
        f"shutil.copyfile({str(answer)!r}, sys.argv[2])\n"
    )
    (conf / "render.sh").write_text(f'#!/bin/sh\ncp "{answer}" "$2"\n')
    shim = tmp_path / "path"
    shim.mkdir()
    (shim / "python").symlink_to(sys.executable)  # "python" found on PATH, as a user's would be
    monkeypatch.setenv("PATH", f"{shim}{os.pathsep}{os.environ['PATH']}")
    path = declare(
        conf,
        entry(
            "py",
            ["python", "./my_renderer.py", "{scene}", "{out}", "--data={here}/data", "../up", "a/./b"],
            'version = ["python", "./my_renderer.py", "--version"]',
        )
        + entry("sh", ["sh", "{here}/render.sh", "{scene}", "{out}"])
        + entry("direct", ["{here}/render.sh", "{scene}", "{out}"]),
    )
    (conf / "render.sh").chmod(0o755)
    monkeypatch.setenv(ENV_VAR, str(path))
    monkeypatch.chdir(tmp_path)  # not the file's folder
    rc, line, err = render(sdir, tmp_path / "py.exr", "py")
    assert rc == 0, err
    assert line["version"] == "mine 1.0"
    got = json.loads(seen.read_text())
    assert got["argv"][0] == str(sdir.absolute())
    assert got["argv"][2:] == [f"--data={conf}/data", f"{conf}/../up", "a/./b"]  # one argument each, unexpanded
    assert line["info"]["command"][:2] == [str(shim / "python"), f"{conf}/./my_renderer.py"]
    for name in ("sh", "direct"):
        rc, line, err = render(sdir, tmp_path / f"{name}.exr", name)
        assert rc == 0, err
        assert np.array_equal(exrbuf.read_buffers(tmp_path / f"{name}.exr")["id.prim"], ref["prim"])
    assert not list(tmp_path.rglob("HOME*"))


FULL = (
    "[[renderer]]\nname = 'full'\ncommand = ['/bin/true']\nfeatures = ['depth', 'ids', 'normals', 'lambert']\n"
    "buffers = ['Z', 'id', 'N', 'RGB']\n[renderer.precision]\nedge_px = 0.01\ndepth_relative = 1e-5\n"
    "normal_relative = 3e-6\nrgb_relative = 1e-4\n"
)


@pytest.mark.parametrize(
    ("key", "bound"),
    [
        ("edge_px", 0.5),
        ("depth_relative", tolerance.MAX_REL),
        ("normal_relative", 1.0),
        ("rgb_relative", 1 - 1 / np.pi),
    ],
)
def test_a_precision_beyond_what_can_be_judged_is_refused(tmp_path: Path, key: str, bound: float) -> None:
    """`edge_px = 1e6` passed a renderer writing triangle 0 everywhere (issue 40, item 5): each
    bounded number is refused at and above its bound (docs/your-renderer.md), accepted below."""
    assert command_renderers.PRECISION_BOUNDS[key][0] == bound
    old = next(line for line in FULL.splitlines() if line.startswith(f"{key} ="))
    for value in (bound, 1e6):
        path = declare(tmp_path, FULL.replace(old, f"{key} = {value!r}"))
        with pytest.raises(RenderersError) as err:
            command_renderers.load(path, registry.RESERVED_NAMES)
        message = str(err.value)
        assert message.startswith(f"{path}: [[renderer]] #1 (full): precision.{key} = ") and "\n" not in message
        assert f"is not below {bound:.4g}, the most that can be judged" in message, message
    below = float(np.nextafter(bound, 0.0))
    path = declare(tmp_path, FULL.replace(old, f"{key} = {below!r}"))
    (r,) = command_renderers.load(path, registry.RESERVED_NAMES)
    assert getattr(r.precision, key) == below


def test_a_hanging_version_command_costs_a_short_timeout_and_the_renderer_still_runs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, answered: tuple[Path, Path]
) -> None:
    """A version command that never ends (issue 40, item 6) delays each render by seconds, not 30 s."""
    sdir, answer = answered
    hang = script(tmp_path, "hang.py", "import time\ntime.sleep(120)\n")
    copy = script(tmp_path, "copy.py", COPY)
    version = f"version = {json.dumps([sys.executable, str(hang)])}"
    path = declare(tmp_path, entry("mine", [sys.executable, str(copy), str(answer), "{out}"], version))
    monkeypatch.setenv(ENV_VAR, str(path))
    t0 = time.monotonic()
    rc, line, err = render(sdir, tmp_path / "out.exr", "mine")
    elapsed = time.monotonic() - t0
    assert rc == 0, err
    assert line["version"] == "unknown (the version command timed out after 5 s)"
    assert exrbuf.read_attrs(tmp_path / "out.exr")["version"] == line["version"]
    assert elapsed < 15.0, f"{elapsed:.1f} s"  # 5 s for the version, then the render (was 30 s and more)


def test_depth_absolute_counts_at_most_the_relative_bound_at_each_pixel(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`depth_absolute` is in scene units, so no load-time bound holds for every scene: at each
    pixel it counts at most MAX_REL Z (docs/your-renderer.md, "What can be judged"), so a huge
    one no longer passes every depth, while one far below the scene's depths is kept whole."""
    path = declare(
        tmp_path, entry("abs", ["/bin/true"], precision="edge_px = 0\ndepth_relative = 1e-6\ndepth_absolute = 1e6")
    )
    monkeypatch.setenv(ENV_VAR, str(path))
    model = precision.depth_model(registry.spec("abs"), "abs")
    ctx = tolerance.DepthContext(z_ref=np.array([2.0, 5.0]), cos=np.array([1.0, 1.0]), info={}, attrs={})
    tol, text = model.depth(ctx)
    assert np.allclose(tol, [2e-3 + 2e-6, 5e-3 + 5e-6]) and "min(1e+06, 0.001*Z)" in text
    path = declare(
        tmp_path,
        entry("abs", ["/bin/true"], precision="edge_px = 0\ndepth_relative = 0\ndepth_absolute = 1e-6"),
        "small.toml",
    )
    monkeypatch.setenv(ENV_VAR, str(path))
    tol, _ = precision.depth_model(registry.spec("abs"), "abs").depth(ctx)
    assert np.array_equal(tol, [1e-6, 1e-6])


def test_a_known_version_is_taken_and_the_version_command_is_not_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, answered: tuple[Path, Path]
) -> None:
    """`rendiff check` asks each renderer's version once (`info --json`) and passes it to every
    render (`--known-version`): the version command does not run again (issue 40, item 6)."""
    sdir, answer = answered
    ran = tmp_path / "version-ran"
    probe = script(tmp_path, "probe.py", f"open({str(ran)!r}, 'a').write('x')\nprint('2.0 from the command')\n")
    copy = script(tmp_path, "copy.py", COPY)
    version = f"version = {json.dumps([sys.executable, str(probe)])}"
    path = declare(tmp_path, entry("mine", [sys.executable, str(copy), str(answer), "{out}"], version))
    monkeypatch.setenv(ENV_VAR, str(path))
    rc, line, err = render(sdir, tmp_path / "out.exr", "mine", "--known-version=-1.0 (told)")
    assert rc == 0, err
    assert line["version"] == "-1.0 (told)"
    assert exrbuf.read_attrs(tmp_path / "out.exr")["version"] == "-1.0 (told)"
    assert not ran.exists(), "the version command ran although the version was known"
    # Without it, the command is asked (the test's probe is real).
    rc, line, err = render(sdir, tmp_path / "out2.exr", "mine")
    assert rc == 0, err
    assert line["version"] == "2.0 from the command" and ran.exists()
