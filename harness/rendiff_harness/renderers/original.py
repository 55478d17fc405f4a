"""What the backends that load the user's original mesh files share (renderers/mitsuba_file: OBJ
through Mitsuba's loader; renderers/pyrender_file: glTF through trimesh): the vertex placement bound
each records in its render (`vertex_placement`, read back by the precision model's
`Model.placement`), and the per-triangle check of the loaded triangles against rendiff's.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..judge.tolerance import DepthContext, render_param, shift_depth

PLACEMENT_ATTR = "vertex_placement"
"""The EXR attribute (and info key) holding the render's vertex placement bound, world units."""


def placement(attrs: Mapping[str, Any]) -> float:
    """The render's recorded vertex placement bound (0 when absent: compared as if exact)."""
    value = render_param(attrs, {}, PLACEMENT_ATTR)
    return value if value is not None and value >= 0.0 else 0.0


def placement_depth(ctx: DepthContext) -> tuple[np.ndarray, float]:
    """The depth term of the render's recorded vertex placement p, and p: every point of the scene
    may sit p from rendiff's, which moves a depth min(p / |cos|, depth span) (`shift_depth`)."""
    placed = placement(ctx.attrs)
    return shift_depth(ctx, np.full(ctx.z_ref.shape, placed)), placed


def disagreement(
    rendiff: np.ndarray, loaded: np.ndarray, bound: np.ndarray, first: int, path: Path, loader: str
) -> str:
    """'' when every triangle the loader placed equals rendiff's (one cyclic rotation of its vertices,
    within the bound per coordinate), else the count and the first that differs. All (n, 3, 3)."""
    ok = np.zeros(rendiff.shape[0], dtype=bool)
    for shift in range(3):
        rolled = np.roll(loaded, shift, axis=1)
        ok |= np.all(np.abs(rolled - rendiff) <= np.roll(bound, shift, axis=1), axis=(1, 2))
    bad = np.flatnonzero(~ok)
    if not bad.size:
        return ""
    k = int(bad[0])
    return (
        f"{bad.size} of {ok.size} triangles of {path.name} differ beyond the float32 placement bound, first "
        f"{loader}'s face {k} {loaded[k].tolist()} against rendiff's prim {first + k} {rendiff[k].tolist()}"
    )
