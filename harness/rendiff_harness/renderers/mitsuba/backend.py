"""Mitsuba 3 as a depth + triangle-ID + geometric-normal backend (the `aov` integrator).

Conventions and their translation (external-renderers notes, re-verified by the tests):

* One `mi.Mesh` holds every triangle with unshared vertices, in prim_id order, so the
  `prim_index` AOV *is* the global prim_id. The film stores it as float32, exact below
  2^24; larger scenes are refused.
* Camera: `perspective` sensor, `fov_axis: 'y'`, fov = 2 atan(tan_half_vfov) in degrees,
  and `to_world` the camera-to-world matrix built in float64 from the resolved basis
  (`camera_to_world`): columns (-right, up_ortho, forward, eye), because Mitsuba's camera
  looks along its +z with +x to the *left* (its own `look_at` puts
  normalize(cross(up, dir)) = -right there), passed whole with its float64 inverse
  transpose. Mitsuba rounds each entry to float32 once. Its `look_at(origin, target, up)`
  is evaluated in float32 instead: `target - origin` with target = eye + forward loses
  about one float32 step of |eye|, which turned the camera by ~ulp(|eye|) radians
  (measured on the calibration probe camera_far, 2.5e4 from the origin: turned by
  5e-4 rad, pixel centers offset by (0.036, 0.014) px, 37 times Mitsuba's own rounding;
  now (4e-6, -3e-6) px; docs/calibration.md). Mitsuba's film has row 0 at the top and x to the
  right, as in docs/DESIGN.md.
* Pixel centers: `stratified` sampler with `sample_count: 1, jitter: False` and a `box`
  reconstruction filter put the single sample at the pixel center with weight 1. Every
  other sampler jitters, even at 1 spp.
* Depth: camera rays start on the near plane, and the `depth` AOV is the ray distance
  from there, along the *normalized* direction. With docs/DESIGN.md's unnormalized pixel
  direction d (forward component 1), cos(theta) = 1/|d|, so
  Z = depth / |d| + near_clip (done in float64). A miss writes depth 0 -> Z = +inf.
* Normals: `geo_normal` is Mitsuba's face normal normalize((b - a) x (c - a)), in world
  space, not flipped toward the viewer.
* No culling: ray intersection is two-sided; the `diffuse` BSDF is wrapped in `twosided`
  anyway (the AOV pass does no shading).

Radiance (docs/radiance.md), rendered in separate passes after the AOV pass
---------------------------------------------------------------------------
Shapes: one `mi.Mesh` per material (the objects' materials, `lighting.group_by_material`),
so that the AOV pass keeps its one global-prim-id mesh while radiance passes carry
per-material BSDFs and emitters. Unit mapping, exactly as built (`radiance_shapes`,
`light_dicts`), every value an `rgb` spectrum used as is by the RGB variants:

* albedo rho -> `diffuse` with `reflectance` rho, which evaluates rho/pi * cos (so no
  conversion). `one_sided`: plain `diffuse` (Mitsuba's diffuse is black seen from the
  back, exactly the contract's one-sided rule); `two_sided`: wrapped in `twosided`.
* emission Le -> an `area` emitter with `radiance` Le on the material's mesh. Mitsuba's
  area emitter is one-sided (front = (b-a)x(c-a), counter-clockwise seen from the
  front: the contract's front). With `two_sided`, a second mesh of the same triangles,
  flipped (winding reversed) and moved back along their normals by
  TWO_SIDED_EMITTER_OFFSET_REL (1e-5) x scene size, carries a second `area` emitter and
  the same BSDF: from the front a ray meets the original (which emits forward), from
  the back it meets the copy (which emits backward). The copy cannot coincide exactly:
  two coincident surfaces at equal t are hit in an arbitrary order, and half the
  emission would be lost. The offset moves the back side's emission by 1e-5 of the
  scene: far below Monte Carlo noise, and the AOV pass (depth, IDs) does not see it.
* point light (I, W/sr) -> `point` with `intensity` I: L = rho/pi I cos/r^2.
* directional light (E, travelling along dir) -> `directional` with `irradiance` E
  and `direction` dir normalized: L = rho/pi E max(0, n.(-dir)).
* Mitsuba always traces shadow rays: `shadows` yes, `shadowless` no.

Integrators:

* Local shading (no `global_illumination`): deterministic, the same pixel-center
  sensor as the AOV pass (`stratified`, 1 spp, no jitter, box filter). `direct`
  samples one emitter per sample *at random* when there are several, so each light is
  rendered in its own pass (`direct`, emitter_samples 1, bsdf_samples 0: a single delta
  light is then sampled with probability 1) and the passes are summed in float64;
  directly seen emission comes from one more pass with `path`, max_depth 1 and the area
  emitters (no light reaches other surfaces from emitters in local shading: the contract
  has no area lights there). Attributes: rendiff:integrator = "direct", rendiff:spp = 1.
* `global_illumination`: `path` (max_depth from the scene's integrator.max_depth,
  Mitsuba's own convention; Russian roulette from depth 5: unbiased), `independent`
  sampler, box filter (the pixel's box integral), every emitter and light in one scene.
  N spp are rendered as K = min(N, VARIANCE_PASSES = 64) independent passes of
  ceil(N/K) spp with seeds seed*K + k; R,G,B is the mean of the K pass means and
  var.R/G/B is their sample variance / K (the variance of that mean, docs/radiance.md).
  K = 64 gives the variance 63 degrees of freedom, enough for the comparison's t tails
  to be close to normal at the Sidak-corrected levels (with K = 8 the Student-t tails at
  7 dof make the per-pixel test far weaker); at N <= 64 every pass is one sample, i.e.
  the per-sample variance, as the core computes it. The extra render calls cost ~15%
  (64 x 64 Cornell box, 64 spp, scalar_rgb: 0.89 s for 64 x 1 spp vs 0.78 s for 1 x 64). Attributes: rendiff:spp
  (N actually rendered), rendiff:seed, rendiff:integrator = "path", rendiff:passes = K,
  rendiff:var_samples = K (the variance is estimated from K values: the statistical
  comparison uses K - 1 degrees of freedom for it).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Mapping
from functools import lru_cache
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import numpy.typing as npt

from ...contract import vocab
from ...contract.camera import Camera
from ...contract.resolved import ResolvedScene
from ...contract.vocab import BACKGROUND_ID, Buffer, Feature
from ...judge.camera_budget import (
    RAY_TRIANGLE_ROUNDINGS,
    ErrorBudget,
    ProbePixels,
    f32_origin_error,
    probe_param,
)
from ...judge.tolerance import (
    F32_U,
    MAX_REL,
    MOELLER_TEXT,
    DepthContext,
    Model,
    RgbTolerance,
    ShadingMove,
    ToleranceError,
    embree_barycentric_move,
    f32_ray_depth,
    in_plane_move,
    moeller_t_depth,
    position_edge,
    position_error,
    relative_grazing,
    shift_depth,
)
from ..errors import BackendError, BackendSkipped, BackendUnavailable
from ..spec import DIRECT_LIGHT_FEATURES, BackendSpec

NAME = "mitsuba"
FEATURES = DIRECT_LIGHT_FEATURES | {
    Feature.SHADOWS,
    Feature.AREA_LIGHT,
    Feature.GLOBAL_ILLUMINATION,
    Feature.TWO_SIDED,
    Feature.ONE_SIDED,
}
BUFFERS = frozenset({Buffer.Z, Buffer.ID, Buffer.N, Buffer.RGB})
PEAK_MEMORY = (120 * 2**20, 250)
"""`BackendSpec.peak_memory`: 108 MiB on three_triangles and 382 MiB on `million` (1,310,722
triangles: 219 B per triangle)."""
VARIANCE_PASSES = 64
TWO_SIDED_EMITTER_OFFSET_REL = 1e-5
DEFAULT_SEED = 0

MAX_TRIANGLES = 1 << 24  # prim_index travels through a float32 film channel
DEFAULT_VARIANT = "scalar_rgb"
LLVM_VARIANT = "llvm_ad_rgb"
VARIANT_ENV = "RENDIFF_MITSUBA_VARIANT"
LLVM_PATH_ENV = "DRJIT_LIBLLVM_PATH"
# Where Debian's libllvm19 (installed by scripts/setup.sh) puts the library llvm_ad_rgb needs;
# used when DRJIT_LIBLLVM_PATH is unset, so Mitsuba's fast CPU variant works without set-up.
DEBIAN_LIBLLVM19 = Path("/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1")
FAR_FACTOR = 2.0
AOVS = "z:depth,pi:prim_index,ng:geo_normal"
DEPTH_REL_TOLERANCE = 1e-5
"""Relative depth precision (the one number; `mitsuba_depth` and the render's info use it): measured
|Z - float64 reference| / Z <= 6e-7 (f32 ray setup + intersection); 1e-5 leaves room for grazing
angles, where the f32 ray-triangle t is known to lose more (notes: Embree 9e-6)."""


def depth_tolerance(z: npt.ArrayLike, near: float | None = None, far: float | None = None) -> np.ndarray:
    """Allowed |Z_mitsuba - Z_reference| at depth z (relative; near/far only for a common signature)."""
    return DEPTH_REL_TOLERANCE * np.abs(np.asarray(z, dtype=np.float64))


# --------------------------------------------------------------------------- variant / import


def selected_variant() -> str:
    """scalar_rgb unless RENDIFF_MITSUBA_VARIANT=llvm_ad_rgb (needs libLLVM 19).

    llvm_ad_rgb aborts the whole process (SIGABRT in LLVM instruction selection) with
    Debian's libLLVM 15/16, which drjit may find first, so it is opt-in and runs only with
    libLLVM 19: DRJIT_LIBLLVM_PATH, else Debian's libllvm19 (set in the environment here,
    before drjit is imported, which reads it then).
    """
    variant = os.environ.get(VARIANT_ENV, "").strip() or DEFAULT_VARIANT
    if variant not in (DEFAULT_VARIANT, LLVM_VARIANT):
        raise BackendUnavailable(
            f"{VARIANT_ENV}={variant!r} is not supported; use {DEFAULT_VARIANT} (default) or {LLVM_VARIANT}"
        )
    if variant == LLVM_VARIANT:
        lib = os.environ.get(LLVM_PATH_ENV, "")
        if not lib and DEBIAN_LIBLLVM19.is_file():
            lib = os.environ[LLVM_PATH_ENV] = str(DEBIAN_LIBLLVM19)
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


F32_MAX = float(np.finfo(np.float32).max)
F32_TINY = float(np.finfo(np.float32).tiny)


def clip_range(scene: ResolvedScene) -> tuple[float, float]:
    """(near_clip, far_clip) for the sensor.

    near is the scene's. Mitsuba needs a finite far_clip (it builds a projection matrix
    from it), so an infinite far becomes 2 x the farthest vertex's planar depth: nothing
    lies beyond it, so visibility is unchanged. So does a finite far beyond that: Mitsuba
    keeps clip distances in float32, and a far of 1e39 (or 1e308) overflowed to inf and
    rendered a blank image reported as ok. far_clip must also exceed near_clip. A range
    float32 still cannot hold (a near below its smallest normal, geometry past its largest
    value) is declined (skipped, with the reason): Mitsuba rejected such a near as an error.
    """
    cam = scene.camera
    near = float(cam.near)
    verts = scene.triangles.reshape(-1, 3).astype(np.float64)
    farthest = float(((verts - cam.eye) @ cam.forward).max()) if verts.size else 0.0
    if math.isfinite(cam.far) and cam.far <= FAR_FACTOR * farthest:
        far = float(cam.far)
    else:
        far = FAR_FACTOR * farthest
    if not far > near:
        far = FAR_FACTOR * near if near > 0 else 1.0
    if not (near >= F32_TINY and far <= F32_MAX):
        raise BackendSkipped(f"{NAME}: clip range [{near:g}, {far:g}] is beyond float32, in which Mitsuba keeps it")
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


def camera_to_world(cam: Camera) -> np.ndarray:
    """Mitsuba's camera-to-world matrix (4x4 float64) for the docs/DESIGN.md camera.

    Mitsuba's camera space looks along +z with +y up and +x to the *left* of the image
    (its `look_at` uses normalize(cross(up, dir)), i.e. -right), so the columns are
    (-right, up_ortho, forward, eye), all taken from the resolved scene's float64 basis.
    """
    m = np.eye(4, dtype=np.float64)
    m[:3, 0] = -np.asarray(cam.right, dtype=np.float64)
    m[:3, 1] = np.asarray(cam.up_ortho, dtype=np.float64)
    m[:3, 2] = np.asarray(cam.forward, dtype=np.float64)
    m[:3, 3] = np.asarray(cam.eye, dtype=np.float64)
    return m


def world_to_camera(cam: Camera) -> np.ndarray:
    """The inverse of `camera_to_world`, in float64 (the basis is orthonormal: R^T, -R^T eye)."""
    m = camera_to_world(cam)
    inv = np.eye(4, dtype=np.float64)
    inv[:3, :3] = m[:3, :3].T
    inv[:3, 3] = -(m[:3, :3].T @ m[:3, 3])
    return inv


def sensor_to_world(mi: ModuleType, cam: Camera) -> Any:
    """The sensor's `to_world`: `camera_to_world` passed whole (Mitsuba rounds each entry to
    float32 once), with its float64 inverse transpose so that Mitsuba inverts nothing."""
    matrix = camera_to_world(cam)
    inverse_transpose = world_to_camera(cam).T
    return mi.ScalarTransform4f(mi.ScalarMatrix4f(matrix.tolist()), mi.ScalarMatrix4f(inverse_transpose.tolist()))


def sensor_dict(mi: ModuleType, cam: Camera, near: float, far: float) -> dict[str, Any]:
    """Pinhole sensor sampling exactly the pixel centers, one sample each."""
    fov_deg = math.degrees(2.0 * math.atan(cam.tan_half_vfov))
    to_world = sensor_to_world(mi, cam)
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
        raise BackendError(f"mitsuba returned {image.shape[1]}x{image.shape[0]}, expected {cam.width}x{cam.height}")
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


# --------------------------------------------------------------------------- radiance


def is_shaded(scene: ResolvedScene) -> bool:
    return vocab.needs_shading(scene.requires)


def _rgb(value: np.ndarray) -> dict[str, Any]:
    return {"type": "rgb", "value": [float(v) for v in value]}


def _bsdf(mi: ModuleType, albedo: np.ndarray, two_sided: bool) -> Any:
    diffuse = {"type": "diffuse", "reflectance": _rgb(albedo)}
    return mi.load_dict({"type": "twosided", "bsdf": diffuse} if two_sided else diffuse)


def _tri_mesh(mi: ModuleType, name: str, tris: np.ndarray, bsdf: Any, emitter: Any | None) -> Any:
    n = int(tris.shape[0])
    props = mi.Properties()
    props["bsdf"] = bsdf
    if emitter is not None:
        props["emitter"] = emitter
    mesh = mi.Mesh(name, 3 * n, n, props=props, has_vertex_normals=False)
    params = mi.traverse(mesh)
    params["vertex_positions"] = _to_buffer(
        params["vertex_positions"], np.ascontiguousarray(tris, dtype=np.float32).ravel()
    )
    params["faces"] = _to_buffer(params["faces"], np.arange(3 * n, dtype=np.uint32))
    params.update()
    return mesh


def radiance_shapes(mi: ModuleType, scene: ResolvedScene, emitters: bool) -> dict[str, Any]:
    """Per-material meshes (keys sorted = material order), plus flipped emitter copies when two-sided."""
    from ...contract import lighting

    two_sided = "two_sided" in scene.requires
    albedo, emission = scene.material_arrays()
    emit = emitters and "emission" in scene.requires
    offset = TWO_SIDED_EMITTER_OFFSET_REL * lighting.scene_size(scene)
    normals = lighting.face_normals(scene.triangles)
    shapes: dict[str, Any] = {}
    for m, prims in lighting.group_by_material(scene):
        tris = scene.triangles[prims]
        le = emission[m]
        glows = emit and bool(np.any(le > 0))
        emitter = mi.load_dict({"type": "area", "radiance": _rgb(le)}) if glows else None
        shapes[f"mat{m:07d}"] = _tri_mesh(mi, f"mat{m}", tris, _bsdf(mi, albedo[m], two_sided), emitter)
        if glows and two_sided:
            keep = np.any(normals[prims] != 0, axis=1)  # degenerate triangles emit nothing anyway
            back = tris[keep][:, [0, 2, 1]].astype(np.float64) - offset * normals[prims][keep][:, None, :]
            if back.shape[0]:
                shapes[f"mat{m:07d}back"] = _tri_mesh(
                    mi,
                    f"mat{m}back",
                    back.astype(np.float32),
                    _bsdf(mi, albedo[m], True),
                    mi.load_dict({"type": "area", "radiance": _rgb(le)}),
                )
    return shapes


def light_dicts(scene: ResolvedScene) -> list[dict[str, Any]]:
    """Mitsuba emitter dicts of the scene's point and directional lights, in scene order."""
    from ...contract import lighting

    points, dirs = lighting.lights_of(scene)
    out: list[dict[str, Any]] = []
    for pos, intensity in points:
        out.append({"type": "point", "position": [float(v) for v in pos], "intensity": _rgb(intensity)})
    for direction, irradiance in dirs:
        out.append({"type": "directional", "direction": [float(v) for v in direction], "irradiance": _rgb(irradiance)})
    return out


def _radiance_scene(
    mi: ModuleType,
    scene: ResolvedScene,
    near: float,
    far: float,
    integrator: dict[str, Any],
    sampler: dict[str, Any],
    shapes: dict[str, Any],
    lights: list[dict[str, Any]],
) -> Any:
    sensor = sensor_dict(mi, scene.camera, near, far)
    sensor["sampler"] = sampler
    desc: dict[str, Any] = {"type": "scene", "integrator": integrator, "sensor": sensor}
    desc.update(shapes)
    for i, light in enumerate(lights):
        desc[f"light{i:07d}"] = light
    try:
        return mi.load_dict(desc)
    except Exception as exc:  # noqa: BLE001
        raise BackendError(f"mitsuba rejected the radiance scene: {type(exc).__name__}: {exc}") from None


def _render_rgb(mi: ModuleType, mi_scene: Any, spp: int, seed: int) -> np.ndarray:
    try:
        image = np.array(mi.render(mi_scene, spp=spp, seed=seed), dtype=np.float64)
    except Exception as exc:  # noqa: BLE001
        raise BackendError(f"mitsuba failed to render radiance: {type(exc).__name__}: {exc}") from None
    return image[:, :, :3]


def render_radiance(
    scene: ResolvedScene,
    spp: int | None = None,
    seed: int | None = None,
    passes: int = VARIANCE_PASSES,
    max_depth: int | None = None,
) -> tuple[np.ndarray, np.ndarray | None, dict[str, Any]]:
    """(RGB (H, W, 3) float64, variance of the mean or None, info) as the module docstring says.

    `max_depth` overrides the scene's path length limit (a speed/accuracy knob: shorter
    paths are faster and biased dark); it applies to `global_illumination` only.
    """
    if max_depth is not None and "global_illumination" not in scene.requires:
        raise BackendError("mitsuba: max_depth applies to path-traced (global_illumination) scenes only")
    if max_depth is not None and (max_depth == 0 or max_depth < -1):
        raise BackendError(f"mitsuba: max_depth must be -1 (unlimited) or >= 1, got {max_depth}")
    depth = int(scene.max_depth) if max_depth is None else int(max_depth)
    mi = _import_mitsuba()
    near, far = clip_range(scene)
    t0 = time.perf_counter()
    info: dict[str, Any] = {}
    if "global_illumination" in scene.requires:
        n_req = int(spp) if spp is not None else scene.spp
        if n_req < 2:
            raise BackendError(f"mitsuba path tracing needs at least 2 spp to estimate a variance, got {n_req}")
        k = max(2, min(int(passes), n_req))
        per = -(-n_req // k)  # ceil: never fewer samples than asked
        base_seed = DEFAULT_SEED if seed is None else int(seed)
        integ = {"type": "path", "max_depth": depth, "hide_emitters": False}
        mi_scene = _radiance_scene(
            mi,
            scene,
            near,
            far,
            integ,
            {"type": "independent", "sample_count": per},
            radiance_shapes(mi, scene, emitters=True),
            light_dicts(scene),
        )
        t1 = time.perf_counter()
        seeds = [(base_seed * k + i) % 2**32 for i in range(k)]
        means = np.stack([_render_rgb(mi, mi_scene, per, sd) for sd in seeds])
        rgb = means.mean(axis=0)
        var = means.var(axis=0, ddof=1) / k
        info.update(
            integrator="path",
            spp=per * k,
            spp_requested=n_req,
            passes=k,
            spp_per_pass=per,
            seed=base_seed,
            pass_seeds=seeds,
            max_depth=depth,
            scene_max_depth=int(scene.max_depth),
            sampler="independent",
            rfilter="box",
            var_samples=k,
        )
        info["timings_s"] = {"build": t1 - t0, "render": time.perf_counter() - t1}
        return rgb, var, info
    # Local shading: deterministic pixel centers; one pass per light + one for emission.
    sampler = {"type": "stratified", "sample_count": 1, "jitter": False}
    rgb = np.zeros((scene.camera.height, scene.camera.width, 3))
    n_passes = 0
    shapes_plain = None
    if "lambert" in scene.requires:
        for light in light_dicts(scene):
            if shapes_plain is None:
                shapes_plain = radiance_shapes(mi, scene, emitters=False)
            integ = {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0, "hide_emitters": False}
            rgb += _render_rgb(mi, _radiance_scene(mi, scene, near, far, integ, sampler, shapes_plain, [light]), 1, 0)
            n_passes += 1
    if "emission" in scene.requires:
        _, emission = scene.material_arrays()
        if np.any(emission > 0):
            integ = {"type": "path", "max_depth": 1, "hide_emitters": False}
            shapes = radiance_shapes(mi, scene, emitters=True)
            rgb += _render_rgb(mi, _radiance_scene(mi, scene, near, far, integ, sampler, shapes, []), 1, 0)
            n_passes += 1
    info.update(
        integrator="direct",
        spp=1,
        passes=n_passes,
        sampler="stratified, 1 spp, no jitter (pixel centers)",
        rfilter="box",
        pass_kinds=(
            "one `direct` pass per light (emitter_samples 1, bsdf_samples 0) + one `path` max_depth 1 pass for emission"
        ),
    )
    info["timings_s"] = {"render": time.perf_counter() - t0}
    return rgb, None, info


def render(
    scene: ResolvedScene,
    out_exr: Path,
    workdir: Path,
    timeout_s: float,
    *,
    spp: int | None = None,
    seed: int | None = None,
    max_depth: int | None = None,
    visibility_only: bool = False,
) -> dict[str, object]:
    """Render `scene` into `out_exr` (Z, id.prim, id.object, N; R,G,B [+ var.*] when shaded).

    In-process (the caller enforces `timeout_s`); `workdir` is unused. `spp` / `seed`
    matter only for `global_illumination` (default: the scene's integrator.spp, seed 0);
    `max_depth` (default: the scene's) only there too, and is refused elsewhere.
    `visibility_only` (a scene whose shading features Mitsuba cannot model, e.g.
    `shadowless`) skips radiance: depth, IDs and normals are still compared.
    """
    from ...contract import exrbuf

    if max_depth is not None and "global_illumination" not in scene.requires:
        raise BackendError("mitsuba: max_depth applies to path-traced (global_illumination) scenes only")

    buffers, info = render_arrays(scene)
    attrs: dict[str, str | float | int] = {
        "backend": NAME,
        "variant": str(info["variant"]),
        "near_clip": float(info["near_clip"]),
        "far_clip": float(info["far_clip"]),
    }
    rgb = var = None
    if visibility_only:
        info["visibility_only"] = True
    elif is_shaded(scene):
        rgb, var, rinfo = render_radiance(scene, spp=spp, seed=seed, max_depth=max_depth)
        rgb = rgb.astype(np.float32)
        var = None if var is None else var.astype(np.float32)
        info["radiance"] = rinfo
        attrs["integrator"] = str(rinfo["integrator"])
        attrs["spp"] = int(rinfo["spp"])
        attrs["rgb_encoding"] = "float32"
        if var is not None:
            attrs["seed"] = int(rinfo["seed"]) if int(rinfo["seed"]) < 2**31 else str(rinfo["seed"])
            attrs["passes"] = int(rinfo["passes"])
            attrs["var_samples"] = int(rinfo["var_samples"])
            attrs["max_depth"] = int(rinfo["max_depth"])
    t0 = time.perf_counter()
    exrbuf.write_buffers(
        out_exr,
        Z=buffers["Z"],
        prim=buffers["prim"],
        obj=buffers["obj"],
        N=buffers["N"],
        RGB=rgb,
        var=var,
        attrs=attrs,
    )
    info["timings_s"]["write"] = time.perf_counter() - t0
    return info


# --------------------------------------------------------------------------- precision model
#
# How far this backend may legitimately differ from the reference: `SPEC` (at the end) carries
# these to the judge; judge/tolerance.py holds the shared machinery (contexts, `Model`, grazing
# and position-shift helpers).


def f32_sensor(offset: float, eye_norm: float, point: np.ndarray) -> np.ndarray:
    """Mitsuba: the sensor's to_world is f32, so its origin is f32(eye), and each ray starts at
    to_world applied to a near-plane point, then moved by near * d, in f32: two more roundings
    of every coordinate of a point about |eye| from the origin (<= u |eye| each, sqrt(3) on
    the vector): offset + 2 sqrt(3) u |eye|."""
    return np.full(point.shape, offset + 2.0 * math.sqrt(3.0) * F32_U * eye_norm)


def mitsuba_depth(ctx: DepthContext) -> tuple[np.ndarray, str]:
    """Mitsuba 3 (scalar_rgb / llvm): float32 ray tracing.

    Rays start on the near plane in f32, the intersection is f32 and the depth AOV is
    converted back to planar depth (Z = t/|d| + near). Measured relative error <= 6e-7
    facing the camera; the f32 ray-triangle t loses more at grazing angles (Embree,
    same arithmetic: 9e-6). Relative 1e-5 / |cos|, capped at 1e-3; plus, uncapped, the bound of
    the f32 t = T / den of Embree's default test, which its CPU variants intersect through
    (`MI_ENABLE_EMBREE`; src/render/scene_embree.inl: RTC_SCENE_FLAG_NONE, rtcIntersect1):
    `moeller_t_depth`, which the fuzzer's grazing `s13_02458` needed past the cap; and, since it is
    the same Embree test, the terms Embree's own model has for its ray (`f32_ray_depth`): the f32
    direction, here Mitsuba's own (sqrt(3) + MITSUBA_RAY_ROUNDINGS) u |d| (the sensor's rotation and its
    ray set-up, as its camera model counts them), and Embree's f32 copy of the triangle at the ray
    origin, from Mitsuba's f32 origin (`f32_sensor`). Both were left out while the measured cap
    covered them; at grazing angles only the triangle's depth span bounds them, as for Embree
    (the fuzzer's `s7_01212`, scenes/fuzz_eye_near_plane.toml).
    """
    o = position_error(ctx, f32_sensor)
    tol = (
        relative_grazing(ctx, DEPTH_REL_TOLERANCE)
        + moeller_t_depth(ctx)
        + shift_depth(ctx, o)
        + f32_ray_depth(ctx, math.sqrt(3.0) + MITSUBA_RAY_ROUNDINGS, o)
    )
    return tol, (
        f"mitsuba: |dZ| <= Z*min({DEPTH_REL_TOLERANCE:g}/|cos|, {MAX_REL:g}) (float32 ray tracing) "
        f"+ {MOELLER_TEXT} (its CPU variants intersect through Embree's default test) "
        f"+ min(o / |cos|, depth span), o = |f32(eye) - eye| ({ctx.origin_offset:.3g}) + 2 sqrt(3) 2^-24 |eye| "
        "(f32 sensor transform) "
        f"+ min(2^-24 ((sqrt(3) + {MITSUBA_RAY_ROUNDINGS:g} + 1) |d| Z + o + 2 longest edge) / |cos|, depth span) "
        "(its f32 ray direction and Embree's f32 triangle at the ray origin)"
    )


PRECISION = Model(
    "mitsuba",
    1e-4,
    "float32 ray-triangle tests decide centers within f32 rounding of an edge",
    mitsuba_depth,
    edge_extra=position_edge(f32_sensor, "(|f32(eye) - eye| + 2 sqrt(3) 2^-24 |eye|) (f32 sensor transform)"),
    position=f32_sensor,
)
"""tolerance.Model of Mitsuba: edge band 1e-4 px (measured) + the f32 sensor transform, depth above."""


MITSUBA_RGB_REL = 5e-5
MITSUBA_RGB_ABS_REL_TO_MAX = 1e-6


def rgb_tolerance(ref: np.ndarray, attrs: Mapping[str, Any], info: Mapping[str, Any]) -> RgbTolerance:
    """Mitsuba `direct` at pixel centers, float32 throughout.

    Measured against the float64 closed form on a lit plane: 5e-8 relative (directional)
    and up to 1e-5 (point lights: f32 hit position, r^2 and cos). rel 5e-5, plus
    1e-6 x the image's largest value for cancellation in cos at grazing light.
    """
    top = float(np.max(np.abs(ref), initial=0.0)) if np.size(ref) else 0.0
    abs_tol = MITSUBA_RGB_ABS_REL_TO_MAX * top
    text = (
        f"mitsuba: |dL| <= {MITSUBA_RGB_ABS_REL_TO_MAX:g}*max|L| ({abs_tol:.3g}) + {MITSUBA_RGB_REL:g}*|L| "
        "(float32 ray tracing and shading; measured <= 1e-5 relative)"
    )
    return RgbTolerance(abs_tol, MITSUBA_RGB_REL, text)


# --------------------------------------------------------------------------- camera calibration model


MITSUBA_RAY_ROUNDINGS = 6.0
"""f32 roundings of a Mitsuba camera ray's direction, relative to |d|: sample-to-camera
projection (3), normalization (1), to_world product (2)."""


def camera_model(px: ProbePixels) -> ErrorBudget:
    """Mitsuba 3 (scalar_rgb / llvm): an f32 sensor transform, rays from the near plane in f32."""
    near = probe_param(px, "near_clip") or 0.0
    origin = f32_origin_error(px.eye, near * px.d)
    film = F32_U * max(px.width, px.height) * px.pixel
    return ErrorBudget(
        px.shift(px.origin_offset + origin)
        + px.sample((math.sqrt(3.0) + MITSUBA_RAY_ROUNDINGS) * F32_U * px.d_norm + film)
        + px.depth_rel(3.0 * F32_U + RAY_TRIANGLE_ROUNDINGS * F32_U / px.cos),
        "to_world rounded to f32 (translation |f32(eye) - eye| = "
        f"{px.origin_offset:.3g}, rotation sqrt(3) 2^-24 |d|); each ray's origin f32(eye) + near d rounded "
        f"to f32 (per coordinate <= min(half a float32 step, |f32(eye) - eye| + near |d|): up to "
        f"{float(origin.max()) if origin.size else 0.0:.3g}); film position and ray direction in f32 "
        f"(2^-24 max(W, H) px + {MITSUBA_RAY_ROUNDINGS:g} 2^-24 |d|); f32 ray-triangle t "
        f"({RAY_TRIANGLE_ROUNDINGS:g} 2^-24 / |cos|); depth AOV, conversion and Z in f32 (3 2^-24)",
    )


MITSUBA_INTERPOLATION = 5.0 * F32_U * (1.0 + 10.0 * F32_U)
"""Mitsuba's `si.p = fmadd(p0, b0, fmadd(p1, b1, p2 * b2))` with b0 = 1 - b1 - b2, all f32 (src/render/mesh.cpp,
`compute_surface_interaction`), times max|v|: b0's two roundings put the weights' sum off 1 by 2 u, which moves
the point by 2 u |p0| (toward or away from the world origin, not in the plane), and the product and the two
fmas round once each, by u times |b2 p2|, |b1 p1 + b2 p2| and |p| (weights in [0, 1 + 2 u], summing to 1 + 4 u at
most): 5 u (1 + 10 u) max|v| in all, the second-order terms rounded up."""


def mitsuba_shading_move(ctx: DepthContext, farthest: np.ndarray) -> np.ndarray:
    """How far Mitsuba's shading point `si.p` may lie from the reference's hit (docs/verifier.md,
    "Radiance: the moved shading point"). Its CPU variants intersect through Embree (`MI_ENABLE_EMBREE`,
    rtcIntersect1) and Mitsuba re-interpolates the point from Embree's f32 barycentrics
    (`compute_surface_interaction`), so the point is not on the ray:

    * its f32 ray is off the exact one by the sensor's origin `f32_sensor` o, its f32 direction
      (sqrt(3) + MITSUBA_RAY_ROUNDINGS) u |d| per unit of depth (the camera model's), and Embree's f32
      copy of the vertex at the ray origin u |C| (|C| <= |d| Z + o + E): a lateral move, /|cos| in the plane;
    * Embree's f32 u, v place the point off that ray's exact hit (`embree_barycentric_move`);
    * together at most the triangle's longest edge (both points are in it: `in_plane_move`);
    * the f32 interpolation, MITSUBA_INTERPOLATION max|v| (not in the plane: b0's rounding).
    """
    if ctx.ray_norm is None:
        raise ToleranceError("Mitsuba's shading move needs each pixel ray's length (DepthContext.ray_norm)")
    o = f32_sensor(ctx.origin_offset, ctx.eye_norm, farthest)
    along = ctx.ray_norm * np.abs(ctx.z_ref)
    extent = np.asarray(ctx.extent if ctx.extent is not None else 0.0, dtype=np.float64)
    lateral = o + (math.sqrt(3.0) + MITSUBA_RAY_ROUNDINGS) * F32_U * along + F32_U * (along + o + extent)
    moved: np.ndarray = in_plane_move(ctx, lateral, embree_barycentric_move(ctx, o)) + MITSUBA_INTERPOLATION * farthest
    return moved


SHADING_MOVE = ShadingMove(
    mitsuba_shading_move,
    "min((o + (sqrt(3) + 6) 2^-24 |d| Z + 2^-24 |C|)/|cos| + Embree's f32 barycentrics, longest edge) "
    "+ 5 2^-24 max|v| (f32 ray, Embree's u, v, and si.p re-interpolated from them in f32)",
    f32_lights=True,
)
"""`BackendSpec.rgb_moved_point` of Mitsuba: its point lights are `ScalarPoint3f` (f32 in its RGB variants)."""


MITSUBA_RAY_EPSILON = 1500.0 * F32_U
"""`math::RayEpsilon` (include/mitsuba/core/math.h): 1500 times drjit's f32 epsilon 2^-24, 8.94e-5."""


def mitsuba_shadow_offset(points: np.ndarray) -> np.ndarray:
    """Mitsuba's shadow-ray origin offset at the shading points (K, 3): `Interaction::offset_p` moves the
    origin along the normal, toward the light, by (1 + max_i |p_i|) RayEpsilon (f32: (1 + 4 u) over it), so
    the shadow ray runs up to that far from the reference's, parallel to it. About 0.09 at a coordinate
    of 1024 (the fuzzer's `translate`): a shadow edge cast within that of the ray may go either way."""
    p = np.abs(np.asarray(points, dtype=np.float64))
    offset: np.ndarray = (1.0 + p.max(axis=-1, initial=0.0)) * MITSUBA_RAY_EPSILON * (1.0 + 4.0 * F32_U)
    return offset


SPEC = BackendSpec(
    NAME,
    FEATURES,
    BUFFERS,
    PRECISION,
    calibration=camera_model,
    rgb_tolerance=rgb_tolerance,
    rgb_moved_point=SHADING_MOVE,
    shadow_ray_offset=mitsuba_shadow_offset,
    peak_memory=PEAK_MEMORY,
    render=render,
    version=version,
    unavailable_reason=unavailable_reason,
)
"""What the registry, the judge and calibration know of this backend (renderers/spec.py)."""
