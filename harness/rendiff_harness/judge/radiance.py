"""Radiance comparison (the `RGB` buffer): deterministic tolerances or a statistical test.

docs/radiance.md "Comparison" and docs/DESIGN.md "Comparing". Which test applies is decided
by the files, never by the scene name:

Deterministic (no var.* channels on either side: local shading at pixel centers)
-------------------------------------------------------------------------------
Per pixel and channel, |a - b| <= abs_tol + rel_tol * |b| (b = reference, a = test), with
abs_tol / rel_tol from the *test* backend's output precision (its spec's rgb_tolerance: 16-bit
PNG -> half a code of its exposure scale; 8-bit gamma -> half a code through the inverse
transfer at b; float32 -> a few ulps). A pixel fails when any channel fails, or when a
value is not finite. Failing pixels are classified:

* *edge* when the pixel is an ID edge mismatch (the two renderers see different
  triangles there, within their rounding distance of an edge), or when the scene has
  `shadows` and the pixel's shadow ray passes within SHADOW_EDGE_REL (1e-3) x scene size
  of an occluder's edge or meets an occluder that close to either of its ends
  (lighting.shadow_ambiguity): renderers offset shadow rays differently (the contract:
  1e-4 x scene size along n; POV-Ray: its own absolute tolerance), so visibility on a
  shadow boundary or in a contact shadow is a matter of rounding. Computed for failing
  pixels only, by brute force (skipped, with a note, past 2e8 segment-triangle tests);
* *interior* otherwise: a shading bug.

Monte Carlo (var.R var.G var.B on both sides; one side missing them counts as exact)
-----------------------------------------------------------------------------------
Per pixel and channel, Welch's statistic t = (a - b)/sqrt(var_a + var_b + floor), where
var is each side's variance of its pixel mean, and floor = (8 * 2^-24 * max(|a|, |b|))^2
absorbs the float32 rounding of two means of identical samples (an emitter seen
directly: every sample is Le, both variances are 0 and the means may still differ in
the last bit). When both variances are 0 and a == b, t = 0; when they differ beyond the
floor, |t| is huge and the pixel fails. Degrees of freedom: nu = min(nu_a, nu_b), each
side's nu = (number of values its variance was estimated from) - 1, read from the EXR
attribute `rendiff:var_samples` (Mitsuba: its K passes) or else `rendiff:spp` (a
per-sample variance); a side without either counts as nu = inf. min(nu_a, nu_b) is the
conservative bound of Welch's test (the true nu lies between it and nu_a + nu_b): the
Welch-Satterthwaite estimate, computed from the sample variances, was measured
anti-conservative exactly where the Sidak levels put the test (8 vs 64 values: 4x the
nominal rate at p < 1e-4, 11x at p < 1e-5), while the min rule stayed at or below
nominal. The two-sided p-value is the Student-t tail at nu; each t is also mapped to
the standard-normal score z with the same tail probability, so that the window test
below is exact for any nu.

Skewed samples: path-traced samples are heavy-tailed (rare bright paths). A side with
few samples that missed the rare paths has a low mean *and* a low sample variance, so
its t is far too large (measured: 64-spp Mitsuba renders of a Cornell box against a
4096-spp one failed 20 runs out of 20, every failure a test mean *below* the reference
with a tiny variance). Mitsuba's own render tests avoid this by predicting the test's
variance from the high-spp reference. The symmetric form used here: each side's
per-sample variance s_i^2 = var_i * n_i (n_i = its spp, `rendiff:spp`) is pooled with
weights n_i (the samples each side saw: what matters is whether the rare paths were
sampled at all, not how many values the variance was computed from), and each side's
variance of its mean becomes max(var_i, s_pool^2 / n_i): a well-sampled side (a cached
reference) lends its variance estimate to a poorly sampled one, and no side's own
estimate is ever lowered (a renderer with a noisier strategy than the other keeps its
larger variance; one with a much better strategy is tested conservatively). Without
spp on both sides no lift is applied (and the tolerance text says so). Measured on
scenes/cornell_gi (48x48) against its cached 4096-spp Mitsuba reference, 40 seeds of
the core at 64 spp: 40/40 false alarms without the lift, 5/40 with dof-weighted pooling,
0/40 with spp-weighted pooling, while the core's injected biases still fail
(missing cosine and one bounce fewer at 64 spp, a 2% albedo error from 256 spp on).

Family-wise alpha = 0.01 for the whole RGB verdict, split equally (Bonferroni) between
two families, each corrected with Sidak (valid for independent tests, conservative for
positively dependent normal ones: Sidak's inequality):

1. pixels: every pixel-channel tested at 1 - (1 - 0.005)^(1/m1), m1 = 3 H W. A pixel fails
   when any of its channels does (`failing_pixels`, `min_p` = smallest raw p).
2. clusters: the 3x3 box mean of z over every full window (per channel), times 3 (so it is
   N(0, 1) under the null for independent pixels), tested two-sided at
   1 - (1 - 0.005)^(1/m2), m2 = 3 (H-2)(W-2) (`cluster_failures`). A bias of d standard
   deviations per pixel shifts this statistic by 3d: a spatially coherent error (a
   missing cosine, a 2% albedo error) is found with 1/9 of the samples the per-pixel test
   needs, while isolated outliers are left to test 1.

`interior_mismatches` = pixels failing test 1, plus the centers of failing windows;
`edge_mismatches` = 0: a Monte Carlo pixel is a box integral over the pixel on both sides,
so no pixel-center edge rounding is involved. The test assumes each side's pixel means
are approximately normal (many samples per pixel, or per pass for the K-pass variance):
at very low spp the heavy, skewed tails of path-traced samples make false alarms more
likely than alpha.

`flip_mean`: NVIDIA FLIP (flip-evaluator, HDR) between the two images, for people only:
never part of the verdict, None with a note when the package is missing or fails.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any

import numpy as np

ALPHA = 0.01
PIXEL_ALPHA = ALPHA / 2
CLUSTER_ALPHA = ALPHA / 2
VAR_FLOOR_ULPS = 8.0
Z_CLIP = 40.0
SHADOW_EDGE_REL = 1e-3
EXAMPLES = 3


class RadianceError(Exception):
    """The radiance buffers cannot be compared (shapes, missing parameters)."""


@dataclass
class RgbResult:
    mode: str  # "deterministic" | "statistical"
    pixels: int
    failing_pixels: int
    edge: int
    interior: int
    fail_mask: np.ndarray  # (H, W) bool: pixels counted as mismatches (edge or interior)
    edge_mask: np.ndarray  # (H, W) bool
    score: np.ndarray  # (H, W) float64: max over channels of |a-b|/tol (det) or |t|/t_crit (stat)
    tolerance: str
    max_abs: float
    mean_abs: float
    max_rel: float
    min_p: float | None = None
    alpha: float | None = None
    cluster_failures: int | None = None
    details: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def _errors(a: np.ndarray, b: np.ndarray) -> tuple[float, float, float]:
    finite = np.isfinite(a) & np.isfinite(b)
    if not finite.any():
        return 0.0, 0.0, 0.0
    err = np.abs(a - b)[finite]
    bb = np.abs(b)[finite]
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(bb > 0, err / np.where(bb > 0, bb, 1.0), np.where(err == 0, 0.0, np.inf))
    return float(err.max()), float(err.mean()), float(rel.max())


# --------------------------------------------------------------------------- deterministic

ShadowEdges = Callable[[np.ndarray, np.ndarray], np.ndarray | None]
"""`shadow_edges(rows, cols)`: per failing pixel, whether its shadow ray is ambiguous (None: not computed)."""


def compare_deterministic(
    ref: np.ndarray,
    test: np.ndarray,
    abs_tol: np.ndarray | float,
    rel_tol: float,
    tol_text: str,
    id_edge_mask: np.ndarray | None = None,
    shadow_edges: ShadowEdges | None = None,
) -> RgbResult:
    """|a - b| <= abs_tol + rel_tol |b| per channel; see the module docstring.

    `abs_tol`: scalar or (H, W, 3). `shadow_edges(rows, cols) -> bool array | None` classifies
    failing pixels that are no ID edge mismatch (None: not computed, with a note).
    """
    b = np.asarray(ref, dtype=np.float64)
    a = np.asarray(test, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 3 or a.shape[2] != 3:
        raise RadianceError(f"RGB shapes differ: test {a.shape}, reference {b.shape}")
    h, w, _ = b.shape
    tol = np.broadcast_to(np.asarray(abs_tol, dtype=np.float64), b.shape) + rel_tol * np.abs(b)
    err = np.abs(a - b)
    ok = err <= tol  # NaN compares False: a non-finite value fails
    ok &= np.isfinite(a) & np.isfinite(b)
    fail = ~np.asarray(ok.all(axis=2))
    with np.errstate(divide="ignore", invalid="ignore"):
        score = np.where(tol > 0, err / np.where(tol > 0, tol, 1.0), np.where(err == 0, 0.0, np.inf))
    score = np.nan_to_num(score, nan=np.inf).max(axis=2)
    edge = np.zeros((h, w), dtype=bool)
    notes: list[str] = []
    if id_edge_mask is not None:
        edge |= fail & id_edge_mask
    rest = fail & ~edge
    if rest.any() and shadow_edges is not None:
        rows, cols = np.nonzero(rest)
        amb = shadow_edges(rows, cols)
        if amb is None:
            notes.append("shadow-edge classification skipped (too many failing pixels x triangles)")
        else:
            edge[rows[amb], cols[amb]] = True
    interior = fail & ~edge
    details: list[str] = []
    bad = np.argwhere(interior)
    if bad.size:
        worst = bad[np.argsort(-score[interior])[:EXAMPLES]]
        ex = ", ".join(f"({x},{y}) ref {_rgb(b[y, x])} test {_rgb(a[y, x])}" for y, x in worst)
        details.append(f"{len(bad)} pixels beyond tolerance, worst {ex}")
    mx, mean, rel = _errors(a, b)
    return RgbResult(
        mode="deterministic",
        pixels=h * w,
        failing_pixels=int(fail.sum()),
        edge=int(edge.sum()),
        interior=int(interior.sum()),
        fail_mask=fail,
        edge_mask=edge,
        score=score,
        tolerance=tol_text,
        max_abs=mx,
        mean_abs=mean,
        max_rel=rel,
        details=details,
        notes=notes,
    )


def _rgb(v: np.ndarray) -> str:
    return "(" + ", ".join(f"{float(c):.6g}" for c in v) + ")"


# --------------------------------------------------------------------------- statistical


def _special() -> ModuleType:
    try:
        import scipy.special as sp
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise RadianceError(f"scipy missing ({exc}): pip install -r harness/requirements.txt") from None
    special: ModuleType = sp  # scipy ships no type hints (pyproject.toml)
    return special


def sidak(alpha: float, m: int) -> float:
    """Per-test level for family-wise `alpha` over `m` independent tests: 1 - (1 - alpha)^(1/m)."""
    if m <= 0:
        return alpha
    return -math.expm1(math.log1p(-alpha) / m)


def welch(
    a: np.ndarray, var_a: np.ndarray, nu_a: float, b: np.ndarray, var_b: np.ndarray, nu_b: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, two-sided p, equivalent normal score z) per element (module docstring)."""
    sp = _special()
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    va = np.maximum(np.asarray(var_a, dtype=np.float64), 0.0)
    vb = np.maximum(np.asarray(var_b, dtype=np.float64), 0.0)
    floor = (VAR_FLOOR_ULPS * 2.0**-24 * np.maximum(np.abs(a), np.abs(b))) ** 2
    v = va + vb + floor
    diff = a - b
    finite = np.isfinite(a) & np.isfinite(b) & np.isfinite(va) & np.isfinite(vb)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(v > 0, diff / np.sqrt(np.where(v > 0, v, 1.0)), np.where(diff == 0, 0.0, np.inf))
    nu_min = min(nu_a if nu_a > 0 else math.inf, nu_b if nu_b > 0 else math.inf)
    nu = np.full(t.shape, max(nu_min, 1.0))
    t = np.where(finite, t, np.inf)
    at = np.abs(t)
    p_one = np.where(np.isinf(nu), sp.ndtr(-at), sp.stdtr(np.where(np.isinf(nu), 1.0, nu), -at))
    p_one = np.where(np.isinf(at), 0.0, p_one)
    with np.errstate(divide="ignore"):
        z_abs = np.where(np.isinf(nu), at, -sp.ndtri(np.clip(p_one, 0.0, 0.5)))
    z = np.sign(t) * np.minimum(np.nan_to_num(z_abs, nan=Z_CLIP, posinf=Z_CLIP), Z_CLIP)
    return t, np.minimum(2.0 * p_one, 1.0), z


def box3(x: np.ndarray) -> np.ndarray:
    """Sum over every full 3x3 window of an (H, W, C) array: (H-2, W-2, C)."""
    h, w = x.shape[:2]
    if h < 3 or w < 3:
        return np.zeros((0, 0) + x.shape[2:])
    c = np.cumsum(np.cumsum(np.pad(x, ((1, 0), (1, 0), (0, 0))), axis=0), axis=1)
    sums: np.ndarray = c[3:, 3:] - c[:-3, 3:] - c[3:, :-3] + c[:-3, :-3]
    return sums


def lift_variances(var_a: np.ndarray, n_a: float, var_b: np.ndarray, n_b: float) -> tuple[np.ndarray, np.ndarray]:
    """Each side's variance of its mean, lifted to at least the pooled per-sample variance / its spp.

    Per-sample variances s_i^2 = var_i * n_i are pooled with weights n_i (samples seen);
    side i's variance becomes max(var_i, s_pool^2 / n_i). Without both n, nothing is lifted.
    """
    if not all(math.isfinite(x) and x > 0 for x in (n_a, n_b)):
        return var_a, var_b
    pooled = (n_a * var_a * n_a + n_b * var_b * n_b) / (n_a + n_b)
    return np.maximum(var_a, pooled / n_a), np.maximum(var_b, pooled / n_b)


def compare_statistical(
    ref: np.ndarray,
    ref_var: np.ndarray | None,
    ref_nu: float,
    test: np.ndarray,
    test_var: np.ndarray | None,
    test_nu: float,
    alpha: float = ALPHA,
    ref_n: float = math.inf,
    test_n: float = math.inf,
) -> RgbResult:
    """Welch per pixel-channel + 3x3 cluster test, each Sidak-corrected (module docstring).

    `ref_n` / `test_n`: samples per pixel behind each mean (rendiff:spp), for the
    variance lift (`lift_variances`); unknown (inf) disables it.
    """
    sp = _special()
    b = np.asarray(ref, dtype=np.float64)
    a = np.asarray(test, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 3 or a.shape[2] != 3:
        raise RadianceError(f"RGB shapes differ: test {a.shape}, reference {b.shape}")
    h, w, _ = b.shape
    vb = np.zeros_like(b) if ref_var is None else np.asarray(ref_var, dtype=np.float64)
    va = np.zeros_like(a) if test_var is None else np.asarray(test_var, dtype=np.float64)
    if va.shape != a.shape or vb.shape != b.shape:
        raise RadianceError(f"variance shapes differ from RGB: test {va.shape}, reference {vb.shape}")
    lifted = ref_var is not None and test_var is not None and math.isfinite(ref_n) and math.isfinite(test_n)
    if lifted:
        va, vb = lift_variances(va, test_n, vb, ref_n)
    t, p, z = welch(a, va, test_nu, b, vb, ref_nu)
    m1 = int(p.size)
    a1 = sidak(alpha / 2, m1)
    fail_pc = p < a1
    fail_px = fail_pc.any(axis=2)
    zw = box3(z) / 3.0
    m2 = int(zw.size)
    a2 = sidak(alpha / 2, m2)
    pw = 2.0 * sp.ndtr(-np.abs(zw))
    fail_w = pw < a2
    win_px = np.zeros((h, w), dtype=bool)
    if m2:
        win_px[1:-1, 1:-1] = fail_w.any(axis=2)
    mism = fail_px | win_px
    z_crit = float(-sp.ndtri(a1 / 2))
    score = np.abs(z).max(axis=2) / z_crit
    details: list[str] = []
    if fail_px.any():
        idx = np.argwhere(fail_px)
        worst = idx[np.argsort(p.min(axis=2)[fail_px])[:EXAMPLES]]
        ex = ", ".join(f"({x},{y}) ref {_rgb(b[y, x])} test {_rgb(a[y, x])} t {_rgb(t[y, x])}" for y, x in worst)
        details.append(f"{int(fail_px.sum())} pixels fail the per-pixel test, e.g. {ex}")
    if fail_w.any():
        wi = np.argwhere(fail_w.any(axis=2))
        worst = wi[np.argsort(-np.abs(zw).max(axis=2)[fail_w.any(axis=2)])[:EXAMPLES]]
        ex = ", ".join(f"({x + 1},{y + 1}) z {_rgb(zw[y, x])}" for y, x in worst)
        details.append(f"{int(fail_w.any(axis=2).sum())} 3x3 windows fail the cluster test, e.g. centers {ex}")
    mx, mean, rel = _errors(a, b)

    def nu_text(nu: float) -> str:
        return "inf" if not math.isfinite(nu) else f"{nu:g}"

    lift_text = (
        f"each side's variance lifted to the spp-weighted pooled per-sample variance / its spp "
        f"(spp ref {ref_n:g}, test {test_n:g})"
        if lifted
        else "no variance lift (spp unknown on a side)"
    )
    text = (
        f"statistical: Welch t per pixel-channel (var of each mean + float32 floor; {lift_text}; "
        f"Student t with nu = min(nu_ref {nu_text(ref_nu)}, nu_test {nu_text(test_nu)})), family-wise alpha {alpha:g} "
        f"split between {m1} pixel-channel tests (Sidak, per test {a1:.3g}, |z| > {z_crit:.3g}) and "
        f"{m2} 3x3 cluster windows of the normal scores (Sidak, per test {a2:.3g})"
    )
    return RgbResult(
        mode="statistical",
        pixels=h * w,
        failing_pixels=int(fail_px.sum()),
        edge=0,
        interior=int(mism.sum()),
        fail_mask=mism,
        edge_mask=np.zeros((h, w), dtype=bool),
        score=score,
        tolerance=text,
        max_abs=mx,
        mean_abs=mean,
        max_rel=rel,
        min_p=float(p.min()) if p.size else 1.0,
        alpha=alpha,
        cluster_failures=int(fail_w.sum()),
        details=details,
    )


# --------------------------------------------------------------------------- helpers


def samples_per_pixel(attrs: Mapping[str, Any]) -> float:
    """rendiff:spp as a float (inf when absent or unusable)."""
    v = attrs.get("spp")
    try:
        n = float(v) if v is not None and not isinstance(v, bool) else math.inf
    except (TypeError, ValueError):
        return math.inf
    return n if math.isfinite(n) and n >= 1 else math.inf


def degrees_of_freedom(attrs: Mapping[str, Any]) -> float:
    """nu of a side's variance: var_samples - 1 (or spp - 1); inf when neither is known."""
    for key in ("var_samples", "spp"):
        v = attrs.get(key)
        try:
            n = float(v) if v is not None and not isinstance(v, bool) else None
        except (TypeError, ValueError):
            n = None
        if n is not None and math.isfinite(n) and n >= 2:
            return n - 1.0
    return math.inf


FLIP_MIN_LUMINANCE = 4.0 * 2.0**-23
"""Below this largest reference luminance FLIP is not computed. HDR-FLIP picks its exposure
range from the reference, start = log2(k / max Y) and stop = log2(k / max(median Y, 2^-23))
(the floor measured from flip-evaluator: a median of 0 with max Y = 0.3 gives start 2.8203 and
stop 24.0833, 0.3 * 2^(2.8203 - 24.0833) = 2^-23), and when start > stop, i.e. max Y < 2^-23,
the library prints "Start exposure must be smaller than stop exposure!" and exits the whole
process (a reduced scene whose one triangle is lit at 1e-14 killed the comparison). 4x the
floor covers a luminance weighting other than Rec. 709's; such an image is black to people."""


FLIP_THREADS = "1"
"""OpenMP threads for flip-evaluator, unless OMP_NUM_THREADS already says: set before its first
import, when its bundled libgomp reads the variable (nothing else here loads libgomp). The images
are small (at most a few hundred pixels a side) and the comparison already runs a process per
core beside the renders, so a second thread only waits at OpenMP's barriers, spinning while the
other is descheduled: the main job's comparison (24 FLIP calls, 2 CPUs busy with a build
beside it) took 25.7 s with libgomp's default of one thread per CPU and 13.5 s with one thread,
FLIP's share going from 11.6 s to under 0.8 s, with the same means."""


def flip_mean(ref: np.ndarray, test: np.ndarray) -> tuple[float | None, str]:
    """Mean HDR FLIP of test against ref, or (None, why not). For people only."""
    os.environ.setdefault("OMP_NUM_THREADS", FLIP_THREADS)
    try:
        import flip_evaluator
    except Exception as exc:  # noqa: BLE001 - an optional, informational metric
        return None, f"FLIP not computed: flip-evaluator unavailable ({type(exc).__name__}: {exc})"
    r = np.ascontiguousarray(np.clip(np.nan_to_num(ref, nan=0.0, posinf=0.0), 0.0, None), dtype=np.float32)
    t = np.ascontiguousarray(np.clip(np.nan_to_num(test, nan=0.0, posinf=0.0), 0.0, None), dtype=np.float32)
    if not r.any() and not t.any():
        return 0.0, ""
    luminance = float((r @ np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)).max())
    if luminance < FLIP_MIN_LUMINANCE:
        return None, f"FLIP not computed: the reference is black to HDR-FLIP (max luminance {luminance:.3g})"
    try:
        _, mean, _ = flip_evaluator.evaluate(r, t, "HDR")
    except Exception as exc:  # noqa: BLE001
        return None, f"FLIP not computed: {type(exc).__name__}: {exc}"
    mean = float(mean)
    return (mean, "") if math.isfinite(mean) else (None, "FLIP not computed: non-finite result")
