"""The CLI passes --spp/--seed to Monte Carlo backends only, and `info` lists the radiance features."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

import backend_cases as cases
from rendiff_harness import __main__ as cli
from rendiff_harness.contract import exrbuf
from rendiff_harness.renderers import registry
from rendiff_harness.renderers.mitsuba import backend as mb
from rendiff_harness.renderers.povray import backend as povray


def test_info_lists_radiance_features(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["info", "--json"]) == 0
    rows = {r["name"]: r for r in json.loads(capsys.readouterr().out)["backends"]}
    assert "RGB" in rows["povray"]["buffers"] and "shadowless" in rows["povray"]["features"]
    assert "global_illumination" in rows["mitsuba"]["features"] and "shadowless" not in rows["mitsuba"]["features"]
    assert "shadows" not in rows["pyrender"]["features"] and "lambert" in rows["pyrender"]["features"]


def test_options_reach_only_backends_that_accept_them(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    seen: dict[str, object] = {}

    def fake_render(scene, out_exr, workdir, timeout_s):  # type: ignore[no-untyped-def]  # no spp/seed
        seen["called"] = True
        return {}

    loaded = registry.load("povray")
    assert loaded.spec is not None
    backend = dataclasses.replace(loaded, spec=dataclasses.replace(loaded.spec, render=fake_render))
    backend.render(None, tmp_path / "x.exr", tmp_path, 1.0, spp=16, seed=3)  # type: ignore[arg-type]
    assert seen == {"called": True}


@pytest.mark.skipif(mb.unavailable_reason() is not None, reason=f"{mb.unavailable_reason()}")
def test_render_cli_spp_and_seed_for_path_tracing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    d = cases.cornell(tmp_path / "s", width=8, height=8)
    out = tmp_path / "m.exr"
    rc = cli.main(
        ["render", "--backend", "mitsuba", "--scene", str(d), "--out", str(out), "--spp", "16", "--seed", "2"]
    )
    assert rc == 0, capsys.readouterr().err
    msg = json.loads(capsys.readouterr().out)
    assert msg["status"] == "ok" and msg["info"]["radiance"]["spp"] == 16
    attrs = exrbuf.read_attrs(out)
    assert attrs["spp"] == 16 and attrs["seed"] == 2 and attrs["integrator"] == "path" and attrs["passes"] == 16
    assert set(exrbuf.read_buffers(out)) >= {"RGB", "var", "Z", "id.prim"}


@pytest.mark.skipif(povray.unavailable_reason() is not None, reason=f"{povray.unavailable_reason()}")
def test_render_cli_povray_ignores_spp(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    d = cases.lit_plane(
        tmp_path / "s", [], requires=("depth", "ids", "emission", "two_sided"), emission=(1, 2, 3), width=8, height=6
    )
    out = tmp_path / "p.exr"
    rc = cli.main(["render", "--backend", "povray", "--scene", str(d), "--out", str(out), "--spp", "16"])
    assert rc == 0, capsys.readouterr().err
    rgb = exrbuf.read_buffers(out)["RGB"]
    assert abs(float(rgb[..., 2].max()) - 3.0) < 3.0 * 2 / 65535
