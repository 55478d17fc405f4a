"""pyrender (OpenGL through Mesa's software OSMesa) as a depth + triangle-ID backend.

Conventions and their translation (docs/external-renderers notes, re-measured here):

* Headless through OSMesa only. pyrender's OSMesa platform declares no framebuffer objects,
  so pyrender draws into the single-sampled default buffer and its `glEnable(GL_MULTISAMPLE)`
  is a no-op. (On EGL pyrender renders into a 4x MSAA FBO that blends IDs.) `render` checks
  `GL_SAMPLES == 0`. pyrender has no sample-count setting, so MSAA is no speed/accuracy knob
  here: `msaa_support()` measures why (recorded in the info dict and by `bench knobs`).
* Camera: OpenGL `look_at` pose (columns right, up, -forward, eye) with
  `PerspectiveCamera(yfov = 2 atan(tan_half_vfov), aspectRatio = W/H)` puts GL's pixel
  centers on docs/DESIGN.md's pixel centers. pyrender flips its read-back so row 0 is the top.
* IDs: every triangle gets its own three vertices, coloured with the uint8 RGB of
  (prim_id + 1), little end first (R = low byte); rendered with FLAT (no lighting, no gamma)
  and SKIP_CULL_FACES. Black = background. 24 bits limit a scene to 2^24 - 1 triangles.
* Depth: GL keeps a 24-bit window depth. pyrender linearizes it to eye-space z (= planar
  depth) in f32 with a cancellation; we read the 24-bit integers back ourselves and
  linearize in float64 instead (the cleared value 2^24-1 = background -> +inf). The error
  is a few steps of that buffer, and the step depends on the GL near/far planes, which we
  choose as tight as the geometry allows (`choose_depth_range`, then `refine_depth_range`
  from a first pass). The comparison must use `depth_tolerance(z, near, far)` with the
  planes returned in the info dict and stored in the EXR attributes (znear, zfar).
* Fill rule: GL applies the top-left rule in window coordinates (y up), which is a
  bottom-left rule in rendiff's row-down image coordinates. Pixel centers exactly on an
  edge may therefore differ from the rendiff loops; the comparison classifies those as edge
  mismatches. llvmpipe also snaps vertices to 1/256 px, so centers within
  EDGE_TOLERANCE_PX (1/256 px) of an edge can flip.

Radiance: a Lambert fragment shader of our own, loaded through pyrender's shader cache
---------------------------------------------------------------------------------------
pyrender's own `mesh.frag` is a metallic-roughness model (F0 = 0.04, Smith G, GGX D at
roughness 1): 2.6-6% off Lambert at metallic 0 / roughness 1, and its point-light
shadows are not implemented. Comparing the contract's L against that would test
nothing but the difference of the two models, so the lit pass replaces pyrender's
program cache (`renderer._renderer._program_cache`, pyrender 0.1.45 is pinned) with one
reading `shaders/mesh.vert` and `mesh.frag`, which compute exactly
docs/radiance.md's local shading from the uniforms pyrender binds itself:

* albedo rho -> `MetallicRoughnessMaterial.baseColorFactor` (rgb, alpha 1);
* emission Le -> `emissiveFactor` = Le / S;
* point light (I) -> `PointLight(color = I, intensity = 1/S)` at its position; the
  shader adds rho/pi * color*intensity * max(0, n.w)/r^2 (no range attenuation);
* directional light (E, along dir) -> `DirectionalLight(color = E, intensity = 1/S)`
  whose pose's -z axis is dir normalized; the shader adds rho/pi * E/S * max(0, -n.dir);
* n is the flat face normal (b-a)x(c-a), normalized in float64 and given as vertex
  normals of unshared vertices, turned toward the camera in the shader (`two_sided`);
  culling is off (SKIP_CULL_FACES). pyrender shades no shadows: `shadowless` only.
* output (L/S)^(1/2.2) clamped to [0, 1], written by GL as 8-bit unorm; decoded as
  L = S * (k/255)^2.2 in float64. S is the largest value of `lighting.upper_bound` at
  the hit points of this backend's own ID and depth pass, times EXPOSURE_MARGIN (1.02),
  so the brightest pixel is about code 252; a pass that reaches 255 on a hit pixel is
  rendered again with 4x the scale. Attributes: rgb_scale = S, rgb_encoding =
  "png8-gamma2.2" (8-bit, gamma 2.2), so the comparison's tolerance is half a code value
  through the inverse transfer at the reference's value (`rgb_tolerance`).
* pyrender binds at most MAX_N_LIGHTS (4) lights of each kind; more are refused.
"""

from __future__ import annotations

import math
import os
import sys
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
    CalibrationError,
    ErrorBudget,
    ProbePixels,
    probe_param,
)
from ...judge.tolerance import (
    F32_U,
    MAX_REL,
    DepthContext,
    Model,
    RgbTolerance,
    ShadingMove,
    ToleranceError,
    exposure_scale,
    in_plane_move,
    param,
    position_edge,
    position_error,
    shift_depth,
)
from ..errors import BackendError, BackendUnavailable
from ..spec import DIRECT_LIGHT_FEATURES, BackendSpec

NAME = "pyrender"
FEATURES = DIRECT_LIGHT_FEATURES | {Feature.SHADOWLESS, Feature.TWO_SIDED}
BUFFERS = frozenset({Buffer.Z, Buffer.ID, Buffer.RGB})
PEAK_MEMORY = (210 * 2**20, 400)
"""`BackendSpec.peak_memory`: 200 MiB on three_triangles and 651 MiB on `million` (1,310,722
triangles: 361 B per triangle)."""
SHADER_DIR = Path(__file__).with_name("shaders")
RGB_GAMMA = 2.2
RGB_CODES = 255
EXPOSURE_MARGIN = 1.02
MAX_RESCALES = 3
MAX_LIGHTS_PER_KIND = 4  # pyrender.constants.MAX_N_LIGHTS

DEPTH_BITS = 24
ID_BITS = 24
MAX_TRIANGLES = (1 << ID_BITS) - 1  # id + 1 must fit in 24 bits; 0 is the background
# Measured |Z - float64 reference| (with our float64 linearization): <= 1.9 steps of the
# 24-bit buffer on large tilted planes, but up to 3.4 steps on a 100k-triangle height field
# (the excess grows with the depth slope: llvmpipe's f32 plane-equation interpolation).
# 4 steps covers every pixel measured.
DEPTH_TOLERANCE_STEPS = 4.0
# llvmpipe rasterizes in fixed point with 8 subpixel bits (vertices snap to a 1/256 px
# grid), so a pixel center within ~2.8e-3 px of an edge may land on either side.
# Measured: every ID mismatch within 2.1e-3 px of an edge (100k-triangle height field).
EDGE_TOLERANCE_PX = 2.0**-8
# Margins around the geometry's depth range used for the GL near/far planes (see
# `choose_depth_range`).
NEAR_FRACTION = 0.5
FAR_FACTOR = 1.5
MIN_PYOPENGL = (3, 1, 4)  # 3.1.0 (pyrender's pin) cannot create OSMesa contexts


# --------------------------------------------------------------------------- imports


def _import_gl() -> tuple[ModuleType, ModuleType]:
    """Import pyrender and OpenGL.GL lazily, forcing the OSMesa platform first.

    PyOpenGL picks its platform once, at first import, from PYOPENGL_PLATFORM; so the
    variable must be set before anything imports OpenGL, and a process that already
    imported it for another platform (EGL: MSAA blends IDs) cannot be used.
    """
    if "OpenGL" not in sys.modules:
        os.environ["PYOPENGL_PLATFORM"] = "osmesa"
    elif os.environ.get("PYOPENGL_PLATFORM") != "osmesa":
        raise BackendUnavailable(
            "OpenGL was already imported in this process for platform "
            f"{os.environ.get('PYOPENGL_PLATFORM')!r}; the pyrender backend needs "
            "PYOPENGL_PLATFORM=osmesa set before the first OpenGL import"
        )
    if not hasattr(np, "infty"):
        np.infty = np.inf  # type: ignore[attr-defined]  # pyrender 0.1.45 uses np.infty (gone in numpy 2)
    try:
        import OpenGL
        import pyrender
        from OpenGL import GL
    except Exception as exc:  # noqa: BLE001 - ImportError, or PyOpenGL failing to load libOSMesa
        raise BackendUnavailable(
            f"cannot import pyrender/PyOpenGL with OSMesa ({type(exc).__name__}: {exc}); "
            "install the harness requirements (pip install -r harness/requirements.txt, then "
            "PyOpenGL==3.1.10) and Debian's libosmesa6"
        ) from None
    version = tuple(int(p) for p in OpenGL.__version__.split(".")[:3] if p.isdigit())
    if version < MIN_PYOPENGL:
        raise BackendUnavailable(
            f"PyOpenGL {OpenGL.__version__} cannot create OSMesa contexts; "
            "pip install PyOpenGL==3.1.10 (after pyrender, which pins 3.1.0)"
        )
    return pyrender, GL


@lru_cache(maxsize=1)
def _probe() -> tuple[str | None, str]:
    """(reason it is unusable or None, GL renderer description), from a 1x1 context."""
    try:
        pyrender, GL = _import_gl()
    except BackendUnavailable as exc:
        return str(exc), ""
    try:
        renderer = pyrender.OffscreenRenderer(1, 1)
    except Exception as exc:  # noqa: BLE001 - any failure here means "no usable OSMesa"
        return (
            f"cannot create an OSMesa context ({type(exc).__name__}: {exc}); apt-get install libosmesa6",
            "",
        )
    try:
        renderer._platform.make_current()
        desc = f"{_gl_string(GL, GL.GL_RENDERER)}; {_gl_string(GL, GL.GL_VERSION)}"
    finally:
        renderer.delete()
    return None, desc


@lru_cache(maxsize=1)
def msaa_support() -> dict[str, Any]:
    """Whether pyrender can antialias here, measured: its sample count is no setting at all.

    pyrender has no MSAA option: with framebuffer support (EGL, pyglet) it always draws into
    a hard-coded 4x multisampled FBO; on OSMesa `OSMesaPlatform.supports_framebuffers()` is
    False, so it draws into the single-sampled default buffer (GL_SAMPLES 0) and its
    `glEnable(GL_MULTISAMPLE)` does nothing, although llvmpipe itself offers
    GL_MAX_SAMPLES multisampled renderbuffers. Measured from a 1x1 context.
    """
    import inspect

    pyrender, GL = _import_gl()
    params = [
        *inspect.signature(pyrender.OffscreenRenderer).parameters,
        *inspect.signature(pyrender.OffscreenRenderer.render).parameters,
    ]
    renderer = pyrender.OffscreenRenderer(1, 1)
    try:
        renderer._platform.make_current()
        return {
            "pyrender_sample_parameters": sorted({p for p in params if "sampl" in p.lower()}),
            "pyrender_uses_msaa_fbo": bool(renderer._platform.supports_framebuffers()),
            "gl_samples_default_buffer": int(GL.glGetIntegerv(GL.GL_SAMPLES)),
            "gl_max_samples": int(GL.glGetIntegerv(GL.GL_MAX_SAMPLES)),
        }
    finally:
        renderer.delete()


def _gl_string(GL: ModuleType, name: int) -> str:
    value = GL.glGetString(name)
    return value.decode() if isinstance(value, bytes) else str(value)


def version() -> str:
    """pyrender, PyOpenGL and Mesa versions: all three change the output bits."""
    try:
        pyrender, _ = _import_gl()
        import OpenGL
    except BackendUnavailable:
        return "pyrender (not importable)"
    _, gl = _probe()
    return f"pyrender {pyrender.__version__}, PyOpenGL {OpenGL.__version__}, {gl or 'no GL context'}"


def unavailable_reason() -> str | None:
    """None when an OSMesa context can be created; else what to install."""
    reason, _ = _probe()
    return reason


# --------------------------------------------------------------------------- depth model


def vertex_depths(scene: ResolvedScene, triangles: np.ndarray | None = None) -> np.ndarray:
    """Planar depth (along `forward`) of every vertex (of `triangles`, else the scene's), float64, shaped (N*3,)."""
    cam = scene.camera
    verts = (scene.triangles if triangles is None else triangles).reshape(-1, 3).astype(np.float64)
    depths: np.ndarray = (verts - cam.eye) @ cam.forward
    return depths


def choose_depth_range(scene: ResolvedScene, triangles: np.ndarray | None = None) -> tuple[float, float]:
    """GL near/far planes for this scene: as tight as the geometry allows.

    The 24-bit depth step at depth z is z^2 (f-n)/(f n) 2^-24, i.e. ~z^2/n 2^-24 for
    f >> n: the near plane decides the precision. The scene's own near (1e-4 x scene
    size by default) would waste ~4 orders of magnitude, so we raise it to half the
    nearest vertex depth. Every visible point of a triangle is a convex combination of
    its vertices, so its depth is >= the smallest vertex depth: the raised plane clips
    nothing; the factor 0.5 keeps the nearest vertex away from the clip plane under
    rounding. When geometry comes closer than 2x the scene's near, the scene's near is
    used as is, so near clipping is the scene's (`refine_depth_range` may still raise it
    after a first pass). The far plane must be finite (zfar=None would give an infinite
    projection with a different precision model): 1.5 x the farthest vertex depth, for
    the same reason, unless the scene's far is closer.
    """
    cam = scene.camera
    if not cam.near > 0.0:
        raise BackendError(f"pyrender needs a positive near plane, the scene has near={cam.near}")
    depths = vertex_depths(scene, triangles)
    near = float(cam.near)
    if depths.size:
        near = max(near, NEAR_FRACTION * float(depths.min()))
    farthest = float(depths.max()) if depths.size else near
    far = FAR_FACTOR * farthest
    if math.isfinite(cam.far):
        far = min(far, float(cam.far))
    if not far > near:  # nothing in front of the near plane: any valid range will do
        far = 2.0 * near
    return near, far


def depth_step(z: npt.ArrayLike, near: float, far: float) -> np.ndarray:
    """Resolution of a 24-bit depth buffer at planar depth z, for GL planes near/far."""
    z = np.asarray(z, dtype=np.float64)
    step: np.ndarray = z * z * (far - near) / (far * near) * 2.0**-DEPTH_BITS
    return step


def depth_tolerance(z: npt.ArrayLike, near: float, far: float) -> np.ndarray:
    """Allowed |Z_pyrender - Z_reference| at depth z: 4 steps of the 24-bit buffer + 1 f32 ulp.

    The ulp covers the final rounding of Z to f32, which exceeds the step when far/near
    is small.
    The near/far to pass are the ones this backend chose (info["depth_model"], EXR
    attributes "rendiff:znear"/"rendiff:zfar", i.e. exrbuf.read_attrs keys "znear"/"zfar"),
    not the scene's.
    """
    z = np.asarray(z, dtype=np.float64)
    ulp = np.spacing(np.abs(z).astype(np.float32)).astype(np.float64)
    tolerance: np.ndarray = DEPTH_TOLERANCE_STEPS * depth_step(z, near, far) + ulp
    return tolerance


# --------------------------------------------------------------------------- IDs


def encode_ids(count: int) -> np.ndarray:
    """RGBA8 colour of each of the 3*count unshared vertices: bytes of (prim_id + 1)."""
    if count > MAX_TRIANGLES:
        raise BackendError(
            f"pyrender encodes triangle IDs in 24-bit RGB8 colour: {count} triangles exceed "
            f"the limit of {MAX_TRIANGLES}"
        )
    code = np.arange(1, count + 1, dtype=np.uint32)
    rgba = np.empty((count, 4), dtype=np.uint8)
    rgba[:, 0] = code & 0xFF
    rgba[:, 1] = (code >> 8) & 0xFF
    rgba[:, 2] = (code >> 16) & 0xFF
    rgba[:, 3] = 0xFF  # opaque: alpha < 1 would make pyrender blend
    return np.repeat(rgba, 3, axis=0)


def decode_ids(color: np.ndarray, count: int) -> np.ndarray:
    """prim_id per pixel from the RGB8 image; background (black) -> 0xFFFFFFFF."""
    c = color[..., :3].astype(np.uint32)
    code = c[..., 0] | (c[..., 1] << 8) | (c[..., 2] << 16)
    if np.any(code > count):
        bad = int(np.count_nonzero(code > count))
        raise BackendError(
            f"pyrender produced {bad} pixels whose colour is no triangle ID (blended colours: is MSAA or lighting on?)"
        )
    prim = code - np.uint32(1)  # background: 0 - 1 wraps to 0xFFFFFFFF
    return prim.astype(np.uint32)


def object_ids(prim: np.ndarray, scene: ResolvedScene) -> np.ndarray:
    """Map prim_id -> object index; background stays 0xFFFFFFFF."""
    obj = np.full(prim.shape, BACKGROUND_ID, dtype=np.uint32)
    hit = prim != BACKGROUND_ID
    obj[hit] = scene.object_ids[prim[hit]]
    return obj


# --------------------------------------------------------------------------- camera


def camera_pose(cam: Camera) -> np.ndarray:
    """OpenGL camera-to-world matrix: columns right, up, -forward, eye."""
    pose = np.eye(4)
    pose[:3, 0] = cam.right
    pose[:3, 1] = cam.up_ortho
    pose[:3, 2] = -cam.forward
    pose[:3, 3] = cam.eye
    return pose


def yfov(cam: Camera) -> float:
    """Vertical field of view in radians from the exported tan(vfov/2) (not vfov_deg)."""
    return 2.0 * math.atan(cam.tan_half_vfov)


# --------------------------------------------------------------------------- rendering


def _build_scene(
    pyrender: ModuleType, GL: ModuleType, scene: ResolvedScene, near: float, far: float, triangles: np.ndarray
) -> Any:
    """pyrender.Scene with one unshared-vertex primitive of `triangles` (prim k coloured k + 1) and the camera."""
    cam = scene.camera
    pscene = pyrender.Scene(bg_color=[0.0, 0.0, 0.0, 0.0], ambient_light=[0.0, 0.0, 0.0])
    if scene.triangle_count:
        positions = np.ascontiguousarray(triangles.reshape(-1, 3), dtype=np.float32)
        prim = pyrender.Primitive(positions=positions, color_0=encode_ids(scene.triangle_count), mode=GL.GL_TRIANGLES)
        pscene.add(pyrender.Mesh([prim]))
    camera = pyrender.PerspectiveCamera(yfov=yfov(cam), znear=near, zfar=far, aspectRatio=cam.width / cam.height)
    pscene.add(camera, pose=camera_pose(cam))
    return pscene


def _draw(
    pyrender: ModuleType, GL: ModuleType, pscene: Any, width: int, height: int
) -> tuple[np.ndarray, np.ndarray, int]:
    """(RGB8 image, 24-bit depth integers, GL_SAMPLES), rows top first.

    The depth is read back ourselves as GL_UNSIGNED_INT, which is exact for a 24-bit
    buffer, because pyrender's own linear depth is computed in f32 with a cancellation in
    (f + n) - ndc (f - n): measured up to 5 buffer steps of extra error when near/far are
    tight (as `choose_depth_range` makes them). This uses pyrender's private `_platform`
    to make the OSMesa context current again after `render`; pyrender is pinned (0.1.45).
    """
    flags = pyrender.RenderFlags.FLAT | pyrender.RenderFlags.SKIP_CULL_FACES
    try:
        renderer = pyrender.OffscreenRenderer(width, height)
    except Exception as exc:  # noqa: BLE001 - PyOpenGL/pyrender raise assorted types
        raise BackendError(f"cannot create an OSMesa context: {type(exc).__name__}: {exc}") from None
    try:
        color, _ = renderer.render(pscene, flags=flags)
        renderer._platform.make_current()
        samples = int(GL.glGetIntegerv(GL.GL_SAMPLES))
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, 0)
        GL.glReadBuffer(GL.GL_FRONT)  # OSMesa is single-buffered; pyrender reads GL_FRONT too
        raw = GL.glReadPixels(0, 0, width, height, GL.GL_DEPTH_COMPONENT, GL.GL_UNSIGNED_INT)
    except Exception as exc:  # noqa: BLE001 - reported as one line, not a traceback
        raise BackendError(f"pyrender failed to render: {type(exc).__name__}: {exc}") from None
    finally:
        renderer.delete()
    words = np.frombuffer(raw, dtype=np.uint32).reshape(height, width)[::-1]
    # unorm24 -> unorm32 replicates the top bits into the low byte: k * 2^8 + (k >> 16).
    depth24 = words >> np.uint32(32 - DEPTH_BITS)
    if np.any((words & np.uint32(0xFF)) != (depth24 >> np.uint32(16))):
        raise BackendError("the OSMesa depth buffer is not 24-bit (GL_UNSIGNED_INT read-back is inexact)")
    return np.ascontiguousarray(color), depth24, samples


def linearize_depth(depth24: np.ndarray, near: float, far: float) -> np.ndarray:
    """Planar depth (float32, +inf for background) from 24-bit window depth, in float64.

    GL (glDepthRange 0..1) stores d = f (z - n) / (z (f - n)); hence z = f n / (f - d (f - n)).
    The cleared value 2^24 - 1 (d = 1) is the background.
    """
    top = (1 << DEPTH_BITS) - 1
    d = depth24.astype(np.float64) / top
    z = far * near / (far - d * (far - near))
    return np.where(depth24 == top, np.inf, z).astype(np.float32)


def _render_pass(
    pyrender: ModuleType, GL: ModuleType, scene: ResolvedScene, near: float, far: float, triangles: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """One FLAT|SKIP_CULL_FACES render of `triangles` with GL planes near/far: (prim ids, Z float32)."""
    cam = scene.camera
    pscene = _build_scene(pyrender, GL, scene, near, far, triangles)
    color, depth24, samples = _draw(pyrender, GL, pscene, cam.width, cam.height)
    if samples != 0:
        raise BackendError(f"OSMesa context has GL_SAMPLES={samples}: MSAA would blend IDs")
    if color.shape[:2] != (cam.height, cam.width):
        raise BackendError(
            f"pyrender returned a {color.shape[1]}x{color.shape[0]} image, expected {cam.width}x{cam.height}"
        )
    prim = decode_ids(color, scene.triangle_count)
    z = linearize_depth(depth24, near, far)
    # A pixel must be covered in both buffers or in neither; anything else is a broken decode.
    if np.any((prim == BACKGROUND_ID) != np.isinf(z)):
        raise BackendError("pyrender's colour and depth buffers disagree on coverage")
    return prim, z


def refine_depth_range(z: np.ndarray, near: float, far: float) -> tuple[float, float]:
    """Tighter GL planes from a first pass's visible depths (`z`, rendered with near/far).

    Vertex depths are a poor bound when geometry reaches behind the camera (a ground
    plane): the nearest vertex is then behind the eye and the scene's tiny near is kept.
    The visible depths are the better bound: every fragment that wins a pixel center lies
    in [lo, hi], the extreme visible depths widened by the first pass's tolerance, so
    planes at 0.5 lo and 1.5 hi clip only geometry that covers no pixel center as the
    nearest surface; coverage itself does not depend on near/far. Never looser than the
    first pass, so the scene's near/far clipping still holds.
    """
    visible = z[np.isfinite(z)].astype(np.float64)
    if not visible.size:
        return near, far
    tol = depth_tolerance(visible, near, far)
    lo, hi = float((visible - tol).min()), float((visible + tol).max())
    new_near = max(near, NEAR_FRACTION * lo)
    new_far = min(far, FAR_FACTOR * hi)
    if not new_far > new_near:
        return near, far
    return new_near, new_far


def _precision(near: float, far: float) -> float:
    """The factor (f - n)/(f n) of the depth step: smaller is better."""
    return (far - near) / (far * near)


def render_arrays(
    scene: ResolvedScene, triangles: np.ndarray | None = None
) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Render and convert to rendiff buffers: ({'Z','prim','obj'}, info).

    `triangles` (the scene's triangle_count, prim order) replaces the resolved triangles: the
    positions a loader of the user's original files placed (renderers/pyrender_file), drawn the same way.

    Renders once with planes from the vertex depths (`choose_depth_range`); when the
    visible depths allow planes that are over 2x more precise (`refine_depth_range`),
    renders again with those and keeps the second pass.
    """
    if scene.triangle_count > MAX_TRIANGLES:
        encode_ids(scene.triangle_count)  # raises with the explanation
    pyrender, GL = _import_gl()
    tris = scene.triangles if triangles is None else triangles
    if tris.shape != (scene.triangle_count, 3, 3):
        raise BackendError(f"pyrender: {tris.shape[0]} triangles given for a scene of {scene.triangle_count}")
    t0 = time.perf_counter()
    near, far = choose_depth_range(scene, tris)
    prim, z = _render_pass(pyrender, GL, scene, near, far, tris)
    passes = [{"near": near, "far": far, "seconds": time.perf_counter() - t0}]
    refined = refine_depth_range(z, near, far)
    if _precision(*refined) < 0.5 * _precision(near, far):
        t1 = time.perf_counter()
        near, far = refined
        prim, z = _render_pass(pyrender, GL, scene, near, far, tris)
        passes.append({"near": near, "far": far, "seconds": time.perf_counter() - t1})
    t2 = time.perf_counter()
    buffers = {"Z": z, "prim": prim, "obj": object_ids(prim, scene)}
    info: dict[str, Any] = {
        "platform": "osmesa",
        "gl_renderer": _probe()[1],
        "gl_samples": 0,  # checked in every pass
        "msaa": msaa_support(),
        "flags": "FLAT|SKIP_CULL_FACES",
        "znear": near,
        "zfar": far,
        "depth_passes": passes,
        "depth_model": {
            "kind": "gl_unorm24",
            "bits": DEPTH_BITS,
            "near": near,
            "far": far,
            "step": "z^2*(far-near)/(far*near)*2^-24",
            "tolerance": "4*step + ulp_f32(z)",
            "tolerance_function": "rendiff_harness.renderers.pyrender.backend.depth_tolerance",
        },
        "fill_rule": "GL top-left in window coordinates (bottom-left in row-down image coordinates)",
        "edge_tolerance_px": EDGE_TOLERANCE_PX,
        "timings_s": {"render": t2 - t0, "decode": time.perf_counter() - t2},
    }
    return buffers, info


# --------------------------------------------------------------------------- radiance


def is_shaded(scene: ResolvedScene) -> bool:
    return vocab.needs_shading(scene.requires)


def decode_rgb8(color: np.ndarray, scale: float) -> np.ndarray:
    """L = S (k/255)^2.2 per channel, float64 (the inverse of the shader's encoding)."""
    return scale * (color[..., :3].astype(np.float64) / RGB_CODES) ** RGB_GAMMA


def encode_rgb8(value: np.ndarray, scale: float) -> np.ndarray:
    """The shader's encoding in float64, rounded to the nearest code (for tests and tolerances)."""
    return np.rint(RGB_CODES * np.clip(np.asarray(value, float) / scale, 0.0, 1.0) ** (1.0 / RGB_GAMMA))


def _light_pose(direction: np.ndarray) -> np.ndarray:
    """A rotation whose -z axis is `direction` (pyrender's directional lights shine along -z)."""
    z = -direction / np.linalg.norm(direction)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2] = x, y, z
    return pose


def _lit_scene(
    pyrender: ModuleType, GL: ModuleType, scene: ResolvedScene, near: float, far: float, scale: float
) -> Any:
    from ...contract import lighting

    cam = scene.camera
    pscene = pyrender.Scene(bg_color=[0.0, 0.0, 0.0, 0.0], ambient_light=[0.0, 0.0, 0.0])
    albedo, emission = scene.material_arrays()
    use_emission = "emission" in scene.requires
    normals = lighting.face_normals(scene.triangles)
    for m, prims in lighting.group_by_material(scene):
        positions = np.ascontiguousarray(scene.triangles[prims].reshape(-1, 3), dtype=np.float32)
        vnormals = np.ascontiguousarray(np.repeat(normals[prims], 3, axis=0), dtype=np.float32)
        le = emission[m] / scale if use_emission else np.zeros(3)
        material = pyrender.MetallicRoughnessMaterial(
            baseColorFactor=[*(float(v) for v in albedo[m]), 1.0],
            emissiveFactor=[float(v) for v in le],
            metallicFactor=0.0,
            roughnessFactor=1.0,
            doubleSided=True,
        )
        prim = pyrender.Primitive(positions=positions, normals=vnormals, material=material, mode=GL.GL_TRIANGLES)
        pscene.add(pyrender.Mesh([prim]))
    if "lambert" in scene.requires:
        points, dirs = lighting.lights_of(scene)
        if len(points) > MAX_LIGHTS_PER_KIND or len(dirs) > MAX_LIGHTS_PER_KIND:
            raise BackendError(
                f"pyrender binds at most {MAX_LIGHTS_PER_KIND} point and {MAX_LIGHTS_PER_KIND} directional "
                f"lights; the scene has {len(points)} and {len(dirs)}"
            )
        for pos, intensity in points:
            pose = np.eye(4)
            pose[:3, 3] = pos
            pscene.add(pyrender.PointLight(color=intensity.astype(np.float32), intensity=1.0 / scale), pose=pose)
        for direction, irradiance in dirs:
            light = pyrender.DirectionalLight(color=irradiance.astype(np.float32), intensity=1.0 / scale)
            pscene.add(light, pose=_light_pose(direction))
    camera = pyrender.PerspectiveCamera(yfov=yfov(cam), znear=near, zfar=far, aspectRatio=cam.width / cam.height)
    pscene.add(camera, pose=camera_pose(cam))
    return pscene


def _draw_lit(pyrender: ModuleType, pscene: Any, width: int, height: int) -> np.ndarray:
    """RGB8 of the lit pass, rows top first, drawn with rendiff's Lambert shaders."""
    from pyrender.shader_program import ShaderProgramCache

    try:
        renderer = pyrender.OffscreenRenderer(width, height)
    except Exception as exc:  # noqa: BLE001
        raise BackendError(f"cannot create an OSMesa context: {type(exc).__name__}: {exc}") from None
    try:
        renderer._renderer._program_cache = ShaderProgramCache(shader_dir=str(SHADER_DIR))
        color, _ = renderer.render(pscene, flags=pyrender.RenderFlags.SKIP_CULL_FACES)
    except Exception as exc:  # noqa: BLE001
        raise BackendError(f"pyrender failed to render the lit pass: {type(exc).__name__}: {exc}") from None
    finally:
        renderer.delete()
    return np.ascontiguousarray(color[..., :3])


def render_radiance(
    scene: ResolvedScene, prim: np.ndarray, z: np.ndarray, near: float, far: float
) -> tuple[np.ndarray, dict[str, Any]]:
    """(RGB (H, W, 3) float64 decoded, info) for a shaded scene; `prim`/`z` from this backend's ID pass."""
    from ...contract import lighting

    pyrender, GL = _import_gl()
    cam = scene.camera
    hit = prim != BACKGROUND_ID
    bound = lighting.upper_bound(scene, prim, z.astype(np.float64))
    top = float(bound.max(initial=0.0))
    info: dict[str, Any] = {"rgb_scale": 0.0, "rescaled": 0, "encoding": "8-bit, (L/S)^(1/2.2)"}
    if not top > 0.0:
        return np.zeros((cam.height, cam.width, 3)), info
    scale = top * EXPOSURE_MARGIN
    t0 = time.perf_counter()
    for attempt in range(MAX_RESCALES + 1):
        color = _draw_lit(pyrender, _lit_scene(pyrender, GL, scene, near, far, scale), cam.width, cam.height)
        if color.shape[:2] != (cam.height, cam.width):
            raise BackendError(f"pyrender's lit pass returned {color.shape[1]}x{color.shape[0]}")
        if not np.any(color[hit] == RGB_CODES):
            break
        if attempt == MAX_RESCALES:
            raise BackendError(f"pyrender's lit pass still clips at scale {scale:.6g}: the exposure bound is wrong")
        scale *= 4.0
        info["rescaled"] += 1
    rgb = decode_rgb8(color, scale)
    rgb[~hit] = 0.0
    info.update(
        rgb_scale=scale,
        max_code=int(color[hit].max(initial=0)),
        seconds=time.perf_counter() - t0,
        shaders=str(SHADER_DIR.name),
    )
    return rgb, info


def render(
    scene: ResolvedScene, out_exr: Path, workdir: Path, timeout_s: float, *, visibility_only: bool = False
) -> dict[str, object]:
    """Render `scene` into `out_exr` (Z, id.prim, id.object, and RGB when shaded); returns settings and timings.

    Runs in-process (the caller enforces `timeout_s` by running us in our own process);
    `workdir` is unused: nothing is written besides the EXR. `visibility_only` skips the lit
    pass (no RGB), so a scene needing a shading feature pyrender lacks (`shadows`,
    `one_sided`, ...) is still rendered for depth and IDs (registry.plan).
    """
    from ...contract import exrbuf

    buffers, info = render_arrays(scene)
    t0 = time.perf_counter()
    # exrbuf stores these as "rendiff:<key>" (read back with exrbuf.read_attrs).
    attrs: dict[str, str | float | int] = {
        "backend": NAME,
        "znear": float(info["znear"]),
        "zfar": float(info["zfar"]),
        "depth_bits": DEPTH_BITS,
    }
    rgb = None
    if visibility_only:
        info["visibility_only"] = True
    elif is_shaded(scene):
        rgb64, rinfo = render_radiance(scene, buffers["prim"], buffers["Z"], float(info["znear"]), float(info["zfar"]))
        rgb = rgb64.astype(np.float32)
        info["radiance"] = rinfo
        attrs.update(rgb_scale=float(rinfo["rgb_scale"]), rgb_encoding="png8-gamma2.2", integrator="direct", spp=1)
    exrbuf.write_buffers(out_exr, Z=buffers["Z"], prim=buffers["prim"], obj=buffers["obj"], RGB=rgb, attrs=attrs)
    info["timings_s"]["write"] = time.perf_counter() - t0
    return info


# --------------------------------------------------------------------------- precision model
#
# How far this backend may legitimately differ from the reference: `SPEC` (at the end) carries
# these to the judge; judge/tolerance.py holds the shared machinery (contexts, `Model`, grazing
# and position-shift helpers).


def f32_view_transform(offset: float, eye_norm: float, point: np.ndarray) -> np.ndarray:
    """GL (pyrender): the vertex shader takes each vertex X to eye space with an f32 4x4 view
    matrix (unit rotation rows, translation about |eye|): each component is a 4-term dot
    product, off by <= 4u (|X| + |eye|) (gamma_4), sqrt(3) of that on the vector."""
    tol: np.ndarray = 4.0 * math.sqrt(3.0) * F32_U * (np.abs(point) + eye_norm)
    return tol


def f32_projection_depth(ctx: DepthContext, znear: float, zfar: float) -> np.ndarray:
    """|dZ| from pyrender's f32 clip coordinates: its shader computes P * V * M * inst_m * v
    left to right, so the f32 matrix P·V (rows A·r3, A·t + B for z; -r3, -t for w) turns
    the vertex into clip z and w with independent roundings of size u·|A|(|X| + |eye|) and
    u(|X| + |eye|) (docs/verifier.md, "Depth": pyrender). NDC z = z_c/w_c, so a vertex at
    depth w is off by (e_z + e_w)/w in NDC (|z_c| <= w_c inside the clip volume); screen-space
    interpolation keeps the largest vertex error, at the nearest vertex (depth >= znear,
    >= Z - span; GL's clipping interpolates new vertices in f32, 5u more on each coordinate);
    dZ = Z^2/B dNDC. Not capped by the span: it moves depth, not along the plane."""
    a = (zfar + znear) / (zfar - znear)
    b = 2.0 * zfar * znear / (zfar - znear)
    z = np.abs(ctx.z_ref)
    point = ctx.point_norm if ctx.point_norm is not None else z + ctx.eye_norm
    if ctx.extent is not None:
        point = point + ctx.extent  # the farthest vertex from the origin
    s = point + ctx.eye_norm
    e = F32_U * (15.0 * (a * s + b) + 11.0 * s)
    nearest = np.full(z.shape, znear) if ctx.depth_span is None else np.maximum(znear, z - ctx.depth_span)
    tol: np.ndarray = z * z * e / (b * nearest)
    return tol


def pyrender_depth(ctx: DepthContext) -> tuple[np.ndarray, str]:
    """pyrender: the backend's own 24-bit depth-buffer model at the GL planes it chose.

    GL stores window depth in 24 bits; its resolution at depth z is
    z^2 (f-n)/(f n) 2^-24 for GL planes n, f. The backend picks n, f per scene and writes
    them as `znear`/`zfar` (info and EXR attributes); its `depth_tolerance(z, n, f)`
    (4 steps + 1 f32 ulp, measured) is used as is. Without the planes the tolerance is
    unknown (the scene's own near would be far too loose), so the comparison errors.
    """
    znear, zfar = param(ctx, "znear"), param(ctx, "zfar")
    if znear is None or zfar is None or not (0.0 < znear < zfar):
        raise ToleranceError(
            "pyrender render gives no valid GL planes (znear/zfar in its info or EXR attributes "
            f"rendiff:znear/rendiff:zfar; got znear={znear}, zfar={zfar}): depth tolerance unknown"
        )
    tol = np.asarray(depth_tolerance(ctx.z_ref, znear, zfar), dtype=np.float64)
    # Slope term: llvmpipe snaps vertices to a 1/256 px grid (GL subpixel precision), which
    # moves the triangle's plane sideways by up to sqrt(2)/256 px. Depth then changes by the
    # plane's screen-space slope times that shift; on a plane z(sx) with unit normal n,
    # |dz/dsx| = z |n.r| / |n.d| <= z / |cos| per image-plane unit, i.e. z * pixel_size / |cos|
    # per pixel. Capped like the other grazing-angle models.
    snap = np.sqrt(2.0) / 256.0
    slope = np.abs(ctx.z_ref) * np.minimum(ctx.pixel_size * snap / np.maximum(ctx.cos, 1e-300), MAX_REL)
    tol = tol + slope + shift_depth(ctx, position_error(ctx, f32_view_transform))
    tol = tol + f32_projection_depth(ctx, znear, zfar)
    text = (
        f"pyrender: |dZ| <= pyrender_backend.depth_tolerance(z, znear={znear:.6g}, zfar={zfar:.6g}) "
        "(4 steps of the 24-bit GL depth buffer z^2(f-n)/(f n)2^-24 + 1 f32 ulp) "
        f"+ Z*min(pixel {ctx.pixel_size:.3g} * sqrt(2)/256 / |cos|, {MAX_REL:g}) (1/256 px vertex snapping) "
        "+ min(4 sqrt(3) 2^-24 (|X| + |eye|) / |cos|, depth span) (f32 view transform of the vertices) "
        "+ Z^2 2^-24 (15 (A s + B) + 11 s) / (B max(znear, Z - span)), s = |X| + extent + |eye|, "
        "A = (f+n)/(f-n), B = 2fn/(f-n) (f32 clip coordinates from the f32 product P*V)"
    )
    return tol, text


# llvmpipe snaps vertices to a 1/256 px grid (8 subpixel bits); rounding to nearest moves
# each coordinate by <= 2^-9 px, so a vertex moves by <= sqrt(2) * 2^-9 px. A point of an
# edge is a convex combination of its endpoints, so the edge moves by no more than that.
# Pixel centers (k + 0.5) lie on the grid, so the fixed-point edge function itself is exact:
# only centers within this distance of the true edge can change side.
PYRENDER_EDGE_PX = math.sqrt(2.0) * 2.0**-9  # 2.76e-3 px; measured max 2.1e-3 px

PRECISION = Model(
    "pyrender",
    PYRENDER_EDGE_PX,
    "GL fixed-point rasterization: llvmpipe snaps vertices to 1/256 px, moving an edge by "
    "<= sqrt(2)*2^-9 px; measured max 2.1e-3 px",
    pyrender_depth,
    edge_extra=position_edge(f32_view_transform, "4 sqrt(3) 2^-24 (|X| + |eye|) (f32 view transform)"),
    position=f32_view_transform,
)
"""tolerance.Model of pyrender: the 1/256 px vertex snap + the f32 view transform, depth above."""


PYRENDER_RGB_REL = 1e-5
PYRENDER_CODE_SLACK = 0.01


def rgb_tolerance(ref: np.ndarray, attrs: Mapping[str, Any], info: Mapping[str, Any]) -> RgbTolerance:
    """pyrender: 8-bit (L/S)^(1/2.2) from rendiff's Lambert shader (renderers/pyrender/backend.py).

    GL rounds to the nearest code (measured: max 0.49997 codes), so at the reference value
    b, with c = 255 (b/S)^(1/2.2), the decoded value may be off by
    S (((c + 0.5 + 0.01)/255)^2.2 - (c/255)^2.2): half a code through the inverse transfer
    (the larger, upper side), plus 0.01 code for the shader's float32 arithmetic at a
    rounding boundary; plus rel 1e-5.
    """
    s = exposure_scale(attrs, info, "rgb_scale")
    if s is None:
        raise ToleranceError("pyrender render gives no exposure scale (rendiff:rgb_scale): RGB tolerance unknown")
    gamma = 2.2
    b = np.clip(np.abs(np.asarray(ref, dtype=np.float64)) / s if s > 0 else np.zeros_like(ref), 0.0, 1.0)
    c = 255.0 * b ** (1.0 / gamma)
    hi = np.minimum((c + 0.5 + PYRENDER_CODE_SLACK) / 255.0, 1.0)
    abs_tol = s * (hi**gamma - (c / 255.0) ** gamma)
    text = (
        f"pyrender: |dL| <= S*(((c+0.5+{PYRENDER_CODE_SLACK:g})/255)^2.2 - (c/255)^2.2), c = 255 (L/S)^(1/2.2), "
        f"S {s:.6g} (half an 8-bit code through the inverse gamma-2.2 transfer at the reference's value; "
        f"+{PYRENDER_CODE_SLACK:g} code for float32 shading) + {PYRENDER_RGB_REL:g}*|L|"
    )
    return RgbTolerance(abs_tol, PYRENDER_RGB_REL, text)


# --------------------------------------------------------------------------- camera calibration model


PYRENDER_VERTEX_DEPTH_STEPS = 4.0
"""Window depth of a vertex computed in f32 (projection, divide, viewport: <= 4 x 2^-24 in [0, 1],
i.e. 4 steps of the 24-bit buffer)."""
PYRENDER_PIXEL_DEPTH_STEPS = 2.5
"""Window depth interpolated in f32 at the pixel (2 steps) and rounded to 24 bits (half a step)."""


def camera_model(px: ProbePixels) -> ErrorBudget:
    """pyrender (GL on llvmpipe): f32 vertex transform, 24-bit depth buffer."""
    znear, zfar = probe_param(px, "znear"), probe_param(px, "zfar")
    if znear is None or zfar is None or not 0.0 < znear < zfar:
        raise CalibrationError(
            f"pyrender render gives no valid GL planes (znear={znear}, zfar={zfar}): its depth precision is unknown"
        )
    scale = (zfar - znear) / (zfar * znear) * 2.0**-24

    def step(z: np.ndarray) -> np.ndarray:
        return np.asarray(z * z * scale)

    window = 8.0 * F32_U * px.vertex_d_norm + 2.0 * F32_U * max(px.width, px.height) * px.pixel
    vertex = (
        4.0 * math.sqrt(3.0) * F32_U * (px.vertex_norm + px.eye_norm)
        + px.vertex_depth * window
        + PYRENDER_VERTEX_DEPTH_STEPS * step(px.vertex_depth)
    )
    return ErrorBudget(
        px.depth_rel(PYRENDER_PIXEL_DEPTH_STEPS * step(px.z) / px.z + F32_U),
        "per vertex: f32 view transform (4 sqrt(3) 2^-24 (|V| + |eye|)), projection, divide and viewport in "
        "f32 (Z (8 2^-24 |d| + 2 2^-24 max(W, H) px)), window depth in f32 "
        f"({PYRENDER_VERTEX_DEPTH_STEPS:g} steps z^2 (f - n)/(f n) 2^-24 at znear {znear:.4g}, zfar {zfar:.4g}); "
        f"per pixel: depth interpolated in f32 and rounded to 24 bits ({PYRENDER_PIXEL_DEPTH_STEPS:g} steps), "
        "Z stored as f32. llvmpipe interpolates depth from the float vertex positions, so its 1/256 px "
        "vertex snapping moves coverage (IDs), not depth samples",
        vertex=vertex,
    )


PYRENDER_INTERPOLATION = 8.0 * F32_U
"""llvmpipe's perspective-correct interpolation of `frag_position` (world f32 vertex values) at a pixel, per
max|v|: the attribute over w is a plane a0 + dadx x + dady y set up in f32 from the three vertices and
evaluated in f32 (about three roundings each in the set-up and the evaluation), then multiplied by the
interpolated w (two): 8 u of values of size max|v|, counted from that structure (not from llvmpipe's
generated code line by line)."""


def pyrender_shading_move(ctx: DepthContext, farthest: np.ndarray) -> np.ndarray:
    """How far pyrender's shading point (`frag_position`, rendiff's Lambert shader) may lie from the
    reference's hit (docs/verifier.md, "Radiance: the moved shading point"). The shader gets the exact f32
    world vertices and llvmpipe interpolates them at the pixel center with the barycentrics of the
    triangle as its f32 view transform placed it relative to the camera (`f32_view_transform` at the
    farthest vertex): the pixel ray meets that moved triangle at barycentrics whose point on the unmoved
    triangle is within the move of the ray and in the triangle's plane, so `in_plane_move` of it; plus
    the f32 interpolation, PYRENDER_INTERPOLATION max|v|. llvmpipe sets its interpolation planes up from
    the float vertex positions (the camera model's measurement: its 1/256 px snap moves coverage, not
    depth samples), so the snap moves no shading point. Far from the origin the view transform
    dominates (0.75 at |X| 9.1e5: the found `fuzz_pyrender_far_light`)."""
    lateral = f32_view_transform(ctx.origin_offset, ctx.eye_norm, farthest)
    moved: np.ndarray = in_plane_move(ctx, lateral) + PYRENDER_INTERPOLATION * farthest
    return moved


SHADING_MOVE = ShadingMove(
    pyrender_shading_move,
    "min(4 sqrt(3) 2^-24 (max|v| + |eye|) / |cos|, longest edge) + 8 2^-24 max|v| "
    "(f32 view transform of the vertices; f32 interpolated position)",
    f32_lights=True,
)
"""`BackendSpec.rgb_moved_point` of pyrender: its point lights reach the shader as f32 uniforms."""


SPEC = BackendSpec(
    NAME,
    FEATURES,
    BUFFERS,
    PRECISION,
    calibration=camera_model,
    rgb_tolerance=rgb_tolerance,
    rgb_moved_point=SHADING_MOVE,
    peak_memory=PEAK_MEMORY,
    render=render,
    version=version,
    unavailable_reason=unavailable_reason,
)
"""What the registry, the judge and calibration know of this backend (renderers/spec.py)."""
