"""Mitsuba 3 rendering the user's original OBJ files itself (`mitsuba_file`): depth, IDs and normals.

Every other renderer reads rendiff's resolved triangles, so a wrong OBJ import (an index, a face
order, an n-gon's triangulation, a transform) would pass everywhere. This backend gives Mitsuba
the files rendiff read (`objects[].mesh` in scene.json, contract/meshfile.py) through its own `obj`
loader, each placed by Mitsuba's `to_world` built from the scene object's transform, and compares
what Mitsuba sees with the reference like any renderer, so its IDs and depths test the import end
to end. Its verdict is separate from `mitsuba`'s (which renders the resolved export); the sensor,
the depth conversion and the intersection are that backend's (renderers/mitsuba/backend.py).

What Mitsuba's OBJ loader does (Mitsuba 3.9.1, `src/shapes/obj.cpp`, checked by the tests on
hand-written files):

* faces in file order, `o`/`g` groups ignored (one shape per file), an n-gon a fan from its first
  vertex ((0 1 2), (0 2 3), ...), as tobj's triangulation in rendiff: so Mitsuba's face k of a
  file use is rendiff's triangle first_prim + k of that use's objects (the groups' objects are
  consecutive, in file order), and the global prim_id is that offset plus Mitsuba's per-shape
  `prim_index`; the object ID is rendiff's object of that prim (group assignment is the `import`
  verdict's to check: Mitsuba has no groups);
* vertices deduplicated by (position, uv, normal) index, which moves no triangle;
* coordinates parsed with `std::strtof` (correctly rounded, as tobj's); degenerate faces kept;
  `l`/`p` lines ignored;
* `to_world` applied to every vertex in float32 while loading (below).

What it cannot read, each scene refused before rendering with the reason (`skipped: ...`), never
silently rendered wrong: a negative (relative) index (Mitsuba reads it as an unsigned number and
fails), a line of 1024 characters or more (Mitsuba's line buffer), an object not read from an OBJ
file (glTF, which Mitsuba has no loader for here; generated shapes and literal triangles, which
have no file). Mitsuba's face count of a file differing from rendiff's triangle count of that use
is an error naming the importer disagreement (no ID could be mapped); triangles that differ beyond
the bound below are named in the render's info (`import_disagreement`) and fail the ID and depth
verdicts where they are seen.

Shapes: in `scalar_rgb` the `shape_index` AOV of the shape hit is 1 + its index in
`scene.shapes()` (whose order Mitsuba chooses: read back after loading; docs/external-renderers.md;
checked per pixel: a value naming no shape or a prim_index beyond that shape's faces is an error).
In `llvm_ad_rgb` it is a registry id that drifts between scenes, so a scene of several file uses is
skipped there; one file use needs no shape_index.

Precision (docs/external-renderers.md, "mitsuba_file"): per coordinate, Mitsuba's vertex is within
    (u + gamma_4 (1 + u) + 2 gamma_16(f64)) |M||v| + u |r|   <=   PLACEMENT_REL |M||v| (1 + 4u)
of rendiff's r (|M||v| = |M| |v| + |t|, u = 2^-24): the matrix entries rounded to float32 once
(u |M|), the affine product M v + t, four terms, in float32 (gamma_4 = 4u / (1 - 4u), Higham's
inner-product bound, whatever the order or fused multiply-adds), rendiff's and this backend's
float64 transform (gamma_16 each, contract/meshfile.object_matrix as the import verdict counts it)
and rendiff's one rounding to float32 (half a unit, <= u |r|, |r| <= |M||v| (1 + 2u)). Both read
the same float32 v (correctly rounded decimals). The render records `vertex_placement`, the
largest such bound over the scene's vertices as a vector (sqrt of the sum of the squared
coordinate bounds), and the precision model moves every point by it: edges by
vertex_placement / (z pixel) px, depths by vertex_placement / |cos| (at most the triangle's depth
span), on top of Mitsuba's own sensor and intersection model; normals (`geo_normal`, from the
file's own winding, so a winding rendiff reversed fails them) by the turn such a move can give a
triangle (judge/normals.placement_angle).
"""

from __future__ import annotations

import re
import time
from pathlib import Path
from typing import Any

import numpy as np

from ...contract import exrbuf
from ...contract.meshfile import object_matrix
from ...contract.resolved import ResolvedScene
from ...contract.userfile import UserFileError, read_regular
from ...contract.vocab import BACKGROUND_ID, Buffer, Feature
from ...judge.tolerance import (
    F32_U,
    Model,
    position_edge,
)
from ..errors import BackendError, BackendSkipped
from ..mitsuba import backend as mb
from ..original import PLACEMENT_ATTR, disagreement, original_file_uses, placed_depth, placement, write_visibility
from ..spec import BackendSpec

NAME = "mitsuba_file"
FEATURES = frozenset({Feature.DEPTH, Feature.IDS, Feature.NORMALS})
BUFFERS = frozenset({Buffer.Z, Buffer.ID, Buffer.N})
AOVS = "z:depth,pi:prim_index,si:shape_index,ng:geo_normal"
MAX_OBJ_BYTES = 1 << 30
"""rendiff's own limit on a mesh file (docs/resolved-scene.md)."""
MITSUBA_LINE_LIMIT = 1024
"""Mitsuba's OBJ loader refuses a line of this many characters or more (its 1025-byte buffer)."""
NEGATIVE_INDEX = re.compile(rb"^[ \t\r]*f[ \t][^\n]*-", re.MULTILINE)
LONG_LINE = re.compile(rb"[^\n]{%d}" % MITSUBA_LINE_LIMIT)
U64 = 2.0**-53
PEAK_MEMORY = (120 * 2**20, 600)
"""`BackendSpec.peak_memory`: 114 MiB on obj_mesh (2,048 triangles) and 164 MiB on nefertiti_scan
(99,938: 520 B per triangle more, each file parsed twice plus the arrays read back)."""


def _gamma(k: int, u: float) -> float:
    return k * u / (1.0 - k * u)


PLACEMENT_REL = (F32_U + _gamma(4, F32_U) * (1.0 + F32_U) + 2.0 * _gamma(16, U64) + F32_U) * (1.0 + 4.0 * F32_U)
"""Per coordinate, Mitsuba's vertex is within PLACEMENT_REL |M||v| of rendiff's (module docstring)."""


# --------------------------------------------------------------------------- what it can read


def _file_of(scene: ResolvedScene, use: list[int]) -> Path:
    mesh = scene.objects[use[0]]["mesh"]
    if mesh.get("format") != "obj":
        name = scene.objects[use[0]].get("name", "")
        raise BackendSkipped(
            f"{NAME}: object {name!r} is read from a {mesh.get('format')} file: "
            "only OBJ files are loaded by Mitsuba here"
        )
    return Path(str(mesh.get("file", "")))


def unreadable(path: Path) -> str | None:
    """Why Mitsuba's OBJ loader would read this file otherwise than the OBJ rules (None: it reads it
    as rendiff does)."""
    try:
        data = read_regular(path, MAX_OBJ_BYTES)
    except (OSError, UserFileError) as exc:
        raise BackendError(f"{NAME}: cannot read {path}: {exc}") from None
    if NEGATIVE_INDEX.search(data):
        return f"{path.name} uses negative (relative) indices, which Mitsuba's OBJ loader does not read"
    if LONG_LINE.search(data):
        return f"{path.name} has a line of {MITSUBA_LINE_LIMIT} characters or more, which Mitsuba's OBJ loader refuses"
    return None


def plan_uses(scene: ResolvedScene) -> list[tuple[Path, int, int, Any]]:
    """(file, first_prim, prim_count, transform) per file use, in prim order; BackendSkipped with the
    reason when the scene has anything Mitsuba cannot load from the user's files."""
    uses = original_file_uses(scene, NAME)
    out: list[tuple[Path, int, int, Any]] = []
    seen: dict[Path, str | None] = {}
    expected = 0
    for use in uses:
        path = _file_of(scene, use)
        if path not in seen:
            seen[path] = unreadable(path)
        if seen[path] is not None:
            raise BackendSkipped(f"{NAME}: {seen[path]}")
        first = int(scene.objects[use[0]]["first_prim"])
        count = sum(int(scene.objects[i]["prim_count"]) for i in use)
        if first != expected:
            raise BackendError(f"{NAME}: the objects of {path.name} do not start at prim {expected} (scene.json)")
        expected = first + count
        out.append((path, first, count, scene.objects[use[0]]["mesh"].get("transform")))
    if expected != scene.triangle_count:
        raise BackendError(f"{NAME}: the scene's file uses cover {expected} of {scene.triangle_count} triangles")
    return out


# --------------------------------------------------------------------------- loading


def to_world(mi: Any, transform: Any) -> Any:
    """Mitsuba's to_world for a scene object's transform: the float64 matrix, rounded to float32 by Mitsuba."""
    m, t = object_matrix(transform)
    full = np.eye(4)
    full[:3, :3], full[:3, 3] = m, t
    return mi.ScalarTransform4f(mi.ScalarMatrix4f(full.tolist()))


def _shape(mi: Any, path: Path, transform: Any | None) -> Any:
    desc: dict[str, Any] = {"type": "obj", "filename": str(path), "face_normals": True}
    if transform is not None:
        desc["to_world"] = to_world(mi, transform)
    desc["bsdf"] = {"type": "twosided", "bsdf": {"type": "diffuse"}}
    try:
        return mi.load_dict(desc)
    except Exception as exc:  # noqa: BLE001 - mitsuba raises plain RuntimeError
        raise BackendError(
            f"{NAME}: importer disagreement: Mitsuba's OBJ loader refuses {path.name}, which rendiff reads: {exc}"
        ) from None


def _arrays(mi: Any, shape: Any) -> tuple[np.ndarray, np.ndarray]:
    params = mi.traverse(shape)
    verts = np.array(params["vertex_positions"], dtype=np.float64).reshape(-1, 3)
    faces = np.array(params["faces"], dtype=np.int64).reshape(-1, 3)
    return verts, faces


def placement_bound(local: np.ndarray, transform: Any) -> np.ndarray:
    """Per vertex and coordinate, how far Mitsuba's placed vertex may lie from rendiff's (module docstring)."""
    m, t = object_matrix(transform)
    mag = np.abs(local) @ np.abs(m).T + np.abs(t)
    bound: np.ndarray = PLACEMENT_REL * mag
    return bound


# --------------------------------------------------------------------------- render


def render_arrays(scene: ResolvedScene) -> tuple[dict[str, np.ndarray], dict[str, Any], float]:
    """({'Z', 'prim', 'obj', 'N'}, info, vertex_placement) of Mitsuba rendering the scene's OBJ files."""
    uses = plan_uses(scene)
    mi = mb._import_mitsuba()
    if len(uses) > 1 and mi.variant() != mb.DEFAULT_VARIANT:
        raise BackendSkipped(
            f"{NAME}: {len(uses)} file uses need shape_index, which only {mb.DEFAULT_VARIANT} numbers by the "
            f"scene's shape order (in {mi.variant()} it is a registry id that drifts between scenes)"
        )
    cam = scene.camera
    near, far = mb.clip_range(scene)
    t0 = time.perf_counter()
    desc: dict[str, Any] = {
        "type": "scene",
        "integrator": {"type": "aov", "aovs": AOVS},
        "sensor": mb.sensor_dict(mi, cam, near, far),
    }
    placement = 0.0
    problems: list[str] = []
    firsts: list[int] = []
    counts: list[int] = []
    for k, (path, first, count, transform) in enumerate(uses):
        if count >= mb.MAX_TRIANGLES:
            raise BackendError(f"{NAME}: prim_index is float32, exact below 2^24: {path.name} has {count} triangles")
        local, faces = _arrays(mi, _shape(mi, path, None))
        placed = _shape(mi, path, transform)
        world, world_faces = _arrays(mi, placed)
        if faces.shape[0] != count or not np.array_equal(faces, world_faces):
            raise BackendError(
                f"{NAME}: importer disagreement: Mitsuba reads {faces.shape[0]} triangles from {path.name}, "
                f"rendiff {count} (prims {first}..{first + count - 1})"
            )
        bound = placement_bound(local, transform)
        placement = max(placement, float(np.max(np.linalg.norm(bound, axis=1), initial=0.0)))
        problem = disagreement(
            scene.triangles[first : first + count].astype(np.float64),
            world[faces],
            bound[faces],
            first,
            path,
            "Mitsuba",
        )
        if problem:
            problems.append(problem)
        desc[f"use{k:07d}"] = placed
        firsts.append(first)
        counts.append(count)
    try:
        mi_scene = mi.load_dict(desc)
    except Exception as exc:  # noqa: BLE001
        raise BackendError(f"{NAME}: mitsuba rejected the scene: {type(exc).__name__}: {exc}") from None
    slots = [int(str(s.id())[3:]) for s in mi_scene.shapes()]
    t1 = time.perf_counter()
    try:
        image = np.array(mi.render(mi_scene, spp=1), dtype=np.float32)
    except Exception as exc:  # noqa: BLE001
        raise BackendError(f"{NAME}: mitsuba failed to render: {type(exc).__name__}: {exc}") from None
    t2 = time.perf_counter()
    if image.shape[:2] != (cam.height, cam.width):
        got = f"{image.shape[1]}x{image.shape[0]}"
        raise BackendError(f"{NAME}: mitsuba returned {got}, expected {cam.width}x{cam.height}")
    names = list(mi_scene.integrator().aov_names())
    ch = {name: image[:, :, i] for i, name in enumerate(names)}
    hit = ch["z.T"] > 0.0
    prim = global_prims(ch["si.I"], ch["pi.I"], hit, slots, firsts, counts)
    obj = np.full(prim.shape, BACKGROUND_ID, dtype=np.uint32)
    obj[hit] = scene.object_ids[prim[hit]]
    info: dict[str, Any] = {
        "variant": mi.variant(),
        "integrator": f"aov({AOVS})",
        "loader": "Mitsuba's obj plugin on the user's files, to_world from each object's transform",
        "files": [str(u[0]) for u in uses],
        "near_clip": near,
        "far_clip": far,
        PLACEMENT_ATTR: placement,
        "timings_s": {"build": t1 - t0, "render": t2 - t1},
    }
    if problems:
        info["import_disagreement"] = "importer disagreement: " + "; ".join(problems)
    normals = np.stack([ch["ng.X"], ch["ng.Y"], ch["ng.Z"]], axis=-1)
    normals[~hit] = 0.0
    buffers = {"Z": mb.planar_depth(ch["z.T"], cam, near), "prim": prim, "obj": obj, "N": normals}
    return buffers, info, placement


def global_prims(
    shape_index: np.ndarray,
    prim_index: np.ndarray,
    hit: np.ndarray,
    slots: list[int],
    firsts: list[int],
    counts: list[int],
) -> np.ndarray:
    """rendiff's prim_id per pixel: the first prim of the file use the shape hit shows, plus Mitsuba's
    per-shape prim_index; background 0xFFFFFFFF. `slots[j]` is the use shown by scene.shapes()[j]."""
    prim = np.full(hit.shape, BACKGROUND_ID, dtype=np.uint32)
    si, pi = shape_index[hit], prim_index[hit]
    if si.size == 0:
        return prim
    if np.any(pi != np.round(pi)):
        raise BackendError(f"{NAME}: mitsuba's prim_index AOV holds values that are no face index")
    if len(slots) == 1:
        use = np.zeros(si.size, dtype=np.int64)
    elif np.any(si != np.round(si)) or si.min() < 1 or si.max() > len(slots):
        raise BackendError(f"{NAME}: mitsuba's shape_index AOV holds values that name none of its {len(slots)} shapes")
    else:
        use = np.asarray(slots, dtype=np.int64)[si.astype(np.int64) - 1]
    p = pi.astype(np.int64)
    if np.any(p < 0) or np.any(p >= np.asarray(counts)[use]):
        raise BackendError(f"{NAME}: mitsuba's prim_index AOV names a face beyond its shape's")
    prim[hit] = (np.asarray(firsts, dtype=np.int64)[use] + p).astype(np.uint32)
    return prim


def render(
    scene: ResolvedScene, out_exr: Path, workdir: Path, timeout_s: float, *, visibility_only: bool = False
) -> dict[str, object]:
    """Render `scene`'s OBJ files with Mitsuba into `out_exr` (Z, id.prim, id.object, N); never RGB
    (`visibility_only` is accepted, and always what is done). In-process; `workdir` is unused."""
    buffers, info, placement = render_arrays(scene)
    attrs: dict[str, exrbuf.AttrValue] = {
        "backend": NAME,
        "variant": str(info["variant"]),
        "near_clip": float(info["near_clip"]),
        "far_clip": float(info["far_clip"]),
        PLACEMENT_ATTR: placement,
    }
    return write_visibility(out_exr, buffers, info, attrs)


# --------------------------------------------------------------------------- precision


depth = placed_depth(
    mb.mitsuba_depth, f"Mitsuba's float32 to_world, {PLACEMENT_REL / F32_U:.4g} 2^-24 |M||v| per coordinate"
)
"""Mitsuba's depth model plus every point moved by the recorded vertex placement."""


PRECISION = Model(
    NAME,
    mb.PRECISION.edge_px,
    mb.PRECISION.edge_reason,
    depth,
    edge_extra=position_edge(mb.f32_sensor, "(|f32(eye) - eye| + 2 sqrt(3) 2^-24 |eye|) (f32 sensor transform)"),
    position=mb.f32_sensor,
    placement=placement,
)
"""Mitsuba's model (renderers/mitsuba/backend.py) with every vertex moved by its float32 placement."""


def version() -> str:
    """Mitsuba's version and variant (the loader is part of it)."""
    return mb.version()


SPEC = BackendSpec(
    NAME,
    FEATURES,
    BUFFERS,
    PRECISION,
    calibration=mb.camera_model,
    peak_memory=PEAK_MEMORY,
    render=render,
    version=version,
    unavailable_reason=mb.unavailable_reason,
)
"""What the registry and the judge know of this backend (renderers/spec.py)."""
