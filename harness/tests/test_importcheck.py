"""The `import` verdict (judge/importcheck, docs/verifier.md "The import verdict").

Each planted import bug is planted honestly: rendiff exports the real resolved scene of a small
file, then the test rewrites that scene's triangles as a buggy importer would have written them
(the same decoder with one step broken: sparse values one element off, a strip read as a list, a
mirrored node's winding kept, an OBJ negative index one off), and the unbroken verdict must fail,
naming the object and the primitive. The unmodified export must pass (so each test can fail both
ways), and a one-unit shift of one vertex must fail (the bound is not loose).
"""

from __future__ import annotations

import base64
import json
import shutil
import struct
import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from fixtures import REPO, rendiff_binary
from rendiff_harness.contract import resolved
from rendiff_harness.judge import importcheck
from rendiff_harness.judge.importcheck import gltf_spec, gltf_trimesh, match

CORPUS = REPO / "scenes" / "corpus"


def _export(tmp: Path, mesh_name: str, mesh: bytes | Path, transform: str = "") -> Path:
    """`rendiff export` of a scene showing `mesh` (bytes written, or a corpus file copied)."""
    binary = rendiff_binary()
    if binary is None:
        pytest.skip("no built rendiff (cargo build first): the import verdict needs its export")
    src = tmp / "scene"
    src.mkdir()
    if isinstance(mesh, Path):
        shutil.copy(mesh, src / mesh_name)
    else:
        (src / mesh_name).write_bytes(mesh)
    (src / "s.toml").write_text(
        'requires = ["depth", "ids"]\n[camera]\neye = [0.3, 0.2, 9.0]\nlook_at = [0.0, 0.0, 0.0]\n'
        f'vfov = 45.0\nwidth = 16\nheight = 16\n[[objects]]\nname = "m"\nmesh = "{mesh_name}"\n{transform}'
    )
    out = tmp / "resolved"
    subprocess.run([str(binary), "export", str(src / "s.toml"), "-o", str(out)], check=True, capture_output=True)
    return out


def _verdict(directory: Path, decoder: str = "gltf_spec") -> importcheck.Entry:
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
    np.concatenate(per_object).astype("<f4").tofile(directory / "triangles.f32")
    ids = np.concatenate([np.full(t.shape[0], i, dtype="<u4") for i, t in enumerate(per_object)])
    ids.tofile(directory / "object_ids.u32")


def _buggy_gltf(directory: Path, patch: Callable[[pytest.MonkeyPatch], None]) -> list[np.ndarray]:
    """The world triangles of the scene's glTF objects as the decoder reads them with one step broken."""
    scene = resolved.load(directory)
    with pytest.MonkeyPatch.context() as mp:
        patch(mp)
        parts = gltf_spec.decode(Path(scene.objects[0]["mesh"]["file"]))
    return [match.place(p, scene.objects[i]["mesh"]["transform"]).tris for i, p in enumerate(parts)]


def _plant_and_judge(
    tmp_path: Path, out: Path, buggy: list[np.ndarray], decoder: str = "gltf_spec"
) -> importcheck.Entry:
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
