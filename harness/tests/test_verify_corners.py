"""The outline test (judge/outline.py) reads only the corners it needs in f64, and answers as before.

It used to copy every triangle of the scene to f64 per visited edge (128 ms and 94 MB a
call at 1.31M triangles). The copy below is that code, kept as the reference: on closed
meshes seen from several eyes, every edge's answer must be the same with either. (Whole
classifications against the code before the batched walk: tests/test_outline_batched.py.)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fixtures import write_scene
from rendiff_harness.contract import resolved, vocab
from rendiff_harness.judge import outline, verify

BG = vocab.BACKGROUND_ID


def _silhouette_whole_copy(
    scene: resolved.ResolvedScene, topo: verify.Topology, tri: int, local: int, slack: float
) -> tuple[bool, str]:
    """The single-edge outline test as it was before (the whole scene copied to f64 per call)."""
    neigh = topo.neighbors(tri, local)
    if not neigh:
        return True, "a mesh boundary edge"
    t = scene.triangles.astype(np.float64)
    eye = scene.camera.eye
    a, b, c = t[tri, local], t[tri, (local + 1) % 3], t[tri, (local + 2) % 3]
    own = outline.side(eye, a, b, c, slack)
    if own == 0:
        return True, "an edge of a triangle this renderer may see edge-on"
    for n_tri, n_local in neigh:
        other = outline.side(eye, a, b, t[n_tri, (n_local + 2) % 3], slack)
        if own * other < 0:
            return False, str(n_tri)
    return True, "a silhouette edge (its neighbors fold behind it, or may for this renderer)"


def _octahedron(center: tuple[float, float, float], r: float) -> list[list[list[float]]]:
    cx, cy, cz = center
    px, nx = [cx + r, cy, cz], [cx - r, cy, cz]
    py, ny = [cx, cy + r, cz], [cx, cy - r, cz]
    pz, nz = [cx, cy, cz + r], [cx, cy, cz - r]
    out = []
    for a, b in ((px, py), (py, nx), (nx, ny), (ny, px)):
        out.append([a, b, pz])
        out.append([b, a, nz])
    return out


# A closed octahedron with non-dyadic corners, a second one partly behind it, and a
# two-triangle floor with an open boundary: closed edges, silhouettes and mesh boundaries.
TRIS = (
    _octahedron((0.1, 0.2, 0.0), 1.3)
    + _octahedron((0.9, -0.4, -1.7), 0.9)
    + [[[-3, -1.5, -3], [3, -1.5, -3], [3, -1.5, 2]], [[-3, -1.5, -3], [3, -1.5, 2], [-3, -1.5, 2]]]
)


@pytest.mark.parametrize("eye", [(0.0, 0.0, 5.0), (2.3, 1.7, 3.1), (-0.4, 3.9, 0.7)])
def test_outline_answers_match_the_whole_scene_copy(tmp_path: Path, eye: tuple[float, float, float]) -> None:
    scene = resolved.load(write_scene(tmp_path / "s", TRIS, eye=eye, width=24, height=20))
    topo = verify.topology(scene.triangles)
    n = scene.triangle_count
    edges = [(tri, local) for tri in range(n) for local in range(3)]
    # Every edge, with no slack and with slacks that open some edges; one at a time and all at once.
    for slack in (0.0, 1e-3, 0.3):
        whole = [_silhouette_whole_copy(scene, topo, tri, local, slack) for tri, local in edges]
        assert outline.silhouettes(scene, topo, edges, slack) == whole, slack
        for (tri, local), answer in zip(edges, whole, strict=True):
            assert outline.silhouettes(scene, topo, [(tri, local)], slack) == [answer], (tri, local, slack)
    # Not vacuous: the scene has closed edges and outlines to tell apart.
    answers = {a for a, _ in outline.silhouettes(scene, topo, edges, 0.0)}
    assert answers == {True, False}
