"""The radiance gate on synthetic data: noise passes, bias fails, tolerances are what they say.

Synthetic Monte Carlo estimates are drawn directly as (mean, variance of the mean): the
mean ~ N(mu, sigma^2/n) and the variance from a chi-square with n-1 degrees of freedom,
exactly what n independent normal samples would give, so 200 seeds cost milliseconds.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rendiff_harness.contract import lighting, resolved
from rendiff_harness.judge import precision, radiance, tolerance
from rendiff_harness.renderers import registry
from rendiff_harness.renderers.povray import backend as povray
from rendiff_harness.renderers.pyrender import backend as pb

H, W = 32, 32
N_SPP = 64


def _field(rng: np.random.Generator) -> np.ndarray:
    """A smooth, positive 'image' of true pixel values."""
    y, x = np.mgrid[0:H, 0:W] / max(H, W)
    base = 0.2 + 0.8 * np.exp(-((x - 0.4) ** 2 + (y - 0.6) ** 2) * 4.0)
    return np.stack([base, 0.6 * base, 0.3 * base + 0.05], axis=-1) * rng.uniform(0.8, 1.2)


def _estimate(
    truth: np.ndarray, rel_sigma: float, n: int, rng: np.random.Generator, sigma_scale: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """(mean, variance of the mean) of n normal samples per pixel-channel with std rel_sigma * truth."""
    sigma = rel_sigma * truth * sigma_scale
    mean = truth + rng.standard_normal(truth.shape) * sigma / math.sqrt(n)
    s2 = sigma**2 * rng.chisquare(n - 1, truth.shape) / (n - 1)
    return mean, s2 / n


def _stat(
    ref: tuple[np.ndarray, np.ndarray], test: tuple[np.ndarray, np.ndarray], n_ref: int = N_SPP, n_test: int = N_SPP
) -> radiance.RgbResult:
    return radiance.compare_statistical(
        ref[0], ref[1], n_ref - 1, test[0], test[1], n_test - 1, ref_n=n_ref, test_n=n_test
    )


def test_false_alarm_rate_is_at_most_alpha() -> None:
    """Two independent estimates of the same image: the gate fails in <= alpha of the runs."""
    seeds = 200
    fails = pixel = cluster = 0
    for seed in range(seeds):
        rng = np.random.default_rng(10_000 + seed)
        truth = _field(rng)
        res = _stat(_estimate(truth, 0.3, N_SPP, rng), _estimate(truth, 0.3, N_SPP, rng))
        fails += res.interior > 0
        pixel += res.failing_pixels > 0
        cluster += (res.cluster_failures or 0) > 0
        assert res.alpha == radiance.ALPHA and res.edge == 0
    rate = fails / seeds
    print(
        f"false-alarm rate over {seeds} seeds: {rate:.3f} "
        f"(pixel test {pixel}, cluster test {cluster}; alpha {radiance.ALPHA})"
    )
    # Binomial(200, 0.01): P(> 6 failures) < 0.5%; Sidak on independent tests is exact, so more means a bug.
    assert fails <= 6


def test_two_percent_bias_with_enough_spp_fails() -> None:
    rng = np.random.default_rng(1)
    truth = _field(rng)
    n = 4096  # per-pixel relative std of the mean: 0.3/64 = 0.5%
    res = _stat(_estimate(truth, 0.3, n, rng), _estimate(truth * 1.02, 0.3, n, rng), n, n)
    assert res.interior > 0.5 * H * W, res.details
    assert res.cluster_failures and res.cluster_failures > res.failing_pixels  # the cluster test is the sharper one
    # ... while at 64 spp the same bias is mostly within the noise (power, not a false pass).
    res_low = _stat(_estimate(truth, 0.3, N_SPP, rng), _estimate(truth * 1.02, 0.3, N_SPP, rng))
    assert res_low.interior < res.interior / 50


def test_missing_cosine_field_fails() -> None:
    """A directional light on a tilted image: the test forgot cos(theta) (varies over the image)."""
    rng = np.random.default_rng(2)
    y, x = np.mgrid[0:H, 0:W]
    cos = np.clip(0.2 + 0.8 * (x / W), 0.0, 1.0)[..., None] * np.ones(3)
    e_over_pi = np.array([0.9, 0.5, 0.3])
    right = e_over_pi * cos
    wrong = e_over_pi * np.ones_like(cos)
    res = _stat(_estimate(right, 0.5, N_SPP, rng), _estimate(wrong, 0.5, N_SPP, rng))
    assert res.interior > 0.3 * H * W
    assert res.min_p is not None and res.min_p < 1e-12


def test_noise_only_variance_mismatch_passes() -> None:
    """Same means, one renderer 3x noisier per sample (another sampling strategy): no failure."""
    fails = 0
    for seed in range(20):
        rng = np.random.default_rng(500 + seed)
        truth = _field(rng)
        res = _stat(_estimate(truth, 0.2, N_SPP, rng), _estimate(truth, 0.2, N_SPP, rng, sigma_scale=3.0))
        fails += res.interior > 0
    assert fails <= 1


def test_variance_lift_protects_a_side_that_missed_rare_samples() -> None:
    """A 64-spp side that missed the rare bright paths: low mean, ~zero variance.

    Against a well-sampled reference its raw Welch t is huge; lifted to the pooled
    per-sample variance it is ~sqrt(p n) (measured false alarms on real renders: module doc).
    """
    p_rare, value, n_ref, n_test = 0.01, 50.0, 4096, 64
    mu = p_rare * value
    per_sample_var = p_rare * value**2 - mu**2
    ref_mean = np.full((8, 8, 3), mu)
    ref_var = np.full((8, 8, 3), per_sample_var / n_ref)
    test_mean = np.zeros((8, 8, 3))  # no rare sample drawn: every sample 0
    test_var = np.zeros((8, 8, 3))
    raw = radiance.compare_statistical(ref_mean, ref_var, n_ref - 1, test_mean, test_var, n_test - 1)
    assert raw.failing_pixels == 64
    lifted = radiance.compare_statistical(
        ref_mean, ref_var, n_ref - 1, test_mean, test_var, n_test - 1, ref_n=n_ref, test_n=n_test
    )
    assert lifted.failing_pixels == 0
    va, vb = radiance.lift_variances(test_var, n_test, ref_var, n_ref)
    assert np.all(vb == ref_var) and np.allclose(va, per_sample_var * n_ref / (n_ref + n_test) / n_test)


def test_zero_variance_guard() -> None:
    a = np.full((4, 4, 3), 2.5, dtype=np.float32)
    zero = np.zeros_like(a)
    same = radiance.compare_statistical(a, zero, 63, a.copy(), zero, 63)
    assert same.interior == 0 and same.min_p == 1.0
    # float32 rounding of a mean of identical samples: within the floor
    nudged = np.nextafter(a, np.float32(np.inf))
    assert radiance.compare_statistical(a, zero, 63, nudged, zero, 63).interior == 0
    other = a.copy()
    other[1, 2, 0] = 2.6
    res = radiance.compare_statistical(a, zero, 63, other, zero, 63)
    assert res.failing_pixels == 1 and res.min_p is not None and res.min_p < 1e-100
    nan = a.copy()
    nan[0, 0, 1] = np.nan
    assert radiance.compare_statistical(a, zero, 63, nan, zero, 63).failing_pixels == 1


def test_sidak_and_welch_basics() -> None:
    assert radiance.sidak(0.01, 1) == pytest.approx(0.01)
    assert radiance.sidak(0.01, 1000) == pytest.approx(1 - 0.99 ** (1 / 1000))
    t, p, z = radiance.welch(np.array([1.0]), np.array([0.25]), math.inf, np.array([0.0]), np.array([0.0]), math.inf)
    assert t[0] == pytest.approx(2.0) and z[0] == pytest.approx(2.0) and p[0] == pytest.approx(0.0455, abs=1e-4)
    # Student t at nu = 7: heavier tails -> larger p, smaller equivalent z
    t7, p7, z7 = radiance.welch(np.array([1.0]), np.array([0.25]), 7, np.array([0.0]), np.array([0.0]), 7)
    assert p7[0] > p[0] and 0 < z7[0] < 2.0
    assert radiance.degrees_of_freedom({"spp": "64"}) == 63
    assert radiance.degrees_of_freedom({"spp": 4096, "var_samples": 64}) == 63
    assert radiance.degrees_of_freedom({}) == math.inf
    assert radiance.samples_per_pixel({"spp": "256"}) == 256 and radiance.samples_per_pixel({}) == math.inf


def test_box3_sums_full_windows() -> None:
    x = np.arange(5 * 4, dtype=float).reshape(5, 4, 1)
    got = radiance.box3(x)
    assert got.shape == (3, 2, 1)
    assert got[0, 0, 0] == x[0:3, 0:3, 0].sum() and got[2, 1, 0] == x[2:5, 1:4, 0].sum()


# --------------------------------------------------------------------------- deterministic


def test_deterministic_tolerance_and_classification() -> None:
    ref = np.full((6, 6, 3), 0.5)
    test = ref.copy()
    test[0, 0] += 0.9e-3  # within abs 1e-3
    test[1, 1, 2] += 1.1e-3 + 0.5 * 1e-2  # beyond abs + rel*|b|
    test[2, 2, 0] = np.nan
    test[3, 3, 1] += 0.01  # beyond, but an ID edge mismatch
    edges = np.zeros((6, 6), dtype=bool)
    edges[3, 3] = True
    res = radiance.compare_deterministic(ref, test, 1e-3, 1e-2, "t", id_edge_mask=edges)
    assert res.failing_pixels == 3 and res.edge == 1 and res.interior == 2
    assert res.fail_mask[1, 1] and res.fail_mask[2, 2] and not res.fail_mask[0, 0]
    assert res.edge_mask[3, 3] and not res.edge_mask[1, 1]
    assert "2 pixels beyond tolerance" in res.details[0]


def test_shadow_edge_callback_moves_failures_to_edge() -> None:
    ref = np.zeros((4, 4, 3))
    test = ref.copy()
    test[1, 2] = 1.0
    test[3, 0] = 1.0
    res = radiance.compare_deterministic(ref, test, 0.0, 0.0, "t", shadow_edges=lambda r, c: (r == 1) & (c == 2))
    assert res.edge == 1 and res.interior == 1
    res = radiance.compare_deterministic(ref, test, 0.0, 0.0, "t", shadow_edges=lambda r, c: None)
    assert res.interior == 2 and "skipped" in res.notes[0]


def test_povray_tolerance_is_half_a_code_of_each_pass() -> None:
    ref = np.full((2, 2, 3), 0.3)
    tol = precision.rgb_tolerance(
        registry.spec("povray"), "povray", ref, {"rgb_scale": 2.0, "emission_scale": "1.0"}, {}
    )
    assert tol.abs_tol == pytest.approx(3.0 / 65535 / 2) and tol.rel == povray.POVRAY_RGB_REL
    with pytest.raises(tolerance.ToleranceError):
        precision.rgb_tolerance(registry.spec("povray"), "povray", ref, {}, {})
    # info from the manifest works too (nested under "radiance" as the backend returns it)
    tol2 = precision.rgb_tolerance(
        registry.spec("povray"), "povray", ref, {}, {"radiance": {"rgb_scale": 2.0, "emission_scale": 1.0}}
    )
    assert tol2.abs_tol == tol.abs_tol


def test_pyrender_tolerance_is_half_an_8bit_code_through_the_gamma() -> None:
    rng = np.random.default_rng(3)
    scale = 1.7
    truth = rng.uniform(0.0, scale, (64, 64, 3))
    decoded = pb.decode_rgb8(pb.encode_rgb8(truth, scale).astype(np.uint8), scale)
    tol = precision.rgb_tolerance(registry.spec("pyrender"), "pyrender", truth, {"rgb_scale": scale}, {})
    err = np.abs(decoded - truth)
    assert np.all(err <= tol.abs_tol + tol.rel * truth)
    # a code more than 0.6 codes from the exact one is outside the tolerance
    c = 255 * (truth / scale) ** (1 / 2.2)
    codes = pb.encode_rgb8(truth, scale)
    off = pb.decode_rgb8(np.clip(codes + 1, 0, 255).astype(np.uint8), scale)
    far = (codes + 1 - c > 0.6) & (codes < 255)
    assert far.mean() > 0.5
    assert np.all(np.abs(off - truth)[far] > (tol.abs_tol + tol.rel * truth)[far])


def test_unknown_backend_rgb_model_is_strict() -> None:
    ref = np.ones((2, 2, 3))
    assert precision.rgb_tolerance(registry.spec("newthing"), "newthing", ref, {}, {}).abs_tol == 0.0
    f32 = precision.rgb_tolerance(registry.spec("newthing"), "newthing", ref, {"rgb_encoding": "float32"}, {})
    assert f32.rel > 0 and "newthing" in f32.text
    assert precision.rgb_tolerance(registry.spec("trace"), "trace", ref, {}, {}).rel == 0.0


def test_flip_is_reported_not_gating() -> None:
    a = np.full((16, 16, 3), 0.5, dtype=np.float32)
    flip, note = radiance.flip_mean(a, a * 1.5)
    assert flip is not None and flip > 0 and note == ""
    assert radiance.flip_mean(a, a)[0] == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("peak", [1.2e-14, 1e-7])
def test_flip_skips_a_reference_black_to_it(peak: float) -> None:
    # HDR-FLIP exits the process on a reference darker than its exposure floor (2^-23): a
    # lone pixel at `peak` on black must come back as a note, not end the comparison.
    a = np.zeros((16, 16, 3), dtype=np.float32)
    a[3, 4] = peak
    flip, note = radiance.flip_mean(a, a * 2.0)
    assert flip is None and "black to HDR-FLIP" in note
    # Just above 4x the floor it is computed.
    a[3, 4] = 8 * radiance.FLIP_MIN_LUMINANCE
    flip, note = radiance.flip_mean(a, a * 2.0)
    assert flip is not None and note == ""


# --------------------------------------------------------------------------- lighting (closed forms)


def _occluder_scene(tmp_path):  # type: ignore[no-untyped-def]
    import backend_cases as cases

    # A floor (z = 0 plane of lit_plane) and a small square occluder at height 1 under a
    # point light at height 2: its shadow is the square scaled by 2, centered below it.
    light = ([0.0, 0.0, 2.0], [4.0, 4.0, 4.0])
    return resolved.load(cases.occluded_plane(tmp_path / "occ", "shadows", width=48, height=36, light=light))


def test_local_radiance_shadows_and_ambiguity(tmp_path) -> None:  # type: ignore[no-untyped-def]
    import backend_cases as cases

    scene = _occluder_scene(tmp_path)
    # visibility in closed form: the occluder square (prim 2) where it covers, else the floor (prim 0)
    z_floor = cases.plane_depth(scene, np.zeros(3), np.array([0.0, 0.0, 1.0]))
    z_occ = cases.plane_depth(scene, np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0]))
    x_occ = lighting.hit_points(scene, z_occ)
    on_occ = (np.abs(x_occ[..., 0]) < 0.25) & (np.abs(x_occ[..., 1]) < 0.25)
    assert on_occ.sum() > 4
    prim = np.where(on_occ, 2, 0).astype(np.uint32)
    z = np.where(on_occ, z_occ, z_floor)
    lit = lighting.local_radiance(scene, prim, z, shadows=False)
    shadowed = lighting.local_radiance(scene, prim, z, shadows=True)
    floor = prim == 0
    x = lighting.hit_points(scene, z)
    in_shadow = floor & (np.abs(x[..., 0]) < 0.5) & (np.abs(x[..., 1]) < 0.5)
    assert in_shadow.sum() > 20
    assert np.all(shadowed[in_shadow] == 0.0) and np.all(lit[in_shadow] > 0)
    outside = floor & ((np.abs(x[..., 0]) > 0.52) | (np.abs(x[..., 1]) > 0.52))
    assert np.array_equal(shadowed[outside], lit[outside])
    # shadow ambiguity: only pixels whose shadow ray grazes the occluder's edges
    rows, cols = np.nonzero(floor)
    amb = lighting.shadow_ambiguity(scene, prim, z, rows, cols, eps=0.01)
    assert amb is not None
    xs = x[rows, cols]
    dist_to_boundary = np.abs(np.maximum(np.abs(xs[:, 0]), np.abs(xs[:, 1])) - 0.5)
    assert np.all(~amb[dist_to_boundary > 0.05])  # 0.01 at the occluder = 0.02 on the floor
    assert amb[dist_to_boundary < 0.005].all()
    assert lighting.shadow_ambiguity(scene, prim, z, rows, cols, eps=0.01, max_work=10) is None
