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

# The harness's resolved scene and shading formula, and the tiny renderer's ray casting and
# EXR writing.
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "harness"))
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "harness" / "examples"))
from tiny_renderer import blank, facets, plane_hits, write  # noqa: E402

from rendiff_harness.contract import lighting, resolved  # noqa: E402

BUGS = ("red_albedo",)


def render(bug: str, scene_dir: Path, out: Path) -> None:
    scene = resolved.load(scene_dir)
    cam = scene.camera
    h, w = cam.height, cam.width
    d = cam.pixel_directions()
    eye = np.asarray(cam.eye, dtype=np.float64)
    tris = scene.triangles.astype(np.float64)
    z, prim, normal = blank(w, h)
    for i, a, b, c, n, length in facets(tris):
        t, inside = plane_hits(a, b, c, n, eye, d)
        hit = inside & np.isfinite(t) & (t >= cam.near) & (t <= cam.far) & (t < z)
        z = np.where(hit, t, z)
        prim = np.where(hit, np.uint32(i), prim)
        normal = np.where(hit[..., None], n / length, normal)
    # The planted bug: a coloured albedo shaded with its red channel in all three.
    materials = copy.deepcopy(scene.materials)
    for m in materials:
        albedo = [float(x) for x in m.get("albedo", [0.0, 0.0, 0.0])]
        if len(set(albedo)) > 1:
            m["albedo"] = [albedo[0]] * 3
    rgb = lighting.local_radiance(dataclasses.replace(scene, materials=materials), prim, z)
    write(out, z, prim, normal, scene.object_ids, bug, rgb=rgb)


if __name__ == "__main__":
    if len(sys.argv) != 4 or sys.argv[1] not in BUGS:
        sys.exit(f"usage: shaded.py {{{','.join(BUGS)}}} SCENE_DIR OUT.exr")
    render(sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3]))
