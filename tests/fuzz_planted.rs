//! `rendiff fuzz` finds planted bugs on its own and `rendiff reduce`
//! shrinks them (docs/fuzzing.md). Declared command renderers
//! (tests/fuzz_renderers/planted.py) each carry one fault: `coplanar_bias`
//! drops a triangle that lies in front of a near-coplanar neighbour drawn
//! before it; `subpixel_shift` moves one vertex of every sub-pixel triangle
//! by 1e-3 px; `far_depth` measures depth from a float32 world-space hit
//! point; `coplanar_swap` swaps the IDs of coplanar neighbours. Within 200 generated scenes the fuzzer must report each
//! and reduce it to at most 8 triangles; for the first, the
//! reduced scene must also have fewer pixels (the image step's crop), (a)
//! still fail on its own, checked from a fresh folder with calibration, and
//! (b) come back from a second reduction byte for byte unchanged.

mod common;

use common::cli::{
    fuzz_renderers, need_venv, output_within, printed, reduce_planted, rendiff_with_venv,
};
use serde_json::Value;
use std::path::Path;

const BACKEND: &str = "coplanar_bias";

/// The planted renderers of this test.
fn renderers() -> String {
    fuzz_renderers("renderers.toml")
}

/// `rendiff fuzz --seed 1 --count 200 --only BACKEND` into `dir/fuzz`:
/// it must exit 1 (failures found); the ledger.
fn fuzz(dir: &Path, backend: &str) -> Value {
    let out = output_within(
        rendiff_with_venv(dir)
            .args(["fuzz", "--seed", "1", "--count", "200", "--only", backend])
            .arg("--renderers")
            .arg(renderers())
            .args(["--no-calibration", "--jobs", "2", "--quiet", "-o", "fuzz"]),
        900,
    );
    assert_eq!(
        out.status.code(),
        Some(1),
        "fuzz must report failures: {}",
        printed(&out)
    );
    let ledger: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("fuzz/findings.json")).unwrap())
            .unwrap();
    assert_eq!(ledger["format"], "rendiff-findings/1");
    assert_eq!(ledger["scenes"], 200);
    ledger
}

/// The findings of `backend` failing `buffer` (any buffer when None) with
/// one of `classes` (any class when empty): one per situation.
fn findings_of<'a>(
    ledger: &'a Value,
    backend: &str,
    buffer: Option<&str>,
    classes: &[&str],
) -> Vec<&'a Value> {
    let out: Vec<&Value> = ledger["findings"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|f| {
            let s = &f["signature"];
            s["backend"] == backend
                && buffer.is_none_or(|b| s["buffer"] == b)
                && (classes.is_empty() || classes.iter().any(|c| s["class"] == *c))
        })
        .collect();
    assert!(
        !out.is_empty(),
        "the planted bug of {backend} was not found: {ledger}"
    );
    out
}

/// The first of [`findings_of`].
fn finding<'a>(
    ledger: &'a Value,
    backend: &str,
    buffer: Option<&str>,
    classes: &[&str],
) -> &'a Value {
    findings_of(ledger, backend, buffer, classes)[0]
}

/// A scene file, loaded and resolved.
fn resolved(file: &Path) -> rendiff::scene::resolve::ResolvedScene {
    let scene = rendiff::scene::Scene::load(file).unwrap();
    rendiff::scene::resolve::ResolvedScene::resolve(&scene).unwrap()
}

#[test]
fn a_planted_coplanar_bug_is_found_reduced_and_reproduced() {
    need_venv();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let ledger = fuzz(dir, BACKEND);
    // The planted bug: interior ID mismatches, coplanar scenes among them.
    // Its findings, one per situation; the one seed 1's smallest hit
    // (s1_00007) is in was reduced from it.
    let all = findings_of(&ledger, BACKEND, Some("id"), &["interior"]);
    let f = *all
        .iter()
        .find(|f| f["scenes"].as_array().unwrap().contains(&"s1_00007".into()))
        .unwrap_or_else(|| panic!("s1_00007 is in no finding: {ledger}"));
    let hits: u64 = all.iter().map(|f| f["hits"].as_u64().unwrap()).sum();
    assert!(hits >= 1);
    let coplanar: u64 = all
        .iter()
        .filter_map(|f| f["families"]["coplanar"].as_u64())
        .sum();
    assert!(coplanar >= 1, "{ledger}");
    let r = &f["reduced"];
    assert!(r["error"].is_null(), "reduction failed: {r}");
    let before = r["triangles_before"].as_u64().unwrap();
    let after = r["triangles_after"].as_u64().unwrap();
    // The bug needs two triangles (one alone always passes the biased test
    // against the background's +inf) and no more: ddmin's 1-minimal result
    // is that pair.
    assert!(after <= 8, "reduced to {after} triangles: {r}");
    assert_eq!(after, 2, "{r}");
    assert!(before > after, "{r}");
    assert!(
        r["bytes_after"].as_u64().unwrap() < r["bytes_before"].as_u64().unwrap(),
        "{r}"
    );
    assert!(
        r["complete"].as_bool().unwrap(),
        "reduction stopped early: {r}"
    );
    // The image step: fewer pixels, a centered crop of the same pitch. The
    // bias does not hang on a ray's last bits, so a crop still fails.
    let pixels = |k: &str| {
        let wh = r[k].as_array().unwrap();
        wh[0].as_u64().unwrap() * wh[1].as_u64().unwrap()
    };
    assert!(pixels("image_after") < pixels("image_before"), "{r}");
    assert!(r["image_note"].is_null(), "{r}");
    assert!(r["command"]
        .as_str()
        .unwrap()
        .contains("--only coplanar_bias"));
    // Its situation is the reduced pair's. The smallest scene that hit it
    // (seed 1's s1_00007) is a `near_plane` scene: two triangles crossing
    // each other and the near plane, dropped where their depths are within
    // the bias of each other, near their intersection line (so not
    // `coplanar`). No declaration names a planted renderer, so it is
    // unclassified, on the ledger and on the page.
    let tags: Vec<&str> = f["signature"]["situation"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t.as_str().unwrap())
        .collect();
    assert_eq!(r["from"], "s1_00007", "{f}");
    assert!(tags.contains(&"near_plane"), "{f}");
    assert_eq!(f["classification"]["kind"], "unclassified", "{f}");
    let page = std::fs::read_to_string(dir.join("fuzz/findings.html")).unwrap();
    assert!(page.contains("coplanar_bias fails id (interior)") && page.contains("unclassified"));
    assert!(
        page.contains("<img src=\"findings/"),
        "the page shows the scene's pictures"
    );
    let reduced = std::fs::read(dir.join("fuzz").join(r["scene"].as_str().unwrap())).unwrap();

    // The largest scene that hit it, reduced by hand from the fuzz's run.
    let largest = f["scenes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap())
        .max_by_key(|s| {
            std::fs::metadata(dir.join(format!("fuzz/scenes/{s}.toml")))
                .unwrap()
                .len()
        })
        .unwrap();
    let big = reduce_planted(
        dir,
        &renderers(),
        "fuzz/run",
        largest,
        BACKEND,
        "id",
        "big.toml",
    );
    let triangles = |file: &Path| resolved(file).triangles.len();
    let big_before = triangles(&dir.join(format!("fuzz/scenes/{largest}.toml")));
    assert_eq!(triangles(&dir.join("big.toml")), 2, "{largest}: {big}");
    assert!(big_before > 2, "{largest} has {big_before} triangles");

    // (a) From a fresh folder, on its own, calibration included: it still fails.
    let fresh = dir.join("fresh");
    std::fs::create_dir(&fresh).unwrap();
    std::fs::write(fresh.join("repro.toml"), &reduced).unwrap();
    let check = output_within(
        rendiff_with_venv(&fresh)
            .args(["check", "repro.toml", "--only", BACKEND, "--renderers"])
            .arg(renderers())
            .args(["--quiet", "-o", "run"]),
        300,
    );
    assert_eq!(
        check.status.code(),
        Some(1),
        "the repro passed: {}",
        printed(&check)
    );
    let results: Value =
        serde_json::from_str(&std::fs::read_to_string(fresh.join("run/results.json")).unwrap())
            .unwrap();
    let entry = results["results"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["scene"] == "repro" && e["backend"] == BACKEND && e["buffer"] == "id")
        .unwrap();
    assert_eq!(entry["status"], "fail", "{entry}");
    assert!(
        entry["interior_mismatches"].as_u64().unwrap() > 0,
        "{entry}"
    );

    // (b) Reducing the reduced scene changes nothing, byte for byte.
    reduce_planted(
        &fresh,
        &renderers(),
        "run",
        "repro",
        BACKEND,
        "id",
        "again.toml",
    );
    assert_eq!(
        String::from_utf8_lossy(&std::fs::read(fresh.join("again.toml")).unwrap()),
        String::from_utf8_lossy(&reduced),
        "a second reduction changed the reduced scene"
    );
}

#[test]
fn a_planted_subpixel_vertex_shift_is_found_and_reduced() {
    need_venv();
    let tmp = tempfile::tempdir().unwrap();
    let backend = "subpixel_shift";
    let ledger = fuzz(tmp.path(), backend);
    // The moved vertex tilts the triangle: its normals and depths leave
    // the declared precision (and a center the shift moves an edge across
    // changes its ID), whichever buffer the verifier sees it in first.
    let f = finding(&ledger, backend, None, &[]);
    let r = &f["reduced"];
    assert!(r["error"].is_null(), "reduction failed: {r}");
    let before = r["triangles_before"].as_u64().unwrap();
    let after = r["triangles_after"].as_u64().unwrap();
    assert!(after <= 8, "reduced to {after} triangles: {r}");
    assert!(after < before || before == 1, "{r}");
    assert!(
        r["complete"].as_bool().unwrap(),
        "reduction stopped early: {r}"
    );
}

/// `coplanar_swap` reports each other's IDs for two coplanar triangles that
/// share an edge and lie on opposite sides of it. Swapping the IDs of
/// overlapping coplanar triangles would prove nothing: where both cover a
/// pixel center at one depth the contract lets either win (a tie,
/// docs/verifier.md). Neighbours never both cover an interior pixel's
/// center, so their swap is forbidden, and the verifier must call it
/// `interior`. The grammar builds such neighbours on purpose (the
/// `pixel_centers` grid's split cells, `dense`, `t_junction`): the fuzz must
/// find the `id` failure among them, and the largest scene that hit it must
/// reduce to the pair, 2 triangles (one alone has no neighbour to swap with).
/// Sizes, not times: whether a reduction reached its fixed point within its
/// time budget depends on the machine's load, so `complete` is not asserted.
#[test]
fn a_planted_coplanar_id_swap_is_found_and_reduced() {
    need_venv();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let backend = "coplanar_swap";
    let ledger = fuzz(dir, backend);
    let found = findings_of(&ledger, backend, Some("id"), &["interior"]);
    let grid: u64 = found
        .iter()
        .filter_map(|f| f["families"]["pixel_centers"].as_u64())
        .sum();
    assert!(grid >= 1, "no pixel_centers scene hit it: {ledger}");
    for f in &found {
        let tags = f["signature"]["situation"].as_array().unwrap();
        assert!(
            tags.contains(&"shared_edge".into()) && tags.contains(&"coplanar".into()),
            "{f}"
        );
        let r = &f["reduced"];
        if !r.is_null() {
            assert!(r["error"].is_null(), "reduction failed: {r}");
            assert!(r["triangles_after"].as_u64().unwrap() <= 8, "{r}");
        }
    }

    // The largest scene that hit it, reduced by hand from the fuzz's run.
    let scene_file = |s: &str| dir.join(format!("fuzz/scenes/{s}.toml"));
    let largest = found
        .iter()
        .flat_map(|f| f["scenes"].as_array().unwrap())
        .map(|s| s.as_str().unwrap())
        .max_by_key(|s| std::fs::metadata(scene_file(s)).unwrap().len())
        .unwrap();
    let out = reduce_planted(
        dir,
        &renderers(),
        "fuzz/run",
        largest,
        backend,
        "id",
        "largest.toml",
    );
    let before = resolved(&scene_file(largest)).triangles.len();
    let after = resolved(&dir.join("largest.toml")).triangles;
    assert!(before > 2, "{largest} has {before} triangles");
    assert_eq!(after.len(), 2, "{largest}: {out}");
    // The pair is a pair of neighbours: one edge in common, bit for bit.
    let shared = after[0]
        .iter()
        .filter(|v| {
            after[1]
                .iter()
                .any(|w| w.to_array().map(f32::to_bits) == v.to_array().map(f32::to_bits))
        })
        .count();
    assert_eq!(shared, 2, "{largest}: {after:?}");
}

/// The core's two loops and Embree's robust mode on generated scenes:
/// raster and trace agree bit for bit on every scene (ARCHITECTURE.md), and
/// Embree ROBUST is watertight, so 200 scenes of the grammar, extremes
/// included, give no finding at all (a finding here is a bug in the core,
/// in Embree's backend or in the grammar, which must stay inside the
/// contract).
#[test]
fn the_core_and_embree_robust_pass_every_generated_scene() {
    need_venv();
    let tmp = tempfile::tempdir().unwrap();
    let out = output_within(
        rendiff_with_venv(tmp.path())
            .args(["fuzz", "--seed", "1", "--count", "200"])
            .args(["--only", "trace,embree_robust", "--no-calibration"])
            .args(["--jobs", "2", "--quiet", "-o", "fuzz"]),
        600,
    );
    assert_eq!(out.status.code(), Some(0), "{}", printed(&out));
    let ledger: Value = serde_json::from_str(
        &std::fs::read_to_string(tmp.path().join("fuzz/findings.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(ledger["findings"].as_array().unwrap().len(), 0, "{ledger}");
    // The run compared every scene: one trace verdict per scene and buffer.
    let results: Value = serde_json::from_str(
        &std::fs::read_to_string(tmp.path().join("fuzz/run/results.json")).unwrap(),
    )
    .unwrap();
    let passed = results["results"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["backend"] == "trace" && e["buffer"] == "id" && e["status"] == "pass")
        .count();
    assert_eq!(passed, 200);
}

/// `far_depth` measures depth from a hit point kept in float32 world
/// space: off by about 2^-24 of the hit point's largest coordinate, which
/// the declared relative depth (1.2e-7, just above 2^-23) excuses only while
/// that coordinate stays within about twice the depth. The grammar's
/// far-from-origin modifier (offsets 2^10 to 2^23) must reach it: a
/// far-from-origin scene among the hits, reduced by hand to at most 8
/// triangles that are still far from the origin. (Near-plane content seen
/// from a few units away, |p| / Z up to 2^6, shows the same bug, so the
/// fuzz's own reduction of its smallest scene may start from one of those.)
#[test]
fn a_planted_far_from_origin_depth_loss_is_found_and_reduced() {
    need_venv();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let backend = "far_depth";
    let ledger = fuzz(dir, backend);
    // Findings are split by situation, and a group gets at most
    // MAX_REDUCTIONS_PER_GROUP reductions: the rest keep their smallest scene
    // unreduced (`reduced: null`). Every reduction made must be complete and
    // small, and there must be one.
    let reduced: Vec<&serde_json::Value> = findings_of(&ledger, backend, Some("Z"), &["interior"])
        .into_iter()
        .map(|f| &f["reduced"])
        .filter(|r| !r.is_null())
        .collect();
    assert!(!reduced.is_empty(), "no finding was reduced: {ledger}");
    for r in reduced {
        assert!(r["error"].is_null(), "reduction failed: {r}");
        assert!(r["triangles_after"].as_u64().unwrap() <= 8, "{r}");
        assert!(r["complete"].as_bool().unwrap(), "{r}");
    }
    // Coverage and ids are exact: the bug is in Z alone.
    for other in ledger["findings"].as_array().unwrap() {
        assert_eq!(other["signature"]["buffer"], "Z", "{other}");
    }

    // The far-from-origin hits (the grammar names its modifiers in each
    // scene's description); the smallest of them, reduced by hand.
    let scene_file = |s: &str| dir.join(format!("fuzz/scenes/{s}.toml"));
    let far: Vec<&str> = findings_of(&ledger, backend, Some("Z"), &["interior"])
        .iter()
        .flat_map(|f| f["scenes"].as_array().unwrap())
        .map(|s| s.as_str().unwrap())
        .filter(|s| {
            std::fs::read_to_string(scene_file(s))
                .unwrap()
                .lines()
                .next()
                .unwrap()
                .contains("far_from_origin")
        })
        .collect();
    assert!(!far.is_empty(), "no far-from-origin scene hit it: {ledger}");
    let smallest = far
        .iter()
        .min_by_key(|s| std::fs::metadata(scene_file(s)).unwrap().len())
        .unwrap();
    let out = reduce_planted(
        dir,
        &renderers(),
        "fuzz/run",
        smallest,
        backend,
        "Z",
        "far.toml",
    );
    let far = resolved(&dir.join("far.toml"));
    assert!(
        (1..=8).contains(&far.triangles.len()),
        "{smallest} reduced to {} triangles: {out}",
        far.triangles.len()
    );
    // Still far from the origin: the modifier's smallest offset is 2^10.
    let largest = far
        .triangles
        .iter()
        .flat_map(|t| t.iter().flat_map(|v| v.to_array()))
        .fold(0.0f64, |m, x| m.max(f64::from(x).abs()));
    assert!(
        largest >= 1024.0,
        "{smallest}: largest coordinate {largest}"
    );
}

/// "Near the same triangles" (docs/fuzzing.md, the reducer): a failure
/// that removing triangles moves onto other triangles is not the same
/// failure. Five triangles in draw order: a near-coplanar pair D, C on the
/// left (C in front of D by 2^-11, within coplanar_bias's 2^-12 relative
/// depth bias, so the planted renderer keeps D), hidden behind E, a
/// triangle much nearer the eye; then the same kind of pair A_b, A_f on the
/// right, in plain view. The scene fails on the right pair only. ddmin's
/// first candidate is {D, C}: with E gone the left pair fails too, with the
/// same backend, buffer and class (checked here), so a test of the class
/// alone reduces the scene to the left pair. The reduction must end on the
/// right pair, the one that failed.
#[test]
fn a_failure_moved_to_other_triangles_is_not_the_same_failure() {
    need_venv();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let gap = 2f64.powi(-11);
    let pair = |x: f64| [0.0, gap].map(|z| [[x - 1.0, -1.0, z], [x + 1.0, -1.0, z], [x, 1.0, z]]);
    let [d, c] = pair(-1.5);
    let [a_b, a_f] = pair(1.5);
    let e = [[-2.2, -1.0, 1.0], [0.0, -1.0, 1.0], [-1.1, 1.2, 1.0]];
    let write = |name: &str, tris: &[[[f64; 3]; 3]]| {
        let verts: Vec<String> = tris
            .iter()
            .flatten()
            .map(|v| format!("[{:?}, {:?}, {:?}]", v[0], v[1], v[2]))
            .collect();
        let text = format!(
            "requires = [\"depth\", \"ids\"]\n\n[camera]\neye = [0.0, 0.0, 4.0]\nlook_at = [0.0, 0.0, 0.0]\n\
             vfov = 45.0\nwidth = 64\nheight = 32\nnear = 0.01\n\n[[objects]]\nname = \"all\"\n\
             shape = {{ kind = \"triangles\", vertices = [{}] }}\n",
            verts.join(", ")
        );
        std::fs::write(dir.join(format!("{name}.toml")), text).unwrap();
    };
    write("moved", &[d, c, e, a_b, a_f]);
    write("left_pair", &[d, c]);
    let out = output_within(
        rendiff_with_venv(dir)
            .args(["check", "moved.toml", "left_pair.toml", "--only", BACKEND])
            .arg("--renderers")
            .arg(renderers())
            .args(["--no-calibration", "--jobs", "2", "--quiet", "-o", "run"]),
        300,
    );
    assert_eq!(out.status.code(), Some(1), "{}", printed(&out));
    let results: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("run/results.json")).unwrap())
            .unwrap();
    let interior = |scene: &str| {
        results["results"]
            .as_array()
            .unwrap()
            .iter()
            .find(|e| e["scene"] == scene && e["backend"] == BACKEND && e["buffer"] == "id")
            .unwrap()["interior_mismatches"]
            .as_u64()
            .unwrap()
    };
    // Both fail the same way: the class alone cannot tell them apart.
    assert!(interior("moved") > 0, "{results}");
    assert!(interior("left_pair") > 0, "{results}");

    let red = reduce_planted(
        dir,
        &renderers(),
        "run",
        "moved",
        BACKEND,
        "id",
        "reduced.toml",
    );
    let r = resolved(&dir.join("reduced.toml"));
    assert_eq!(r.triangles.len(), 2, "{red}");
    for t in &r.triangles {
        let x = (t[0].x + t[1].x + t[2].x) / 3.0;
        assert!(x > 0.0, "reduced to the left pair: {t:?}\n{red}");
    }
}
