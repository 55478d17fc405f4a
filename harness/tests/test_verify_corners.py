"""verify.py's outline test reads only the corners it needs in f64, and judges as before.

It used to copy every triangle of the scene to f64 per visited edge (128 ms and 94 MB a
call at 1.31M triangles). The copy below is that code, kept as the reference: on closed
meshes seen from several eyes, every edge's answer and every classified mismatch (class,
sentence, groups) must be the same with either.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fixtures import write_scene
from rendiff_harness.contract import resolved, vocab
from rendiff_harness.judge import verify

BG = vocab.BACKGROUND_ID


def _silhouette_whole_copy(
    scene: resolved.ResolvedScene, topo: verify.Topology, tri: int, local: int, slack: float
) -> tuple[bool, str]:
    """verify._silhouette as it was before (the whole scene copied to f64 per call)."""
    neigh = topo.neighbors(tri, local)
    if not neigh:
        return True, "a mesh boundary edge"
    t = scene.triangles.astype(np.float64)
    eye = scene.camera.eye
    a, b, c = t[tri, local], t[tri, (local + 1) % 3], t[tri, (local + 2) % 3]
    own = verify._side(eye, a, b, c, slack)
    if own == 0:
        return True, "an edge of a triangle this renderer may see edge-on"
    for n_tri, n_local in neigh:
        other = verify._side(eye, a, b, t[n_tri, (n_local + 2) % 3], slack)
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
def test_outline_answers_and_verdicts_match_the_whole_scene_copy(
    tmp_path: Path, eye: tuple[float, float, float], monkeypatch: pytest.MonkeyPatch
) -> None:
    scene = resolved.load(write_scene(tmp_path / "s", TRIS, eye=eye, width=24, height=20))
    topo = verify.topology(scene.triangles)
    n = scene.triangle_count
    # Every edge, with no slack and with slacks that open some edges.
    for slack in (0.0, 1e-3, 0.3):
        for tri in range(n):
            for local in range(3):
                assert verify._silhouette(scene, topo, tri, local, slack) == _silhouette_whole_copy(
                    scene, topo, tri, local, slack
                ), (tri, local, slack)
    # Every pixel, each triangle against the background and against a neighbor: the
    # classification walks outlines across the meshes.
    h, w = scene.camera.height, scene.camera.width
    rows, cols = (g.ravel() for g in np.mgrid[0:h, 0:w])
    for ref in range(n):
        for test in (BG, (ref + 1) % n):
            args = (
                scene,
                np.full(rows.size, ref, dtype=np.uint32),
                np.full(rows.size, test, dtype=np.uint32),
                rows,
                cols,
                0.75,
                lambda z, c: np.zeros_like(z),
            )
            now = verify.classify_mismatches(*args, eye_slack=1e-3)
            with monkeypatch.context() as m:
                m.setattr(verify, "_silhouette", _silhouette_whole_copy)
                before = verify.classify_mismatches(*args, eye_slack=1e-3)
            assert np.array_equal(now.cls, before.cls)
            assert now.why == before.why
            assert now.groups == before.groups
    # Not vacuous: the scene has closed edges, outlines and cracks to tell apart.
    answers = {verify._silhouette(scene, topo, t, k, 0.0)[0] for t in range(n) for k in range(3)}
    assert answers == {True, False}
