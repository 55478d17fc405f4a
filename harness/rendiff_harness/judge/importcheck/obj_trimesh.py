"""OBJ files read by trimesh (its own parser, not tobj, which rendiff loads with): the second
reading of every OBJ a scene shows (`import` verdict).

trimesh is asked for one geometry per `o`/`g` group (`split_objects`, `split_groups`), faces in
file order (`maintain_order`), nothing merged or removed (`process=False`); its n-gons are fans
from the first vertex, as tobj's, though written as other rotations of the same triangles (a quad
a b c d as (a b c), (c d a)), which the comparison does not tell apart (a triangle is compared
up to a cyclic rotation of its vertices, never a reflection: the winding stays). Groups without
faces make no part (as in rendiff). Coordinates are OBJ decimal text, which rendiff reads as
float32 (tobj); trimesh reads float64 and this module rounds them to float32, which can differ from
rounding the decimal straight to float32 by one float32 unit (double rounding): `input_rel`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .parts import DecodeError, Part, empty_part, extend

INPUT_REL = 2.0**-23
"""One float32 unit, relative: how far trimesh's float64-then-float32 value may be from the decimal
rounded straight to float32 (both are within half a unit of the decimal's float64 value... or the
decimal itself: together at most one unit)."""

OPS_POINT = 0
"""trimesh applies no transform to OBJ vertices: the values are the parsed ones."""


def decode(path: Path) -> list[Part]:
    """The OBJ's groups with faces, in file order, each a Part labelled with its group name."""
    import trimesh  # noqa: PLC0415 - heavy import, only where an OBJ is checked

    try:
        with path.open("rb") as fh:
            loaded: Any = trimesh.load(
                fh,
                file_type="obj",
                force="scene",
                process=False,
                maintain_order=True,
                group_material=False,
                split_objects=True,
                split_groups=True,
                skip_materials=True,
            )
    except Exception as exc:  # noqa: BLE001 - a third-party parser's failure is the file's verdict
        raise DecodeError(f"{path}: trimesh cannot read it: {type(exc).__name__}: {exc}") from None
    out: list[Part] = []
    for name, geom in loaded.geometry.items():
        faces = np.asarray(getattr(geom, "faces", np.zeros((0, 3))), dtype=np.int64)
        if faces.size == 0:
            continue
        verts = np.asarray(geom.vertices, dtype=np.float64).astype(np.float32).astype(np.float64)
        part = empty_part(str(name), f"OBJ group {name!r}", OPS_POINT)
        part.input_rel = INPUT_REL
        tris = verts[faces]
        extend(part, f"group {name!r} (faces in file order, n-gons as fans)", tris, np.abs(tris))
        out.append(part)
    return out
