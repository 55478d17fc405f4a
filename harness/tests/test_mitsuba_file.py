"""`mitsuba_file`: Mitsuba rendering the user's original OBJ files (renderers/mitsuba_file/backend.py).

The loader facts the backend's ID mapping rests on are checked on hand-written files; a planted
import bug (rendiff's resolved triangles rewritten as a buggy importer would have written them)
must fail this backend's id verdict while `mitsuba`, which renders the resolved export, passes;
and the unmodified scenes (the torus placed twice, the corpus's n-gon control meshes) pass.
"""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import backend_cases as cases
import meshfiles
from fixtures import REPO, rendiff_binary, three_triangles
from rendiff_harness.contract import meshfile, resolved
from rendiff_harness.renderers import registry
from rendiff_harness.renderers.errors import BackendError, BackendSkipped
from rendiff_harness.renderers.mitsuba import backend as mb
from rendiff_harness.renderers.mitsuba_file import backend as mf

REASON = mb.unavailable_reason()
pytestmark = pytest.mark.skipif(REASON is not None, reason=f"mitsuba unavailable: {REASON}")

GRID = "".join(f"v {x} {y} 0\n" for y in range(4) for x in range(4)) + "g left\n"
"""A 3 x 3 grid of unit quads in z = 0 (vertex 1 + x + 4 y at (x, y)), as two groups, plus one
convex pentagon above it (vertices 13, 14 and three more)."""
GRID += "".join(
    f"f {1 + x + 4 * y} {2 + x + 4 * y} {6 + x + 4 * y} {5 + x + 4 * y}\n" for y in range(3) for x in range(2)
)
GRID += "g right\n" + "".join(f"f {3 + 4 * y} {4 + 4 * y} {8 + 4 * y} {7 + 4 * y}\n" for y in range(3))
GRID += "v 1.3 3.5 0\nv 0.5 3.9 0\nv -0.3 3.5 0\nf 13 14 17 18 19\n"
TRANSFORM = "transform = { rotate = [10.0, -20.0, 30.0], scale = [0.9, 1.1, 1.0], translate = [-1.2, -1.4, 0.3] }"


def _export(tmp: Path, obj: str | Path, transform: str = TRANSFORM, name: str = "m.obj") -> Path:
    camera = "eye = [0.2, 0.1, 6.0]\nlook_at = [0.0, 0.0, 0.0]\nvfov = 45.0\nwidth = 48\nheight = 40"
    return meshfiles.export(tmp, name, obj, camera, transform, tmp / "run" / "scenes" / "s" / "resolved")


def _judge(directory: Path, backends: tuple[str, ...] = ("mitsuba", "mitsuba_file")) -> dict[tuple[str, str], Any]:
    return cases.judge_renders(directory, backends)


def test_mitsubas_obj_loader_keeps_face_order_ignores_groups_and_fans_ngons(tmp_path: Path) -> None:
    """The facts the prim_id mapping rests on: Mitsuba's face k of a file is the k-th triangle of the
    file's faces in order, each n-gon a fan (0 1 2), (0 2 3), ... from its first vertex."""
    path = tmp_path / "g.obj"
    path.write_text(GRID)
    mi = mb._import_mitsuba()
    verts, faces = mf._arrays(mi, mf._shape(mi, path, None))
    lines = GRID.splitlines()
    text_verts = np.array([[float(c) for c in ln.split()[1:]] for ln in lines if ln.startswith("v ")])
    fans = []
    for ln in lines:
        if ln.startswith("f "):
            idx = [int(c) - 1 for c in ln.split()[1:]]
            fans += [[idx[0], idx[i], idx[i + 1]] for i in range(1, len(idx) - 1)]
    assert np.array_equal(verts[faces], text_verts.astype(np.float32)[np.array(fans)])


def test_the_unmodified_export_passes_and_records_its_placement(tmp_path: Path) -> None:
    out = _export(tmp_path, GRID)
    res = _judge(out)
    for key in [(b, buf) for b in ("mitsuba", "mitsuba_file") for buf in ("id", "Z", "N")]:
        assert res[key]["status"] == "pass", (key, res[key]["reason"])
    assert "vertex placement" in res["mitsuba_file", "Z"]["tolerance"]
    info = registry.get("mitsuba_file").render(resolved.load(out), tmp_path / "x.exr", tmp_path, 60.0)
    assert 0.0 < float(str(info["vertex_placement"])) < 1e-5 and "import_disagreement" not in info


def _fan_from_the_second_vertex(scene: resolved.ResolvedScene) -> np.ndarray:
    """Each quad (a b c d) triangulated (b c d), (b d a): the other diagonal."""
    tris = scene.triangles.copy()
    quads = np.arange(0, 18, 2)  # the nine quads come first, two triangles each
    a, b, c = tris[quads, 0], tris[quads, 1], tris[quads, 2]
    d = tris[quads + 1, 2]
    tris[quads] = np.stack([b, c, d], axis=1)
    tris[quads + 1] = np.stack([b, d, a], axis=1)
    return tris


def _rotations_in_the_wrong_order(scene: resolved.ResolvedScene) -> np.ndarray:
    """The scene object's rotations composed Rx Ry Rz instead of Rz Ry Rx."""
    mesh = scene.objects[0]["mesh"]
    m, t = meshfile.object_matrix(mesh["transform"])
    local = (scene.triangles.astype(np.float64) - t) @ np.linalg.inv(m).T
    rot = mesh["transform"]["rotate"]
    rx, _ = meshfile.object_matrix({"rotate": [rot[0], 0, 0]})
    ry, _ = meshfile.object_matrix({"rotate": [0, rot[1], 0]})
    rz, _ = meshfile.object_matrix({"rotate": [0, 0, rot[2]]})
    wrong = rx @ ry @ rz @ np.diag(mesh["transform"]["scale"])
    return np.asarray(local @ wrong.T + t)


@pytest.mark.parametrize("plant", [_fan_from_the_second_vertex, _rotations_in_the_wrong_order])
def test_a_planted_import_bug_fails_mitsuba_file_while_the_resolved_export_passes(
    tmp_path: Path, plant: Callable[[resolved.ResolvedScene], np.ndarray]
) -> None:
    out = _export(tmp_path, GRID)
    ok = _judge(out)
    assert ok["mitsuba_file", "id"]["status"] == "pass", ok["mitsuba_file", "id"]["reason"]
    disagreement = meshfiles.planted_import_bug(out, plant(resolved.load(out)), "mitsuba", tmp_path)
    assert "importer disagreement" in disagreement


def test_a_winding_flipped_under_a_mirroring_transform_fails_mitsuba_files_normals(tmp_path: Path) -> None:
    """An importer that reversed the winding because the object's transform mirrors (glTF's rule for
    node matrices, which OBJ scene transforms do not have): the same triangles, so every ID agrees,
    but Mitsuba's normals, from the file's own winding, face the other way."""
    out = _export(tmp_path, GRID, TRANSFORM.replace("scale = [0.9,", "scale = [-0.9,"))
    ok = _judge(out)
    assert ok["mitsuba_file", "N"]["status"] == "pass", ok["mitsuba_file", "N"]["reason"]
    meshfiles.planted_winding_bug(out, resolved.load(out).triangles[:, [0, 2, 1]], "mitsuba")


def test_the_torus_placed_twice_maps_both_shapes(tmp_path: Path) -> None:
    """scenes/obj_mesh.toml: two uses of one file, so shape_index picks the prim offset."""
    binary = rendiff_binary()
    if binary is None:
        pytest.skip("no built rendiff")
    out = tmp_path / "run" / "scenes" / "obj_mesh" / "resolved"
    subprocess.run([str(binary), "export", str(REPO / "scenes/obj_mesh.toml"), "-o", str(out)], check=True)
    assert len(meshfile.file_uses(resolved.load(out))) == 2
    res = _judge(out, ("mitsuba_file",))
    assert res["mitsuba_file", "id"]["status"] == "pass", res["mitsuba_file", "id"]["reason"]
    assert res["mitsuba_file", "Z"]["status"] == "pass", res["mitsuba_file", "Z"]["reason"]


def test_negative_indices_long_lines_gltf_and_shapes_are_skipped_with_a_reason(tmp_path: Path) -> None:
    neg = _export(tmp_path / "neg", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n")
    with pytest.raises(BackendSkipped, match="negative"):
        mf.plan_uses(resolved.load(neg))
    long = _export(tmp_path / "long", "# " + "x" * 1100 + "\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(BackendSkipped, match="1024 characters"):
        mf.plan_uses(resolved.load(long))
    gltf = _export(tmp_path / "gltf", REPO / "scenes/corpus/meshes/box.gltf", "", "b.gltf")
    with pytest.raises(BackendSkipped, match="gltf file"):
        mf.plan_uses(resolved.load(gltf))
    with pytest.raises(BackendSkipped, match="not read from a mesh file"):
        mf.plan_uses(resolved.load(three_triangles(tmp_path / "t")))


def test_a_face_count_rendiff_disagrees_with_is_an_error_naming_the_importers(tmp_path: Path) -> None:
    """An importer that dropped the pentagon's last triangle: no prim_id can be mapped, so the render
    is an error that says so (never IDs shifted onto the wrong triangles)."""
    out = _export(tmp_path, GRID)
    meta = json.loads((out / "scene.json").read_text())
    tris = resolved.load(out).triangles[:-1]
    meta["triangle_count"] = int(tris.shape[0])
    meta["objects"][-1]["prim_count"] -= 1
    (out / "scene.json").write_text(json.dumps(meta))
    meshfiles.rewrite_triangles(out, tris)
    np.fromfile(out / "object_ids.u32", dtype="<u4")[:-1].tofile(out / "object_ids.u32")
    with pytest.raises(BackendError, match=r"importer disagreement: Mitsuba reads 21 triangles from m.obj, rendiff 20"):
        registry.get("mitsuba_file").render(resolved.load(out), tmp_path / "x.exr", tmp_path, 60.0)
