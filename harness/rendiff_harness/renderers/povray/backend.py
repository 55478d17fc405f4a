"""POV-Ray 3.7 backend: resolved scene -> SDL -> `povray` CLI -> 16-bit PNGs -> buffer EXR.

Everything here follows docs/external-renderers.md ("POV-Ray 3.7"):

* Security: Debian's POV-Ray ignores povray.conf I/O restrictions, so SDL is a
  program with full file access. The SDL below is built only from numbers this
  module formatted itself (`_num` for floats; Python ints from numpy index
  arrays for indices and ID colours) and from fixed text; no string from
  the scene (names, sources, materials) ever reaches it.
* Exactness: antialiasing off (`-A`), one sample at each pixel center,
  `File_Gamma=1.0` and 16-bit PNG so that k/65535 reads back as k.
* IDs: one flat texture per face in a `mesh2`; id+1 = R + 65536*G.
* Depth: a function pigment of planar depth, 32-bit fixed point over [0, R)
  split into two 16-bit channels; R is chosen per scene from the largest
  planar depth of any vertex, so every ramp stays inside [0, 1].
* Near/far: POV-Ray's camera has no clip planes. The mesh is `clipped_by` the
  half-spaces depth >= near and depth <= far, which removes the surface *and
  shows what lies behind it*, as the Rust tracer's t-interval does. (Masking the
  final hits instead would show background where the reference shows the next
  surface.)

Passes are table-driven (`_PASSES`) for IDs and depth; shaded scenes add the
radiance passes below.

Radiance (docs/radiance.md; notes "POV-Ray 3.7 / Radiance", re-measured by the tests)
--------------------------------------------------------------------------------------
Unit mapping, exactly as emitted:

* `global_settings { assumed_gamma 1.0 ambient_light 0 }`, every material
  `finish { ambient 0 emission 0 diffuse 1 specular 0 phong 0 brilliance 1 reflection 0 }`
  and `pigment { rgb albedo }`. POV-Ray then computes
  L = pigment * light colour * diffuse * |cos| * attenuation, with **no 1/pi**, and with
  the normal turned toward the viewer (two-sided only: no `one_sided`).
* Point light (I, W/sr): `light_source { p, rgb I/(pi * 2 fd^2 * S) fade_distance fd
  fade_power 2 }`. POV-Ray's attenuation is 2/(1 + (d/fd)^2), so the colour times it is
  I/(pi S) * 1/(d^2 + fd^2): I/(pi S d^2) to a relative error (fd/d)^2. fd is chosen
  per scene as FADE_REL (1e-4) times the smallest distance from the light to any visible
  hit point, so that error is <= 1e-8.
* Directional light (E, W/m^2, travelling along dir): `light_source { c - R dir,
  rgb E/(pi S) parallel point_at c }` with c the scene's bounding-box center and R two
  scene sizes (a parallel light still casts shadows only from objects in front of its
  location, so it is placed outside the scene). No fade.
* `shadowless` on every light when the scene requires `shadowless`; else POV-Ray's
  own shadow rays (which ignore occluders within its own small tolerance of the
  surface: contact shadows may differ on a line of pixels; the comparison classifies
  those as shadow edges).* Emission (Le): a separate pass with `pigment { rgb Le/S_e } finish { ambient 0
  emission 1 diffuse 0 }` and no lights (POV-Ray's `emission` multiplies the pigment,
  which in the lit pass must be the albedo; a separate pass keeps both exact, albedo 0
  included). POV-Ray emits on both sides, as `two_sided` asks.
* Exposure: both passes write 16-bit PNG with File_Gamma=1.0, which is exact: code k
  reads back as k/65535. L = S * k/65535 (lit) + S_e * k_e/65535 (emission), in float64.
  S (S_e) is the largest value of `lighting.upper_bound` (shadowless, |cos|, at the hit
  points of this backend's own ID and depth passes) times EXPOSURE_MARGIN (1+2^-6), so
  nothing clips and the quantization step S/65535 is as small as the image allows. A
  pass whose hit pixels reach code 65535 anyway (a bound that failed) is rendered again
  with 4x the scale (at most 3 times; recorded in info). The EXR attributes carry
  `rgb_scale`, `emission_scale` and `rgb_encoding = "png16-linear"`; the comparison's
  tolerance is (S + S_e)/65535/2 absolute (half a code of each pass) plus a relative
  term for POV-Ray's float32 colour arithmetic (`rgb_tolerance`).

Quality settings (speed/accuracy knobs; `rendiff bench knobs`)
--------------------------------------------------------------
`Settings` carries POV-Ray's own antialiasing (+AM method, +A threshold, +R depth, jitter
always off: -J) and quality level (+Q). They reach the **radiance passes only**: the ID
and depth passes always run with `-A` and the default quality, because an ID is not
averageable (an antialiased ID pixel would be a blend of colours that decodes to no
triangle, or to the wrong one) and a blended fixed-point depth decodes to no surface.
Quality below 6 would also disable the function pigment that encodes depth. The
defaults (AA off, +Q default 9) are the conformance contract: one sample at the pixel
center. With AA on, a pixel is an average over its area, so background pixels partly
covered by geometry keep their value (not zeroed by the center-sample hit mask), the
clipping check covers every pixel, and the EXR records `antialias` and `quality`.
The AA threshold compares colours of the exposure-scaled PNG (values in [0, 1], about
1 at the brightest visible pixel), so it is relative to the image's brightest value.
"""

from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from ...contract import exrbuf, vertex_ids, vocab
from ...contract.camera import Camera
from ...contract.resolved import ResolvedScene
from ...contract.vocab import BACKGROUND_ID, Buffer, Feature
from ...judge.camera_budget import (
    F64_U,
    ErrorBudget,
    ProbePixels,
    probe_param,
)
from ...judge.tolerance import (
    F32_U,
    DepthContext,
    EdgeContext,
    Model,
    RgbTolerance,
    ShadingMove,
    ToleranceError,
    along_ray_move,
    exposure_scale,
    param,
    shift_depth,
    shift_edge,
)
from ..children import die_with_parent
from ..errors import BackendError, BackendUnavailable
from ..spec import DIRECT_LIGHT_FEATURES, BackendSpec
from .int_rows import int_rows

NAME = "povray"
FEATURES = DIRECT_LIGHT_FEATURES | {Feature.SHADOWS, Feature.SHADOWLESS, Feature.TWO_SIDED}
BUFFERS = frozenset({Buffer.Z, Buffer.ID, Buffer.RGB})
PEAK_MEMORY = (70 * 2**20, 1800)
"""`BackendSpec.peak_memory`: 64 MiB on three_triangles and 1.05 GiB on `million` (1,310,722
triangles) for one POV-Ray process, counted twice since the ID and depth passes run side by side
(1,720 B per triangle)."""
WAITS_BELOW = 2_500
"""Triangles below which a render keeps one core busy for at most a fifth of its wall time, the
rest being POV-Ray's polling sleeps (spec.BackendSpec.waits_below). Measured as (this process's
and its children's CPU seconds) / wall seconds of `render`, ID and depth passes side by side,
on a shared 2-core machine: 0.08 at 3 triangles (0.66 s), 0.12 at 1,280, 0.15 at 4,248, 0.18 at
6,090, 0.20 at 11,712, 0.25 at 16,719, 0.41 at 44,582, 0.65 at 99,938; CPU ~ 0.05 s + 12 us
per triangle (more where many pixels are covered: 0.21 for a 4,900-triangle sphere at 160x120),
so 2,500 keeps a render under it near 0.12. Measured by hand, not in a test (a timing); 12,000 was
tried on the main job and dropped (docs/benchmarks.md, "Scale")."""
EXPOSURE_MARGIN = 1.0 + 2.0**-6
"""Exposure scale = largest upper bound * this, so the brightest pixel stays below code 65535."""
FADE_REL = 1e-4
"""fade_distance = FADE_REL * (smallest light-to-hit distance): relative 1/d^2 error <= FADE_REL^2."""
MAX_RESCALES = 3
PNG16_MAX = 65535

BINARY = "povray"
THREADS = 2
DEPTH_MARGIN = 1.0 + 2.0**-6
"""R = max vertex depth * DEPTH_MARGIN, so the high word stays below 65535 (a ramp value
of exactly 1.0 is the edge where POV-Ray's wrap-around starts)."""
_STDERR_TAIL = 2000
_INSTALL_HINT = "install it with `apt-get install povray` (or run scripts/setup.sh as root)"


# --------------------------------------------------------------------------- availability


def _binary() -> str | None:
    return shutil.which(BINARY)


def unavailable_reason() -> str | None:
    """None when usable, else what is missing and how to install it."""
    if _binary() is None:
        return f"`{BINARY}` not found on PATH; {_INSTALL_HINT}"
    try:
        import OpenImageIO  # noqa: F401  (decodes the PNGs)
    except ImportError:
        return "Python module OpenImageIO missing (decodes POV-Ray's PNGs); run `pip install openimageio==3.2.2.0`"
    return None


@lru_cache(maxsize=4)
def _version_of(binary: str) -> str:
    try:
        proc = subprocess.run(
            [binary, "--version"],
            check=False,
            capture_output=True,
            text=True,
            timeout=30,
            env=_clean_env(Path("/tmp")),
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise BackendUnavailable(f"{NAME}: `{binary} --version` failed: {exc}") from exc
    match = re.search(r"(?:POV-Ray|Version)\s+(\d+\.\d+[\w.]*)", proc.stdout + proc.stderr)
    if not match:
        raise BackendUnavailable(f"{NAME}: cannot parse the version from `{binary} --version`")
    return f"POV-Ray {match.group(1)}"


def version() -> str:
    """E.g. 'POV-Ray 3.7.0.10.unofficial' (Debian's build calls itself unofficial)."""
    binary = _binary()
    if binary is None:
        raise BackendUnavailable(f"{NAME}: `{BINARY}` not found on PATH; {_INSTALL_HINT}")
    return _version_of(binary)


# --------------------------------------------------------------------------- SDL from numbers only


def _num(x: float) -> str:
    """The only way a float enters SDL: finite, as Python's shortest round-trip repr.

    `repr(float(x))` because numpy 2 scalars repr as `np.float64(...)`, and POV-Ray
    rejects nan/inf but silently accepts overflow like 1e400.
    """
    value = float(x)
    if not math.isfinite(value):
        raise BackendError(f"{NAME}: refusing to write a non-finite number ({value!r}) into SDL")
    return repr(value)


def _vec(v: np.ndarray | tuple[float, float, float]) -> str:
    return "<" + ",".join(_num(c) for c in v) + ">"


def camera_sdl(cam: Camera) -> str:
    """Pinhole through pixel centers with docs/DESIGN.md's basis, used as-is (right-handed).

    POV-Ray shoots direction + x0*right + y0*up with x0, y0 in [-0.5, 0.5] at pixel
    centers; with |direction| = 0.5/tan(vfov/2) and right = r*W/H this is exactly
    docs/DESIGN.md's (sx, sy). Handedness only matters for POV's look_at/sky helpers,
    which are not used: an explicit `right` pointing right keeps the image unmirrored.
    """
    direction = cam.forward * (0.5 / cam.tan_half_vfov)
    right = cam.right * (cam.width / cam.height)
    return (
        f"camera {{ perspective location {_vec(cam.eye)} direction {_vec(direction)}"
        f" up {_vec(cam.up_ortho)} right {_vec(right)} }}\n"
    )


def clip_sdl(cam: Camera) -> str:
    """`clipped_by` keeping near <= depth <= far (see the module docstring)."""
    e_dot_f = float(np.dot(cam.eye, cam.forward))
    planes = [f"plane {{ {_vec(-cam.forward)}, {_num(-(cam.near + e_dot_f))} }}"]
    if math.isfinite(cam.far):
        planes.append(f"plane {{ {_vec(cam.forward)}, {_num(cam.far + e_dot_f)} }}")
    if len(planes) == 1:
        return f"clipped_by {{ {planes[0]} }}\n"
    return "clipped_by { intersection { " + " ".join(planes) + " } }\n"


def _unique_vertices(tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bitwise-identical vertices shared once (smaller SDL, faster parse; same f32 values).

    Returns (vertices (V, 3) f32, faces (N, 3) indices). Keys are the raw f32 bits, so
    -0.0 and 0.0 stay distinct and nothing is merged that is not the very same vertex.
    """
    flat = np.ascontiguousarray(tris.reshape(-1, 3), dtype=np.float32)
    if flat.shape[0] == 0:
        return flat, np.zeros((0, 3), dtype=np.int64)
    first, inverse = vertex_ids.group(*vertex_ids.keys(flat.view(np.uint32)))
    return flat[first], inverse.reshape(-1, 3)


def _nums(values: np.ndarray) -> list[str]:
    """`_num` of every value in row-major order, in one pass over the array.

    The same strings as `_num` (repr of the Python float), without its per-call checks:
    finiteness is tested once for the array, and a non-finite value raises `_num`'s own
    error. A mesh has millions of numbers; this halves the time to format them.
    """
    flat = np.asarray(values, dtype=np.float64).ravel()
    bad = ~np.isfinite(flat)
    if bad.any():
        _num(float(flat[bad][0]))  # raises BackendError naming the value
    return list(map(repr, flat.tolist()))


def _rows(values: Sequence[str] | Sequence[int], template: str) -> str:
    """`template` filled row by row from `values`, the rows joined by ",\\n".

    `values` holds the cells in row-major order (strings from `_nums`, or Python ints); a
    row has as many cells as `template` has `{}` (one shared iterator feeds every slot).
    """
    cells = iter(values)
    width = template.count("{}")
    return ",\n".join(map(template.format, *([cells] * width)))


def _vertex_block(verts: np.ndarray) -> str:
    # float(np.float32) is exact in float64, and its repr round-trips, so POV-Ray's
    # float32 mesh2 storage gets back the very same f32 vertex.
    return "".join((f"vertex_vectors {{ {verts.shape[0]},\n", _rows(_nums(verts), "<{},{},{}>"), "\n}\n"))


@dataclass(frozen=True)
class MeshSdl:
    """The scene's triangles as mesh2 pieces, formatted once and shared by every pass."""

    vertex_block: str
    faces: np.ndarray  # (N, 3) indices into the vertex block; row k is prim k
    vertex_count: int


def mesh_for(scene: ResolvedScene) -> MeshSdl:
    verts, faces = _unique_vertices(scene.triangles)
    return MeshSdl(_vertex_block(verts), faces, int(verts.shape[0]))


def _face_rows(faces: np.ndarray, tags: np.ndarray | None = None) -> str:
    """`<a,b,c>` per face, or `<a,b,c>,tag` (a texture index), joined by ",\\n"; ints only."""
    if tags is None:
        return int_rows(np.asarray(faces, dtype=np.int64), "<{},{},{}>")
    cells = np.column_stack([np.asarray(faces, dtype=np.int64), np.asarray(tags, dtype=np.int64)])
    return int_rows(cells, "<{},{},{}>,{}")


def _face_block(faces: np.ndarray, with_texture: bool) -> str:
    n = faces.shape[0]
    tags = np.arange(n, dtype=np.int64) if with_texture else None
    return "".join((f"face_indices {{ {n},\n", _face_rows(faces, tags), "\n}\n"))


_PRELUDE = (
    "#version 3.7;\n"
    "global_settings { assumed_gamma 1.0 max_trace_level 1 }\n"
    "background { rgb 0 }\n"
    "default { finish { ambient 1 diffuse 0 } }\n"
)


def ids_sdl(scene: ResolvedScene, mesh: MeshSdl) -> str:
    """One flat texture per face: colour (id+1) split into 16-bit R (low) and G (high)."""
    n = mesh.faces.shape[0]
    if n >= BACKGROUND_ID:
        raise BackendError(f"{NAME}: {n} triangles do not fit the 32-bit id encoding")
    code = np.arange(1, n + 1, dtype=np.int64)
    textures = int_rows(np.column_stack([code & 0xFFFF, code >> 16]), "texture{pigment{rgb<{},{},0>/65535}}")
    # One join, not a chain of `+` (each would copy the whole text so far: 134 MB on `million`).
    return "".join(
        (
            _PRELUDE,
            camera_sdl(scene.camera),
            "mesh2 {\n",
            mesh.vertex_block,
            f"texture_list {{ {n},\n",
            textures,
            "\n}\n",
            _face_block(mesh.faces, with_texture=True),
            clip_sdl(scene.camera),
            "}\n",
        )
    )


def depth_range(scene: ResolvedScene) -> float:
    """R for the fixed-point depth: the largest vertex planar depth, with margin (>0)."""
    cam = scene.camera
    if scene.triangle_count == 0:
        return 1.0
    d = (scene.triangles.reshape(-1, 3).astype(np.float64) - cam.eye) @ cam.forward
    dmax = float(d.max())
    if math.isfinite(cam.far):
        dmax = min(dmax, cam.far)  # clipped_by removes everything beyond far
    return max(dmax, 1e-30) * DEPTH_MARGIN


def depth_step(r: float) -> float:
    """Resolution of the fixed-point depth (absolute): the compare step's tolerance floor."""
    return r / 65536.0 / 65535.0


def depth_sdl(scene: ResolvedScene, mesh: MeshSdl, r: float) -> str:
    """Planar depth as 32-bit fixed point over [0, r): high word in R, low word in G."""
    cam = scene.camera
    ex, ey, ez = (_num(c) for c in cam.eye)
    fx, fy, fz = (_num(c) for c in cam.forward)
    return "".join(
        (
            _PRELUDE,
            camera_sdl(cam),
            f"#declare DF = function {{ (x-({ex}))*({fx})+(y-({ey}))*({fy})+(z-({ez}))*({fz}) }}\n",
            f"#declare QF = function {{ DF(x,y,z)/({_num(r)})*65536 }}\n",
            "#declare PH = pigment { function { floor(QF(x,y,z))/65535 } color_map {[0 rgb 0][1 rgb <2,0,0>]} }\n",
            "#declare PL = pigment { function { QF(x,y,z)-floor(QF(x,y,z)) } color_map {[0 rgb 0][1 rgb <0,2,0>]} }\n",
            "mesh2 {\n",
            mesh.vertex_block,
            _face_block(mesh.faces, with_texture=False),
            "texture { pigment { average pigment_map {[1 PH][1 PL]} } }\n",
            clip_sdl(cam),
            "}\n",
        )
    )


# --------------------------------------------------------------------------- running POV-Ray


def _clean_env(workdir: Path) -> dict[str, str]:
    """No POVINI, HOME in the scratch dir: POV-Ray loads ./povray.ini, $POVINI and ~/.povray."""
    env = {"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "HOME": str(workdir), "LC_ALL": "C"}
    return env


AA_METHODS = (1, 2)
"""+AM1: supersample pixels that differ from a neighbour by more than the threshold; +AM2: recursive adaptive."""
AA_THRESHOLD_RANGE = (0.0, 3.0)
AA_DEPTH_RANGE = (1, 9)
QUALITY_RANGE = (0, 11)
DEFAULT_AA_THRESHOLD = 0.3  # POV-Ray's own defaults when antialiasing is on
DEFAULT_AA_DEPTH = 3


@dataclass(frozen=True)
class Settings:
    """POV-Ray's speed/quality settings for the radiance passes (module docstring, "Quality settings").

    The default is the conformance contract: no antialiasing, POV-Ray's default quality.
    """

    aa_method: int | None = None
    aa_threshold: float | None = None
    aa_depth: int | None = None
    quality: int | None = None

    def __post_init__(self) -> None:
        if self.aa_method is None and (self.aa_threshold is not None or self.aa_depth is not None):
            raise BackendError(f"{NAME}: an antialiasing threshold or depth needs an antialiasing method (1 or 2)")
        if self.aa_method is not None and self.aa_method not in AA_METHODS:
            raise BackendError(f"{NAME}: antialiasing method must be 1 or 2, got {self.aa_method!r}")
        lo, hi = AA_THRESHOLD_RANGE
        if self.aa_threshold is not None and not (lo <= self.aa_threshold <= hi):
            raise BackendError(f"{NAME}: antialiasing threshold must be in [{lo:g}, {hi:g}], got {self.aa_threshold!r}")
        for what, value, (a, b) in (
            ("antialiasing depth", self.aa_depth, AA_DEPTH_RANGE),
            ("quality", self.quality, QUALITY_RANGE),
        ):
            if value is not None and not (isinstance(value, int) and a <= value <= b):
                raise BackendError(f"{NAME}: {what} must be an integer in {a}..{b}, got {value!r}")

    @property
    def antialiased(self) -> bool:
        return self.aa_method is not None

    def flags(self) -> list[str]:
        """Command-line flags for a radiance pass (numbers formatted here, never from the scene)."""
        if self.aa_method is None:
            out = ["-A"]
        else:
            threshold = DEFAULT_AA_THRESHOLD if self.aa_threshold is None else self.aa_threshold
            depth = DEFAULT_AA_DEPTH if self.aa_depth is None else self.aa_depth
            out = [f"+A{_num(threshold)}", f"+AM{int(self.aa_method)}", f"+R{int(depth)}", "-J"]
        if self.quality is not None:
            out.append(f"+Q{int(self.quality)}")
        return out

    def label(self) -> str:
        return " ".join(self.flags())


EXACT = Settings()
"""The settings of every ID and depth pass, and the default of the radiance passes."""


def povray_command(
    binary: str, width: int, height: int, sdl_name: str, png_name: str, settings: Settings = EXACT
) -> list[str]:
    """The command line from the notes; file names are relative to the scratch dir (cwd)."""
    return [
        binary,
        "-D",
        "-V",
        "-GS",
        "-GR",
        "-GD",
        *settings.flags(),
        f"+WT{THREADS}",
        f"+W{width}",
        f"+H{height}",
        "+FN16",
        "File_Gamma=1.0",
        f"+I{sdl_name}",
        f"+O{png_name}",
    ]


@dataclass
class _Running:
    """One started POV-Ray pass (`_start`), awaited by `_finish`."""

    stem: str
    png_name: str
    proc: subprocess.Popen[bytes]
    started: float


def _start(
    binary: str,
    scratch: Path,
    cam: Camera,
    stem: str,
    sdl: str,
    deadline: float,
    timeout_s: float,
    settings: Settings = EXACT,
) -> _Running:
    """Write SDL and start POV-Ray on it; `_finish` waits for it under the same deadline."""
    sdl_name, png_name = f"{stem}.pov", f"{stem}.png"
    (scratch / sdl_name).write_text(sdl)
    cmd = povray_command(binary, cam.width, cam.height, sdl_name, png_name, settings)
    if deadline - time.monotonic() <= 0:
        raise BackendError(f"{NAME}: timed out after {timeout_s:g} s (before the {stem} pass)")
    proc = subprocess.Popen(
        cmd,
        cwd=scratch,
        env=_clean_env(scratch),
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        # Same process group as the harness, so rendiff's group kill (timeout,
        # SIGINT/SIGTERM) reaches POV-Ray; and dead with the harness (children.py).
        preexec_fn=die_with_parent,
    )
    return _Running(stem, png_name, proc, time.monotonic())


def _finish(run: _Running, scratch: Path, deadline: float, timeout_s: float) -> float:
    """Wait for a started pass with the hard deadline; returns its wall time."""
    proc, stem = run.proc, run.stem
    try:
        out, err = proc.communicate(timeout=max(deadline - time.monotonic(), 0.0))
    except subprocess.TimeoutExpired as exc:
        proc.kill()
        proc.communicate()
        raise BackendError(
            f"{NAME}: timed out after {timeout_s:g} s (in the {stem} pass); scratch kept in {scratch}"
        ) from exc
    elapsed = time.monotonic() - run.started
    if proc.returncode != 0:
        tail = (err + out).decode("utf-8", "replace")[-_STDERR_TAIL:]
        raise BackendError(f"{NAME}: {stem} pass exited with rc={proc.returncode}; scratch kept in {scratch}\n{tail}")
    if not (scratch / run.png_name).is_file():
        raise BackendError(f"{NAME}: {stem} pass wrote no {run.png_name}; scratch kept in {scratch}")
    return elapsed


def _run_together(runs: list[_Running], scratch: Path, deadline: float, timeout_s: float) -> dict[str, float]:
    """Wait for passes started side by side; the first failure kills the others (no orphan
    keeps rendering) and is raised. Returns each pass's wall time by stem."""
    times: dict[str, float] = {}
    try:
        for run in runs:
            times[run.stem] = _finish(run, scratch, deadline, timeout_s)
    finally:
        for run in runs:
            if run.proc.poll() is None:
                run.proc.kill()
                run.proc.communicate()
    return times


def read_png16(path: Path, width: int, height: int) -> np.ndarray:
    """(H, W, 3) uint16 exactly as stored (OIIO applies no gamma to integer reads)."""
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise BackendError(f"{NAME}: cannot read {path}: {oiio.geterror()}")
    try:
        spec = inp.spec()
        if spec.format != oiio.UINT16 or (spec.width, spec.height) != (width, height) or spec.nchannels < 3:
            raise BackendError(
                f"{NAME}: {path} is {spec.width}x{spec.height}x{spec.nchannels} {spec.format},"
                f" expected {width}x{height} 16-bit RGB"
            )
        pix = inp.read_image(0, 0, 0, 3, oiio.UINT16)
    finally:
        inp.close()
    if pix is None:
        raise BackendError(f"{NAME}: cannot decode {path}")
    return np.asarray(pix, dtype=np.uint16).reshape(height, width, 3)


def decode_ids(png: np.ndarray, n_tris: int) -> np.ndarray:
    """id+1 = R + 65536*G; 0 is background -> 0xFFFFFFFF."""
    code = png[..., 0].astype(np.uint64) + (png[..., 1].astype(np.uint64) << 16)
    if png[..., 2].any() or int(code.max(initial=0)) > n_tris:
        raise BackendError(f"{NAME}: ID pass decoded a colour that is no triangle (conversion bug)")
    prim = np.where(code == 0, np.uint64(BACKGROUND_ID), code - 1)
    return prim.astype(np.uint32)


def decode_depth(png: np.ndarray, r: float) -> np.ndarray:
    """d = R*(hi + lo/65535)/65536 in float64 (not yet masked)."""
    hi = png[..., 0].astype(np.float64)
    lo = png[..., 1].astype(np.float64)
    return r * (hi + lo / 65535.0) / 65536.0


# --------------------------------------------------------------------------- radiance passes

_LIT_FINISH = "finish { ambient 0 emission 0 diffuse 1 specular 0 phong 0 brilliance 1 reflection 0 }"
_EMIT_FINISH = "finish { ambient 0 emission 1 diffuse 0 specular 0 phong 0 reflection 0 }"
_RADIANCE_PRELUDE = (
    "#version 3.7;\nglobal_settings { assumed_gamma 1.0 ambient_light 0 max_trace_level 1 }\nbackground { rgb 0 }\n"
)


def is_shaded(scene: ResolvedScene) -> bool:
    return vocab.needs_shading(scene.requires)


def _material_mesh(scene: ResolvedScene, mesh: MeshSdl, colours: np.ndarray, finish: str) -> str:
    """mesh2 with one texture per material (colours (M, 3), already scaled) and faces tagged by material."""
    mats = scene.prim_materials()
    textures = [f"texture{{pigment{{rgb{_vec(c)}}}{finish}}}" for c in colours]
    return "".join(
        (
            "mesh2 {\n",
            mesh.vertex_block,
            f"texture_list {{ {len(textures)},\n",
            ",\n".join(textures),
            "\n}\n",
            f"face_indices {{ {mesh.faces.shape[0]},\n",
            _face_rows(mesh.faces, mats),
            "\n}\n",
            clip_sdl(scene.camera),
            "}\n",
        )
    )


def fade_distance(scene: ResolvedScene, position: np.ndarray, points: np.ndarray) -> float:
    """FADE_REL x the smallest distance from `position` to the visible hit points (> 0)."""
    from ...contract import lighting

    if points.size:
        dmin = float(np.sqrt(((points - position[None, :]) ** 2).sum(axis=1)).min())
    else:
        dmin = 0.0
    if not dmin > 0.0:
        dmin = lighting.scene_size(scene)
    return FADE_REL * dmin


def lights_sdl(scene: ResolvedScene, scale: float, hit_points: np.ndarray) -> tuple[str, list[dict[str, float]]]:
    """light_source blocks for the lit pass (see the module docstring), and their fade distances."""
    from ...contract import lighting

    shadowless = " shadowless" if "shadowless" in scene.requires else ""
    points, dirs = lighting.lights_of(scene)
    parts: list[str] = []
    fades: list[dict[str, float]] = []
    for pos, intensity in points:
        fd = fade_distance(scene, pos, hit_points)
        colour = intensity / (math.pi * 2.0 * fd * fd * scale)
        parts.append(
            f"light_source {{ {_vec(pos)}, rgb {_vec(colour)} fade_distance {_num(fd)} fade_power 2{shadowless} }}"
        )
        fades.append({"fade_distance": fd})
    if dirs:
        verts = scene.triangles.reshape(-1, 3).astype(np.float64)
        center = 0.5 * (verts.max(axis=0) + verts.min(axis=0)) if verts.size else np.zeros(3)
        reach = 2.0 * lighting.scene_size(scene) + 1.0
        for direction, irradiance in dirs:
            colour = irradiance / (math.pi * scale)
            loc = center - reach * direction
            parts.append(
                f"light_source {{ {_vec(loc)}, rgb {_vec(colour)} parallel point_at {_vec(center)}{shadowless} }}"
            )
    return "\n".join(parts) + "\n", fades


def lit_sdl(
    scene: ResolvedScene, mesh: MeshSdl, scale: float, hit_points: np.ndarray
) -> tuple[str, list[dict[str, float]]]:
    albedo, _ = scene.material_arrays()
    lights, fades = lights_sdl(scene, scale, hit_points)
    sdl = _RADIANCE_PRELUDE + camera_sdl(scene.camera) + lights + _material_mesh(scene, mesh, albedo, _LIT_FINISH)
    return sdl, fades


def emission_sdl(scene: ResolvedScene, mesh: MeshSdl, scale: float) -> str:
    _, emission = scene.material_arrays()
    return _RADIANCE_PRELUDE + camera_sdl(scene.camera) + _material_mesh(scene, mesh, emission / scale, _EMIT_FINISH)


def exposure(bound: np.ndarray) -> float:
    """Scale S for a pass whose values are bounded by `bound` (0 when the pass is all black)."""
    m = float(np.max(bound, initial=0.0))
    return m * EXPOSURE_MARGIN if m > 0.0 and math.isfinite(m) else 0.0


@dataclass(frozen=True)
class _Pass:
    """One POV-Ray run: how to write its SDL, and the PNG it leaves for decoding."""

    stem: str
    build: Callable[[ResolvedScene, MeshSdl, float], str]


_PASSES: tuple[_Pass, ...] = (
    _Pass("ids", lambda scene, mesh, r: ids_sdl(scene, mesh)),
    _Pass("depth", depth_sdl),
)


def render(
    scene: ResolvedScene,
    out_exr: Path,
    workdir: Path,
    timeout_s: float,
    *,
    aa_method: int | None = None,
    aa_threshold: float | None = None,
    aa_depth: int | None = None,
    quality: int | None = None,
    visibility_only: bool = False,
) -> dict[str, object]:
    """Render IDs and depth (and radiance when shaded); write `out_exr` atomically; return settings and sub-timings.

    The keyword settings (module docstring, "Quality settings") reach the radiance passes only.
    `visibility_only` skips the radiance passes (no RGB), so a scene needing a shading feature
    POV-Ray lacks (`one_sided`, `area_light`, ...) is still rendered for depth and IDs
    (registry.plan); nothing in the ID and depth passes depends on the shading features.
    """
    settings = Settings(aa_method, aa_threshold, aa_depth, quality)
    shaded = is_shaded(scene) and not visibility_only
    binary = _binary()
    if binary is None:
        raise BackendUnavailable(f"{NAME}: `{BINARY}` not found on PATH; {_INSTALL_HINT}")
    cam = scene.camera
    h, w = cam.height, cam.width
    deadline = time.monotonic() + timeout_s
    info: dict[str, object] = {
        "threads": THREADS,
        "flags": povray_command(BINARY, w, h, "<scene>.pov", "<out>.png")[1:],
        "near_far": "clipped_by planes",
        "radiance_flags": settings.flags(),
    }
    if visibility_only:
        info["visibility_only"] = True
    n = scene.triangle_count
    if n == 0:
        prim = np.full((h, w), BACKGROUND_ID, dtype=np.uint32)
        z = np.full((h, w), np.inf, dtype=np.float32)
        rgb = np.zeros((h, w, 3), dtype=np.float32) if shaded else None
        exrbuf.write_buffers(out_exr, Z=z, prim=prim, obj=prim, RGB=rgb, attrs={"backend": NAME})
        info["note"] = "empty scene: POV-Ray not run"
        return info

    workdir.mkdir(parents=True, exist_ok=True)
    scratch = Path(tempfile.mkdtemp(prefix="povray-", dir=workdir))
    t0 = time.monotonic()
    mesh = mesh_for(scene)
    r = depth_range(scene)
    info.update(vertices=mesh.vertex_count, triangles=n, depth_range=r, depth_step=depth_step(r))
    info["prepare_s"] = time.monotonic() - t0

    # The ID and depth passes are independent: they run side by side. Each POV-Ray run spends
    # about 0.7 s in its front end's polling sleeps whatever the scene's size (measured on
    # three_triangles at 96x72: 0.69 s alone, 0.69 s for two at once), so this halves the
    # backend's wall time on small scenes; `passes` keeps each run's own time.
    pngs: dict[str, np.ndarray] = {}
    passes: dict[str, dict[str, float]] = {}
    started: list[_Running] = []
    try:
        for p in _PASSES:
            t_sdl = time.monotonic()
            sdl = p.build(scene, mesh, r)
            sdl_s = time.monotonic() - t_sdl
            passes[p.stem] = {"sdl_s": sdl_s, "sdl_bytes": float(len(sdl))}
            started.append(_start(binary, scratch, cam, p.stem, sdl, deadline, timeout_s))
    except BaseException:  # a pass that cannot start: the one already running must not outlive it
        for run in started:
            run.proc.kill()
            run.proc.communicate()
        raise
    for stem, run_s in _run_together(started, scratch, deadline, timeout_s).items():
        passes[stem]["povray_s"] = run_s
        pngs[stem] = read_png16(scratch / f"{stem}.png", w, h)
    info["passes"] = passes

    prim = decode_ids(pngs["ids"], n)
    hit = prim != BACKGROUND_ID
    depth = decode_depth(pngs["depth"], r)
    # Both passes trace the same mesh2, so their hit masks must agree; a depth-pass hit
    # reads nonzero unless its depth is below one fixed-point step.
    info["mask_disagree_px"] = int(np.count_nonzero(~hit & pngs["depth"][..., :2].any(axis=-1)))
    z = np.where(hit, depth, np.inf).astype(np.float32)
    obj = np.full((h, w), BACKGROUND_ID, dtype=np.uint32)
    obj[hit] = scene.object_ids[prim[hit]]
    attrs: dict[str, str | float | int] = {
        "backend": NAME,
        "version": version(),
        "depth_range": r,
        "depth_step": depth_step(r),
    }
    rgb = None
    if shaded:
        shading = _radiance(
            binary, scratch, scene, mesh, prim, np.where(hit, depth, np.inf), deadline, timeout_s, settings
        )
        rgb = shading.rgb
        info["radiance"] = shading.info
        passes.update(shading.passes)
        attrs.update(
            rgb_scale=shading.rgb_scale,
            emission_scale=shading.emission_scale,
            rgb_encoding="png16-linear",
            integrator="direct",
            spp=1,
        )
        if settings != EXACT:
            attrs.update(radiance_flags=settings.label())
    exrbuf.write_buffers(out_exr, Z=z, prim=prim, obj=obj, RGB=rgb, attrs=attrs)
    shutil.rmtree(scratch, ignore_errors=True)
    return info


@dataclass(frozen=True)
class _Shading:
    """What the radiance passes produced (`_radiance`)."""

    rgb: np.ndarray  # (H, W, 3) float32
    info: dict[str, object]  # becomes info["radiance"]
    passes: dict[str, dict[str, float]]  # per pass timings, merged into info["passes"]
    rgb_scale: float  # the lit pass's final exposure scale (0: not run)
    emission_scale: float  # the emission pass's (0: not run)


def _radiance(
    binary: str,
    scratch: Path,
    scene: ResolvedScene,
    mesh: MeshSdl,
    prim: np.ndarray,
    z: np.ndarray,
    deadline: float,
    timeout_s: float,
    settings: Settings = EXACT,
) -> _Shading:
    """Lit and emission passes -> (H, W, 3) float32 radiance and what was done.

    With antialiasing a pixel averages its area, so partly covered background pixels keep
    their value and the clipping check covers every pixel, not only center-sample hits.
    """
    from ...contract import lighting

    cam = scene.camera
    h, w = cam.height, cam.width
    hit = prim != BACKGROUND_ID
    points = lighting.hit_points(scene, z)[hit]
    checked = np.ones_like(hit) if settings.antialiased else hit
    rgb = np.zeros((h, w, 3))
    passes: dict[str, dict[str, float]] = {}
    info: dict[str, object] = {"rgb_scale": 0.0, "emission_scale": 0.0, "rescaled": 0}
    scales = {"rgb_scale": 0.0, "emission_scale": 0.0}  # the same numbers as info's, typed
    rescaled = 0
    plans: list[tuple[str, float]] = []
    if "lambert" in scene.requires and scene.lights:
        plans.append(("lit", exposure(lighting.upper_bound(scene, prim, z, emission=False))))
    if "emission" in scene.requires:
        plans.append(("emission", exposure(lighting.upper_bound(scene, prim, z, lights=False))))
    for stem, scale in plans:
        if scale == 0.0:
            continue  # every visible value is exactly 0: nothing to render
        for attempt in range(MAX_RESCALES + 1):
            t_sdl = time.monotonic()
            if stem == "lit":
                sdl, fades = lit_sdl(scene, mesh, scale, points)
                info["fade"] = fades
            else:
                sdl = emission_sdl(scene, mesh, scale)
            sdl_s = time.monotonic() - t_sdl
            one = _start(binary, scratch, cam, stem, sdl, deadline, timeout_s, settings)
            run_s = _run_together([one], scratch, deadline, timeout_s)[stem]
            png = read_png16(scratch / f"{stem}.png", w, h)
            passes[stem] = {"sdl_s": sdl_s, "povray_s": run_s, "sdl_bytes": float(len(sdl)), "scale": scale}
            if not np.any(png[checked] == PNG16_MAX):
                break
            if attempt == MAX_RESCALES:
                raise BackendError(
                    f"{NAME}: {stem} pass still clips at scale {scale:.6g} after {MAX_RESCALES} rescales "
                    "(the exposure bound is wrong: a bug)"
                )
            scale *= 4.0
            rescaled += 1
            info["rescaled"] = rescaled
        rgb += png.astype(np.float64) * (scale / PNG16_MAX)
        key = "rgb_scale" if stem == "lit" else "emission_scale"
        scales[key] = info[key] = scale
    info["quantization_step"] = (scales["rgb_scale"] + scales["emission_scale"]) / PNG16_MAX
    if not settings.antialiased:
        rgb[~hit] = 0.0
    info["flags"] = settings.flags()
    return _Shading(rgb.astype(np.float32), info, passes, scales["rgb_scale"], scales["emission_scale"])


# --------------------------------------------------------------------------- precision model
#
# How far this backend may legitimately differ from the reference: `SPEC` (at the end) carries
# these to the judge; judge/tolerance.py holds the shared machinery (contexts, `Model`, grazing
# and position-shift helpers).

POVRAY_RGB_REL = 1e-5


def povray_plane_error(point_norm: np.ndarray, extent: np.ndarray | float = 0.0) -> np.ndarray:
    """Offset e of POV-Ray's mesh2 plane from the true one at a point X, world units.

    POV-Ray keeps each mesh triangle's unit normal n and plane offset d = n.P1 in single
    precision (`SnglVector3d` normals, `SNGL Distance`; source/core/shape/mesh.h) and
    intersects with t = (d - n.O) / (n.D) in double. Rounding n to f32 moves each
    component by <= u|n_i| (u = 2^-24), so n.X moves by <= u|X| (Cauchy-Schwarz, |n| = 1);
    rounding d moves it by <= u|d| <= u|X - P1| + u|X|. Whether d is computed from the
    rounded or the unrounded normal, the plane's offset at X is within
    u (|X| + |P1|) + u|X| <= u (3|X| + extent), with extent >= |X - P1| the triangle's
    longest edge. It grows with the distance from the origin, not with depth.
    """
    error: np.ndarray = F32_U * (3.0 * np.abs(point_norm) + extent)
    return error


def povray_depth(ctx: DepthContext) -> tuple[np.ndarray, str]:
    """POV-Ray: 32-bit fixed point, single-precision plane offsets, two f32 roundings.

    The depth pass encodes planar depth as 32-bit fixed point split over two 16-bit PNG
    channels; one step is R / (65536 * 65535) ~ R / 2^32 (`depth_step`, written by the
    backend into info and the EXR attributes). The plane's offset error e at the hit point
    (`povray_plane_error`) moves the hit along the ray by e / |cos|, and planar depth by
    at most that (D.f <= |D|), and never beyond the triangle's own depth span (the hit
    stays on it; `shift_depth`). Both sides' Z are stored as f32: 2 x 2^-24 |Z|. When
    `depth_step` is missing it is derived as R / 2^32 with R = `depth_range` if present,
    else from the reference's largest depth times the backend's margin 1+2^-6.
    """
    step = param(ctx, "depth_step")
    source = "depth_step from the render"
    if step is None:
        r = param(ctx, "depth_range")
        source = "R/2^32 with R = depth_range from the render"
        if r is None:
            zmax = float(np.max(np.abs(ctx.z_ref))) if ctx.z_ref.size else 1.0
            r = zmax * (1.0 + 2.0**-6)
            source = "R/2^32 with R estimated from the reference's largest depth (render gave no depth_step)"
        step = r / 65536.0 / 65535.0
    point = ctx.point_norm if ctx.point_norm is not None else np.abs(ctx.z_ref)
    extent = ctx.extent if ctx.extent is not None else 0.0
    plane = povray_plane_error(point, extent)
    slope = shift_depth(ctx, plane)
    tol = step + slope + 2.0 * F32_U * np.abs(ctx.z_ref)
    text = (
        f"povray: |dZ| <= depth_step ({step:.3g}, {source}; 32-bit fixed point) "
        "+ min(e / |cos|, the triangle's depth span), e = 2^-24 (3|X| + extent) "
        "(mesh2 keeps plane normal and offset in f32; "
        "|X| = hit point's distance from the origin) + 2^-23 Z (both sides stored as f32)"
    )
    return tol, text


def povray_edge(ctx: EdgeContext) -> tuple[np.ndarray, str]:
    """POV-Ray's inside test runs on the hit point, which its f32 plane moves along the ray.

    A hit moved by e / |cos| along the ray lands up to e / |cos| off the plane; its
    dominant-axis projection then shifts sideways by at most sqrt(3) e / |cos| x |cos|
    = sqrt(3) e, which a point at depth z sees as at most sqrt(3) e sqrt(1 + |q|^2) / ((z - sqrt(3) e) pixel)
    px (`shift_edge`).
    """
    e = povray_plane_error(ctx.point_norm)
    return shift_edge(np.sqrt(3.0) * e, ctx), (
        "sqrt(3) 2^-24 3|X| * sqrt(1 + |q|^2) / ((z - moved) pixel) (f32 plane offset moves the hit)"
    )


PRECISION = Model(
    "povray",
    1e-3,
    "POV-Ray mesh2 stores f32 vertices and picks its own tie winners for centers on edges; "
    "measured differences lie within ~1e-6 of an edge",
    povray_depth,
    edge_extra=povray_edge,
    position=lambda offset, eye, point: povray_plane_error(point),
)
"""tolerance.Model of POV-Ray: edge band 1e-3 px (measured) + the f32 plane's sideways shift, depth above."""


def rgb_tolerance(ref: np.ndarray, attrs: Mapping[str, Any], info: Mapping[str, Any]) -> RgbTolerance:
    """POV-Ray: two 16-bit linear passes, L = S k/65535 + S_e k_e/65535 (renderers/povray/backend.py).

    Each pass rounds to the nearest code (measured: max 0.502 codes on a point-lit plane,
    the excess being POV-Ray's float32 colour arithmetic), so abs = (S + S_e)/65535/2;
    rel 1e-5 covers the float32 arithmetic (measured 3e-8) and both sides' f32 storage.
    """
    s = exposure_scale(attrs, info, "rgb_scale")
    se = exposure_scale(attrs, info, "emission_scale")
    if s is None or se is None:
        raise ToleranceError(
            "povray render gives no exposure scales (rendiff:rgb_scale / rendiff:emission_scale): RGB tolerance unknown"
        )
    abs_tol = (s + se) / 65535.0 / 2.0
    text = (
        f"povray: |dL| <= (S {s:.6g} + S_e {se:.6g})/65535/2 = {abs_tol:.3g} (half a code of each 16-bit linear pass) "
        f"+ {POVRAY_RGB_REL:g}*|L| (float32 colour arithmetic)"
    )
    return RgbTolerance(abs_tol, POVRAY_RGB_REL, text)


# --------------------------------------------------------------------------- camera calibration model


def camera_model(px: ProbePixels) -> ErrorBudget:
    """POV-Ray: f64 camera, mesh2 planes with f32 normal and offset, 32-bit fixed-point depth."""
    step = probe_param(px, "depth_step")
    if step is None:
        r = probe_param(px, "depth_range")
        if r is None:
            r = float(px.z.max()) * (1.0 + 2.0**-6) if px.z.size else 1.0
        step = r / 65536.0 / 65535.0
    vertex = F32_U * (3.0 * px.vertex_norm + px.tri_extent[:, None])
    return ErrorBudget(
        px.depth_rel(step / px.z + F32_U) + px.sample(4.0 * F64_U * px.d_norm),
        "mesh2 keeps each plane's normal and offset in f32 (plane off by <= 2^-24 (3|V| + extent) "
        f"at each vertex V); f64 camera rays (4 2^-53 |d|); 32-bit fixed-point depth "
        f"(step {step:.3g}) and Z stored as f32 (2^-24)",
        vertex=vertex,
    )


def povray_shading_move(ctx: DepthContext, farthest: np.ndarray) -> np.ndarray:
    """POV-Ray shades the hit of its exact (f64) pixel ray on its f32 plane, and places its lights in
    f64: the plane error at the triangle's farthest vertex (`povray_plane_error`, which is no smaller
    anywhere on the triangle: the norm is convex, and the offset's rounding through P1 is within
    u (2|X| + |P1|) <= 3 u max|v|) moves it along the ray (docs/verifier.md)."""
    return along_ray_move(ctx, povray_plane_error(farthest))


SHADING_MOVE = ShadingMove(
    povray_shading_move,
    "|d| min(m/|cos|, depth span), m = 3 2^-24 max|v| (its f32 mesh2 plane at the triangle's "
    "farthest vertex; the hit stays on its f64 ray)",
)
"""`BackendSpec.rgb_moved_point` of POV-Ray: lights placed exactly (f64)."""


SPEC = BackendSpec(
    NAME,
    FEATURES,
    BUFFERS,
    PRECISION,
    calibration=camera_model,
    rgb_tolerance=rgb_tolerance,
    rgb_moved_point=SHADING_MOVE,
    peak_memory=PEAK_MEMORY,
    waits_below=WAITS_BELOW,
    render=render,
    version=version,
    unavailable_reason=unavailable_reason,
)
"""What the registry, the judge and calibration know of this backend (renderers/spec.py)."""
