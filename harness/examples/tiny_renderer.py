#!/usr/bin/env python3
"""A complete renderer for rendiff in one file: the worked example of docs/your-renderer.md.

    python tiny_renderer.py SCENE_DIR OUT.exr

It reads the resolved scene that `rendiff export` writes (docs/resolved-scene.md), casts one
ray through each pixel center, and writes Z, id.prim, id.object and N to OUT.exr. Each
triangle is tested against the pixels of its projected bounding box (every pixel when a
vertex is behind the near plane): it is a teaching renderer, not a fast one.

Arithmetic, from which its declared precision follows (renderers.toml beside it):

* t = n.(a - eye) / n.d per pixel in float64, the planar depth (d is not normalized), rounded
  to float32 once: it can differ from the core's f32 value by one f32 step, 2^-23 Z;
* coverage: the hit point P = eye + t d is inside when the three float64 edge functions
  ((b - a) x (P - a)).n etc. are all >= 0 or all <= 0 (closed edges: a center exactly on a
  shared edge is covered by both triangles, and the lower prim_id wins, not the top-left
  rule: the verifier's *edge* class allows that); float64 rounding moves an edge by far
  less than 1e-6 px;
* N = normalize((b - a) x (c - a)) in float64, rounded to float32: angle <= 4 2^-24.

Exit status: 0 with OUT.exr written; 3 (skipped) with the reason on the last stderr line
when it cannot run here; anything else is an error.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

try:
    import numpy as np
except ImportError:
    print("numpy is not installed", file=sys.stderr)
    sys.exit(3)

# The harness's EXR writer (float32 Z and N, exact uint32 ids); any OpenEXR writer will do.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from rendiff_harness.contract import exrbuf  # noqa: E402

BACKGROUND = 0xFFFFFFFF


def read_scene(scene_dir: Path) -> tuple[tuple[Any, ...], np.ndarray, np.ndarray]:
    """The camera (width, height, eye, forward, right, up, near, far, tan of half the vertical field
    of view; vectors in float64, far inf when there is none), the triangles (n, 3, 3) in float64 and
    each triangle's object ID, as docs/resolved-scene.md defines them."""
    meta = json.loads((scene_dir / "scene.json").read_text())
    cam = meta["camera"]
    eye, fwd, right, up = (np.array(cam[k], dtype=np.float64) for k in ("eye", "forward", "right", "up_ortho"))
    far = np.inf if cam["far"] is None else cam["far"]
    camera = (cam["width"], cam["height"], eye, fwd, right, up, cam["near"], far, cam["tan_half_vfov"])
    files = meta["files"]
    tris = np.fromfile(scene_dir / files["triangles"], dtype="<f4").reshape(-1, 3, 3).astype(np.float64)
    return camera, tris, np.fromfile(scene_dir / files["object_ids"], dtype="<u4")


def render(scene_dir: Path, out: Path) -> None:
    (w, h, eye, fwd, right, up, near, far, tan_half), tris, objects = read_scene(scene_dir)

    # Pixel rays exactly as docs/DESIGN.md defines them: x right, y down, centers at +0.5.
    sx = (2.0 * (np.arange(w) + 0.5) / w - 1.0) * tan_half * w / h
    sy = (1.0 - 2.0 * (np.arange(h) + 0.5) / h) * tan_half
    d = fwd + sx[None, :, None] * right + sy[:, None, None] * up  # (H, W, 3)

    z, prim, normal = blank(w, h)
    for i, a, b, c, n, length in facets(tris):
        depth, px, py = project(np.array([a, b, c]), eye, fwd, right, up, tan_half, w, h)
        rows, cols = window(depth, px, py, w, h, near)
        dd = d[rows, cols]
        t, inside = plane_hits(a, b, c, n, eye, dd)
        zc = z[rows, cols]
        hit = inside & np.isfinite(t) & (t >= near) & (t <= far) & (t < zc)  # equal depth: lower prim wins
        z[rows, cols] = np.where(hit, t, zc)
        prim[rows, cols] = np.where(hit, i, prim[rows, cols])
        normal[rows, cols] = np.where(hit[..., None], n / length, normal[rows, cols])
    write(out, z, prim, normal, objects, "tiny")


def blank(w: int, h: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The buffers before any triangle is drawn: Z at infinity, every prim ID the background, N zero."""
    return np.full((h, w), np.inf), np.full((h, w), BACKGROUND, dtype=np.uint32), np.zeros((h, w, 3))


def facets(tris: np.ndarray) -> Iterator[tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]]:
    """Each triangle that has an area, in draw order: its index, vertices a, b, c, its normal
    (b - a) x (c - a) (not normalized) and that normal's length. Zero-area triangles are never
    visible, so they are left out."""
    for i, (a, b, c) in enumerate(tris):
        n = np.cross(b - a, c - a)
        length = np.linalg.norm(n)
        if length != 0.0:
            yield i, a, b, c, n, float(length)


def plane_hits(
    a: np.ndarray, b: np.ndarray, c: np.ndarray, n: np.ndarray, eye: np.ndarray, d: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """For rays eye + t d (d of any shape (..., 3), not normalized): each one's t where it meets
    the plane of triangle a, b, c (normal n from `facets`), the planar depth (inf or nan where the
    ray is parallel to the plane), and whether that hit point is inside the triangle, its three
    float64 edge functions all >= 0 or all <= 0 (closed edges)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.dot(a - eye, n) / (d @ n)
    p = eye + t[..., None] * d
    e = [np.cross(v1 - v0, p - v0) @ n for v0, v1 in ((a, b), (b, c), (c, a))]
    inside = ((e[0] >= 0) & (e[1] >= 0) & (e[2] >= 0)) | ((e[0] <= 0) & (e[1] <= 0) & (e[2] <= 0))
    return t, inside


def write(
    out: Path,
    z: np.ndarray,
    prim: np.ndarray,
    normal: np.ndarray,
    objects: np.ndarray,
    renderer: str,
    rgb: np.ndarray | None = None,
) -> None:
    """Writes OUT.exr: Z, N (and RGB when given) rounded to float32, id.prim, and id.object looked
    up from each pixel's prim ID (the background where there is none)."""
    seen = prim != BACKGROUND
    obj = np.full(prim.shape, BACKGROUND, dtype=np.uint32)
    obj[seen] = objects[prim[seen]]
    exrbuf.write_buffers(
        out,
        Z=z.astype(np.float32),
        prim=prim,
        obj=obj,
        N=normal.astype(np.float32),
        RGB=None if rgb is None else rgb.astype(np.float32),
        attrs={"renderer": renderer},
    )


def project(
    v: np.ndarray,
    eye: np.ndarray,
    fwd: np.ndarray,
    right: np.ndarray,
    up: np.ndarray,
    tan_half: float,
    w: int,
    h: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points' planar depths and image positions in pixels, as docs/DESIGN.md defines them: x right,
    y down, the image's top-left corner at (0, 0), so pixel (x, y)'s center is at (x + 0.5, y + 0.5).
    The positions mean something only where the depth is > 0."""
    depth = (v - eye) @ fwd
    with np.errstate(divide="ignore", invalid="ignore"):
        px = ((v - eye) @ right / depth / (tan_half * w / h) + 1.0) * w / 2.0
        py = (1.0 - (v - eye) @ up / depth / tan_half) * h / 2.0
    return depth, px, py


def window(depth: np.ndarray, px: np.ndarray, py: np.ndarray, w: int, h: int, near: float) -> tuple[slice, slice]:
    """The pixels a triangle can cover, from its vertices' projection (`project`): its projected
    bounding box plus a pixel, or all of them when a vertex is not beyond the near plane."""
    if depth.min() <= near:
        return slice(0, h), slice(0, w)
    px, py = px - 0.5, py - 0.5  # pixel (x, y)'s center at (x, y)
    x0, x1 = int(np.clip(np.floor(px.min()) - 1, 0, w)), int(np.clip(np.ceil(px.max()) + 2, 0, w))
    y0, y1 = int(np.clip(np.floor(py.min()) - 1, 0, h)), int(np.clip(np.ceil(py.max()) + 2, 0, h))
    return slice(y0, y1), slice(x0, x1)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: tiny_renderer.py SCENE_DIR OUT.exr")
    render(Path(sys.argv[1]), Path(sys.argv[2]))
