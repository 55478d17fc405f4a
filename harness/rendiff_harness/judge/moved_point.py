"""The RGB tolerance's geometric term: how much the direct light may change at a shading point that
the renderer's own arithmetic moved (docs/verifier.md, "Radiance: the moved shading point").

Why: a backend's deterministic RGB tolerance (its spec's `rgb_tolerance`) sees the reference values
only, and allows for its output's quantization and its colour arithmetic. Far from the origin a
renderer's geometry arithmetic moves the point it shades by far more than that: POV-Ray's f32 mesh
plane put the point of the `translate` variant of scenes/two_lights_shadowless.toml (|X| = 1774)
1.1e-4 off along its pixel ray, which changed the light from a point 1.9 away by 9e-5 relative,
beyond its 1e-5 (scenes/fuzz_povray_far_light.toml keeps it). The move is the backend's own, derived
from its arithmetic beside its other models and seen through each pixel's geometry; the term is
proportional to it, so it shrinks with the scene's distance from the origin like the move does.

Which backends: those whose spec gives an `rgb_moved_point` (`tolerance.ShadingMove`): the backend's own
move of its shading point, derived in its backend module from its arithmetic (POV-Ray: its f32 plane,
along the ray; Mitsuba: Embree's f32 hit and its f32 barycentric interpolation; pyrender: its f32 view
transform and interpolated position), and whether it rounds its point lights to f32. A
scene without point lights gets no term: moving the point changes neither a directional light's n.l
nor emission.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..contract import lighting
from ..contract.manifest import Reference
from ..contract.vocab import BACKGROUND_ID
from ..renderers.spec import BackendSpec
from . import tolerance
from .depth import depth_context

F64_U = 2.0**-53


def f32_move(position: np.ndarray) -> float:
    """|f32(L) - L|: how far a renderer that stores a light's position in f32 puts it."""
    exact = np.asarray(position, dtype=np.float64)
    return float(np.linalg.norm(exact.astype(np.float32).astype(np.float64) - exact))


def point_light_change(
    x: np.ndarray,
    n: np.ndarray,
    rho: np.ndarray,
    lights: list[tuple[np.ndarray, np.ndarray]],
    delta: np.ndarray,
    eps: np.ndarray,
    light_moves: Sequence[float] | None = None,
) -> np.ndarray:
    """(K, 3) bound on |L(X') - L(X)| of the point lights' direct term for |X' - X| <= delta.

    x (K, 3): the reference's shading point as the judge reconstructs it, within eps (K,) of the
    one the reference shaded; n (K, 3) the unit normals it shades with (turned toward the viewer
    when two-sided; zero for a back-facing hit of a one-sided scene, which is black wherever the
    point moves along its ray); rho (K, 3) albedo; lights [(position, intensity)]. Per light, with
    r the distance to the light and c = n.w (w the unit vector to it), the term is
    rho/pi I max(0, c)/r^2, and a move by delta gives

        |d(1/r^2)| <= 1/(r - delta)^2 - 1/r^2          (r' >= r - delta; the far side changes less)
        |w' - w|   <= 2 delta / (r + r') <= delta / (r - delta)  =: dc   (Dunkl-Williams)
        |d term|   <= rho/pi I [ dc / (r - delta)^2 + max(0, c) (1/(r - delta)^2 - 1/r^2) ]

    (max(0, .) is 1-Lipschitz, so |dmax(0, c)| <= |n.(w' - w)| <= dc; the first part is that
    over the moved 1/r'^2, the second the change of 1/r^2 at the old cosine), and 0 when
    c + dc <= 0 (the light stays behind the surface: no light before or after). Evaluated at the
    reconstructed point: r is lowered by eps and c raised by eps/r, which only enlarges the bound.
    Where the move may reach the light (r <= delta) the bound is infinite. Summed over the lights.
    `light_moves`: how far the renderer put each light (|f32(L) - L|); only X - L enters the term, so a
    light moved by l is the point moved by l more (delta + l for that light).
    """
    out = np.zeros((x.shape[0], 3))
    moves = [0.0] * len(lights) if light_moves is None else list(light_moves)
    for (pos, intensity), light_move in zip(lights, moves, strict=True):
        to_l = pos[None, :] - x
        r0 = np.linalg.norm(to_l, axis=1)
        r = r0 - eps
        with np.errstate(all="ignore"):
            c = np.einsum("ij,ij->i", n, to_l) / r0 + eps / r
            move = delta + light_move
            near = r - move
            dc = move / near
            change = dc / near**2 + np.maximum(c, 0.0) * (1.0 / near**2 - 1.0 / r**2)
        change = np.where((r > 0) & (near > 0) & np.isfinite(change), change, np.inf)
        change = np.where((r > 0) & (near > 0) & (c + dc <= 0.0), 0.0, change)
        out += rho * (intensity[None, :] / math.pi) * change[:, None]
    return out


def moved_point_tolerance(
    ref: Reference, spec: BackendSpec | None, render: Mapping[str, Any], attrs: Mapping[str, Any]
) -> tuple[np.ndarray, str] | None:
    """(H, W, 3) absolute RGB tolerance to add for the moved shading point, and its sentence; None
    when it does not apply (the backend has no such model, or the scene no point light).

    Each pixel the reference hits: its point X = eye + Z d from the reference's f32 depth (within
    eps = 2^-24 Z|d| + 4 2^-53 (|eye| + Z|d|) of the point it shaded), its triangle's normal and
    albedo, the backend's move (`spec.rgb_moved_point.point`) and its lights' f32 move, and
    `point_light_change`. Raises ToleranceError
    when the reference has no Z or id.prim to place the points with.
    """
    if spec is None or spec.rgb_moved_point is None:
        return None
    model = spec.rgb_moved_point
    scene = ref.scene
    if "lambert" not in scene.requires:
        return None
    points, _ = lighting.lights_of(scene)
    if not points:
        return None
    prim, z = ref.buffers.get("id.prim"), ref.buffers.get("Z")
    if prim is None or z is None:
        raise tolerance.ToleranceError(
            f"{spec.name}'s RGB tolerance needs the reference's Z and id.prim (the points it shades)"
        )
    hit = (prim != BACKGROUND_ID) & (prim.astype(np.uint64) < np.uint64(scene.triangle_count)) & np.isfinite(z)
    rows, cols = np.nonzero(hit)
    out = np.zeros((*prim.shape, 3))
    if rows.size == 0:
        return out, "; + moved shading point (no pixel hit)"
    prims = prim[rows, cols].astype(np.int64)
    z_ref = z[rows, cols].astype(np.float64)
    ctx = depth_context(ref, rows, cols, z_ref, prims, render, attrs)
    tris = scene.triangles[prims].astype(np.float64)
    delta = model.point(ctx, np.linalg.norm(tris, axis=2).max(axis=1))
    cam = scene.camera
    d = cam.center_directions(rows, cols)
    along = np.abs(z_ref) * np.linalg.norm(d, axis=1)
    x = cam.eye[None, :] + z_ref[:, None] * d
    eps = tolerance.F32_U * along + 4.0 * F64_U * (float(np.linalg.norm(cam.eye)) + along)
    n = lighting.face_normals(tris)
    front = np.einsum("ij,ij->i", n, d) < 0.0
    if "two_sided" in scene.requires:
        n = np.where(front[:, None], n, -n)
    else:
        n = np.where(front[:, None], n, 0.0)
    albedo, _ = scene.material_arrays()
    rho = albedo[scene.prim_materials()[prims]]
    light_moves = [f32_move(pos) if model.f32_lights else 0.0 for pos, _ in points]
    out[rows, cols] = point_light_change(x, n, rho, points, delta, eps, light_moves)
    text = (
        "; + moved shading point: sum over point lights "
        "rho/pi I [delta/(r-delta)^3 + max(0, n.w) (1/(r-delta)^2 - 1/r^2)], "
        f"delta = {model.text} (delta <= {float(np.max(delta)):.3g} here)"
    )
    if model.f32_lights:
        text += f", + |f32(L) - L| per light (<= {max(light_moves):.3g})"
    return out, text
