"""The judges of the id, Z and N buffers (judge/ids.py, depth.py, normals.py) at their class
boundaries, on synthetic buffers, from both sides (issue 37 item 6, docs/mutation.md).

Scene: eye (0, 0, 4) looking down -z, vfov 90; the plane z = 0 is at planar depth 4 at every
pixel, where a world point (x, y) projects to px = 2x + 8, py = 8 - 2y (16 x 16 pixels).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fixtures import write_scene
from rendiff_harness.contract import resolved, vocab
from rendiff_harness.contract.manifest import Reference
from rendiff_harness.contract.results import Entry
from rendiff_harness.judge import depth, expectations, ids, normals, tolerance, verify
from rendiff_harness.renderers import registry

BG = vocab.BACKGROUND_ID
U = 2.0**-24
BIG = [[-20, -20, 0], [20, -20, 0], [0, 20, 0]]
LEFT = [[-20, -20, 0], [-1.5, -20, 0], [-1.5, 20, 0]]  # x <= -1.5: columns 0-4 (px < 5)
XY = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]  # normal +z, cond 1
SLIVER = [[0, 0, 0], [1, 0, 0], [1, 0.0625, 0]]  # normal +z, cond sqrt(1 + 1/256) * 16
YZ = [[0, 0, 0], [0, 1, 0], [0, 0, 1]]  # normal +x


def _ref(
    tmp_path: Path, tris: list[list[list[float]]], buffers: dict[str, np.ndarray], size: tuple[int, int] = (16, 16)
) -> Reference:
    h, w = size
    d = write_scene(tmp_path / "scene", tris, eye=(0.0, 0.0, 4.0), vfov_deg=90.0, width=w, height=h)
    return Reference(resolved.load(d), buffers, (h, w))


def _model(edge_px: float = 0.0, depth_tol: float = 0.0, **kw: Any) -> tolerance.Model:
    def dm(ctx: tolerance.DepthContext) -> tuple[np.ndarray, str]:
        return np.full(ctx.z_ref.shape, depth_tol), "D"

    return tolerance.Model("m", edge_px, "E", dm, **kw)


# =========================================================================== ids.py


def test_the_metamorphic_edge_band_is_closed_at_edge_px(tmp_path: Path) -> None:
    prim = np.zeros((2, 4), dtype=np.uint32)
    ref = _ref(tmp_path, [BIG], {"id.prim": prim}, size=(2, 4))
    test = prim.copy()
    test[0, 1] = BG  # distance 0.5: edge
    test[0, 2] = BG  # distance just above: interior
    test[1, 3] = 1  # names no triangle (the scene has 1), even at distance 0
    dist = {(0, 1): 0.5, (0, 2): float(np.nextafter(0.5, 1.0)), (1, 3): 0.0}
    calls: list[int] = []

    def edge_distance(r: np.ndarray, t: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        calls.append(r.size)
        assert r.tolist() == [0, 0, 0] and t.tolist() == [BG, BG, 1]
        return np.array([dist[(int(y), int(x))] for y, x in zip(rows, cols, strict=True)])

    res = ids.compare_ids(ref, {"id.prim": test}, _model(edge_px=0.5), edge_distance=edge_distance)
    assert calls == [3]
    assert res.explanations == []  # the metamorphic comparison explains nothing
    assert (res.edge, res.interior, res.tie, res.crack) == (1, 2, 0, 0)
    assert (
        res.classes is not None
        and res.classes.dtype == np.int8
        and res.classes.tolist()
        == [
            [-1, verify.EDGE, verify.INTERIOR, -1],
            [-1, -1, -1, verify.INTERIOR],
        ]
    )
    assert res.edge_mask.tolist() == [[False, True, False, False], [False] * 4]
    assert res.details == [
        "1 pixels carry IDs naming no triangle (scene has 1)",
        "interior e.g. (2,0) ref 0 test bg d=0.5px, (3,1) ref 0 test 1 d=0px",
    ]
    assert res.tolerance == (
        "edge: pixel center within 0.5 px of a triangle edge (E); id.object not compared (missing on one side)"
    )


def test_metamorphic_distances_print_inf_as_inf(tmp_path: Path) -> None:
    prim = np.zeros((1, 2), dtype=np.uint32)
    ref = _ref(tmp_path, [BIG], {"id.prim": prim}, size=(1, 2))
    test = np.array([[BG, 0]], dtype=np.uint32)
    res = ids.compare_ids(ref, {"id.prim": test}, _model(), edge_distance=lambda r, t, y, x: np.full(r.size, np.inf))
    assert res.details == ["interior e.g. (0,0) ref 0 test bg d=inf"]


def test_the_verifier_gets_the_renderers_eps_slack_and_depth_tolerance(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """eps at each pixel from the model's edge model at the reference's depth (else the test's),
    the eye uncertainty from its position error, the depth tolerance as given (else exact)."""
    prim = np.zeros((16, 16), dtype=np.uint32)
    z = np.full((16, 16), 4.0, dtype=np.float32)
    z[4, 6] = np.inf  # the reference saw nothing there ...
    prim[4, 6] = BG
    ref = _ref(tmp_path, [BIG, LEFT], {"id.prim": prim, "Z": z})
    test_prim, test_z = prim.copy(), z.copy()
    test_prim[4, 4] = 1
    test_prim[4, 6] = 0  # ... the test saw prim 0 at depth 3 (not on its plane: Z judges that)
    test_z[4, 6] = 3.0
    test_z[4, 4] = 4.5  # where both saw something, the reference's depth is the one used
    seen: dict[str, Any] = {}

    def extra(ctx: tolerance.EdgeContext) -> tuple[np.ndarray, str]:
        seen["edge"] = ctx
        return np.full(ctx.z.shape, 0.125), "X"

    def position(offset: float, eye: float, point: np.ndarray) -> np.ndarray:
        seen["position"] = (offset, eye, point.tolist())
        return point * 0.5

    real = verify.classify_mismatches

    def spy(*args: Any, **kw: Any) -> verify.Classified:
        seen["args"] = args
        return real(*args, **kw)

    monkeypatch.setattr(verify, "classify_mismatches", spy)
    eye = (0.0, 0.0, 4.0)
    res = ids.compare_ids(ref, {"id.prim": test_prim, "Z": test_z}, _model(0.25, edge_extra=extra, position=position))
    ctx = seen["edge"]
    assert ctx.z.tolist() == [4.0, 3.0]  # the reference's depth, else the test's
    d = ref.scene.camera.center_directions(np.array([4, 4]), np.array([4, 6]))
    expect_norm = np.linalg.norm(np.asarray(eye) + np.array([4.0, 3.0])[:, None] * d, axis=1)
    assert ctx.point_norm.tolist() == expect_norm.tolist()
    assert ctx.pixel_size == 2.0 / 16 and ctx.origin_offset == 0.0 and ctx.eye_norm == 4.0
    args = seen["args"]
    assert args[5].tolist() == [0.375, 0.375]  # eps = edge_px + extra
    assert args[6](np.array([4.0]), np.array([1.0]), np.array([0])).tolist() == [0.0]  # exact by default
    assert args[7] is ref.topology_cache and args[8] == "the test renderer"
    assert args[9] == max(expect_norm.tolist()) * 0.5  # the eye uncertainty: the largest position error
    assert seen["position"] == (0.0, 4.0, expect_norm.tolist())
    assert res.tolerance == (
        "edge: pixel center within 0.25 px of a triangle edge (E) + X; tie: both triangles cover the center and "
        "their depths agree within the sum of the depth tolerances on the two; crack: a leak through a closed edge "
        "(allowed only where the backend declares it); id.object not compared (missing on one side)"
    )


def test_origin_offset_eye_norm_and_point_norm(tmp_path: Path) -> None:
    d = write_scene(tmp_path / "s", [BIG], eye=(0.1, 0.0, 4.0), vfov_deg=90.0, width=4, height=4)
    ref = Reference(resolved.load(d), {}, (4, 4))
    assert ids.origin_offset(ref) == abs(float(np.float32(0.1)) - 0.1) > 0.0
    eye_norm = float(np.linalg.norm([0.1, 0.0, 4.0]))
    assert ids.eye_norm(ref) == eye_norm
    assert ids.pixel_size(ref) == 0.5
    rows, cols = np.array([0, 3]), np.array([1, 2])
    dirs = ref.scene.camera.center_directions(rows, cols)
    got = ids.point_norm(ref, rows, cols, np.array([2.0, np.inf]))
    assert got.tolist() == [float(np.linalg.norm(ref.scene.camera.eye + 2.0 * dirs[0])), eye_norm]


def test_classes_counts_and_masks_of_the_verifier_path(tmp_path: Path) -> None:
    """One pixel of each class, counted once, and edge, tie and crack all allowed by the mask."""
    a = [[-3, 0, 0], [3, 0, 0], [0, 3, 0]]
    b = [[3, 0, 0], [-3, 0, 0], [0, -3, 0]]
    dup = a
    prim = np.full((16, 16), BG, dtype=np.uint32)
    prim[7, 8] = 0  # center (8.5, 7.5): 0.5 px above the shared edge y = 0
    prim[5, 8] = 0  # center (8.5, 5.5): inside a, 2.5 px above the edge
    ref = _ref(tmp_path, [a, b, dup], {"id.prim": prim})
    test = prim.copy()
    test[7, 8] = 1  # across the shared edge: edge
    test[5, 8] = 2  # the duplicate: tie
    test[6, 8] = 0  # the reference saw background 1.5 px inside a, 1.5 px from its edge y = 0: interior
    test[4, 8] = 0  # ... and 1.41 px from a's slanted edge: interior too
    res = ids.compare_ids(ref, {"id.prim": test}, _model(0.5))
    assert (res.edge, res.tie, res.crack, res.interior) == (1, 1, 0, 2)
    allowed = np.zeros((16, 16), dtype=bool)
    allowed[7, 8] = allowed[5, 8] = True
    assert np.array_equal(res.edge_mask, allowed)
    assert res.interior_mask.sum() == 2 and res.interior_mask[6, 8] and res.interior_mask[4, 8]
    assert res.details == [
        "interior e.g. (8,4) ref bg test 0: center 1.41 px inside the boundary of prim 0 (allowed 0.5 px); the "
        "reference saw background: interior; (8,6) ref bg test 0: center 1.5 px inside the boundary of prim 0 "
        "(allowed 0.5 px); the reference saw background: interior"
    ]
    # A crack: the test saw the background through the closed edge, 0.5 px from it.
    prim[7, 9] = 0  # center (9.5, 7.5): 0.5 px above the shared edge too
    ref = _ref(tmp_path / "two", [a, b, dup], {"id.prim": prim})
    test2 = prim.copy()
    test2[7, 8] = test2[7, 9] = BG
    res = ids.compare_ids(ref, {"id.prim": test2}, _model(0.5))
    assert (res.edge, res.tie, res.crack, res.interior) == (0, 0, 2, 0)
    assert res.edge_mask[7, 8] and not res.interior_mask.any()
    why = (
        "center 0.5 px from the closed edge prim 0 shares with prim 1, and no outline within 0.5 px, but the test "
        "renderer saw background behind it: crack"
    )
    assert res.details == [f"crack e.g. (8,7) ref 0 test bg: {why}; (9,7) ref 0 test bg: {why}"]


def test_object_ids_must_follow_prim_ids(tmp_path: Path) -> None:
    prim = np.zeros((2, 3), dtype=np.uint32)
    obj = np.zeros((2, 3), dtype=np.uint32)
    ref = _ref(tmp_path, [BIG], {"id.prim": prim, "id.object": obj}, size=(2, 3))
    t_obj = obj.copy()
    t_obj[1, 2] = 5
    t_obj[0, 1] = BG
    res = ids.compare_ids(ref, {"id.prim": prim.copy(), "id.object": t_obj}, _model())
    assert res.interior == 2 and res.interior_mask.tolist() == [[False, True, False], [False, False, True]]
    assert res.details == ["2 pixels with the same id.prim but a different id.object, e.g. (1,0) ref 0 test bg"]
    assert res.explanations == [
        {
            "class": "interior",
            "ref_prim": None,
            "test_prim": None,
            "pixels": 2,
            "example": [1, 0],
            "why": "same prim, different object id (ref 0, test bg): the exporter or renderer mislabels objects",
        }
    ]
    assert res.tolerance.endswith("; id.object must match wherever id.prim does")
    assert res.tolerance == (
        "edge: pixel center within 0 px of a triangle edge (E); tie: both triangles cover the center and their depths "
        "agree within the sum of the depth tolerances on the two; crack: a leak through a closed edge (allowed "
        "only where the backend declares it); id.object must match wherever id.prim does"
    )
    # Where the prims differ, the objects may too: judged by the prim's class alone; an object
    # mismatch elsewhere adds to it, and its explanation comes first.
    t_prim = prim.copy()
    t_prim[0, 0] = BG
    res = ids.compare_ids(ref, {"id.prim": t_prim, "id.object": obj.copy()}, _model())
    assert res.interior == 1 and res.explanations[0]["class"] == "interior" and res.explanations[0]["ref_prim"] == 0
    res = ids.compare_ids(ref, {"id.prim": t_prim, "id.object": t_obj}, _model())
    assert res.interior == 3 and res.interior_mask.tolist() == [[True, True, False], [False, False, True]]
    assert [g["ref_prim"] for g in res.explanations] == [None, 0]
    # The reference without id.object: not compared, whatever the test wrote.
    ref2 = Reference(ref.scene, {"id.prim": prim}, (2, 3))
    res = ids.compare_ids(ref2, {"id.prim": prim.copy(), "id.object": t_obj}, _model())
    assert res.interior == 0 and res.tolerance.endswith("; id.object not compared (missing on one side)")
    res = ids.compare_ids(ref2, {"id.prim": prim.copy(), "id.object": t_obj}, _model(), edge_distance=lambda *a: a[0])
    assert res.explanations == [] and res.tolerance.endswith("; id.object not compared (missing on one side)")


# =========================================================================== depth.py


def _depth(
    ref: Reference,
    test: dict[str, np.ndarray],
    model: tolerance.Model,
    classes: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    own_plane: bool = False,
) -> depth.DepthResult:
    return depth.compare_depth(ref, test, model, {"info": {}}, {}, mask, classes, own_plane=own_plane)


def test_a_hit_miss_mismatch_takes_the_class_of_its_id_mismatch(tmp_path: Path) -> None:
    z = np.full((1, 5), 4.0, dtype=np.float32)
    prim = np.zeros((1, 5), dtype=np.uint32)
    ref = _ref(tmp_path, [BIG], {"Z": z, "id.prim": prim}, size=(1, 5))
    tz = z.copy()
    tz[0, :] = np.inf  # every pixel missed by the test
    tp = np.full((1, 5), BG, dtype=np.uint32)
    classes = np.array([[verify.EDGE, verify.TIE, verify.CRACK, verify.INTERIOR, -1]], dtype=np.int8)
    res = _depth(ref, {"Z": tz, "id.prim": tp}, _model(), classes, own_plane=True)
    assert (res.mask, res.edge, res.tie, res.crack, res.interior, res.compared) == (5, 1, 1, 1, 2, 0)
    assert res.own_plane == 0  # a hit/miss mismatch has no depth of the test's to judge
    assert res.details == ["hit/miss mask mismatches e.g. (3,0) ref 4 test inf, (4,0) ref 4 test inf"]
    # Without the verifier's classes: the allowed mask alone (the metamorphic comparison) ...
    allowed = np.array([[True, False, False, False, True]])
    res = _depth(ref, {"Z": tz, "id.prim": tp}, _model(), mask=allowed)
    assert (res.edge, res.tie, res.crack, res.interior) == (2, 0, 0, 3)
    # ... and without either, every mask mismatch is interior.
    res = _depth(ref, {"Z": tz, "id.prim": tp}, _model())
    assert (res.edge, res.interior) == (0, 5)
    # NaN is a hit with a wrong depth, never background.
    tz[0, :] = np.nan
    res = _depth(ref, {"Z": tz, "id.prim": prim.copy()}, _model())
    assert res.mask == 0 and res.interior == 5 and res.compared == 5


def test_same_prim_depth_is_within_the_model_inclusive(tmp_path: Path) -> None:
    z = np.full((1, 3), 4.0, dtype=np.float32)
    prim = np.zeros((1, 3), dtype=np.uint32)
    ref = _ref(tmp_path, [BIG], {"Z": z, "id.prim": prim}, size=(1, 3))
    tz = z.copy()
    tz[0, 1] = 4.5  # |dZ| 0.5: at the tolerance
    tz[0, 2] = 4.5  # ... and then the tolerance just below it
    res = _depth(ref, {"Z": tz, "id.prim": prim.copy()}, _model(depth_tol=0.5))
    assert (res.interior, res.compared, res.max_abs, res.max_rel) == (0, 3, 0.5, 0.125)
    assert res.mean_abs == pytest.approx(1.0 / 3.0, rel=1e-15)
    res = _depth(ref, {"Z": tz, "id.prim": prim.copy()}, _model(depth_tol=float(np.nextafter(0.5, 0.0))))
    assert res.interior == 2
    assert res.details == [
        "2 depths beyond tolerance, worst (1,0) ref 4 test 4.5 |d| 0.5 > tol 0.5, "
        "(2,0) ref 4 test 4.5 |d| 0.5 > tol 0.5"
    ]
    assert res.tolerance == (
        "D; compared where both hit the same prim; hit/miss masks exact except where the ID mismatch is an allowed "
        "class (edge, tie; crack only where declared)"
    )


def test_same_prim_failures_are_listed_worst_first(tmp_path: Path) -> None:
    """By |dZ| over the tolerance, which grows with |cos| here: column 2 (oblique) before column 1."""
    z = np.full((1, 3), 4.0, dtype=np.float32)
    prim = np.zeros((1, 3), dtype=np.uint32)
    ref = _ref(tmp_path, [BIG], {"Z": z, "id.prim": prim}, size=(1, 3))
    tz = z.copy()
    tz[0, 1:] = 4.5

    def by_cos(ctx: tolerance.DepthContext) -> tuple[np.ndarray, str]:
        return 0.1 * ctx.cos, "D"

    res = _depth(ref, {"Z": tz, "id.prim": prim.copy()}, tolerance.Model("m", 0, "", by_cos))
    worst = res.details[-1].split("worst ")[1]
    assert worst.startswith("(2,0) ref 4 test 4.5 |d| 0.5 > tol 0.0") and ", (1,0) ref 4 test 4.5" in worst


def test_a_zero_reference_depth_has_a_relative_error_only_when_they_differ(tmp_path: Path) -> None:
    z = np.zeros((1, 2), dtype=np.float32)
    prim = np.zeros((1, 2), dtype=np.uint32)
    ref = _ref(tmp_path, [BIG], {"Z": z, "id.prim": prim}, size=(1, 2))
    res = _depth(ref, {"Z": z.copy(), "id.prim": prim.copy()}, _model())
    assert res.max_rel == 0.0 and res.max_abs == 0.0
    tz = z.copy()
    tz[0, 1] = 1.0
    assert _depth(ref, {"Z": tz, "id.prim": prim.copy()}, _model(depth_tol=2.0)).max_rel == math.inf


def test_the_depth_model_sees_the_triangles_cos_extent_and_span(tmp_path: Path) -> None:
    tilted = [[-20, -20, -2], [20, -20, -2], [0, 20, 1]]  # depths 6, 6 and 3: span 3
    z = np.full((1, 1), 4.0, dtype=np.float32)
    prim = np.zeros((1, 1), dtype=np.uint32)
    ref = _ref(tmp_path, [tilted], {"Z": z, "id.prim": prim}, size=(1, 1))
    seen: list[tolerance.DepthContext] = []

    def dm(ctx: tolerance.DepthContext) -> tuple[np.ndarray, str]:
        seen.append(ctx)
        return np.zeros(ctx.z_ref.shape), "D"

    model = tolerance.Model("m", 0.0, "E", dm)
    depth.compare_depth(ref, {"Z": z.copy(), "id.prim": prim.copy()}, model, {"info": {"k": 1}}, {"a": 2}, None)
    ctx = seen[0]
    assert ctx.z_ref.tolist() == [4.0] and ctx.info == {"k": 1} and ctx.attrs == {"a": 2}
    assert ctx.cos.tolist() == ref.ray_cos(np.array([0]), np.array([0]), np.array([0])).tolist()
    assert 0.0 < ctx.cos[0] < 1.0
    assert ctx.extent is not None and ctx.extent.tolist() == [float(np.linalg.norm([20, 40, 3]))]
    assert ctx.depth_span is not None and ctx.depth_span.tolist() == [3.0]
    assert ctx.pixel_size == 2.0 and ctx.eye_norm == 4.0 and ctx.origin_offset == 0.0
    assert (
        ctx.point_norm is not None
        and ctx.point_norm.tolist() == ids.point_norm(ref, np.array([0]), np.array([0]), np.array([4.0])).tolist()
    )
    # Without the reference's ids: the worst angle, and the text says why.
    seen.clear()
    ref2 = Reference(ref.scene, {"Z": z}, (1, 1))
    res = depth.compare_depth(ref2, {"Z": z.copy()}, model, {"info": {}}, {}, None)
    assert seen[0].cos.tolist() == [0.0] and seen[0].extent is None and seen[0].depth_span is None
    assert res.tolerance.endswith("; reference has no id.prim: grazing factor at its cap")
    assert "compared where both hit (no id.prim on the test side: prims not checked)" in res.tolerance


def test_pixels_of_another_prim_are_judged_on_the_tests_own_plane_inclusive(tmp_path: Path) -> None:
    """Own plane: |Z_test - f32(planar depth of its triangle)| <= the model, judged only when asked."""
    z = np.full((1, 3), 4.0, dtype=np.float32)
    prim = np.zeros((1, 3), dtype=np.uint32)
    ref = _ref(tmp_path, [BIG, BIG], {"Z": z, "id.prim": prim}, size=(1, 3))
    tp = prim.copy()
    tp[0, :] = 1  # the duplicate everywhere
    tz = z.copy()
    tz[0, 0] = 4.0
    tz[0, 1] = 4.5
    tz[0, 2] = 4.5
    res = _depth(ref, {"Z": tz, "id.prim": tp}, _model(depth_tol=0.5), own_plane=True)
    assert (res.own_plane, res.own_plane_beyond, res.own_plane_max_abs, res.interior) == (3, 0, 0.5, 0)
    assert (res.compared, res.max_abs, res.mean_abs, res.max_rel) == (0, 0.0, 0.0, 0.0)
    res = _depth(ref, {"Z": tz, "id.prim": tp}, _model(depth_tol=float(np.nextafter(0.5, 0))), own_plane=True)
    assert (res.own_plane, res.own_plane_beyond, res.interior) == (3, 2, 2)
    assert res.details == [
        "2 depths off their own triangle's plane (where the test sees another prim than the reference), worst "
        "(1,0) prim 1 plane 4 test 4.5 |d| 0.5 > tol 0.5, (2,0) prim 1 plane 4 test 4.5 |d| 0.5 > tol 0.5"
    ]
    assert "(3 pixels)" in res.tolerance
    # Not asked (the metamorphic comparison, and the default): nothing judged on its own plane.
    res = _depth(ref, {"Z": tz, "id.prim": tp}, _model(), own_plane=False)
    assert (res.own_plane, res.interior, res.not_comparable, res.own_plane_max_abs) == (0, 0, {}, 0.0)
    res = depth.compare_depth(ref, {"Z": tz, "id.prim": tp}, _model(), {"info": {}}, {}, None)
    assert res.own_plane == 0
    # The worst first: by |d| over the tolerance, which grows with |cos| here (largest at column 1,
    # the one whose ray is nearest the plane's normal).
    tz[0, 1] = 4.5
    tz[0, 2] = 4.5

    def by_cos(ctx: tolerance.DepthContext) -> tuple[np.ndarray, str]:
        return 0.1 * ctx.cos, "D"

    own = depth.own_plane_depths(
        ref,
        {"Z": tz, "id.prim": tp},
        np.ones((1, 3), bool),
        np.zeros((1, 3), bool),
        tolerance.Model("m", 0, "", by_cos),
        {},
        {},
    )
    assert own.details[0].split("worst ")[1].startswith("(2,0) prim 1 plane 4 test 4.5 |d| 0.5 > tol 0.0")
    assert ", (1,0) prim 1 plane 4 test 4.5 |d| 0.5 > tol 0.1" in own.details[0]
    assert own.tolerance == "D" and own.max_abs == 0.5 and own.beyond.tolist() == [1, 2]


def test_own_plane_depth_is_the_planes_depth_rounded_to_f32(tmp_path: Path) -> None:
    """A tilted triangle, the test's depth solved here as a ray-triangle system (not the judge's
    formula) and stored in f32: exact models pass it; 1e-3 more fails; its depth 0.5 (< 1) is judged;
    a plane through the eye (depth 0) and one along the ray are not comparable."""
    tilted = [[-8.0, -8.0, -1.0], [8.0, -8.0, 0.3], [0.0, 8.0, 1.7]]
    near = [[-20, -20, 3.5], [20, -20, 3.5], [0, 20, 3.5]]  # depth 0.5
    through = [[-20, 0, -20], [20, 0, -20], [0, 0, 20]]  # the plane y = 0 holds the eye
    ref = _ref(tmp_path, [BIG, tilted, near, through], {}, size=(2, 2))
    cam = ref.scene.camera
    rows, cols = np.array([0, 0, 1, 1]), np.array([0, 1, 0, 1])
    d = cam.center_directions(rows, cols)
    t = ref.scene.triangles[1].astype(np.float64)
    depths = []
    for k in range(2):  # eye + z d = a + u (b - a) + v (c - a)
        m = np.stack([d[k], t[0] - t[1], t[0] - t[2]], axis=1)
        depths.append(np.linalg.solve(m, t[0] - cam.eye)[0])
    z = np.full((2, 2), 4.0, dtype=np.float32)
    prim = np.zeros((2, 2), dtype=np.uint32)
    tz = np.array([[depths[0], depths[1]], [0.5, 4.0]], dtype=np.float32)
    tp = np.array([[1, 1], [2, 3]], dtype=np.uint32)
    ref = Reference(ref.scene, {"Z": z, "id.prim": prim}, (2, 2))
    res = _depth(ref, {"Z": tz, "id.prim": tp}, _model(), own_plane=True)
    assert (res.own_plane, res.own_plane_beyond, res.interior) == (3, 0, 0)
    assert res.not_comparable == {"the pixel ray runs along (or away from) the test's triangle's plane": 1}
    tz[0, 1] += np.float32(1e-3)
    res = _depth(ref, {"Z": tz, "id.prim": tp}, _model(), own_plane=True)
    assert (res.own_plane_beyond, res.interior) == (1, 1)


def test_a_ray_along_the_tests_plane_is_not_comparable_and_quiet(tmp_path: Path) -> None:
    """One pixel, its ray (0, 0, -1) along the plane x = 1: n . d = 0, no depth, no warning."""
    wall = [[1, -5, -5], [1, 5, -5], [1, 0, 5]]
    z = np.full((1, 1), 4.0, dtype=np.float32)
    ref = _ref(tmp_path, [BIG, wall], {"Z": z, "id.prim": np.zeros((1, 1), np.uint32)}, size=(1, 1))
    res = _depth(ref, {"Z": z.copy(), "id.prim": np.ones((1, 1), np.uint32)}, _model(), own_plane=True)
    assert res.not_comparable == {"the pixel ray runs along (or away from) the test's triangle's plane": 1}


def test_same_prim_pixels_need_a_valid_reference_prim(tmp_path: Path) -> None:
    """Depth is compared where both hit the same valid prim; without the test's ids, where both hit
    and the reference names a valid prim; a reference without ids compares every common hit."""
    z = np.full((1, 4), 4.0, dtype=np.float32)
    rp = np.array([[0, BG, 1, 0]], dtype=np.uint32)  # 1: one past the last triangle
    ref = _ref(tmp_path, [BIG], {"Z": z, "id.prim": rp}, size=(1, 4))
    tz = z.copy()
    tz[0, 3] = np.inf  # the test missed there
    res = _depth(ref, {"Z": tz, "id.prim": rp.copy()}, _model())
    assert (res.compared, res.mask, res.interior) == (1, 1, 1)
    res = _depth(ref, {"Z": tz}, _model())
    assert (res.compared, res.mask, res.interior) == (1, 1, 1)
    assert "compared where both hit (no id.prim on the test side: prims not checked)" in res.tolerance
    ref2 = Reference(ref.scene, {"Z": z}, (1, 4))
    res = _depth(ref2, {"Z": tz, "id.prim": rp.copy()}, _model())
    assert (res.compared, res.mask) == (3, 1)


def test_own_plane_pixels_that_cannot_be_judged_are_counted_by_reason(tmp_path: Path) -> None:
    behind = [[-20, -20, 8], [20, -20, 8], [0, 20, 8]]  # its plane is behind the eye
    z = np.full((1, 4), 4.0, dtype=np.float32)
    prim = np.zeros((1, 4), dtype=np.uint32)
    ref = _ref(tmp_path, [BIG, behind], {"Z": z, "id.prim": prim}, size=(1, 4))
    tp = np.array([[2, 1, 1, 0]], dtype=np.uint32)  # 2: one past the last triangle
    res = _depth(ref, {"Z": z.copy(), "id.prim": tp}, _model(), own_plane=True)
    assert res.not_comparable == {
        "the pixel ray runs along (or away from) the test's triangle's plane": 2,
        "the test's id.prim names no triangle of the scene": 1,
    }
    assert res.own_plane == 0 and res.interior == 0
    assert res.tolerance.endswith(
        "; not comparable: the pixel ray runs along (or away from) the test's triangle's plane (2 px), "
        "the test's id.prim names no triangle of the scene (1 px)"
    )
    own = depth.own_plane_depths(ref, {"Z": z}, np.ones((1, 4), bool), np.zeros((1, 4), bool), _model(), {}, {})
    assert own.not_comparable == {"the test wrote no id.prim: its triangle there is unknown": 4}
    assert (own.idx.size, own.beyond.size, own.max_abs, own.details, own.tolerance) == (0, 0, 0.0, [], "")
    own = depth.own_plane_depths(ref, {"Z": z}, np.ones((1, 4), bool), np.ones((1, 4), bool), _model(), {}, {})
    assert own.not_comparable == {}


def test_the_tie_tolerance_is_the_models_depth_at_z_and_cos(tmp_path: Path) -> None:
    d = write_scene(tmp_path / "s", [BIG], eye=(0.1, 0.0, 4.0), vfov_deg=90.0, width=4, height=4)
    ref = Reference(resolved.load(d), {}, (4, 4))
    eye = float(np.linalg.norm([0.1, 0.0, 4.0]))
    seen: list[tolerance.DepthContext] = []

    def dm(ctx: tolerance.DepthContext) -> tuple[np.ndarray, str]:
        seen.append(ctx)
        return ctx.z_ref * ctx.cos, "D"

    fn = depth.depth_tolerance_fn(ref, tolerance.Model("m", 0.0, "", dm), {"info": {"q": 1}}, {"a": 1})
    assert fn(np.array([-2.0, 3.0]), np.array([0.5, 0.25]), np.array([0, 0])).tolist() == [-1.0, 0.75]
    ctx = seen[0]
    # The triangle's own extent and depth span, as the depth verdict's context has them: an
    # edge-on triangle's bound is min(e/|cos|, span), not the fixed cap (docs/verifier.md).
    extent, span = depth.triangle_extent_span(ref, np.array([0, 0]))
    assert ctx.extent is not None and ctx.extent.tolist() == extent.tolist()
    assert ctx.depth_span is not None and ctx.depth_span.tolist() == span.tolist()
    assert ctx.point_norm is not None and ctx.point_norm.tolist() == [2.0 + eye, 3.0 + eye]  # |z| + |eye|
    ctx2 = depth.depth_context(ref, np.array([0]), np.array([0]), np.array([4.0]), np.array([0]), {}, {})
    assert ctx2.origin_offset == ids.origin_offset(ref) > 0.0
    assert (ctx.pixel_size, ctx.eye_norm, ctx.info, ctx.attrs) == (0.5, eye, {"q": 1}, {"a": 1})
    assert ctx.origin_offset == ids.origin_offset(ref) > 0.0

    def broken(ctx: tolerance.DepthContext) -> tuple[np.ndarray, str]:
        raise tolerance.ToleranceError("no")

    fn = depth.depth_tolerance_fn(ref, tolerance.Model("m", 0.0, "", broken), {}, {})
    assert fn(np.array([2.0, 3.0]), np.array([1.0, 1.0]), np.array([0, 0])).tolist() == [0.0, 0.0]
    const = depth.depth_tolerance_fn(ref, _model(depth_tol=0.25), {}, {})
    assert const(np.array([2.0, 3.0]), np.array([1.0, 1.0]), np.array([0, 0])).tolist() == [0.25, 0.25]


def test_the_depth_models_get_each_pixel_rays_length_and_the_tie_test_the_longest(tmp_path: Path) -> None:
    """Embree's f32-direction term scales with |d| of the pixel ray: the depth verdict's context
    carries each compared pixel's, the tie test (not told the pixel) the longest of the image."""
    d = write_scene(tmp_path / "s", [BIG], eye=(0.1, 0.0, 4.0), vfov_deg=70.0, width=7, height=3)
    ref = Reference(resolved.load(d), {}, (3, 7))
    seen: list[tolerance.DepthContext] = []

    def dm(ctx: tolerance.DepthContext) -> tuple[np.ndarray, str]:
        seen.append(ctx)
        return np.zeros_like(ctx.z_ref), "D"

    rows, cols = np.array([0, 1, 2, 2]), np.array([0, 3, 4, 1])
    ctx = depth.depth_context(ref, rows, cols, np.full(4, 4.0), np.zeros(4, dtype=np.int64), {}, {})
    each = np.linalg.norm(ref.scene.camera.center_directions(rows, cols), axis=1)
    assert ctx.ray_norm is not None and np.asarray(ctx.ray_norm).tolist() == each.tolist()
    assert len(set(each.tolist())) == 4  # four different lengths: no pixel stands in for another
    depth.depth_tolerance_fn(ref, tolerance.Model("m", 0.0, "", dm), {}, {})(
        np.array([4.0]), np.array([1.0]), np.array([0])
    )
    every = np.linalg.norm(ref.scene.camera.pixel_directions(), axis=-1)
    assert seen[-1].ray_norm == float(every.max()) and every.max() > every.min()


def test_the_radial_hint_needs_nine_in_ten(tmp_path: Path) -> None:
    ref = _ref(tmp_path, [BIG], {}, size=(1, 10))
    rows, cols = np.zeros(10, dtype=np.int64), np.arange(10)
    dn = np.linalg.norm(ref.scene.camera.center_directions(rows, cols), axis=1)
    z_ref = np.full(10, 4.0)
    tol = np.full(10, 1e-6)
    beyond = np.ones(10, dtype=bool)
    radial = z_ref * dn
    for n_radial, said in ((9, True), (8, False)):
        z_test = np.where(np.arange(10) < n_radial, radial, z_ref + 1.0)
        hint = depth.radial_hint(ref, rows, cols, z_ref, z_test, tol, beyond)
        assert bool(hint) == said
    z_test = np.where(np.arange(10) < 9, radial, z_ref + 1.0)
    assert depth.radial_hint(ref, rows, cols, z_ref, z_test, tol, beyond) == (
        "9 of the 10 depths beyond tolerance equal the radial distance from the eye (Z |d|), not the planar depth "
        "the contract asks for (docs/DESIGN.md, Buffers)"
    )
    assert depth.radial_hint(ref, rows, cols, z_ref, z_test, tol, np.zeros(10, dtype=bool)) == ""
    # Radial within the tolerance scaled along the ray, tol |d|: 0.9 of it still counts.
    near_radial = np.where(np.arange(10) < 9, radial + 0.9 * tol * dn, z_ref + 1.0)
    assert depth.radial_hint(ref, rows, cols, z_ref, near_radial, tol, beyond).startswith("9 of the 10")
    assert (dn[:9] > 1.06).sum() >= 2  # where tol / |d| would be too narrow
    # Only the pixels beyond tolerance count: 9 radial of 9 beyond.
    only = np.arange(10) < 9
    assert depth.radial_hint(ref, rows, cols, z_ref, z_test, tol, only).startswith("9 of the 9 depths")


# =========================================================================== normals.py


def _normals(
    tmp_path: Path, tris: list[list[list[float]]], n: np.ndarray, prim: np.ndarray, spec_name: str | None = "raster"
) -> tuple[Entry, Any]:
    h, w = prim.shape
    ref = _ref(tmp_path, tris, {}, size=(h, w))
    e = Entry.for_render("s", "b", vocab.Buffer.N, {}, normals.N_FIELDS)
    spec = registry.spec(spec_name) if spec_name else None
    judged = normals.judge_normals(ref, "b", {"N": n, "id.prim": prim}, e, spec)
    return e, judged


def _rot(angle: float) -> list[float]:
    """+z turned by `angle` towards +x."""
    return [math.sin(angle), 0.0, math.cos(angle)]


def test_the_normal_angle_band_and_the_models_cond(tmp_path: Path) -> None:
    """Without a spec, f32 arithmetic: angle <= 8u cond + 6u, cond = |e1||e2| / |e1 x e2| of each prim."""
    cond = {0: 1.0, 1: math.sqrt(1 + 1 / 256) * 16}
    tol = {k: 8 * U * c + 6 * U for k, c in cond.items()}
    prim = np.array([[0, 1]], dtype=np.uint32)
    for factor, bad in ((0.9, 0), (1.1, 2)):
        n = np.array([[_rot(factor * tol[0]), _rot(factor * tol[1])]])
        e, _ = _normals(tmp_path / str(factor), [XY, SLIVER], n, prim, spec_name=None)
        assert (e.interior_mismatches, e.compared_pixels) == (bad, 2), factor
        assert e.max_angle_rad == pytest.approx(factor * tol[1], rel=1e-9)
    # The sliver's own room is not the right triangle's: 0.9 of the sliver's fails on prim 0.
    n = np.array([[_rot(0.9 * tol[1]), _rot(0.9 * tol[1])]])
    e, _ = _normals(tmp_path / "swap", [XY, SLIVER], n, prim, spec_name=None)
    assert e.interior_mismatches == 1


def test_cond_is_the_product_of_the_edge_lengths_over_the_cross(tmp_path: Path) -> None:
    """|e1| = 1, |e2| = 4 at a right angle: cond = 1, the f32 model allows 14u; 10u passes."""
    tall = [[0, 0, 0], [1, 0, 0], [0, 4, 0]]
    e, _ = _normals(tmp_path, [tall], np.array([[_rot(10 * U)]]), np.array([[0]], dtype=np.uint32), spec_name=None)
    assert e.interior_mismatches == 0


def test_the_angle_of_a_normal_that_is_not_unit_is_its_direction(tmp_path: Path) -> None:
    """|N| = 0.5 fails the unit test, and the angle recorded is the direction's own (0.3 rad)."""
    n = np.array([[[0.5 * c for c in _rot(0.3)]]])
    e, _ = _normals(tmp_path, [XY], n, np.array([[0]], dtype=np.uint32))
    assert e.interior_mismatches == 1 and e.max_angle_rad == pytest.approx(0.3, abs=1e-12)


def test_a_spec_brings_its_own_normal_model(tmp_path: Path) -> None:
    """raster's N is the f64 cross product rounded once (4u): 5u fails there, passes the f32 model."""
    prim = np.array([[0]], dtype=np.uint32)
    n = np.array([[_rot(5 * U)]])
    assert _normals(tmp_path / "r", [XY], n, prim)[0].interior_mismatches == 1
    assert _normals(tmp_path / "f", [XY], n, prim, spec_name=None)[0].interior_mismatches == 0


def test_the_unit_length_band_is_four_u_plus_the_angle_model(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """With a model that allows no angle: |N| = 1 + 4u passes, anything longer fails; exact passes."""
    monkeypatch.setattr(normals.precision, "normal_tolerance", lambda spec, cond: (np.zeros(cond.shape), "zero"))
    prim = np.array([[0, 0, 0]], dtype=np.uint32)
    n = np.array([[[1.0 + 4 * U, 0.0, 0.0], [1.0 + 4 * U + 2.0**-50, 0.0, 0.0], [1.0, 0.0, 0.0]]])
    e, _ = _normals(tmp_path, [YZ], n, prim)
    assert e.interior_mismatches == 1 and e.max_angle_rad == 0.0
    assert e.tolerance == "N: zero; |N| = 1 within 4 * 2^-24; facing per the winding (b-a) x (c-a)"


def test_normal_failures_are_counted_and_explained(tmp_path: Path) -> None:
    prim = np.array([[0, 0, 0], [0, BG, 2]], dtype=np.uint32)
    nan = math.nan
    n = np.array(
        [
            [[0, 0, 1], [0, 0, -1], [0, 0, 0]],  # exact, flipped, zero
            [[1, 0, 0], [0, 0, 1], [nan, nan, nan]],  # perpendicular, background (not judged), not finite
        ],
        dtype=np.float64,
    )
    e, judged = _normals(tmp_path, [XY, SLIVER, YZ], n, prim)
    assert (e.compared_pixels, e.interior_mismatches, e.max_angle_rad) == (5, 4, math.pi)
    assert judged.details == [
        "4 normals off, 1 of them facing the other way, 2 zero or not finite (angle shown as pi); e.g. "
        "(1,0) prim 0 angle 3.14 rad (tol 2.4e-07), (2,0) prim 0 angle 3.14 rad (tol 2.4e-07), "
        "(0,1) prim 0 angle 1.57 rad (tol 2.4e-07)"
    ]
    assert e.explanations == [
        {
            "class": "interior",
            "ref_prim": 0,
            "test_prim": 0,
            "pixels": 4,
            "example": [1, 0],
            "why": "N is 3.14 rad from normalize((b-a) x (c-a)) of the prim it names (flipped)",
        }
    ]
    # The first failure a zero vector; then one merely perpendicular, and one short but not zero.
    n2 = n.copy()
    n2[0, 1] = [0, 0, 0]
    n2[0, 2] = [0, 0, 2]  # the second failure: twice too long
    e, judged = _normals(tmp_path / "zero", [XY, SLIVER, YZ], n2, prim)
    assert e.explanations is not None
    assert e.explanations[0]["why"] == "N is the zero vector or not finite (|N| = 0), not normalize((b-a) x (c-a))"
    assert judged.details[0].startswith("4 normals off, 0 of them facing the other way, 2 zero or not finite")
    n3 = np.zeros((1, 2, 3))
    n3[0, 0] = [1, 0, 0]
    n3[0, 1] = [0, 0, 0.5]
    e, judged = _normals(tmp_path / "perp", [XY], n3, np.array([[0, 0]], dtype=np.uint32))
    assert e.explanations is not None
    assert e.explanations[0]["why"] == "N is 1.57 rad from normalize((b-a) x (c-a)) of the prim it names"
    assert judged.details[0].startswith("2 normals off, 0 of them facing the other way, 0 zero or not finite")


@pytest.mark.parametrize(("spec", "bad"), [("raster", 1), (None, 0)])
def test_a_degenerate_triangle_has_no_normal_to_match(tmp_path: Path, spec: str | None, bad: int) -> None:
    """|e1 x e2| = 0: no direction to match, the angle is recorded as pi. The core (f64 cross
    product) fails it; in f32 arithmetic the rounded cross product of a degenerate triangle may
    point anywhere, and the f32 model's room, 8u cond with cond infinite, says so."""
    line = [[0, 0, 0], [1, 0, 0], [2, 0, 0]]
    e, _ = _normals(tmp_path, [line], np.array([[[0.0, 0.0, 1.0]]]), np.array([[0]], dtype=np.uint32), spec)
    assert (e.interior_mismatches, e.max_angle_rad) == (bad, math.pi)


def test_normals_skip_without_buffers_and_count_only_named_triangles(tmp_path: Path) -> None:
    ref = _ref(tmp_path, [XY], {}, size=(1, 2))
    for buffers, reason in (
        ({"id.prim": np.zeros((1, 2), np.uint32)}, "b writes no N"),
        ({"N": np.zeros((1, 2, 3))}, "b writes N but no id.prim to judge it by"),
        ({}, "b writes no N"),
    ):
        e = Entry.for_render("s", "b", vocab.Buffer.N, {}, normals.N_FIELDS)
        assert normals.judge_normals(ref, "b", buffers, e, None) is None
        assert (e.status, e.reason) == (vocab.Status.SKIPPED, reason)
    # ids naming no triangle (1 is one past the last) are not judged: nothing compared, angle 0.
    e = Entry.for_render("s", "b", vocab.Buffer.N, {}, normals.N_FIELDS)
    prim = np.array([[1, BG]], dtype=np.uint32)
    judged = normals.judge_normals(ref, "b", {"N": np.zeros((1, 2, 3)), "id.prim": prim}, e, None)
    assert judged is not None and judged.details == []
    assert (e.compared_pixels, e.interior_mismatches, e.max_angle_rad) == (0, 0, 0.0)


def test_compare_normals_gives_a_verdict(tmp_path: Path) -> None:
    ref = _ref(tmp_path, [XY], {}, size=(1, 2))
    exps = expectations.Expectations(None)
    prim = np.zeros((1, 2), dtype=np.uint32)
    ok = np.array([[[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]], dtype=np.float32)
    e = normals.compare_normals("s", "raster", {"time_s": 1.0}, ref, {"N": ok, "id.prim": prim}, exps, None)
    assert (e.status, e.pixels, e.buffer, e.backend, e.time_s) == (vocab.Status.PASS, 2, "N", "raster", 1.0)
    spec = registry.spec("raster")
    assert spec is not None
    bad = ok.copy()
    bad[0, 1] = [0, 0, -1]
    e = normals.compare_normals("s", "raster", {}, ref, {"N": bad, "id.prim": prim}, exps, spec)
    assert e.status == vocab.Status.FAIL and "1 normals off, 1 of them facing the other way" in e.reason
    assert "2.4e-07" in e.reason  # raster's model (4u), not the f32 one
    e = normals.compare_normals("s", "raster", {}, ref, {"id.prim": prim}, exps, spec)
    assert e.status == vocab.Status.SKIPPED and e.reason == "raster writes no N"


def test_a_float32_normal_is_judged_in_float64(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """N = (a, b, 0) stored in f32 with |N| = 1 + 4u + 6e-8 in f64: beyond the unit band, though its
    length taken in f32 rounds to 1 + 4u and would pass. Its triangle's normal is exactly along N."""
    monkeypatch.setattr(normals.precision, "normal_tolerance", lambda spec, cond: (np.full(cond.shape, 1e-12), "t"))
    a, b = 0.8426332473754883, 0.5384884476661682
    n = np.array([[[a, b, 0.0]]], dtype=np.float32)
    assert float(np.linalg.norm(n.astype(np.float64))) > 1 + 4 * U + 1e-12 >= float(np.linalg.norm(n[0, 0]))
    e, _ = _normals(tmp_path, [[[0, 0, 0], [-b, a, 0], [0, 0, 1]]], n, np.array([[0]], dtype=np.uint32))
    assert e.interior_mismatches == 1 and e.max_angle_rad is not None and e.max_angle_rad < 1e-12
