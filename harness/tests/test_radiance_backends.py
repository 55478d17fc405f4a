"""Each backend's radiance unit mapping against closed forms (docs/radiance.md).

A large Lambert plane (backend_cases.lit_plane) under a point light
(L = rho/pi I cos/r^2), a directional light (L = rho/pi E cos), and emission only
(L = Le), with the closed form written out in backend_cases.closed_form_plane from the
exact plane depth at every pixel center. Every backend must match within its own
documented precision (tolerance.rgb_model); the measured worst errors are printed
(pytest -s) for the report.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import backend_cases as cases
from rendiff_harness.contract import exrbuf, lighting, resolved
from rendiff_harness.judge import precision, radiance
from rendiff_harness.renderers import registry
from rendiff_harness.renderers.errors import BackendError
from rendiff_harness.renderers.mitsuba import backend as mb
from rendiff_harness.renderers.povray import backend as povray
from rendiff_harness.renderers.pyrender import backend as pb

POINT = [{"kind": "point", "position": [0.3, 0.2, 1.5], "intensity": [10.0, 5.0, 2.0]}]
POINT2 = POINT + [{"kind": "point", "position": [-1.3, 0.4, 0.5], "intensity": [1.0, 5.0, 2.0]}]
DIRECTIONAL = [{"kind": "directional", "direction": [0.3, 0.4, -1.0], "irradiance": [2.0, 3.0, 4.0]}]
BOTH = POINT + DIRECTIONAL
EMISSION = (3.0, 0.5, 0.0)

# name -> (lights, features beyond depth/ids, emission, flip)
CASES: dict[str, tuple[list[dict[str, Any]], tuple[str, ...], tuple[float, float, float], bool]] = {
    "point": (POINT, ("lambert", "point_light"), (0.0, 0.0, 0.0), False),
    "two_points": (POINT2, ("lambert", "point_light"), (0.0, 0.0, 0.0), False),
    "directional": (DIRECTIONAL, ("lambert", "directional_light"), (0.0, 0.0, 0.0), False),
    "directional_back": (DIRECTIONAL, ("lambert", "directional_light"), (0.0, 0.0, 0.0), True),
    "emission": ([], ("emission",), EMISSION, False),
    "emission_back": ([], ("emission",), EMISSION, True),
    "emission_and_lights": (BOTH, ("emission", "lambert", "point_light", "directional_light"), EMISSION, False),
}


def _requires(extra: tuple[str, ...], shadows: str, sides: str) -> tuple[str, ...]:
    lights = any(f in extra for f in ("point_light", "directional_light"))
    return ("depth", "ids", *extra, *((shadows,) if lights else ()), sides)


def _render(module: Any, tmp_path: Path, case: str, shadows: str, sides: str) -> tuple[dict[str, Any], np.ndarray]:
    """Render CASES[case] with `module`; ({"bufs", "attrs", "info"}, closed-form radiance)."""
    lights, extra, emission, flip = CASES[case]
    d = cases.lit_plane(
        tmp_path / case, lights, requires=_requires(extra, shadows, sides), emission=emission, flip=flip
    )
    scene = resolved.load(d)
    out = tmp_path / f"{case}.exr"
    info = module.render(scene, out, tmp_path / "work", 120.0)
    bufs = exrbuf.read_buffers(out, require=("RGB",))
    attrs = exrbuf.read_attrs(out)
    want = cases.closed_form_plane(scene, flip=flip)
    return {"bufs": bufs, "attrs": attrs, "info": info}, want


def _check(backend: str, got: np.ndarray, want: np.ndarray, attrs: dict, info: dict, case: str) -> None:
    tol = precision.rgb_tolerance(registry.spec(backend), backend, want, attrs, info)
    err = np.abs(got.astype(np.float64) - want)
    allowed = tol.abs_tol + tol.rel * np.abs(want)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(want > 0, err / want, 0.0)
    print(
        f"{backend} {case}: max |err| {err.max():.3g}, max rel {rel.max():.3g}, "
        f"max err/tol {np.max(err / np.maximum(allowed, 1e-300)):.3f}"
    )
    assert np.all(err <= allowed), f"{backend} {case}: max err {err.max():.3g}; {tol.text}"


# --------------------------------------------------------------------------- POV-Ray

needs_povray = pytest.mark.skipif(povray.unavailable_reason() is not None, reason=f"{povray.unavailable_reason()}")


@needs_povray
@pytest.mark.parametrize(
    "case", ["point", "two_points", "directional", "directional_back", "emission", "emission_and_lights"]
)
def test_povray_matches_closed_form(tmp_path: Path, case: str) -> None:
    r, want = _render(povray, tmp_path, case, "shadowless", "two_sided")
    _check("povray", r["bufs"]["RGB"], want, r["attrs"], r["info"], case)
    assert r["attrs"]["rgb_encoding"] == "png16-linear"
    rad = r["info"]["radiance"]
    # exposure: the brightest pixel sits just below full scale (bound x 1+2^-6), nothing clipped
    if rad["rgb_scale"]:
        assert rad["rescaled"] == 0
    if case in ("point", "directional"):
        lit_max = float(want.max())
        assert lit_max / rad["rgb_scale"] == pytest.approx(1 / povray.EXPOSURE_MARGIN, rel=1e-6)
    if case == "emission":
        assert rad["emission_scale"] == pytest.approx(max(EMISSION) * povray.EXPOSURE_MARGIN)


@needs_povray
def test_povray_sdl_mapping_is_exact_text(tmp_path: Path) -> None:
    """The emitted light blocks: no 1/pi in POV-Ray -> folded into the colour; fade for 1/d^2."""
    lights, extra, _, _ = CASES["emission_and_lights"]
    scene = resolved.load(cases.lit_plane(tmp_path / "s", lights, requires=_requires(extra, "shadows", "two_sided")))
    pts = np.array([[0.3, 0.2, 0.0]])
    sdl, fades = povray.lights_sdl(scene, 2.0, pts)
    fd = fades[0]["fade_distance"]
    assert fd == pytest.approx(povray.FADE_REL * 1.5)  # nearest hit point 1.5 below the light
    colour = np.array([10.0, 5.0, 2.0]) / (math.pi * 2 * fd * fd * 2.0)
    c0, c1, c2 = (float(c) for c in colour)
    assert f"rgb <{c0!r},{c1!r},{c2!r}> fade_distance {fd!r} fade_power 2 }}" in sdl
    assert "parallel point_at" in sdl and "shadowless" not in sdl
    scene2 = resolved.load(
        cases.lit_plane(tmp_path / "t", lights, requires=_requires(extra, "shadowless", "two_sided"))
    )
    assert povray.lights_sdl(scene2, 2.0, pts)[0].count("shadowless") == 2


@needs_povray
@pytest.mark.parametrize("shadows", ["shadows", "shadowless"])
def test_povray_shadows_match_float64_shadow_rays_and_shadowless_ignores_the_occluder(
    tmp_path: Path, shadows: str
) -> None:
    scene = _occluded(tmp_path, shadows)
    out = tmp_path / "o.exr"
    info = povray.render(scene, out, tmp_path / "w", 120.0)
    _check_occluded("povray", scene, exrbuf.read_buffers(out), exrbuf.read_attrs(out), info)


# --------------------------------------------------------------------------- Mitsuba

needs_mitsuba = pytest.mark.skipif(mb.unavailable_reason() is not None, reason=f"{mb.unavailable_reason()}")


@needs_mitsuba
@pytest.mark.parametrize("sides", ["two_sided", "one_sided"])
@pytest.mark.parametrize("case", list(CASES))
def test_mitsuba_direct_matches_closed_form(tmp_path: Path, case: str, sides: str) -> None:
    r, want = _render(mb, tmp_path, case, "shadows", sides)
    _check("mitsuba", r["bufs"]["RGB"], want, r["attrs"], r["info"], f"{case} {sides}")
    assert r["attrs"]["integrator"] == "direct" and int(r["attrs"]["spp"]) == 1
    assert "var" not in r["bufs"]
    if sides == "one_sided" and CASES[case][3]:
        assert np.all(r["bufs"]["RGB"] == 0.0), "one-sided: the back of the plane is black"


@needs_mitsuba
def test_mitsuba_direct_is_exact_at_pixel_centers(tmp_path: Path) -> None:
    """Notes: 1 spp direct lighting on pixel centers matches rho/pi E cos to ~1e-6 (directional)."""
    r, want = _render(mb, tmp_path, "directional", "shadows", "two_sided")
    rel = np.abs(r["bufs"]["RGB"] - want) / want
    assert rel.max() < 1e-6


@needs_mitsuba
def test_mitsuba_shadows_match_float64_shadow_rays(tmp_path: Path) -> None:
    scene = _occluded(tmp_path, "shadows")
    out = tmp_path / "o.exr"
    info = mb.render(scene, out, tmp_path / "w", 120.0)
    _check_occluded("mitsuba", scene, exrbuf.read_buffers(out), exrbuf.read_attrs(out), info)


@needs_mitsuba
def test_mitsuba_path_furnace_is_le_over_one_minus_rho(tmp_path: Path) -> None:
    """Closed room, every wall rho = 0.5 and Le = 1 (one-sided, facing in): L = 2 everywhere.

    The statistical gate must pass against the exact image and fail against a 2% wrong one.
    """
    scene = resolved.load(cases.furnace(tmp_path / "f"))
    out = tmp_path / "f.exr"
    info = mb.render(scene, out, tmp_path / "w", 300.0, spp=1024, seed=3)
    bufs = exrbuf.read_buffers(out, require=("RGB", "var"))
    attrs = exrbuf.read_attrs(out)
    assert attrs["integrator"] == "path" and attrs["spp"] == 1024 and attrs["seed"] == 3
    assert attrs["passes"] == mb.VARIANCE_PASSES and attrs["var_samples"] == mb.VARIANCE_PASSES
    assert info["radiance"]["spp_per_pass"] == 1024 // mb.VARIANCE_PASSES
    rgb, var = bufs["RGB"], bufs["var"]
    nu = radiance.degrees_of_freedom(attrs)
    exact = radiance.compare_statistical(np.full(rgb.shape, 2.0), None, math.inf, rgb, var, nu)
    assert exact.interior == 0, exact.details
    wrong = radiance.compare_statistical(np.full(rgb.shape, 1.0 / (1.0 - 0.51)), None, math.inf, rgb, var, nu)
    assert wrong.interior > 0.5 * rgb.shape[0] * rgb.shape[1]
    # whole-image mean within 4 standard errors of 2
    se = math.sqrt(float(var.mean()) / var[..., 0].size / 3)
    assert abs(float(rgb.mean()) - 2.0) < 4 * se + 1e-6


@needs_mitsuba
def test_mitsuba_two_sided_emitters_emit_on_both_sides_in_path(tmp_path: Path) -> None:
    """Path tracing with max_depth 1 sees only emission: Le on both sides when two-sided, front only else."""
    for sides, flip, want in (
        ("two_sided", True, EMISSION),
        ("one_sided", True, (0, 0, 0)),
        ("one_sided", False, EMISSION),
    ):
        d = cases.lit_plane(
            tmp_path / f"{sides}{flip}",
            [],
            flip=flip,
            emission=EMISSION,
            requires=("depth", "ids", "emission", "area_light", "global_illumination", sides),
        )
        import json

        meta = json.loads((d / "scene.json").read_text())
        meta["integrator"] = {"max_depth": 1, "spp": 4}
        (d / "scene.json").write_text(json.dumps(meta))
        rgb, var, info = mb.render_radiance(resolved.load(d), spp=4, seed=0)
        assert var is not None and info["passes"] == 4
        assert np.allclose(rgb, np.asarray(want, float), rtol=1e-6, atol=0), (sides, flip)


# --------------------------------------------------------------------------- pyrender

needs_pyrender = pytest.mark.skipif(pb.unavailable_reason() is not None, reason=f"{pb.unavailable_reason()}")


@needs_pyrender
@pytest.mark.parametrize(
    "case",
    ["point", "two_points", "directional", "directional_back", "emission", "emission_back", "emission_and_lights"],
)
def test_pyrender_lambert_shader_matches_closed_form(tmp_path: Path, case: str) -> None:
    r, want = _render(pb, tmp_path, case, "shadowless", "two_sided")
    got = r["bufs"]["RGB"]
    _check("pyrender", got, want, r["attrs"], r["info"], case)
    scale = r["info"]["radiance"]["rgb_scale"]
    assert r["attrs"]["rgb_encoding"] == "png8-gamma2.2" and r["attrs"]["rgb_scale"] == pytest.approx(scale)
    # in code units: GL rounds to nearest
    c_exact = 255 * np.clip(want / scale, 0, 1) ** (1 / 2.2)
    c_got = pb.encode_rgb8(got.astype(np.float64), scale)
    print(
        f"pyrender {case}: max code error {np.abs(c_got - c_exact).max():.4f}, "
        f"brightest code {r['info']['radiance']['max_code']}"
    )
    assert np.abs(c_got - c_exact).max() <= 0.5 + pb.PYRENDER_CODE_SLACK
    assert r["info"]["radiance"]["max_code"] < 255


@needs_pyrender
def test_pyrender_is_not_its_default_pbr_shader(tmp_path: Path) -> None:
    """pyrender's own shader is 2.6-6% off Lambert; ours must be within half a code (checked above) and
    the program cache must read our folder."""
    assert (pb.SHADER_DIR / "mesh.frag").is_file() and "INV_PI" in (pb.SHADER_DIR / "mesh.frag").read_text()
    assert "shadows" not in pb.FEATURES and "one_sided" not in pb.FEATURES


@needs_pyrender
def test_pyrender_refuses_more_lights_than_it_binds(tmp_path: Path) -> None:
    lights = [{"kind": "point", "position": [0.1 * i, 0.0, 1.0], "intensity": [1.0, 1.0, 1.0]} for i in range(5)]
    scene = resolved.load(
        cases.lit_plane(
            tmp_path / "s", lights, requires=("depth", "ids", "lambert", "point_light", "shadowless", "two_sided")
        )
    )
    with pytest.raises(BackendError, match="at most 4"):
        pb.render(scene, tmp_path / "o.exr", tmp_path / "w", 60.0)


# --------------------------------------------------------------------------- occluder scene


def _occluded(tmp_path: Path, shadows: str) -> resolved.ResolvedScene:
    return resolved.load(cases.occluded_plane(tmp_path / f"occ_{shadows}", shadows))


def _check_occluded(backend: str, scene: resolved.ResolvedScene, bufs: dict, attrs: dict, info: dict) -> None:
    """Within tolerance of the float64 formula with shadow rays, except where the shadow ray is ambiguous."""
    prim, z = bufs["id.prim"], bufs["Z"]
    want = lighting.local_radiance(scene, prim, z.astype(np.float64))
    tol = precision.rgb_tolerance(registry.spec(backend), backend, want, attrs, info)
    bad = ~(np.abs(bufs["RGB"] - want) <= tol.abs_tol + tol.rel * want).all(axis=2)
    shadowed = (want == 0).all(axis=2) & (prim != 0xFFFFFFFF)
    if "shadows" in scene.requires:
        assert shadowed.sum() > 30, "the fixture must cast a visible shadow"
    else:
        assert not shadowed.any()
    rows, cols = np.nonzero(bad)
    amb = lighting.shadow_ambiguity(scene, prim, z, rows, cols, radiance.SHADOW_EDGE_REL * lighting.scene_size(scene))
    print(
        f"{backend} occluder ({'shadows' if 'shadows' in scene.requires else 'shadowless'}): "
        f"{int(bad.sum())} pixels beyond tolerance, all on ambiguous shadow rays: "
        f"{bool(amb.all()) if amb is not None else None}"
    )
    assert amb is not None and amb.all(), list(zip(rows[~amb], cols[~amb], strict=True))
