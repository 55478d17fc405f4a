"""glTF files read by trimesh (a third decoder, neither rendiff's `gltf` crate nor gltf_spec.py),
with its known departures from the specification declared, each with its reason, like a
renderer's known bugs: a mesh node whose primitives use a declared feature is not compared with
trimesh (the entry says which and why); any other difference fails, and the entry says whether
gltf_spec.py sides with rendiff (then trimesh departs from the specification: declare it in
contract/gltfgraph.TRIMESH_GAPS after checking) or with trimesh.

trimesh keeps its scene graph (read through contract/gltfgraph.py, shared with `pyrender_file`):
each geometry node is named as the glTF node (its `name`, else its index, made unique in node order;
a mesh of several primitives is one child frame per primitive, `<node>_<6 random characters>`, in
primitive order), its transform the node's world matrix read from the JSON in
float64 (rendiff reads node numbers as float32: `input_rel`), and `Trimesh.apply_transform`
reverses the faces of a mirrored node, as the specification asks. A POINTS or LINES primitive is a
PointCloud or Path geometry without faces (rendiff skips it: nothing to compare); LINE_LOOP and
LINE_STRIP are not loaded at all.

What trimesh 5.2.0 does not read (checked on hand-written files, harness/tests/test_importcheck.py)
is declared, not compared: the parts it meets are left out and the entry says why (KNOWN_BUGS).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...contract import gltfgraph
from . import gltf_spec
from .parts import Part, empty_part, extend

KNOWN_BUGS = gltfgraph.TRIMESH_GAPS
"""Feature -> why trimesh's reading of it is not compared (contract/gltfgraph.py, shared with `pyrender_file`)."""

INPUT_REL_PER_LEVEL = gltfgraph.TRIMESH_INPUT_REL_PER_LEVEL
declared = gltfgraph.trimesh_gaps


def decode(path: Path, chosen: int | None = None) -> tuple[list[Part | None], list[str]]:
    """Per part of the shown scene (gltf_spec's slots: order and labels): trimesh's triangles, or
    None where a declared bug makes trimesh's reading not comparable; and the notes saying which."""
    doc, bin_chunk = gltfgraph.container(path)
    slots = gltf_spec.slots(doc, path, chosen, {}, bin_chunk)
    if gltfgraph.scene_index(doc, chosen) != gltfgraph.scene_index(doc, None):
        return [None] * len(slots), [f"{len(slots)} part(s) not compared with trimesh: {KNOWN_BUGS['scene']}"]
    scene = gltfgraph.trimesh_load(path)
    names = gltfgraph.trimesh_node_names(doc)
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
        frames, prims = gltfgraph.trimesh_primitives(scene, names, ni)
        part = empty_part(
            slot.label, f"node {ni} as trimesh names it ({names[ni]!r})", gltfgraph.OPS_PER_LEVEL * slot.depth + 4
        )
        part.input_rel = INPUT_REL_PER_LEVEL * slot.depth
        for prim in prims:
            # the magnitude bound uses |W| (product of the absolute local matrices, gltf_spec's) on the
            # largest absolute coordinate of the primitive, per axis
            local = np.abs(prim.local).reshape(-1, 3).max(axis=0, initial=0.0)
            mag = slot.world_abs[:3, :3] @ local + np.abs(slot.world_abs[:3, 3])
            extend(
                part,
                f"mesh {slot.mesh} geometry {prim.geometry!r} (frame {prim.frame!r})",
                prim.tris,
                np.broadcast_to(mag, prim.tris.shape),
            )
        out.append(part)
    return out, notes
