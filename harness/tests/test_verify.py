"""verify.py: every ID mismatch gets the class the geometry gives it (edge, tie, crack, interior)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fixtures import write_scene
from rendiff_harness.contract import resolved, vocab
from rendiff_harness.judge import verify
from verify_cases import classify_one as _one
from verify_cases import exact_depth as _exact

BG = vocab.BACKGROUND_ID

# Camera: eye (0, 0, 5) looking down -z, vfov 90, 16 x 16. A point at depth z = 5 - world_z
# projects to px = (x/z + 1) * 8, py = (1 - y/z) * 8.
# Full-screen square at world z = 0 split along its diagonal px + py = 16: pixel (7, 8)
# has its center (7.5, 8.5) exactly on the shared diagonal.
T0 = [[-5, -5, 0], [5, -5, 0], [5, 5, 0]]
T1 = [[-5, -5, 0], [5, 5, 0], [-5, 5, 0]]
# A triangle in front (world z = 2.5, depth 2.5): bottom edge at py = 11.2.
FRONT = [[-1, -1, 2.5], [1, -1, 2.5], [0, 1, 2.5]]
ON_DIAGONAL = (7, 8)
INSIDE_FRONT_NEAR_BOTTOM = (8, 10)  # center (8.5, 10.5): 0.7 px above the bottom edge
DEEP_IN_FRONT = (8, 7)


def _scene(tmp_path: Path, tris: list[list[list[float]]]) -> resolved.ResolvedScene:
    d = write_scene(tmp_path / "s", tris, vfov_deg=90.0, width=16, height=16)
    return resolved.load(d)


def test_other_triangle_across_a_shared_edge_is_edge(tmp_path: Path) -> None:
    s = _scene(tmp_path, [T0, T1])
    cls, why = _one(s, 0, 1, ON_DIAGONAL)
    assert cls == "edge" and "prims 0 and 1 share" in why


def test_background_through_a_closed_edge_is_a_crack(tmp_path: Path) -> None:
    s = _scene(tmp_path, [T0, T1])
    cls, why = _one(s, 0, BG, ON_DIAGONAL)
    assert cls == "crack" and "saw background" in why


def test_far_from_any_edge_is_interior(tmp_path: Path) -> None:
    s = _scene(tmp_path, [T0, T1, FRONT])
    cls, why = _one(s, 2, 0, DEEP_IN_FRONT)
    assert cls == "interior" and "inside the boundary of prim 2" in why


def test_near_a_boundary_edge_is_edge_only_within_the_rounding_distance(tmp_path: Path) -> None:
    s = _scene(tmp_path, [T0, T1, FRONT])
    cls, why = _one(s, 2, 0, INSIDE_FRONT_NEAR_BOTTOM, eps=0.75)
    assert cls == "edge" and "mesh boundary" in why
    assert _one(s, 2, 0, INSIDE_FRONT_NEAR_BOTTOM, eps=0.5)[0] == "interior"
    # The nearer triangle drawn by the test where the reference saw the plane: same edge decides.
    assert _one(s, 0, 2, INSIDE_FRONT_NEAR_BOTTOM, eps=0.75)[0] == "edge"


def test_fold_seen_edge_on_is_a_silhouette_not_a_crack(tmp_path: Path) -> None:
    # Edge y = 0 (py = 8) shared by A (in the z = 0 plane, above it) and B folding backwards and
    # up: both third vertices project above the edge, so below it nothing continues.
    a = [[-3, 0, 0], [3, 0, 0], [0, 3, 0]]
    fold = [[3, 0, 0], [-3, 0, 0], [0, 3, -3]]
    flat = [[3, 0, 0], [-3, 0, 0], [0, -3, 0]]
    s = _scene(tmp_path / "fold", [a, fold])
    cls, why = _one(s, 0, BG, (8, 7), eps=0.6)  # center (8.5, 7.5): 0.5 px above the edge
    assert cls == "edge" and "silhouette" in why
    s = _scene(tmp_path / "flat", [a, flat])
    assert _one(s, 0, BG, (8, 7), eps=0.6)[0] == "crack"


def test_duplicate_and_coplanar_triangles_tie(tmp_path: Path) -> None:
    s = _scene(tmp_path, [T0, T1, T0])
    cls, why = _one(s, 0, 2, (12, 4))  # inside T0 and its duplicate, far from edges
    assert cls == "tie" and "identical triangles" in why
    # A coplanar triangle of other vertices covering the same center: tie too.
    other = [[-3, -5, 0], [5, -5, 0], [5, 3, 0]]  # covers centers with px + py > 19.2
    s = _scene(tmp_path / "cop", [T0, T1, other])
    cls, why = _one(s, 0, 2, (14, 13))
    assert cls == "tie" and "coplanar" in why


def test_tie_needs_depths_within_the_tolerance(tmp_path: Path) -> None:
    lifted = [[v[0], v[1], 1e-4] for v in T0]  # 1e-4 in front of T0
    s = _scene(tmp_path, [T0, T1, lifted])
    assert _one(s, 2, 0, (12, 4))[0] == "interior"

    def loose(z: np.ndarray, cos: np.ndarray, prims: np.ndarray) -> np.ndarray:
        return np.full_like(z, 2e-4)

    assert _one(s, 2, 0, (12, 4), depth_tol=loose)[0] == "tie"


def test_ids_naming_no_triangle_are_interior_even_on_an_edge(tmp_path: Path) -> None:
    s = _scene(tmp_path, [T0, T1])
    cls, why = _one(s, 0, 77, ON_DIAGONAL, eps=10.0)
    assert cls == "interior" and "names no triangle" in why


def test_topology_shares_exact_f32_vertices_only() -> None:
    tris = np.array([T0, T1, [[-5, -5, 0], [5, -5, -0.0], [5, 5, 1e-7]]], dtype=np.float32)
    topo = verify.topology(tris)
    assert sorted(topo.neighbors(0, 2)) == [(1, 0)]  # the diagonal (5,5)-(-5,-5)
    assert (2, 0) in topo.neighbors(0, 0)  # -0.0 is the same vertex as 0.0
    assert topo.neighbors(0, 1) == []  # (5,5,0) is not (5,5,1e-7)


def test_explanations_group_pairs_failures_first(tmp_path: Path) -> None:
    s = _scene(tmp_path, [T0, T1, FRONT])
    rows = np.array([8, 8, 7])
    cols = np.array([7, 7, 8])
    res = verify.classify_mismatches(
        s, np.array([0, 0, 2], dtype=np.uint32), np.array([1, 1, 0], dtype=np.uint32), rows, cols, 1e-3, _exact
    )
    assert [g["class"] for g in res.groups] == ["interior", "edge"]
    assert res.groups[1]["pixels"] == 2 and res.groups[1]["ref_prim"] == 0 and res.groups[1]["test_prim"] == 1
    assert verify.counts(res.cls) == {"edge": 2, "tie": 0, "crack": 0, "interior": 1}


@pytest.mark.parametrize("n", [0])
def test_no_mismatches(tmp_path: Path, n: int) -> None:
    s = _scene(tmp_path, [T0])
    e = np.zeros(n, dtype=np.uint32)
    res = verify.classify_mismatches(s, e, e, e.astype(np.int64), e.astype(np.int64), 1e-3, _exact)
    assert res.cls.size == 0 and res.groups == []


def test_a_sliver_neighbor_whose_outline_is_within_reach_makes_it_an_edge(tmp_path: Path) -> None:
    # a's edge y = 0 (py = 8) is closed by a sliver reaching down to y = -0.1 (py <= 8.16),
    # whose boundary is ~0.64 px from the center (8.5, 7.5): a renderer whose rounding
    # reaches that far may legitimately pass below the whole surface.
    a = [[-3, 0, 0], [3, 0, 0], [0, 3, 0]]
    sliver = [[3, 0, 0], [-3, 0, 0], [0, -0.1, 0]]
    s = _scene(tmp_path, [a, sliver])
    assert _one(s, 0, BG, (8, 7), eps=0.6)[0] == "crack"
    cls, why = _one(s, 0, BG, (8, 7), eps=0.7)
    assert cls == "edge" and "of prim 1" in why


def test_an_eye_close_to_a_plane_opens_the_edge(tmp_path: Path) -> None:
    # Flat neighbors seen from 5 units away: closed, unless the renderer may move the eye by
    # more than its distance to their planes (5), when either may turn edge-on.
    a = [[-3, 0, 0], [3, 0, 0], [0, 3, 0]]
    flat = [[3, 0, 0], [-3, 0, 0], [0, -3, 0]]
    s = _scene(tmp_path, [a, flat])
    x, y = 8, 7
    args = (
        s,
        np.array([0], dtype=np.uint32),
        np.array([BG], dtype=np.uint32),
        np.array([y]),
        np.array([x]),
        0.6,
        _exact,
    )
    assert verify.CLASSES[int(verify.classify_mismatches(*args, eye_slack=4.9).cls[0])] == "crack"
    assert verify.CLASSES[int(verify.classify_mismatches(*args, eye_slack=5.1).cls[0])] == "edge"
