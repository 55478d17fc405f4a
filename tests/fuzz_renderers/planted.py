#!/usr/bin/env python3
"""Renderers with planted bugs, for `rendiff fuzz`'s own tests (tests/fuzz_planted.rs).

    planted.py BUG SCENE_DIR OUT.exr

Each is harness/examples/tiny_renderer.py (one float64 ray per pixel center, closed edges,
t rounded to float32 once) with one deliberate fault, chosen by BUG:

* `coplanar_bias`: the depth test keeps the current surface unless the new one is nearer by
  more than a relative 2^-12, `t < z * (1 - 2^-12)` instead of `t < z`, as a depth bias meant
  to stop z-fighting would. A triangle drawn after a near-coplanar neighbour that it lies in
  front of, by less than 2^-12 of the depth, is dropped.
* `subpixel_shift`: a triangle whose image is smaller than a pixel (projected area below
  1 px^2) has its first vertex moved 1e-3 px to the right (along the camera's right axis, at
  the vertex's depth), as a snapping step applied to small triangles only would.
* `coplanar_swap`: two coplanar triangles that share an edge and lie on opposite sides of it
  (neighbours in one plane, such as the two halves of a quad) report each other's IDs, as a
  mesh optimiser that merges coplanar neighbours into one polygon and relabels its halves in
  the wrong order would. Where two triangles both cover a pixel center at the same depth the
  contract lets either win (a *tie*, docs/verifier.md), so swapping overlapping or duplicated
  coplanar triangles is allowed; neighbours never both cover an interior pixel's center, so
  this swap is one the contract forbids.

Two more are camera-convention faults, for the report's and the calibration's tests
(tests/report_causes.rs, harness/tests/test_calibration_hypotheses.py):

* `corner_sample`: samples each pixel at its top-left corner, `x` instead of `x + 0.5`, as a
  renderer that forgot the pixel-center offset would (a half-pixel shift).
* `radial_depth`: writes the distance from the eye, `t |d|`, in Z instead of the planar depth
  `t` (docs/DESIGN.md "Buffers").

All six are declared with the tiny renderer's honest precision (renderers.toml), so the fault
is all the verifier sees: its pixels are interior (or crack) mismatches.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np

# The tiny renderer's reading of the resolved scene, its projection, its ray casting and its EXR
# writing (the harness's writer: float32 Z and N, exact uint32 ids).
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "harness" / "examples"))
from tiny_renderer import BACKGROUND, blank, facets, plane_hits, project, read_scene, write  # noqa: E402

BIAS = 2.0**-12
SHIFT_PX = 1e-3
# Two triangles are coplanar for `coplanar_swap` when each one's third vertex is within this
# fraction of its distance from the eye of the other's plane (the `coplanar` situation tag's
# threshold, docs/fuzzing.md).
COPLANAR = 2.0**-10
BUGS = ("coplanar_bias", "subpixel_shift", "far_depth", "coplanar_swap", "corner_sample", "radial_depth")


def projected_area_px(tri: np.ndarray, camera: tuple[Any, ...]) -> float:
    """The triangle's image area in square pixels (inf when a vertex is not in front of the eye)."""
    w, h, eye, fwd, right, up, _near, _far, tan_half = camera
    depth, px, py = project(tri, eye, fwd, right, up, tan_half, w, h)
    if depth.min() <= 0.0:
        return float("inf")
    return float(abs((px[1] - px[0]) * (py[2] - py[0]) - (px[2] - px[0]) * (py[1] - py[0])) / 2.0)


def subpixel_shift(tris: np.ndarray, camera: tuple[Any, ...]) -> np.ndarray:
    """The triangles as `subpixel_shift` draws them: the first vertex of each one whose image is
    under 1 px^2 (`projected_area_px`) moved 1e-3 px right, along the camera's right axis at the
    vertex's depth."""
    _w, h, eye, fwd, right, _up, _near, _far, tan_half = camera
    shifted = tris.copy()
    for i, tri in enumerate(tris):
        if projected_area_px(tri, camera) < 1.0:
            pixel = 2.0 * tan_half * float((tri[0] - eye) @ fwd) / h
            shifted[i, 0] = tri[0] + right * (SHIFT_PX * pixel)
    return shifted


def coplanar_swap(tris: np.ndarray, eye: np.ndarray) -> np.ndarray:
    """The ID each triangle reports under `coplanar_swap`: its own, or its paired neighbour's.

    Triangles are paired in draw order, each with the first unpaired later one that shares an
    edge with it (two vertices equal bit for bit), lies on the other side of that edge and is
    coplanar with it (`COPLANAR`). Exact duplicates share three vertices and are never paired.
    """
    ids = np.arange(len(tris))
    by_edge: dict[bytes, list[int]] = {}
    for i, tri in enumerate(tris):
        for k in range(3):
            by_edge.setdefault(_edge_key(tri, k), []).append(i)
    paired = np.zeros(len(tris), dtype=bool)
    for i, tri in enumerate(tris):
        if paired[i]:
            continue
        for j in sorted({j for k in range(3) for j in by_edge[_edge_key(tri, k)] if j > i}):
            if not paired[j] and _neighbours_in_one_plane(tri, tris[j], eye):
                ids[i], ids[j] = j, i
                paired[i] = paired[j] = True
                break
    return ids


def _edge_key(tri: np.ndarray, k: int) -> bytes:
    """Edge k of a triangle, its two vertices' bytes in a fixed order (either winding)."""
    first: bytes = tri[k].tobytes()
    second: bytes = tri[(k + 1) % 3].tobytes()
    return min(first, second) + max(first, second)


def _neighbours_in_one_plane(s: np.ndarray, t: np.ndarray, eye: np.ndarray) -> bool:
    """Whether two triangles share exactly one edge, are coplanar and lie on opposite sides of it."""
    in_t = {v.tobytes() for v in t}
    shared = [v for v in s if v.tobytes() in in_t]
    if len(shared) != 2:
        return False
    p, q = shared
    r_s = next(v for v in s if v.tobytes() not in in_t)
    in_s = {v.tobytes() for v in s}
    r_t = next(v for v in t if v.tobytes() not in in_s)
    for a, b in ((s, r_t), (t, r_s)):
        n = np.cross(a[1] - a[0], a[2] - a[0])
        length = np.linalg.norm(n)
        if length == 0.0 or abs((b - a[0]) @ n) / length > COPLANAR * np.linalg.norm(b - eye):
            return False
    n = np.cross(s[1] - s[0], s[2] - s[0])
    return float((np.cross(q - p, r_s - p) @ n) * (np.cross(q - p, r_t - p) @ n)) < 0.0


def render(bug: str, scene_dir: Path, out: Path) -> None:
    camera, tris, objects = read_scene(scene_dir)
    w, h, eye, fwd, right, up, near, far, tan_half = camera

    center = 0.0 if bug == "corner_sample" else 0.5  # the corner_sample bug: no half-pixel offset
    sx = (2.0 * (np.arange(w) + center) / w - 1.0) * tan_half * w / h
    sy = (1.0 - 2.0 * (np.arange(h) + center) / h) * tan_half
    d = fwd + sx[None, :, None] * right + sy[:, None, None] * up

    if bug == "subpixel_shift":
        # The planted bug: one vertex of each sub-pixel triangle moved 1e-3 px right.
        tris = subpixel_shift(tris, camera)
    z, prim, normal = blank(w, h)
    for i, a, b, c, n, length in facets(tris):
        t, inside = plane_hits(a, b, c, n, eye, d)
        # The coplanar_bias bug: a relative depth bias in the depth test.
        nearer = t < z * (1.0 - BIAS) if bug == "coplanar_bias" else t < z
        hit = inside & np.isfinite(t) & (t >= near) & (t <= far) & nearer
        z = np.where(hit, t, z)
        prim = np.where(hit, np.uint32(i), prim)
        normal = np.where(hit[..., None], n / length, normal)
    seen = prim != BACKGROUND
    if bug == "coplanar_swap":
        # The planted bug: coplanar neighbours report each other's IDs.
        prim = np.where(seen, coplanar_swap(tris, eye)[np.where(seen, prim, 0)], prim).astype(np.uint32)
    if bug == "far_depth":
        # The planted bug: the hit point kept in float32 world space, the depth measured from it.
        with np.errstate(invalid="ignore"):
            hit_point = (eye + z[..., None] * d).astype(np.float32).astype(np.float64)
            z = np.where(seen, (hit_point - eye) @ fwd, z)
    if bug == "radial_depth":
        # The radial_depth bug: distance from the eye instead of planar depth.
        z = np.where(seen, z * np.linalg.norm(d, axis=2), z)
    write(out, z, prim, normal, objects, bug)


if __name__ == "__main__":
    if len(sys.argv) != 4 or sys.argv[1] not in BUGS:
        sys.exit(f"usage: planted.py {{{','.join(BUGS)}}} SCENE_DIR OUT.exr")
    render(sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3]))
