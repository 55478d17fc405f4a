"""The `id` buffer: prim IDs compared exactly, each mismatch classed by the verifier (verify.py) as
edge, tie, crack or interior (docs/DESIGN.md "Comparing", docs/verifier.md)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..contract import vocab
from ..contract.manifest import Reference
from ..contract.vocab import BACKGROUND_ID
from . import tolerance, verify
from .verdict import EXAMPLES


@dataclass
class IdResult:
    edge: int
    interior: int
    edge_mask: np.ndarray  # (H, W) bool: allowed ID differences (edge, tie, declared-or-not crack)
    interior_mask: np.ndarray  # (H, W) bool
    tolerance: str
    details: list[str]
    tie: int = 0
    crack: int = 0
    classes: np.ndarray | None = None  # (H, W) int8: verify.EDGE..INTERIOR, -1 where the IDs agree
    explanations: list[dict[str, Any]] = field(default_factory=list)


EdgeDistance = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]
"""(ref ids, test ids, rows, cols) of the mismatched pixels -> pixel distance to an edge involved."""


def origin_offset(ref: Reference) -> float:
    """|f32(eye) - eye|: how far a renderer whose camera origin is f32 moves every ray."""
    eye = np.asarray(ref.scene.camera.eye, dtype=np.float64)
    return float(np.linalg.norm(eye.astype(np.float32).astype(np.float64) - eye))


def eye_norm(ref: Reference) -> float:
    """|eye|: the size of the camera's coordinates, which f32 arithmetic rounds relative to."""
    return float(np.linalg.norm(np.asarray(ref.scene.camera.eye, dtype=np.float64)))


def pixel_size(ref: Reference) -> float:
    """One pixel on the image plane at distance 1."""
    return ref.scene.camera.pixel_size()


def point_norm(ref: Reference, rows: np.ndarray, cols: np.ndarray, z: np.ndarray) -> np.ndarray:
    """|X| of the points at planar depth z along pixel rays (distance from the world origin)."""
    cam = ref.scene.camera
    d = cam.center_directions(rows, cols)
    zz = np.where(np.isfinite(z), z, 0.0)
    norms: np.ndarray = np.linalg.norm(cam.eye[None, :] + zz[:, None] * d, axis=1)
    return norms


def involved_triangles(
    ref: Reference, rows: np.ndarray, cols: np.ndarray, prims: tuple[np.ndarray, ...]
) -> dict[str, np.ndarray]:
    """What the edge models need of the triangles at each mismatched pixel (tolerance.EdgeContext):
    the pixel center's off-axis factor sqrt(1 + |q|^2), and over the prims named (background and
    IDs naming no triangle skipped) the largest |v - eye|, longest edge, largest height, and the
    nearest planar depth at which a prim's plane crosses the pixel ray, but no nearer than that
    prim's nearest vertex (inf: none)."""
    cam = ref.scene.camera
    eye = np.asarray(cam.eye, dtype=np.float64)
    sx, sy = cam.screen_at(*cam.pixel_centers(cols, rows))
    d = cam.direction(sx, sy)  # planar component 1: t along d is planar depth
    out = {
        "off_axis": np.sqrt(1.0 + sx * sx + sy * sy),
        "vertex_distance": np.zeros(rows.size),
        "extent": np.zeros(rows.size),
        "height": np.zeros(rows.size),
        "plane_depth": np.full(rows.size, np.inf),
    }
    n = ref.scene.triangle_count
    for ids in prims:
        ok = ids.astype(np.uint64) < np.uint64(n)
        if not ok.any():
            continue
        tri = ref.scene.triangles[ids[ok].astype(np.int64)].astype(np.float64)  # (k, 3, 3)
        edges = np.linalg.norm(tri[:, [1, 2, 0]] - tri, axis=2)  # (k, 3)
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        twice_area = np.linalg.norm(normal, axis=1)
        with np.errstate(all="ignore"):
            height = np.where(edges.min(axis=1) > 0, twice_area / edges.min(axis=1), 0.0)
            t = np.einsum("ij,ij->i", normal, tri[:, 0] - eye) / np.einsum("ij,ij->i", normal, d[ok])
        for key, value in (
            ("vertex_distance", np.linalg.norm(tri - eye, axis=2).max(axis=1)),
            ("extent", edges.max(axis=1)),
            ("height", height),
        ):
            out[key][ok] = np.maximum(out[key][ok], value)
        # The moved edge point lies on the triangle: never nearer than its nearest vertex (a plane
        # seen edge-on may cross the pixel ray anywhere, far from the triangle).
        t = np.maximum(t, ((tri - eye) @ cam.forward).min(axis=1))
        out["plane_depth"][ok] = np.minimum(out["plane_depth"][ok], np.where(np.isfinite(t) & (t > 0), t, np.inf))
    return out


def per_triangle_terms(
    ref: Reference, model: tolerance.Model
) -> tuple[verify.EdgeTerms | None, verify.TriangleSlack | None]:
    """The model's per-edge band growth and per-triangle eye uncertainty (`Model.edge_products`,
    `Model.plane_move`) as the verifier asks for them: by triangle index and pixel, on this scene."""
    scene = ref.scene
    cam = scene.camera
    origin = np.asarray(cam.eye, dtype=np.float64).astype(np.float32).astype(np.float64)
    products, plane = model.edge_products, model.plane_move
    edge_terms: verify.EdgeTerms | None = None
    tri_slack: verify.TriangleSlack | None = None
    if products is not None:

        def edge_terms(prims: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
            tris = scene.triangles[np.asarray(prims, dtype=np.int64)].astype(np.float64)
            return products(tris, origin, cam.center_directions(rows, cols), cam.pixel_size())

    if plane is not None:

        def tri_slack(prims: np.ndarray) -> np.ndarray:
            return plane(scene.triangles[np.asarray(prims, dtype=np.int64)].astype(np.float64), origin)

    return edge_terms, tri_slack


def compare_ids(
    ref: Reference,
    test: Mapping[str, np.ndarray],
    model: tolerance.Model,
    edge_distance: EdgeDistance | None = None,
    depth_tol: verify.DepthTolerance | None = None,
    backend: str = "the test renderer",
    attrs: Mapping[str, Any] | None = None,
) -> IdResult:
    """Exact id.prim / id.object comparison; every mismatch gets a class (verify.py).

    With `edge_distance` (the metamorphic comparison, metamorphic.py, which also looks at
    the variant's scene) a mismatch is only edge (within `model.edge_px` of an edge
    involved) or interior. Otherwise the verifier classifies each mismatch as edge, tie,
    crack or interior, with the test renderer's per-pixel rounding distance
    (`model.edge_eps`) and depth tolerance `depth_tol` (for ties; default: exact).
    """
    rp, tp = ref.buffers["id.prim"], test["id.prim"]
    h, w = rp.shape
    mism = rp != tp
    idx = np.flatnonzero(mism)
    rows, cols = idx // w, idx % w
    r_ids, t_ids = rp.ravel()[idx], tp.ravel()[idx]
    n = ref.scene.triangle_count
    details: list[str] = []
    classes = np.full((h, w), -1, dtype=np.int8)
    explanations: list[dict[str, Any]] = []
    if edge_distance is not None:
        dist = edge_distance(r_ids, t_ids, rows, cols)
        invalid = (t_ids != BACKGROUND_ID) & (t_ids.astype(np.uint64) >= np.uint64(n))
        cls = np.where((dist <= model.edge_px) & ~invalid, verify.EDGE, verify.INTERIOR).astype(np.int8)
        tol_text = model.edge_text()
        bad = np.nonzero(cls == verify.INTERIOR)[0][:EXAMPLES]
        if invalid.any():
            details.append(f"{int(invalid.sum())} pixels carry IDs naming no triangle (scene has {n})")
        if bad.size:
            ex = ", ".join(
                f"({cols[k]},{rows[k]}) ref {_id(r_ids[k])} test {_id(t_ids[k])} d={_dist(dist[k])}" for k in bad
            )
            details.append(f"interior e.g. {ex}")
    else:
        zr = ref.buffers.get("Z")
        zt = test.get("Z")
        z_here = np.full(idx.size, np.inf)
        if zr is not None:
            z_here = zr.ravel()[idx].astype(np.float64)
        if zt is not None:
            zt_here = zt.ravel()[idx].astype(np.float64)
            z_here = np.where(np.isfinite(z_here), z_here, zt_here)
        tris = involved_triangles(ref, rows, cols, (r_ids, t_ids))
        # The edge that moved is on one of the two triangles, and a point moved by d shifts by d / z
        # on the image: the nearer one's depth at the pixel bounds both (its plane, from the scene).
        z_edge = np.minimum(np.where(np.isfinite(z_here), z_here, np.inf), tris["plane_depth"])
        z_edge = np.where(np.isfinite(z_edge), z_edge, z_here)
        ectx = tolerance.EdgeContext(
            z=z_edge,
            point_norm=point_norm(ref, rows, cols, z_here),
            pixel_size=pixel_size(ref),
            origin_offset=origin_offset(ref),
            eye_norm=eye_norm(ref),
            off_axis=tris["off_axis"],
            vertex_distance=tris["vertex_distance"],
            extent=tris["extent"],
            height=tris["height"],
            attrs=attrs or {},
        )
        eps, tol_text = model.edge_eps(ectx)

        def exact(z: np.ndarray, cos: np.ndarray, prims: np.ndarray) -> np.ndarray:
            return np.zeros_like(z)

        slack = model.eye_uncertainty(ectx.origin_offset, ectx.eye_norm, ectx.point_norm, ectx.attrs)
        result = verify.classify_mismatches(
            ref.scene,
            r_ids,
            t_ids,
            rows,
            cols,
            eps,
            depth_tol or exact,
            ref.topology_cache,
            backend,
            slack,
            *per_triangle_terms(ref, model),
        )
        cls = result.cls
        explanations = result.groups
        tol_text += (
            "; tie: both triangles cover the center and their depths agree within the sum of the depth tolerances "
            "on the two; crack: a leak through a closed edge (allowed only where the backend declares it)"
        )
        for name, cls_value in (("interior", verify.INTERIOR), ("crack", verify.CRACK)):
            shown = np.nonzero(cls == cls_value)[0][:EXAMPLES]
            if shown.size:
                details.append(
                    f"{name} e.g. "
                    + "; ".join(
                        f"({cols[k]},{rows[k]}) ref {_id(r_ids[k])} test {_id(t_ids[k])}: {result.why[k]}"
                        for k in shown
                    )
                )
    classes.ravel()[idx] = cls
    edge_mask = (classes == verify.EDGE) | (classes == verify.TIE) | (classes == verify.CRACK)
    interior_mask = classes == verify.INTERIOR
    # id.object must follow id.prim: where the prims agree the objects must too.
    if "id.object" in ref.buffers and "id.object" in test:
        obj_bad = ~mism & (ref.buffers["id.object"] != test["id.object"])
        if obj_bad.any():
            interior_mask |= obj_bad
            oi = np.flatnonzero(obj_bad)
            y, x = oi[0] // w, oi[0] % w
            details.append(
                f"{oi.size} pixels with the same id.prim but a different id.object, e.g. ({x},{y}) "
                f"ref {_id(ref.buffers['id.object'][y, x])} test {_id(test['id.object'][y, x])}"
            )
            explanations.insert(
                0,
                {
                    "class": vocab.MismatchClass.INTERIOR,
                    "ref_prim": None,
                    "test_prim": None,
                    "pixels": int(oi.size),
                    "example": [int(x), int(y)],
                    "why": f"same prim, different object id (ref {_id(ref.buffers['id.object'][y, x])}, "
                    f"test {_id(test['id.object'][y, x])}): the exporter or renderer mislabels objects",
                },
            )
        tol_text += "; id.object must match wherever id.prim does"
    else:
        tol_text += "; id.object not compared (missing on one side)"
    return IdResult(
        int(np.count_nonzero(classes == verify.EDGE)),
        int(interior_mask.sum()),
        edge_mask,
        interior_mask,
        tol_text,
        details,
        tie=int(np.count_nonzero(classes == verify.TIE)),
        crack=int(np.count_nonzero(classes == verify.CRACK)),
        classes=classes,
        explanations=explanations,
    )


def _id(v: Any) -> str:
    v = int(v)
    return "bg" if v == BACKGROUND_ID else str(v)


def _dist(d: float) -> str:
    return "inf" if not math.isfinite(d) else f"{d:.3g}px"
