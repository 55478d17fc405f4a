#!/usr/bin/env python3
"""A shaded renderer with a planted bug, for `rendiff reduce` on shaded scenes (tests/fuzz_shaded.rs).

    shaded.py red_albedo SCENE_DIR OUT.exr

One float64 ray per pixel center through the resolved scene (docs/resolved-scene.md), closed
edges, as harness/examples/tiny_renderer.py; RGB is the contract's local shading
(docs/radiance.md), evaluated by the harness's float64 formula (contract/lighting.py) at
those hits. The planted fault, `red_albedo`: a material whose albedo is not grey (its three
channels differ) is shaded with its red albedo in every channel, as a renderer that reads a
colour's first channel as a scalar would. Grey materials, emission, depth, IDs and normals
are right, so the fault is all the verifier sees: the pixels of coloured, lit surfaces.
"""

from __future__ import annotations

import copy
import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "harness"))
from rendiff_harness.contract import exrbuf, lighting, resolved  # noqa: E402

BACKGROUND = 0xFFFFFFFF
BUGS = ("red_albedo",)


def render(bug: str, scene_dir: Path, out: Path) -> None:
    scene = resolved.load(scene_dir)
    cam = scene.camera
    h, w = cam.height, cam.width
    d = cam.pixel_directions()
    eye = np.asarray(cam.eye, dtype=np.float64)
    tris = scene.triangles.astype(np.float64)
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
        hit = inside & np.isfinite(t) & (t >= cam.near) & (t <= cam.far) & (t < z)
        z = np.where(hit, t, z)
        prim = np.where(hit, np.uint32(i), prim)
        normal = np.where(hit[..., None], n / length, normal)
    seen = prim != BACKGROUND
    # The planted bug: a coloured albedo shaded with its red channel in all three.
    materials = copy.deepcopy(scene.materials)
    for m in materials:
        albedo = [float(x) for x in m.get("albedo", [0.0, 0.0, 0.0])]
        if len(set(albedo)) > 1:
            m["albedo"] = [albedo[0]] * 3
    rgb = lighting.local_radiance(dataclasses.replace(scene, materials=materials), prim, z)
    obj = np.full((h, w), BACKGROUND, dtype=np.uint32)
    obj[seen] = scene.object_ids[prim[seen]]
    exrbuf.write_buffers(
        out,
        Z=z.astype(np.float32),
        prim=prim,
        obj=obj,
        N=normal.astype(np.float32),
        RGB=rgb.astype(np.float32),
        attrs={"renderer": bug},
    )


if __name__ == "__main__":
    if len(sys.argv) != 4 or sys.argv[1] not in BUGS:
        sys.exit(f"usage: shaded.py {{{','.join(BUGS)}}} SCENE_DIR OUT.exr")
    render(sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3]))
