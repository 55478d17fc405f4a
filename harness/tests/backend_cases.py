"""Shared cases for the external-backend tests, and the float64 answer they are checked against.

`cast` is a pixel-center ray cast.

It follows docs/DESIGN.md literally (one ray through each pixel center, planar depth, nearest
wins, equal depth -> lower prim_id, no culling, zero-area never visible) but shares no
code with any backend or with the Rust core. Coverage is decided in float64 on the
projected triangle (equivalent in sign to the 3-D orientation test for geometry in front
of the camera), with closed edges instead of the top-left rule, so pixel centers within
~1e-9 px of an edge are ambiguous: tests use `edge_dist` to leave those out or to classify
mismatches as edge mismatches.

The scene builders below write small resolved scenes (through fixtures.write_scene) whose
answers are known in closed form or from `cast`; `height_field` is the ~100k-triangle
fixture used for timings.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from fixtures import write_scene
from rendiff_harness import compare
from rendiff_harness.contract import exrbuf, resolved
from rendiff_harness.contract.resolved import ResolvedScene
from rendiff_harness.renderers import registry

BACKGROUND_ID = 0xFFFFFFFF


@dataclass(frozen=True)
class Reference:
    prim: np.ndarray  # (H, W) uint32, 0xFFFFFFFF = background
    obj: np.ndarray  # (H, W) uint32
    z: np.ndarray  # (H, W) float64 planar depth, +inf = background
    edge_dist: np.ndarray  # (H, W) float64: px from the center to the nearest projected edge (inf if > ~1 px)


def project(scene: ResolvedScene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Continuous pixel coordinates (x right, y down, centers at k+0.5) and planar depth of each vertex.

    Shapes (N, 3). Only meaningful for vertices in front of the camera.
    """
    cam = scene.camera
    x, y, depth = np.moveaxis(cam.to_camera(scene.triangles), -1, 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        pixel = cam.to_pixel(x, y, depth)
    return pixel[..., 0], pixel[..., 1], depth


def _segment_dist(
    px: np.ndarray, py: np.ndarray, ax: np.ndarray, ay: np.ndarray, bx: np.ndarray, by: np.ndarray
) -> np.ndarray:
    ex, ey = bx - ax, by - ay
    len2 = ex * ex + ey * ey
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.clip(((px - ax) * ex + (py - ay) * ey) / len2, 0.0, 1.0)
    t = np.where(len2 > 0, t, 0.0)
    return np.hypot(px - (ax + t * ex), py - (ay + t * ey))


def _edge(ax: np.ndarray, ay: np.ndarray, bx: np.ndarray, by: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Edge function of a -> b at p, evaluated from the lexicographically smaller endpoint.

    Both triangles sharing an edge then get exactly opposite values (bit for bit), so
    with closed edges no pixel center falls through a shared edge.
    """
    swap = (ax > bx) | ((ax == bx) & (ay > by))
    lx, ly = np.where(swap, bx, ax), np.where(swap, by, ay)
    hx, hy = np.where(swap, ax, bx), np.where(swap, ay, by)
    e = (hx - lx) * (py - ly) - (hy - ly) * (px - lx)
    return np.where(swap, -e, e)


def _candidates(x0: np.ndarray, y0: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(triangle, column, row) for every pixel of a size x size window at (x0, y0) per triangle."""
    off = np.arange(size)
    ox, oy = np.meshgrid(off, off)
    tri = np.repeat(np.arange(x0.size), size * size)
    cols = (x0[:, None] + ox.ravel()[None, :]).ravel()
    rows = (y0[:, None] + oy.ravel()[None, :]).ravel()
    return tri, cols, rows


def cast(scene: ResolvedScene, margin_px: float = 1.0) -> Reference:
    """Pixel-center ray cast of the whole scene in float64 (geometry must be in front of the eye)."""
    cam = scene.camera
    w, h = cam.width, cam.height
    px, py, depth = project(scene)
    if depth.size and depth.min() <= cam.near:
        raise ValueError("reference cast needs every vertex beyond the near plane")
    tris = scene.triangles.astype(np.float64)
    normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    offset = np.einsum("ij,ij->i", normals, tris[:, 0] - cam.eye)

    # Pixel windows: bbox of the projection grown by margin_px (for edge distances).
    x0 = np.floor(px.min(axis=1) - 0.5 - margin_px).astype(np.int64)
    x1 = np.ceil(px.max(axis=1) - 0.5 + margin_px).astype(np.int64)
    y0 = np.floor(py.min(axis=1) - 0.5 - margin_px).astype(np.int64)
    y1 = np.ceil(py.max(axis=1) - 0.5 + margin_px).astype(np.int64)
    x0, y0 = np.clip(x0, 0, w - 1), np.clip(y0, 0, h - 1)
    x1, y1 = np.clip(x1, -1, w - 1), np.clip(y1, -1, h - 1)
    extent = np.maximum(x1 - x0, y1 - y0) + 1
    onscreen = (x1 >= x0) & (y1 >= y0)
    small = onscreen & (extent <= 12)
    parts = []
    idx = np.nonzero(small)[0]
    if idx.size:
        size = int(extent[idx].max())
        t, c, r = _candidates(x0[idx], y0[idx], size)
        parts.append((idx[t], c, r))
    for i in np.nonzero(onscreen & ~small)[0]:
        cc, rr = np.meshgrid(np.arange(x0[i], x1[i] + 1), np.arange(y0[i], y1[i] + 1))
        parts.append((np.full(cc.size, i), cc.ravel(), rr.ravel()))

    prim = np.full((h, w), BACKGROUND_ID, dtype=np.uint32)
    zbuf = np.full((h, w), np.inf)
    edge = np.full((h, w), np.inf)
    if not parts:
        return Reference(prim, prim.copy(), zbuf, edge)
    tri = np.concatenate([p[0] for p in parts])
    col = np.concatenate([p[1] for p in parts])
    row = np.concatenate([p[2] for p in parts])
    keep = (col >= 0) & (col < w) & (row >= 0) & (row < h)
    tri, col, row = tri[keep], col[keep], row[keep]

    cx, cy = col + 0.5, row + 0.5
    ax, ay, bx, by, qx, qy = (px[tri, 0], py[tri, 0], px[tri, 1], py[tri, 1], px[tri, 2], py[tri, 2])
    dist = np.minimum(
        np.minimum(_segment_dist(cx, cy, ax, ay, bx, by), _segment_dist(cx, cy, bx, by, qx, qy)),
        _segment_dist(cx, cy, qx, qy, ax, ay),
    )
    pix = row * w + col
    np.minimum.at(edge.ravel(), pix, dist)

    e0 = _edge(ax, ay, bx, by, cx, cy)
    e1 = _edge(bx, by, qx, qy, cx, cy)
    e2 = _edge(qx, qy, ax, ay, cx, cy)
    # Closed triangles (>= 0): a center exactly on a shared edge is covered by both sides, so
    # the reference has no cracks; the tie then goes to the nearer / lower prim_id.
    area = (bx - ax) * (qy - ay) - (by - ay) * (qx - ax)
    inside = (area != 0) & (((e0 >= 0) & (e1 >= 0) & (e2 >= 0)) | ((e0 <= 0) & (e1 <= 0) & (e2 <= 0)))

    d = cam.pixel_directions()[row, col]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = offset[tri] / np.einsum("ij,ij->i", normals[tri], d)
    inside &= np.isfinite(t) & (t >= cam.near) & (t <= cam.far)
    tri, pix, t = tri[inside], pix[inside], t[inside]
    order = np.lexsort((tri, t, pix))
    tri, pix, t = tri[order], pix[order], t[order]
    first = np.ones(pix.size, dtype=bool)
    first[1:] = pix[1:] != pix[:-1]
    prim.ravel()[pix[first]] = tri[first]
    zbuf.ravel()[pix[first]] = t[first]
    obj = np.full((h, w), BACKGROUND_ID, dtype=np.uint32)
    hit = prim != BACKGROUND_ID
    obj[hit] = scene.object_ids[prim[hit]]
    return Reference(prim, obj, zbuf, edge)


def plane_depth(scene: ResolvedScene, point: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Closed-form planar depth of the plane (point, normal) at every pixel center, float64."""
    cam = scene.camera
    d = cam.pixel_directions()
    return float(np.dot(normal, point - cam.eye)) / (d @ normal)


def height_field(directory: Path, quads_per_side: int = 224, width: int = 640, height: int = 480) -> Path:
    """~2*quads^2 triangles (100,352 by default) of a bumpy surface filling a 45-degree view.

    Two objects (left / right half) so object IDs are exercised; shared edges everywhere,
    so it is a fair test of edge handling.
    """
    n = quads_per_side
    xs = np.linspace(-3.2, 3.2, n + 1)
    ys = np.linspace(-2.6, 2.6, n + 1)
    gx, gy = np.meshgrid(xs, ys)
    gz = 0.35 * np.sin(2.1 * gx) * np.cos(1.7 * gy) + 0.1 * np.sin(7.3 * gx + 3.1 * gy)
    v = np.stack([gx, gy, gz], axis=-1)
    a, b, c, d = v[:-1, :-1], v[:-1, 1:], v[1:, 1:], v[1:, :-1]
    lower = np.stack([a, b, c], axis=2).reshape(-1, 3, 3)
    upper = np.stack([a, c, d], axis=2).reshape(-1, 3, 3)
    tris = np.stack([lower, upper], axis=1).reshape(-1, 3, 3)
    centroid_x = tris[:, :, 0].mean(axis=1)
    oids = (centroid_x > 0).astype(np.uint32)
    return _write(directory, tris, oids, width=width, height=height, name="height_field")


def _write(directory: Path, tris: npt.ArrayLike, oids: npt.ArrayLike | None = None, **kwargs: Any) -> Path:
    """fixtures.write_scene with numpy inputs (it wants nested sequences; values stay exact)."""
    tri_list = np.asarray(tris, dtype=np.float32).reshape(-1, 3, 3).tolist()
    oid_list = None if oids is None else [int(v) for v in np.asarray(oids).ravel()]
    return write_scene(directory, tri_list, oid_list, **kwargs)


def _quad(center: np.ndarray, e1: np.ndarray, e2: np.ndarray) -> list[np.ndarray]:
    """Two triangles covering center +- e1 +- e2 (counter-clockwise seen against e1 x e2)."""
    a, b, c, d = center - e1 - e2, center + e1 - e2, center + e1 + e2, center - e1 + e2
    return [np.array([a, b, c]), np.array([a, c, d])]


def facing_quad(directory: Path, distance: float, width: int = 64, height: int = 48) -> Path:
    """A plane perpendicular to the view axis at `distance`, filling the view: Z == distance."""
    eye = np.array([0.3, -0.2, distance])
    half = 2.0 * distance
    tris = _quad(np.array([0.3, -0.2, 0.0]), np.array([half, 0.0, 0.0]), np.array([0.0, half, 0.0]))
    return _write(
        directory,
        tris,
        eye=eye,
        look_at=(0.3, -0.2, 0.0),
        width=width,
        height=height,
        near=1e-3 * distance,
        name="facing_quad",
    )


TILTED_POINT = np.array([0.0, 0.0, 0.0])
TILTED_NORMAL = np.array([0.4, 0.3, 1.0]) / np.linalg.norm([0.4, 0.3, 1.0])


def tilted_quad(directory: Path, width: int = 80, height: int = 60) -> Path:
    """A plane through TILTED_POINT with normal TILTED_NORMAL, seen off-axis; fills the view."""
    e1 = np.cross(TILTED_NORMAL, [0.0, 1.0, 0.0])
    e1 = 30.0 * e1 / np.linalg.norm(e1)
    e2 = 30.0 * np.cross(TILTED_NORMAL, e1) / np.linalg.norm(e1)
    return _write(
        directory,
        _quad(TILTED_POINT, e1, e2),
        eye=(1.0, 2.0, 6.0),
        look_at=(0.0, 0.0, 0.0),
        width=width,
        height=height,
        name="tilted_quad",
    )


def three_triangles_two_objects(directory: Path, width: int = 160, height: int = 120) -> Path:
    """fixtures.three_triangles' geometry with object_ids [0, 1, 1]."""
    tris = [
        [[-1.5, -1.0, 0.0], [0.5, -1.0, 0.0], [-0.5, 1.2, 0.0]],
        [[-0.5, -1.2, -1.0], [1.5, -1.2, -1.0], [0.5, 1.0, -1.0]],
        [[-1.0, -0.2, 1.0], [1.0, -0.2, 1.0], [0.0, 0.6, 1.0]],
    ]
    return _write(directory, tris, [0, 1, 1], width=width, height=height, name="three_triangles_2obj")


def orientation_scene(directory: Path) -> Path:
    """prim 0 left of the view center, prim 1 above it (camera on +z looking at -z, y up)."""
    tris = [
        [[-1.6, -0.3, 0.0], [-0.6, -0.3, 0.0], [-1.1, 0.3, 0.0]],
        [[-0.3, 0.6, 0.0], [0.3, 0.6, 0.0], [0.0, 1.4, 0.0]],
    ]
    return _write(directory, tris, [0, 1], width=64, height=48, name="orientation")


def back_facing(directory: Path) -> Path:
    """One triangle wound clockwise as seen from the camera (its normal points away)."""
    tris = [[[-1.0, -1.0, 0.0], [0.0, 1.0, 0.0], [1.0, -1.0, 0.0]]]
    return _write(directory, tris, width=32, height=24, name="back_facing")


HIGH_IDS = (255, 65535, 70000)


def high_ids(directory: Path, count: int = 70001) -> Path:
    """`count` tiny triangles far off-screen, except prims HIGH_IDS: visible, side by side.

    The IDs exercise every byte of a 24-bit colour code (id + 1 = 0x100, 0x10000, 0x11171).
    """
    base = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]])
    tris = np.repeat(base[None], count, axis=0)
    tris[:, :, 0] += 100.0 + 0.02 * (np.arange(count) % 100)[:, None]
    tris[:, :, 1] += 0.02 * (np.arange(count) // 100)[:, None]
    oids = np.zeros(count, dtype=np.uint32)
    for k, prim in enumerate(HIGH_IDS):
        x0 = -1.5 + 1.0 * k
        tris[prim] = [[x0, -0.5, 0.0], [x0 + 0.9, -0.5, 0.0], [x0 + 0.45, 0.5, 0.0]]
        oids[prim] = k + 1
    return _write(directory, tris, oids, width=64, height=48, name="high_ids")


def empty_scene(directory: Path) -> Path:
    return _write(directory, np.zeros((0, 3, 3)), width=16, height=12, name="empty")


def near_clipped(directory: Path) -> Path:
    """Prims 0-1 (a quad at depth 0.05, half the view) lie before the near plane 0.1; prims 2-3 fill it at depth 1."""
    tris = _quad(np.array([0.0, 0.0, 4.95]), np.array([0.01, 0, 0]), np.array([0, 0.01, 0]))
    tris += _quad(np.array([0.0, 0.0, 4.0]), np.array([5.0, 0, 0]), np.array([0, 5.0, 0]))
    return _write(directory, tris, [0, 0, 1, 1], width=32, height=24, near=0.1, name="near_clipped")


# --------------------------------------------------------------------------- lit scenes

LIT_ALBEDO = (0.8, 0.5, 0.25)


def lit_plane(
    directory: Path,
    lights: list[dict[str, Any]],
    *,
    requires: tuple[str, ...] = ("depth", "ids", "lambert", "point_light", "shadowless", "two_sided"),
    albedo: tuple[float, float, float] = LIT_ALBEDO,
    emission: tuple[float, float, float] = (0.0, 0.0, 0.0),
    width: int = 64,
    height: int = 48,
    flip: bool = False,
) -> Path:
    """A large quad in the plane z = 0 (normal +z, or -z when `flip`) seen from (0.4, -0.3, 4) off-axis.

    Every pixel sees the plane, so the closed-form radiance is known at every pixel center.
    """
    tris = _quad(np.array([0.0, 0.0, 0.0]), np.array([20.0, 0.0, 0.0]), np.array([0.0, 20.0, 0.0]))
    if flip:
        tris = [t[[0, 2, 1]] for t in tris]
    mats = [{"name": "m", "albedo": list(albedo), "emission": list(emission)}]
    return _write(
        directory,
        tris,
        eye=(0.4, -0.3, 4.0),
        look_at=(0.0, 0.2, 0.0),
        width=width,
        height=height,
        requires=requires,
        materials=mats,
        lights=lights,
        name="lit_plane",
    )


def occluded_plane(
    directory: Path,
    shadows: str,
    width: int = 64,
    height: int = 48,
    light: tuple[list[float], list[float]] = ([0.1, 0.05, 2.0], [4.0, 3.0, 2.0]),
) -> Path:
    """lit_plane plus a small square (prims 2-3) at height 1 between the plane and a point light at height 2.

    `shadows` is "shadows" or "shadowless"; with shadows the square casts a visible shadow.
    `light` is the point light's (position, intensity).
    """
    import json

    d = lit_plane(
        directory,
        [{"kind": "point", "position": light[0], "intensity": light[1]}],
        requires=("depth", "ids", "lambert", "point_light", shadows, "two_sided"),
        width=width,
        height=height,
    )
    tris = np.fromfile(d / "triangles.f32", dtype="<f4").reshape(-1, 3, 3)
    sq = np.array(_quad(np.array([0.0, 0.0, 1.0]), np.array([0.25, 0, 0]), np.array([0, 0.25, 0])))
    np.concatenate([tris, sq.astype(np.float32)]).astype("<f4").tofile(d / "triangles.f32")
    np.array([0, 0, 1, 1], dtype="<u4").tofile(d / "object_ids.u32")
    meta = json.loads((d / "scene.json").read_text())
    meta["triangle_count"] = 4
    meta["objects"].append({"name": "occluder", "material": 0, "first_prim": 2, "prim_count": 2})
    (d / "scene.json").write_text(json.dumps(meta))
    return d


def closed_form_plane(scene: ResolvedScene, flip: bool = False) -> np.ndarray:
    """(H, W, 3) float64 contract radiance on `lit_plane` at the pixel centers, written out by hand.

    x = eye + z d with z the exact plane depth; the viewer is above the plane (z > 0), so
    the geometric normal n = (0, 0, +-1) faces it unless `flip`:
      two_sided: n turned toward the viewer, emission and shading on both sides;
      one_sided: a back-facing plane is black.
    L = Le + sum_point rho/pi I max(0, n.w)/r^2 + sum_dir rho/pi E max(0, -n.dir)   (no occluders)
    """
    n_geo = np.array([0.0, 0.0, -1.0 if flip else 1.0])
    z = plane_depth(scene, np.zeros(3), n_geo)
    x = scene.camera.eye[None, None, :] + z[..., None] * scene.camera.pixel_directions()
    facing = not flip  # the eye is at z > 0
    two_sided = "two_sided" in scene.requires
    if not facing and not two_sided:
        return np.zeros(z.shape + (3,))
    n = np.array([0.0, 0.0, 1.0])  # turned toward the viewer
    mat = scene.materials[0]
    rho = np.asarray(mat["albedo"], float)
    out = np.zeros(z.shape + (3,))
    if "emission" in scene.requires:
        out += np.asarray(mat["emission"], float)
    for light in scene.lights:
        if light["kind"] == "point":
            to_l = np.asarray(light["position"], float) - x
            r2 = (to_l**2).sum(axis=-1)
            cos = np.maximum((to_l @ n) / np.sqrt(r2), 0.0)
            out += rho / np.pi * np.asarray(light["intensity"], float) * (cos / r2)[..., None]
        else:
            d = np.asarray(light["direction"], float)
            d = d / np.linalg.norm(d)
            cos = max(0.0, float(-(n @ d)))
            out += rho / np.pi * np.asarray(light["irradiance"], float) * cos
    return out


def furnace(directory: Path, albedo: float = 0.5, emission: float = 1.0, width: int = 24, height: int = 24) -> Path:
    """A closed room, every inward wall with albedo rho and emission Le: L = Le / (1 - rho) everywhere."""
    import json

    tris = _box((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0), inward=True)
    path = _write(
        directory,
        tris,
        eye=(0.1, 0.2, 0.3),
        look_at=(0.5, -0.3, -1.0),
        vfov_deg=70.0,
        width=width,
        height=height,
        requires=("depth", "ids", "emission", "lambert", "area_light", "global_illumination", "one_sided"),
        materials=[{"name": "wall", "albedo": [albedo] * 3, "emission": [emission] * 3}],
        name="furnace",
    )
    meta = json.loads((path / "scene.json").read_text())
    meta["integrator"] = {"max_depth": -1, "spp": 64}
    (path / "scene.json").write_text(json.dumps(meta, indent=1))
    return path


def _quad_n(center: Any, normal: Any, u: Any, half_u: float, half_v: float) -> list[np.ndarray]:
    """Two triangles of a rectangle facing `normal` (counter-clockwise seen from that side)."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    uu = np.asarray(u, float) / np.linalg.norm(u)
    return _quad(np.asarray(center, float), uu * half_u, np.cross(n, uu) * half_v)


def _box(lo: Any, hi: Any, yaw_deg: float = 0.0, at: Any = (0.0, 0.0, 0.0), inward: bool = False) -> list[np.ndarray]:
    """12 triangles of an axis-aligned box [lo, hi], turned by yaw about +y and moved to `at`."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c, h = 0.5 * (lo + hi), 0.5 * (hi - lo)
    s = -1.0 if inward else 1.0
    faces = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = np.zeros(3)
            n[axis] = sign
            u = np.zeros(3)
            u[(axis + 1) % 3] = 1.0
            v_axis = (axis + 2) % 3
            faces += _quad_n(c + n * h[axis], s * n, u, h[(axis + 1) % 3], h[v_axis])
    a = np.radians(yaw_deg)
    rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    return [t @ rot.T + np.asarray(at, float) for t in faces]


CORNELL_REQUIRES = (
    "depth",
    "ids",
    "emission",
    "lambert",
    "area_light",
    "global_illumination",
    "one_sided",
)


def cornell(
    directory: Path,
    width: int = 64,
    height: int = 64,
    requires: tuple[str, ...] = CORNELL_REQUIRES,
    lights: list[dict[str, Any]] | None = None,
    emission: tuple[float, float, float] = (17.0, 12.0, 4.0),
) -> Path:
    """A Cornell-like box (scenes/cornell_box.toml's layout): inward room, red/green walls,
    two blocks, a one-sided ceiling light facing down. Objects: room 0, left 1, right 2,
    tall 3, short 4, light 5; materials white 0, red 1, green 2, light 3."""
    objs: list[tuple[list[np.ndarray], int]] = [
        (_box((-1.0, 0.0, -1.0), (1.0, 2.0, 3.5), inward=True), 0),
        (_quad_n((-0.999, 1.0, 1.25), (1, 0, 0), (0, 0, 1), 2.25, 1.0), 1),
        (_quad_n((0.999, 1.0, 1.25), (-1, 0, 0), (0, 0, 1), 2.25, 1.0), 2),
        (_box((-0.3, 0.0, -0.3), (0.3, 1.2, 0.3), 17.0, (-0.35, 0.0, -0.3)), 0),
        (_box((-0.3, 0.0, -0.3), (0.3, 0.6, 0.3), -18.0, (0.35, 0.0, 0.35)), 0),
        (_quad_n((0.0, 1.98, 0.0), (0, -1, 0), (1, 0, 0), 0.25, 0.2), 3),
    ]
    tris, oids = [], []
    for k, (faces, _) in enumerate(objs):
        tris += faces
        oids += [k] * len(faces)
    materials = [
        {"name": "white", "albedo": [0.73, 0.73, 0.73], "emission": [0, 0, 0]},
        {"name": "red", "albedo": [0.63, 0.065, 0.05], "emission": [0, 0, 0]},
        {"name": "green", "albedo": [0.14, 0.45, 0.091], "emission": [0, 0, 0]},
        {"name": "light", "albedo": [0.78, 0.78, 0.78], "emission": list(emission)},
    ]
    path = _write(
        directory,
        tris,
        oids,
        eye=(0.0, 1.0, 3.3),
        look_at=(0.0, 1.0, 0.0),
        vfov_deg=40.0,
        width=width,
        height=height,
        requires=requires,
        materials=materials,
        lights=lights,
        name="cornell",
    )
    # fixtures.write_scene gives every object material 0: set the real ones.
    import json

    meta = json.loads((path / "scene.json").read_text())
    for k, (_, m) in enumerate(objs):
        meta["objects"][k]["material"] = m
    meta["integrator"] = {"max_depth": -1, "spp": 64}
    (path / "scene.json").write_text(json.dumps(meta, indent=1))
    return path


def judge_renders(directory: Path, backends: tuple[str, ...]) -> dict[tuple[str, str], Any]:
    """Renders the resolved scene in `directory` (a run's scenes/<name>/resolved) on `backends`, the
    float64 ray cast (`cast`) as the reference, and returns the comparison's id, Z and N entries by
    (backend, buffer)."""
    scene = resolved.load(directory)
    sdir, run = directory.parent, directory.parents[2]
    ref = cast(scene)
    exrbuf.write_buffers(sdir / "raster.exr", Z=ref.z.astype(np.float32), prim=ref.prim, obj=ref.obj)
    renders: list[dict[str, Any]] = [
        {"backend": "raster", "status": "ok", "exr": (sdir / "raster.exr").relative_to(run).as_posix(), "info": {}}
    ]
    for name in backends:
        exr = sdir / f"{name}.exr"
        backend = registry.get(name)
        info = backend.render(scene, exr, sdir, 60.0)
        renders.append(
            {
                "backend": name,
                "status": "ok",
                "exr": exr.relative_to(run).as_posix(),
                "buffers": [b for b in ("Z", "id", "N") if b in backend.buffers],
                "info": info,
                "time_s": 0.1,
                "version": name,
                "command": name,
            }
        )
    manifest = {
        "format": "rendiff-manifest/1",
        "reference": "raster",
        "created": "2026-11-29T10:00:00Z",
        "rendiff_version": "0.1.0",
        "scenes": [
            {
                "scene": sdir.name,
                "scene_file": "s.toml",
                "resolved": directory.relative_to(run).as_posix(),
                "requires": ["depth", "ids"],
                "renders": renders,
            }
        ],
    }
    (run / "manifest.json").write_text(json.dumps(manifest))
    assert compare.main(["--run", str(run), "--no-images"]) in (0, 1)
    doc = json.loads((run / "results.json").read_text())
    return {(r["backend"], r["buffer"]): r for r in doc["results"] if r["buffer"] in ("id", "Z", "N")}
