"""Mitsuba 3 as a depth + triangle-ID + geometric-normal backend (the `aov` integrator).

Conventions and their translation (external-renderers notes, re-verified by the tests):

* One `mi.Mesh` holds every triangle with unshared vertices, in prim_id order, so the
  `prim_index` AOV *is* the global prim_id. The film stores it as float32, exact below
  2^24; larger scenes are refused.
* Camera: `perspective` sensor, `fov_axis: 'y'`, fov = 2 atan(tan_half_vfov) in degrees,
  `to_world = look_at(eye, eye + forward, up_ortho)`. Mitsuba's film has row 0 at the top
  and x to the right, as in DESIGN.md.
* Pixel centers: `stratified` sampler with `sample_count: 1, jitter: False` and a `box`
  reconstruction filter put the single sample at the pixel center with weight 1. Every
  other sampler jitters, even at 1 spp.
* Depth: camera rays start on the near plane, and the `depth` AOV is the ray distance
  from there, along the *normalized* direction. With DESIGN.md's unnormalized pixel
  direction d (forward component 1), cos(theta) = 1/|d|, so
  Z = depth / |d| + near_clip (done in float64). A miss writes depth 0 -> Z = +inf.
* Normals: `geo_normal` is Mitsuba's face normal normalize((b - a) x (c - a)), in world
  space, not flipped toward the viewer.
* No culling: ray intersection is two-sided; the `diffuse` BSDF is wrapped in `twosided`
  anyway so a later shading pass sees both sides alike.
"""

from __future__ import annotations

import math
import os
import time
from functools import lru_cache
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import BackendError, BackendUnavailable
from ..resolved import Camera, ResolvedScene

NAME = "mitsuba"
FEATURES = frozenset({"depth", "ids"})
BUFFERS = frozenset({"Z", "id", "N"})

BACKGROUND_ID = 0xFFFFFFFF
MAX_TRIANGLES = 1 << 24  # prim_index travels through a float32 film channel
DEFAULT_VARIANT = "scalar_rgb"
LLVM_VARIANT = "llvm_ad_rgb"
VARIANT_ENV = "RENDIFF_MITSUBA_VARIANT"
LLVM_PATH_ENV = "DRJIT_LIBLLVM_PATH"
FAR_FACTOR = 2.0
AOVS = "z:depth,pi:prim_index,ng:geo_normal"
# Measured |Z - float64 reference| / Z <= 6e-7 (f32 ray setup + intersection); 1e-5 leaves room
# for grazing angles, where the f32 ray-triangle t is known to lose more (notes: Embree 9e-6).
DEPTH_REL_TOLERANCE = 1e-5


def depth_tolerance(z: npt.ArrayLike, near: float | None = None, far: float | None = None) -> np.ndarray:
    """Allowed |Z_mitsuba - Z_reference| at depth z (relative; near/far only for a common signature)."""
    return DEPTH_REL_TOLERANCE * np.abs(np.asarray(z, dtype=np.float64))


# --------------------------------------------------------------------------- variant / import


def selected_variant() -> str:
    """scalar_rgb unless RENDIFF_MITSUBA_VARIANT=llvm_ad_rgb (needs DRJIT_LIBLLVM_PATH).

    llvm_ad_rgb aborts the whole process (SIGABRT in LLVM instruction selection) with
    Debian's libLLVM 15/16, so it is opt-in and requires an explicit libLLVM 19 path.
    """
    variant = os.environ.get(VARIANT_ENV, "").strip() or DEFAULT_VARIANT
    if variant not in (DEFAULT_VARIANT, LLVM_VARIANT):
        raise BackendUnavailable(
            f"{VARIANT_ENV}={variant!r} is not supported; use {DEFAULT_VARIANT} (default) or {LLVM_VARIANT}"
        )
    if variant == LLVM_VARIANT:
        lib = os.environ.get(LLVM_PATH_ENV, "")
        if not lib or not Path(lib).is_file():
            raise BackendUnavailable(
                f"{VARIANT_ENV}={LLVM_VARIANT} needs {LLVM_PATH_ENV} naming libLLVM 19 "
                "(apt-get install libllvm19; "
                f"{LLVM_PATH_ENV}=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1); "
                f"got {lib!r}. Older libLLVM aborts the process."
            )
    return variant


def _import_mitsuba() -> ModuleType:
    """Import mitsuba lazily, select the variant and silence its logging."""
    variant = selected_variant()
    try:
        import mitsuba as mi
    except Exception as exc:  # noqa: BLE001 - ImportError or a broken native library
        raise BackendUnavailable(
            f"cannot import mitsuba ({type(exc).__name__}: {exc}); "
            "pip install -r harness/requirements.txt (mitsuba==3.9.1, drjit==1.5.0)"
        ) from None
    if variant not in mi.variants():
        raise BackendUnavailable(f"this mitsuba build has no {variant} variant (has {mi.variants()})")
    try:
        mi.set_variant(variant)
    except Exception as exc:  # noqa: BLE001 - reported as one line, not a traceback
        raise BackendUnavailable(f"mitsuba cannot load variant {variant}: {exc}") from None
    mi.set_log_level(mi.LogLevel.Error)
    return mi


def version() -> str:
    """Mitsuba and Dr.Jit versions plus the variant: each changes the output bits."""
    try:
        mi = _import_mitsuba()
        import drjit
    except BackendUnavailable:
        return "mitsuba (not importable)"
    return f"mitsuba {getattr(mi, '__version__', '?')}, drjit {getattr(drjit, '__version__', '?')}, {mi.variant()}"


@lru_cache(maxsize=1)
def _probe() -> str | None:
    try:
        _import_mitsuba()
    except BackendUnavailable as exc:
        return str(exc)
    return None


def unavailable_reason() -> str | None:
    """None when mitsuba imports with the selected variant; else what to install or set."""
    return _probe()


# --------------------------------------------------------------------------- scene


def clip_range(scene: ResolvedScene) -> tuple[float, float]:
    """(near_clip, far_clip) for the sensor.

    near is the scene's. Mitsuba needs a finite far_clip (it builds a projection matrix
    from it), so an infinite far becomes 2 x the farthest vertex's planar depth: nothing
    lies beyond it, so visibility is unchanged. far_clip must also exceed near_clip.
    """
    cam = scene.camera
    near = float(cam.near)
    if math.isfinite(cam.far):
        far = float(cam.far)
    else:
        verts = scene.triangles.reshape(-1, 3).astype(np.float64)
        farthest = float(((verts - cam.eye) @ cam.forward).max()) if verts.size else 0.0
        far = FAR_FACTOR * farthest
    if not far > near:
        far = FAR_FACTOR * near if near > 0 else 1.0
    return near, far


def _to_buffer(template: Any, values: np.ndarray) -> Any:
    """Convert numpy data to the variant's dynamic array type (scalar or LLVM)."""
    return type(template)(values)


def build_mesh(mi: ModuleType, scene: ResolvedScene) -> Any:
    """One mesh of all triangles, unshared vertices, faces (3i, 3i+1, 3i+2) = prim i."""
    n = scene.triangle_count
    props = mi.Properties()
    props["bsdf"] = mi.load_dict({"type": "twosided", "bsdf": {"type": "diffuse"}})
    mesh = mi.Mesh("rendiff", 3 * n, n, props=props, has_vertex_normals=False)
    params = mi.traverse(mesh)
    positions = np.ascontiguousarray(scene.triangles, dtype=np.float32).ravel()
    faces = np.arange(3 * n, dtype=np.uint32)
    params["vertex_positions"] = _to_buffer(params["vertex_positions"], positions)
    params["faces"] = _to_buffer(params["faces"], faces)
    params.update()
    return mesh


def sensor_dict(mi: ModuleType, cam: Camera, near: float, far: float) -> dict[str, Any]:
    """Pinhole sensor sampling exactly the pixel centers, one sample each."""
    fov_deg = math.degrees(2.0 * math.atan(cam.tan_half_vfov))
    to_world = mi.ScalarTransform4f().look_at(
        origin=[float(v) for v in cam.eye],
        target=[float(v) for v in cam.eye + cam.forward],
        up=[float(v) for v in cam.up_ortho],
    )
    return {
        "type": "perspective",
        "fov_axis": "y",
        "fov": fov_deg,
        "near_clip": near,
        "far_clip": far,
        "to_world": to_world,
        "film": {
            "type": "hdrfilm",
            "width": cam.width,
            "height": cam.height,
            "rfilter": {"type": "box"},
            "pixel_format": "rgb",
            "component_format": "float32",
        },
        "sampler": {"type": "stratified", "sample_count": 1, "jitter": False},
    }


def build_scene(mi: ModuleType, scene: ResolvedScene, near: float, far: float) -> Any:
    """Mitsuba scene: AOV integrator, pixel-center sensor, one mesh (none if empty)."""
    desc: dict[str, Any] = {
        "type": "scene",
        "integrator": {"type": "aov", "aovs": AOVS},
        "sensor": sensor_dict(mi, scene.camera, near, far),
    }
    if scene.triangle_count:
        desc["mesh"] = build_mesh(mi, scene)
    try:
        return mi.load_dict(desc)
    except Exception as exc:  # noqa: BLE001 - mitsuba raises plain Exception/RuntimeError
        raise BackendError(f"mitsuba rejected the scene: {type(exc).__name__}: {exc}") from None


# --------------------------------------------------------------------------- conversion


def _channels(mi_scene: Any, image: np.ndarray) -> dict[str, np.ndarray]:
    """Split the rendered tensor by AOV channel name ('z.T', 'pi.I', 'ng.X', ...)."""
    names = list(mi_scene.integrator().aov_names())
    if image.ndim != 3 or image.shape[2] != len(names):
        raise BackendError(f"mitsuba returned {image.shape}, expected channels {names}")
    return {name: image[:, :, i] for i, name in enumerate(names)}


def planar_depth(depth: np.ndarray, cam: Camera, near: float) -> np.ndarray:
    """Z (float32, +inf for misses) from Mitsuba's near-plane ray distance, in float64."""
    norm = np.linalg.norm(cam.pixel_directions(), axis=-1)
    hit = depth > 0.0
    z = depth.astype(np.float64) / norm + near
    return np.where(hit, z, np.inf).astype(np.float32)


def prim_ids(prim_index: np.ndarray, hit: np.ndarray, count: int) -> np.ndarray:
    """uint32 prim_id from the float32 channel; background -> 0xFFFFFFFF."""
    prim = np.full(prim_index.shape, BACKGROUND_ID, dtype=np.uint32)
    values = prim_index[hit]
    if values.size and (np.any(values != np.round(values)) or values.min() < 0 or values.max() >= count):
        raise BackendError("mitsuba's prim_index AOV holds values that are no triangle index")
    prim[hit] = values.astype(np.uint32)
    return prim


def render_arrays(scene: ResolvedScene) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Render and convert to rendiff buffers: ({'Z','prim','obj','N'}, info)."""
    n = scene.triangle_count
    if n > MAX_TRIANGLES:
        raise BackendError(
            f"mitsuba's prim_index AOV is float32, exact only below 2^24: {n} triangles exceed {MAX_TRIANGLES}"
        )
    mi = _import_mitsuba()
    cam = scene.camera
    near, far = clip_range(scene)
    t0 = time.perf_counter()
    mi_scene = build_scene(mi, scene, near, far)
    t1 = time.perf_counter()
    try:
        image = np.array(mi.render(mi_scene, spp=1), dtype=np.float32)
    except Exception as exc:  # noqa: BLE001 - reported as one line, not a traceback
        raise BackendError(f"mitsuba failed to render: {type(exc).__name__}: {exc}") from None
    t2 = time.perf_counter()
    if image.shape[:2] != (cam.height, cam.width):
        raise BackendError(
            f"mitsuba returned {image.shape[1]}x{image.shape[0]}, expected {cam.width}x{cam.height}"
        )
    ch = _channels(mi_scene, image)
    hit = ch["z.T"] > 0.0
    prim = prim_ids(ch["pi.I"], hit, n)
    obj = np.full(prim.shape, BACKGROUND_ID, dtype=np.uint32)
    obj[hit] = scene.object_ids[prim[hit]]
    normals = np.stack([ch["ng.X"], ch["ng.Y"], ch["ng.Z"]], axis=-1)
    normals[~hit] = 0.0
    buffers = {"Z": planar_depth(ch["z.T"], cam, near), "prim": prim, "obj": obj, "N": normals}
    t3 = time.perf_counter()
    info: dict[str, Any] = {
        "variant": mi.variant(),
        "integrator": f"aov({AOVS})",
        "sampler": "stratified, 1 spp, no jitter (pixel centers)",
        "rfilter": "box",
        "near_clip": near,
        "far_clip": far,
        "depth_model": {"kind": "float32_ray_distance", "rel_tolerance": DEPTH_REL_TOLERANCE},
        "timings_s": {"build": t1 - t0, "render": t2 - t1, "decode": t3 - t2},
    }
    return buffers, info


def render(scene: ResolvedScene, out_exr: Path, workdir: Path, timeout_s: float) -> dict[str, object]:
    """Render `scene` into `out_exr` (Z, id.prim, id.object, N); returns settings and timings.

    In-process (the caller enforces `timeout_s`); `workdir` is unused.
    """
    from .. import exrbuf

    buffers, info = render_arrays(scene)
    t0 = time.perf_counter()
    attrs: dict[str, str | float | int] = {
        "backend": NAME,
        "variant": str(info["variant"]),
        "near_clip": float(info["near_clip"]),
        "far_clip": float(info["far_clip"]),
    }
    exrbuf.write_buffers(
        out_exr, Z=buffers["Z"], prim=buffers["prim"], obj=buffers["obj"], N=buffers["N"], attrs=attrs
    )
    info["timings_s"]["write"] = time.perf_counter() - t0
    return info
