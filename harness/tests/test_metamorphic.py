"""metamorphic.py on tiny runs: a float64 ray cast stands in for each backend's base and variant renders."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import backend_cases as cases
from fixtures import write_scene
from rendiff_harness.__main__ import main as harness_main
from rendiff_harness.contract import exrbuf, resolved, vocab
from rendiff_harness.contract.manifest import Reference
from rendiff_harness.judge import depth, metamorphic
from rendiff_harness.renderers import registry

BG = vocab.BACKGROUND_ID

# vfov 90, 32x32, eye (0, 0, 5) looking at -z: at world z = 0, px = (x/5 + 1) * 16, so the
# vertical line x = X projects to px = 16.5, through the centers of column 16.
X = 0.15625
BIG = [[X - 2.0, -3.0, 0.0], [X + 2.0, -3.0, 0.0], [X, 3.0, 0.0]]  # split edge: (X, -3) - (X, 3)
FRONT = [[-1.0, -1.0, 1.0], [1.0, -1.0, 1.0], [0.0, 1.2, 1.0]]  # in front, rows 11..20
ON_SPLIT_EDGE = (16, 22)  # column 16, below FRONT: inside BIG, exactly on the split edge
INSIDE_BIG = (14, 22)  # inside BIG, > 0.5 px from every edge of both scenes
CAMERA: dict[str, Any] = {"vfov_deg": 90.0, "width": 32, "height": 32}


def _halves(t: list[list[float]]) -> list[list[list[float]]]:
    a, b, c = (np.asarray(v) for v in t)
    m = (a + b) / 2.0
    return [[a.tolist(), m.tolist(), c.tolist()], [m.tolist(), b.tolist(), c.tolist()]]


def _cast(scene_dir: Path) -> dict[str, np.ndarray]:
    ref = cases.cast(resolved.load(scene_dir))
    return {"Z": ref.z.astype(np.float32), "prim": ref.prim, "obj": ref.obj}


class Run:
    """A run folder with scenes and per-backend renders, plus the spec of its cases."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.scenes: dict[str, dict[str, Any]] = {}
        self.cases: list[dict[str, Any]] = []

    def scene(self, name: str, tris: Any, oids: Any, **camera: Any) -> dict[str, np.ndarray]:
        d = write_scene(self.root / f"scenes/{name}/resolved", tris, oids, name=name, **{**CAMERA, **camera})
        self.scenes[name] = {
            "scene": name,
            "scene_file": f"{name}.toml",
            "resolved": f"scenes/{name}/resolved",
            "requires": ["depth", "ids"],
            "renders": [],
        }
        return _cast(d)

    def render(self, scene: str, backend: str, bufs: dict[str, np.ndarray] | None, **extra: Any) -> None:
        if bufs is None:
            self.scenes[scene]["renders"].append({"backend": backend, **extra})
            return
        rel = f"scenes/{scene}/{backend}.exr"
        exrbuf.write_buffers(self.root / rel, Z=bufs["Z"], prim=bufs["prim"], obj=bufs["obj"], attrs=extra.get("attrs"))
        self.scenes[scene]["renders"].append(
            {"backend": backend, "status": "ok", "exr": rel, "buffers": ["Z", "id"], "info": extra.get("info", {})}
        )

    def case(self, relation: str, variant: str, prim_map: list[int], object_map: list[int], scale: float = 1.0) -> None:
        self.cases.append(
            {
                "relation": relation,
                "base": "base",
                "variant": variant,
                "prim_map": prim_map,
                "object_map": object_map,
                "depth_scale": scale,
            }
        )

    def compare(self, expectations: Path | None = None) -> dict[tuple[str, str, str], dict[str, Any]]:
        (self.root / "manifest.json").write_text(
            json.dumps(
                {
                    "format": "rendiff-manifest/1",
                    "reference": "raster",
                    "rendiff_version": "0.1.0",
                    "scenes": list(self.scenes.values()),
                }
            )
        )
        spec = self.root / "spec.json"
        spec.write_text(json.dumps({"format": metamorphic.SPEC_FORMAT, "cases": self.cases}))
        doc = metamorphic.run_metamorphic(self.root, spec, expectations, self.root / "metamorphic.json", registry.spec)
        return {(r["relation"], r["backend"], r["buffer"]): r for r in doc["results"]}


@pytest.fixture()
def run(tmp_path: Path) -> Run:
    return Run(tmp_path / "run")


def test_reorder_maps_ids_back_and_a_wrong_map_fails(run: Run) -> None:
    base = run.scene("base", [BIG, FRONT], [0, 1])
    var = run.scene("swapped", [FRONT, BIG], [0, 1])  # objects reversed too
    for b in ("embree", "raster"):
        run.render("base", b, base)
        run.render("swapped", b, var)
    run.case("reorder", "swapped", [1, 0], [1, 0])
    run.case("reorder_wrong", "swapped", [0, 1], [1, 0])
    run.case("reorder_wrong_objects", "swapped", [1, 0], [0, 1])
    res = run.compare()
    for b in ("embree", "raster"):
        assert res[("reorder", b, "id")]["status"] == "pass"
        assert res[("reorder", b, "id")]["edge_mismatches"] == 0
        assert res[("reorder", b, "Z")]["status"] == "pass"
        wrong = res[("reorder_wrong", b, "id")]
        assert wrong["status"] == "fail"
        # Every covered pixel changes; the few near an edge of both triangles count as edge.
        assert wrong["edge_mismatches"] + wrong["interior_mismatches"] == int((base["prim"] != BG).sum())
        assert wrong["interior_mismatches"] > 100
        # Right prims, wrong objects: id.object disagrees wherever the prims agree.
        assert res[("reorder_wrong_objects", b, "id")]["status"] == "fail"
        assert "different id.object" in res[("reorder_wrong_objects", b, "id")]["reason"]


def test_split_edge_counts_as_an_edge_and_a_crack_elsewhere_does_not(run: Run) -> None:
    base = run.scene("base", [BIG, FRONT], [0, 1])
    var = run.scene("split", [*_halves(BIG), FRONT], [0, 0, 1])
    assert var["prim"][ON_SPLIT_EDGE[1], ON_SPLIT_EDGE[0]] in (0, 1)
    cracked = {k: v.copy() for k, v in var.items()}
    x, y = ON_SPLIT_EDGE
    cracked["prim"][y, x], cracked["obj"][y, x], cracked["Z"][y, x] = BG, BG, np.inf
    holed = {k: v.copy() for k, v in var.items()}
    x, y = INSIDE_BIG
    holed["prim"][y, x], holed["obj"][y, x], holed["Z"][y, x] = BG, BG, np.inf
    run.render("base", "embree", base)
    run.render("split", "embree", cracked)
    run.render("base", "mitsuba", base)
    run.render("split", "mitsuba", holed)
    run.case("split", "split", [0, 0, 1], [0, 1])
    res = run.compare()
    # Only the variant's new edge is near that center: the base triangle's own edges are far.
    crack = res[("split", "embree", "id")]
    assert (crack["status"], crack["edge_mismatches"], crack["interior_mismatches"]) == ("pass", 1, 0)
    z = res[("split", "embree", "Z")]
    assert (z["status"], z["edge_mismatches"], z["mask_mismatches"]) == ("pass", 1, 1)
    hole = res[("split", "mitsuba", "id")]
    assert (hole["status"], hole["interior_mismatches"]) == ("fail", 1)
    assert res[("split", "mitsuba", "Z")]["status"] == "fail"


def test_scale_divides_depth_exactly_for_the_core(run: Run) -> None:
    s = 4.0
    base = run.scene("base", [BIG, FRONT], [0, 1])
    big = (np.asarray([BIG, FRONT]) * s).tolist()
    var = run.scene("scaled", big, [0, 1], eye=(0.0, 0.0, 5.0 * s), near=1e-3 * s)
    assert np.array_equal(var["Z"][np.isfinite(var["Z"])] / np.float32(s), base["Z"][np.isfinite(base["Z"])])
    run.render("base", "trace", base)
    run.render("scaled", "trace", var)
    run.case("scale", "scaled", [0, 1], [0, 1], scale=s)
    run.case("scale_wrong", "scaled", [0, 1], [0, 1], scale=2.0)
    res = run.compare()
    assert res[("scale", "trace", "Z")]["status"] == "pass"
    assert res[("scale", "trace", "Z")]["max_abs_error"] == 0.0
    assert res[("scale_wrong", "trace", "Z")]["status"] == "fail"


def _side_tolerance(run: Run, backend: str, x: int, y: int) -> float:
    """`backend`'s relative depth tolerance at pixel (x, y) of BIG (prim 0, z = 0, at Z = 5) in the
    run's base scene: the verifier's own depth context (`depth.depth_context`, every ray from the
    contract's camera) through the backend's own model."""
    ref = Reference(resolved.load(run.root / "scenes/base/resolved"), buffers={}, shape=(32, 32))
    ctx = depth.depth_context(ref, np.array([y]), np.array([x]), np.array([5.0]), np.array([0]), {}, {})
    spec = registry.spec(backend)
    assert spec is not None
    tol, _ = spec.precision.depth(ctx)
    return float(tol[0]) / 5.0


def test_depth_bound_is_the_sum_of_both_sides_tolerances(run: Run) -> None:
    base = run.scene("base", [BIG, FRONT], [0, 1])
    var = run.scene("same", [BIG, FRONT], [0, 1])
    x, y = INSIDE_BIG  # facing the camera at Z = 5
    # Each side's relative depth tolerance there, from the backends' own models (the measured 1e-5 / |cos|
    # plus the derived terms: the f32 t = T / den on BIG, its rays and copies), so the two renders below
    # sit between one side and both (Mitsuba) and between both sides and three (Embree).
    side = {name: _side_tolerance(run, name, x, y) for name in ("mitsuba", "embree")}
    within, beyond = ({k: v.copy() for k, v in var.items()} for _ in range(2))
    within["Z"][y, x] *= np.float32(1 + 1.5 * side["mitsuba"])  # beyond one side, within the sum
    beyond["Z"][y, x] *= np.float32(1 + 2.5 * side["embree"])  # beyond the sum, within three sides
    run.render("base", "mitsuba", base)
    run.render("same", "mitsuba", within)
    run.render("base", "embree", base)
    run.render("same", "embree", beyond)
    run.render("base", "raster", base)
    run.render("same", "raster", within)
    run.case("flip_winding", "same", [0, 1], [0, 1])
    res = run.compare()
    assert res[("flip_winding", "mitsuba", "Z")]["status"] == "pass"
    assert "sum of both sides" in res[("flip_winding", "mitsuba", "Z")]["tolerance"]
    assert res[("flip_winding", "embree", "Z")]["status"] == "fail"
    assert res[("flip_winding", "raster", "Z")]["status"] == "fail"  # the core is exact here


def test_skips_and_errors_are_carried_with_the_side_named(run: Run) -> None:
    base = run.scene("base", [BIG], [0])
    run.scene("same", [BIG], [0])
    run.render("base", "povray", base)
    run.render("same", "povray", None, status="skipped", reason="missing features: lambert")
    run.render("base", "pyrender", base)
    run.render("same", "pyrender", None, status="error", message="timed out after 120 s")
    run.case("flip_winding", "same", [0], [0])
    res = run.compare()
    sk = res[("flip_winding", "povray", "id")]
    assert sk["status"] == "skipped" and "variant scene same: missing features: lambert" in sk["reason"]
    assert sk["interior_mismatches"] is None  # not compared, never "0 mismatches"
    assert res[("flip_winding", "pyrender", "Z")]["status"] == "error"


def test_known_failure_is_expected_fail_and_edge_bounds_are_refused(run: Run, tmp_path: Path) -> None:
    base = run.scene("base", [BIG, FRONT], [0, 1])
    var = run.scene("same", [BIG, FRONT], [0, 1])
    bad = {k: v.copy() for k, v in var.items()}
    x, y = INSIDE_BIG
    bad["prim"][y, x] = 1
    bad["obj"][y, x] = 1
    run.render("base", "povray", base, info={"depth_step": 1e-9})
    run.render("same", "povray", bad, info={"depth_step": 1e-9})
    run.case("flip_winding", "same", [0, 1], [0, 1])
    exp = tmp_path / "exp.toml"
    exp.write_text(
        '[[expect]]\nscene = "flip_winding"\nbackend = "povray"\nbuffer = "id"\n'
        'interior_mismatches = [1, 1]\nstatus = "expected_fail"\nreason = "a test"\n'
    )
    res = run.compare(exp)
    assert res[("flip_winding", "povray", "id")]["status"] == "expected_fail"
    exp.write_text(
        '[[expect]]\nscene = "flip_winding"\nbackend = "povray"\nbuffer = "id"\n'
        'edge_mismatches = [0, 5]\nreason = "a test"\n'
    )
    with pytest.raises(metamorphic.expectations.ExpectationsError, match="allowed classes"):
        run.compare(exp)


def test_preimage_lists_every_variant_prim_of_a_base_prim() -> None:
    table = metamorphic.preimage(np.array([2, 0, 0, 1, 2]), 4)
    assert [sorted(x for x in row if x >= 0) for row in table.tolist()] == [[1, 2], [3], [0, 4], []]


def test_bad_spec_exits_2_naming_the_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    r = Run(tmp_path / "run")
    r.scene("base", [BIG], [0])
    (r.root / "manifest.json").write_text(json.dumps({"format": "rendiff-manifest/1", "scenes": []}))
    spec = tmp_path / "spec.json"
    spec.write_text(
        json.dumps(
            {
                "format": metamorphic.SPEC_FORMAT,
                "cases": [
                    {
                        "relation": "scale",
                        "base": "base",
                        "variant": "base",
                        "prim_map": [0],
                        "object_map": [0],
                        "depth_scale": 3.0,
                    }
                ],
            }
        )
    )
    assert harness_main(["metamorphic", "--run", str(r.root), "--spec", str(spec)]) == 2
    err = capsys.readouterr().err
    assert str(spec) in err and "power of two" in err
    assert not (r.root / "metamorphic.json").exists()


def test_a_map_that_does_not_fit_the_variant_is_an_error(run: Run) -> None:
    base = run.scene("base", [BIG, FRONT], [0, 1])
    run.scene("split", [*_halves(BIG), FRONT], [0, 0, 1])
    run.render("base", "embree", base)
    run.render("split", "embree", base)  # wrong size of map below, whatever the buffers
    run.case("split", "split", [0, 1], [0, 1])
    res = run.compare()
    e = res[("split", "embree", "id")]
    assert e["status"] == "error" and "prim_map has 2 entries" in e["reason"] and "3 triangles" in e["reason"]
