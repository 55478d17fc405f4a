"""verify.py's outline search as it was before it was batched (issue 40 item 5): the oracle.

judge/outline.py replaced the walk below, one pixel at a time with numpy calls per edge and
per neighbor, by one walk per pixel advanced for all pixels together. This is the old code
that has no unchanged twin in the judge: the walk (`_outline_near`), the single-edge outline
test (`_silhouette`) and the edge part of the old side_geometry (`edge_distances`: the one
part the walk read, and the clipping outline.clipped_edge_distances now does for a batch).
What the rewrite kept as it was is imported, not copied: the exact single-edge side test
(outline.side, pinned at its boundaries by test_judge_boundaries.py and
test_outline_boundaries.py), the projection (outline.project), verify's Topology. So
tests/test_outline_batched.py can require the old walk's answer for every pixel the batched
search answers; the classing around it is verify.py's alone.
"""

from __future__ import annotations

import numpy as np

from rendiff_harness.contract.camera import Camera
from rendiff_harness.contract.resolved import ResolvedScene
from rendiff_harness.judge import geometry
from rendiff_harness.judge.outline import project, side
from rendiff_harness.judge.verify import Topology


def _near_far(cam: Camera, cam_tris: np.ndarray) -> tuple[float, float]:
    near = cam.near if cam.near > 0.0 else 1e-12 * max(1.0, float(np.abs(cam_tris).max(initial=0.0)))
    far = cam.far if np.isfinite(cam.far) and cam.far > near else np.inf
    return near, far


def edge_distances(scene: ResolvedScene, prims: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """side_geometry's `edge_d` as it was: (K, 3) distances of pixel (cols[i], rows[i])'s center to
    the visible part of each edge of prims[i] (valid indices), near and far shared by the batch."""
    cam = scene.camera
    prims = np.asarray(prims, dtype=np.int64).ravel()
    k = prims.size
    edge_d = np.full((k, 3), np.inf)
    tris = scene.triangles[prims].astype(np.float64)
    cx, cy = cam.pixel_centers(np.asarray(cols).ravel(), np.asarray(rows).ravel())
    with np.errstate(all="ignore"):
        ct = cam.to_camera(tris)
        near, far = _near_far(cam, ct)
        for i in range(3):
            a, b = ct[:, i], ct[:, (i + 1) % 3]
            za, zb = a[:, 2], b[:, 2]
            dz = zb - za
            # Parameter range of the segment inside near <= z <= far.
            t0 = np.zeros(k)
            t1 = np.ones(k)
            safe = np.where(dz != 0.0, dz, 1.0)
            tn = (near - za) / safe
            t0 = np.where(dz > 0, np.maximum(t0, tn), t0)
            t1 = np.where(dz < 0, np.minimum(t1, tn), t1)
            if np.isfinite(far):
                tf = (far - za) / safe
                t1 = np.where(dz > 0, np.minimum(t1, tf), t1)
                t0 = np.where(dz < 0, np.maximum(t0, tf), t0)
            flat_out = (dz == 0) & ((za < near) | (za > far))
            ok = (t0 <= t1) & ~flat_out
            pa = project(cam, a + t0[:, None] * (b - a))
            pb = project(cam, a + t1[:, None] * (b - a))
            d = geometry.segment_distance(cx, cy, pa, pb)
            edge_d[:, i] = np.where(ok & np.isfinite(d), d, np.inf)
    return edge_d


def _silhouette(scene: ResolvedScene, topo: Topology, tri: int, local: int, slack: float) -> tuple[bool, str]:
    """Is edge `local` of `tri` an outline as seen from the eye? (True, why) or (False, neighbor).

    Closed means a neighbor across the edge lies on the other side, with the eye farther
    than `slack` (the renderer's eye uncertainty) from both planes.
    """
    neigh = topo.neighbors(tri, local)
    if not neigh:
        return True, "a mesh boundary edge"
    # Only the corners it reads go to f64 (exact, so the same values as a copy of the whole
    # scene, which this made per visited edge: 128 ms and 94 MB at 1.31M triangles).
    t = scene.triangles
    eye = scene.camera.eye
    own_tri = np.asarray(t[tri], dtype=np.float64)
    a, b, c = own_tri[local], own_tri[(local + 1) % 3], own_tri[(local + 2) % 3]
    own = side(eye, a, b, c, slack)
    if own == 0:
        return True, "an edge of a triangle this renderer may see edge-on"
    for n_tri, n_local in neigh:
        other = side(eye, a, b, np.asarray(t[n_tri, (n_local + 2) % 3], dtype=np.float64), slack)
        if own * other < 0:
            return False, str(n_tri)
    return True, "a silhouette edge (its neighbors fold behind it, or may for this renderer)"


MAX_PATCH = 64
"""Triangles the outline search visits around one pixel before it calls the patch closed."""


def _outline_near(
    scene: ResolvedScene, topo: Topology, start: int, near: list[int], row: int, col: int, eps: float, slack: float
) -> tuple[str, str]:
    """Is there an outline of the surface within `eps` of the pixel center? (why, "") or ("", neighbor).

    A renderer whose rounding moves the sample by up to `eps` may land anywhere in that
    disc. Starting from the missed triangle's edges near the center (`near`), walk across
    closed edges to the neighbors and look at their edges within `eps`: an outline (a mesh
    boundary, a silhouette, or an edge this renderer may see edge-on) means the renderer
    could have missed the surface legitimately. Only when the whole patch under the disc
    is closed is the miss a leak.
    """
    seen = {start}
    frontier = [(start, near)]
    first_closed = ""
    while frontier and len(seen) <= MAX_PATCH:
        tri, edges = frontier.pop()
        for j in edges:
            is_outline, what = _silhouette(scene, topo, tri, j, slack)
            if is_outline:
                return f"{what} of prim {tri}", ""
            first_closed = first_closed or what
            for n_tri, _ in topo.neighbors(tri, j):
                if n_tri in seen:
                    continue
                seen.add(n_tri)
                d = edge_distances(scene, np.array([n_tri]), np.array([row]), np.array([col]))
                n_near = [k for k in range(3) if d[0, k] <= eps]
                if n_near:
                    frontier.append((n_tri, n_near))
    return "", first_closed
