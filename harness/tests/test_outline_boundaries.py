"""The outline answers of judge/outline.py at their boundaries, on a flat square of two triangles
seen from eye (0, 0, 4): the shared diagonal is closed (its neighbor named, as an integer), the
other edges are mesh boundaries, and the eye's distance from the plane (4, exact here: the corners
are small integers) is where an edge becomes one this renderer may see edge-on. The determinant
goes through an LU factorization, a few units of 2^-53 off, so the slack is taken 1e-6 (relative)
either side of the distance: outside the rounding and outside outline.UNDECIDED_REL, so the batched
answer is the one tested, and `side` (the exact test) is checked on its own."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fixtures import write_scene
from rendiff_harness.contract import resolved
from rendiff_harness.judge import outline, verify

SQUARE = [
    [[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0]],  # edge 2 is the diagonal
    [[-1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]],  # edge 0 is the diagonal
]


def _scene(tmp_path: Path) -> resolved.ResolvedScene:
    return resolved.load(write_scene(tmp_path / "s", SQUARE, eye=(0.0, 0.0, 4.0), width=16, height=16))


def test_the_shared_diagonal_is_closed_by_the_other_triangle_and_the_rest_are_boundaries(tmp_path: Path) -> None:
    scene = _scene(tmp_path)
    topo = verify.topology(scene.triangles)
    got = outline.silhouettes(scene, topo, [(0, 2), (0, 0), (1, 0), (1, 1), (0, 1)], 0.0)
    assert got == [
        (False, "1"),
        (True, outline.BOUNDARY),
        (False, "0"),
        (True, outline.BOUNDARY),
        (True, outline.BOUNDARY),
    ]


def test_an_edge_is_edge_on_from_a_slack_of_the_eyes_distance_to_the_plane(tmp_path: Path) -> None:
    scene = _scene(tmp_path)
    topo = verify.topology(scene.triangles)
    distance = float(scene.camera.eye[2])  # the plane is z = 0
    over, under = distance * (1.0 + 1e-6), distance * (1.0 - 1e-6)
    at = outline.silhouettes(scene, topo, [(0, 2)], over)
    below = outline.silhouettes(scene, topo, [(0, 2)], under)
    assert at == [(True, outline.EDGE_ON)]
    assert below == [(False, "1")]
    eye = np.asarray(scene.camera.eye, dtype=np.float64)
    a, b, c = (np.asarray(v, dtype=np.float64) for v in SQUARE[0])
    assert outline.side(eye, a, b, c, over) == 0
    assert outline.side(eye, a, b, c, under) in (1, -1)
    rows = outline.sides(eye, a[None, :], b[None, :], c[None, :], under)
    assert rows.dtype == np.int8 and int(rows[0]) == outline.side(eye, a, b, c, 0.0)
