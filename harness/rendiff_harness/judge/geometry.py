"""Edge / interior geometry for ID mismatches (docs/DESIGN.md "Comparing").

An ID mismatch is an *edge* mismatch when the pixel center lies within the renderer's
own rounding distance of an edge of a triangle involved (the reference's prim or the
test's prim at that pixel); anything else is an *interior* mismatch, i.e. a bug. This
module computes that distance, in pixels, in float64, for the mismatched pixels only
(scenes have up to millions of triangles, mismatches are few).

Projection: the camera's own (contract/camera.py: `Camera.to_camera`, `Camera.to_pixel`),
pixel centers at k + 0.5. A triangle is first clipped in camera space against the near plane
(z >= near) and, when finite, the far plane (z <= far): the visible part of a triangle
that crosses the eye plane is a polygon (up to 5 vertices) whose projection is finite.
The clip edges count as edges: they bound what a renderer may show.

Robustness: a triangle entirely outside [near, far] has distance +inf (no renderer
should show it); a projected polygon of zero (or ~1e-12 relative) area, e.g. a triangle
seen exactly edge-on, has distance 0, as every pixel it could cover is on its boundary.
No NaN and no floating-point warnings reach the caller.
"""

from __future__ import annotations

import math

import numpy as np

from ..contract.camera import Camera
from ..contract.resolved import ResolvedScene

CHUNK = 1 << 17
"""Triangles per vectorized batch: bounds temporary memory if a renderer is badly broken."""
DEGENERATE_REL_AREA = 1e-12


def _clip(verts: np.ndarray, count: np.ndarray, plane: float, sign: float) -> tuple[np.ndarray, np.ndarray]:
    """Sutherland-Hodgman against sign*z >= sign*plane. verts (M, K, 3) -> (M, K+1, 3)."""
    m, k_max, _ = verts.shape
    out = np.zeros((m, k_max + 1, 3), dtype=np.float64)
    n_out = np.zeros(m, dtype=np.int64)
    rows = np.arange(m)
    for k in range(k_max):
        valid = k < count
        nxt = np.where(k + 1 < count, k + 1, 0)
        a = verts[:, k]
        b = verts[rows, nxt]
        ina = sign * a[:, 2] >= sign * plane
        inb = sign * b[:, 2] >= sign * plane
        keep = valid & ina
        idx = np.nonzero(keep)[0]
        out[idx, n_out[idx]] = a[idx]
        n_out += keep
        cross = valid & (ina != inb)
        idx = np.nonzero(cross)[0]
        if idx.size:
            za, zb = a[idx, 2], b[idx, 2]
            t = (plane - za) / (zb - za)  # za, zb on opposite sides: zb != za
            p = a[idx] + t[:, None] * (b[idx] - a[idx])
            p[:, 2] = plane
            out[idx, n_out[idx]] = p
            n_out += cross
    return out, n_out


def clip_and_project(camera: Camera, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Visible polygon of each triangle in pixel coordinates: ((M, 5, 2), vertex counts (M,)).

    Counts are 0 (nothing between near and far) or 3-5. Unused slots are zero.
    """
    cam_tris = camera.to_camera(tris)
    m = cam_tris.shape[0]
    near = camera.near if camera.near > 0.0 else 1e-12 * max(1.0, float(np.abs(cam_tris).max(initial=0.0)))
    poly, count = _clip(cam_tris, np.full(m, 3, dtype=np.int64), near, 1.0)
    if math.isfinite(camera.far) and camera.far > near:
        poly, count = _clip(poly, count, camera.far, -1.0)
    else:  # keep the shape (M, 5, 3) either way
        poly = np.concatenate([poly, np.zeros((m, 1, 3))], axis=1)
    z = np.where(np.arange(poly.shape[1])[None, :] < count[:, None], poly[..., 2], 1.0)
    return camera.to_pixel(poly[..., 0], poly[..., 1], z), count


def segment_distance(cx: np.ndarray, cy: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from (cx, cy) to the segments a-b ((M, 2) each); zero-length segments -> point distance."""
    ex, ey = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    dx, dy = cx - a[:, 0], cy - a[:, 1]
    len2 = ex * ex + ey * ey
    safe = np.where(len2 > 0.0, len2, 1.0)
    t = np.where(len2 > 0.0, np.clip((dx * ex + dy * ey) / safe, 0.0, 1.0), 0.0)
    distance: np.ndarray = np.hypot(dx - t * ex, dy - t * ey)
    return distance


def polygon_distance(poly: np.ndarray, count: np.ndarray, cx: np.ndarray, cy: np.ndarray) -> np.ndarray:
    m, k_max, _ = poly.shape
    rows = np.arange(m)
    dist = np.full(m, np.inf)
    area2 = np.zeros(m)
    perimeter = np.zeros(m)
    for k in range(k_max):
        valid = k < count
        nxt = np.where(k + 1 < count, k + 1, 0)
        a, b = poly[:, k], poly[rows, nxt]
        d = segment_distance(cx, cy, a, b)
        dist = np.where(valid, np.minimum(dist, d), dist)
        # Shoelace relative to the first vertex keeps the area accurate far from the origin.
        a0, b0 = a - poly[:, 0], b - poly[:, 0]
        area2 += np.where(valid, a0[:, 0] * b0[:, 1] - a0[:, 1] * b0[:, 0], 0.0)
        perimeter += np.where(valid, np.hypot(b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]), 0.0)
    finite = np.all(np.isfinite(poly.reshape(m, -1)), axis=1) & np.isfinite(area2) & np.isfinite(perimeter)
    degenerate = (count > 0) & (~finite | (np.abs(area2) <= DEGENERATE_REL_AREA * perimeter * perimeter))
    dist = np.where(degenerate, 0.0, dist)
    return np.where(count > 0, dist, np.inf)


def edge_distance(camera: Camera, tris: np.ndarray, cx: np.ndarray, cy: np.ndarray) -> np.ndarray:
    """Pixel distance from centers (cx[i], cy[i]) to the nearest edge of triangle tris[i].

    tris: (M, 3, 3) world-space vertices; cx, cy: (M,) continuous pixel coordinates
    (a pixel (x, y) has its center at x + 0.5, y + 0.5). Returns (M,) float64:
    0 for a degenerate projection, +inf for a triangle outside [near, far].
    """
    tris = np.asarray(tris, dtype=np.float64).reshape(-1, 3, 3)
    cx = np.asarray(cx, dtype=np.float64).ravel()
    cy = np.asarray(cy, dtype=np.float64).ravel()
    out = np.empty(tris.shape[0], dtype=np.float64)
    with np.errstate(all="ignore"):
        for s in range(0, tris.shape[0], CHUNK):
            e = s + CHUNK
            poly, count = clip_and_project(camera, tris[s:e])
            out[s:e] = polygon_distance(poly, count, cx[s:e], cy[s:e])
    return out


def prim_edge_distance(scene: ResolvedScene, prims: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Distance from pixel (cols[i], rows[i])'s center to an edge of prim prims[i].

    Background (0xFFFFFFFF) and IDs that name no triangle give +inf.
    """
    prims = np.asarray(prims, dtype=np.uint64).ravel()
    dist = np.full(prims.size, np.inf)
    valid = prims < np.uint64(scene.triangle_count)
    idx = np.nonzero(valid)[0]
    if idx.size:
        tris = scene.triangles[prims[idx].astype(np.int64)]
        cx, cy = scene.camera.pixel_centers(np.asarray(cols)[idx], np.asarray(rows)[idx])
        dist[idx] = edge_distance(scene.camera, tris, cx, cy)
    return dist


def mismatch_edge_distance(
    scene: ResolvedScene, ref_prims: np.ndarray, test_prims: np.ndarray, rows: np.ndarray, cols: np.ndarray
) -> np.ndarray:
    """min(distance to the reference prim's edges, distance to the test prim's edges) per pixel.

    Whichever side is background (or an ID naming no triangle) does not contribute; +inf
    when neither names a triangle.
    """
    d_ref = prim_edge_distance(scene, ref_prims, rows, cols)
    d_test = prim_edge_distance(scene, test_prims, rows, cols)
    distance: np.ndarray = np.minimum(d_ref, d_test)
    return distance
