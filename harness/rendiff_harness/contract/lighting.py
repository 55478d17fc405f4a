"""Local shading of docs/radiance.md in float64: closed forms for tests, exposure bounds, shadow geometry.

This is *not* a renderer: it evaluates the contract's local-shading formula at points
that some renderer already found (the pixel-center hit points of its own ID and
depth passes), for three purposes:

* `upper_bound`: an upper bound of each pixel's radiance, used by the backends that
  write fixed-point images (POV-Ray's 16-bit PNG, pyrender's 8-bit output) to choose an
  exposure scale so that nothing clips and the quantization step is as small as the
  image allows. It ignores shadows (shadows only darken) and takes |cos| (either side).
* `local_radiance`: the formula itself (with or without float64 shadow rays), which the
  backend tests compare against closed-form scenes.
* `shadow_ambiguity`: for the comparison: does a pixel's shadow ray pass so close to an
  occluder's edge (or meet an occluder so close to either end) that renderers with
  different ray offsets may legitimately disagree on visibility? Such RGB mismatches
  are classified as *edge*, like ID mismatches on triangle edges.

The formula (docs/radiance.md, "Local shading"): at the visible point x with unit
geometric normal n (turned toward the viewer when two-sided; a back-facing hit in a
one-sided scene is black)

    L = Le + sum_point rho/pi I max(0, n.w)/r^2 V + sum_dir rho/pi E max(0, -n.dir) V
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from .resolved import ResolvedScene
from .vocab import BACKGROUND_ID

INV_PI = 1.0 / math.pi
SHADOW_OFFSET_SIZE = 1e-7
SHADOW_OFFSET_POS = 1e-9
"""Shadow-ray origin offset along n: 1e-7 x max(scene size, 1) + 1e-9 x |x| (docs/radiance.md)."""


def shadow_offset(scene: ResolvedScene, x: np.ndarray) -> np.ndarray:
    """(K,) the contract's shadow-ray offset along n at the points x (K, 3)."""
    size_term = SHADOW_OFFSET_SIZE * max(scene_size(scene), 1.0)
    offset: np.ndarray = size_term + SHADOW_OFFSET_POS * np.linalg.norm(x, axis=-1)
    return offset


def face_normals(tris: np.ndarray) -> np.ndarray:
    """(N, 3) float64 unit normals (b - a) x (c - a); zero for degenerate triangles."""
    t = np.asarray(tris, dtype=np.float64)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    length = np.linalg.norm(n, axis=1)
    with np.errstate(all="ignore"):
        return np.where(length[:, None] > 0, n / np.where(length > 0, length, 1.0)[:, None], 0.0)


def scene_size(scene: ResolvedScene) -> float:
    """Diagonal of the bounding box of the triangles (1.0 for an empty scene)."""
    if scene.triangle_count == 0:
        return 1.0
    v = scene.triangles.reshape(-1, 3).astype(np.float64)
    d = float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))
    return d if d > 0 else 1.0


def hit_points(scene: ResolvedScene, z: np.ndarray) -> np.ndarray:
    """World positions eye + z d of the pixel centers, (H, W, 3) float64 (nan where z is not finite)."""
    cam = scene.camera
    d = cam.pixel_directions()
    zz = np.where(np.isfinite(z), z.astype(np.float64), np.nan)
    points: np.ndarray = cam.eye[None, None, :] + zz[..., None] * d
    return points


def lights_of(scene: ResolvedScene) -> tuple[list[tuple[np.ndarray, np.ndarray]], list[tuple[np.ndarray, np.ndarray]]]:
    """([(position, intensity)], [(unit direction, irradiance)]) as float64 arrays.

    Directions are normalized here: the contract says light travels *along* `direction`.
    """
    points, dirs = [], []
    for i, light in enumerate(scene.lights):
        kind = light.get("kind") if isinstance(light, dict) else None
        if kind == "point":
            points.append(
                (np.asarray(light["position"], float).reshape(3), np.asarray(light["intensity"], float).reshape(3))
            )
        elif kind == "directional":
            d = np.asarray(light["direction"], float).reshape(3)
            n = float(np.linalg.norm(d))
            if not n > 0:
                raise ValueError(f"lights[{i}]: directional light with a zero direction")
            dirs.append((d / n, np.asarray(light["irradiance"], float).reshape(3)))
        else:
            raise ValueError(f"lights[{i}]: unknown light kind {kind!r}")
    return points, dirs


def _shading_frame(
    scene: ResolvedScene, prim: np.ndarray, z: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(hit mask, x (K,3), n_geo (K,3), view cos sign (K,), material index (K,)) for hit pixels."""
    hit = (prim != BACKGROUND_ID) & np.isfinite(z)
    hit &= prim.astype(np.uint64) < np.uint64(scene.triangle_count)
    idx = np.flatnonzero(hit)
    p = prim.ravel()[idx].astype(np.int64)
    x = hit_points(scene, z).reshape(-1, 3)[idx]
    n = face_normals(scene.triangles)[p]
    d = scene.camera.pixel_directions().reshape(-1, 3)[idx]
    front = np.einsum("ij,ij->i", n, d) < 0.0
    mats = scene.prim_materials()[p]
    return hit, x, n, front, mats


def local_radiance(
    scene: ResolvedScene,
    prim: np.ndarray,
    z: np.ndarray,
    *,
    two_sided: bool | None = None,
    shadows: bool | None = None,
    upper_bound: bool = False,
    emission: bool = True,
    lights: bool = True,
) -> np.ndarray:
    """(H, W, 3) float64 radiance of docs/radiance.md's local shading at the given hits.

    `prim`, `z`: a renderer's pixel-center prim ids and planar depths (background:
    0xFFFFFFFF / inf -> radiance 0). two_sided / shadows default to the scene's
    `requires`. `upper_bound=True` gives the bound used for exposures: both sides lit
    (|cos|), emission on both sides, no shadows. `emission=False` / `lights=False` drop
    the emitted / the reflected term.
    """
    req = scene.requires
    if two_sided is None:
        two_sided = "two_sided" in req
    if shadows is None:
        shadows = "shadows" in req
    h, w = prim.shape
    out = np.zeros((h * w, 3))
    hit, x, n, front, mats = _shading_frame(scene, prim, z)
    if not x.shape[0]:
        return out.reshape(h, w, 3)
    mat_albedo, mat_emission = scene.material_arrays()
    rho, le = mat_albedo[mats], mat_emission[mats]
    if upper_bound:
        visible = np.ones(front.shape, dtype=bool)
        n_eff = n
    else:
        visible = front | two_sided
        n_eff = np.where(front[:, None] | (not two_sided), n, -n)
    value = np.zeros((x.shape[0], 3))
    if emission and ("emission" in req or upper_bound):
        value += np.where(visible[:, None], le, 0.0)
    points, dirs = lights_of(scene) if lights and (upper_bound or "lambert" in req) else ([], [])
    offset = shadow_offset(scene, x)[:, None]
    for pos, intensity in points:
        to_l = pos[None, :] - x
        r2 = np.einsum("ij,ij->i", to_l, to_l)
        with np.errstate(all="ignore"):
            cos = np.einsum("ij,ij->i", n_eff, to_l) / np.sqrt(r2)
            cos = np.abs(cos) if upper_bound else np.maximum(cos, 0.0)
            e = np.where(r2 > 0, cos / r2, 0.0)
        if shadows and not upper_bound:
            e = e * visible_to(scene, x + offset * n_eff, np.broadcast_to(pos, x.shape), finite=True)
        value += np.where(visible[:, None], rho * INV_PI * intensity[None, :] * e[:, None], 0.0)
    for direction, irradiance in dirs:
        cos = -(n_eff @ direction)
        cos = np.abs(cos) if upper_bound else np.maximum(cos, 0.0)
        if shadows and not upper_bound:
            far = 4.0 * scene_size(scene) + float(np.abs(x).max(initial=0.0))
            cos = cos * visible_to(scene, x + offset * n_eff, x - far * direction[None, :], finite=False)
        value += np.where(visible[:, None], rho * INV_PI * irradiance[None, :] * cos[:, None], 0.0)
    out[np.flatnonzero(hit)] = value
    return out.reshape(h, w, 3)


def upper_bound(
    scene: ResolvedScene, prim: np.ndarray, z: np.ndarray, *, emission: bool = True, lights: bool = True
) -> np.ndarray:
    """(H, W, 3) float64: no renderer following the contract exceeds this at these hits.

    `emission` / `lights` select the terms (a backend that renders them in separate
    passes bounds each pass on its own).
    """
    return local_radiance(scene, prim, z, upper_bound=True, emission=emission, lights=lights)


# --------------------------------------------------------------------------- shadow rays


def _segment_hits(origins: np.ndarray, targets: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K, M) segment parameter s in (0, 1) where segment k crosses triangle m (nan if not), and inside mask."""
    o, e = origins[:, None, :], (targets - origins)[:, None, :]
    a, b, c = tris[None, :, 0], tris[None, :, 1], tris[None, :, 2]
    e1, e2 = b - a, c - a
    pvec = np.cross(e, e2)
    det = np.einsum("kmi,kmi->km", e1, pvec)
    with np.errstate(all="ignore"):
        inv = 1.0 / det
        tvec = o - a
        u = np.einsum("kmi,kmi->km", tvec, pvec) * inv
        qvec = np.cross(tvec, e1)
        v = np.einsum("kmi,kmi->km", e, qvec) * inv
        s = np.einsum("kmi,kmi->km", e2, qvec) * inv
    inside = np.isfinite(s) & (u >= 0) & (v >= 0) & (u + v <= 1)
    return s, inside


def visible_to(
    scene: ResolvedScene, origins: np.ndarray, targets: np.ndarray, finite: bool = True, chunk: int = 1 << 22
) -> np.ndarray:
    """(K,) float64 1.0 where no triangle crosses the open segment origin -> target, else 0.0.

    Brute force over every triangle in float64 (tests and small scenes only).
    """
    tris = scene.triangles.astype(np.float64)
    k = origins.shape[0]
    vis = np.ones(k)
    if not tris.shape[0] or not k:
        return vis
    step = max(1, chunk // max(1, tris.shape[0]))
    for s0 in range(0, k, step):
        s, inside = _segment_hits(origins[s0 : s0 + step], targets[s0 : s0 + step], tris)
        blocked = inside & (s > 0) & (s < 1)
        vis[s0 : s0 + step] = np.where(blocked.any(axis=1), 0.0, 1.0)
    return vis


def shadow_ambiguity(
    scene: ResolvedScene,
    prim: np.ndarray,
    z: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    eps: float,
    max_work: float = 2e8,
    ray_offset: Callable[[np.ndarray], np.ndarray] | None = None,
) -> np.ndarray | None:
    """(K,) bool: pixel (rows[k], cols[k])'s shadow ray to some light is within ~`eps` of flipping.

    For every light, the segment from the hit point x (the reference's) to the light
    (or 4 scene sizes along -direction) is ambiguous when
      (a) moving it sideways by `eps` (8 directions perpendicular to it, 45 degrees
          apart: any edge within 0.92 eps is crossed) changes whether a triangle blocks
          it: it passes an occluder's silhouette (internal edges of a surface do not
          count: the shifted rays are blocked by the neighbouring triangle), or
      (b) a triangle other than the pixel's own crosses it within `eps` of either end
          (contact shadows: each renderer offsets its shadow rays differently).
    Triangles coplanar with the pixel's own (the receiver's surface: within `eps` of its
    plane, normals parallel) cannot block a ray leaving that plane and are ignored.
    Brute force over all triangles: returns None when 9 K * triangles * lights exceeds
    `max_work` (the caller then classifies nothing as a shadow edge and says so).
    `ray_offset(x)` (K,): a renderer's own shadow-ray offset at the hit points, which moves its shadow
    ray that far from the reference's (parallel to it); where it exceeds `eps` the band at that pixel
    is offset / cos(pi/8), so that an edge within the offset is crossed by one of the 8 shifts.
    """
    k = rows.size
    out = np.zeros(k, dtype=bool)
    if k == 0 or not scene.lights or scene.triangle_count == 0:
        return out
    n_tri = scene.triangle_count
    if 9.0 * k * n_tri * len(scene.lights) > max_work:
        return None
    pr = prim[rows, cols]
    zz = z[rows, cols].astype(np.float64)
    ok = (pr != BACKGROUND_ID) & (pr.astype(np.uint64) < np.uint64(n_tri)) & np.isfinite(zz)
    if not ok.any():
        return out
    d = scene.camera.pixel_directions()[rows, cols]
    x = scene.camera.eye[None, :] + np.where(ok, zz, 0.0)[:, None] * d
    band = np.full(k, float(eps))
    if ray_offset is not None:
        band = np.maximum(band, ray_offset(x) / math.cos(math.pi / 8.0))
    tris = scene.triangles.astype(np.float64)
    points, dirs = lights_of(scene)
    far = 4.0 * scene_size(scene) + float(np.abs(tris).max(initial=0.0))
    ends = [np.broadcast_to(p, x.shape) for p, _ in points] + [x - far * dd[None, :] for dd, _ in dirs]
    own = np.where(ok, pr, 0).astype(np.int64)
    normals = face_normals(tris)
    n_own = normals[own]  # (K, 3)
    step = max(1, int(4e6 // max(1, n_tri)))
    angles = np.arange(8) * (np.pi / 4.0)
    for end in ends:
        seg = end - x
        length = np.linalg.norm(seg, axis=1)
        with np.errstate(all="ignore"):
            u = np.where(length[:, None] > 0, seg / np.where(length > 0, length, 1.0)[:, None], 0.0)
        helper = np.where(np.abs(u[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
        t1 = np.cross(u, helper)
        t1 /= np.maximum(np.linalg.norm(t1, axis=1), 1e-300)[:, None]
        t2 = np.cross(u, t1)
        for s0 in range(0, k, step):
            sl = slice(s0, s0 + step)
            xs, es, bs = x[sl], end[sl], band[sl]
            # (K', M): triangle m lies in pixel k's receiver plane, or is the pixel's own
            blockers = ~(
                (np.abs(n_own[sl] @ normals.T) > 1.0 - 1e-9)
                & (
                    np.abs(
                        np.einsum("kj,mj->km", n_own[sl], tris[:, 0]) - np.einsum("kj,kj->k", n_own[sl], xs)[:, None]
                    )
                    < bs[:, None]
                )
            )
            blockers[np.arange(xs.shape[0]), own[sl]] = False
            s, inside = _segment_hits(xs, es, tris)
            crossing = inside & (s > 0) & (s < 1) & blockers
            base = crossing.any(axis=1)
            along = s * length[sl, None]
            close = (crossing & ((along < bs[:, None]) | (along > length[sl, None] - bs[:, None]))).any(axis=1)
            flips = np.zeros(xs.shape[0], dtype=bool)
            for a in angles:
                shift = bs[:, None] * (np.cos(a) * t1[sl] + np.sin(a) * t2[sl])
                s2, in2 = _segment_hits(xs + shift, es + shift, tris)
                flips |= (in2 & (s2 > 0) & (s2 < 1) & blockers).any(axis=1) != base
            out[sl] |= ok[sl] & (close | flips)
    return out


def emissive_materials(scene: ResolvedScene) -> np.ndarray:
    """(M,) bool: materials with any emission > 0."""
    _, emi = scene.material_arrays()
    return np.asarray((emi > 0).any(axis=1)) if emi.size else np.zeros(0, dtype=bool)


def light_summary(scene: ResolvedScene) -> list[dict[str, Any]]:
    """The lights as plain floats (for info dicts)."""
    points, dirs = lights_of(scene)
    out: list[dict[str, Any]] = [{"kind": "point", "position": p.tolist(), "intensity": i.tolist()} for p, i in points]
    out += [{"kind": "directional", "direction": d.tolist(), "irradiance": e.tolist()} for d, e in dirs]
    return out


def group_by_material(scene: ResolvedScene) -> list[tuple[int, np.ndarray]]:
    """[(material index, prim ids (ascending) of its triangles)] for materials that have triangles."""
    mats = scene.prim_materials()
    out: list[tuple[int, np.ndarray]] = []
    for m in np.unique(mats).tolist():
        out.append((int(m), np.flatnonzero(mats == m)))
    return out
