"""Mitsuba backend: conversions checked against closed forms and a float64 pixel-center ray cast."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import backend_cases as cases
from rendiff_harness.contract import exrbuf, resolved
from rendiff_harness.contract.resolved import ResolvedScene
from rendiff_harness.renderers import registry
from rendiff_harness.renderers.errors import BackendError, BackendUnavailable
from rendiff_harness.renderers.mitsuba import backend as mb

REASON = mb.unavailable_reason()
needs_mitsuba = pytest.mark.skipif(REASON is not None, reason=f"mitsuba backend unavailable: {REASON}")
BG = mb.BACKGROUND_ID
REL_DEPTH = 1e-6  # measured max 3e-7 on these planes

Rendered = tuple[ResolvedScene, dict[str, np.ndarray], dict[str, Any]]


def _render(tmp_path: Path, build: Callable[[Path], Path]) -> Rendered:
    scene = resolved.load(build(tmp_path / "scene"))
    buffers, info = mb.render_arrays(scene)
    return scene, buffers, info


@needs_mitsuba
def test_version_names_the_variant() -> None:
    """What it declares: test_registry.py's DECLARED."""
    assert mb.version().startswith("mitsuba 3.9.1") and mb.selected_variant() in mb.version()


@needs_mitsuba
@pytest.mark.parametrize("distance", [5.0, 123.25])
def test_facing_plane_depth_is_its_distance(tmp_path: Path, distance: float) -> None:
    _, buf, _ = _render(tmp_path, lambda d: cases.facing_quad(d, distance))
    assert np.all(buf["prim"] != BG), "the quad fills the view"
    rel = np.abs(buf["Z"].astype(np.float64) - distance) / distance
    assert rel.max() <= REL_DEPTH, f"max relative error {rel.max():.3g}"


@needs_mitsuba
def test_tilted_plane_depth_matches_ray_plane_intersection(tmp_path: Path) -> None:
    scene, buf, _ = _render(tmp_path, cases.tilted_quad)
    want = cases.plane_depth(scene, cases.TILTED_POINT, cases.TILTED_NORMAL)
    assert np.all(buf["prim"] != BG)
    # Steep enough that a sample 1e-3 px off the pixel center would break the tolerance:
    # this pins the sampler to exact pixel centers (no jitter, no half-pixel shift).
    assert 1e-3 * np.abs(np.diff(want, axis=1)).min() > REL_DEPTH * want.max()
    rel = np.abs(buf["Z"].astype(np.float64) - want) / want
    assert rel.max() <= REL_DEPTH, f"max relative error {rel.max():.3g}"
    assert np.all(np.abs(buf["Z"] - want) <= mb.depth_tolerance(want))


@needs_mitsuba
def test_depth_matches_ray_cast_where_ids_agree(tmp_path: Path) -> None:
    scene, buf, _ = _render(tmp_path, cases.three_triangles_two_objects)
    ref = cases.cast(scene)
    same = (buf["prim"] == ref.prim) & (ref.prim != BG)
    rel = np.abs(buf["Z"][same].astype(np.float64) - ref.z[same]) / ref.z[same]
    assert rel.max() <= REL_DEPTH


@needs_mitsuba
def test_background_has_a_zero_normal(tmp_path: Path) -> None:
    """The rest of the background (inf, all ones): test_id_backends.py."""
    _, buf, _ = _render(tmp_path, cases.three_triangles_two_objects)
    bg = buf["prim"] == BG
    assert bg.sum() > 100 and np.all(buf["N"][bg] == 0.0)


@needs_mitsuba
def test_back_facing_triangle_has_its_winding_normal(tmp_path: Path) -> None:
    """Its IDs: test_id_backends.py."""
    _, buf, _ = _render(tmp_path, cases.back_facing)
    hit = buf["prim"] == 0
    assert np.count_nonzero(hit) > 20
    assert np.allclose(buf["N"][hit], [0.0, 0.0, -1.0], atol=1e-6), "winding normal, not flipped"


@needs_mitsuba
def test_normals_are_face_normals(tmp_path: Path) -> None:
    _, buf, _ = _render(tmp_path, cases.tilted_quad)
    assert np.allclose(buf["N"].reshape(-1, 3), cases.TILTED_NORMAL, atol=1e-6)


@needs_mitsuba
def test_scene_near_plane_clips(tmp_path: Path) -> None:
    _, buf, _ = _render(tmp_path, cases.near_clipped)
    assert np.all((buf["prim"] == 2) | (buf["prim"] == 3))
    assert np.abs(buf["Z"] - 1.0).max() <= REL_DEPTH


def test_refuses_more_triangles_than_float32_holds(tmp_path: Path) -> None:
    small = resolved.load(cases.back_facing(tmp_path / "s"))
    huge = np.broadcast_to(small.triangles[:1], (2**24 + 1, 3, 3))  # no memory behind it
    scene = ResolvedScene(**{**small.__dict__, "triangles": huge})
    with pytest.raises(BackendError, match="2\\^24"):
        mb.render_arrays(scene)


def test_variant_defaults_to_scalar_rgb(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(mb.VARIANT_ENV, raising=False)
    assert mb.selected_variant() == "scalar_rgb"


def test_llvm_variant_needs_an_llvm_path(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv(mb.VARIANT_ENV, "llvm_ad_rgb")
    monkeypatch.delenv(mb.LLVM_PATH_ENV, raising=False)
    monkeypatch.setattr(mb, "DEBIAN_LIBLLVM19", tmp_path / "no-libllvm19.so")
    with pytest.raises(BackendUnavailable, match="DRJIT_LIBLLVM_PATH"):
        mb.selected_variant()
    monkeypatch.setenv(mb.LLVM_PATH_ENV, str(tmp_path / "missing.so"))
    with pytest.raises(BackendUnavailable, match="libllvm19"):
        mb.selected_variant()


def test_llvm_variant_finds_debians_libllvm19(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Without DRJIT_LIBLLVM_PATH the Debian library is used, and exported for drjit's import."""
    lib = tmp_path / "libLLVM.so.19.1"
    lib.write_bytes(b"")
    monkeypatch.setenv(mb.VARIANT_ENV, "llvm_ad_rgb")
    monkeypatch.setenv(mb.LLVM_PATH_ENV, "")  # unset in effect; restored afterwards, as selected_variant sets it
    monkeypatch.setattr(mb, "DEBIAN_LIBLLVM19", lib)
    assert mb.selected_variant() == "llvm_ad_rgb"
    assert os.environ[mb.LLVM_PATH_ENV] == str(lib)


def test_unknown_variant_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(mb.VARIANT_ENV, "cuda_ad_rgb")
    with pytest.raises(BackendUnavailable, match="not supported"):
        mb.selected_variant()


@needs_mitsuba
def test_render_writes_exr(tmp_path: Path) -> None:
    scene = resolved.load(cases.three_triangles_two_objects(tmp_path / "s"))
    out = tmp_path / "out.exr"
    info = mb.render(scene, out, tmp_path, timeout_s=60.0)
    got = exrbuf.read_buffers(out, require=["Z", "id.prim", "id.object", "N"])
    attrs = exrbuf.read_attrs(out)
    assert attrs["variant"] == mb.selected_variant() and attrs["near_clip"] == scene.camera.near
    buf, _ = mb.render_arrays(scene)
    assert np.array_equal(got["id.prim"], buf["prim"]) and np.array_equal(got["id.object"], buf["obj"])
    assert np.array_equal(got["Z"], buf["Z"]) and np.array_equal(got["N"], buf["N"])
    assert "RGB" not in got
    timings = info["timings_s"]
    assert isinstance(timings, dict) and set(timings) >= {"build", "render", "write"}


# --------------------------------------------------------------------------- camera export (calibration)


def _old_look_at(mi: Any, cam: Any) -> Any:
    """The export before the fix: Mitsuba's look_at, evaluated in float32."""
    return mi.ScalarTransform4f().look_at(
        origin=[float(v) for v in cam.eye],
        target=[float(v) for v in cam.eye + cam.forward],
        up=[float(v) for v in cam.up_ortho],
    )


@needs_mitsuba
@pytest.mark.parametrize("probe", ["camera_near", "camera_far"])
def test_to_world_is_the_float64_basis_rounded_once(tmp_path: Path, probe: str) -> None:
    from test_calibration import probe_scene

    cam = probe_scene(tmp_path / probe, probe).camera
    m64 = mb.camera_to_world(cam)
    assert np.allclose(m64[:3, 0], -cam.right) and np.allclose(m64[:3, 1], cam.up_ortho)
    assert np.allclose(m64[:3, 2], cam.forward) and np.array_equal(m64[:3, 3], cam.eye)
    assert np.allclose(m64[:3, :3].T @ m64[:3, :3], np.eye(3), atol=1e-15)
    assert np.allclose(mb.world_to_camera(cam) @ m64, np.eye(4), atol=1e-12 * max(1.0, float(np.abs(cam.eye).max())))
    mi = mb._import_mitsuba()
    sensor = mi.load_dict(mb.sensor_dict(mi, cam, cam.near, 50.0))
    m32 = np.array(sensor.world_transform().matrix, dtype=np.float64)
    # each entry is the float64 one rounded to float32 once (to nearest: <= 2^-24 of its size)
    assert np.all(np.abs(m32 - m64) <= 2.0**-24 * np.abs(m64)), m32 - m64
    # the old look_at export is off by about one float32 step of |eye| (f32 target - origin)
    old = np.array(_old_look_at(mi, cam).matrix, dtype=np.float64)
    err = np.abs(old[:3, :3] - m64[:3, :3]).max()
    if probe == "camera_far":
        assert err > 1e-5, f"the far probe must show the float32 look_at error (got {err:.3g})"


@needs_mitsuba
def test_far_probe_calibrates_and_the_old_look_at_does_not(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """2.5e4 from the origin, the float64 to_world keeps Mitsuba's camera within its f32 rounding;
    the float32 look_at turned it by ~5e-4 rad (0.036 px): a convention error, named as such."""
    from rendiff_harness.judge import calibration
    from test_calibration import probe_scene

    scene = probe_scene(tmp_path / "far", "camera_far")
    buf, info = mb.render_arrays(scene)
    now = calibration.measure(scene, mb.NAME, buf["Z"], buf["prim"], info=info, specs=registry.spec)
    assert now.status == "pass", now.reason
    assert now.max_shift_px is not None and now.max_shift_px < 1e-4
    monkeypatch.setattr(mb, "sensor_to_world", _old_look_at)
    buf, info = mb.render_arrays(scene)
    before = calibration.measure(scene, mb.NAME, buf["Z"], buf["prim"], info=info, specs=registry.spec)
    assert before.status == "fail"
    assert before.reason.startswith("convention error in the mitsuba exporter: ")
    assert "camera turned by (" in before.reason
    assert before.max_shift_px is not None and before.max_shift_px > 0.01


def test_clip_ranges_float32_cannot_hold_are_clamped_or_declined(tmp_path: Path) -> None:
    # Mitsuba keeps clip distances in float32: a far of 1e308 overflowed to inf and rendered a
    # blank image reported as ok; a near of 1e-300 was rejected as an error.
    from fixtures import write_scene
    from rendiff_harness.renderers.errors import BackendSkipped

    tri = [[[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]]]
    far = resolved.load(write_scene(tmp_path / "far", tri, far=1e308))
    near, clip = mb.clip_range(far)
    assert clip == mb.FAR_FACTOR * 5.0 and near == far.camera.near  # beyond every vertex: clips nothing
    kept = resolved.load(write_scene(tmp_path / "kept", tri, far=4.0))
    assert mb.clip_range(kept)[1] == 4.0  # a far that clips is the scene's own
    tiny = resolved.load(write_scene(tmp_path / "tiny", tri, near=1e-300))
    with pytest.raises(BackendSkipped, match="beyond float32"):
        mb.clip_range(tiny)
