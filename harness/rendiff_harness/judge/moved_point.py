"""The RGB tolerance's geometric term: how much the direct light may change at a shading point that
the renderer's own arithmetic moved (docs/verifier.md, "Radiance: the moved shading point").

Why: a backend's deterministic RGB tolerance (its spec's `rgb_tolerance`) sees the reference values
only, and allows for its output's quantization and its colour arithmetic. Far from the origin a
renderer's geometry arithmetic moves the point it shades by far more than that: POV-Ray's f32 mesh
plane put the point of the `translate` variant of scenes/two_lights_shadowless.toml (|X| = 1774)
1.1e-4 off along its pixel ray, which changed the light from a point 1.9 away by 9e-5 relative,
beyond its 1e-5 (scenes/fuzz_povray_far_light.toml keeps it). The move is the backend's own position
model (`Model.position`, its one home), seen through each pixel's geometry; the term is
proportional to it, so it shrinks with the scene's distance from the origin like the move does.

Which backends: those whose spec says `rgb_moved_point` (their lights are placed exactly and their
shading point is the hit the position model moves). A scene without point lights gets no term:
moving the point changes neither a directional light's n.l nor emission.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..contract import lighting
from ..contract.manifest import Reference
from ..contract.vocab import BACKGROUND_ID
from ..renderers.spec import BackendSpec
from . import tolerance
from .depth import depth_context

F64_U = 2.0**-53


def moved_distance(ctx: tolerance.DepthContext, position: tolerance.PositionError, farthest: np.ndarray) -> np.ndarray:
    """(K,) how far the renderer may move each pixel's shading point, world units.

    The position model m(|P|) bounds how far the renderer moves the surface relative to its ray
    for a point |P| from the origin, and grows with |P|. It is taken at the triangle's farthest
    vertex (`farthest`, (K,) max |v|): no point of the triangle is farther (the norm is convex),
    and POV-Ray's plane error, which also rounds the offset through a vertex P1, is within
    u (2|X| + |P1|) <= 3u max|v| = its m there. The hit stays on the pixel ray: the depth models'
    `shift_depth` bounds its planar depth's move by min(m/|cos|, the triangle's depth span), and
    along the ray d (unit planar depth) the point moves |d| times that.
    """
    m = position(ctx.origin_offset, ctx.eye_norm, farthest)
    ray = np.asarray(ctx.ray_norm if ctx.ray_norm is not None else 1.0, dtype=np.float64)
    moved: np.ndarray = ray * tolerance.shift_depth(ctx, m)
    return moved


def point_light_change(
    x: np.ndarray,
    n: np.ndarray,
    rho: np.ndarray,
    lights: list[tuple[np.ndarray, np.ndarray]],
    delta: np.ndarray,
    eps: np.ndarray,
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
    """
    out = np.zeros((x.shape[0], 3))
    for pos, intensity in lights:
        to_l = pos[None, :] - x
        r0 = np.linalg.norm(to_l, axis=1)
        r = r0 - eps
        with np.errstate(all="ignore"):
            c = np.einsum("ij,ij->i", n, to_l) / r0 + eps / r
            near = r - delta
            dc = delta / near
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
    albedo, the backend's move `moved_distance`, and `point_light_change`. Raises ToleranceError
    when the reference has no Z or id.prim to place the points with.
    """
    if spec is None or not spec.rgb_moved_point or spec.precision.position is None:
        return None
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
    delta = moved_distance(ctx, spec.precision.position, np.linalg.norm(tris, axis=2).max(axis=1))
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
    out[rows, cols] = point_light_change(x, n, rho, points, delta, eps)
    text = (
        "; + moved shading point: sum over point lights "
        "rho/pi I [delta/(r-delta)^3 + max(0, n.w) (1/(r-delta)^2 - 1/r^2)], "
        "delta = |d| min(m/|cos|, depth span), m = its position error at the triangle's farthest vertex "
        f"(delta <= {float(np.max(delta)):.3g} here)"
    )
    return out, text
