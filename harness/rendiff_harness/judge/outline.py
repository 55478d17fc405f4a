"""The verifier's outline search, for every pixel that needs one at once (docs/verifier.md).

Where one side missed a triangle M near its edges, verify.py asks whether an outline of
the surface (a mesh boundary, a silhouette, an edge the renderer may see edge-on) lies
within the rounding distance `eps` of the pixel center: then the miss is an `edge`, else
a `crack`. Each pixel walks from M across closed edges to the neighbors whose edges come
within `eps`, depth first, up to `MAX_PATCH` triangles.

It used to walk one pixel at a time, asking numpy for one edge's two 3x3 determinants and
one neighbor's distances per call: a renderer declaring `edge_px = 0.4999` (the largest
legal value) that wrote triangle 0 everywhere put almost every pixel within reach of an
edge, and `rendiff check scenes/` took 296 s against 8.8 s at `edge_px = 1e-6`. Here every
pixel keeps its own walk, in the same order, but each round (one triangle popped per
pixel) asks numpy once for the outline answers of all the edges reached (each edge once
per search: the answer depends on the edge and the eye, not the pixel) and once for the
distances of all the neighbors reached. The answers are the ones the single-pixel walk
gave, bit for bit: the same f64 arithmetic element by element (numpy's batched matmul and
determinant run the same routine on each 3x3 block), and where a shortcut (the plane
area's norm) is not decisive the exact single-edge function decides
(tests/test_outline_batched.py holds the old walk as the oracle).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from ..contract.camera import Camera
from ..contract.resolved import ResolvedScene
from . import geometry

MAX_PATCH = 64
"""Triangles the outline search visits around one pixel before it calls the patch closed."""

CHUNK = 1 << 15
"""Rows per numpy batch: bounds the temporaries when a broken renderer makes every pixel walk."""

UNDECIDED_REL = 1e-9
"""How close |det| may come to slack x area (relative) before the exact single-edge test decides.

The batched area is sqrt of a 3-term sum in another order than numpy's norm: a few units
of 2^-53 apart, far inside this margin, so every row outside it is decided as `side` would."""

BOUNDARY = "a mesh boundary edge"
EDGE_ON = "an edge of a triangle this renderer may see edge-on"
SILHOUETTE = "a silhouette edge (its neighbors fold behind it, or may for this renderer)"


class EdgeTable(Protocol):
    """What the search reads of verify.Topology: its sorted edge table (exact f32 vertex identity)."""

    corner_vid: np.ndarray  # (N, 3) vertex id of every corner
    keys: np.ndarray  # (3N,) sorted edge keys lo * vertices + hi
    key_tri: np.ndarray  # (3N,) triangle of each sorted key
    key_local: np.ndarray  # (3N,) local edge index of each sorted key
    vertices: int


def across(topo: EdgeTable, tri: np.ndarray, loc: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The other (triangle, local edge) pairs sharing each edge (tri[i], loc[i]), in the edge
    table's order (verify.Topology.neighbors for every edge at once): (owner i, triangle, local)."""
    a = topo.corner_vid[tri, loc]
    b = topo.corner_vid[tri, (loc + 1) % 3]
    key = np.minimum(a, b) * topo.vertices + np.maximum(a, b)
    lo = np.searchsorted(topo.keys, key, side="left")
    count = np.searchsorted(topo.keys, key, side="right") - lo
    owner = np.repeat(np.arange(tri.size), count)
    pos = np.arange(owner.size) - np.repeat(np.cumsum(count) - count, count) + np.repeat(lo, count)
    n_tri, n_loc = topo.key_tri[pos], topo.key_local[pos]
    keep = n_tri != tri[owner]
    return owner[keep], n_tri[keep], n_loc[keep]


def side(eye: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray, slack: float) -> int:
    """Which side of the plane (eye, a, b) c lies on: +1, -1, or 0 when the eye is within
    `slack` of the plane of (a, b, c), so that the renderer's view of it may be edge-on."""
    det = float(np.linalg.det(np.stack([a - eye, b - eye, c - eye])))
    # det = |(b-a) x (c-a)| x (signed distance of the eye from the plane of a, b, c).
    area2 = float(np.linalg.norm(np.cross(b - a, c - a)))
    if abs(det) <= slack * area2:
        return 0
    return 1 if det > 0.0 else -1


def sides(eye: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray, slack: float | np.ndarray) -> np.ndarray:
    """`side` of each row of a, b, c ((M, 3) f64 each), as int8; `slack` one for all or (M,) per row."""
    out = np.empty(a.shape[0], dtype=np.int8)
    slack_rows = np.broadcast_to(np.asarray(slack, dtype=np.float64), (a.shape[0],))
    for s in range(0, a.shape[0], CHUNK):
        e = s + CHUNK
        aa, bb, cc, sl = a[s:e], b[s:e], c[s:e], slack_rows[s:e]
        with np.errstate(all="ignore"):
            det = np.linalg.det(np.stack([aa - eye, bb - eye, cc - eye], axis=1))
            cr = np.cross(bb - aa, cc - aa)
            thr = sl * np.sqrt(np.einsum("ij,ij->i", cr, cr))
            undecided = ~(np.isfinite(det) & np.isfinite(thr)) | (np.abs(np.abs(det) - thr) <= UNDECIDED_REL * thr)
        part = np.where(np.abs(det) <= thr, 0, np.where(det > 0.0, 1, -1)).astype(np.int8)
        for i in np.nonzero(undecided)[0]:
            part[i] = side(eye, aa[i], bb[i], cc[i], float(sl[i]))
        out[s:e] = part
    return out


def silhouettes(
    scene: ResolvedScene, topo: EdgeTable, edges: Sequence[tuple[int, int]], slack: float
) -> list[tuple[bool, str]]:
    """Is each edge (tri, local) an outline as seen from the eye? (True, why) or (False, neighbor).

    Closed means a neighbor across the edge lies on the other side, with the eye farther
    than `slack` (the renderer's eye uncertainty) from both planes; the neighbor named is
    the first such in the edge table's order.
    """
    return [(is_outline, what) for is_outline, what, _ in _edge_answers(scene, topo, edges, slack)]


TriangleSlack = Callable[[np.ndarray], np.ndarray]
"""verify.TriangleSlack: (triangle indices (M,)) -> (M,) world distance added to the slack for each."""
EdgeTerms = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
"""verify.EdgeTerms: (triangle indices, rows, cols) (M,) -> (M, 3) px added to eps on each edge."""


def _edge_answers(
    scene: ResolvedScene,
    topo: EdgeTable,
    edges: Sequence[tuple[int, int]],
    slack: float,
    tri_slack: TriangleSlack | None = None,
) -> list[tuple[bool, str, list[int]]]:
    """`silhouettes`, with each edge's neighbor triangles (the walk's next steps); each plane's slack
    grown by `tri_slack` of its own triangle."""
    if not edges:
        return []
    eye = scene.camera.eye
    t = scene.triangles
    tri = np.array([e[0] for e in edges], dtype=np.int64)
    loc = np.array([e[1] for e in edges], dtype=np.int64)
    # Only the corners read go to f64 (exact), never a copy of the whole scene.
    own = np.asarray(t[tri], dtype=np.float64)
    rows = np.arange(tri.size)
    a, b, c = own[rows, loc], own[rows, (loc + 1) % 3], own[rows, (loc + 2) % 3]
    own_slack: float | np.ndarray = slack if tri_slack is None else slack + tri_slack(tri)
    own_side = sides(eye, a, b, c, own_slack)
    owner, n_tri, n_loc = across(topo, tri, loc)
    apex = np.asarray(t[n_tri, (n_loc + 2) % 3], dtype=np.float64).reshape(-1, 3)
    other_slack: float | np.ndarray = slack if tri_slack is None or n_tri.size == 0 else slack + tri_slack(n_tri)
    other = sides(eye, a[owner], b[owner], apex, other_slack)
    # The first neighbor on the other side, per edge (-1: none).
    closed = np.nonzero(own_side[owner].astype(np.int64) * other < 0)[0]
    first = np.full(tri.size, -1, dtype=np.int64)
    by = owner[closed]  # sorted: owner is
    lead = np.ones(by.size, dtype=bool)
    lead[1:] = by[1:] != by[:-1]
    first[by[lead]] = n_tri[closed[lead]]
    start = np.searchsorted(owner, rows, side="left").tolist()
    end = np.searchsorted(owner, rows, side="right").tolist()
    names = n_tri.tolist()
    out: list[tuple[bool, str, list[int]]] = []
    for s, e, f, o in zip(start, end, first.tolist(), own_side.tolist(), strict=True):
        ns = names[s:e]
        if not ns:
            out.append((True, BOUNDARY, ns))
        elif o == 0:
            out.append((True, EDGE_ON, ns))
        elif f >= 0:
            out.append((False, str(f), ns))
        else:
            out.append((True, SILHOUETTE, ns))
    return out


def near_far_rows(cam: Camera, cam_tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The near and far planes verify.side_geometry uses for each triangle (M, 3, 3) alone.

    A camera without a near plane (near <= 0) gets one at 1e-12 of the triangle's largest
    camera-space coordinate (at least 1e-12); with a batch of one, as the walk asked, that is
    the triangle's own."""
    m = cam_tris.shape[0]
    if cam.near > 0.0:
        near = np.full(m, cam.near)
    else:
        near = 1e-12 * np.fmax(1.0, np.abs(cam_tris).reshape(m, -1).max(axis=1, initial=0.0))
    far = np.where(np.isfinite(cam.far) & (cam.far > near), cam.far, np.inf)
    return near, far


def clipped_edge_distances(
    cam: Camera, ct: np.ndarray, cx: np.ndarray, cy: np.ndarray, near: np.ndarray, far: np.ndarray
) -> np.ndarray:
    """(M, 3) pixel distance from (cx, cy) to the visible part (near <= z <= far) of each edge
    of the camera-space triangles ct (M, 3, 3); inf when none of it is visible.

    verify.side_geometry's edges too (near and far the same on every row there)."""
    m = ct.shape[0]
    edge_d = np.full((m, 3), np.inf)
    finite_far = np.isfinite(far)
    with np.errstate(all="ignore"):
        for i in range(3):
            a, b = ct[:, i], ct[:, (i + 1) % 3]
            za, zb = a[:, 2], b[:, 2]
            dz = zb - za
            # Parameter range of the segment inside near <= z <= far.
            t0 = np.zeros(m)
            t1 = np.ones(m)
            safe = np.where(dz != 0.0, dz, 1.0)
            tn = (near - za) / safe
            t0 = np.where(dz > 0, np.maximum(t0, tn), t0)
            t1 = np.where(dz < 0, np.minimum(t1, tn), t1)
            tf = (far - za) / safe
            t1 = np.where(finite_far & (dz > 0), np.minimum(t1, tf), t1)
            t0 = np.where(finite_far & (dz < 0), np.maximum(t0, tf), t0)
            flat_out = (dz == 0) & ((za < near) | (za > far))
            ok = (t0 <= t1) & ~flat_out
            pa = project(cam, a + t0[:, None] * (b - a))
            pb = project(cam, a + t1[:, None] * (b - a))
            d = geometry.segment_distance(cx, cy, pa, pb)
            edge_d[:, i] = np.where(ok & np.isfinite(d), d, np.inf)
    return edge_d


def project(cam: Camera, p: np.ndarray) -> np.ndarray:
    """Camera-space points (..., 3) in front of the eye -> pixel coordinates (..., 2)."""
    return cam.to_pixel(p[..., 0], p[..., 1], np.where(p[..., 2] > 0.0, p[..., 2], 1.0))


def edge_distances(scene: ResolvedScene, tris: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """(M, 3) distances of pixel (cols[i], rows[i])'s center to the edges of triangle tris[i]
    (valid indices), each triangle clipped by its own near/far as a batch of one would be."""
    cam = scene.camera
    out = np.empty((tris.size, 3))
    for s in range(0, tris.size, CHUNK):
        e = s + CHUNK
        t64 = scene.triangles[tris[s:e]].astype(np.float64)
        cx, cy = cam.pixel_centers(cols[s:e], rows[s:e])
        with np.errstate(all="ignore"):
            ct = cam.to_camera(t64)
            near, far = near_far_rows(cam, ct)
        out[s:e] = clipped_edge_distances(cam, ct, cx, cy, near, far)
    return out


def search(
    scene: ResolvedScene,
    topo: EdgeTable,
    starts: Sequence[int],
    nears: Sequence[list[int]],
    rows: np.ndarray,
    cols: np.ndarray,
    eps: np.ndarray,
    slack: float,
    edge_terms: EdgeTerms | None = None,
    tri_slack: TriangleSlack | None = None,
) -> list[tuple[str, str]]:
    """For each pixel p: is there an outline within eps[p] of its center? (why, "") or ("", neighbor).

    A renderer whose rounding moves the sample by up to `eps` may land anywhere in that
    disc. Starting from the missed triangle starts[p]'s edges near the center (nears[p]),
    walk across closed edges to the neighbors and look at their edges within `eps`: an
    outline means the renderer could have missed the surface legitimately. Only when the
    whole patch under the disc is closed is the miss a leak; the neighbor named is the one
    across the first closed edge met. `edge_terms` grows eps on each neighbor's edges and
    `tri_slack` the slack on each triangle's plane (verify.classify_mismatches).
    """
    n = len(starts)
    seen = [{int(s)} for s in starts]
    stack: list[list[tuple[int, list[int]]]] = [[(int(starts[p]), list(nears[p]))] for p in range(n)]
    first_closed = [""] * n
    result: list[tuple[str, str] | None] = [None] * n
    answers: dict[tuple[int, int], tuple[bool, str, list[int]]] = {}
    active = list(range(n))
    while active:
        popped: list[tuple[int, int, list[int]]] = []
        for p in active:
            if stack[p] and len(seen[p]) <= MAX_PATCH:
                tri, edges = stack[p].pop()
                popped.append((p, tri, edges))
            else:
                result[p] = ("", first_closed[p])
        asked = list(dict.fromkeys((tri, j) for _, tri, edges in popped for j in edges if (tri, j) not in answers))
        answers.update(zip(asked, _edge_answers(scene, topo, asked, slack, tri_slack), strict=True))
        reached_p: list[int] = []
        reached_tri: list[int] = []
        for p, tri, edges in popped:
            start = len(reached_p)
            s = seen[p]
            for j in edges:
                is_outline, what, others = answers[(tri, j)]
                if is_outline:
                    result[p] = (f"{what} of prim {tri}", "")
                    del reached_p[start:], reached_tri[start:]
                    break
                first_closed[p] = first_closed[p] or what
                for n_tri in others:
                    if n_tri not in s:
                        s.add(n_tri)
                        reached_p.append(p)
                        reached_tri.append(n_tri)
        if reached_p:
            rp = np.array(reached_p, dtype=np.int64)
            reached = np.array(reached_tri, dtype=np.int64)
            d = edge_distances(scene, reached, rows[rp], cols[rp])
            if edge_terms is None:
                within = d <= eps[rp][:, None]
            else:
                with np.errstate(invalid="ignore"):
                    within = np.isfinite(d) & (d <= eps[rp][:, None] + edge_terms(reached, rows[rp], cols[rp]))
            rows_within = within.tolist()
            for k in np.nonzero(within.any(axis=1))[0].tolist():
                w = rows_within[k]
                stack[reached_p[k]].append((reached_tri[k], [j for j in range(3) if w[j]]))
        active = [p for p in active if result[p] is None]
    return [r if r is not None else ("", "") for r in result]
