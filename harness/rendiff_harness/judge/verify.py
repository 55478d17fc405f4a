"""The verifier: one class for every ID mismatch, from the geometry (docs/DESIGN.md "Comparing").

A result passes when every pixel is one the conventions allow, judged at the test
renderer's own precision (the Khronos CTS rasterization verifier's rule). For a pixel
whose prim differs between the reference (R) and the test renderer (T), either of which
may be the background:

* `tie`: both triangles cover the center (inside, or within the rounding distance `eps`
  of their boundary) and their planar depths there agree within the sum of the test
  renderer's depth tolerances on the two triangles (each at its own depth; plus two f32
  roundings): coplanar or duplicated surfaces, which its arithmetic may rank either way.
  The reference's lower-prim rule is a convention, not a law, so either is allowed.
* `edge`: the center lies within `eps` of an edge or vertex that R and T share (same f32
  vertices), or of a *silhouette* edge of the triangle the test renderer missed: a
  mesh boundary, an edge whose neighbors fold to the same side of it as seen from the
  eye, or the near/far clip of the triangle. Either answer is allowed there.
* `crack`: the center lies within `eps` of an edge of the missed triangle that is closed
  (a neighbor across it continues the surface on the other side), and the test
  renderer saw the background or something farther: a watertightness leak. It fails
  unless the backend declares cracks (expectations.py `[[declare]]`), once, with a reason.
* `interior`: anything else, including an ID that names no triangle. A bug.

"Missed" is decided by depth: the side that saw the farther surface (or the background)
is the one that missed the nearer triangle, whose edge must then explain the difference.
Shared edges and vertices are found by exact f32 vertex identity (`Topology`), built
once per scene and only when there are mismatches to explain.

Every mismatch also gets a short explanation; `explain` groups them by
(class, R, T) for results.json and the report.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..contract import vertex_ids
from ..contract.camera import Camera
from ..contract.resolved import ResolvedScene, SceneError
from ..contract.vocab import BACKGROUND_ID
from . import geometry, outline

CLASSES = ("edge", "tie", "crack", "interior")
EDGE, TIE, CRACK, INTERIOR = range(4)
F32_ULP = 2.0**-23
MAX_EXPLANATIONS = 20

EdgeTerms = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
"""(triangle indices (M,), rows (M,), cols (M,)) -> (M, 3) px added to `eps` on edge j (corner j to j + 1)
of that triangle at that pixel (tolerance.Model.edge_products); inf: unbounded, every pixel is near it."""
TriangleSlack = Callable[[np.ndarray], np.ndarray]
"""(triangle indices (M,)) -> (M,) world distance added to `eye_slack` for that triangle's plane
(tolerance.Model.plane_move)."""

DepthTolerance = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
"""(planar depth z (K,), |cos| (K,), the triangle seen there (K,)) -> allowed |dZ| (K,) of the
test renderer on that triangle (its depth model needs the triangle's own depth span and size)."""


# --------------------------------------------------------------------------- topology


@dataclass
class Topology:
    """Which triangles share which f32 vertices and edges (exact identity)."""

    corner_vid: np.ndarray  # (N, 3) int64 vertex id of every corner
    keys: np.ndarray  # (3N,) sorted edge keys lo * V + hi
    key_tri: np.ndarray  # (3N,) triangle of each sorted key
    key_local: np.ndarray  # (3N,) local edge index (i: corners i, i+1 mod 3)
    vertices: int

    def edge_key(self, tri: int, local: int) -> int:
        a = int(self.corner_vid[tri, local])
        b = int(self.corner_vid[tri, (local + 1) % 3])
        lo, hi = (a, b) if a < b else (b, a)
        return lo * self.vertices + hi

    def neighbors(self, tri: int, local: int) -> list[tuple[int, int]]:
        """Other (triangle, local edge) pairs with the same two vertices."""
        key = self.edge_key(tri, local)
        lo = int(np.searchsorted(self.keys, key, side="left"))
        hi = int(np.searchsorted(self.keys, key, side="right"))
        return [(int(self.key_tri[i]), int(self.key_local[i])) for i in range(lo, hi) if int(self.key_tri[i]) != tri]


def topology(triangles: np.ndarray, numbers: np.ndarray | None = None) -> Topology:
    """Vertex ids by exact f32 identity (+0 and -0 merged), and the sorted edge table.

    `numbers`: the export's vertex number of every corner (`vertex_ids.u32`), used once
    `vertex_ids.checked` has proved them this very numbering (ValueError otherwise); None:
    numbered here."""
    n = np.asarray(triangles).reshape(-1, 3, 3).shape[0]
    # Numbered in the rows' byte order, as np.unique on 12-byte rows numbered them (faster).
    hi, lo = vertex_ids.corner_keys(triangles)
    inverse = vertex_ids.group(hi, lo)[1] if numbers is None else vertex_ids.checked(hi, lo, numbers)
    vid = inverse.reshape(n, 3)
    nv = int(vid.max()) + 1 if n else 0
    a = vid
    b = np.roll(vid, -1, axis=1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    keys = (lo * nv + hi).ravel()
    order = np.argsort(keys, kind="stable")
    tri_of = np.repeat(np.arange(n, dtype=np.int64), 3)
    local = np.tile(np.arange(3, dtype=np.int64), n)
    return Topology(vid, keys[order], tri_of[order], local[order], nv)


def scene_topology(scene: ResolvedScene) -> Topology:
    """`topology` of the scene's triangles, with the export's vertex numbers where it wrote
    them; a wrong vertex_ids.u32 raises SceneError naming it."""
    numbers = scene.corner_vertex_ids()
    try:
        return topology(scene.triangles, numbers)
    except ValueError as exc:
        raise SceneError(f"{scene.vertex_ids_file}: {exc}") from None


# --------------------------------------------------------------------------- per-side geometry


@dataclass
class Side:
    """Geometry of one side's triangle at each mismatched pixel center (K pixels)."""

    valid: np.ndarray  # (K,) bool: names a triangle of the scene
    edge_d: np.ndarray  # (K, 3) px distance to each triangle edge's visible (clipped) part
    vert_d: np.ndarray  # (K, 3) px distance to each vertex in front of the near plane
    poly_d: np.ndarray  # (K,) px distance to the visible polygon's boundary (clip edges included)
    inside: np.ndarray  # (K,) bool: center inside the visible polygon's projection
    z: np.ndarray  # (K,) planar depth of the triangle's plane along the pixel ray (inf: none)
    cos: np.ndarray  # (K,) |cos| between the pixel ray and the triangle's normal


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
        edge_d[idx] = outline.clipped_edge_distances(cam, ct, cx, cy, np.full(idx.size, near), np.full(idx.size, far))
        for i in range(3):
            a = ct[:, i]
            vin = (a[:, 2] >= near) & (a[:, 2] <= far)
            pv = outline.project(cam, a)
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


# --------------------------------------------------------------------------- classification


@dataclass
class Classified:
    """Class and explanation of each of K mismatched pixels."""

    cls: np.ndarray  # (K,) int8 in EDGE, TIE, CRACK, INTERIOR
    why: list[str]  # (K,) one sentence each
    groups: list[dict[str, object]] = field(default_factory=list)


def _shared(topo: Topology, r: int, t: int) -> set[int]:
    return set(int(v) for v in topo.corner_vid[r]) & set(int(v) for v in topo.corner_vid[t])


def classify_mismatches(
    scene: ResolvedScene,
    ref_ids: np.ndarray,
    test_ids: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    eps: np.ndarray | float,
    depth_tol: DepthTolerance,
    topo_cache: dict[str, Topology] | None = None,
    backend: str = "the test renderer",
    eye_slack: float = 0.0,
    edge_terms: EdgeTerms | None = None,
    tri_slack: TriangleSlack | None = None,
) -> Classified:
    """Classify K mismatched pixels; `eps` is the test renderer's rounding distance (px), grown on
    each edge by `edge_terms`, `eye_slack` how far (world units) its arithmetic may move the eye
    relative to the geometry, grown per triangle by `tri_slack`."""
    k = int(np.asarray(ref_ids).size)
    cls = np.full(k, INTERIOR, dtype=np.int8)
    why = [""] * k
    if k == 0:
        return Classified(cls, why)
    r_ids = np.asarray(ref_ids).ravel().astype(np.uint64)
    t_ids = np.asarray(test_ids).ravel().astype(np.uint64)
    eps_a = np.broadcast_to(np.asarray(eps, dtype=np.float64), (k,))
    sr = side_geometry(scene, r_ids, rows, cols)
    st = side_geometry(scene, t_ids, rows, cols)
    n = scene.triangle_count
    bg = np.uint64(BACKGROUND_ID)
    invalid_t = (t_ids != bg) & ~st.valid
    invalid_r = (r_ids != bg) & ~sr.valid
    xr = _edge_extra(edge_terms, sr, r_ids, rows, cols)
    xt = _edge_extra(edge_terms, st, t_ids, rows, cols)
    covers_r = sr.valid & (sr.inside | (sr.poly_d <= eps_a) | _near(sr.edge_d, eps_a, xr).any(axis=1))
    covers_t = st.valid & (st.inside | (st.poly_d <= eps_a) | _near(st.edge_d, eps_a, xt).any(axis=1))
    both = covers_r & covers_t & np.isfinite(sr.z) & np.isfinite(st.z)
    tol = np.zeros(k)
    if both.any():
        # The test renderer ranks its own two depths, each off by up to its tolerance on
        # that triangle: the order can flip whenever the exact gap is within their sum.
        zi = np.nonzero(both)[0]
        tol_r = np.asarray(depth_tol(sr.z[zi], sr.cos[zi], r_ids[zi]), dtype=np.float64)
        tol_t = np.asarray(depth_tol(st.z[zi], st.cos[zi], t_ids[zi]), dtype=np.float64)
        tol[zi] = tol_r + tol_t + 2.0 * F32_ULP * np.abs(sr.z[zi])
    with np.errstate(invalid="ignore"):
        tie = both & (np.abs(sr.z - st.z) <= tol)
    topo: Topology | None = None

    def get_topo() -> Topology:
        nonlocal topo
        if topo is None:
            if topo_cache is not None and "topo" in topo_cache:
                topo = topo_cache["topo"]
            else:
                topo = scene_topology(scene)
                if topo_cache is not None:
                    topo_cache["topo"] = topo
        return topo

    rows_a = np.asarray(rows).ravel()
    cols_a = np.asarray(cols).ravel()
    walk: list[tuple[int, int, list[int], float, str, str, str]] = []  # pixels whose miss needs the outline search
    for i in range(k):
        r, t = int(r_ids[i]), int(t_ids[i])
        rn = "background" if r == BACKGROUND_ID else f"prim {r}"
        tn = "background" if t == BACKGROUND_ID else f"prim {t}"
        e = float(eps_a[i])
        if invalid_t[i] or invalid_r[i]:
            bad = t if invalid_t[i] else r
            why[i] = f"id {bad} names no triangle (the scene has {n})"
            continue
        if sr.valid[i] and st.valid[i]:
            tp = get_topo()
            shared = _shared(tp, r, t)
            if shared:
                # A shared feature is on both triangles: either one's band there may flip the pixel.
                rv, tv = [int(v) for v in tp.corner_vid[r]], [int(v) for v in tp.corner_vid[t]]
                near_v = [
                    j
                    for j in range(3)
                    if rv[j] in shared
                    and _within(sr.vert_d[i, j], e, _vertex_band(xr[i], j), _vertex_band(xt[i], tv.index(rv[j])))
                ]
                near_e = [
                    j
                    for j in range(3)
                    if rv[j] in shared
                    and rv[(j + 1) % 3] in shared
                    and _within(sr.edge_d[i, j], e, xr[i, j], xt[i, _edge_index(tv, rv[j], rv[(j + 1) % 3])])
                ]
                if near_e or near_v:
                    cls[i] = EDGE
                    d = min([sr.edge_d[i, j] for j in near_e] + [sr.vert_d[i, j] for j in near_v])
                    feature = "edge" if near_e else "vertex"
                    why[i] = f"center {d:.2g} px from the {feature} prims {r} and {t} share: edge"
                    continue
        if tie[i]:
            cls[i] = TIE
            tp = get_topo()
            same = sorted(int(v) for v in tp.corner_vid[r]) == sorted(int(v) for v in tp.corner_vid[t])
            what = "identical triangles" if same else "coplanar here"
            why[i] = (
                f"prims {r} and {t} are {what} (depths {sr.z[i]:.9g} and {st.z[i]:.9g} agree within {tol[i]:.3g}): tie"
            )
            continue
        # The side that saw the farther surface missed the nearer triangle.
        if sr.valid[i] and (not st.valid[i] or st.z[i] > sr.z[i]):
            missed, g, gx, missed_name, seen_name, who = r, sr, xr, rn, tn, backend
        elif st.valid[i]:
            missed, g, gx, missed_name, seen_name, who = t, st, xt, tn, rn, "the reference"
        else:
            why[i] = "both sides name no triangle"
            continue
        near = [j for j in range(3) if np.isfinite(g.edge_d[i, j]) and g.edge_d[i, j] <= e + gx[i, j]]
        if not near:
            if g.poly_d[i] <= e:
                cls[i] = EDGE
                why[i] = f"center {g.poly_d[i]:.2g} px from the near/far clip of {missed_name}: edge"
            else:
                dist = g.poly_d[i]
                where = "inside" if g.inside[i] else "outside"
                why[i] = (
                    f"center {dist:.3g} px {where} the boundary of {missed_name} (allowed {e:.2g} px); "
                    f"{who} saw {seen_name}: interior"
                )
            continue
        walk.append((i, missed, near, float(min(g.edge_d[i, j] for j in near)), missed_name, who, seen_name))
    if walk:
        # Every pixel's outline search at once (outline.py): numpy per round, not per pixel.
        at = np.array([w[0] for w in walk], dtype=np.int64)
        found = outline.search(
            scene,
            get_topo(),
            [w[1] for w in walk],
            [w[2] for w in walk],
            rows_a[at],
            cols_a[at],
            eps_a[at],
            eye_slack,
            edge_terms,
            tri_slack,
        )
        for (i, _, _, d, missed_name, who, seen_name), (line, closed_by) in zip(walk, found, strict=True):
            if line:
                cls[i] = EDGE
                why[i] = f"center {d:.2g} px from {line} (reached from {missed_name}): edge"
            else:
                cls[i] = CRACK
                why[i] = (
                    f"center {d:.2g} px from the closed edge {missed_name} shares with prim {closed_by}, "
                    f"and no outline within {float(eps_a[i]):.2g} px, but {who} saw {seen_name} behind it: crack"
                )
    return Classified(cls, why, explain(cls, why, r_ids, t_ids, rows, cols))


def _edge_extra(
    terms: EdgeTerms | None, side: Side, prims: np.ndarray, rows: np.ndarray, cols: np.ndarray
) -> np.ndarray:
    """(K, 3) `terms` of each side's triangle at each pixel (0 where there are none or no triangle)."""
    out = np.zeros((prims.size, 3))
    idx = np.nonzero(side.valid)[0]
    if terms is not None and idx.size:
        out[idx] = terms(prims[idx].astype(np.int64), np.asarray(rows).ravel()[idx], np.asarray(cols).ravel()[idx])
    return out


def _vertex_band(extra: np.ndarray, j: int) -> float:
    """A vertex is on its two edges (j - 1 and j): it moves with the larger of their bands."""
    return float(max(extra[j], extra[(j + 2) % 3]))


def _edge_index(corners: list[int], a: int, b: int) -> int:
    """The local edge of a triangle (its corner vertex ids) whose ends are vertices a and b."""
    return next(k for k in range(3) if {corners[k], corners[(k + 1) % 3]} == {a, b})


def _within(dist: float, eps: float, extra_r: float, extra_t: float) -> bool:
    """A visible feature (finite distance) within eps plus the larger of the two triangles' bands on it."""
    return bool(np.isfinite(dist)) and dist <= eps + max(extra_r, extra_t)


def _near(dist: np.ndarray, eps: np.ndarray, extra: np.ndarray) -> np.ndarray:
    """(K, 3) bool: a visible feature (finite distance) within eps plus its own extra."""
    with np.errstate(invalid="ignore"):
        near: np.ndarray = np.isfinite(dist) & (dist <= eps[:, None] + extra)
    return near


def explain(
    cls: np.ndarray, why: list[str], r_ids: np.ndarray, t_ids: np.ndarray, rows: np.ndarray, cols: np.ndarray
) -> list[dict[str, object]]:
    """Mismatches grouped by (class, ref prim, test prim): failing classes first, then by size."""
    groups: dict[tuple[int, int, int], dict[str, object]] = {}
    pixels: dict[tuple[int, int, int], int] = {}  # each group's "pixels", typed
    for i in range(cls.size):
        key = (int(cls[i]), int(r_ids[i]), int(t_ids[i]))
        g = groups.get(key)
        if g is None:
            pixels[key] = 1
            groups[key] = {
                "class": CLASSES[int(cls[i])],
                "ref_prim": None if key[1] == BACKGROUND_ID else key[1],
                "test_prim": None if key[2] == BACKGROUND_ID else key[2],
                "pixels": 1,
                "example": [int(np.asarray(cols).ravel()[i]), int(np.asarray(rows).ravel()[i])],
                "why": why[i],
            }
        else:
            pixels[key] += 1
            g["pixels"] = pixels[key]
    rank = {INTERIOR: 0, CRACK: 1, TIE: 2, EDGE: 3}
    ordered = sorted(groups.items(), key=lambda kv: (rank[kv[0][0]], -pixels[kv[0]]))
    return [g for _, g in ordered[:MAX_EXPLANATIONS]]


def counts(cls: np.ndarray) -> dict[str, int]:
    """{edge, tie, crack, interior} pixel counts."""
    return {name: int(np.count_nonzero(cls == i)) for i, name in enumerate(CLASSES)}
