"""Reader for the resolved scene written by `rendiff export` (docs/resolved-scene.md).

Backends read this instead of the TOML so that triangles, IDs and the camera are
the same numbers in every renderer.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

FORMAT = "rendiff-resolved/1"


class SceneError(Exception):
    """A resolved scene that cannot be read; the message names the file."""


@dataclass(frozen=True)
class Camera:
    """Pinhole camera exactly as docs/DESIGN.md defines it (pixel centers, row 0 on top)."""

    eye: np.ndarray
    look_at: np.ndarray
    up: np.ndarray
    forward: np.ndarray
    right: np.ndarray
    up_ortho: np.ndarray
    vfov_deg: float
    tan_half_vfov: float
    width: int
    height: int
    near: float
    far: float  # math.inf when unbounded

    def screen_coords(self) -> tuple[np.ndarray, np.ndarray]:
        """(sx, sy) of every pixel center, each shaped (H, W), float64."""
        w, h = self.width, self.height
        xs = (2.0 * (np.arange(w, dtype=np.float64) + 0.5) / w - 1.0) * self.tan_half_vfov * (w / h)
        ys = (1.0 - 2.0 * (np.arange(h, dtype=np.float64) + 0.5) / h) * self.tan_half_vfov
        sx, sy = np.meshgrid(xs, ys)
        return sx, sy

    def pixel_directions(self) -> np.ndarray:
        """Unnormalized ray directions d(x, y), shaped (H, W, 3); t along d is planar depth."""
        sx, sy = self.screen_coords()
        directions: np.ndarray = (
            self.forward[None, None, :]
            + sx[..., None] * self.right[None, None, :]
            + sy[..., None] * self.up_ortho[None, None, :]
        )
        return directions


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


def load(directory: str | Path) -> ResolvedScene:
    """Load a resolved scene directory; raises SceneError naming the bad file."""
    directory = Path(directory)
    meta_path = directory / "scene.json"
    try:
        meta = json.loads(meta_path.read_text())
    except FileNotFoundError as exc:
        raise SceneError(f"{meta_path}: missing (run `rendiff export` first)") from exc
    except json.JSONDecodeError as exc:
        raise SceneError(f"{meta_path}: not valid JSON: {exc}") from exc
    if meta.get("format") != FORMAT:
        raise SceneError(f"{meta_path}: format is {meta.get('format')!r}, expected {FORMAT!r}")
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
    count = int(meta["triangle_count"])
    files = meta.get("files", {})
    tri_path = directory / files.get("triangles", "triangles.f32")
    ids_path = directory / files.get("object_ids", "object_ids.u32")
    try:
        tris = np.fromfile(tri_path, dtype="<f4")
        oids = np.fromfile(ids_path, dtype="<u4")
    except FileNotFoundError as exc:
        raise SceneError(f"{exc.filename}: missing") from exc
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
    )
