"""What the backends that load the user's original mesh files share (renderers/mitsuba_file: OBJ
through Mitsuba's loader; renderers/pyrender_file: glTF through trimesh): the vertex placement bound
each records in its render (`vertex_placement`, read back by the precision model's
`Model.placement`) and its depth term on top of the drawing backend's model, the per-triangle check
of the loaded triangles against rendiff's, and the EXR their visibility-only render writes.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..contract import exrbuf
from ..contract.meshfile import file_uses
from ..contract.resolved import ResolvedScene
from ..judge.tolerance import DepthContext, DepthModel, render_param, shift_depth
from .errors import BackendSkipped

PLACEMENT_ATTR = "vertex_placement"
"""The EXR attribute (and info key) holding the render's vertex placement bound, world units."""


def original_file_uses(scene: ResolvedScene, backend: str) -> list[list[int]]:
    """The scene's file uses (contract/meshfile.file_uses); BackendSkipped with the reason when an
    object is not read from a mesh file, since `backend` has no original file to load for it."""
    uses = file_uses(scene)
    in_use = {i for use in uses for i in use}
    for i, obj in enumerate(scene.objects):
        if i not in in_use:
            raise BackendSkipped(
                f"{backend}: object {obj.get('name', '')!r} is not read from a mesh file (a generated shape or "
                "literal triangles): there is no original file to load"
            )
    return uses


def placement(attrs: Mapping[str, Any]) -> float:
    """The render's recorded vertex placement bound (0 when absent: compared as if exact)."""
    value = render_param(attrs, {}, PLACEMENT_ATTR)
    return value if value is not None and value >= 0.0 else 0.0


def placement_depth(ctx: DepthContext) -> tuple[np.ndarray, float]:
    """The depth term of the render's recorded vertex placement p, and p: every point of the scene
    may sit p from rendiff's, which moves a depth min(p / |cos|, depth span) (`shift_depth`)."""
    placed = placement(ctx.attrs)
    return shift_depth(ctx, np.full(ctx.z_ref.shape, placed)), placed


def placed_depth(base: DepthModel, placement_why: str) -> DepthModel:
    """The drawing backend's depth model `base` plus every point moved by the recorded vertex
    placement (`placement_depth`); `placement_why` says where that placement comes from."""

    def depth(ctx: DepthContext) -> tuple[np.ndarray, str]:
        tol, text = base(ctx)
        term, placed = placement_depth(ctx)
        return tol + term, f"{text} + min(p / |cos|, depth span), p = {placed:.3g} (vertex placement: {placement_why})"

    return depth


def write_visibility(
    out_exr: Path, buffers: Mapping[str, np.ndarray], info: dict[str, Any], attrs: Mapping[str, exrbuf.AttrValue]
) -> dict[str, object]:
    """Write a render's Z, id.prim, id.object and N (never RGB) with `attrs` to `out_exr`; `info`
    gains the write's time and says the render was visibility-only, and is returned."""
    t0 = time.perf_counter()
    exrbuf.write_buffers(out_exr, Z=buffers["Z"], prim=buffers["prim"], obj=buffers["obj"], N=buffers["N"], attrs=attrs)
    info["timings_s"]["write"] = time.perf_counter() - t0
    info["visibility_only"] = True
    return info


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
