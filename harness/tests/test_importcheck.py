"""The `import` verdict (judge/importcheck, docs/verifier.md "The import verdict").

Each planted import bug is planted honestly: rendiff exports the real resolved scene of a small
file, then the test rewrites that scene's triangles as a buggy importer would have written them
(the same decoder with one step broken: sparse values one element off, a strip read as a list, a
mirrored node's winding kept, an OBJ negative index one off, instances in the wrong order or
placed after the node's transform instead of before, quantized positions not normalized, the
file's default glTF scene read instead of the chosen one), and the unbroken verdict must fail,
naming the object and the primitive. The unmodified export must pass (so each test can fail both
ways), and a one-unit shift of one vertex must fail (the bound is not loose).
"""

from __future__ import annotations

import base64
import json
import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import meshfiles
from fixtures import REPO
from meshfiles import Gltf
from rendiff_harness.contract import gltfgraph, resolved
from rendiff_harness.contract.results import Entry
from rendiff_harness.judge import importcheck
from rendiff_harness.judge.importcheck import gltf_spec, gltf_trimesh, match

CORPUS = REPO / "scenes" / "corpus"


def _export(tmp: Path, mesh_name: str, mesh: bytes | Path, transform: str = "") -> Path:
    """`rendiff export` of a scene showing `mesh` (bytes written, or a corpus file copied)."""
    camera = "eye = [0.3, 0.2, 9.0]\nlook_at = [0.0, 0.0, 0.0]\nvfov = 45.0\nwidth = 16\nheight = 16"
    return meshfiles.export(tmp, mesh_name, mesh, camera, transform, tmp / "resolved")


def _verdict(directory: Path, decoder: str = "gltf_spec") -> Entry:
    """The scene's import entry of `decoder`."""
    entries = {e.backend: e for e in importcheck.import_entries(resolved.load(directory))}
    return entries[decoder]


def _rewrite(directory: Path, per_object: list[np.ndarray]) -> None:
    """The resolved scene as an importer that produced `per_object` triangles would have written it."""
    meta = json.loads((directory / "scene.json").read_text())
    first = 0
    for obj, tris in zip(meta["objects"], per_object, strict=True):
        obj["first_prim"], obj["prim_count"] = first, int(tris.shape[0])
        first += int(tris.shape[0])
    meta["triangle_count"] = first
    (directory / "scene.json").write_text(json.dumps(meta))
    meshfiles.rewrite_triangles(directory, np.concatenate(per_object))
    ids = np.concatenate([np.full(t.shape[0], i, dtype="<u4") for i, t in enumerate(per_object)])
    ids.tofile(directory / "object_ids.u32")


def _buggy_gltf(directory: Path, patch: Callable[[pytest.MonkeyPatch], None]) -> list[np.ndarray]:
    """The world triangles of the scene's glTF objects as the decoder reads them with one step broken."""
    scene = resolved.load(directory)
    with pytest.MonkeyPatch.context() as mp:
        patch(mp)
        mesh = scene.objects[0]["mesh"]
        parts = gltf_spec.decode(Path(mesh["file"]), mesh.get("gltf_scene"))
    return [match.place(p, scene.objects[i]["mesh"]["transform"]).tris for i, p in enumerate(parts)]


def _plant_and_judge(tmp_path: Path, out: Path, buggy: list[np.ndarray], decoder: str = "gltf_spec") -> Entry:
    ok = _verdict(out, decoder)
    assert ok.status == "pass", ok.reason
    _rewrite(out, buggy)
    return _verdict(out, decoder)


def test_sparse_values_at_the_wrong_index_fail_naming_the_primitive(tmp_path: Path) -> None:
    out = _export(tmp_path, "s.gltf", CORPUS / "meshes" / "simple_sparse_accessor.gltf")

    def off_by_one(values: np.ndarray, idx: np.ndarray, vals: np.ndarray) -> np.ndarray:
        v = values.copy()
        v[np.minimum(idx + 1, len(v) - 1)] = vals
        return v

    bad = _plant_and_judge(
        tmp_path, out, _buggy_gltf(out, lambda mp: mp.setattr(gltf_spec, "apply_sparse", off_by_one))
    )
    assert bad.status == "fail"
    assert (
        "object 'm/0' (node 0, mesh 0)" in bad.reason and "mesh 0 primitive 0 (TRIANGLES sparse POSITION)" in bad.reason
    )
    assert "glTF 2.0 specification: rendiff departs from it" in bad.reason


def test_a_strip_decoded_as_a_list_fails_naming_the_primitive(tmp_path: Path) -> None:
    out = _export(tmp_path, "s.gltf", CORPUS / "meshes" / "mesh_primitive_modes_triangles.gltf")
    real = gltf_spec.triangles_of

    def as_list(mode: int, idx: np.ndarray) -> np.ndarray:
        return real(4 if mode == 5 else mode, idx)

    bad = _plant_and_judge(tmp_path, out, _buggy_gltf(out, lambda mp: mp.setattr(gltf_spec, "triangles_of", as_list)))
    assert bad.status == "fail"
    assert "object 'm/5'" in bad.reason and "mesh 5 primitive 0 (TRIANGLE_STRIP)" in bad.reason
    assert "rendiff has 2 triangles, gltf_spec 4" in bad.reason
    assert "m/4" not in bad.reason and "m/6" not in bad.reason  # the list and fan nodes stay right


def _mirrored_gltf() -> bytes:
    """One triangle under a node scaled by -1 in x, below an unscaled parent."""
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], dtype="<f4")
    idx = np.array([0, 1, 2, 1, 3, 2], dtype="<u2")
    data = idx.tobytes() + pos.tobytes()
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"children": [1], "translation": [0.5, 0, 0]}, {"name": "mirror", "mesh": 0, "scale": [-1, 1, 1]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 1}, "indices": 0}]}],
        "buffers": [
            {"uri": "data:application/octet-stream;base64," + base64.b64encode(data).decode(), "byteLength": len(data)}
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 12},
            {"buffer": 0, "byteOffset": 12, "byteLength": 48},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5123, "count": 6, "type": "SCALAR"},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
        ],
    }
    return json.dumps(doc).encode()


def test_a_mirrored_node_whose_winding_is_kept_fails_naming_the_primitive(tmp_path: Path) -> None:
    out = _export(tmp_path, "m.gltf", _mirrored_gltf())
    bad = _plant_and_judge(
        tmp_path, out, _buggy_gltf(out, lambda mp: mp.setattr(gltf_spec, "mirrors", lambda w: False))
    )
    assert bad.status == "fail"
    assert "object 'm/mirror' (node 1, mesh 0 (mirrored: winding reversed))" in bad.reason
    assert "mesh 0 primitive 0 (TRIANGLES) triangle 0" in bad.reason
    assert "the same vertices with the winding reversed" in bad.reason


OBJ = b"v 9 9 0\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf -4 -3 -2\nf -3 -1 -2\n"
"""Five vertices, two faces by negative (relative) indices: -k is vertex n - k + 1 (1-based)."""


def test_an_obj_negative_index_off_by_one_fails_naming_the_face(tmp_path: Path) -> None:
    out = _export(tmp_path, "q.obj", OBJ)
    verts = np.array(
        [[float(x) for x in line.split()[1:]] for line in OBJ.decode().splitlines() if line.startswith("v ")]
    )
    faces = [[int(x) for x in line.split()[1:]] for line in OBJ.decode().splitlines() if line.startswith("f ")]
    buggy = np.array([[verts[len(verts) + k - 1] for k in f] for f in faces])  # -k -> n - k (0-based n - k - 1)
    bad = _plant_and_judge(tmp_path, out, [buggy], "trimesh")
    assert bad.status == "fail", bad.reason
    assert "object 'm'" in bad.reason and "triangle 0 (prim_id 0)" in bad.reason and "group" in bad.reason


def test_one_float32_unit_on_one_vertex_fails(tmp_path: Path) -> None:
    out = _export(tmp_path, "t.gltf", CORPUS / "meshes" / "triangle_without_indices.gltf")
    assert _verdict(out).status == "pass"
    tris = np.fromfile(out / "triangles.f32", dtype="<f4").reshape(-1, 3, 3)
    tris[0, 1, 0] = np.nextafter(tris[0, 1, 0], np.float32(2))  # (1, 0, 0) -> (1 + 2^-23, 0, 0)
    _rewrite(out, [tris])
    bad = _verdict(out)
    assert bad.status == "fail" and "1 of 1 triangles differ" in bad.reason


def test_strip_and_fan_numbering_is_the_specifications() -> None:
    idx = np.arange(6)
    # glTF 2.0 topology table: strip p_i = {v_i, v_(i+(1+i%2)), v_(i+(2-i%2))}; fan p_i = {v_(i+1), v_(i+2), v_0}
    assert gltf_spec.triangles_of(5, idx).tolist() == [[0, 1, 2], [1, 3, 2], [2, 3, 4], [3, 5, 4]]
    assert gltf_spec.triangles_of(6, idx).tolist() == [[1, 2, 0], [2, 3, 0], [3, 4, 0], [4, 5, 0]]
    assert gltf_spec.triangles_of(0, idx).shape == (0, 3)


def test_a_scene_of_shapes_has_no_import_entry(tmp_path: Path) -> None:
    from fixtures import three_triangles

    assert importcheck.import_entries(resolved.load(three_triangles(tmp_path / "t"))) == []


def test_trimesh_known_glTF_bugs_are_declared_and_an_undeclared_one_is_blamed_on_trimesh(tmp_path: Path) -> None:
    out = _export(tmp_path, "s.gltf", CORPUS / "meshes" / "simple_sparse_accessor.gltf")
    declared = _verdict(out, "trimesh")
    assert declared.status == "skipped" and "ignores `accessor.sparse`" in declared.reason
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(gltf_trimesh, "KNOWN_BUGS", {})
        mp.setattr(gltf_trimesh, "declared", lambda doc, node: [])
        blamed = _verdict(out, "trimesh")
    assert blamed.status == "fail"
    assert "agrees with rendiff: trimesh departs from it" in blamed.reason
    assert _verdict(out, "gltf_spec").status == "pass"


def _glb(doc: dict[str, object], binary: bytes) -> bytes:
    """A GLB container (glTF 2.0 section 4): header, JSON chunk padded with spaces, BIN chunk with zeros."""
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    binary += b"\0" * (-len(binary) % 4)
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<III", 0x46546C67, 2, 12 + len(chunks)) + chunks


def test_a_glb_with_interleaved_attributes_byte_indices_two_primitives_and_a_hierarchy_passes(tmp_path: Path) -> None:
    # Five vertices interleaved with a normal (byteStride 24), u8 indices: a TRIANGLES primitive and a
    # fan; under a parent with a non-unit quaternion and a non-uniform scale; two mesh nodes named alike.
    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 1.5, 0.25]], dtype="<f4")
    inter = np.concatenate([pos, np.tile(np.array([[0, 0, 1]], dtype="<f4"), (5, 1))], axis=1)
    tri_idx = np.array([0, 1, 2, 0, 2, 3], dtype="u1")
    fan_idx = np.array([4, 3, 2, 1], dtype="u1")
    binary = tri_idx.tobytes() + fan_idx.tobytes() + b"\0\0" + inter.tobytes()
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [
            {
                "children": [1, 2],
                "rotation": [0.1, 0.2, 0.05, 0.9],
                "scale": [1.5, 0.75, 1.0],
                "translation": [0.1, -0.2, 0.3],
            },
            {"name": "twin", "mesh": 0},
            {"name": "twin", "mesh": 0, "matrix": [0, 1, 0, 0, -1, 0, 0, 0, 0, 0, 1, 0, 2, 0, 0, 1]},
        ],
        "meshes": [
            {
                "primitives": [
                    {"attributes": {"POSITION": 2}, "indices": 0},
                    {"attributes": {"POSITION": 2}, "indices": 1, "mode": 6},
                ]
            }
        ],
        "buffers": [{"byteLength": len(binary)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 10},
            {"buffer": 0, "byteOffset": 12, "byteLength": 120, "byteStride": 24},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5121, "count": 6, "type": "SCALAR"},
            {"bufferView": 0, "byteOffset": 6, "componentType": 5121, "count": 4, "type": "SCALAR"},
            {
                "bufferView": 1,
                "componentType": 5126,
                "count": 5,
                "type": "VEC3",
                "min": [0, 0, 0],
                "max": [1, 1.5, 0.25],
            },
        ],
    }
    out = _export(
        tmp_path,
        "m.glb",
        _glb(doc, binary),
        "transform = { rotate = [30.0, -20.0, 75.0], scale = [2.0, 1.0, 0.5], translate = [1.0, 2.0, -3.0] }\n",
    )
    spec = _verdict(out)
    assert spec.status == "pass", spec.reason
    assert spec.extra == {"triangles": 8, "objects": 2}
    assert [o["name"] for o in resolved.load(out).objects] == ["m/twin#1", "m/twin#2"]
    tm = _verdict(out, "trimesh")
    assert tm.status == "skipped" and "drops TRIANGLE_FAN" in tm.reason


QUAD = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.25]]
"""Four vertices of two triangles (0 1 2, 1 3 2), not in a plane."""


def _quad(g: Gltf) -> dict[str, Any]:
    """A TRIANGLES primitive of QUAD (float positions, u16 indices)."""
    pos = g.acc(QUAD, "VEC3", 5126, "<f4")
    return {"attributes": {"POSITION": pos}, "indices": g.acc([0, 1, 2, 1, 3, 2], "SCALAR", 5123, "<u2")}


def _instanced_gltf() -> bytes:
    """Under a rotated, translated parent: node "trees" with three EXT_mesh_gpu_instancing instances
    (float translations, a normalized signed-short rotation, a scale mirroring the last), and a
    plain node "ground" after it."""
    g = Gltf()
    prim = _quad(g)
    t = g.acc([[0, 0, 0], [2, 0.5, -1], [-1.5, 1, 0.25]], "VEC3", 5126, "<f4")
    c, s = round(32767 * np.cos(0.3)), round(32767 * np.sin(0.3))
    r = g.acc([[0, 0, 0, 32767], [0, s, 0, c], [s, 0, s, c]], "VEC4", 5122, "<i2", normalized=True)
    sc = g.acc([[1, 1, 1], [0.5, 2, 1], [-1, 1, 1.5]], "VEC3", 5126, "<f4")
    inst = {"EXT_mesh_gpu_instancing": {"attributes": {"TRANSLATION": t, "ROTATION": r, "SCALE": sc}}}
    g.doc |= {
        "meshes": [{"primitives": [prim]}],
        "nodes": [
            {"children": [1, 2], "rotation": [0.2, 0.1, 0.0, 0.97], "translation": [0.5, -0.25, 0.1]},
            {"name": "trees", "mesh": 0, "scale": [1.0, 1.5, 1.0], "extensions": inst},
            {"name": "ground", "mesh": 0, "translation": [0, -2, 0]},
        ],
        "scenes": [{"nodes": [0]}],
    }
    return g.bytes(scene=0, extensionsUsed=["EXT_mesh_gpu_instancing"], extensionsRequired=["EXT_mesh_gpu_instancing"])


TURNED = "transform = { rotate = [10.0, 25.0, -40.0], scale = [1.5, 1.5, 0.5], translate = [0.25, -1.0, 2.0] }\n"


def test_instances_are_objects_in_instance_order_and_pass(tmp_path: Path) -> None:
    out = _export(tmp_path, "i.gltf", _instanced_gltf(), TURNED)
    assert [o["name"] for o in resolved.load(out).objects] == ["m/trees/0", "m/trees/1", "m/trees/2", "m/ground"]
    spec = _verdict(out)
    assert spec.status == "pass", spec.reason
    assert spec.extra == {"triangles": 8, "objects": 4}
    parts = gltf_spec.decode(Path(resolved.load(out).objects[0]["mesh"]["file"]))
    assert "instance 2 of 3 (mirrored: winding reversed)" in parts[2].where
    tm = _verdict(out, "trimesh")  # the plain node compared, the instances declared
    assert tm.status == "pass" and tm.extra == {"triangles": 2, "objects": 1}, tm.reason
    assert "does not apply EXT_mesh_gpu_instancing" in tm.reason


def test_instances_in_the_wrong_order_fail_naming_the_instance(tmp_path: Path) -> None:
    out = _export(tmp_path, "i.gltf", _instanced_gltf(), TURNED)
    real = gltf_spec.instance_matrices

    def reversed_order(*args: Any) -> list[np.ndarray]:
        return real(*args)[::-1]

    bad = _plant_and_judge(
        tmp_path, out, _buggy_gltf(out, lambda mp: mp.setattr(gltf_spec, "instance_matrices", reversed_order))
    )
    assert bad.status == "fail", bad.reason
    assert "object 'm/trees/0' (node 1, mesh 0, instance 0 of 3)" in bad.reason
    assert "mesh 0 primitive 0 (TRIANGLES) triangle 0" in bad.reason
    assert "m/ground" not in bad.reason


def test_an_instance_placed_after_the_node_instead_of_before_fails_naming_it(tmp_path: Path) -> None:
    out = _export(tmp_path, "i.gltf", _instanced_gltf(), TURNED)
    bad = _plant_and_judge(
        tmp_path,
        out,
        _buggy_gltf(out, lambda mp: mp.setattr(gltf_spec, "instance_world", lambda world, inst: inst @ world)),
    )
    assert bad.status == "fail", bad.reason
    assert "object 'm/trees/1' (node 1, mesh 0, instance 1 of 3)" in bad.reason
    assert "m/trees/0" not in bad.reason and "m/ground" not in bad.reason  # the identity instance commutes


def _quantized_gltf() -> bytes:
    """KHR_mesh_quantization positions under dequantizing node transforms: unsigned shorts and signed
    bytes normalized, unsigned shorts unnormalized, each padded to a 4-byte stride."""
    g = Gltf()
    idx = g.acc([0, 1, 2, 1, 3, 2], "SCALAR", 5123, "<u2")
    u16 = g.acc([[0, 0, 0], [65535, 1234, 0], [17, 65535, 300], [40000, 50000, 65535]], "VEC3", 5123, "<u2", True, 8)
    i8 = g.acc([[-128, 0, 5], [127, -3, 0], [0, 127, -127], [100, 90, 64]], "VEC3", 5120, "<i1", True, 4)
    raw = g.acc([[0, 0, 0], [3, 0, 1], [0, 3, 0], [3, 3, 2]], "VEC3", 5123, "<u2", False, 8)
    g.doc |= {
        "meshes": [{"primitives": [{"attributes": {"POSITION": a}, "indices": idx}]} for a in (u16, i8, raw)],
        "nodes": [
            {"name": "u16", "mesh": 0, "scale": [2.5, 1.75, 0.5], "translation": [-1.25, -0.875, 0.1]},
            {"name": "i8", "mesh": 1, "scale": [0.75, 0.75, 0.75], "translation": [1.0, 0.0, 0.0]},
            {"name": "raw", "mesh": 2, "scale": [0.125, 0.125, 0.125], "translation": [0.0, 1.0, 0.0]},
        ],
        "scenes": [{"nodes": [0, 1, 2]}],
    }
    return g.bytes(scene=0, extensionsUsed=["KHR_mesh_quantization"], extensionsRequired=["KHR_mesh_quantization"])


def test_quantized_positions_pass_and_trimesh_compares_only_the_unnormalized(tmp_path: Path) -> None:
    out = _export(tmp_path, "q.gltf", _quantized_gltf(), TURNED)
    spec = _verdict(out)
    assert spec.status == "pass" and spec.extra == {"triangles": 6, "objects": 3}, spec.reason
    tm = _verdict(out, "trimesh")
    assert tm.status == "pass" and tm.extra == {"triangles": 2, "objects": 1}, tm.reason
    assert "ignores `accessor.normalized`" in tm.reason


def test_quantized_positions_not_normalized_fail_naming_the_primitive(tmp_path: Path) -> None:
    out = _export(tmp_path, "q.gltf", _quantized_gltf(), TURNED)
    real = gltf_spec.dequantize
    bad = _plant_and_judge(
        tmp_path,
        out,
        _buggy_gltf(out, lambda mp: mp.setattr(gltf_spec, "dequantize", lambda v, ct, norm: real(v, ct, False))),
    )
    assert bad.status == "fail", bad.reason
    assert "object 'm/u16' (node 0, mesh 0)" in bad.reason
    assert "mesh 0 primitive 0 (TRIANGLES quantized POSITION) triangle 0" in bad.reason
    assert "m/raw" not in bad.reason  # the unnormalized positions stay right


def test_a_float32_dequantization_would_lie_outside_the_bound(tmp_path: Path) -> None:
    # Why gltf_spec divides in float64 (docs/verifier.md): 12345/65535 in float32 is up to half a float32
    # unit of 0.19 away from rendiff's float64 value; a node translation that cancels it leaves a world
    # coordinate near 1e-5, whose own half unit (4.5e-13) cannot absorb that difference (here 1.6e-9).
    g = Gltf()
    pos = g.acc([[12345, 0, 0], [65535, 0, 0], [12345, 65535, 0]], "VEC3", 5123, "<u2", True, 8)
    q = np.float32(12345 / 65535)
    g.doc |= {
        "meshes": [{"primitives": [{"attributes": {"POSITION": pos}}]}],
        "nodes": [{"mesh": 0, "translation": [float(-q) + 1e-5, 0, 0]}],
        "scenes": [{"nodes": [0]}],
    }
    out = _export(tmp_path, "c.gltf", g.bytes(scene=0))
    assert _verdict(out).status == "pass"

    def in_float32(values: np.ndarray, ct: int, normalized: bool) -> np.ndarray:
        div, floor = gltf_spec.NORMALIZE[ct]
        as32: np.ndarray = np.maximum(values.astype(np.float32) / np.float32(div), np.float32(floor))
        return as32.astype(np.float64)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(gltf_spec, "dequantize", in_float32)
        assert _verdict(out).status == "fail"


def _two_scenes_gltf() -> bytes:
    """Scene 0 (the default, "first") shows node 0, scene 1 ("second") node 1: both named "part",
    so only the geometry tells them apart."""
    g = Gltf()
    a = g.acc([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "VEC3", 5126, "<f4")
    b = g.acc([[0, 0, 0], [1, 0, 0], [0, 1, 0.5]], "VEC3", 5126, "<f4")
    g.doc |= {
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": a}}]},
            {"primitives": [{"attributes": {"POSITION": b}}]},
        ],
        "nodes": [{"name": "part", "mesh": 0}, {"name": "part", "mesh": 1}],
        "scenes": [{"name": "first", "nodes": [0]}, {"name": "second", "nodes": [1]}],
    }
    return g.bytes(scene=0)


def test_the_chosen_gltf_scene_is_recorded_and_read(tmp_path: Path) -> None:
    for i, (choice, want) in enumerate([("", 0), ('gltf_scene = "second"\n', 1), ("gltf_scene = 0\n", 0)]):
        (tmp_path / str(i)).mkdir()
        out = _export(tmp_path / str(i), "s.gltf", _two_scenes_gltf(), choice)
        assert resolved.load(out).objects[0]["mesh"]["gltf_scene"] == want
        assert _verdict(out).status == "pass"
        tm = _verdict(out, "trimesh")
        assert tm.status == ("skipped" if want else "pass"), tm.reason
        assert ("loads only the file's default glTF scene" in tm.reason) == bool(want)


def test_the_default_scene_read_instead_of_the_chosen_one_fails_naming_the_primitive(tmp_path: Path) -> None:
    out = _export(tmp_path, "s.gltf", _two_scenes_gltf(), "gltf_scene = 1\n")
    bad = _plant_and_judge(
        tmp_path,
        out,
        _buggy_gltf(out, lambda mp: mp.setattr(gltfgraph, "scene_index", lambda doc, chosen: doc.get("scene", 0))),
    )
    assert bad.status == "fail", bad.reason
    assert (
        "object 'm/part' (node 1, mesh 1)" in bad.reason and "mesh 1 primitive 0 (TRIANGLES) triangle 0" in bad.reason
    )


def test_points_and_lines_are_skipped_and_a_node_of_nothing_else_is_no_object(tmp_path: Path) -> None:
    g = Gltf()
    prim = _quad(g)
    line = {"attributes": {"POSITION": prim["attributes"]["POSITION"]}, "mode": 1}
    g.doc |= {
        "meshes": [
            {"primitives": [line, prim, dict(line, mode=0), {"attributes": prim["attributes"], "mode": 5}]},
            {"primitives": [dict(line, mode=3), dict(line, mode=0)]},
        ],
        "nodes": [{"name": "a", "mesh": 0}, {"name": "b", "mesh": 1}, {"name": "c", "mesh": 0, "scale": [1, -1, 1]}],
        "scenes": [{"nodes": [0, 1, 2]}],
    }
    out = _export(tmp_path, "l.gltf", g.bytes(scene=0), TURNED)
    assert [o["name"] for o in resolved.load(out).objects] == ["m/a", "m/c"]
    for decoder in ("gltf_spec", "trimesh"):  # trimesh: a mesh of several primitives, lines among them
        entry = _verdict(out, decoder)
        assert entry.status == "pass" and entry.extra == {"triangles": 8, "objects": 2}, entry.reason
    with pytest.MonkeyPatch.context() as mp:  # a decoder that made an object of node b would disagree
        mp.setattr(gltf_spec, "draws_nothing", lambda mesh: False)
        wrong = _verdict(out)
    assert wrong.status == "fail" and "the decoder found 3 mesh nodes and instances" in wrong.reason
