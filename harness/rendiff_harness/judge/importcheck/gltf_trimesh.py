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

from ...contract import gltfgraph
from . import gltf_spec
from .parts import DecodeError, Part, empty_part, extend

KNOWN_BUGS = gltfgraph.TRIMESH_GAPS
"""Feature -> why trimesh's reading of it is not compared (contract/gltfgraph.py, shared with `pyrender_file`)."""

INPUT_REL_PER_LEVEL = gltfgraph.TRIMESH_INPUT_REL_PER_LEVEL
declared = gltfgraph.trimesh_gaps


def decode(path: Path, chosen: int | None = None) -> tuple[list[Part | None], list[str]]:
    """Per part of the shown scene (gltf_spec's slots: order and labels): trimesh's triangles, or
    None where a declared bug makes trimesh's reading not comparable; and the notes saying which."""
    import trimesh  # noqa: PLC0415 - heavy import, only where a glTF is checked

    doc, bin_chunk = gltfgraph.container(path)
    slots = gltf_spec.slots(doc, path, chosen, {}, bin_chunk)
    if gltfgraph.scene_index(doc, chosen) != gltfgraph.scene_index(doc, None):
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
        frames = gltfgraph.trimesh_frames(scene, key, node_names)
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
