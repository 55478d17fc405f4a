"""compare.py's RGB buffer end to end: deterministic tolerances, the statistical gate, cached references."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import backend_cases as cases
from rendiff_harness import compare
from rendiff_harness.contract import exrbuf, resolved, vocab
from rendiff_harness.judge import expectations
from rendiff_harness.renderers.mitsuba import backend as mb
from rendiff_harness.renderers.mitsuba import reference as mitsuba_reference
from rendiff_harness.renderers.pyrender import backend as pb

LIGHTS = [{"kind": "point", "position": [0.3, 0.2, 1.5], "intensity": [10.0, 5.0, 2.0]}]
LIT_REQ = ("depth", "ids", "lambert", "point_light", "shadowless", "two_sided")


def _exr(
    path: Path,
    rgb: np.ndarray | None,
    z: np.ndarray,
    prim: np.ndarray,
    var: np.ndarray | None = None,
    attrs: dict[str, Any] | None = None,
) -> str:
    path.parent.mkdir(parents=True, exist_ok=True)
    exrbuf.write_buffers(path, Z=z, prim=prim, obj=np.zeros_like(prim), RGB=rgb, var=var, attrs=attrs)
    return path.as_posix()


def _ok(backend: str, exr: str, buffers: tuple[str, ...] = ("Z", "id", "RGB"), **kw: Any) -> dict[str, Any]:
    r = {
        "backend": backend,
        "status": "ok",
        "exr": exr,
        "time_s": 0.1,
        "version": f"{backend} 1",
        "command": f"render {backend}",
        "buffers": list(buffers),
        "info": {},
    }
    r.update(kw)
    return r


def _lit_scene(run: Path) -> tuple[resolved.ResolvedScene, np.ndarray, np.ndarray, np.ndarray]:
    d = cases.lit_plane(run / "scenes/lit/resolved", LIGHTS, requires=LIT_REQ)
    scene = resolved.load(d)
    want = cases.closed_form_plane(scene)
    z = cases.plane_depth(scene, np.zeros(3), np.array([0.0, 0.0, 1.0])).astype(np.float32)
    prim = np.zeros(z.shape, dtype=np.uint32)
    return scene, want, z, prim


def _povray_like(want: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
    s = float(want.max()) * (1 + 2**-6)
    codes = np.rint(want / s * 65535)
    return (codes * (s / 65535)).astype(np.float32), {
        "rgb_scale": s,
        "emission_scale": 0.0,
        "rgb_encoding": "png16-linear",
    }


def _run_dir(tmp_path: Path) -> Path:
    run = tmp_path / "run"
    run.mkdir()
    return run


def _manifest(run: Path, scenes: list[dict[str, Any]]) -> None:
    doc = {
        "format": "rendiff-manifest/1",
        "reference": "raster",
        "created": "x",
        "rendiff_version": "0",
        "scenes": scenes,
    }
    (run / "manifest.json").write_text(json.dumps(doc))


def _index(doc: dict[str, Any]) -> dict[tuple[str, str, str], dict[str, Any]]:
    return {(r["scene"], r["backend"], r["buffer"]): r for r in doc["results"]}


def test_deterministic_rgb_entries(tmp_path: Path) -> None:
    run = _run_dir(tmp_path)
    scene, want, z, prim = _lit_scene(run)
    s = run / "scenes/lit"
    rel = lambda p: Path(p).relative_to(run).as_posix()  # noqa: E731
    ref32 = want.astype(np.float32)
    renders = [_ok("raster", rel(_exr(s / "raster.exr", ref32, z, prim, attrs={"integrator": "direct", "spp": "1"})))]
    pov, pattrs = _povray_like(want)
    renders.append(_ok("povray", rel(_exr(s / "povray.exr", pov, z, prim, attrs=pattrs))))
    scale = float(want.max()) * 1.02
    pyr = pb.decode_rgb8(pb.encode_rgb8(want, scale).astype(np.uint8), scale).astype(np.float32)
    renders.append(
        _ok(
            "pyrender",
            rel(_exr(s / "pyrender.exr", pyr, z, prim, attrs={"rgb_scale": scale, "znear": 1.0, "zfar": 50.0})),
        )
    )
    mit = (want * (1 + 3e-6)).astype(np.float32)
    mit[5, 7, 1] *= 1.01  # one pixel beyond 5e-5 relative
    renders.append(_ok("mitsuba", rel(_exr(s / "mitsuba.exr", mit, z, prim))))
    renders.append(_ok("nolit", rel(_exr(s / "nolit.exr", None, z, prim)), buffers=("Z", "id")))
    renders.append({"backend": "embree", "status": "skipped", "reason": "missing features: lambert"})
    _manifest(run, [{"scene": "lit", "resolved": "scenes/lit/resolved", "requires": list(LIT_REQ), "renders": renders}])
    res = _index(compare.run_compare(run, None))
    p = res[("lit", "povray", "RGB")]
    assert p["status"] == "pass" and p["mode"] == "deterministic" and p["failing_pixels"] == 0
    assert "half a code" in p["tolerance"] and p["flip_mean"] is not None and p["min_p"] is None
    assert p["images"]["heat"] == "scenes/lit/diff/povray.RGB.png" and (run / p["images"]["heat"]).is_file()
    assert res[("lit", "pyrender", "RGB")]["status"] == "pass"
    m = res[("lit", "mitsuba", "RGB")]
    assert m["status"] == "fail" and m["interior_mismatches"] == 1 and m["edge_mismatches"] == 0
    assert "(7,5)" in m["reason"]
    n = res[("lit", "nolit", "RGB")]
    assert n["status"] == "skipped" and n["failing_pixels"] is None and "does not produce RGB" in n["reason"]
    e = res[("lit", "embree", "RGB")]
    assert e["status"] == "skipped" and e["min_p"] is None and e["pixels"] is None
    # expectations accept buffer "RGB"
    exp = tmp_path / "exp.toml"
    exp.write_text(
        '[[expect]]\nscene = "lit"\nbackend = "mitsuba"\nbuffer = "RGB"\ninterior_mismatches = [1, 1]\n'
        'status = "expected_fail"\nreason = "test"\n'
    )
    res2 = _index(compare.run_compare(run, exp))
    assert res2[("lit", "mitsuba", "RGB")]["status"] == "expected_fail"


def test_unshaded_scenes_get_no_rgb_entries(tmp_path: Path) -> None:
    run = _run_dir(tmp_path)
    d = cases.lit_plane(run / "scenes/plain/resolved", [], requires=("depth", "ids"))
    scene = resolved.load(d)
    z = cases.plane_depth(scene, np.zeros(3), np.array([0.0, 0.0, 1.0])).astype(np.float32)
    prim = np.zeros(z.shape, dtype=np.uint32)
    exr = _exr(run / "scenes/plain/raster.exr", None, z, prim)
    renders = [
        _ok("raster", Path(exr).relative_to(run).as_posix(), buffers=("Z", "id")),
        {"backend": "povray", "status": "skipped", "reason": "x"},
    ]
    _manifest(
        run, [{"scene": "plain", "resolved": "scenes/plain/resolved", "requires": ["depth", "ids"], "renders": renders}]
    )
    doc = compare.run_compare(run, None)
    assert {r["buffer"] for r in doc["results"]} == {"id", "Z"}


def _noisy(truth: np.ndarray, rel_sigma: float, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    sigma = rel_sigma * truth + 1e-3
    mean = truth + rng.standard_normal(truth.shape) * sigma / np.sqrt(n)
    var = sigma**2 * rng.chisquare(n - 1, truth.shape) / (n - 1) / n
    return mean.astype(np.float32), var.astype(np.float32)


def test_statistical_rgb_entries(tmp_path: Path) -> None:
    run = _run_dir(tmp_path)
    req = ("depth", "ids", "emission", "lambert", "area_light", "global_illumination", "one_sided")
    d = cases.lit_plane(run / "scenes/gi/resolved", [], requires=req, emission=(1.0, 1.0, 1.0))
    scene = resolved.load(d)
    z = cases.plane_depth(scene, np.zeros(3), np.array([0.0, 0.0, 1.0])).astype(np.float32)
    prim = np.zeros(z.shape, dtype=np.uint32)
    rng = np.random.default_rng(4)
    y, x = np.mgrid[0 : z.shape[0], 0 : z.shape[1]]
    truth = np.stack([0.5 + x / 100.0, 0.3 + y / 100.0, 0.2 + 0 * x], axis=-1)
    s = run / "scenes/gi"
    rel = lambda p: Path(p).relative_to(run).as_posix()  # noqa: E731
    ref_m, ref_v = _noisy(truth, 0.3, 256, rng)
    renders = [_ok("raster", rel(_exr(s / "raster.exr", ref_m, z, prim, ref_v, {"spp": "256", "integrator": "path"})))]
    a_m, a_v = _noisy(truth, 0.3, 256, rng)
    renders.append(
        _ok(
            "mitsuba",
            rel(_exr(s / "mitsuba.exr", a_m, z, prim, a_v, {"spp": 256, "var_samples": 64, "integrator": "path"})),
        )
    )
    b_m, b_v = _noisy(truth * 1.1, 0.3, 256, rng)  # 10% too bright
    renders.append(_ok("newthing", rel(_exr(s / "newthing.exr", b_m, z, prim, b_v, {"spp": 256}))))
    renders.append(_ok("novar", rel(_exr(s / "novar.exr", truth.astype(np.float32), z, prim))))
    _manifest(run, [{"scene": "gi", "resolved": "scenes/gi/resolved", "requires": list(req), "renders": renders}])
    res = _index(compare.run_compare(run, None))
    m = res[("gi", "mitsuba", "RGB")]
    assert m["status"] == "pass" and m["mode"] == "statistical" and m["alpha"] == 0.01
    assert m["cluster_failures"] == 0 and 0 < m["min_p"] <= 1 and "Sidak" in m["tolerance"]
    assert "nu_test 63" in m["tolerance"] and "spp ref 256, test 256" in m["tolerance"]
    b = res[("gi", "newthing", "RGB")]
    assert b["status"] == "fail" and b["interior_mismatches"] > 100 and b["cluster_failures"] > 0
    assert b["edge_mismatches"] == 0 and "cluster test" in b["reason"]
    nv = res[("gi", "novar", "RGB")]
    assert nv["mode"] == "statistical" and "no var channels" in nv["reason"]


# --------------------------------------------------------------------------- cached references


@pytest.mark.skipif(mb.unavailable_reason() is not None, reason=f"{mb.unavailable_reason()}")
def test_cached_reference_entries(tmp_path: Path) -> None:
    run = _run_dir(tmp_path)
    sd = cases.cornell(run / "scenes/box/resolved", width=16, height=16)
    scene = resolved.load(sd)
    refs = tmp_path / "refs"
    refs.mkdir()
    mitsuba_reference.generate(sd, refs / "box.exr", spp=256, seed=1)
    rgb, var, info = mb.render_radiance(scene, spp=64, seed=2)  # stands in for the core's path tracer
    aov, _ = mb.render_arrays(scene)
    exr = _exr(
        run / "scenes/box/raster.exr",
        rgb.astype(np.float32),
        aov["Z"],
        aov["prim"],
        var.astype(np.float32),
        {"spp": "64", "integrator": "path"},
    )
    renders = [_ok("raster", Path(exr).relative_to(run).as_posix())]
    _manifest(
        run,
        [{"scene": "box", "resolved": "scenes/box/resolved", "requires": sorted(scene.requires), "renders": renders}],
    )
    res = _index(compare.run_compare(run, None, references_dir=refs))
    e = res[("box", vocab.CACHED_REFERENCE_BACKEND, "RGB")]
    assert e["status"] == "pass" and e["mode"] == "statistical" and e["version"].startswith("mitsuba 3.9.1")
    assert "python -m rendiff_harness reference" in e["command"]
    # without --references: no such entry
    assert ("box", vocab.CACHED_REFERENCE_BACKEND, "RGB") not in _index(compare.run_compare(run, None))
    # stale: the run's scene changed
    meta = json.loads((sd / "scene.json").read_text())
    meta["materials"][3]["emission"] = [18.0, 12.0, 4.0]
    (sd / "scene.json").write_text(json.dumps(meta))
    e = _index(compare.run_compare(run, None, references_dir=refs))[("box", vocab.CACHED_REFERENCE_BACKEND, "RGB")]
    assert (
        e["status"] == "error"
        and "reference is stale: regenerate with python -m rendiff_harness reference" in e["reason"]
    )
    assert e["failing_pixels"] is None
    # missing
    shutil.rmtree(refs)
    refs.mkdir()
    e = _index(compare.run_compare(run, None, references_dir=refs))[("box", vocab.CACHED_REFERENCE_BACKEND, "RGB")]
    assert e["status"] == "error" and "cached reference missing: generate it with" in e["reason"]


def test_expectations_accept_rgb_buffer(tmp_path: Path) -> None:
    p = tmp_path / "e.toml"
    p.write_text(
        '[[expect]]\nscene = "*"\nbackend = "pyrender"\nbuffer = "RGB"\nstatus = "expected_fail"\nreason = "r"\n'
    )
    assert expectations.load(p).lookup("s", "pyrender", "RGB") is not None
    p.write_text(
        '[[expect]]\nscene = "*"\nbackend = "pyrender"\nbuffer = "rgb"\nstatus = "expected_fail"\nreason = "r"\n'
    )
    with pytest.raises(expectations.ExpectationsError, match="RGB"):
        expectations.load(p)
