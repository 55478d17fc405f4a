"""Cached Mitsuba references: generated with provenance, refused loudly when missing, stale or corrupt."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import backend_cases as cases
import fixtures
from rendiff_harness import __main__ as cli
from rendiff_harness.contract import exrbuf, references, resolved
from rendiff_harness.judge import radiance
from rendiff_harness.renderers.mitsuba import backend as mb

REPO = Path(__file__).resolve().parents[2]
needs_mitsuba = pytest.mark.skipif(mb.unavailable_reason() is not None, reason=f"{mb.unavailable_reason()}")


@pytest.fixture(scope="module")
def generated(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A 16x16 Cornell fixture and its 32-spp reference, made through the CLI."""
    if mb.unavailable_reason() is not None:
        pytest.skip(f"mitsuba unavailable: {mb.unavailable_reason()}")
    root = tmp_path_factory.mktemp("refs")
    scene_dir = cases.cornell(root / "scene", width=16, height=16)
    out = root / "refs" / "cornell.exr"
    out.parent.mkdir()
    rc = cli.main(["reference", "--scene", str(scene_dir), "--spp", "32", "--seed", "5", "--out", str(out)])
    assert rc == 0
    return scene_dir, out


def _copy(generated: tuple[Path, Path], tmp_path: Path) -> tuple[Path, Path]:
    scene_dir, out = generated
    sd, rd = tmp_path / "scene", tmp_path / "refs"
    shutil.copytree(scene_dir, sd)
    shutil.copytree(out.parent, rd)
    return sd, rd / out.name


def test_generate_writes_exr_and_provenance(generated: tuple[Path, Path]) -> None:
    scene_dir, out = generated
    prov = json.loads(references.provenance_path(out).read_text())
    assert prov["format"] == references.FORMAT
    assert prov["scene_hash"] == references.scene_hash(scene_dir)
    assert prov["spp"] == 32 and prov["seed"] == 5 and prov["passes"] == 32 and prov["spp_per_pass"] == 1
    assert prov["mitsuba"] == "3.9.1" and prov["drjit"] == "1.5.0" and prov["variant"] == mb.selected_variant()
    assert prov["integrator"] == "path" and prov["max_depth"] == -1
    assert "--spp 32 --seed 5" in prov["command"] and prov["exr_sha256"] == references.file_sha256(out)
    attrs = exrbuf.read_attrs(out)
    assert attrs["spp"] == 32 and attrs["var_samples"] == 32 and attrs["scene_hash"] == prov["scene_hash"]
    cached = references.load(out, resolved.load(scene_dir))
    assert cached.rgb.shape == (16, 16, 3) and cached.var.shape == (16, 16, 3) and np.all(cached.var >= 0)
    assert cached.rgb.max() > 0.1  # the light and lit walls are there


def test_missing_reference_says_how_to_generate(generated: tuple[Path, Path], tmp_path: Path) -> None:
    scene_dir, _ = generated
    with pytest.raises(references.ReferenceError) as err:
        references.load(tmp_path / "nope.exr", resolved.load(scene_dir))
    msg = str(err.value)
    assert "cached reference missing: generate it with python -m rendiff_harness reference --scene" in msg
    assert str(tmp_path / "nope.exr") in msg


def test_missing_provenance_is_an_error(generated: tuple[Path, Path], tmp_path: Path) -> None:
    sd, exr = _copy(generated, tmp_path)
    references.provenance_path(exr).unlink()
    with pytest.raises(references.ReferenceError, match="provenance of the cached reference missing"):
        references.load(exr, resolved.load(sd))


def test_stale_hash_says_regenerate(generated: tuple[Path, Path], tmp_path: Path) -> None:
    sd, exr = _copy(generated, tmp_path)
    meta = json.loads((sd / "scene.json").read_text())
    meta["materials"][0]["albedo"] = [0.74, 0.73, 0.73]
    (sd / "scene.json").write_text(json.dumps(meta))
    with pytest.raises(references.ReferenceError) as err:
        references.load(exr, resolved.load(sd))
    assert "reference is stale" in str(err.value) and "regenerate with python -m rendiff_harness reference" in str(
        err.value
    )
    assert "--spp 32 --seed 5" in str(err.value)  # keeps the recorded settings


def test_triangles_change_is_stale_but_source_path_is_not(generated: tuple[Path, Path], tmp_path: Path) -> None:
    sd, exr = _copy(generated, tmp_path)
    meta = json.loads((sd / "scene.json").read_text())
    meta["source"] = "/elsewhere/scenes/cornell.toml"
    # Nor the vertex numbers' file, a function of triangles.f32: a reference made before
    # exports wrote it (as this fixture's scene has none) holds for an export with it.
    meta["files"] = {**meta["files"], "vertex_ids": "vertex_ids.u32"}
    (sd / "scene.json").write_text(json.dumps(meta, indent=4))  # another layout, same content
    references.load(exr, resolved.load(sd))
    tris = np.fromfile(sd / "triangles.f32", dtype="<f4")
    tris[0] = np.nextafter(tris[0], np.float32(np.inf))
    tris.tofile(sd / "triangles.f32")
    with pytest.raises(references.ReferenceError, match="reference is stale"):
        references.load(exr, resolved.load(sd))


def test_corrupt_exr_is_refused(generated: tuple[Path, Path], tmp_path: Path) -> None:
    sd, exr = _copy(generated, tmp_path)
    data = bytearray(exr.read_bytes())
    data[len(data) // 2] ^= 0xFF
    exr.write_bytes(bytes(data))
    with pytest.raises(references.ReferenceError, match="corrupt .*sha256 differs"):
        references.load(exr, resolved.load(sd))
    # garbage whose checksum was "updated" too: the EXR reader refuses it
    exr.write_bytes(b"not an exr at all")
    prov_path = references.provenance_path(exr)
    prov = json.loads(prov_path.read_text())
    prov["exr_sha256"] = references.file_sha256(exr)
    prov_path.write_text(json.dumps(prov))
    with pytest.raises(references.ReferenceError, match="cached reference corrupt"):
        references.load(exr, resolved.load(sd))


def test_corrupt_provenance_is_refused(generated: tuple[Path, Path], tmp_path: Path) -> None:
    sd, exr = _copy(generated, tmp_path)
    references.provenance_path(exr).write_text("{not json")
    with pytest.raises(references.ReferenceError, match="corrupt .*provenance unreadable"):
        references.load(exr, resolved.load(sd))
    references.provenance_path(exr).write_text(json.dumps({"format": "something/9"}))
    with pytest.raises(references.ReferenceError, match="corrupt .*format"):
        references.load(exr, resolved.load(sd))


@needs_mitsuba
def test_reference_refuses_scenes_without_global_illumination(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    d = cases.lit_plane(tmp_path / "s", [], requires=("depth", "ids", "emission", "two_sided"), emission=(1, 1, 1))
    rc = cli.main(["reference", "--scene", str(d), "--spp", "8", "--out", str(tmp_path / "x.exr")])
    assert rc == 2 and "global_illumination" in capsys.readouterr().err
    assert not (tmp_path / "x.exr").exists()


# --------------------------------------------------------------------------- the committed references


def _committed() -> list[Path]:
    return sorted((REPO / "tests" / "references").glob("*.exr"))


@pytest.mark.parametrize("exr", _committed(), ids=lambda p: p.stem)
def test_committed_references_are_intact(exr: Path) -> None:
    prov = json.loads(references.provenance_path(exr).read_text())
    assert prov["format"] == references.FORMAT and prov["exr_sha256"] == references.file_sha256(exr)
    bufs = exrbuf.read_buffers(exr, require=("RGB", "var"))
    assert bufs["RGB"].shape == (prov["height"], prov["width"], 3)
    assert prov["width"] * prov["height"] <= 64 * 64, "keep cached references small"


def _rendiff() -> Path | None:
    return fixtures.rendiff_binary()


@needs_mitsuba
@pytest.mark.skipif(_rendiff() is None, reason="rendiff binary not built (cargo build)")
@pytest.mark.parametrize("exr", _committed(), ids=lambda p: p.stem)
def test_committed_reference_matches_its_scene_and_mitsuba(exr: Path, tmp_path: Path) -> None:
    """The scene file still hashes to the reference's hash; a fresh 256-spp Mitsuba render passes
    the statistical gate against it, and the same render with every albedo 2% high (1024 spp) fails."""
    toml = REPO / "scenes" / f"{exr.stem}.toml"
    if not toml.is_file():
        pytest.skip(f"{toml} not found")
    out = tmp_path / "resolved"
    proc = subprocess.run([str(_rendiff()), "export", str(toml), "-o", str(out)], capture_output=True, text=True)
    # A failure, not a skip (a skip would hide a rendiff that refuses the scene).
    assert proc.returncode == 0, f"rendiff export failed (rebuild it?): {proc.stderr[-300:]}"
    scene = resolved.load(out)
    cached = references.load(exr, scene)  # raises "reference is stale: regenerate with ..." if the scene changed
    n_ref = radiance.samples_per_pixel(cached.attrs)

    def gate(sc: resolved.ResolvedScene, spp: int) -> radiance.RgbResult:
        rgb, var, info = mb.render_radiance(sc, spp=spp, seed=11)
        return radiance.compare_statistical(
            cached.rgb,
            cached.var,
            radiance.degrees_of_freedom(cached.attrs),
            rgb,
            var,
            info["var_samples"] - 1,
            ref_n=n_ref,
            test_n=info["spp"],
        )

    same = gate(scene, 256)
    print(f"{exr.stem}: 256-spp Mitsuba vs cached: interior {same.interior}, min p {same.min_p:.3g}, flip n/a")
    assert same.interior == 0, same.details
    meta = json.loads((out / "scene.json").read_text())
    for m in meta["materials"]:
        m["albedo"] = [1.02 * a for a in m["albedo"]]
    (out / "scene.json").write_text(json.dumps(meta))
    biased = gate(resolved.load(out), 1024)
    print(f"{exr.stem}: albedo +2% at 1024 spp: interior {biased.interior}, clusters {biased.cluster_failures}")
    assert biased.interior > 0
