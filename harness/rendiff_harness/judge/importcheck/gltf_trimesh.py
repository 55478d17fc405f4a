"""glTF files read by trimesh (a third decoder, neither rendiff's `gltf` crate nor gltf_spec.py),
with its known departures from the specification declared, each with its reason, like a
renderer's known bugs: a mesh node whose primitives use a declared feature is not compared with
trimesh (the entry says which and why); any other difference fails, and the entry says whether
gltf_spec.py sides with rendiff (then trimesh departs from the specification: declare it here
after checking) or with trimesh.

trimesh keeps its scene graph: each geometry node is named as the glTF node (its `name`, else its
index), its transform the node's world matrix read from the JSON in float64 (rendiff reads node
numbers as float32: `input_rel`), and `Trimesh.apply_transform` reverses the faces of a mirrored
node, as the specification asks.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from . import gltf_spec
from .parts import DecodeError, Part, empty_part, extend

KNOWN_BUGS: dict[str, str] = {
    "sparse": "trimesh 5.2.0 ignores `accessor.sparse`: it reads the base values only (SimpleSparseAccessor's "
    "three lifted vertices stay at y = 1)",
    "TRIANGLE_FAN": "trimesh 5.2.0 drops TRIANGLE_FAN primitives (MeshPrimitiveModes' fan mesh loads as no geometry)",
}
"""Features of a primitive -> why trimesh's reading of it is not compared (each seen on the corpus)."""

INPUT_REL_PER_LEVEL = 2.0**-21
"""trimesh reads node numbers in float64, rendiff in float32: each entry of a level's matrix differs
by at most half a float32 unit (2^-24 relative); a rotation entry is a quadratic form of the
quaternion, normalized (2^-24 on each component, 2 x that after normalizing, twice that again in
the product): at most 8 x 2^-24 = 2^-21 relative per level, summed over the levels to first order."""


def declared(doc: dict[str, Any], node: int) -> list[str]:
    """The declared trimesh bugs a mesh node's primitives meet."""
    mesh = doc["meshes"][doc["nodes"][node]["mesh"]]
    found = []
    for prim in mesh.get("primitives", []):
        pos = prim.get("attributes", {}).get("POSITION")
        acc = doc.get("accessors", [])
        if isinstance(pos, int) and 0 <= pos < len(acc) and "sparse" in acc[pos]:
            found.append("sparse")
        if prim.get("mode", 4) == 6:
            found.append("TRIANGLE_FAN")
    return sorted(set(found))


def decode(path: Path) -> tuple[list[Part | None], list[str]]:
    """Per mesh node of the shown scene (gltf_spec's order and labels): trimesh's triangles, or
    None where a declared bug makes trimesh's reading not comparable; and the notes saying which."""
    import trimesh  # noqa: PLC0415 - heavy import, only where a glTF is checked

    doc, _ = gltf_spec.container(path)
    nodes = gltf_spec.mesh_nodes(doc, path)
    labels = gltf_spec.labels(doc, [n[0] for n in nodes])
    try:
        scene: Any = trimesh.load(str(path), force="scene", process=False)
    except Exception as exc:  # noqa: BLE001 - a third-party parser's failure is the file's verdict
        raise DecodeError(f"{path}: trimesh cannot read it: {type(exc).__name__}: {exc}") from None
    by_name: dict[str, list[str]] = {}
    for name in scene.graph.nodes_geometry:
        by_name.setdefault(str(name), []).append(str(name))
    out: list[Part | None] = []
    notes = []
    for (ni, _world, world_abs, depth), label in zip(nodes, labels, strict=True):
        bugs = declared(doc, ni)
        if bugs:
            out.append(None)
            notes.append(f"node {ni} not compared with trimesh: " + "; ".join(KNOWN_BUGS[b] for b in bugs))
            continue
        key = str(doc["nodes"][ni].get("name") or ni)
        names = by_name.get(key, [])
        part = empty_part(label, f"node {ni} as trimesh names it ({key!r})", gltf_spec.OPS_PER_LEVEL * depth + 4)
        part.input_rel = INPUT_REL_PER_LEVEL * depth
        if len(names) != 1:
            out.append(part)  # no or several trimesh nodes of that name: the count tells
            continue
        transform, geom_name = scene.graph[names[0]]
        mesh = scene.geometry[geom_name].copy()
        if not hasattr(mesh, "faces"):
            out.append(part)
            continue
        mesh.apply_transform(transform)
        tris = np.asarray(mesh.vertices, dtype=np.float64)[np.asarray(mesh.faces, dtype=np.int64)]
        # trimesh keeps no per-level matrices: the magnitude bound uses |W| (product of the absolute
        # local matrices, gltf_spec's) on the largest absolute coordinate of the mesh, per axis.
        local = np.abs(np.asarray(scene.geometry[geom_name].vertices, dtype=np.float64)).max(axis=0, initial=0.0)
        mag = world_abs[:3, :3] @ local + np.abs(world_abs[:3, 3])
        extend(
            part,
            f"mesh {doc['nodes'][ni]['mesh']} (trimesh merges its primitives)",
            tris,
            np.broadcast_to(mag, tris.shape),
        )
        out.append(part)
    return out, notes
