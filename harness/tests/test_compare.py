"""compare.py end to end on tiny runs: a float64 ray cast as the reference, fake backends derived from it."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import backend_cases as cases
from fixtures import QUADS_OIDS as OIDS
from fixtures import QUADS_TRIS as TRIS
from fixtures import manifest_scene, write_manifest, write_scene
from rendiff_harness import compare
from rendiff_harness.__main__ import main as harness_main
from rendiff_harness.contract import exrbuf, resolved, results, vocab
from rendiff_harness.judge import diffimages, precision, tolerance
from rendiff_harness.renderers import registry

BG = vocab.BACKGROUND_ID

# Scene "quads" (fixtures.py): two quads share the vertical edge x = 5/32, which projects
# to px = 16.5: every center of column 16 lies exactly on it.
EDGE_PX = (16, 8)  # (x, y): on the shared edge, ref prim 0
INTERIOR_PX = (15, 17)  # inside prim 4, 2.15 px from its edges, 1 px from prim 2
PLAIN_PX = (10, 20)  # inside prim 0 or 1, away from column 16


def _ref(scene_dir: Path) -> tuple[resolved.ResolvedScene, dict[str, np.ndarray]]:
    scene = resolved.load(scene_dir)
    ref = cases.cast(scene)
    return scene, {"Z": ref.z.astype(np.float32), "prim": ref.prim, "obj": ref.obj}


def _write_exr(path: Path, bufs: dict[str, np.ndarray], attrs: dict[str, Any] | None = None) -> str:
    path.parent.mkdir(parents=True, exist_ok=True)
    exrbuf.write_buffers(path, Z=bufs.get("Z"), prim=bufs.get("prim"), obj=bufs.get("obj"), attrs=attrs)
    return path.as_posix()


def _ok(backend: str, exr: str, **kw: Any) -> dict[str, Any]:
    r = {
        "backend": backend,
        "status": "ok",
        "exr": exr,
        "time_s": 0.5,
        "version": f"{backend} 1.0",
        "command": f"render {backend}",
        "buffers": ["Z", "id"],
        "info": {},
    }
    r.update(kw)
    return r


def _copy(b: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {k: v.copy() for k, v in b.items()}


def build_run(tmp_path: Path) -> tuple[Path, dict[str, np.ndarray]]:
    """A run with scene 'quads' (reference + fake backends) and scene 'noref' (reference EXR missing)."""
    run = tmp_path / "run"
    sdir = write_scene(run / "scenes/quads/resolved", TRIS, OIDS, vfov_deg=90.0, width=32, height=32, name="quads")
    scene, ref = _ref(sdir)
    assert ref["prim"][EDGE_PX[1], EDGE_PX[0]] == 0
    assert ref["prim"][INTERIOR_PX[1], INTERIOR_PX[0]] == 4
    assert ref["prim"][PLAIN_PX[1], PLAIN_PX[0]] in (0, 1)
    rel = lambda p: p.relative_to(run).as_posix()  # noqa: E731
    s = run / "scenes/quads"
    renders = [_ok("raster", rel(Path(_write_exr(s / "raster.exr", ref))))]

    renders.append(_ok("trace", rel(Path(_write_exr(s / "trace.exr", ref)))))

    pov = _copy(ref)
    pov["prim"][EDGE_PX[1], EDGE_PX[0]] = 3  # the right quad's triangle across the edge
    pov["obj"][EDGE_PX[1], EDGE_PX[0]] = 1
    pov["prim"][INTERIOR_PX[1], INTERIOR_PX[0]] = 2
    pov["obj"][INTERIOR_PX[1], INTERIOR_PX[0]] = 1
    pov["Z"][INTERIOR_PX[1], INTERIOR_PX[0]] = 5.0
    renders.append(
        _ok("povray", rel(Path(_write_exr(s / "povray.exr", pov, {"depth_step": 1e-9}))), info={"depth_step": 1e-9})
    )

    mit = _copy(ref)
    hit = np.isfinite(mit["Z"])
    mit["Z"][hit] *= np.float32(1 + 2e-6)  # within 1e-5/|cos|
    x, y = PLAIN_PX
    mit["Z"][y, x] = ref["Z"][y, x] * np.float32(1 + 1e-4)  # beyond
    mit["Z"][y + 1, x] = np.inf  # interior mask mismatch (ID kept)
    ex, ey = EDGE_PX
    mit["prim"][ey, ex] = BG  # ID edge mismatch + Z mask mismatch at it -> Z edge
    mit["obj"][ey, ex] = BG
    mit["Z"][ey, ex] = np.inf
    renders.append(_ok("mitsuba", rel(Path(_write_exr(s / "mitsuba.exr", mit)))))

    pyr = _copy(ref)
    pyr["Z"][hit] = np.nextafter(pyr["Z"][hit], np.float32(np.inf))  # 1 f32 ulp: inside the 24-bit model
    renders.append(_ok("pyrender", rel(Path(_write_exr(s / "pyrender.exr", pyr, {"znear": 3.0, "zfar": 8.0})))))

    odd = _copy(ref)
    odd["Z"][hit] *= np.float32(1 + 1e-6)  # an unknown backend is compared exactly
    renders.append(_ok("newthing", rel(Path(_write_exr(s / "newthing.exr", odd)))))

    nan_bg = _copy(ref)
    assert not np.isfinite(ref["Z"][0, :2]).any()  # the image's top-left corner is background
    nan_bg["Z"][0, 0] = np.nan  # not background: only +inf is (IDs kept)
    nan_bg["Z"][0, 1] = -np.inf
    renders.append(_ok("nanbg", rel(Path(_write_exr(s / "nanbg.exr", nan_bg)))))

    renders.append({"backend": "embree", "status": "skipped", "reason": "missing features: lambert"})
    renders.append(
        {
            "backend": "embree_robust",
            "status": "error",
            "message": "timed out after 600 s",
            "time_s": 600.0,
            "command": "rendiff render --backend embree_robust",
        }
    )

    sdir2 = write_scene(run / "scenes/noref/resolved", TRIS[:1], vfov_deg=90.0, width=8, height=8, name="noref")
    _, ref2 = _ref(sdir2)
    t2 = rel(Path(_write_exr(run / "scenes/noref/povray.exr", ref2)))
    renders2 = [
        _ok("raster", "scenes/noref/raster.exr"),  # never written
        _ok("povray", t2),
        {"backend": "pyrender", "status": "skipped", "reason": "missing features: two_sided"},
    ]
    write_manifest(run, [manifest_scene("quads", renders), manifest_scene("noref", renders2)])
    return run, ref


def _strict_json(path: Path) -> dict[str, Any]:
    def no_const(name: str) -> None:
        raise AssertionError(f"non-JSON constant {name} in {path}")

    return json.loads(path.read_text(), parse_constant=no_const)


def _index(doc: dict[str, Any]) -> dict[tuple[str, str, str], dict[str, Any]]:
    return {(r["scene"], r["backend"], r["buffer"]): r for r in doc["results"]}


@pytest.fixture(scope="module")
def compared(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[tuple[str, str, str], dict[str, Any]], str]:
    tmp = tmp_path_factory.mktemp("cmp")
    run, _ = build_run(tmp)
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        rc = compare.main(["--run", str(run)])
    assert rc == 0
    return run, _index(_strict_json(run / "results.json")), out.getvalue()


def test_results_cover_every_backend_and_buffer(compared: Any) -> None:
    run, res, _ = compared
    doc = _strict_json(run / "results.json")
    assert doc["format"] == "rendiff-results/1" and doc["reference"] == "raster"
    backends = {"trace", "povray", "mitsuba", "pyrender", "newthing", "nanbg", "embree", "embree_robust"}
    assert {(b, buf) for (s, b, buf) in res if s == "quads"} == {(b, f) for b in backends for f in ("id", "Z")}
    assert all(r["backend"] != "raster" for r in res.values())
    assert not list(run.glob(".results.*"))  # the temp file was renamed


def test_identical_backend_passes(compared: Any) -> None:
    _, res, _ = compared
    for buf in ("id", "Z"):
        r = res[("quads", "trace", buf)]
        assert r["status"] == "pass", r
        assert (r["edge_mismatches"], r["interior_mismatches"], r["mask_mismatches"]) == (0, 0, 0)
        assert r["pixels"] == 32 * 32
        assert (r["time_s"], r["version"], r["command"]) == (0.5, "trace 1.0", "render trace")
    assert res[("quads", "trace", "Z")]["max_abs_error"] == 0.0
    assert res[("quads", "trace", "Z")]["compared_pixels"] > 300


def test_edge_and_interior_id_mismatches(compared: Any) -> None:
    _, res, _ = compared
    r = res[("quads", "povray", "id")]
    assert (r["edge_mismatches"], r["interior_mismatches"]) == (1, 1)
    assert r["status"] == "fail"
    assert "(15,17) ref 4 test 2" in r["reason"]
    assert "1e-03 px" in r["tolerance"] or "0.001 px" in r["tolerance"]
    z = res[("quads", "povray", "Z")]
    assert z["status"] == "pass", z  # differing prims are not depth-compared; masks agree
    assert "depth_step (1e-09" in z["tolerance"]


def test_depth_tolerance_and_mask_mismatches(compared: Any) -> None:
    _, res, _ = compared
    r = res[("quads", "mitsuba", "id")]
    # Background seen through the closed edge prims 0 and 3 share: a crack, which fails
    # without a declaration (this run has no expectations file).
    assert (r["edge_mismatches"], r["crack_mismatches"], r["interior_mismatches"], r["status"]) == (0, 1, 0, "fail")
    assert "crack" in r["reason"] and r["explanations"][0]["class"] == "crack"
    z = res[("quads", "mitsuba", "Z")]
    assert z["mask_mismatches"] == 2
    assert z["crack_mismatches"] == 1  # the mask mismatch at the ID crack
    assert z["interior_mismatches"] == 2  # one depth beyond 1e-5/|cos|, one mask mismatch
    assert z["status"] == "fail"
    assert z["max_rel_error"] == pytest.approx(1e-4, rel=0.05)
    assert 1e-6 < z["mean_abs_error"] < z["max_abs_error"]
    assert "beyond tolerance" in z["reason"] and "mask" in z["reason"]
    # Where: the interior pixels grouped by (ref prim, test prim) like the id buffer's, each
    # with an example; both are in the left quad (prims 0, 1), with their own prims on both sides.
    groups = z["explanations"]
    assert sum(g["pixels"] for g in groups) == 2 and all(g["class"] == "interior" for g in groups), groups
    x, y = PLAIN_PX
    assert {tuple(g["example"]) for g in groups} <= {(x, y), (x, y + 1)}
    assert all(g["ref_prim"] == g["test_prim"] and g["ref_prim"] in (0, 1) for g in groups), groups
    # A Z verdict with no interior pixel has none.
    assert "explanations" not in res[("quads", "trace", "Z")]


def test_nan_or_negative_infinite_depth_is_never_background(compared: Any) -> None:
    _, res, _ = compared
    z = res[("quads", "nanbg", "Z")]
    assert (z["mask_mismatches"], z["interior_mismatches"], z["status"]) == (2, 2, "fail"), z
    assert "(0,0) ref inf test nan" in z["reason"] and "(1,0) ref inf test -inf" in z["reason"]
    assert res[("quads", "nanbg", "id")]["status"] == "pass"


def test_pyrender_uses_the_backend_depth_model(compared: Any) -> None:
    _, res, _ = compared
    z = res[("quads", "pyrender", "Z")]
    assert z["status"] == "pass", z
    assert z["max_abs_error"] > 0
    assert "znear=3" in z["tolerance"] and "zfar=8" in z["tolerance"]


def test_unknown_backend_is_compared_exactly(compared: Any) -> None:
    _, res, _ = compared
    z = res[("quads", "newthing", "Z")]
    assert z["status"] == "fail" and z["interior_mismatches"] > 300
    assert "no precision model" in z["tolerance"]
    assert res[("quads", "newthing", "id")]["status"] == "pass"


def test_skipped_and_error_pass_through(compared: Any) -> None:
    _, res, _ = compared
    for buf in ("id", "Z"):
        s = res[("quads", "embree", buf)]
        assert (s["status"], s["reason"]) == ("skipped", "missing features: lambert")
        e = res[("quads", "embree_robust", buf)]
        assert (e["status"], e["reason"]) == ("error", "timed out after 600 s")
        assert e["time_s"] == 600.0 and e["command"] == "rendiff render --backend embree_robust"
        assert e["images"] == {}
        for r in (s, e):  # not compared: null, never "0 mismatches"
            assert all(r[k] is None for k in results.NUMERIC_FIELDS)


def test_missing_reference_makes_every_entry_an_error(compared: Any) -> None:
    _, res, _ = compared
    entries = [r for (s, _, _), r in res.items() if s == "noref"]
    assert len(entries) == 4
    for r in entries:
        assert r["status"] == "error"
        assert "reference raster unreadable" in r["reason"] and "raster.exr" in r["reason"]
    assert "pyrender itself skipped: missing features: two_sided" in res[("noref", "pyrender", "id")]["reason"]


def test_diff_images(compared: Any) -> None:
    import OpenImageIO as oiio

    run, res, _ = compared
    r = res[("quads", "povray", "id")]
    assert r["images"] == {"heat": "scenes/quads/diff/povray.id.png"}
    px = oiio.ImageBuf(str(run / r["images"]["heat"])).get_pixels(oiio.UINT8)
    assert px.shape == (32, 32, 3)
    x, y = EDGE_PX
    assert tuple(px[y, x]) == (255, 191, 0)  # edge: amber
    x, y = INTERIOR_PX
    assert tuple(px[y, x]) == (255, 0, 255)  # interior: magenta
    x, y = PLAIN_PX
    assert tuple(px[y, x]) == (56, 56, 56)  # same id: dark gray
    assert tuple(px[0, 0]) == (0, 0, 0)  # background in both
    z = res[("quads", "mitsuba", "Z")]
    zpx = oiio.ImageBuf(str(run / z["images"]["heat"])).get_pixels(oiio.UINT8)
    x, y = PLAIN_PX
    assert tuple(zpx[y + 1, x]) == (0, 255, 255)  # mask mismatch: cyan
    assert tuple(zpx[y, x]) == (248, 254, 95)  # the largest error: the bright end of inferno
    assert tuple(zpx[0, 0]) == (0, 0, 0)


def test_table_on_stdout(compared: Any) -> None:
    _, _, out = compared
    lines = out.splitlines()
    assert lines[0].split()[:4] == ["scene", "backend", "buf", "status"]
    assert any(ln.split()[:4] == ["quads", "povray", "id", "fail"] for ln in lines)
    # stdout is the table alone (rendiff check prints it as it is); the count line ends it.
    assert "entries:" in lines[-1]
    assert not any("results.json" in ln for ln in lines)


def _run_with(tmp_path: Path, toml: str) -> dict[tuple[str, str, str], dict[str, Any]]:
    run, _ = build_run(tmp_path)
    exp = tmp_path / "exp.toml"
    exp.write_text(toml)
    assert compare.main(["--run", str(run), "--expectations", str(exp), "--no-images"]) == 0
    return _index(_strict_json(run / "results.json"))


def _expect(scene: str, backend: str, buffer: str, reason: str, **bounds: list[int]) -> str:
    """One `[[expect]]` entry of an expectations file: status expected_fail, its count bounds."""
    keys = {"scene": scene, "backend": backend, "buffer": buffer, "status": "expected_fail", "reason": reason}
    lines = [f"{k} = {json.dumps(v)}" for k, v in {**keys, **bounds}.items()]
    return "\n[[expect]]\n" + "\n".join(lines) + "\n"


def test_expectations_pass_unexpected_pass_expected_fail_fail(tmp_path: Path) -> None:
    toml = "".join(
        [
            _expect("quads", "povray", "id", "recorded povray bug", interior_mismatches=[1, 1]),
            _expect("quads", "mitsuba", "Z", "mitsuba depth bug"),
            _expect("quads", "trace", "id", "was broken"),
            _expect("quads", "newthing", "Z", "too tight", interior_mismatches=[0, 3]),
            _expect("gone", "povray", "id", "stale"),
            '[[declare]]\nbackend = "mitsuba"\nallows = "crack"\nreason = "not watertight"\n',
        ]
    )
    res = _run_with(tmp_path, toml)
    p = res[("quads", "povray", "id")]
    assert p["status"] == "expected_fail" and "recorded povray bug" in p["reason"]
    assert p["bound"] == {"interior_mismatches": [1, 1], "crack_mismatches": [0, None]}
    m = res[("quads", "mitsuba", "id")]
    assert m["status"] == "pass" and m["crack_mismatches"] == 1 and "cracks allowed: not watertight" in m["reason"]
    assert res[("quads", "mitsuba", "Z")]["status"] == "expected_fail"
    assert res[("quads", "trace", "id")]["status"] == "unexpected_pass"
    n = res[("quads", "newthing", "Z")]
    assert n["status"] == "fail" and "interior_mismatches" in n["reason"]
    assert res[("quads", "trace", "Z")]["bound"] is None
    doc = _strict_json(tmp_path / "run" / "results.json")
    assert doc["unused_expectations"] == [{"entry": 5, "scene": "gone", "backend": "povray", "buffer": "id"}]


def test_unused_expectations_noted_only_for_the_runs_scenes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A stale entry of a scene in the run is shown; one of a scene the run never had is only in results.json."""
    toml = _expect("quads", "povray ", "id", "a typo in the backend") + _expect(
        "elsewhere", "povray", "id", "a scene of another run"
    )
    _run_with(tmp_path, toml)
    err = capsys.readouterr().err
    note = [line for line in err.splitlines() if line.startswith("note: expectations matched by no compared result")]
    assert len(note) == 1 and "quads/povray /id" in note[0] and "elsewhere" not in note[0], err
    doc = _strict_json(tmp_path / "run" / "results.json")
    assert [u["scene"] for u in doc["unused_expectations"]] == ["quads", "elsewhere"]


def test_malformed_expectations_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run, _ = build_run(tmp_path)
    exp = tmp_path / "bad.toml"
    exp.write_text(
        '[[expect]]\nscene = "quads"\nbackend = "povray"\nbuffer = "id"\nreason = "r"\nedge_mismatches = [4, 1]\n'
    )
    assert compare.main(["--run", str(run), "--expectations", str(exp)]) == 2
    err = capsys.readouterr().err
    assert str(exp) in err and "entry 1" in err and "'edge_mismatches'" in err
    assert not (run / "results.json").exists()


@pytest.mark.parametrize("content", [None, "{not json", '{"format": "other"}', '{"format": "rendiff-manifest/1"}'])
def test_unreadable_manifest_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str], content: str | None) -> None:
    run = tmp_path / "run"
    run.mkdir()
    if content is not None:
        (run / "manifest.json").write_text(content)
    assert compare.main(["--run", str(run)]) == 2
    err = capsys.readouterr().err
    assert str(run / "manifest.json") in err
    assert err.count("\n") == 1  # one line, no traceback


def test_missing_run_folder_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert compare.main(["--run", str(tmp_path / "nope")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_image_failure_keeps_the_numbers(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def boom(path: Any, *a: Any, **k: Any) -> None:
        raise diffimages.DiffImageError(f"{path}: disk full")

    monkeypatch.setattr(diffimages, "write_id_diff", boom)
    run, _ = build_run(tmp_path)
    assert compare.main(["--run", str(run)]) == 0
    r = _index(_strict_json(run / "results.json"))[("quads", "povray", "id")]
    assert (r["edge_mismatches"], r["interior_mismatches"], r["status"]) == (1, 1, "fail")
    assert "diff image not written" in r["reason"] and "disk full" in r["reason"]
    assert r["images"] == {}


def test_pyrender_without_planes_is_an_error(tmp_path: Path) -> None:
    run, ref = build_run(tmp_path)
    manifest = json.loads((run / "manifest.json").read_text())
    _write_exr(run / "scenes/quads/pyrender.exr", ref)  # no znear/zfar attributes, none in info either
    (run / "manifest.json").write_text(json.dumps(manifest))
    assert compare.main(["--run", str(run), "--no-images"]) == 0
    res = _index(_strict_json(run / "results.json"))
    assert res[("quads", "pyrender", "Z")]["status"] == "error"
    assert "znear" in res[("quads", "pyrender", "Z")]["reason"]
    assert res[("quads", "pyrender", "id")]["status"] == "pass"


def test_planes_from_info_when_attrs_lack_them(tmp_path: Path) -> None:
    run, ref = build_run(tmp_path)
    _write_exr(run / "scenes/quads/pyrender.exr", ref)
    manifest = json.loads((run / "manifest.json").read_text())
    for r in manifest["scenes"][0]["renders"]:
        if r["backend"] == "pyrender":
            r["info"] = {"znear": 3.0, "zfar": 8.0}
    (run / "manifest.json").write_text(json.dumps(manifest))
    assert compare.main(["--run", str(run), "--no-images"]) == 0
    assert _index(_strict_json(run / "results.json"))[("quads", "pyrender", "Z")]["status"] == "pass"


def test_missing_channel_and_bad_paths(tmp_path: Path) -> None:
    run, ref = build_run(tmp_path)
    exrbuf.write_buffers(run / "scenes/quads/povray.exr", prim=ref["prim"], obj=ref["obj"])  # no Z
    manifest = json.loads((run / "manifest.json").read_text())
    renders = manifest["scenes"][0]["renders"]
    for r in renders:
        if r["backend"] == "povray":
            r["buffers"] = ["id"]
        if r["backend"] == "mitsuba":
            r["exr"] = "../../etc/passwd"
        if r["backend"] == "trace":
            r["exr"] = "scenes/quads/none.exr"
    (run / "manifest.json").write_text(json.dumps(manifest))
    assert compare.main(["--run", str(run), "--no-images"]) == 0
    res = _index(_strict_json(run / "results.json"))
    assert res[("quads", "povray", "Z")]["status"] == "skipped"
    assert res[("quads", "povray", "id")]["status"] == "pass"
    assert res[("quads", "mitsuba", "id")]["status"] == "error"
    assert "relative to the run folder" in res[("quads", "mitsuba", "id")]["reason"]
    assert res[("quads", "trace", "Z")]["status"] == "error"
    assert "none.exr" in res[("quads", "trace", "Z")]["reason"]


def test_object_id_mismatch_is_interior(tmp_path: Path) -> None:
    run, ref = build_run(tmp_path)
    bad = _copy(ref)
    x, y = PLAIN_PX
    bad["obj"][y, x] = 7
    _write_exr(run / "scenes/quads/trace.exr", bad)
    assert compare.main(["--run", str(run), "--no-images"]) == 0
    r = _index(_strict_json(run / "results.json"))[("quads", "trace", "id")]
    assert (r["edge_mismatches"], r["interior_mismatches"], r["status"]) == (0, 1, "fail")
    assert "id.object" in r["reason"]


def test_invalid_test_id_is_interior_even_on_an_edge(tmp_path: Path) -> None:
    run, ref = build_run(tmp_path)
    bad = _copy(ref)
    x, y = EDGE_PX
    bad["prim"][y, x] = 99  # names no triangle (the scene has 5)
    _write_exr(run / "scenes/quads/povray.exr", bad, {"depth_step": 1e-9})
    assert compare.main(["--run", str(run), "--no-images"]) == 0
    r = _index(_strict_json(run / "results.json"))[("quads", "povray", "id")]
    assert (r["edge_mismatches"], r["interior_mismatches"]) == (0, 1)
    assert "names no triangle" in r["reason"]


def test_harness_cli_dispatches_compare(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run, _ = build_run(tmp_path)
    assert harness_main(["compare", "--", "--run", str(run), "--no-images"]) == 0
    assert (run / "results.json").is_file()
    assert "entries:" in capsys.readouterr().out


# --------------------------------------------------------------------------- tolerance models


def _ctx(
    z: float, cos: float, info: dict[str, Any] | None = None, attrs: dict[str, Any] | None = None
) -> tolerance.DepthContext:
    return tolerance.DepthContext(np.array([z]), np.array([cos]), info or {}, attrs or {})


def test_relative_models_scale_with_grazing_angle_and_cap() -> None:
    m = precision.depth_model(registry.spec("mitsuba"), "mitsuba")

    def mitsuba(cos: float) -> float:
        ctx = tolerance.DepthContext(np.array([10.0]), np.array([cos]), {}, {}, ray_norm=np.array([1.0]))
        return float(m.depth(ctx)[0][0])

    # its f32 ray direction, (sqrt(3) + 6) u |d| Z, and Embree's f32 triangle at the origin, u |d| Z (no extent)
    ray = 2.0**-24 * (math.sqrt(3.0) + 6.0 + 1.0) * 10.0
    assert mitsuba(1.0) == pytest.approx(1e-4 + ray, rel=1e-12)
    assert mitsuba(0.1) == pytest.approx(1e-3 + ray / 0.1, rel=1e-12)
    # edge-on, without the triangle's depth span: each part at the fallback cap 1e-3 Z
    assert mitsuba(0.0) == pytest.approx(2.0 * 10.0 * tolerance.MAX_REL, rel=1e-12)
    with pytest.raises(
        tolerance.ToleranceError,
        match=r"^the Embree depth model needs each pixel ray's length \(DepthContext\.ray_norm\)$",
    ):
        m.depth(_ctx(10.0, 1.0))  # without the pixel's |d|, like Embree's
    # 1000 from the origin: the sensor's origin o = offset + 2 sqrt(3) u |eye| moves the hit (o / |cos|) and
    # is where Embree's triangle copy sits (u o more)
    far = tolerance.DepthContext(
        np.array([10.0]), np.array([1.0]), {}, {}, ray_norm=np.array([1.0]), origin_offset=1e-5, eye_norm=1000.0
    )
    o = 1e-5 + 2.0 * math.sqrt(3.0) * 2.0**-24 * 1000.0
    assert float(m.depth(far)[0][0]) == pytest.approx(1e-4 + o + ray + 2.0**-24 * o, rel=1e-12)
    embree = precision.depth_model(registry.spec("embree"), "embree")
    ctx = tolerance.DepthContext(np.array([10.0]), np.array([0.5]), {}, {}, ray_norm=np.array([1.5]))
    # the f32 direction (u |d| Z) and the triangle's f32 copy at the origin (u |d| Z, no extent given)
    assert embree.depth(ctx)[0][0] == pytest.approx(2e-4 + 2.0 * 2.0**-24 * 1.5 * 10.0 / 0.5, rel=1e-12)


def test_povray_depth_step_sources() -> None:
    m = precision.depth_model(registry.spec("povray"), "povray")
    # Without a hit point, |X| defaults to Z = 2: plane 2^-24 * 3 * 2, storage 2^-23 * 2.
    rest = 10 * 2.0**-24
    tol, text = m.depth(_ctx(2.0, 1.0, attrs={"depth_step": 1e-7}))
    assert tol[0] == pytest.approx(1e-7 + rest) and "from the render" in text
    tol, text = m.depth(_ctx(2.0, 1.0, info={"depth_range": 65536.0 * 65535.0}))
    assert tol[0] == pytest.approx(1.0 + rest) and "depth_range" in text
    tol, text = m.depth(_ctx(2.0, 1.0))
    assert tol[0] == pytest.approx(2.0 * (1 + 2**-6) / 2**32 + rest, rel=1e-3) and "estimated" in text


def test_povray_depth_grows_with_distance_from_the_origin_not_depth() -> None:
    m = precision.depth_model(registry.spec("povray"), "povray")
    near = tolerance.DepthContext(
        np.array([2.0]), np.array([1.0]), {}, {"depth_step": 0.0}, point_norm=np.array([3.0]), extent=np.array([0.5])
    )
    far = tolerance.DepthContext(
        np.array([2.0]), np.array([1.0]), {}, {"depth_step": 0.0}, point_norm=np.array([2e4]), extent=np.array([0.5])
    )
    t_near, t_far = m.depth(near)[0][0], m.depth(far)[0][0]
    assert t_near == pytest.approx(2.0**-24 * (9.0 + 0.5) + 2.0**-23 * 2.0)
    assert t_far == pytest.approx(2.0**-24 * (6e4 + 0.5) + 2.0**-23 * 2.0)
    # A bias of 16 f32 ulps of Z is beyond the bound near the origin.
    assert 16 * 2.0**-23 * 2.0 > t_near


def test_edge_tolerances() -> None:
    assert precision.depth_model(registry.spec("trace"), "trace").edge_px == 0.0
    assert precision.depth_model(registry.spec("povray"), "povray").edge_px == 1e-3
    assert precision.depth_model(registry.spec("pyrender"), "pyrender").edge_px == pytest.approx(math.sqrt(2) / 512)
    assert precision.depth_model(registry.spec("mitsuba"), "mitsuba").edge_px == 1e-4
    # Embree's constant is 0: every term is derived, per pixel, per edge and per triangle (test_embree_edge.py)
    robust = precision.depth_model(registry.spec("embree_robust"), "embree_robust")
    assert robust.edge_px == 0.0 and robust.edge_products is not None and robust.plane_move is not None
    unknown = precision.depth_model(registry.spec("zzz"), "zzz")
    assert unknown.edge_px == 0.0 and not unknown.known
    assert unknown.depth(_ctx(1.0, 1.0))[0][0] == 0.0


# --------------------------------------------------------------------------- normals, scene errors


def _normals_of(scene: resolved.ResolvedScene, prim: np.ndarray) -> np.ndarray:
    t = scene.triangles.astype(np.float64)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    n /= np.linalg.norm(n, axis=1)[:, None]
    out = np.zeros(prim.shape + (3,), dtype=np.float32)
    hit = prim != BG
    out[hit] = n[prim[hit].astype(np.int64)]
    return out


def _normals_run(
    tmp_path: Path, flip_reference: bool, tilt_test: float, zero_test: bool = False
) -> dict[tuple[str, str, str], Any]:
    run = tmp_path / "run"
    sdir = write_scene(run / "scenes/quads/resolved", TRIS, OIDS, vfov_deg=90.0, width=32, height=32, name="quads")
    scene, ref = _ref(sdir)
    n_ref = _normals_of(scene, ref["prim"])
    n_test = n_ref.copy()
    if flip_reference:
        n_ref = -n_ref
    x, y = PLAIN_PX
    n_test[y, x] = (n_test[y, x] + np.array([tilt_test, 0, 0], dtype=np.float32)).astype(np.float32)
    n_test[y, x] /= np.linalg.norm(n_test[y, x])
    if zero_test:
        n_test[ref["prim"] != BG] = 0.0
    s = run / "scenes/quads"
    exrbuf.write_buffers(s / "raster.exr", Z=ref["Z"], prim=ref["prim"], obj=ref["obj"], N=n_ref)
    exrbuf.write_buffers(s / "mitsuba.exr", Z=ref["Z"], prim=ref["prim"], obj=ref["obj"], N=n_test)
    renders = [
        _ok("raster", "scenes/quads/raster.exr", buffers=["Z", "id", "N"]),
        _ok("mitsuba", "scenes/quads/mitsuba.exr", buffers=["Z", "id", "N"]),
    ]
    write_manifest(run, [manifest_scene("quads", renders, ["depth", "ids", "normals"])])
    assert compare.main(["--run", str(run), "--no-images"]) == 0
    return _index(_strict_json(run / "results.json"))


def test_normals_are_judged_against_the_winding_for_every_backend_and_the_reference(tmp_path: Path) -> None:
    res = _normals_run(tmp_path / "a", flip_reference=False, tilt_test=0.0)
    for backend in ("raster", "mitsuba"):
        e = res[("quads", backend, "N")]
        assert e["status"] == "pass", e
        assert e["compared_pixels"] == 400 and e["max_angle_rad"] < 1e-6  # every hit pixel
    # The reference's normals negated: every one of its pixels fails, and says "flipped".
    res = _normals_run(tmp_path / "b", flip_reference=True, tilt_test=0.0)
    e = res[("quads", "raster", "N")]
    assert e["status"] == "fail" and e["interior_mismatches"] == 400 and "facing the other way" in e["reason"]
    # A test normal off by 1e-4 rad at one pixel fails there (f32 bound: ~1e-6 rad for a right triangle).
    res = _normals_run(tmp_path / "c", flip_reference=False, tilt_test=1e-4)
    e = res[("quads", "mitsuba", "N")]
    assert e["status"] == "fail" and e["interior_mismatches"] == 1


def test_a_zero_normal_fails_and_is_not_called_reversed(tmp_path: Path) -> None:
    # Mitsuba's normal of a huge triangle is the zero vector (scenes/found/mitsuba_zero_normal.toml):
    # every pixel fails, none reads as facing the other way, and the reason says zero.
    res = _normals_run(tmp_path, flip_reference=False, tilt_test=0.0, zero_test=True)
    e = res[("quads", "mitsuba", "N")]
    assert e["status"] == "fail" and e["interior_mismatches"] == 400
    assert "0 of them facing the other way, 400 zero or not finite" in e["reason"], e["reason"]
    assert "zero vector" in e["explanations"][0]["why"]
    ref = res[("quads", "raster", "N")]
    assert ref["status"] == "pass" and "zero" not in ref["reason"]


def test_a_scene_that_failed_to_load_is_an_error_entry(tmp_path: Path) -> None:
    run = tmp_path / "run"
    run.mkdir()
    message = "cannot load scene: broken.toml: camera.vfov: must be in (0, 180)"
    write_manifest(run, [manifest_scene("broken", [{"backend": "raster", "status": "error", "message": message}], [])])
    assert compare.main(["--run", str(run), "--no-images"]) == 0
    res = _index(_strict_json(run / "results.json"))
    assert list(res) == [("broken", "raster", "scene")]
    e = res[("broken", "raster", "scene")]
    assert e["status"] == "error" and "camera.vfov" in e["reason"]


def test_scenes_compared_in_processes_give_the_same_results(tmp_path: Path) -> None:
    # Two scenes: `--jobs 2` compares them in two spawned processes; the document, the
    # unused-expectation list included, must be what one process writes.
    run, _ = build_run(tmp_path)
    exps = tmp_path / "exps.toml"
    exps.write_text(
        '[[expect]]\nscene = "quads"\nbackend = "povray"\nbuffer = "id"\nstatus = "expected_fail"\n'
        'reason = "known"\n\n[[expect]]\nscene = "nowhere"\nbackend = "povray"\nbuffer = "id"\n'
        'status = "expected_fail"\nreason = "never matched"\n'
    )
    docs = []
    for jobs in ("1", "2"):
        assert compare.main(["--run", str(run), "--no-images", "--expectations", str(exps), "--jobs", jobs]) == 0
        doc = _strict_json(run / "results.json")
        docs.append(doc)
    assert len({r["scene"] for r in docs[0]["results"]}) >= 2
    assert docs[0] == docs[1]
    assert [u["scene"] for u in docs[1]["unused_expectations"]] == ["nowhere"]


def test_the_verdict_table_puts_failures_first_and_escapes_reasons() -> None:
    from rendiff_harness.contract import results

    def row(scene: str, status: str, reason: str = "") -> dict[str, Any]:
        return {"scene": scene, "backend": "b", "buffer": "id", "status": status, "reason": reason}

    # 86 ASCII characters, then multi-byte ones across the cut; a bell and an escape.
    long = "x" * 86 + "ééé✓✓✓ and more text to pass ninety characters"
    table = results.format_table(
        [row("a", "pass"), row("b", "skipped", "why"), row("c", "fail", long), row("d", "error", "bell\x07 esc\x1b")]
    )
    lines = table.splitlines()
    assert [line.split()[0] for line in lines[1:5]] == ["c", "d", "b", "a"]
    note = lines[1].split("  ")[-1]
    assert note.endswith("...") and len(note) == 90 and "é" in note
    assert lines[2].endswith("bell\\x07 esc\\x1b")
    assert lines[-1] == "4 entries: error 1, fail 1, pass 1, skipped 1"
