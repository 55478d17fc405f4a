//! The regression gate and bless: every rule of `rendiff gate` on hand-made
//! verdicts (no renderers needed), then bless → gate → break → gate on a real
//! run through the command line, and the committed baseline itself.

use rendiff::check::manifest::{ResultEntry, Results};
use rendiff::gate::{self, Baseline, BaselineEntry, ChangeKind, Noise, Provenance};
use serde_json::{json, Value};
use std::path::Path;

mod common_cli;
use common_cli::{rendiff, small_check};

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
    ResultEntry {
        scene: scene.into(),
        backend: backend.into(),
        buffer: buffer.into(),
        status: status.into(),
        reason: format!("{status} because"),
        details: details.as_object().unwrap().clone(),
    }
}

fn baseline_of(entries: &[ResultEntry]) -> Baseline {
    Baseline {
        format: gate::BASELINE_FORMAT.into(),
        provenance: Provenance::default(),
        policy: String::new(),
        entries: entries
            .iter()
            .map(|e| BaselineEntry {
                scene: e.scene.clone(),
                backend: e.backend.clone(),
                buffer: e.buffer.clone(),
                status: e.status.clone(),
                reason: e.reason.clone(),
                metrics: e
                    .details
                    .iter()
                    .map(|(k, v)| (k.clone(), v.clone()))
                    .collect(),
                noise: Noise::for_backend(&e.backend, 4.0),
            })
            .collect(),
    }
}

fn results(entries: Vec<ResultEntry>) -> Results {
    Results {
        format: "rendiff-results/1".into(),
        reference: "raster".into(),
        results: entries,
    }
}

fn kinds(o: &gate::Outcome, what: &str) -> Vec<ChangeKind> {
    o.changes
        .iter()
        .filter(|c| c.what.contains(what))
        .map(|c| c.kind)
        .collect()
}

#[test]
fn an_unchanged_run_passes() {
    let base = vec![
        entry("a", "trace", "id", "pass", 0, 0.0),
        entry("a", "povray", "Z", "expected_fail", 12, 1e-6),
        entry("a", "mitsuba", "Z", "skipped", 0, 0.0),
    ];
    let o = gate::compare(&baseline_of(&base), &results(base.clone()));
    assert_eq!(o.regressions(), 0, "{:?}", o.changes);
    assert_eq!(o.compared, 3);
    assert!(o.changes.is_empty());
}

#[test]
fn new_failures_fail_the_gate_and_fixes_are_reported() {
    let base = vec![
        entry("a", "trace", "id", "pass", 0, 0.0),
        entry("a", "povray", "id", "expected_fail", 3, 0.0),
        entry("a", "mitsuba", "id", "skipped", 0, 0.0),
        entry("a", "embree", "id", "fail", 3, 0.0),
        entry("b", "embree", "id", "pass", 0, 0.0),
        entry("c", "embree", "id", "error", 0, 0.0),
    ];
    let now = vec![
        entry("a", "trace", "id", "fail", 0, 0.0),
        entry("a", "povray", "id", "unexpected_pass", 2, 0.0),
        entry("a", "mitsuba", "id", "error", 0, 0.0),
        entry("a", "embree", "id", "fail", 3, 0.0),
        entry("b", "embree", "id", "skipped", 0, 0.0),
        entry("c", "embree", "id", "pass", 0, 0.0),
    ];
    let o = gate::compare(&baseline_of(&base), &results(now));
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
    let base = vec![
        entry("a", "povray", "id", "pass", 10, 0.0),
        entry("a", "povray", "Z", "pass", 0, 1e-6),
        entry("a", "pyrender", "Z", "pass", 0, 1e-6),
        entry("a", "trace", "Z", "pass", 0, 0.0),
        entry("a", "embree", "Z", "pass", 0, 1e-6),
    ];
    let now = vec![
        entry("a", "povray", "id", "pass", 11, 0.0),
        entry("a", "povray", "Z", "pass", 0, 1.4e-6),
        entry("a", "pyrender", "Z", "pass", 0, 1e-5),
        entry("a", "trace", "Z", "pass", 0, 1e-9),
        entry("a", "embree", "Z", "pass", 0, 1e-9),
    ];
    let o = gate::compare(&baseline_of(&base), &results(now));
    let by = |backend: &str, what: &str| {
        o.changes
            .iter()
            .filter(|c| c.backend == backend && c.what.contains(what))
            .map(|c| c.kind)
            .collect::<Vec<_>>()
    };
    assert_eq!(
        by("povray", "edge_mismatches worse"),
        vec![ChangeKind::Regression],
        "{:#?}",
        o.changes
    );
    assert!(
        by("povray", "max_abs_error").is_empty(),
        "×1.4 is within the noise of an external renderer"
    );
    assert_eq!(
        by("pyrender", "max_abs_error worse"),
        vec![ChangeKind::Regression]
    );
    assert_eq!(
        by("trace", "max_abs_error worse"),
        vec![ChangeKind::Regression],
        "the core is exact"
    );
    assert_eq!(
        by("embree", "max_abs_error better"),
        vec![ChangeKind::Improvement]
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
    let o = gate::compare(&baseline_of(&base), &results(now));
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
        if gate::is_bad(&e.status) {
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
    let out = rendiff()
        .arg("bless")
        .arg(&run)
        .arg("--baseline")
        .arg(&baseline)
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let b = gate::load_baseline(&baseline).unwrap();
    assert_eq!(b.entries.len(), 8, "2 scenes x 2 backends x 2 buffers");
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
    let out = rendiff()
        .arg("gate")
        .arg("--baseline")
        .arg(&baseline)
        .arg(&run)
        .output()
        .unwrap();
    let md = String::from_utf8_lossy(&out.stdout).into_owned();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{md}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
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
    let out = rendiff()
        .arg("gate")
        .arg("--baseline")
        .arg(&baseline)
        .arg(&run)
        .output()
        .unwrap();
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

    // Bless refuses a failing run unless told to accept its failures.
    let out = rendiff()
        .arg("bless")
        .arg(&run)
        .arg("--baseline")
        .arg(&baseline)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--allow-failures"));
    assert_eq!(
        std::fs::read(&baseline).unwrap(),
        before,
        "a refused bless changed the baseline"
    );
    let out = rendiff()
        .arg("bless")
        .arg(&run)
        .arg("--baseline")
        .arg(&baseline)
        .arg("--allow-failures")
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = rendiff()
        .arg("gate")
        .arg("--baseline")
        .arg(&baseline)
        .arg(&run)
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
}
