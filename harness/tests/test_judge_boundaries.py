"""Every class boundary of the verifier (judge/verify.py), tried from both sides on synthetic scenes.

Issue 37 item 6: faults planted in the verifier passed every test because no scene sat on the
boundary they moved (a tie that no longer asked both triangles to cover the center turned 9,962
interior pixels of `million` into ties). Each test here puts a pixel center at a distance the
scene fixes exactly and asks for the class on either side of it; docs/mutation.md lists the
mutants these tests kill.

Camera: eye (0, 0, 4) looking down -z, vfov 90, 16 x 16 pixels. On the plane z = 0 (depth 4)
a world point (x, y) projects to px = 2x + 8, py = 8 - 2y, exactly (powers of two), so the
pixel (c, r), center (c + 0.5, r + 0.5), sits at x = (c - 7.5) / 2, y = (7.5 - r) / 2 and a
world distance w on that plane is 2w pixels.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fixtures import write_scene
from rendiff_harness.contract import resolved, vocab
from rendiff_harness.contract.camera import Camera
from rendiff_harness.contract.manifest import Reference
from rendiff_harness.judge import geometry, outline, verify
from verify_cases import classify_one, exact_depth

BG = vocab.BACKGROUND_ID
PX = (4, 4)  # center (4.5, 4.5): world (-1.75, 1.75) on z = 0
BIG = [[-20, -20, 0], [20, -20, 0], [0, 20, 0]]  # covers PX, its edges more than 10 px away
# Coplanar with BIG, to the right of the vertical line x = -1.5 (px = 5): 0.5 px from PX's center.
RIGHT_OF_PX = [[-1.5, -3, 0], [3, -3, 0], [-1.5, 3, 0]]


def _scene(tmp_path: Path, tris: list[list[list[float]]], near: float = 1e-3) -> resolved.ResolvedScene:
    d = write_scene(tmp_path, tris, eye=(0.0, 0.0, 4.0), vfov_deg=90.0, width=16, height=16, near=near)
    return resolved.load(d)


def _one(scene: resolved.ResolvedScene, ref: int, test: int, px: tuple[int, int] = PX, **kw: Any) -> tuple[str, str]:
    """`classify_one` at PX unless told otherwise."""
    return classify_one(scene, ref, test, px, **kw)


def _distance(scene: resolved.ResolvedScene, prim: int, px: tuple[int, int] = PX) -> float:
    """The verifier's own distance from the center to the prim's visible boundary."""
    g = verify.side_geometry(scene, np.array([prim]), np.array([px[1]]), np.array([px[0]]))
    return float(g.poly_d[0])


# --------------------------------------------------------------------------- tie: both must cover


def test_tie_needs_the_test_triangle_to_cover_the_center(tmp_path: Path) -> None:
    """Planted fault (a): coplanar surfaces tie only where BOTH triangles cover the center.

    The test renderer drew RIGHT_OF_PX (coplanar with BIG, same depth) at a center 0.5 px
    outside it: within a rounding distance of 0.5 px it may have, beyond it it may not.
    """
    s = _scene(tmp_path, [BIG, RIGHT_OF_PX])
    d = _distance(s, 1)
    assert d == 0.5  # the scene fixes it: x = -1.5 against the center's -1.75, two px per unit
    cls, why = _one(s, 0, 1, eps=d)
    assert cls == "tie" and "prims 0 and 1 are coplanar here" in why
    cls, why = _one(s, 0, 1, eps=float(np.nextafter(d, 0.0)))
    assert cls == "interior", why
    assert "center 0.5 px outside the boundary of prim 1" in why and "the reference saw prim 0: interior" in why


def test_tie_needs_the_reference_triangle_to_cover_the_center(tmp_path: Path) -> None:
    """The same boundary with the sides swapped: the reference's triangle must cover too."""
    s = _scene(tmp_path, [BIG, RIGHT_OF_PX])
    d = _distance(s, 1)
    assert _one(s, 1, 0, eps=d)[0] == "tie"
    cls, why = _one(s, 1, 0, eps=float(np.nextafter(d, 0.0)))
    assert cls == "interior" and "the reference saw prim 1: interior" in why


def test_tie_needs_both_depths_on_their_planes(tmp_path: Path) -> None:
    """Both covering is not enough: a triangle with no depth along the ray (behind the eye) never ties."""
    behind = [[-20, -20, 8], [20, -20, 8], [0, 20, 8]]  # the plane z = 8, behind the eye at z = 4
    s = _scene(tmp_path, [BIG, behind])
    assert not np.isfinite(verify.side_geometry(s, np.array([1]), np.array([4]), np.array([4])).z[0])
    assert _one(s, 0, 1, eps=100.0)[0] != "tie"


# --------------------------------------------------------------------------- tie: depth agreement


def test_tie_allows_two_f32_roundings_of_depth_and_no_more(tmp_path: Path) -> None:
    """An exact renderer's tie: |dz| <= 0 + 2 * 2^-23 * z. At z = 4 that is 9.54e-7."""
    allowed = 2.0 * verify.F32_ULP * 4.0
    for lift, expect in ((0.75 * allowed, "tie"), (1.25 * allowed, "interior")):
        up = float(np.float32(lift))  # world z of the second copy: its depth is 4 - lift
        lifted = [[v[0], v[1], up] for v in BIG]
        s = _scene(tmp_path / expect, [BIG, lifted])
        cls, why = _one(s, 0, 1)
        assert cls == expect, (lift, why)


def test_tie_adds_the_renderers_depth_tolerance_on_both_triangles(tmp_path: Path) -> None:
    """The renderer ranks its own two depths, each off by up to its tolerance on that
    triangle, so the tie widens by exactly the sum of the two, each asked at its own
    triangle's (z, cos). Unequal shares catch a verifier that counts one side twice."""
    lift = 1e-3
    lifted = [[v[0], v[1], lift] for v in BIG]
    s = _scene(tmp_path, [BIG, lifted])
    dz = 4.0 - (4.0 - float(np.float32(lift)))
    seen: list[tuple[float, float, float]] = []

    def tol(share_0: float, share_1: float) -> verify.DepthTolerance:
        def f(z: np.ndarray, cos: np.ndarray, prims: np.ndarray) -> np.ndarray:
            seen.extend((float(a), float(b), float(c)) for a, b, c in zip(z, cos, prims, strict=True))
            return np.where(prims == 0, share_0 * dz, share_1 * dz)

        return f

    # The sum reaches dz: a tie; 1% short of it (more than the 2 roundings, 9.5e-7 of 1e-3): not.
    assert _one(s, 0, 1, depth_tol=tol(0.3, 0.7))[0] == "tie"
    assert _one(s, 0, 1, depth_tol=tol(0.3, 0.69))[0] == "interior"
    assert _one(s, 0, 1, depth_tol=tol(0.69, 0.3))[0] == "interior"
    # Either side alone, however large its share of the sum, is not enough.
    assert _one(s, 0, 1, depth_tol=tol(0.0, 0.99))[0] == "interior"
    assert _one(s, 0, 1, depth_tol=tol(0.99, 0.0))[0] == "interior"
    # Asked at each triangle's planar depth and |cos| there (PX's ray is oblique).
    g0 = verify.side_geometry(s, np.array([0]), np.array([PX[1]]), np.array([PX[0]]))
    g1 = verify.side_geometry(s, np.array([1]), np.array([PX[1]]), np.array([PX[0]]))
    assert float(g0.z[0]) != float(g1.z[0])
    assert seen[:2] == [(float(g0.z[0]), float(g0.cos[0]), 0.0), (float(g1.z[0]), float(g1.cos[0]), 1.0)]


# --------------------------------------------------------------------------- shared edge and vertex


def test_an_edge_counts_as_shared_only_when_both_its_vertices_are(tmp_path: Path) -> None:
    """Planted fault (b): R and T share the vertex V only. The center is 0.25 px from R's edge
    V-W (W not in T) and 8.5 px from V; T, nearer, covers it deeply. Not an edge R and T share:
    the reference missed T far inside T, an interior mismatch."""
    v = [-6.0, 1.875, 0.0]
    r = [v, [6.0, 1.875, 0.0], [0.0, -6.0, 0.0]]  # edge V-W at py = 4.25
    t = [v, [6.0, 8.0, 2.0], [6.0, -6.0, 2.0]]  # in front of R at PX
    s = _scene(tmp_path, [r, t])
    g = verify.side_geometry(s, np.array([0, 1]), np.array([4, 4]), np.array([4, 4]))
    assert g.edge_d[0, 0] == 0.25 and g.vert_d[0, 0] > 8.0 and g.poly_d[1] > 4.0
    cls, why = _one(s, 0, 1, eps=1.0)
    assert cls == "interior", why
    assert "inside the boundary of prim 1" in why and "the reference saw prim 0" in why
    # Both vertices shared (T hinged on the whole edge V-W): the same center is an edge.
    t2 = [v, [0.0, 8.0, 2.0], [6.0, 1.875, 0.0]]
    s = _scene(tmp_path / "hinge", [r, t2])
    cls, why = _one(s, 0, 1, eps=1.0)
    assert cls == "edge" and why == "center 0.25 px from the edge prims 0 and 1 share: edge"
    # ... only within the rounding distance of that edge.
    assert _one(s, 0, 1, eps=0.2)[0] != "edge"


def test_a_shared_edge_band_is_closed_at_eps(tmp_path: Path) -> None:
    """The band of a shared edge: distance <= eps is an edge, anything above it is not."""
    left = [[-1.5, -3, 0], [-1.5, 3, 0], [-6, 0, 0]]  # shares x = -1.5 with RIGHT_OF_PX
    s = _scene(tmp_path, [left, RIGHT_OF_PX])
    # RIGHT_OF_PX's edge x = -1.5 is local edge 2 (corner 2 -> corner 0); the center is 0.5 px away.
    assert _one(s, 0, 1, eps=0.5) == ("edge", "center 0.5 px from the edge prims 0 and 1 share: edge")
    # Just inside the band no more: the two are coplanar, so the test's prim, 0.5 px away, no longer
    # covers the center and its edge (a closed one) is out of reach: interior.
    assert _one(s, 0, 1, eps=float(np.nextafter(0.5, 0.0)))[0] == "interior"


def test_a_shared_vertex_band_is_closed_at_eps(tmp_path: Path) -> None:
    """Near only a shared vertex (not an edge through it): edge at distance <= eps."""
    v = [-1.5, 1.5, 0.0]  # px (5, 5): the center (4.5, 4.5) is sqrt(0.5) px from it
    r = [v, [-8.0, 1.5, 0.0], [-1.5, 8.0, 0.0]]  # up-left of V: covers PX
    t = [v, [6.0, -1.5, 1.0], [1.5, -6.0, 1.0]]  # down-right of V, nearer
    s = _scene(tmp_path, [r, t])
    d = float(np.hypot(0.5, 0.5))
    g = verify.side_geometry(s, np.array([0]), np.array([4]), np.array([4]))
    assert g.vert_d[0, 0] == d
    cls, why = _one(s, 0, 1, eps=d)
    assert cls == "edge" and why.startswith("center 0.71 px from the vertex prims 0 and 1 share")
    # Below it the vertex no longer explains the pixel; R's own boundary edges, 0.5 px away, still do.
    cls, why = _one(s, 0, 1, eps=float(np.nextafter(d, 0.0)))
    assert cls == "edge" and why.startswith("center 0.5 px from a mesh boundary edge of prim 0")


# --------------------------------------------------------------------------- invalid ids


@pytest.mark.parametrize("side", ["test", "ref"])
def test_an_id_one_past_the_last_triangle_names_none(tmp_path: Path, side: str) -> None:
    s = _scene(tmp_path, [BIG, RIGHT_OF_PX])
    n = s.triangle_count
    ref, test = (0, n) if side == "test" else (n, 0)
    cls, why = _one(s, ref, test, eps=100.0)
    assert (cls, why) == ("interior", f"id {n} names no triangle (the scene has {n})")
    # The last triangle is a triangle: the pair is judged by geometry (a tie here).
    ref, test = (0, n - 1) if side == "test" else (n - 1, 0)
    assert _one(s, ref, test, eps=100.0)[0] == "tie"


# --------------------------------------------------------------------------- which side missed


# Covers PX; its left edge x = -1.875 (px 4.25) is a mesh boundary 0.25 px from PX's center.
EDGE_NEAR_PX = [[-1.875, -3, 0], [3, -3, 0], [-1.875, 3, 0]]
FAR_AWAY = [[2, 2, 0], [3, 2, 0], [2, 3, 0]]  # coplanar with EDGE_NEAR_PX, far from PX


def test_a_coplanar_triangle_drawn_away_from_its_area_is_interior_even_at_the_others_edge(tmp_path: Path) -> None:
    """Equal depths: the side whose triangle does not reach the center is the one that must explain
    it. The test drew FAR_AWAY at PX; that the reference's own edge is 0.25 px away does not help."""
    s = _scene(tmp_path, [EDGE_NEAR_PX, FAR_AWAY])
    cls, why = _one(s, 0, 1, eps=0.5)
    assert cls == "interior" and "outside the boundary of prim 1" in why, why


def test_the_missed_triangles_edge_band_is_closed_at_eps(tmp_path: Path) -> None:
    """The test saw the background where the reference saw a triangle 0.25 px inside its boundary."""
    s = _scene(tmp_path, [EDGE_NEAR_PX])
    d = _distance(s, 0)
    assert d == 0.25
    assert _one(s, 0, BG, eps=d) == (
        "edge",
        "center 0.25 px from a mesh boundary edge of prim 0 (reached from prim 0): edge",
    )
    below = float(np.nextafter(d, 0.0))
    assert _one(s, 0, BG, eps=below) == (
        "interior",
        f"center 0.25 px inside the boundary of prim 0 (allowed {below:.2g} px); the test renderer saw background: "
        "interior",
    )
    # The other way round: the reference saw the background, the test drew the triangle there.
    assert _one(s, BG, 0, eps=d)[0] == "edge"
    cls, why = _one(s, BG, 0, eps=below)
    assert cls == "interior" and why.endswith("the reference saw background: interior")


def test_the_far_clip_is_an_outline_within_eps(tmp_path: Path) -> None:
    """A plane z = y cut by the far plane (depth 8, py = 12): row 11's centers are 0.5 px from the
    clip line and several px from the triangle's edges. The clip bounds what a renderer shows."""
    tilted = [[-30, -10, -10], [30, -10, -10], [0, 3, 3]]
    d = write_scene(tmp_path, [tilted], eye=(0.0, 0.0, 4.0), vfov_deg=90.0, width=16, height=16, far=8.0)
    s = resolved.load(d)
    px = (8, 11)
    g = verify.side_geometry(s, np.array([0]), np.array([px[1]]), np.array([px[0]]))
    clip = float(g.poly_d[0])
    assert clip == pytest.approx(0.5, abs=1e-12) and g.inside[0] and float(g.edge_d[0].min()) > 2.0
    cls, why = _one(s, 0, BG, px=px, eps=clip)
    assert (cls, why) == ("edge", "center 0.5 px from the near/far clip of prim 0: edge")
    cls, why = _one(s, 0, BG, px=px, eps=float(np.nextafter(clip, 0.0)))
    assert cls == "interior" and "0.5 px inside the boundary of prim 0" in why
    # Beyond the far plane nothing is visible: a center there is outside the polygon.
    g = verify.side_geometry(s, np.array([0]), np.array([13]), np.array([8]))
    assert not g.inside[0] and g.poly_d[0] == pytest.approx(1.5, abs=1e-12)


# --------------------------------------------------------------------------- crack


FOLD_A = [[-3, 0, 0], [3, 0, 0], [0, 3, 0]]  # edge y = 0 at py = 8
FLAT_B = [[3, 0, 0], [-3, 0, 0], [0, -3, 0]]  # continues FOLD_A below the edge, same plane


def test_a_closed_edge_is_a_crack_until_the_eye_is_within_the_renderers_slack_of_the_plane(tmp_path: Path) -> None:
    """Both planes are z = 0, 4 units from the eye: within a slack of 4 the renderer may see them
    edge-on (an outline), beyond it the edge is closed and a miss there leaks."""
    s = _scene(tmp_path, [FOLD_A, FLAT_B])
    px = (8, 7)  # center (8.5, 7.5): 0.5 px above the shared edge, inside FOLD_A
    cls, why = _one(s, 0, BG, px=px, eps=0.5, eye_slack=4.0 * (1 - 1e-12))
    assert cls == "crack"
    assert why == (
        "center 0.5 px from the closed edge prim 0 shares with prim 1, and no outline within 0.5 px, "
        "but the test renderer saw background behind it: crack"
    )
    cls, why = _one(s, 0, BG, px=px, eps=0.5, eye_slack=4.0 * (1 + 1e-12))
    assert cls == "edge" and "an edge of a triangle this renderer may see edge-on of prim 0" in why
    # The closed edge is out of reach below 0.5 px: the center is plainly inside prim 0.
    assert _one(s, 0, BG, px=px, eps=0.49)[0] == "interior"


def test_a_neighbor_on_the_same_side_is_a_silhouette(tmp_path: Path) -> None:
    """FOLD_A's edge y = 0 with a neighbor folding back up (behind it as seen from the eye): an outline."""
    fold = [[3, 0, 0], [-3, 0, 0], [0, 3, -3]]
    s = _scene(tmp_path, [FOLD_A, fold])
    cls, why = _one(s, 0, BG, px=(8, 7), eps=0.5)
    assert cls == "edge"
    assert why == (
        "center 0.5 px from a silhouette edge (its neighbors fold behind it, or may for this renderer) "
        "of prim 0 (reached from prim 0): edge"
    )


def test_side_is_zeroexact_depthly_at_the_slack(tmp_path: Path) -> None:
    """_side: |det| <= slack * |(b - a) x (c - a)| is edge-on; the eye's distance decides."""
    eye = np.array([0.0, 0.0, 4.0])
    a, b, c = (np.array(p, dtype=np.float64) for p in FOLD_A)
    assert outline.side(eye, a, b, c, 4.0) == 0
    assert outline.side(eye, a, b, c, float(np.nextafter(4.0, 0.0))) != 0
    assert outline.side(eye, a, b, c, 0.0) == -outline.side(eye, b, a, c, 0.0)
    assert {outline.side(eye, a, b, c, 0.0), outline.side(eye, b, a, c, 0.0)} == {1, -1}


def test_side_is_the_sign_of_orient3d_beyond_the_slack() -> None:
    """In general position: det(a - eye, b - eye, c - eye) = -37 and |(b - a) x (c - a)| = sqrt(74)
    (integer arithmetic), so the eye is 37 / sqrt(74) from the plane; at a tenth of the scale the
    determinant is -0.037, and its sign, not its size, decides."""
    eye, a, b, c = (np.array(p, dtype=np.float64) for p in ([1, 2, 5], [1, 1, 0], [4, 0, 0], [0, 4, 1]))
    dist = 37.0 / math.sqrt(74.0)
    assert outline.side(eye, a, b, c, 0.0) == -1 and outline.side(eye, b, a, c, 0.0) == 1
    assert outline.side(eye, a, b, c, dist * (1 - 1e-9)) == -1
    assert outline.side(eye, a, b, c, dist * (1 + 1e-9)) == 0
    assert outline.side(eye / 10, b / 10, a / 10, c / 10, 0.0) == 1
    assert outline.side(eye / 10, a / 10, b / 10, c / 10, dist / 10 * (1 + 1e-9)) == 0


def test_the_outline_search_walks_across_closed_edges(tmp_path: Path) -> None:
    """A strip of three coplanar triangles: the middle one's closed edges lead to the outer ones,
    whose mesh boundary within eps makes the miss an edge; out of reach, a crack."""
    a = [[-3, 0, 0], [3, 0, 0], [0, 3, 0]]
    b = [[3, 0, 0], [-3, 0, 0], [0, -0.125, 0]]  # a sliver closing a's edge y = 0, 0.25 px deep
    s = _scene(tmp_path, [a, b])
    px = (8, 7)  # 0.5 px above y = 0; b's lower edges are 0.5 + ~0.25 px away
    cls, why = _one(s, 0, BG, px=px, eps=0.5)
    assert cls == "crack" and "shares with prim 1" in why
    cls, why = _one(s, 0, BG, px=px, eps=0.8)
    assert cls == "edge" and "a mesh boundary edge of prim 1 (reached from prim 0)" in why
    # The neighbor's own edges count from the distance eps on, inclusive (the verifier's distance).
    g = verify.side_geometry(s, np.array([1]), np.array([px[1]]), np.array([px[0]]))
    lower = float(g.edge_d[0, 1:].min())
    assert g.edge_d[0, 0] == 0.5 and 0.5 < lower < 0.8
    assert _one(s, 0, BG, px=px, eps=lower)[0] == "edge"
    assert _one(s, 0, BG, px=px, eps=float(np.nextafter(lower, 0.0)))[0] == "crack"


# --------------------------------------------------------------------------- explanations and counts


def test_explanations_rank_failures_first_then_size_and_cap_at_twenty() -> None:
    # 2 interior (0 vs 1 at PX), 3 edge (0 vs bg at PX, eps 0.5), and 25 one-pixel groups.
    ref = [0, 0] + [0, 0, 0] + [0] * 25
    test = [1, 1] + [BG, BG, BG] + [1] * 25
    rows = [4, 4] + [4, 4, 4] + [4] * 25
    cols = [4, 4] + [4, 4, 4] + [4] * 25
    cls = np.array([verify.INTERIOR] * 2 + [verify.EDGE] * 3 + [verify.TIE] * 25, dtype=np.int8)
    why = [f"w{i}" for i in range(30)]
    r_ids = np.array(ref, dtype=np.uint64)
    t_ids = np.array(test, dtype=np.uint64)
    t_ids[5:] = np.arange(100, 125)  # 25 distinct test prims: 25 tie groups of one pixel
    groups = verify.explain(cls, why, r_ids, t_ids, np.array(rows), np.array(cols))
    assert len(groups) == verify.MAX_EXPLANATIONS == 20
    assert groups[0] == {
        "class": "interior",
        "ref_prim": 0,
        "test_prim": 1,
        "pixels": 2,
        "example": [4, 4],
        "why": "w0",
    }
    assert groups[1] == {"class": "tie", "ref_prim": 0, "test_prim": 100, "pixels": 1, "example": [4, 4], "why": "w5"}
    # Edges rank last: the cap drops them before any tie.
    assert all(g["class"] == "tie" for g in groups[1:])
    groups = verify.explain(cls[:5], why[:5], r_ids[:5], t_ids[:5], np.array(rows[:5]), np.array(cols[:5]))
    assert groups[1] == {"class": "edge", "ref_prim": 0, "test_prim": None, "pixels": 3, "example": [4, 4], "why": "w2"}
    assert verify.counts(cls) == {"edge": 3, "tie": 25, "crack": 0, "interior": 2}


def test_explanations_order_crack_before_tie_and_larger_groups_first() -> None:
    cls = np.array([verify.EDGE, verify.TIE, verify.CRACK, verify.TIE, verify.EDGE, verify.EDGE], dtype=np.int8)
    r = np.array([1, 2, 3, 2, 5, 5], dtype=np.uint64)
    t = np.array([BG, 9, BG, 9, 6, 6], dtype=np.uint64)
    rows, cols = np.arange(6), np.arange(6) + 10
    groups = verify.explain(cls, [str(i) for i in range(6)], r, t, rows, cols)
    assert [(g["class"], g["pixels"], g["example"]) for g in groups] == [
        ("crack", 1, [12, 2]),
        ("tie", 2, [11, 1]),
        ("edge", 2, [14, 4]),
        ("edge", 1, [10, 0]),
    ]
    assert groups[3]["ref_prim"] == 1 and groups[3]["test_prim"] is None
    assert verify.explain(cls, ["x"] * 6, np.full(6, BG, dtype=np.uint64), t, rows, cols)[0]["ref_prim"] is None


def _fan(wedges: int) -> list[list[list[float]]]:
    """`wedges` coplanar triangles around the apex V at PX's center, spanning 300 degrees: every
    edge through V is closed except the first and the last (mesh boundaries)."""
    v = [-1.75, 1.75, 0.0]
    rim = [[v[0] + 2 * math.cos(a), v[1] + 2 * math.sin(a), 0.0] for a in np.radians(np.linspace(0, 300, wedges + 1))]
    return [[v, rim[i], rim[i + 1]] for i in range(wedges)]


def test_the_outline_search_stops_after_max_patch_triangles(tmp_path: Path) -> None:
    """The walk from wedge 1 (its edges through V both closed) goes first towards the last wedge,
    whose edge is an outline. Wedge k is reached with 2 + (k - 1) triangles seen (wedges 0 and
    1..k), and looked at while no more than MAX_PATCH are: a last wedge MAX_PATCH - 1 is
    reached, one more and the patch counts as closed."""
    n = outline.MAX_PATCH
    s = _scene(tmp_path / "in", _fan(n))
    cls, why = _one(s, 1, BG, eps=0.5)
    assert cls == "edge" and f"a mesh boundary edge of prim {n - 1}" in why, why
    s = _scene(tmp_path / "out", _fan(n + 1))
    assert _one(s, 1, BG, eps=0.5)[0] == "crack"


def test_the_outline_search_follows_every_neighbor_across_a_shared_edge(tmp_path: Path) -> None:
    """A non-manifold edge: S, X and P fan around V (PX's center), and D lies over X on the edge
    V-C that X and P share; D's other edge through V is a mesh boundary. The walk reaches X and
    P first, and from each of them sees across V-C one neighbor already queued (P or X) before
    D: D must still be visited, and its outline makes the miss an edge."""
    v = [-1.75, 1.75, 0.0]
    a, b, c, d = ([v[0] + 3 * math.cos(t), v[1] + 3 * math.sin(t), 0.0] for t in np.radians([0, 120, 240, 300]))
    s_, x_, p_, d_ = [v, a, b], [v, c, a], [v, b, c], [v, c, d]
    s = _scene(tmp_path, [s_, x_, p_, d_])
    topo = verify.topology(s.triangles)
    assert [t for t, _ in topo.neighbors(2, 2)] == [1, 3]  # P across V-C: X, then D
    cls, why = _one(s, 0, BG, eps=0.5)
    assert cls == "edge" and "a mesh boundary edge of prim 3 (reached from prim 0)" in why, why
    # Without D the fan is closed all round: a crack.
    s = _scene(tmp_path / "closed", [s_, x_, p_])
    assert _one(s, 0, BG, eps=0.5)[0] == "crack"


def test_the_slack_boundary_is_taken_in_f64_from_the_f32_vertices(tmp_path: Path) -> None:
    """Corners whose f32 differences round (3.3 - -3.1 needs more bits than f32 has): the plane
    z = 0 is 4 from the eye, and the edge-on test |det| <= slack |(b - a) x (c - a)| must hold
    at 4 (1 + 1e-9) and fail at 4 (1 - 1e-9), as computed in f64, where f32 would err ~1e-7."""
    a = [[-3.1, 0.1, 0], [3.3, 0.1, 0], [0.2, 3.7, 0]]
    b = [[3.3, 0.1, 0], [-3.1, 0.1, 0], [0.3, -2.9, 0]]
    s = _scene(tmp_path, [a, b])
    px = (8, 7)  # center (8.5, 7.5): 0.3 px above the shared edge y = 0.1 (py 7.8)
    assert _one(s, 0, BG, px=px, eps=0.5, eye_slack=4.0 * (1 - 1e-9))[0] == "crack"
    assert _one(s, 0, BG, px=px, eps=0.5, eye_slack=4.0 * (1 + 1e-9))[0] == "edge"


def test_a_neighbor_seen_edge_on_does_not_close_the_edge(tmp_path: Path) -> None:
    """FOLD_A's edge y = 0 with a neighbor hanging straight down in the plane y = 0, which holds
    the eye: the renderer sees it edge-on, on neither side, so the edge is an outline."""
    hanging = [[3, 0, 0], [-3, 0, 0], [0, 0, -3]]
    s = _scene(tmp_path, [FOLD_A, hanging])
    eye = np.array([0.0, 0.0, 4.0])
    a, b = np.array(FOLD_A[0], dtype=np.float64), np.array(FOLD_A[1], dtype=np.float64)
    assert outline.side(eye, a, b, np.array([0.0, 0.0, -3.0]), 0.0) == 0
    cls, why = _one(s, 0, BG, px=(8, 7), eps=0.5)
    assert cls == "edge" and "a silhouette edge" in why, why


# --------------------------------------------------------------------------- clipping at near and far


def _visible_distances(
    cam: Camera, tri: np.ndarray, near: float, far: float, cx: np.ndarray, cy: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The spec of side_geometry's edge and vertex distances, written apart: each edge's part with
    near <= depth <= far, projected, its distance from each center (inf: none visible); each vertex
    within [near, far], its distance (inf otherwise)."""
    ct = cam.to_camera(tri)
    edge = np.full((cx.size, 3), np.inf)
    vert = np.full((cx.size, 3), np.inf)
    for i in range(3):
        a, b = ct[i], ct[(i + 1) % 3]
        dz = b[2] - a[2]
        if dz == 0:
            lo, hi = (0.0, 1.0) if near <= a[2] <= far else (1.0, 0.0)
        else:
            tn, tf = (near - a[2]) / dz, (far - a[2]) / dz if math.isfinite(far) else math.copysign(math.inf, dz)
            lo, hi = (max(0.0, tn), min(1.0, tf)) if dz > 0 else (max(0.0, tf), min(1.0, tn))
        if lo <= hi:
            p, q = (cam.to_pixel(*(a + t * (b - a))) for t in (lo, hi))
            edge[:, i] = geometry.segment_distance(cx, cy, np.tile(p, (cx.size, 1)), np.tile(q, (cx.size, 1)))
        if near <= a[2] <= far:
            pv = cam.to_pixel(*a)
            vert[:, i] = np.hypot(pv[0] - cx, pv[1] - cy)
    return edge, vert


CLIP_CASES = {
    # name: (near, far, triangles); eye (0, 0, 4) looking down -z: depth = 4 - z
    "crossing near and far": (1.0, 6.0, [[[0, -1, 2], [2, -1, 4], [0, 1, 2]], [[0, 0, -4], [1, 1, 0], [-1, 1, -4]]]),
    "flat edges on near and far": (
        1.0,
        6.0,
        [[[-1, -1, 3], [1, -1, 3], [0, 1, 0]], [[-1, -1, -2], [1, -1, -2], [0, 1, 0]]],
    ),
    "flat edges beyond near and far": (
        1.0,
        6.0,
        [[[-1, -1, 3.5], [1, -1, 3.5], [0, 1, 0]], [[-1, -1, -3], [1, -1, -3], [0, 1, 0]]],
    ),
    "near at 0.5": (0.5, None, [[[0, -1, 2], [2, -1, 3.75], [0, 1, 3.25]]]),
    "far equal to near": (2.0, 2.0, [[[0, -1, -1], [2, -1, 3], [0, 1, 1]]]),
    # one vertex exactly on the plane, the others beyond: each edge through it is visible as a point
    "touching near and far": (1.0, 6.0, [[[0, 0, -2], [1, 0, -4], [0, 1, -4]], [[0, 0, 3], [1, 0, 3.5], [0, 1, 3.5]]]),
}


@pytest.mark.parametrize("case", sorted(CLIP_CASES))
def test_edge_and_vertex_distances_see_only_what_lies_between_near_and_far(tmp_path: Path, case: str) -> None:
    near, far, tris = CLIP_CASES[case]
    d = write_scene(tmp_path, tris, eye=(0.0, 0.0, 4.0), vfov_deg=90.0, width=16, height=16, near=near, far=far)
    s = resolved.load(d)
    cols, rows = (g.ravel() for g in np.meshgrid(np.arange(-8, 25, 4), np.arange(-8, 25, 4)))
    cx, cy = s.camera.pixel_centers(cols, rows)
    eff_far = far if far is not None and far > near else math.inf
    for prim in range(len(tris)):
        g = verify.side_geometry(s, np.full(cols.size, prim), rows, cols)
        edge, vert = _visible_distances(s.camera, s.triangles[prim].astype(np.float64), near, eff_far, cx, cy)
        assert np.allclose(g.edge_d, edge, rtol=1e-9, atol=1e-9), (prim, g.edge_d, edge)
        assert np.array_equal(np.isinf(g.vert_d), np.isinf(vert)) and np.allclose(g.vert_d, vert, rtol=1e-12), prim
        assert np.isfinite(g.edge_d).any(), prim  # something of every triangle is visible


def test_without_a_near_plane_the_eye_plane_is_pushed_to_1e_12_of_the_scene(tmp_path: Path) -> None:
    """near 0: a vertex counts as in front of the eye from 1e-12 x max(1, largest camera coordinate)
    on. A unit triangle's corner at depth 1.5e-12 is in front; a size-10 one's at 5e-12 is not."""
    unit = [[0.5, 0.5, -1.5e-12], [1, 0, -1], [0, 1, -1]]
    big = [[0.5, 0.5, -5e-12], [10, 0, -10], [0, 10, -10]]
    d = write_scene(tmp_path, [unit, big], eye=(0.0, 0.0, 0.0), look_at=(0.0, 0.0, -1.0), near=0.0, width=4, height=4)
    s = resolved.load(d)
    g0, g1 = (verify.side_geometry(s, np.array([p]), np.array([1]), np.array([1])) for p in (0, 1))
    assert np.isfinite(g0.vert_d[0, 0]) and np.isinf(g1.vert_d[0, 0])
    assert np.isfinite(g0.vert_d[0, 1:]).all() and np.isfinite(g1.vert_d[0, 1:]).all()


def test_a_side_without_a_triangle_has_no_geometry(tmp_path: Path) -> None:
    """The background or an unknown id: every distance infinite, outside, no depth, cos 0; a ray
    along the triangle's plane has no depth either, quietly."""
    # The plane 16 x - 7 z = -16 holds the direction (-7/16, sy, -1) of every ray of column 4.
    wall = [[-1, -5, 0], [-1, 5, 0], [-0.125, 0, 2]]
    d = write_scene(tmp_path, [BIG, wall], eye=(0.0, 0.0, 4.0), vfov_deg=90.0, width=16, height=16)
    s = resolved.load(d)
    for prims in ([BG, 5], [BG]):
        k = len(prims)
        g = verify.side_geometry(s, np.array(prims, dtype=np.uint32), np.zeros(k, np.int64), np.zeros(k, np.int64))
        assert g.edge_d.shape == g.vert_d.shape == (k, 3)
        assert np.isinf(g.edge_d).all() and np.isinf(g.vert_d).all() and np.isinf(g.poly_d).all()
        assert not g.inside.any() and not g.valid.any() and np.isinf(g.z).all() and (g.cos == 0).all()
    g = verify.side_geometry(s, np.array([1]), np.array([4]), np.array([4]))  # px 4.5: sx = -7/16
    assert np.isinf(g.z[0]) and g.cos[0] == 0.0


def test_topology_identity_isexact_depth_f32() -> None:
    """Two vertices are one when their f32 coordinates are equal, whatever f64 values they came from."""
    a = [0.1, 0.0, 0.0]
    a2 = [0.1 + 1e-12, 0.0, 0.0]  # the same f32
    b = [1e-8, 0.0, 1.0]  # not (0, 0, 1)
    topo = verify.topology([[a, [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], [a2, [0.0, 1.0, 0.0], b]])
    assert topo.neighbors(0, 0) == [(1, 0)] and topo.neighbors(0, 2) == [] and topo.vertices == 4
    empty = verify.topology(np.zeros((0, 3, 3), dtype=np.float32))
    assert empty.vertices == 0 and empty.keys.size == 0


# --------------------------------------------------------------------------- classify_mismatches' plumbing


def test_the_tie_band_is_inclusive(tmp_path: Path) -> None:
    """Depths 4 and 4 - 2^-10, exact; a renderer tolerance of (2^-10 - 2^-20) / 2 on each
    triangle plus the two f32 roundings 2 * 2^-23 * 4 = 2^-20 is exactly 2^-10: a tie; any
    less is not."""
    lifted = [[v[0], v[1], 2.0**-10] for v in BIG]
    s = _scene(tmp_path, [BIG, lifted])

    def tol(value: float) -> verify.DepthTolerance:
        return lambda z, cos, prims: np.full_like(z, value)

    half = (2.0**-10 - 2.0**-20) / 2.0
    assert _one(s, 0, 1, depth_tol=tol(half))[0] == "tie"
    assert _one(s, 0, 1, depth_tol=tol(float(np.nextafter(half, 0.0))))[0] == "interior"


def test_the_eye_slack_defaults_to_none(tmp_path: Path) -> None:
    """Without an eye slack a closed edge 0.5 from the eye is closed (a crack), not edge-on."""
    d = write_scene(tmp_path, [FOLD_A, FLAT_B], eye=(0.0, 0.0, 0.5), vfov_deg=90.0, width=16, height=16)
    s = resolved.load(d)
    args = (np.array([0], np.uint32), np.array([BG], np.uint32), np.array([7]), np.array([8]), 0.5, exact_depth)
    assert verify.CLASSES[int(verify.classify_mismatches(s, *args).cls[0])] == "crack"


def test_every_pixel_is_classified_whatever_comes_before_it(tmp_path: Path) -> None:
    """An id naming no triangle, then background on both sides (no triangle either way), then a shared
    edge: each gets its own class and sentence; classes are int8."""
    s = _scene(tmp_path, [FOLD_A, FLAT_B])
    n = s.triangle_count
    res = verify.classify_mismatches(
        s,
        np.array([n, BG, BG, 0], np.uint32),
        np.array([0, BG, n, 1], np.uint32),
        np.array([7, 7, 7, 7]),
        np.array([8, 8, 8, 8]),
        0.5,
        exact_depth,
    )
    assert res.cls.dtype == np.int8
    assert [verify.CLASSES[c] for c in res.cls] == ["interior", "interior", "interior", "edge"]
    assert res.why[:3] == [f"id {n} names no triangle (the scene has {n})", "both sides name no triangle"] + [
        f"id {n} names no triangle (the scene has {n})"
    ]
    empty = verify.classify_mismatches(
        s, *(np.zeros(0, np.uint32),) * 2, *(np.zeros(0, np.int64),) * 2, 0.5, exact_depth
    )
    assert empty.cls.dtype == np.int8 and empty.why == [] and empty.groups == []


def test_the_topology_is_cached_under_topo_and_read_back(tmp_path: Path) -> None:
    """The edge table is built once per scene: stored in the cache, and a cached one is used."""
    s = _scene(tmp_path, [FOLD_A, FLAT_B])
    args = (np.array([0], np.uint32), np.array([1], np.uint32), np.array([7]), np.array([8]), 0.5, exact_depth)
    cache: dict[str, verify.Topology] = {}
    assert verify.CLASSES[int(verify.classify_mismatches(s, *args, cache).cls[0])] == "edge"
    assert set(cache) == {"topo"} and cache["topo"].vertices == 4
    # A cached table in which the two triangles share nothing: no shared edge, the pixel is judged
    # as the test's triangle drawn 0.5 px outside itself.
    apart = {"topo": verify.topology(np.array([FOLD_A, [[3, 0, 1], [-3, 0, 1], [0, -3, 1]]], np.float32))}
    res = verify.classify_mismatches(s, *args, apart)
    assert "share" not in res.why[0], res.why[0]


def test_explanations_put_interior_before_a_larger_crack_group() -> None:
    cls = np.array([verify.CRACK, verify.CRACK, verify.INTERIOR], dtype=np.int8)
    r = np.array([1, 1, 2], dtype=np.uint64)
    t = np.array([BG, BG, 3], dtype=np.uint64)
    groups = verify.explain(cls, ["a", "b", "c"], r, t, np.arange(3), np.arange(3))
    assert [(g["class"], g["pixels"]) for g in groups] == [("interior", 1), ("crack", 2)]


def test_planar_depth_and_cos_agree_with_separate_computations(tmp_path: Path) -> None:
    """side_geometry's z against a ray-triangle solve and its |cos| against Reference.ray_cos, on a
    tilted triangle, a small one (|n| |d| < 1), one whose n . d is exactly 1, a degenerate one, one
    whose plane holds the eye and one at depth 0.5: z is inf where there is no depth in front."""
    tris = [
        [[-8.0, -8.0, -1.0], [8.0, -8.0, 0.3], [0.0, 8.0, 1.7]],
        [[0, 0, 0], [0.5, 0, 0], [0, 0.5, 0]],
        [[0, 0, 0], [0, 1, 0], [1, 0, 0]],
        [[0, 0, 0], [1, 1, 0], [2, 2, 0]],
        [[-20, 0, -20], [20, 0, -20], [0, 0, 20]],
        [[-20, -20, 3.5], [20, -20, 3.5], [0, 20, 3.5]],
    ]
    s = _scene(tmp_path, tris)
    ref = Reference(s, {}, (16, 16))
    cols, rows = (g.ravel() for g in np.meshgrid(np.arange(0, 16, 3), np.arange(0, 16, 3)))
    for prim in range(len(tris)):
        prims = np.full(cols.size, prim)
        g = verify.side_geometry(s, prims, rows, cols)
        assert np.allclose(g.cos, ref.ray_cos(rows, cols, prims), rtol=1e-12, atol=1e-15), prim
        t = s.triangles[prim].astype(np.float64)
        d = s.camera.center_directions(rows, cols)
        for k in range(cols.size):
            m = np.stack([d[k], t[0] - t[1], t[0] - t[2]], axis=1)
            if abs(np.linalg.det(m)) < 1e-12:
                want = math.inf  # degenerate, or the ray along the plane
            else:
                z = float(np.linalg.solve(m, t[0] - s.camera.eye)[0])
                want = z if z > 1e-9 else math.inf  # the plane through the eye: 0 up to the solve's rounding
            assert g.z[k] == pytest.approx(want, rel=1e-12), (prim, k)
    assert verify.side_geometry(s, np.array([2]), np.array([4]), np.array([4])).z[0] == 4.0  # n . d = 1


def test_a_center_on_an_edge_is_inside(tmp_path: Path) -> None:
    """The visible polygon's inside test includes its boundary: PX's center (x = -1.75) lies on the
    edge x = -1.75 of one triangle, 0.25 px inside another, 0.25 px outside a third."""
    on = [[-1.75, -3, 0], [3, -3, 0], [-1.75, 3, 0]]
    s = _scene(tmp_path, [on, EDGE_NEAR_PX, RIGHT_OF_PX, [[-1.75, 3, 0], [3, -3, 0], [-1.75, -3, 0]]])
    g = verify.side_geometry(s, np.array([0, 1, 2, 3]), np.full(4, PX[1]), np.full(4, PX[0]))
    assert g.inside.tolist() == [True, True, False, True]  # either winding
    assert g.poly_d.tolist() == [0.0, 0.25, 0.5, 0.0]
