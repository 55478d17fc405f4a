"""glTF files read by trimesh (a third decoder, neither rendiff's `gltf` crate nor gltf_spec.py),
with its known departures from the specification declared, each with its reason, like a
renderer's known bugs: a mesh node whose primitives use a declared feature is not compared with
trimesh (the entry says which and why); any other difference fails, and the entry says whether
gltf_spec.py sides with rendiff (then trimesh departs from the specification: declare it here
after checking) or with trimesh.

trimesh keeps its scene graph: each geometry node is named as the glTF node (its `name`, else its
index; a mesh of several primitives is one child frame per primitive, `<node>_<6 random
characters>`, in primitive order), its transform the node's world matrix read from the JSON in
float64 (rendiff reads node numbers as float32: `input_rel`), and `Trimesh.apply_transform`
reverses the faces of a mirrored node, as the specification asks. A POINTS or LINES primitive is a
PointCloud or Path geometry without faces (rendiff skips it: nothing to compare); LINE_LOOP and
LINE_STRIP are not loaded at all.

What trimesh 5.2.0 does not read (checked on hand-written files, harness/tests/test_importcheck.py)
is declared, not compared: the parts it meets are left out and the entry says why (KNOWN_BUGS).
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
    "normalized": "trimesh 5.2.0 ignores `accessor.normalized`: a KHR_mesh_quantization position is read as the "
    "raw integer (an unsigned short 65535 stays 65535.0, not 1.0); unnormalized integer positions it reads "
    "right, and those are compared",
    "instancing": "trimesh 5.2.0 does not apply EXT_mesh_gpu_instancing: it keeps the extension in the node's "
    "metadata and draws the node's mesh once at the node's own transform, not once per instance",
    "scene": "trimesh 5.2.0 loads only the file's default glTF scene (`scene`, else the first): no argument "
    "chooses another, so a `gltf_scene` choosing another scene is not compared with trimesh",
}
"""Feature -> why trimesh's reading of it is not compared (each checked on trimesh 5.2.0)."""

INPUT_REL_PER_LEVEL = 2.0**-21
"""trimesh reads node numbers in float64, rendiff in float32: each entry of a level's matrix differs
by at most half a float32 unit (2^-24 relative); a rotation entry is a quadratic form of the
quaternion, normalized (2^-24 on each component, 2 x that after normalizing, twice that again in
the product): at most 8 x 2^-24 = 2^-21 relative per level, summed over the levels to first order."""


def declared(doc: dict[str, Any], node: int) -> list[str]:
    """The declared trimesh bugs a mesh node's primitives (and the node itself) meet."""
    mesh = doc["meshes"][doc["nodes"][node]["mesh"]]
    found = []
    if gltf_spec.INSTANCING in (doc["nodes"][node].get("extensions") or {}):
        found.append("instancing")
    for prim in mesh.get("primitives", []):
        pos = prim.get("attributes", {}).get("POSITION")
        acc = doc.get("accessors", [])
        mode = prim.get("mode", 4)
        if mode not in gltf_spec.SURFACE_MODES:
            continue
        if isinstance(pos, int) and 0 <= pos < len(acc) and "sparse" in acc[pos]:
            found.append("sparse")
        if isinstance(pos, int) and 0 <= pos < len(acc) and acc[pos].get("normalized") is True:
            found.append("normalized")
        if mode == 6:
            found.append("TRIANGLE_FAN")
    return sorted(set(found))


def _geometry_frames(scene: Any, key: str, node_names: set[str]) -> list[str]:
    """trimesh's geometry frames of the glTF node trimesh names `key`: the frame itself (one
    primitive), or its per-primitive child frames (`<key>_<6 characters>`, not glTF nodes)."""
    parents = scene.graph.transforms.parents
    out = []
    for name in scene.graph.nodes_geometry:
        n = str(name)
        if n == key or (
            parents.get(name) == key and n.startswith(key + "_") and len(n) == len(key) + 7 and n not in node_names
        ):
            out.append(n)
    return out


def decode(path: Path, chosen: int | None = None) -> tuple[list[Part | None], list[str]]:
    """Per part of the shown scene (gltf_spec's slots: order and labels): trimesh's triangles, or
    None where a declared bug makes trimesh's reading not comparable; and the notes saying which."""
    import trimesh  # noqa: PLC0415 - heavy import, only where a glTF is checked

    doc, bin_chunk = gltf_spec.container(path)
    slots = gltf_spec.slots(doc, path, chosen, {}, bin_chunk)
    if gltf_spec.scene_index(doc, chosen) != gltf_spec.scene_index(doc, None):
        return [None] * len(slots), [f"{len(slots)} part(s) not compared with trimesh: {KNOWN_BUGS['scene']}"]
    try:
        scene: Any = trimesh.load(str(path), force="scene", process=False)
    except Exception as exc:  # noqa: BLE001 - a third-party parser's failure is the file's verdict
        raise DecodeError(f"{path}: trimesh cannot read it: {type(exc).__name__}: {exc}") from None
    node_names = {str(n.get("name", i)) for i, n in enumerate(doc.get("nodes", []))}
    order = {str(g): k for k, g in enumerate(scene.geometry)}
    out: list[Part | None] = []
    notes = []
    for slot in slots:
        ni = slot.node
        bugs = declared(doc, ni)
        if bugs:
            out.append(None)
            if slot.instance is None or slot.instance == 0:
                notes.append(f"node {ni} not compared with trimesh: " + "; ".join(KNOWN_BUGS[b] for b in bugs))
            continue
        key = str(doc["nodes"][ni].get("name") or ni)
        frames = _geometry_frames(scene, key, node_names)
        part = empty_part(
            slot.label, f"node {ni} as trimesh names it ({key!r})", gltf_spec.OPS_PER_LEVEL * slot.depth + 4
        )
        part.input_rel = INPUT_REL_PER_LEVEL * slot.depth
        geoms = [(frame, *scene.graph[frame]) for frame in frames]
        # faces only (a POINTS or LINES primitive is a geometry without them), in primitive order
        geoms = sorted((g for g in geoms if hasattr(scene.geometry[g[2]], "faces")), key=lambda g: order[str(g[2])])
        if not geoms and frames:
            out.append(part)  # geometry frames, none with faces: the count tells
            continue
        for frame, transform, geom_name in geoms:
            mesh = scene.geometry[geom_name].copy()
            mesh.apply_transform(transform)
            tris = np.asarray(mesh.vertices, dtype=np.float64)[np.asarray(mesh.faces, dtype=np.int64)]
            # trimesh keeps no per-level matrices: the magnitude bound uses |W| (product of the absolute
            # local matrices, gltf_spec's) on the largest absolute coordinate of the mesh, per axis.
            local = np.abs(np.asarray(scene.geometry[geom_name].vertices, dtype=np.float64)).max(axis=0, initial=0.0)
            mag = slot.world_abs[:3, :3] @ local + np.abs(slot.world_abs[:3, 3])
            extend(
                part,
                f"mesh {slot.mesh} geometry {geom_name!r} (frame {frame!r})",
                tris,
                np.broadcast_to(mag, tris.shape),
            )
        out.append(part)
    return out, notes
