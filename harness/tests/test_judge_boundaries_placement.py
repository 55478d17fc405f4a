"""The normal's placement term (normals.placement_angle, the `placement` of a backend that places
vertices itself, such as mitsuba_file): its derivation on both sides of each boundary.

Moving every vertex by at most p moves each edge by at most 2p, so the cross product c = e1 x e2
by at most |dc| = 2p (|e1| + |e2|) + 4p^2, and c turns by at most asin(|dc| / |c|), or any
direction (pi) once |dc| >= |c|. The expected values below are that sentence, computed here."""

from __future__ import annotations

import math
import warnings

import numpy as np

from rendiff_harness.judge import normals


def _derived(p: float, e1: np.ndarray, e2: np.ndarray, length: float) -> float:
    dc = 2.0 * p * (math.hypot(*e1) + math.hypot(*e2)) + 4.0 * p * p
    return math.asin(dc / length) if dc < length else math.pi


def _angle(p: float, e1: np.ndarray, e2: np.ndarray, length: float) -> float:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the term silences the warnings it expects, no others
        out = normals.placement_angle(p, e1[None, :], e2[None, :], np.array([length]))
    assert out.shape == (1,)
    return float(out[0])


E1 = np.array([3.0, 0.0, 0.0])
E2 = np.array([1.0, 2.0, 0.0])


def test_no_placement_turns_no_normal() -> None:
    for p in (0.0, -1e-3):
        # A zero-length cross product too: no placement, nothing to turn (not "any direction").
        out = normals.placement_angle(p, np.zeros((4, 3)), np.zeros((4, 3)), np.array([1.0, 0.0, 2.0, 0.0]))
        assert out.shape == (4,) and not out.any()


def test_the_angle_is_the_derived_asin_and_bounds_every_move() -> None:
    length = float(np.linalg.norm(np.cross(E1, E2)))
    p = 1e-3
    want = _derived(p, E1, E2, length)
    assert _angle(p, E1, E2, length) == want
    rng = np.random.default_rng(11)
    c = np.cross(E1, E2)
    worst = 0.0
    for _ in range(500):
        d = rng.normal(size=(3, 3))
        d *= p / np.linalg.norm(d, axis=1)[:, None]
        c2 = np.cross(E1 + d[1] - d[0], E2 + d[2] - d[0])
        worst = max(worst, math.atan2(float(np.linalg.norm(np.cross(c, c2))), float(c @ c2)))
    assert worst <= want
    assert worst > want / 4.0  # a bound, not a wild overestimate


def test_the_angle_is_any_direction_exactly_from_a_change_as_long_as_the_cross_product() -> None:
    p = 0.125  # 2p (|e1| + |e2|) + 4p^2 is computed the same way in both places
    dc = 2.0 * p * (np.linalg.norm(E1) + np.linalg.norm(E2)) + 4.0 * p * p
    assert _angle(p, E1, E2, float(dc)) == math.pi
    above = float(np.nextafter(dc, np.inf))
    got = _angle(p, E1, E2, above)
    assert got == _derived(p, E1, E2, above) and got < math.pi / 2 + 1e-6
    assert _angle(p, E1, E2, float(dc) / 2.0) == math.pi  # |dc| > |c|: pi, not asin of more than 1


def test_a_degenerate_triangle_may_turn_any_way_without_a_warning() -> None:
    assert _angle(1e-6, E1, E2, 0.0) == math.pi
