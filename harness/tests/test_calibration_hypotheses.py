"""The calibration's diagnosis (judge/hypotheses.py): a failing camera is told which convention it
follows, depth and camera hypotheses tested against each other, the best one first in the message.

The buffers are test_calibration's exact ray casts of the committed near probe through a camera
with one known fault, stored as that fault's renderer would store them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rendiff_harness.contract.resolved import ResolvedScene
from rendiff_harness.judge import calibration as cal
from rendiff_harness.judge import hypotheses as hyp
from rendiff_harness.renderers import registry
from test_calibration import cast, pixel, probe_scene


@pytest.fixture(scope="module")
def near(tmp_path_factory: pytest.TempPathFactory) -> ResolvedScene:
    return probe_scene(tmp_path_factory.mktemp("probe") / "near")


def judged(scene: ResolvedScene, z: np.ndarray, prim: np.ndarray) -> cal.Calibration:
    return cal.measure(scene, "raster", z.astype(np.float32), prim, specs=registry.spec)


def body(m: cal.Calibration) -> str:
    """The reason after "convention error in <owner>: "."""
    return m.reason.split(": ", 1)[1]


def window(scene: ResolvedScene, z: np.ndarray) -> np.ndarray:
    """Z as window depth in [0, 1] with the probe's near and far (1/Z interpolated)."""
    n, f = scene.camera.near, scene.camera.far
    with np.errstate(all="ignore"):
        return np.where(np.isfinite(z), (1.0 / n - 1.0 / z.astype(np.float64)) / (1.0 / n - 1.0 / f), np.inf)


def test_radial_distance_is_named_first(near: ResolvedScene) -> None:
    z, prim = cast(near, radial=True)
    m = judged(near, z, prim)
    assert m.status == "fail"
    assert body(m).startswith("Z holds radial distance from the eye, not planar depth"), m.reason
    assert "read as such, the camera follows the convention" in m.reason
    assert m.hypotheses is not None and m.hypotheses["depth"] == hyp.RADIAL
    rms = m.hypotheses["depth_rms_px"]
    assert rms[hyp.RADIAL] <= m.hypotheses["rms_bound_px"] < rms[hyp.PLANAR]
    # Every depth hypothesis has its residual in the message.
    for name in (hyp.PLANAR, hyp.RADIAL, hyp.WINDOW, hyp.NDC, hyp.REVERSED):
        assert name in m.reason


@pytest.mark.parametrize(
    ("name", "store"),
    [
        (hyp.WINDOW, lambda s, z: window(s, z)),
        (hyp.NDC, lambda s, z: 2.0 * window(s, z) - 1.0),
        (hyp.REVERSED, lambda s, z: 1.0 - window(s, z)),
    ],
)
def test_window_ndc_and_reversed_depths_are_told_apart(near: ResolvedScene, name: str, store: object) -> None:
    z, prim = cast(near)
    # float64 here: the stored float32 of a window depth loses most of 1/Z's digits near 1
    # (that precision loss is the renderer's to declare); the hypothesis itself is what is tested.
    w = store(near, z)  # type: ignore[operator]
    m = cal.measure(near, "raster", w, prim, specs=registry.spec)
    assert m.status == "fail", m.reason
    assert m.hypotheses is not None and m.hypotheses["depth"] == name, m.reason
    assert body(m).startswith("Z holds "), m.reason


@pytest.mark.parametrize(
    ("g", "name"),
    [
        (np.array([[1.0, 0, 0], [0.5, 1, 0], [-0.5, 0, 1]]), hyp.OFFSET),  # corners, not centers (scaled below)
        (np.diag([1.0, 1.01, 1.01]), hyp.FOV),
        (np.diag([1.0, 1.0, 1.01]), hyp.ASPECT),
        (np.diag([1.0, -1.0, 1.0]), hyp.MIRRORED),
        (np.diag([1.0, 1.0, -1.0]), hyp.FLIPPED),
    ],
)
def test_each_camera_fault_is_named_by_its_hypothesis(near: ResolvedScene, g: np.ndarray, name: str) -> None:
    g = g.copy()
    g[1:, 0] *= -pixel(near)  # the offset case: half a pixel left and up, as sampling corners does
    z, prim = cast(near, g)
    m = judged(near, z, prim)
    assert m.status == "fail"
    assert m.hypotheses is not None and m.hypotheses["depth"] == hyp.PLANAR
    assert m.hypotheses["camera"] == name, m.reason
    assert body(m).startswith(name), m.reason
    rms = m.hypotheses["camera_rms_px"]
    assert rms[name] <= m.hypotheses["rms_bound_px"] < rms[hyp.CONVENTION]


def test_a_passing_camera_is_not_diagnosed(near: ResolvedScene) -> None:
    z, prim = cast(near)
    m = judged(near, z, prim)
    assert m.status == "pass" and m.hypotheses is None


def test_the_diagnosis_json_has_no_infinities() -> None:
    d = hyp.Diagnosis(hyp.PLANAR, {hyp.PLANAR: 1.0, hyp.WINDOW: math.inf}, None, {hyp.CONVENTION: 2.0}, 1e-5)
    assert d.as_json()["depth_rms_px"] == {hyp.PLANAR: 1.0, hyp.WINDOW: None}
    assert d.lead().startswith("no camera or depth hypothesis fits (closest: convention")
