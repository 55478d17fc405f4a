"""verify.py's outline search as it was before it was batched (issue 40 item 5): the oracle.

judge/outline.py replaced the walk below, one pixel at a time with numpy calls per edge and
per neighbor, by one walk per pixel advanced for all pixels together. This is the old code,
verbatim but for its imports (verify's Side and Topology are unchanged), so
tests/test_outline_batched.py can require the old walk's answer for every pixel the batched
search answers. Only the rewritten code is kept: the classing around it is verify.py's alone.
"""

from __future__ import annotations

import numpy as np

from rendiff_harness.contract.camera import Camera
from rendiff_harness.contract.resolved import ResolvedScene
from rendiff_harness.judge import geometry
from rendiff_harness.judge.verify import (
    Side,
    Topology,
)


def _project(cam: Camera, p: np.ndarray) -> np.ndarray:
    """Camera-space points (..., 3) in front of the eye -> pixel coordinates (..., 2)."""
    return cam.to_pixel(p[..., 0], p[..., 1], np.where(p[..., 2] > 0.0, p[..., 2], 1.0))


def _near_far(cam: Camera, cam_tris: np.ndarray) -> tuple[float, float]:
    near = cam.near if cam.near > 0.0 else 1e-12 * max(1.0, float(np.abs(cam_tris).max(initial=0.0)))
    far = cam.far if np.isfinite(cam.far) and cam.far > near else np.inf
    return near, far


def side_geometry(scene: ResolvedScene, prims: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> Side:
    """Distances, coverage and depth of prims[i] at pixel (cols[i], rows[i])'s center."""
    cam = scene.camera
    prims = np.asarray(prims, dtype=np.uint64).ravel()
    k = prims.size
    valid = prims < np.uint64(scene.triangle_count)
    edge_d = np.full((k, 3), np.inf)
    vert_d = np.full((k, 3), np.inf)
    poly_d = np.full(k, np.inf)
    inside = np.zeros(k, dtype=bool)
    z = np.full(k, np.inf)
    cos = np.zeros(k)
    idx = np.nonzero(valid)[0]
    if idx.size == 0:
        return Side(valid, edge_d, vert_d, poly_d, inside, z, cos)
    tris = scene.triangles[prims[idx].astype(np.int64)].astype(np.float64)
    cx, cy = cam.pixel_centers(np.asarray(cols).ravel()[idx], np.asarray(rows).ravel()[idx])
    with np.errstate(all="ignore"):
        ct = cam.to_camera(tris)
        near, far = _near_far(cam, ct)
        for i in range(3):
            a, b = ct[:, i], ct[:, (i + 1) % 3]
            za, zb = a[:, 2], b[:, 2]
            dz = zb - za
            # Parameter range of the segment inside near <= z <= far.
            t0 = np.zeros(idx.size)
            t1 = np.ones(idx.size)
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
            pa = _project(cam, a + t0[:, None] * (b - a))
            pb = _project(cam, a + t1[:, None] * (b - a))
            d = geometry.segment_distance(cx, cy, pa, pb)
            edge_d[idx, i] = np.where(ok & np.isfinite(d), d, np.inf)
            vin = (a[:, 2] >= near) & (a[:, 2] <= far)
            pv = _project(cam, a)
            vert_d[idx, i] = np.where(vin, np.hypot(pv[:, 0] - cx, pv[:, 1] - cy), np.inf)
        poly, count = geometry.clip_and_project(cam, tris)
        poly_d[idx] = geometry.polygon_distance(poly, count, cx, cy)
        # Inside: the center is on one side of every edge of the (convex) visible polygon.
        m = idx.size
        rows_i = np.arange(m)
        pos = np.ones(m, dtype=bool)
        neg = np.ones(m, dtype=bool)
        for j in range(poly.shape[1]):
            valid_j = j < count
            nxt = np.where(j + 1 < count, j + 1, 0)
            p0, p1 = poly[:, j], poly[rows_i, nxt]
            cr = (p1[:, 0] - p0[:, 0]) * (cy - p0[:, 1]) - (p1[:, 1] - p0[:, 1]) * (cx - p0[:, 0])
            pos &= ~valid_j | (cr >= 0.0)
            neg &= ~valid_j | (cr <= 0.0)
        inside[idx] = (count >= 3) & (pos | neg)
        # Planar depth of the plane along d = f + sx r + sy u (d.f = 1, so t is Z).
        d = cam.direction(*cam.screen_at(cx, cy))
        nrm = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        nd = np.einsum("ij,ij->i", nrm, d)
        t = np.einsum("ij,ij->i", nrm, tris[:, 0] - cam.eye[None, :]) / nd
        zz = np.where((nd != 0.0) & np.isfinite(t) & (t > 0.0), t, np.inf)
        z[idx] = zz
        nl = np.linalg.norm(nrm, axis=1) * np.linalg.norm(d, axis=1)
        cos[idx] = np.where(nl > 0.0, np.clip(np.abs(nd) / np.where(nl > 0, nl, 1.0), 0.0, 1.0), 0.0)
    return Side(valid, edge_d, vert_d, poly_d, inside, z, cos)


def _side(eye: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray, slack: float) -> int:
    """Which side of the plane (eye, a, b) c lies on: +1, -1, or 0 when the eye is within
    `slack` of the plane of (a, b, c), so that the renderer's view of it may be edge-on."""
    det = float(np.linalg.det(np.stack([a - eye, b - eye, c - eye])))
    # det = |(b-a) x (c-a)| x (signed distance of the eye from the plane of a, b, c).
    area2 = float(np.linalg.norm(np.cross(b - a, c - a)))
    if abs(det) <= slack * area2:
        return 0
    return 1 if det > 0.0 else -1


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
    own = _side(eye, a, b, c, slack)
    if own == 0:
        return True, "an edge of a triangle this renderer may see edge-on"
    for n_tri, n_local in neigh:
        other = _side(eye, a, b, np.asarray(t[n_tri, (n_local + 2) % 3], dtype=np.float64), slack)
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
                g = side_geometry(scene, np.array([n_tri]), np.array([row]), np.array([col]))
                n_near = [k for k in range(3) if g.edge_d[0, k] <= eps]
                if n_near:
                    frontier.append((n_tri, n_near))
    return "", first_closed
