"""Where a resolved scene's objects came from: the mesh file each was read from and the scene
object's transform (`objects[].mesh` in scene.json, docs/resolved-scene.md).

One home for reading that record, because two independent readings of the user's files use it:
the `import` verdict (judge/importcheck/, which decodes the file again and compares triangles) and
the renderer that loads the original file itself (renderers/mitsuba_file/, which renders it).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .resolved import ResolvedScene

OPS_OBJECT = 16
"""Roundings the scene object's transform adds to a coordinate: degrees to radians (1), sin and cos
(within one unit each: 2), the products Rz Ry Rx (two 3-term products: 6), the scale (1), the point
(a 3-term product plus the translation: 4): 14, taken as 16."""


class MeshFileError(Exception):
    """A mesh file an independent reading cannot read; the message names the file and the problem."""


def file_uses(scene: ResolvedScene) -> list[list[int]]:
    """Indices of the objects read from one scene object's mesh file, one list per use of a file
    (a use starts at part 0; the objects of one use are consecutive, in the file's part order).
    Objects without `mesh` (generated shapes, literal triangles) are in none."""
    out: list[list[int]] = []
    for i, obj in enumerate(scene.objects):
        mesh = obj.get("mesh") if isinstance(obj, dict) else None
        if not isinstance(mesh, dict):
            continue
        if mesh.get("part") == 0 or not out:
            out.append([])
        out[-1].append(i)
    return out


def object_matrix(transform: Any) -> tuple[np.ndarray, np.ndarray]:
    """A scene object's transform as written (scale, rotate in degrees X then Y then Z, translate):
    (M, t) in float64 with world = M p + t, M = Rz Ry Rx diag(scale) (docs/resolved-scene.md)."""
    t = transform if isinstance(transform, dict) else {}
    s = np.asarray(t.get("scale", [1.0, 1.0, 1.0]), dtype=np.float64).reshape(3)
    rx, ry, rz = np.radians(np.asarray(t.get("rotate", [0.0, 0.0, 0.0]), dtype=np.float64).reshape(3))
    tr = np.asarray(t.get("translate", [0.0, 0.0, 0.0]), dtype=np.float64).reshape(3)
    cx, sx, cy, sy, cz, sz = math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry), math.cos(rz), math.sin(rz)
    mx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    my = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    mz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return mz @ my @ mx @ np.diag(s), tr
