"""Reader for the resolved scene written by `rendiff export` (docs/resolved-scene.md).

Backends read this instead of the TOML so that triangles, IDs and the camera are
the same numbers in every renderer.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .camera import Camera
from .userfile import JsonFileError, UserFileError, open_regular, read_record

FORMAT = "rendiff-resolved/1"


class SceneError(Exception):
    """A resolved scene that cannot be read; the message names the file."""


@dataclass(frozen=True)
class ResolvedScene:
    """World-space triangles with global IDs, plus camera, materials and lights."""

    directory: Path
    name: str
    source: str
    requires: frozenset[str]
    camera: Camera
    triangles: np.ndarray  # (N, 3, 3) float32
    object_ids: np.ndarray  # (N,) uint32
    objects: list[dict[str, Any]] = field(default_factory=list)
    materials: list[dict[str, Any]] = field(default_factory=list)
    lights: list[dict[str, Any]] = field(default_factory=list)
    integrator: dict[str, Any] = field(default_factory=dict)  # {"max_depth": int, "spp": int} (path tracing)
    vertex_ids_file: Path | None = None  # files.vertex_ids, if the export wrote one (read on demand)

    @property
    def triangle_count(self) -> int:
        return int(self.triangles.shape[0])

    def prim_materials(self) -> np.ndarray:
        """(N,) int64: the material index of every triangle (objects[object_id].material).

        An object without a material entry, or a material index outside `materials`,
        raises SceneError: shading would otherwise silently pick a wrong albedo.
        """
        mats = np.zeros(len(self.objects), dtype=np.int64)
        for i, obj in enumerate(self.objects):
            m = obj.get("material") if isinstance(obj, dict) else None
            if isinstance(m, bool) or not isinstance(m, int) or not 0 <= m < len(self.materials):
                raise SceneError(
                    f"{self.directory}/scene.json: objects[{i}].material is {m!r}, "
                    f"not an index into {len(self.materials)} materials"
                )
            mats[i] = m
        if self.triangle_count and (not self.objects or int(self.object_ids.max()) >= len(self.objects)):
            raise SceneError(f"{self.directory}: object_ids.u32 names objects beyond the {len(self.objects)} listed")
        return mats[self.object_ids.astype(np.int64)] if self.triangle_count else np.zeros(0, dtype=np.int64)

    def material_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(albedo (M, 3), emission (M, 3)) float64 of every material (missing keys are 0)."""
        alb = np.zeros((len(self.materials), 3))
        emi = np.zeros((len(self.materials), 3))
        for i, m in enumerate(self.materials):
            for arr, key in ((alb, "albedo"), (emi, "emission")):
                v = m.get(key, [0.0, 0.0, 0.0]) if isinstance(m, dict) else None
                try:
                    arr[i] = np.asarray(v, dtype=np.float64).reshape(3)
                except (TypeError, ValueError):
                    raise SceneError(f"{self.directory}/scene.json: materials[{i}].{key} must be 3 numbers") from None
                if not np.all(np.isfinite(arr[i])) or np.any(arr[i] < 0):
                    raise SceneError(f"{self.directory}/scene.json: materials[{i}].{key} must be finite and >= 0")
        return alb, emi

    def corner_vertex_ids(self) -> np.ndarray | None:
        """(N, 3) uint32: the export's vertex number of every corner (`vertex_ids.u32`), or None
        where the export wrote none (a hand-written or older folder). Read on demand: only the
        verifier needs it, and `contract/vertex_ids.checked` checks it before use."""
        if self.vertex_ids_file is None:
            return None
        return _read_array(self.vertex_ids_file, "<u4", self.triangle_count, 3).reshape(-1, 3)

    @property
    def spp(self) -> int:
        """Samples per pixel the scene asks for (integrator.spp, default 64)."""
        v = self.integrator.get("spp", 64)
        return int(v) if isinstance(v, int) and not isinstance(v, bool) and v > 0 else 64

    @property
    def max_depth(self) -> int:
        """Longest path in vertices, Mitsuba's convention (-1 = unlimited; default -1)."""
        v = self.integrator.get("max_depth", -1)
        return int(v) if isinstance(v, int) and not isinstance(v, bool) else -1


def _vec(meta: dict[str, Any], key: str, where: Path) -> np.ndarray:
    value = meta.get(key)
    if not isinstance(value, list) or len(value) != 3:
        raise SceneError(f"{where}: camera.{key} must be a list of 3 numbers")
    arr = np.asarray(value, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise SceneError(f"{where}: camera.{key} is not finite")
    return arr


# Largest scene.json read: its size limit in Rust's readers (run records, 256 MiB).
MAX_SCENE_JSON_BYTES = 256 << 20


def _data_file(directory: Path, files: Any, key: str, default: str, meta_path: Path) -> Path:
    """The data file `files[key]` names: a plain file name inside `directory` (a name from
    scene.json with a folder in it, `..` or an absolute path read a file elsewhere)."""
    name = files.get(key, default) if isinstance(files, dict) else default
    if not isinstance(name, str) or not name or Path(name).name != name or name in (".", ".."):
        raise SceneError(f"{meta_path}: files.{key} must be a file name in its folder, got {name!r}")
    return directory / name


def _read_array(path: Path, dtype: str, count: int, per: int) -> np.ndarray:
    """`count * per` values of `dtype` from the regular file `path`, its size checked first (a FIFO
    there hung the reader, /dev/zero ran it out of memory)."""
    want = count * per * np.dtype(dtype).itemsize
    try:
        with open_regular(path) as fh:
            size = os.fstat(fh.fileno()).st_size
            if size != want:
                raise SceneError(f"{path}: is {size} bytes, expected {want} ({count} x {per} x {dtype})")
            data: np.ndarray = np.fromfile(fh, dtype=dtype, count=count * per)
            return data
    except FileNotFoundError:
        raise SceneError(f"{path}: missing") from None
    except UserFileError as exc:
        raise SceneError(f"{path}: {exc}") from None
    except OSError as exc:
        raise SceneError(f"{path}: unreadable: {exc.strerror or exc}") from None


def load(directory: str | Path) -> ResolvedScene:
    """Load a resolved scene directory; raises SceneError naming the bad file."""
    directory = Path(directory)
    meta_path = directory / "scene.json"
    try:
        meta = read_record(meta_path, MAX_SCENE_JSON_BYTES, FORMAT, " (run `rendiff export` first)")
    except JsonFileError as exc:
        raise SceneError(str(exc)) from None
    cam = meta["camera"]
    far = cam.get("far")
    camera = Camera(
        eye=_vec(cam, "eye", meta_path),
        look_at=_vec(cam, "look_at", meta_path),
        up=_vec(cam, "up", meta_path),
        forward=_vec(cam, "forward", meta_path),
        right=_vec(cam, "right", meta_path),
        up_ortho=_vec(cam, "up_ortho", meta_path),
        vfov_deg=float(cam["vfov_deg"]),
        tan_half_vfov=float(cam["tan_half_vfov"]),
        width=int(cam["width"]),
        height=int(cam["height"]),
        near=float(cam["near"]),
        far=math.inf if far is None else float(far),
    )
    count = meta["triangle_count"]
    if isinstance(count, bool) or not isinstance(count, int) or count < 0:
        raise SceneError(f"{meta_path}: triangle_count must be a count, got {count!r}")
    files = meta.get("files", {})
    tri_path = _data_file(directory, files, "triangles", "triangles.f32", meta_path)
    ids_path = _data_file(directory, files, "object_ids", "object_ids.u32", meta_path)
    has_vids = isinstance(files, dict) and "vertex_ids" in files
    vids_path = _data_file(directory, files, "vertex_ids", "vertex_ids.u32", meta_path) if has_vids else None
    tris = _read_array(tri_path, "<f4", count, 9)
    oids = _read_array(ids_path, "<u4", count, 1)
    if tris.size != count * 9:
        raise SceneError(f"{tri_path}: holds {tris.size} floats, expected {count * 9}")
    if oids.size != count:
        raise SceneError(f"{ids_path}: holds {oids.size} ids, expected {count}")
    if not np.all(np.isfinite(tris)):
        raise SceneError(f"{tri_path}: contains NaN or Inf")
    return ResolvedScene(
        directory=directory,
        name=str(meta.get("name", "")),
        source=str(meta.get("source", "")),
        requires=frozenset(meta.get("requires", [])),
        camera=camera,
        triangles=tris.reshape(count, 3, 3),
        object_ids=oids,
        objects=list(meta.get("objects", [])),
        materials=list(meta.get("materials", [])),
        lights=list(meta.get("lights", [])),
        integrator=dict(meta["integrator"]) if isinstance(meta.get("integrator"), dict) else {},
        vertex_ids_file=vids_path,
    )
