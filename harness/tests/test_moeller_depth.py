"""The f32 t = T / den of Embree's triangle tests (tolerance.moeller_t_depth), which Embree and Mitsuba
(whose CPU variants intersect through Embree's default test) share: each term of the bound, where it is
infinite, and the fuzzer's grazing Mitsuba finding (seed 13, `s13_02458`, reduced to
scenes/fuzz_grazing_t.toml) on both sides of it (docs/verifier.md, "Depth")."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace
from typing import Any, cast

import numpy as np
import pytest

from fixtures import write_scene
from rendiff_harness.contract import resolved
from rendiff_harness.contract.manifest import Reference
from rendiff_harness.judge import depth
from rendiff_harness.judge import tolerance as tl
from rendiff_harness.renderers.mitsuba.backend import f32_sensor, mitsuba_depth

U = 2.0**-24
GAMMA5_SQRT2 = 5 * U / (1 - 5 * U) * math.sqrt(2.0)


def _ctx(z: float, cos: float, **kw: Any) -> tl.DepthContext:
    kw.setdefault("info", {})
    kw.setdefault("attrs", {})
    return tl.DepthContext(z_ref=np.array([z]), cos=np.array([cos]), **kw)


def test_the_dot_product_coefficient_is_gamma5_sqrt2() -> None:
    assert tl.MOELLER_DOT == pytest.approx(GAMMA5_SQRT2, rel=1e-15)
    assert tl.MOELLER_DIVIDE == 4 * U


def test_the_bound_is_den_s_relative_error_plus_t_s_numerator_over_den() -> None:
    z, cos, cond, extent, ray, offset = 7.0, 0.01, 3.0, 2.0, 1.2, 0.5
    ctx = _ctx(z, cos, corner_cond=np.array([cond]), extent=np.array([extent]), ray_norm=ray, origin_offset=offset)
    eps = GAMMA5_SQRT2 * cond / cos
    numerator = GAMMA5_SQRT2 * cond * (ray * z + offset + extent) / cos
    want = (eps * z + numerator) / (1 - eps) + 4 * U * z
    assert tl.moeller_t_depth(ctx)[0] == pytest.approx(want, rel=1e-12)
    # each input counts: a sliver (cond), a far vertex (extent) and a far origin (offset) all grow it
    for change in ({"corner_cond": np.array([2 * cond])}, {"extent": np.array([10 * extent])}, {"origin_offset": 9.0}):
        kw: dict[str, Any] = {
            "corner_cond": np.array([cond]),
            "extent": np.array([extent]),
            "ray_norm": ray,
            "origin_offset": offset,
        }
        kw.update(change)
        assert tl.moeller_t_depth(_ctx(z, cos, **kw))[0] > want


def test_the_bound_is_infinite_once_den_is_within_its_own_error() -> None:
    cond = 2.0
    at = GAMMA5_SQRT2 * cond  # the |cos| at which eps_den = 1
    kw: dict[str, Any] = {"corner_cond": np.array([cond]), "extent": np.array([1.0]), "ray_norm": 1.0}
    assert math.isinf(tl.moeller_t_depth(_ctx(5.0, at * (1 - 1e-9), **kw))[0])
    assert math.isinf(tl.moeller_t_depth(_ctx(5.0, 0.0, **kw))[0])
    assert math.isfinite(tl.moeller_t_depth(_ctx(5.0, at * 1.001, **kw))[0])


def test_without_the_triangle_or_the_ray_nothing_is_added() -> None:
    full: dict[str, Any] = {"corner_cond": np.array([2.0]), "extent": np.array([1.0]), "ray_norm": 1.0}
    assert tl.moeller_t_depth(_ctx(5.0, 0.5, **full))[0] > 0
    for missing in full:
        kw = {k: v for k, v in full.items() if k != missing}
        assert tl.moeller_t_depth(_ctx(5.0, 0.5, **kw)).tolist() == [0.0], missing


def test_the_corner_condition_is_one_over_the_sine_of_the_smallest_angle() -> None:
    h = math.sqrt(3.0) / 2
    tris = np.array(
        [
            [[0, 0, 0], [1, 0, 0], [0.5, h, 0]],  # equilateral: 1/sin 60
            [[0, 0, 0], [1, 0, 0], [0, 1, 0]],  # right isosceles: 1/sin 45 at the two far corners
            [[0, 0, 0], [10, 0, 0], [5, 0.1, 0]],  # a sliver: its two small angles, atan(0.02)
            [[0, 0, 0], [1, 0, 0], [2, 0, 0]],  # degenerate: collinear
            [[0, 0, 0], [0, 0, 0], [1, 1, 0]],  # degenerate: two vertices equal (0/0 at them)
        ],
        dtype=np.float32,
    )
    ref = cast(Any, SimpleNamespace(scene=SimpleNamespace(triangles=tris)))
    got = depth.triangle_corner_cond(ref, np.arange(5))
    assert got[:3].tolist() == pytest.approx([1 / h, math.sqrt(2.0), 1 / math.sin(math.atan(0.02))], rel=1e-6)
    assert got[3:].tolist() == [math.inf, math.inf]


# The finding: one triangle seen at |cos| 5.2e-5 (scenes/fuzz_grazing_t.toml), pixel (39, 0) of 96x26.
EYE = np.array([0.0, 0.0, 4.0])
TRI = np.array(
    [
        [-13.32635498046875, -10.772857666015625, -6.778167724609375],
        [2.996612548828125, 8.641204833984375, -6.778167724609375],
        [0.840057373046875, 2.421478271484375, 0.97943115234375],
    ]
)
REF_Z, MITSUBA_Z = 8.14498329, 8.16947842  # the reference's and Mitsuba 3.9.1's depth there


def _finding_ctx(tmp_path: Path) -> tl.DepthContext:
    """The verifier's own depth context at the finding's pixel: the scene written as the exporter
    resolves it, every ray and norm from the contract's camera (no projection of its own here)."""
    w, h, vfov = 96, 26, 30.308136100625195
    scene_dir = write_scene(tmp_path / "grazing", [TRI.tolist()], eye=EYE.tolist(), vfov_deg=vfov, width=w, height=h)
    ref = Reference(resolved.load(scene_dir), buffers={}, shape=(h, w))
    return depth.depth_context(ref, np.array([0]), np.array([39]), np.array([REF_Z]), np.array([0]), {}, {})


def test_the_grazing_finding_is_within_the_t_bound_and_was_beyond_the_measured_cap(tmp_path: Path) -> None:
    ctx = _finding_ctx(tmp_path)
    assert ctx.cos[0] == pytest.approx(5.2e-5, rel=0.01)
    err = abs(MITSUBA_Z - REF_Z)
    tol, _ = mitsuba_depth(ctx)
    assert err <= tol[0]
    # the bound is not vacuous: well inside the triangle's depth span, which any hit on it stays within
    assert tol[0] < 0.2 * float(np.asarray(ctx.depth_span)[0])
    # without the t term the model stopped at its measured cap, below this error: the false alarm
    old = tl.relative_grazing(ctx, 1e-5) + tl.shift_depth(ctx, tl.position_error(ctx, f32_sensor))
    assert err > old[0]
    # the error is one rounding of den at this angle: u * cond / |cos| of Z, what the bound's eps counts
    one_rounding = U * float(np.asarray(ctx.corner_cond)[0]) / ctx.cos[0] * REF_Z
    assert err == pytest.approx(one_rounding, rel=0.1)
