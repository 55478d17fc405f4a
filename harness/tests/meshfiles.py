"""Scenes that show one mesh file, as `rendiff export` writes them, for the tests of the import
verdict (test_importcheck.py) and of the backends that load the file themselves
(test_mitsuba_file.py, test_pyrender_file.py): a small glTF builder, the export, and the planted
importer bugs that a `*_file` backend must fail while its resolved-export twin passes.
"""

from __future__ import annotations

import base64
import json
import shutil
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import backend_cases as cases
from fixtures import rendiff_binary
from rendiff_harness.contract import resolved, vertex_ids
from rendiff_harness.renderers import registry


class Gltf:
    """A small glTF under construction: each array becomes an accessor of one base64 `data:` buffer."""

    def __init__(self) -> None:
        self.data = b""
        self.doc: dict[str, Any] = {"asset": {"version": "2.0"}, "bufferViews": [], "accessors": []}

    def acc(self, values: Any, kind: str, ct: int, dtype: str, normalized: bool = False, stride: int = 0) -> int:
        """Appends `values` (rows of `kind`) as an accessor of componentType `ct`; its index."""
        arr = np.ascontiguousarray(np.asarray(values, dtype=dtype).reshape(len(values), -1))
        self.data += b"\0" * (-len(self.data) % 4)
        raw = arr.tobytes()
        if stride:  # vertex attributes padded to a 4-byte stride, as KHR_mesh_quantization requires
            raw = b"".join(row.tobytes() + b"\0" * (stride - arr.itemsize * arr.shape[1]) for row in arr)
        view: dict[str, Any] = {"buffer": 0, "byteOffset": len(self.data), "byteLength": len(raw)}
        if stride:
            view["byteStride"] = stride
        self.doc["bufferViews"].append(view)
        self.data += raw
        acc: dict[str, Any] = {"bufferView": len(self.doc["bufferViews"]) - 1, "componentType": ct}
        acc |= {"count": len(arr), "type": kind, "normalized": normalized}
        if kind == "VEC3":
            acc |= {"min": arr.min(axis=0).tolist(), "max": arr.max(axis=0).tolist()}
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def bytes(self, **top: Any) -> bytes:
        uri = "data:application/octet-stream;base64," + base64.b64encode(self.data).decode()
        return json.dumps(self.doc | top | {"buffers": [{"uri": uri, "byteLength": len(self.data)}]}).encode()


def export(tmp: Path, name: str, mesh: bytes | str | Path, camera: str, after: str, out: Path) -> Path:
    """`rendiff export` into `out` of a scene (in tmp/scene) whose one object "m" shows the file
    `name`: `mesh` written as bytes or text, or a file copied. `camera` is the [camera] table's
    body, `after` what follows the object's `mesh` line (its transform, more keys)."""
    binary = rendiff_binary()
    if binary is None:
        pytest.skip("no built rendiff (cargo build first): the scene comes from its export")
    src = tmp / "scene"
    src.mkdir(parents=True)
    if isinstance(mesh, Path):
        shutil.copy(mesh, src / name)
    elif isinstance(mesh, str):
        (src / name).write_text(mesh)
    else:
        (src / name).write_bytes(mesh)
    (src / "s.toml").write_text(
        f'requires = ["depth", "ids"]\n[camera]\n{camera}\n[[objects]]\nname = "m"\nmesh = "{name}"\n{after}\n'
    )
    subprocess.run([str(binary), "export", str(src / "s.toml"), "-o", str(out)], check=True, capture_output=True)
    return out


def rewrite_triangles(directory: Path, tris: np.ndarray) -> None:
    """The resolved scene as an importer that produced `tris` (same count and objects) would have written it:
    the triangles and, where the export wrote them, their corners' vertex numbers (vertex_ids.u32)."""
    tris.astype("<f4").tofile(directory / "triangles.f32")
    if (directory / "vertex_ids.u32").exists():
        _, numbers = vertex_ids.group(*vertex_ids.corner_keys(tris))
        numbers.astype("<u4").tofile(directory / "vertex_ids.u32")


def _planted(out: Path, tris: np.ndarray, backend: str) -> dict[tuple[str, str], Any]:
    """The export at `out` rewritten as an importer that produced `tris` would have written it,
    judged for `backend` (which renders the export: every verdict of it passes) and its `_file` twin
    (which loads the file itself): their entries."""
    rewrite_triangles(out, tris)
    judged = cases.judge_renders(out, (backend, f"{backend}_file"))
    assert all(e["status"] == "pass" for (b, _), e in judged.items() if b == backend), judged
    return judged


def planted_import_bug(out: Path, tris: np.ndarray, backend: str, tmp: Path) -> str:
    """`_planted` with triangles moved: the `_file` twin fails its IDs inside triangles. Returns its
    render's `import_disagreement`."""
    file_backend = f"{backend}_file"
    bad = _planted(out, tris, backend)
    assert bad[file_backend, "id"]["status"] == "fail", bad[file_backend, "id"]["reason"]
    assert bad[file_backend, "id"]["interior_mismatches"] > 0
    info = registry.get(file_backend).render(resolved.load(out), tmp / "x.exr", tmp, 60.0)
    return str(info["import_disagreement"])


def planted_winding_bug(out: Path, tris: np.ndarray, backend: str) -> None:
    """`_planted` with the same triangles in the other winding: the `_file` twin's IDs pass and its
    normals, from the file's own winding, fail, facing the other way."""
    file_backend = f"{backend}_file"
    bad = _planted(out, tris, backend)
    assert bad[file_backend, "id"]["status"] == "pass", bad[file_backend, "id"]["reason"]
    assert bad[file_backend, "N"]["status"] == "fail" and "facing the other way" in bad[file_backend, "N"]["reason"]
