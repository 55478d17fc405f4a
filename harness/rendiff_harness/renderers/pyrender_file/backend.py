"""pyrender rendering the user's original glTF files as trimesh loads them (`pyrender_file`): depth,
IDs and normals.

Every other renderer reads rendiff's resolved triangles, so a wrong glTF import (a node transform, a
mirrored node's winding, a primitive's order or topology) would pass everywhere. This backend reads
the files rendiff read (`objects[].mesh` in scene.json, contract/meshfile.py) with trimesh, pyrender's
own glTF path (`trimesh.load`, its scene graph and node transforms as trimesh reads them), places
each primitive by trimesh's float64 world matrix of its frame and then by the scene object's
transform, and draws the result with the `pyrender` backend's ID and depth passes
(renderers/pyrender/backend.py: OSMesa, FLAT, IDs as colours, 24-bit depth read back and linearized
in float64). So its IDs and depths test the import end to end; its verdict is separate from
`pyrender`'s (which renders the resolved export).

What trimesh 5.2.0 does with a glTF file (contract/gltfgraph.py, checked by the tests on hand-written
files): each node is a frame named by trimesh's own unique names; a mesh of several primitives is one
child frame per primitive, in primitive order; TRIANGLES faces in index order and TRIANGLE_STRIP faces
in the specification's order (each the same triangle, one cyclic rotation of its corners);
`Trimesh.apply_transform` reverses the faces where the world matrix mirrors; POINTS and LINES are
geometries without faces. So the j-th triangle of a node's primitives with faces, in order, is
rendiff's prim first_prim + j of the node's object (the shown scene's mesh nodes in rendiff's object
order, contract/gltfgraph.mesh_nodes), and pyrender draws prim k with colour k + 1.

What it cannot read as the specification says (contract/gltfgraph.TRIMESH_GAPS: sparse accessors,
TRIANGLE_FAN, normalized positions, EXT_mesh_gpu_instancing, a glTF scene other than the file's
default), and objects not read from a glTF file (OBJ, which `mitsuba_file` loads with Mitsuba's own
loader; generated shapes and literal triangles, which have no file), make the scene skipped with the
reason (`skipped: ...`), never rendered wrong. trimesh's triangle count of a node differing from
rendiff's is an error naming both importers (no ID could be mapped); triangles farther apart than the
bound below are named in the render's info (`import_disagreement`) and fail the ID, depth and normal
verdicts where they are seen.

N is not shaded by GL: it is the face normal normalize((b - a) x (c - a)) of the triangle pyrender
shows at the pixel (its ID), from the corners as trimesh placed them, in trimesh's winding (float64,
stored as float32), so a winding rendiff did not reverse under a mirroring node fails it.

Precision (docs/external-renderers.md, "Its glTF path"): per coordinate, the float32 vertex drawn is
within PLACEMENT_REL(d) m + d_in of rendiff's, with m = |M_o| (max(A_32, A_64) (|v|, 1)) + |t_o|
(A_32 the product of the absolute local matrices as rendiff reads them, contract/gltfgraph.mesh_nodes;
A_64 trimesh's, contract/gltfgraph.trimesh_abs_world; u = 2^-24):

* rendiff's value r is its float64 value a rounded once to float32 (<= u |r|);
* a lies within gamma_k m of x, the exact value of rendiff's numbers (node numbers read as float32),
  k = OPS_PER_LEVEL d + OPS_POINT + OPS_OBJECT (the import verdict's counts), and trimesh's float64
  value b within gamma_k m of x', the exact value of trimesh's numbers (node numbers read as float64;
  its quaternion matrix, its T R S product and apply_transform stay within a level's 20);
* x and x' differ because the two read the same decimals at two precisions; that difference is
  computed here, d_in = |M_o ((W_32 - W_64) (v, 1))| in float64 from both world matrices, and it
  lies within d_in + 3 gamma_(k+8) m of |x - x'| (each world matrix within gamma_k of its exact
  product, the difference and the products 8 more roundings);
* this backend rounds b to float32 once (<= u |b|).

Hence PLACEMENT_REL(d) = (2u + 6 gamma_(k+8)) (1 + 4u) (the last factor: |r|, |b| <= m (1 + 2u)),
plus d_in (1 + 4u). The render records `vertex_placement`, the largest vector norm of that bound over
the scene's vertices; the precision model moves every point by it on top of pyrender's own model
(edges by p / (z pixel) px, depths by p / |cos|, at most the triangle's depth span; normals by the
turn such a move can give a triangle, judge/normals.placement_angle).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ...contract import exrbuf, gltfgraph
from ...contract.meshfile import OPS_OBJECT, MeshFileError, object_matrix
from ...contract.resolved import ResolvedScene
from ...contract.vocab import BACKGROUND_ID, Buffer, Feature
from ...judge.tolerance import F32_U, Model
from ..errors import BackendError, BackendSkipped
from ..original import PLACEMENT_ATTR, disagreement, original_file_uses, placed_depth, placement, write_visibility
from ..pyrender import backend as pb
from ..spec import BackendSpec

NAME = "pyrender_file"
FEATURES = frozenset({Feature.DEPTH, Feature.IDS, Feature.NORMALS})
BUFFERS = frozenset({Buffer.Z, Buffer.ID, Buffer.N})
PEAK_MEMORY = (210 * 2**20, 600)
"""`BackendSpec.peak_memory`: 202 MiB on a 2-triangle glTF and 310 MiB on a 199,712-triangle one
(568 B per triangle more: trimesh's scene and the float64 copies of every triangle)."""
U64 = 2.0**-53


def _gamma(k: int, u: float) -> float:
    return k * u / (1.0 - k * u)


def placement_rel(levels: int) -> float:
    """PLACEMENT_REL(d) of the module docstring for a node `levels` levels deep."""
    k = gltfgraph.OPS_PER_LEVEL * levels + gltfgraph.OPS_POINT + OPS_OBJECT
    return (2.0 * F32_U + 6.0 * _gamma(k + 8, U64)) * (1.0 + 4.0 * F32_U)


# --------------------------------------------------------------------------- what it can read


@dataclass
class Use:
    """One use of a glTF file: the file, the glTF scene shown, the objects made of it (rendiff's order)
    and the scene object's transform."""

    path: Path
    chosen: int | None
    objects: list[int]
    transform: Any


def plan_uses(scene: ResolvedScene) -> list[Use]:
    """The scene's file uses, in prim order; BackendSkipped with the reason when an object has no glTF
    file to load."""
    uses = original_file_uses(scene, NAME)
    out = []
    expected = 0
    for use in uses:
        mesh = scene.objects[use[0]]["mesh"]
        if mesh.get("format") != "gltf":
            raise BackendSkipped(
                f"{NAME}: object {scene.objects[use[0]].get('name', '')!r} is read from a {mesh.get('format')} file: "
                "only glTF files are loaded through trimesh here (mitsuba_file loads OBJ files with Mitsuba's loader)"
            )
        first = int(scene.objects[use[0]]["first_prim"])
        if first != expected:
            raise BackendError(
                f"{NAME}: the objects of {mesh.get('file')} do not start at prim {expected} (scene.json)"
            )
        expected = first + sum(int(scene.objects[i]["prim_count"]) for i in use)
        chosen = mesh.get("gltf_scene")
        chosen = chosen if isinstance(chosen, int) and not isinstance(chosen, bool) else None
        out.append(Use(Path(str(mesh.get("file", ""))), chosen, use, mesh.get("transform")))
    if expected != scene.triangle_count:
        raise BackendError(f"{NAME}: the scene's file uses cover {expected} of {scene.triangle_count} triangles")
    return out


@dataclass
class Part:
    """A part rendiff makes of the file: its mesh node, label, and world matrix (with the product of
    the absolute local matrices and the depth) as rendiff reads the node numbers."""

    node: int
    label: str
    world: np.ndarray
    world_abs: np.ndarray
    depth: int


def mesh_parts(doc: dict[str, Any], path: Path, chosen: int | None) -> list[Part]:
    """Each part rendiff makes of the file (contract/gltfgraph: the shown scene's mesh
    nodes in order, none for a node whose mesh draws nothing); BackendSkipped where trimesh departs from
    the specification (contract/gltfgraph.TRIMESH_GAPS)."""
    if gltfgraph.scene_index(doc, chosen) != gltfgraph.scene_index(doc, None):
        default = gltfgraph.scene_index(doc, None)
        raise BackendSkipped(
            f"{NAME}: {path.name} is shown with glTF scene {chosen}, not its default {default}: "
            f"{gltfgraph.TRIMESH_GAPS['scene']}"
        )
    nodes = gltfgraph.mesh_nodes(doc, path, chosen)
    out = []
    for (ni, world, world_abs, depth), label in zip(nodes, gltfgraph.labels(doc, [n[0] for n in nodes]), strict=True):
        if gltfgraph.draws_nothing(doc["meshes"][doc["nodes"][ni]["mesh"]]):
            continue
        gaps = gltfgraph.trimesh_gaps(doc, ni)
        if gaps:
            raise BackendSkipped(f"{NAME}: {path.name} node {ni} ({label}): {gltfgraph.TRIMESH_GAPS[gaps[0]]}")
        out.append(Part(ni, label, world, world_abs, depth))
    return out


# --------------------------------------------------------------------------- loading


@dataclass
class Loaded:
    """The scene's triangles as trimesh placed them (float64 and the float32 drawn, prim order), each
    coordinate's placement bound, and the disagreements found."""

    tris: np.ndarray
    drawn: np.ndarray
    bound: np.ndarray
    problems: list[str]
    files: list[str]


def load(scene: ResolvedScene) -> Loaded:
    """Every glTF file use of the scene through trimesh, placed by the objects' transforms."""
    uses = plan_uses(scene)
    tris = np.zeros((scene.triangle_count, 3, 3))
    bound = np.zeros((scene.triangle_count, 3, 3))
    problems: list[str] = []
    for use in uses:
        try:
            doc, _ = gltfgraph.container(use.path)
            parts = mesh_parts(doc, use.path, use.chosen)
            loaded = gltfgraph.trimesh_load(use.path)
        except MeshFileError as exc:
            raise BackendError(f"{NAME}: importer disagreement: {exc}, which rendiff reads") from None
        if len(parts) != len(use.objects):
            raise BackendError(
                f"{NAME}: importer disagreement: rendiff made {len(use.objects)} objects of {use.path.name}, "
                f"its shown glTF scene has {len(parts)} mesh nodes that draw triangles"
            )
        names = gltfgraph.trimesh_node_names(doc)
        m, t = object_matrix(use.transform)
        for i, part in zip(use.objects, parts, strict=True):
            obj = scene.objects[i]
            ni, label = part.node, part.label
            first, count = int(obj["first_prim"]), int(obj["prim_count"])
            _, prims = gltfgraph.trimesh_primitives(loaded, names, ni)
            got = sum(p.tris.shape[0] for p in prims)
            if got != count:
                raise BackendError(
                    f"{NAME}: importer disagreement: trimesh reads {got} triangles of node {ni} ({label}) in "
                    f"{use.path.name}, rendiff {count} (object {obj.get('name', '')!r}, "
                    f"prims {first}..{first + count - 1})"
                )
            at = first
            for prim in prims:
                n = prim.tris.shape[0]
                chain, _ = gltfgraph.trimesh_abs_world(loaded, prim.frame)
                hom = np.concatenate([prim.local, np.ones((n, 3, 1))], axis=2)
                mag = (np.abs(hom) @ np.maximum(chain, part.world_abs).T)[..., :3] @ np.abs(m).T + np.abs(t)
                trimesh_world = np.asarray(loaded.graph[prim.frame][0], dtype=np.float64)
                d_in = np.abs((hom @ (part.world - trimesh_world).T)[..., :3] @ m.T)
                tris[at : at + n] = prim.tris @ m.T + t
                bound[at : at + n] = placement_rel(part.depth) * mag + d_in * (1.0 + 4.0 * F32_U)
                at += n
            problem = disagreement(
                scene.triangles[first : first + count].astype(np.float64),
                tris[first : first + count].astype(np.float32).astype(np.float64),
                bound[first : first + count],
                first,
                use.path,
                "trimesh",
            )
            if problem:
                problems.append(f"object {obj.get('name', '')!r}: {problem}")
    return Loaded(tris, tris.astype(np.float32), bound, problems, sorted({str(u.path) for u in uses}))


def face_normals(tris: np.ndarray) -> np.ndarray:
    """normalize((b - a) x (c - a)) per triangle, float64; 0 for a degenerate one (it covers no pixel)."""
    c = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    length = np.linalg.norm(c, axis=1, keepdims=True)
    out: np.ndarray = np.divide(c, length, out=np.zeros_like(c), where=length > 0)
    return out


# --------------------------------------------------------------------------- render


def render_arrays(scene: ResolvedScene) -> tuple[dict[str, np.ndarray], dict[str, Any], float]:
    """({'Z', 'prim', 'obj', 'N'}, info, vertex_placement) of pyrender drawing the scene's glTF files."""
    t0 = time.perf_counter()
    loaded = load(scene)
    t1 = time.perf_counter()
    buffers, info = pb.render_arrays(scene, loaded.drawn)
    prim = buffers["prim"]
    hit = prim != BACKGROUND_ID
    normals = np.zeros((*prim.shape, 3), dtype=np.float32)
    normals[hit] = face_normals(loaded.drawn.astype(np.float64))[prim[hit]]
    buffers["N"] = normals
    placed = float(np.max(np.linalg.norm(loaded.bound, axis=2), initial=0.0))
    info.update(
        loader="trimesh.load of the user's glTF files (its scene graph), each object's transform after",
        files=loaded.files,
        trimesh=trimesh_version(),
        normals="face normal of the triangle shown, from trimesh's corners and winding",
    )
    info[PLACEMENT_ATTR] = placed
    info["timings_s"]["load"] = t1 - t0
    if loaded.problems:
        info["import_disagreement"] = "importer disagreement: " + "; ".join(loaded.problems)
    return buffers, info, placed


def render(
    scene: ResolvedScene, out_exr: Path, workdir: Path, timeout_s: float, *, visibility_only: bool = False
) -> dict[str, object]:
    """Render `scene`'s glTF files as trimesh loads them into `out_exr` (Z, id.prim, id.object, N); never
    RGB (`visibility_only` is accepted, and always what is done). In-process; `workdir` is unused."""
    buffers, info, placed = render_arrays(scene)
    attrs: dict[str, exrbuf.AttrValue] = {
        "backend": NAME,
        "znear": float(info["znear"]),
        "zfar": float(info["zfar"]),
        "depth_bits": pb.DEPTH_BITS,
        PLACEMENT_ATTR: placed,
    }
    return write_visibility(out_exr, buffers, info, attrs)


# --------------------------------------------------------------------------- precision


depth = placed_depth(
    pb.pyrender_depth,
    "trimesh's float64 node matrices against rendiff's float32 node numbers, both float64 chains, "
    "two float32 roundings",
)
"""pyrender's depth model plus every point moved by the recorded vertex placement."""


PRECISION = Model(
    NAME,
    pb.PRECISION.edge_px,
    pb.PRECISION.edge_reason,
    depth,
    edge_extra=pb.PRECISION.edge_extra,
    position=pb.PRECISION.position,
    placement=placement,
)
"""pyrender's model (renderers/pyrender/backend.py) with every vertex moved by trimesh's placement."""


def trimesh_version() -> str:
    """trimesh's version (the loader)."""
    import trimesh  # noqa: PLC0415 - heavy import

    return str(trimesh.__version__)


def version() -> str:
    """pyrender's versions and trimesh's (the loader is part of this backend)."""
    try:
        return f"{pb.version()}, trimesh {trimesh_version()}"
    except ImportError:
        return f"{pb.version()}, trimesh (not importable)"


def unavailable_reason() -> str | None:
    """pyrender's reason, else trimesh's absence."""
    reason = pb.unavailable_reason()
    if reason is not None:
        return reason
    try:
        trimesh_version()
    except ImportError as exc:
        return f"cannot import trimesh ({exc}); install the harness requirements"
    return None


SPEC = BackendSpec(
    NAME,
    FEATURES,
    BUFFERS,
    PRECISION,
    calibration=pb.camera_model,
    peak_memory=PEAK_MEMORY,
    render=render,
    version=version,
    unavailable_reason=unavailable_reason,
)
"""What the registry and the judge know of this backend (renderers/spec.py)."""
