#!/usr/bin/env python3
"""A renderer with a planted bug, for `rendiff fuzz`'s own tests (tests/fuzz_planted.rs).

    coplanar_bias.py SCENE_DIR OUT.exr

It is harness/examples/tiny_renderer.py (one float64 ray per pixel center, closed edges,
t rounded to float32 once) with one change: its depth test keeps the current surface unless
the new one is nearer by more than a relative 2^-12,

    hit = t < z * (1 - 2^-12)      instead of      hit = t < z

as a depth bias meant to stop z-fighting would. So a triangle drawn after a near-coplanar
neighbour that it lies in front of, by less than 2^-12 of the depth, is dropped: the
farther surface shows where the nearer one should. Its declared precision (renderers.toml)
is the tiny renderer's, honest for everything but this bug, so the verifier calls those
pixels interior mismatches.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

# The harness's EXR writer (float32 Z and N, exact uint32 ids).
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "harness"))
from rendiff_harness import exrbuf  # noqa: E402

BACKGROUND = 0xFFFFFFFF
BIAS = 2.0**-12


def render(scene_dir: Path, out: Path) -> None:
    meta = json.loads((scene_dir / "scene.json").read_text())
    cam = meta["camera"]
    w, h = cam["width"], cam["height"]
    eye, fwd, right, up = (np.array(cam[k], dtype=np.float64) for k in ("eye", "forward", "right", "up_ortho"))
    near = cam["near"]
    far = np.inf if cam["far"] is None else cam["far"]
    tan_half = cam["tan_half_vfov"]
    files = meta["files"]
    tris = np.fromfile(scene_dir / files["triangles"], dtype="<f4").reshape(-1, 3, 3).astype(np.float64)
    objects = np.fromfile(scene_dir / files["object_ids"], dtype="<u4")

    sx = (2.0 * (np.arange(w) + 0.5) / w - 1.0) * tan_half * w / h
    sy = (1.0 - 2.0 * (np.arange(h) + 0.5) / h) * tan_half
    d = fwd + sx[None, :, None] * right + sy[:, None, None] * up

    z = np.full((h, w), np.inf)
    prim = np.full((h, w), BACKGROUND, dtype=np.uint32)
    normal = np.zeros((h, w, 3))
    for i, (a, b, c) in enumerate(tris):
        n = np.cross(b - a, c - a)
        length = np.linalg.norm(n)
        if length == 0.0:
            continue
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.dot(a - eye, n) / (d @ n)
        p = eye + t[..., None] * d
        e = [np.cross(v1 - v0, p - v0) @ n for v0, v1 in ((a, b), (b, c), (c, a))]
        inside = ((e[0] >= 0) & (e[1] >= 0) & (e[2] >= 0)) | ((e[0] <= 0) & (e[1] <= 0) & (e[2] <= 0))
        # The planted bug: a relative depth bias in the depth test.
        hit = inside & np.isfinite(t) & (t >= near) & (t <= far) & (t < z * (1.0 - BIAS))
        z = np.where(hit, t, z)
        prim = np.where(hit, np.uint32(i), prim)
        normal = np.where(hit[..., None], n / length, normal)
    seen = prim != BACKGROUND
    obj = np.full((h, w), BACKGROUND, dtype=np.uint32)
    obj[seen] = objects[prim[seen]]
    exrbuf.write_buffers(
        out,
        Z=z.astype(np.float32),
        prim=prim,
        obj=obj,
        N=normal.astype(np.float32),
        attrs={"renderer": "coplanar_bias"},
    )


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: coplanar_bias.py SCENE_DIR OUT.exr")
    render(Path(sys.argv[1]), Path(sys.argv[2]))
