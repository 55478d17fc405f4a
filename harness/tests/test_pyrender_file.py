"""`pyrender_file`: pyrender drawing the user's original glTF files as trimesh loads them
(renderers/pyrender_file/backend.py).

The loader facts the backend's ID mapping rests on are checked on a hand-written file against the
specification decoder; a planted import bug (rendiff's resolved triangles rewritten as a buggy
importer would have written them) must fail this backend while `pyrender`, which renders the
resolved export, passes; the unmodified export passes; and each refusal says why.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import backend_cases as cases
import meshfiles
from fixtures import REPO, three_triangles
from meshfiles import Gltf
from rendiff_harness.contract import gltfgraph, meshfile, resolved
from rendiff_harness.judge.importcheck import gltf_spec
from rendiff_harness.renderers import registry
from rendiff_harness.renderers.errors import BackendError, BackendSkipped
from rendiff_harness.renderers.pyrender import backend as pb
from rendiff_harness.renderers.pyrender_file import backend as pf

REASON = pb.unavailable_reason()
pytestmark = pytest.mark.skipif(REASON is not None, reason=f"pyrender unavailable: {REASON}")

CORPUS = REPO / "scenes" / "corpus" / "meshes"
TRANSFORM = "transform = { rotate = [10.0, -20.0, 15.0], scale = [0.9, 1.1, 1.0], translate = [0.1, -0.5, 0.2] }"
STRIP = [[0, 1.1, 0], [1, 1.1, 0.1], [0, 1.6, 0], [1, 1.6, 0.2], [0, 2.1, 0.1], [1, 2.1, 0]]


def _quad(g: Gltf, pos: list[list[float]]) -> dict[str, Any]:
    return {
        "attributes": {"POSITION": g.acc(pos, "VEC3", 5126, "<f4")},
        "indices": g.acc([0, 1, 2, 1, 3, 2], "SCALAR", 5123, "<u2"),
    }


def _hierarchy_gltf() -> bytes:
    """A rotated, translated root; under it "body" (rotated about x, scaled) showing a mesh of two
    primitives (a quad of TRIANGLES, then a TRIANGLE_STRIP of four), and "mirror" (scale -1 in x)
    showing another quad."""
    g = Gltf()
    quad = _quad(g, [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.25]])
    strip = {"attributes": {"POSITION": g.acc(STRIP, "VEC3", 5126, "<f4")}, "mode": 5}
    other = _quad(g, [[0, 0, 0], [1, 0, 0.2], [0, 1, 0], [1, 1, 0]])
    g.doc |= {
        "meshes": [{"primitives": [quad, strip]}, {"primitives": [other]}],
        "nodes": [
            {
                "name": "root",
                "children": [1, 2],
                "translation": [0.2, -0.1, 0],
                "rotation": [0, 0, 0.25881904, 0.96592583],
            },
            {"name": "body", "mesh": 0, "rotation": [0.34202014, 0, 0, 0.93969262], "scale": [1.2, 0.8, 1.0]},
            {"name": "mirror", "mesh": 1, "translation": [-0.4, 0, 0], "scale": [-1, 1, 1]},
        ],
        "scenes": [{"nodes": [0]}],
    }
    return g.bytes(scene=0)


def _export(tmp: Path, mesh: bytes | Path, name: str = "m.gltf", transform: str = TRANSFORM, extra: str = "") -> Path:
    camera = "eye = [-0.3, 0.6, 5.0]\nlook_at = [-0.3, 0.6, 0.0]\nvfov = 45.0\nwidth = 64\nheight = 48"
    return meshfiles.export(tmp, name, mesh, camera, f"{transform}\n{extra}", tmp / "run" / "scenes" / "s" / "resolved")


def _judge(directory: Path) -> dict[tuple[str, str], Any]:
    return cases.judge_renders(directory, ("pyrender", "pyrender_file"))


def _cyclic_equal(a: np.ndarray, b: np.ndarray, tol: float) -> bool:
    """Every triangle of `a` equals one cyclic rotation of `b`'s (winding kept)."""
    ok = np.zeros(a.shape[0], dtype=bool)
    for k in range(3):
        ok |= np.all(np.abs(np.roll(b, k, axis=1) - a) <= tol, axis=(1, 2))
    return bool(ok.all())


def test_trimesh_places_each_nodes_primitives_in_order_as_the_specification_does(tmp_path: Path) -> None:
    """The facts the prim_id mapping rests on: the j-th triangle of a node's primitives with faces, in
    order, as trimesh places it, is the specification's j-th (a strip's triangles in the topology
    table's order, the winding reversed under the mirroring node), up to a cyclic rotation."""
    path = tmp_path / "h.gltf"
    path.write_bytes(_hierarchy_gltf())
    doc, _ = gltfgraph.container(path)
    spec = gltf_spec.decode(path)
    scene = gltfgraph.trimesh_load(path)
    names = gltfgraph.trimesh_node_names(doc)
    assert [p.label for p in spec] == ["body", "mirror"]
    for part, node in zip(spec, (1, 2), strict=True):
        frames, prims = gltfgraph.trimesh_primitives(scene, names, node)
        assert len(frames) == len(prims) == (2 if node == 1 else 1)
        tris = np.concatenate([p.tris for p in prims])
        assert tris.shape == part.tris.shape
        assert _cyclic_equal(tris, part.tris, 1e-6)
        assert not _cyclic_equal(tris, part.tris[:, [0, 2, 1]], 1e-6)  # the winding is the test's


def test_trimesh_names_nodes_that_share_a_name_apart() -> None:
    """Two nodes named "a" are frames "a" and "a_1" in trimesh's graph: each object finds its own node."""
    doc = {"nodes": [{"name": "a"}, {"name": "a"}, {}, {"name": "world"}]}
    names = gltfgraph.trimesh_node_names(doc)
    assert names[0] == "a" and names[1] == "a_1" and names[2] == "2" and names[3] not in ("world", "a", "a_1", "2")


def test_the_unmodified_export_passes_and_records_its_placement(tmp_path: Path) -> None:
    out = _export(tmp_path, _hierarchy_gltf())
    scene = resolved.load(out)
    assert [o["name"] for o in scene.objects] == ["m/body", "m/mirror"]
    res = _judge(out)
    for key in [("pyrender", "id"), ("pyrender", "Z")] + [("pyrender_file", b) for b in ("id", "Z", "N")]:
        assert res[key]["status"] == "pass", (key, res[key]["reason"])
    assert "vertex placement" in res["pyrender_file", "Z"]["tolerance"]
    info = registry.get("pyrender_file").render(scene, tmp_path / "x.exr", tmp_path, 60.0)
    assert 0.0 < float(str(info["vertex_placement"])) < 1e-5 and "import_disagreement" not in info
    seen = np.unique(pf.render_arrays(scene)[0]["prim"])
    assert set(range(scene.triangle_count)) <= set(seen.tolist()), "every triangle must be seen to test its ID"


def _world_bug(scene: resolved.ResolvedScene, wrong: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
    """The body's triangles placed by `wrong(L_root, L_body)` instead of L_root L_body."""
    mesh = scene.objects[0]["mesh"]
    doc, _ = gltfgraph.container(Path(mesh["file"]))
    path = Path(mesh["file"])
    l0, l1 = (gltfgraph.local_matrix(doc["nodes"][i], i, path) for i in (0, 1))
    m, t = meshfile.object_matrix(mesh["transform"])
    tris = scene.triangles.astype(np.float64).copy()
    body = tris[:6]
    local = (body - t) @ np.linalg.inv(m).T
    hom = np.concatenate([local, np.ones((6, 3, 1))], axis=2) @ np.linalg.inv(l0 @ l1).T
    bad = hom @ wrong(l0, l1).T
    tris[:6] = bad[..., :3] @ m.T + t
    return tris


def _rotations_composed_in_the_wrong_order(scene: resolved.ResolvedScene) -> np.ndarray:
    return _world_bug(scene, lambda root, body: body @ root)


def _primitives_swapped(scene: resolved.ResolvedScene) -> np.ndarray:
    """The body's strip read before its quad."""
    tris = scene.triangles.copy()
    tris[:6] = np.concatenate([scene.triangles[2:6], scene.triangles[0:2]])
    return tris


@pytest.mark.parametrize("plant", [_rotations_composed_in_the_wrong_order, _primitives_swapped])
def test_a_planted_import_bug_fails_pyrender_file_while_the_resolved_export_passes(
    tmp_path: Path, plant: Callable[[resolved.ResolvedScene], np.ndarray]
) -> None:
    out = _export(tmp_path, _hierarchy_gltf())
    disagreement = meshfiles.planted_import_bug(out, plant(resolved.load(out)), "pyrender", tmp_path)
    assert "object 'm/body'" in disagreement


def test_a_mirrored_nodes_winding_not_reversed_fails_pyrender_files_normals(tmp_path: Path) -> None:
    """An importer that kept the winding under the mirroring node: the same triangles, so every ID and
    depth agrees, but the normals of trimesh's winding face the other way."""
    out = _export(tmp_path, _hierarchy_gltf())
    tris = resolved.load(out).triangles.copy()
    tris[6:] = tris[6:, [0, 2, 1]]
    meshfiles.planted_winding_bug(out, tris, "pyrender")


def test_a_triangle_count_rendiff_disagrees_with_is_an_error_naming_both_importers(tmp_path: Path) -> None:
    """An importer that dropped the strip's last triangle: no prim_id can be mapped, so the render is an
    error that says so (never IDs shifted onto the wrong triangles)."""
    out = _export(tmp_path, _hierarchy_gltf())
    meta = json.loads((out / "scene.json").read_text())
    tris = np.delete(resolved.load(out).triangles, 5, axis=0)
    meta["triangle_count"] = int(tris.shape[0])
    meta["objects"][0]["prim_count"] -= 1
    meta["objects"][1]["first_prim"] -= 1
    (out / "scene.json").write_text(json.dumps(meta))
    meshfiles.rewrite_triangles(out, tris)
    np.delete(np.fromfile(out / "object_ids.u32", dtype="<u4"), 5).tofile(out / "object_ids.u32")
    with pytest.raises(
        BackendError, match=r"importer disagreement: trimesh reads 6 triangles of node 1 \(body\) in m.gltf, rendiff 5"
    ):
        registry.get("pyrender_file").render(resolved.load(out), tmp_path / "x.exr", tmp_path, 60.0)


def _two_scenes_gltf() -> bytes:
    g = Gltf()
    a = g.acc([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "VEC3", 5126, "<f4")
    g.doc |= {
        "meshes": [{"primitives": [{"attributes": {"POSITION": a}}]}],
        "nodes": [{"name": "p", "mesh": 0}, {"name": "q", "mesh": 0, "translation": [0, 0, 0.5]}],
        "scenes": [{"nodes": [0]}, {"nodes": [1]}],
    }
    return g.bytes(scene=0)


@pytest.mark.parametrize(
    ("mesh", "extra", "reason"),
    [
        (CORPUS / "simple_sparse_accessor.gltf", "", "ignores `accessor.sparse`"),
        (CORPUS / "mesh_primitive_modes_triangles.gltf", "", "drops TRIANGLE_FAN"),
        (None, "gltf_scene = 1\n", "loads only the file's default glTF scene"),
    ],
)
def test_what_trimesh_does_not_read_is_skipped_with_its_reason(
    tmp_path: Path, mesh: Path | None, extra: str, reason: str
) -> None:
    out = _export(tmp_path, mesh if mesh is not None else _two_scenes_gltf(), transform="", extra=extra)
    with pytest.raises(BackendSkipped, match=reason):
        registry.get("pyrender_file").render(resolved.load(out), tmp_path / "x.exr", tmp_path, 60.0)


def test_obj_files_and_shapes_are_skipped_with_a_reason(tmp_path: Path) -> None:
    obj = _export(tmp_path / "obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "t.obj")
    with pytest.raises(BackendSkipped, match="obj file: only glTF files are loaded through trimesh"):
        pf.plan_uses(resolved.load(obj))
    with pytest.raises(BackendSkipped, match="not read from a mesh file"):
        pf.plan_uses(resolved.load(three_triangles(tmp_path / "t")))


def test_the_placement_bound_is_two_float32_roundings_and_the_float64_chains() -> None:
    """PLACEMENT_REL(d): rendiff's and this backend's float32 roundings, and the float64 chains' gamma
    terms, far below a float32 unit even ten levels deep (the input difference is computed apart)."""
    u = 2.0**-24
    rel = [pf.placement_rel(d) for d in range(11)]
    assert all(2 * u < r < 2.001 * u for r in rel) and rel == sorted(rel)
