//! The regression gate and bless: every rule of `rendiff gate` on hand-made
//! verdicts (no renderers needed), then bless → gate → break → gate on a real
//! run through the command line, and the committed baseline itself.

use rendiff::check::manifest::{ResultEntry, Results};
use rendiff::gate::{self, ChangeKind, Noise};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

mod common;
use common::cli::{bless_command, gate_command, small_check, succeeds};
use common::gate::{baseline_of, verdicts as results};

fn entry(
    scene: &str,
    backend: &str,
    buffer: &str,
    status: &str,
    edge: u64,
    max_abs: f64,
) -> ResultEntry {
    let details = json!({
        "edge_mismatches": edge, "interior_mismatches": 0, "mask_mismatches": 0,
        "max_abs_error": max_abs, "max_rel_error": max_abs / 4.0,
    });
    with_details(scene, backend, buffer, status, details)
}

/// A verdict with the given details (a JSON object) and a reason naming its status.
fn with_details(
    scene: &str,
    backend: &str,
    buffer: &str,
    status: &str,
    details: Value,
) -> ResultEntry {
    ResultEntry {
        scene: scene.into(),
        backend: backend.into(),
        buffer: buffer.into(),
        status: status.into(),
        reason: format!("{status} because"),
        details: details.as_object().unwrap().clone(),
    }
}

/// An entry's status, edge count and largest error.
type Side<'a> = (&'a str, u64, f64);

/// A baseline's entries and a run's from one table: per row, the entry's
/// scene, backend and buffer, then its [`Side`] in the baseline and now.
fn before_now(rows: &[(&str, &str, &str, Side, Side)]) -> (Vec<ResultEntry>, Vec<ResultEntry>) {
    let mut sides = (Vec::new(), Vec::new());
    for &(scene, backend, buffer, (s0, e0, m0), (s1, e1, m1)) in rows {
        sides.0.push(entry(scene, backend, buffer, s0, e0, m0));
        sides.1.push(entry(scene, backend, buffer, s1, e1, m1));
    }
    sides
}

/// The gate's outcome for run entries `now` against a baseline blessed from `base`.
fn compare(base: &[ResultEntry], now: Vec<ResultEntry>) -> gate::Outcome {
    gate::compare(&baseline_of(base), &results(now))
}

/// The kinds of the changes whose description contains `what`.
fn kinds(o: &gate::Outcome, what: &str) -> Vec<ChangeKind> {
    kinds_of(o, None, what)
}

/// [`kinds`] of `backend`'s changes only, where a backend is given.
fn kinds_of(o: &gate::Outcome, backend: Option<&str>, what: &str) -> Vec<ChangeKind> {
    o.changes
        .iter()
        .filter(|c| backend.is_none_or(|b| c.backend == b) && c.what.contains(what))
        .map(|c| c.kind)
        .collect()
}

/// Asserts that `backend`'s changes whose description contains `what` are
/// exactly `want`, printing `why` and every change otherwise.
fn expect_kinds(o: &gate::Outcome, backend: &str, what: &str, want: &[ChangeKind], why: &str) {
    assert_eq!(
        kinds_of(o, Some(backend), what),
        want,
        "{why}: {:#?}",
        o.changes
    );
}

#[test]
fn an_unchanged_run_passes() {
    let base = vec![
        entry("a", "trace", "id", "pass", 0, 0.0),
        entry("a", "povray", "Z", "expected_fail", 12, 1e-6),
        entry("a", "mitsuba", "Z", "skipped", 0, 0.0),
    ];
    let o = compare(&base, base.clone());
    assert_eq!(o.regressions(), 0, "{:?}", o.changes);
    assert_eq!(o.compared, 3);
    assert!(o.changes.is_empty());
}

#[test]
fn new_failures_fail_the_gate_and_fixes_are_reported() {
    let (base, now) = before_now(&[
        ("a", "trace", "id", ("pass", 0, 0.0), ("fail", 0, 0.0)),
        (
            "a",
            "povray",
            "id",
            ("expected_fail", 3, 0.0),
            ("unexpected_pass", 2, 0.0),
        ),
        ("a", "mitsuba", "id", ("skipped", 0, 0.0), ("error", 0, 0.0)),
        ("a", "embree", "id", ("fail", 3, 0.0), ("fail", 3, 0.0)),
        ("b", "embree", "id", ("pass", 0, 0.0), ("skipped", 0, 0.0)),
        ("c", "embree", "id", ("error", 0, 0.0), ("pass", 0, 0.0)),
    ]);
    let o = compare(&base, now);
    assert_eq!(kinds(&o, "new failure").len(), 3, "{:#?}", o.changes);
    assert_eq!(
        kinds(&o, "no longer compared"),
        vec![ChangeKind::Regression]
    );
    assert_eq!(kinds(&o, "still failing"), vec![ChangeKind::Note]);
    assert_eq!(kinds(&o, "fixed"), vec![ChangeKind::Improvement]);
    assert_eq!(
        kinds(&o, "edge_mismatches better"),
        vec![ChangeKind::Improvement]
    );
    assert_eq!(o.regressions(), 4);
    assert_eq!(
        o.changes[0].kind,
        ChangeKind::Regression,
        "regressions come first"
    );
}

#[test]
fn counts_may_not_grow_and_errors_only_within_their_noise() {
    let (base, now) = before_now(&[
        ("a", "povray", "id", ("pass", 10, 0.0), ("pass", 11, 0.0)),
        ("a", "povray", "Z", ("pass", 0, 1e-6), ("pass", 0, 1.4e-6)),
        ("a", "pyrender", "Z", ("pass", 0, 1e-6), ("pass", 0, 1e-5)),
        ("a", "trace", "Z", ("pass", 0, 0.0), ("pass", 0, 1e-9)),
        ("a", "embree", "Z", ("pass", 0, 1e-6), ("pass", 0, 1e-9)),
    ]);
    let o = compare(&base, now);
    let (regression, improvement) = (&[ChangeKind::Regression], &[ChangeKind::Improvement]);
    expect_kinds(
        &o,
        "povray",
        "edge_mismatches worse",
        regression,
        "a count that grows",
    );
    let noise = "×1.4 is within the noise of an external renderer";
    expect_kinds(&o, "povray", "max_abs_error", &[], noise);
    expect_kinds(
        &o,
        "pyrender",
        "max_abs_error worse",
        regression,
        "×10 is not",
    );
    expect_kinds(
        &o,
        "trace",
        "max_abs_error worse",
        regression,
        "the core is exact",
    );
    expect_kinds(
        &o,
        "embree",
        "max_abs_error better",
        improvement,
        "an error that shrinks",
    );
    let c = o.changes.iter().find(|c| c.backend == "povray").unwrap();
    assert_eq!((c.before.as_str(), c.now.as_str()), ("10", "11 (+1)"));
}

#[test]
fn entries_on_one_side_only_fail_the_gate() {
    let base = vec![
        entry("a", "trace", "id", "pass", 0, 0.0),
        entry("a", "trace", "Z", "pass", 0, 0.0),
    ];
    let now = vec![
        entry("a", "trace", "id", "pass", 0, 0.0),
        entry("new", "trace", "id", "pass", 0, 0.0),
    ];
    let o = compare(&base, now);
    assert_eq!(kinds(&o, "missing result"), vec![ChangeKind::Regression]);
    assert_eq!(
        kinds(&o, "not in the baseline"),
        vec![ChangeKind::Regression]
    );
    assert_eq!(o.regressions(), 2);
}

#[test]
fn the_committed_baseline_is_blessed_with_provenance() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let b = gate::load_baseline(&root.join("reports/baseline.json")).unwrap();
    let p = &b.provenance;
    assert!(!b.entries.is_empty());
    assert!(!p.cpu.is_empty() && !p.blessed.is_empty() && p.command.contains("bless"));
    for backend in ["raster", "trace", "embree", "povray", "pyrender", "mitsuba"] {
        assert!(
            p.renderers.get(backend).is_some_and(|v| !v.is_empty()),
            "no version for {backend}"
        );
    }
    for e in &b.entries {
        // A failure gets into the baseline only through `bless --allow-failures`, with its reason.
        if e.status.is_bad() {
            assert!(
                !e.reason.is_empty(),
                "accepted failure without a reason: {} {} {}",
                e.scene,
                e.backend,
                e.buffer
            );
        }
        if gate::EXACT_BACKENDS.contains(&e.backend.as_str()) {
            assert_eq!(
                e.noise,
                Noise::for_backend(&e.backend, 0.0),
                "exact backends get no noise"
            );
        }
    }
}

// ---------------------------------------------------------------- the command line, on a real run

fn edit(results: &mut Value, scene: &str, backend: &str, buffer: &str, f: impl FnOnce(&mut Value)) {
    let e = results["results"]
        .as_array_mut()
        .unwrap()
        .iter_mut()
        .find(|e| e["scene"] == scene && e["backend"] == backend && e["buffer"] == buffer)
        .unwrap_or_else(|| panic!("no {scene}/{backend}/{buffer}"));
    f(e);
}

#[test]
fn bless_then_gate_passes_and_catches_every_kind_of_change() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    small_check(&run);
    let baseline = dir.path().join("base/baseline.json");
    succeeds(&mut bless_command(&run, &baseline));
    let b = gate::load_baseline(&baseline).unwrap();
    let r: Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("results.json")).unwrap()).unwrap();
    assert_eq!(
        b.entries.len(),
        r["results"].as_array().unwrap().len(),
        "one baseline entry per verdict"
    );
    for scene in ["three_triangles", "pixel_grid"] {
        for backend in ["trace", "embree"] {
            for buffer in ["id", "Z"] {
                assert!(
                    b.entries.iter().any(|e| (
                        e.scene.as_str(),
                        e.backend.as_str(),
                        e.buffer.as_str()
                    ) == (scene, backend, buffer)),
                    "no {scene}/{backend}/{buffer} in the baseline"
                );
            }
        }
    }
    assert!(b.provenance.renderers["embree"].starts_with("Embree"));
    assert!(b.provenance.renderers["trace"].starts_with("rendiff"));
    assert_eq!(b.provenance.rendiff_version, env!("CARGO_PKG_VERSION"));
    assert!(b.provenance.blessed.ends_with('Z') && b.provenance.command.contains("bless"));
    let stray = std::fs::read_dir(baseline.parent().unwrap())
        .unwrap()
        .count();
    assert_eq!(stray, 1, "bless left temporary files");

    // Unchanged: passes, writes RUN/gate.md, leaves the baseline alone.
    let before = std::fs::read(&baseline).unwrap();
    let out = succeeds(&mut gate_command(&run, &baseline));
    let md = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(md.starts_with("## rendiff gate: PASS"), "{md}");
    assert_eq!(std::fs::read_to_string(run.join("gate.md")).unwrap(), md);
    assert_eq!(
        std::fs::read(&baseline).unwrap(),
        before,
        "gate changed the baseline"
    );

    // Break things in results.json the way regressions would.
    let path = run.join("results.json");
    let mut r: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    edit(&mut r, "pixel_grid", "trace", "id", |e| {
        e["status"] = "fail".into();
        e["reason"] = "60 interior mismatches".into();
        e["interior_mismatches"] = 60.into();
    });
    edit(&mut r, "pixel_grid", "embree", "id", |e| {
        let n = e["edge_mismatches"].as_u64().unwrap();
        e["edge_mismatches"] = (n + 5).into();
    });
    edit(&mut r, "three_triangles", "embree", "Z", |e| {
        e["max_abs_error"] = 0.5.into()
    });
    let arr = r["results"].as_array_mut().unwrap();
    arr.retain(|e| {
        !(e["scene"] == "three_triangles" && e["backend"] == "trace" && e["buffer"] == "Z")
    });
    let mut extra = arr[0].clone();
    extra["scene"] = "brand_new".into();
    arr.push(extra);
    std::fs::write(&path, serde_json::to_string_pretty(&r).unwrap()).unwrap();
    let out = gate_command(&run, &baseline).output().unwrap();
    let md = String::from_utf8_lossy(&out.stdout).into_owned();
    assert_eq!(out.status.code(), Some(1), "{md}");
    assert!(md.starts_with("## rendiff gate: FAIL"), "{md}");
    for needle in [
        "new failure: pass → fail — 60 interior mismatches",
        "interior_mismatches worse",
        "edge_mismatches worse",
        "max_abs_error worse",
        "missing result",
        "not in the baseline",
        "report/pixel_grid.html#b-trace",
        "report/three_triangles.html#b-embree",
    ] {
        assert!(md.contains(needle), "gate summary lacks {needle:?}:\n{md}");
    }
    assert_eq!(std::fs::read_to_string(run.join("gate.md")).unwrap(), md);

    // Bless refuses a failing run unless told to accept its failures, and a
    // run with a new scene unless told to accept scene changes.
    let (code, err) = bless_cli(&run, &baseline, &[]);
    bless_refused(code, &err, &["--allow-failures"], &baseline, &before);
    let (code, err) = bless_cli(&run, &baseline, &["--allow-failures"]);
    let needles = ["added 1: \"brand_new\"", "--allow-scene-changes"];
    bless_refused(code, &err, &needles, &baseline, &before);
    // The entry the gate found missing is not dropped silently: bless names
    // it and wants a reason (issue 40: it used to bless it away).
    let allow_all = ["--allow-failures", "--allow-scene-changes"];
    let (code, err) = bless_cli(&run, &baseline, &allow_all);
    let needles = [
        "1 entry of the baseline's scenes is not in the run",
        "three_triangles::trace::Z",
        "--drop-reason",
    ];
    bless_refused(code, &err, &needles, &baseline, &before);
    let reason = ["--drop-reason", "trace no longer writes depth"];
    let (code, err) = bless_cli(&run, &baseline, &[&allow_all[..], &reason].concat());
    assert_eq!(code, Some(0), "{err}");
    succeeds(&mut gate_command(&run, &baseline));
}

// ---------------------------------------------------------------- the verifier's classes and new buffers (issue 11)

/// An entry with the verifier's four class counts (None: field absent).
fn classed(backend: &str, tie: Option<u64>, crack: Option<u64>) -> ResultEntry {
    let mut e = entry("a", backend, "id", "pass", 2, 0.0);
    if let Some(t) = tie {
        e.details.insert("tie_mismatches".into(), t.into());
    }
    if let Some(c) = crack {
        e.details.insert("crack_mismatches".into(), c.into());
    }
    e
}

fn other(scene: &str, backend: &str, buffer: &str, status: &str) -> ResultEntry {
    let details = json!({"rms_px": 0.01, "max_angle_rad": 1e-4, "interior_mismatches": 0});
    with_details(scene, backend, buffer, status, details)
}

#[test]
fn tie_and_crack_counts_are_held_like_edge_counts() {
    assert!(gate::COUNT_METRICS.contains(&"tie_mismatches"));
    assert!(gate::COUNT_METRICS.contains(&"crack_mismatches"));
    let base = vec![
        classed("povray", Some(4), Some(0)),
        classed("embree", Some(0), Some(7)),
        classed("trace", Some(1), Some(1)),
    ];
    let now = vec![
        classed("povray", Some(5), Some(0)),
        classed("embree", Some(0), Some(3)),
        classed("trace", Some(1), Some(1)),
    ];
    let o = compare(&base, now);
    let grows = "a tie count that grows is a regression";
    expect_kinds(
        &o,
        "povray",
        "tie_mismatches worse",
        &[ChangeKind::Regression],
        grows,
    );
    let c = o
        .changes
        .iter()
        .find(|c| c.what == "tie_mismatches worse")
        .unwrap();
    assert_eq!((c.before.as_str(), c.now.as_str()), ("4", "5 (+1)"));
    let shrinks = "a crack count that shrinks is an improvement";
    expect_kinds(
        &o,
        "embree",
        "crack_mismatches better",
        &[ChangeKind::Improvement],
        shrinks,
    );
    expect_kinds(
        &o,
        "trace",
        "tie_mismatches worse",
        &[],
        "an unchanged count",
    );
    assert_eq!(o.regressions(), 1);
}

#[test]
fn class_counts_a_side_did_not_record_are_not_compared() {
    // An older baseline (no tie/crack fields at all) against a new run, and a
    // run that did not compare them (null) against a baseline that has them.
    let base = vec![
        classed("povray", None, None),
        classed("embree", Some(3), Some(2)),
    ];
    let mut now = vec![
        classed("povray", Some(40), Some(9)),
        classed("embree", None, None),
    ];
    now[1].details.insert("tie_mismatches".into(), Value::Null);
    let o = compare(&base, now);
    assert_eq!(o.regressions(), 0, "{:#?}", o.changes);
    assert!(o.changes.is_empty(), "{:#?}", o.changes);
}

#[test]
fn normals_camera_and_scene_entries_are_gated_by_status_and_presence() {
    let base = vec![
        other("a", "povray", "N", "pass"),
        other("probe", "povray", "camera", "pass"),
        other("probe", "embree", "camera", "pass"),
        other("b", "trace", "N", "pass"),
    ];
    let now = vec![
        other("a", "povray", "N", "fail"),
        other("probe", "povray", "camera", "pass"),
        // embree's camera entry is gone; a scene that no longer loads appears.
        other("b", "trace", "N", "pass"),
        ResultEntry {
            reason: "cannot load scene: bad TOML at line 3".into(),
            ..other("c", "raster", "scene", "error")
        },
    ];
    let o = compare(&base, now);
    let find = |buffer: &str, what: &str| {
        o.changes
            .iter()
            .filter(|c| c.buffer == buffer && c.what == what)
            .map(|c| (c.kind, c.detail.clone()))
            .collect::<Vec<_>>()
    };
    assert_eq!(find("N", "new failure").len(), 1, "{:#?}", o.changes);
    assert_eq!(find("camera", "missing result").len(), 1);
    let scene = find("scene", "not in the baseline");
    assert_eq!(scene.len(), 1);
    assert_eq!(scene[0].0, ChangeKind::Regression);
    assert!(
        scene[0].1.contains("cannot load scene"),
        "the load error is named: {scene:?}"
    );
    assert_eq!(o.regressions(), 3);
}

#[test]
fn bless_names_scene_load_errors_first_and_scene_changes_in_one_line() {
    let mut scene_err = other("zz_broken", "raster", "scene", "error");
    scene_err.reason = "cannot load scene: no such material \"x\"".into();
    let r = results(vec![
        entry("a", "trace", "id", "fail", 0, 0.0),
        entry("a", "trace", "Z", "pass", 0, 0.0),
        scene_err.clone(),
    ]);
    let why = gate::failure_summary(&r).unwrap();
    assert!(
        why.starts_with("1 scene could not be loaded: zz_broken (cannot load scene"),
        "{why}"
    );
    assert!(why.contains("a::trace::id (fail)"), "{why}");
    assert!(
        gate::failure_summary(&results(vec![entry("a", "trace", "id", "pass", 0, 0.0)])).is_none()
    );

    let before = baseline_of(&[
        entry("a", "trace", "id", "pass", 0, 0.0),
        entry("gone", "trace", "id", "pass", 0, 0.0),
    ]);
    let now = baseline_of(&[
        entry("a", "trace", "id", "pass", 0, 0.0),
        entry("new1", "trace", "id", "pass", 0, 0.0),
        entry("new2", "trace", "Z", "pass", 0, 0.0),
    ]);
    let (added, removed) = gate::scene_changes(&before, &now);
    assert_eq!(added, vec!["new1", "new2"]);
    assert_eq!(removed, vec!["gone"]);
    let line = gate::scene_change_summary(&before, &now).unwrap();
    assert!(!line.contains('\n'));
    assert!(
        line.contains("added 2: \"new1\", \"new2\"") && line.contains("removed 1: \"gone\""),
        "{line}"
    );
    assert!(gate::scene_change_summary(&before, &before).is_none());
}

/// A run folder without renders (bless only reads the two JSON files; the
/// EXRs it would read for depth scales are optional).
fn json_run(run: &Path, scenes: &[&str], extra: Vec<Value>) {
    let tie = json!({"tie_mismatches": 1, "explanations": [{"class": "tie", "ref_prim": 16,
        "test_prim": 20, "pixels": 1, "example": [3, 4],
        "why": "prims 16 and 20 are identical triangles: tie"}]});
    common::runs::json_run(run, scenes, &["trace"], &["id", "Z", "N"], tie);
    common::runs::edit_results(run, |r| r["results"].as_array_mut().unwrap().extend(extra));
}

/// A refused bless: exit 2, each of `needles` in `err` (the message, or the
/// line of it that must say them all), and the baseline file still `kept`.
fn bless_refused(code: Option<i32>, err: &str, needles: &[&str], baseline: &Path, kept: &[u8]) {
    assert_eq!(code, Some(2), "{err}");
    for n in needles {
        assert!(err.contains(n), "expected {n:?} in: {err}");
    }
    let now = std::fs::read(baseline).unwrap();
    assert!(now == kept, "a refused bless changed the baseline");
}

/// A run of scenes alpha and beta ([`json_run`]) in `dir/NAME`, blessed into
/// `dir/baseline.json`, which that first bless (nothing to compare with) must
/// create: the baseline's path, the run's, and the baseline's bytes.
fn first_bless(dir: &Path, name: &str) -> (PathBuf, PathBuf, Vec<u8>) {
    let baseline = dir.join("baseline.json");
    let run = dir.join(name);
    json_run(&run, &["alpha", "beta"], vec![]);
    let (code, err) = bless_cli(&run, &baseline, &[]);
    assert_eq!(
        code,
        Some(0),
        "the first bless has nothing to compare with: {err}"
    );
    let blessed = std::fs::read(&baseline).unwrap();
    (baseline, run, blessed)
}

fn bless_cli(run: &Path, baseline: &Path, flags: &[&str]) -> (Option<i32>, String) {
    let out = bless_command(run, baseline).args(flags).output().unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn bless_refuses_scene_errors_and_changed_scene_sets_unless_told() {
    let dir = tempfile::tempdir().unwrap();
    let (baseline, _, blessed) = first_bless(dir.path(), "first");
    let b = gate::load_baseline(&baseline).unwrap();
    let e = b.entries.iter().find(|e| e.buffer == "N").unwrap();
    assert_eq!(
        e.metrics["tie_mismatches"],
        json!(1),
        "class counts are blessed"
    );
    assert_eq!(e.metrics["crack_mismatches"], json!(0));

    // A scene that could not be loaded: refused, named, even with the scene set unchanged.
    let broken = dir.path().join("broken");
    json_run(
        &broken,
        &["alpha", "beta"],
        vec![
            json!({"scene": "beta", "backend": "raster", "buffer": "scene", "status": "error",
                    "reason": "cannot load scene: unknown shape kind \"blob\""}),
        ],
    );
    let (code, err) = bless_cli(&broken, &baseline, &[]);
    let needles = [
        "1 scene could not be loaded: beta (cannot load scene: unknown shape kind",
        "--allow-failures",
    ];
    bless_refused(code, &err, &needles, &baseline, &blessed);

    // Scenes added and removed: one line naming both, refused until allowed.
    let changed = dir.path().join("changed");
    json_run(&changed, &["alpha", "gamma", "delta"], vec![]);
    let (code, err) = bless_cli(&changed, &baseline, &[]);
    let line = err
        .lines()
        .find(|l| l.contains("scenes differ"))
        .unwrap_or_else(|| panic!("no scene-change line in {err}"));
    let needles = [
        "added 2: \"delta\", \"gamma\"",
        "removed 1: \"beta\"",
        "--allow-scene-changes",
    ];
    bless_refused(code, line, &needles, &baseline, &blessed);
    let (code, err) = bless_cli(&changed, &baseline, &["--allow-scene-changes"]);
    assert_eq!(code, Some(0), "{err}");
    let b = gate::load_baseline(&baseline).unwrap();
    assert!(b.entries.iter().any(|e| e.scene == "gamma"));
    assert!(!b.entries.iter().any(|e| e.scene == "beta"));
    // The same scenes again: no flag needed.
    let (code, err) = bless_cli(&changed, &baseline, &[]);
    assert_eq!(code, Some(0), "{err}");
}

// ---------------------------------------------------------------- typed verdicts and baseline (issue 12)

fn gate_cli(run: &Path, baseline: &Path) -> (Option<i32>, String, String) {
    let out = gate_command(run, baseline).output().unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Rewrites a JSON file through `f`.
fn edit_json(path: &Path, f: impl FnOnce(&mut Value)) {
    let mut v: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    f(&mut v);
    std::fs::write(path, serde_json::to_string_pretty(&v).unwrap()).unwrap();
}

/// The one error line of a refused command, checked to name `file` and `field`.
fn one_error_line(code: Option<i32>, err: &str, file: &Path, field: &str) {
    assert_eq!(code, Some(2), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    let want = format!("{}: {field}", file.display());
    assert!(err.contains(&want), "expected {want:?} in: {err}");
}

#[test]
fn unknown_statuses_and_negative_counts_are_refused_naming_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let (baseline, run, blessed) = first_bless(dir.path(), "run");
    let results = run.join("results.json");
    let clean = std::fs::read(&results).unwrap();
    type Case = (&'static str, fn(&mut Value), &'static str);
    let cases: [Case; 7] = [
        (
            // The gate kept the last of two verdicts for one entry: PASS.
            "a failing verdict followed by a passing copy",
            |v| {
                let copy = v["results"][1].clone();
                v["results"][1]["status"] = "fail".into();
                v["results"][1]["interior_mismatches"] = 50.into();
                v["results"].as_array_mut().unwrap().push(copy);
            },
            "results[6]: a second verdict for scene alpha, backend trace, buffer Z (the first is results[1])",
        ),
        (
            "another format",
            |v| v["format"] = "rendiff-results/9".into(),
            "format is \"rendiff-results/9\", expected \"rendiff-results/1\"",
        ),
        (
            "unknown status",
            |v| v["results"][4]["status"] = "passs".into(),
            "results[4].status: unknown status \"passs\"",
        ),
        (
            "negative count",
            |v| v["results"][3]["edge_mismatches"] = (-1).into(),
            "results[3].edge_mismatches: -1 is not a count",
        ),
        (
            "fractional count",
            |v| v["results"][0]["tie_mismatches"] = 0.5.into(),
            "results[0].tie_mismatches: 0.5 is not a count",
        ),
        (
            "negative error",
            |v| v["results"][1]["max_abs_error"] = (-1e-3).into(),
            "results[1].max_abs_error: -0.001 is not an error",
        ),
        (
            "status of the wrong type",
            |v| v["results"][2]["status"] = 1.into(),
            "results[2].status: 1 is not a status",
        ),
    ];
    for (what, f, field) in cases {
        std::fs::write(&results, &clean).unwrap();
        edit_json(&results, f);
        let (code, out, err) = gate_cli(&run, &baseline);
        one_error_line(code, &err, &results, field);
        assert!(
            !out.contains("better") && !out.contains("Improvement"),
            "{what} read as an improvement: {out}"
        );
        let (code, err) = bless_cli(&run, &baseline, &["--allow-failures"]);
        one_error_line(code, &err, &results, field);
        assert_eq!(
            std::fs::read(&baseline).unwrap(),
            blessed,
            "{what}: a refused bless changed the baseline"
        );
    }

    // The baseline is typed the same way.
    std::fs::write(&results, &clean).unwrap();
    let (code, out, err) = gate_cli(&run, &baseline);
    assert_eq!(code, Some(0), "{out}{err}");
    type Edit = (fn(&mut Value), &'static str);
    let baseline_cases: [Edit; 3] = [
        (
            |v| v["entries"][2]["metrics"]["interior_mismatches"] = (-2).into(),
            "entries[2].metrics.interior_mismatches: -2 is not a count",
        ),
        (
            |v| {
                let copy = v["entries"][0].clone();
                v["entries"].as_array_mut().unwrap().push(copy);
            },
            "entries[6]: a second verdict for scene",
        ),
        (
            |v| v["entries"][0]["status"] = "expected_failure".into(),
            "entries[0].status: unknown status \"expected_failure\"",
        ),
    ];
    for (edit, field) in baseline_cases {
        std::fs::write(&baseline, &blessed).unwrap();
        edit_json(&baseline, edit);
        let (code, _, err) = gate_cli(&run, &baseline);
        one_error_line(code, &err, &baseline, field);
    }
}

#[test]
fn statuses_round_trip_with_their_results_json_names() {
    for &s in gate::Status::ALL {
        let v = serde_json::to_value(s).unwrap();
        assert_eq!(v, Value::String(s.as_str().into()));
        assert_eq!(serde_json::from_value::<gate::Status>(v).unwrap(), s);
        assert_eq!(gate::Status::parse(s.as_str()), Some(s));
    }
    assert_eq!(gate::Status::parse("passs"), None);
    let bad = Results {
        format: "rendiff-results/1".into(),
        reference: "raster".into(),
        results: vec![
            entry("a", "trace", "id", "pass", 0, 0.0),
            entry("a", "trace", "Z", "PASS", 0, 0.0),
        ],
    };
    let e = gate::verdicts(&bad).unwrap_err().to_string();
    assert_eq!(e, "results[1].status: unknown status \"PASS\"");
}
