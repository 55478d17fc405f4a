"""The renderers' own speed/quality settings on `render`: validated, refused by backends
without them, reaching the renderer's command line, changing the output, and never the
ID/depth passes (an ID is not averageable)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import backend_cases as cases
from rendiff_harness import __main__ as cli
from rendiff_harness.contract import exrbuf
from rendiff_harness.renderers.errors import BackendError
from rendiff_harness.renderers.mitsuba import backend as mb
from rendiff_harness.renderers.povray import backend as povray
from rendiff_harness.renderers.pyrender import backend as pr

needs_povray = pytest.mark.skipif(povray.unavailable_reason() is not None, reason=f"{povray.unavailable_reason()}")
needs_mitsuba = pytest.mark.skipif(mb.unavailable_reason() is not None, reason=f"{mb.unavailable_reason()}")
needs_pyrender = pytest.mark.skipif(pr.unavailable_reason() is not None, reason=f"{pr.unavailable_reason()}")


def _render(tmp_path: Path, backend: str, scene: Path, *extra: str, name: str = "o.exr") -> tuple[int, Path]:
    out = tmp_path / name
    return cli.main(["render", "--backend", backend, "--scene", str(scene), "--out", str(out), *extra]), out


def _refused(tmp_path: Path, capsys: pytest.CaptureFixture[str], backend: str, scene: Path, *extra: str) -> str:
    """`_render` that must fail as bad input (exit 1, no EXR written): its stderr."""
    rc, out = _render(tmp_path, backend, scene, *extra)
    assert rc == cli.EXIT_ERROR
    assert not out.exists()
    return capsys.readouterr().err


@pytest.mark.parametrize(
    "flag, value",
    [
        ("--aa-method", "3"),
        ("--aa-method", "0"),
        ("--aa-method", "x"),
        ("--aa-threshold", "-0.1"),
        ("--aa-threshold", "3.5"),
        ("--aa-threshold", "nan"),
        ("--aa-depth", "0"),
        ("--aa-depth", "10"),
        ("--aa-depth", "2.5"),
        ("--quality", "-1"),
        ("--quality", "12"),
        ("--max-depth", "0"),
        ("--max-depth", "-2"),
        ("--max-depth", "two"),
        ("--variant", "cuda_ad_rgb"),
    ],
)
def test_invalid_values_are_rejected_with_the_option_named(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], flag: str, value: str
) -> None:
    scene = cases.facing_quad(tmp_path / "s", 2.0, width=8, height=6)
    with pytest.raises(SystemExit) as exc:
        _render(tmp_path, "povray", scene, flag, value)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert flag in err and value in err
    assert not (tmp_path / "o.exr").exists()


@pytest.mark.parametrize(
    "backend, extra, named",
    [
        ("mitsuba", ["--aa-method", "1"], "--aa-method"),
        ("pyrender", ["--quality", "4"], "--quality"),
        ("povray", ["--max-depth", "3"], "--max-depth"),
        ("povray", ["--variant", "scalar_rgb"], "--variant"),
        ("pyrender", ["--variant", "llvm_ad_rgb"], "--variant"),
    ],
)
def test_a_backend_refuses_a_setting_it_does_not_have(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], backend: str, extra: list[str], named: str
) -> None:
    scene = cases.facing_quad(tmp_path / "s", 2.0, width=8, height=6)
    err = _refused(tmp_path, capsys, backend, scene, *extra)
    assert f"{backend}: {named} is not a setting of this backend" in err


def test_povray_settings_validate_and_format() -> None:
    assert povray.Settings().flags() == ["-A"]
    assert povray.Settings(quality=2).flags() == ["-A", "+Q2"]
    assert povray.Settings(1).flags() == ["+A0.3", "+AM1", "+R3", "-J"]
    assert povray.Settings(2, 0.05, 4, 9).flags() == ["+A0.05", "+AM2", "+R4", "-J", "+Q9"]
    with pytest.raises(BackendError, match="needs an antialiasing method"):
        povray.Settings(aa_threshold=0.1)
    with pytest.raises(BackendError, match="method must be 1 or 2"):
        povray.Settings(aa_method=3)
    with pytest.raises(BackendError, match="quality must be an integer in 0..11"):
        povray.Settings(quality=12)


@needs_povray
def test_povray_threshold_without_method_fails_clearly(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scene = cases.facing_quad(tmp_path / "s", 2.0, width=8, height=6)
    assert "needs an antialiasing method" in _refused(tmp_path, capsys, "povray", scene, "--aa-threshold", "0.1")


@needs_povray
def test_povray_antialiasing_reaches_the_radiance_passes_only(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    scene = cases.occluded_plane(tmp_path / "s", "shadows", width=48, height=36)
    rc, plain = _render(tmp_path, "povray", scene, name="plain.exr")
    assert rc == 0, capsys.readouterr().err
    capsys.readouterr()
    commands: dict[str, list[str]] = {}
    real = povray.povray_command

    def spy(
        binary: str, width: int, height: int, sdl: str, png: str, settings: povray.Settings = povray.EXACT
    ) -> list[str]:
        cmd = real(binary, width, height, sdl, png, settings)
        commands[Path(sdl).stem] = cmd
        return cmd

    monkeypatch.setattr(povray, "povray_command", spy)
    rc, aa = _render(
        tmp_path, "povray", scene, "--aa-method", "2", "--aa-threshold", "0", "--aa-depth", "2", name="aa.exr"
    )
    assert rc == 0, capsys.readouterr().err
    msg = json.loads(capsys.readouterr().out)
    assert msg["info"]["radiance_flags"] == ["+A0.0", "+AM2", "+R2", "-J"]
    commands.pop("<scene>", None)  # the command recorded in the info dict, not run
    assert set(commands) == {"ids", "depth", "lit"}
    for stem in ("ids", "depth"):
        assert "-A" in commands[stem] and not any(f.startswith("+A") for f in commands[stem]), stem
    assert {"+A0.0", "+AM2", "+R2", "-J"} <= set(commands["lit"]) and "-A" not in commands["lit"]
    a, b = exrbuf.read_buffers(plain), exrbuf.read_buffers(aa)
    assert np.array_equal(a["id.prim"], b["id.prim"]) and np.array_equal(a["Z"].view(np.uint32), b["Z"].view(np.uint32))
    changed = np.abs(a["RGB"] - b["RGB"]).max(axis=2) > 1e-3
    assert changed.sum() >= 10, "antialiasing must change pixels along the occluder's edges and its shadow"
    assert exrbuf.read_attrs(aa)["radiance_flags"] == "+A0.0 +AM2 +R2 -J"
    assert "radiance_flags" not in exrbuf.read_attrs(plain), "the default output is unchanged"


@needs_povray
def test_povray_quality_below_4_drops_shadows(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scene = cases.occluded_plane(tmp_path / "s", "shadows", width=48, height=36)
    runs = {}
    for q in ("2", "4"):
        rc, out = _render(tmp_path, "povray", scene, "--quality", q, name=f"q{q}.exr")
        assert rc == 0, capsys.readouterr().err
        assert json.loads(capsys.readouterr().out)["info"]["radiance"]["flags"] == ["-A", f"+Q{q}"]
        runs[q] = exrbuf.read_buffers(out)
    hit = runs["4"]["id.prim"] != 0xFFFFFFFF
    dark4 = (runs["4"]["RGB"].max(axis=2) == 0) & hit
    assert dark4.sum() > 30, "the fixture casts a shadow at +Q4"
    assert (runs["2"]["RGB"][dark4].max(axis=1) > 0).all(), "+Q2 computes no shadows"
    assert np.array_equal(runs["2"]["id.prim"], runs["4"]["id.prim"])


@needs_mitsuba
def test_mitsuba_max_depth_reaches_the_integrator(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scene = cases.cornell(tmp_path / "s", width=8, height=8)
    rc, out = _render(tmp_path, "mitsuba", scene, "--spp", "8", "--max-depth", "2")
    assert rc == 0, capsys.readouterr().err
    info = json.loads(capsys.readouterr().out)["info"]["radiance"]
    assert info["max_depth"] == 2 and info["scene_max_depth"] == -1
    assert exrbuf.read_attrs(out)["max_depth"] == 2
    rc, full = _render(tmp_path, "mitsuba", scene, "--spp", "8", name="full.exr")
    assert rc == 0
    short, long = exrbuf.read_buffers(out)["RGB"], exrbuf.read_buffers(full)["RGB"]
    # max_depth 2 keeps direct light only: the walls get no interreflection, so less light overall.
    assert float(short.sum()) < 0.9 * float(long.sum())


@needs_mitsuba
def test_mitsuba_max_depth_is_refused_for_local_shading(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scene = cases.lit_plane(
        tmp_path / "s",
        [{"kind": "point", "position": [0, 0, 2], "intensity": [1, 1, 1]}],
        requires=("depth", "ids", "lambert", "point_light", "shadows", "two_sided"),
        width=8,
        height=6,
    )
    assert "max_depth applies to path-traced" in _refused(tmp_path, capsys, "mitsuba", scene, "--max-depth", "3")


@needs_mitsuba
def test_mitsuba_llvm_variant_without_libllvm_fails_clearly(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(mb.VARIANT_ENV, mb.DEFAULT_VARIANT)  # restored afterwards: --variant sets it
    monkeypatch.delenv(mb.LLVM_PATH_ENV, raising=False)
    monkeypatch.setattr(mb, "DEBIAN_LIBLLVM19", tmp_path / "no-libllvm19.so")  # as on a machine without it
    mb._probe.cache_clear()
    try:
        scene = cases.cornell(tmp_path / "s", width=8, height=8)
        err = _refused(tmp_path, capsys, "mitsuba", scene, "--variant", "llvm_ad_rgb", "--spp", "4")
    finally:
        mb._probe.cache_clear()
    assert mb.LLVM_PATH_ENV in err


@needs_pyrender
def test_pyrender_has_no_msaa_on_osmesa() -> None:
    """Measured, not assumed: no sample-count parameter, no MSAA FBO, a single-sampled buffer."""
    m = pr.msaa_support()
    assert m["pyrender_sample_parameters"] == []
    assert m["pyrender_uses_msaa_fbo"] is False and m["gl_samples_default_buffer"] == 0
    assert m["gl_max_samples"] >= 0
