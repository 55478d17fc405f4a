//! The gate's unit tests, one per comparison and from both sides of each
//! boundary, on synthetic verdicts and run folders (no renderer runs). They
//! are what `cargo mutants` runs against `src/gate/` (docs/mutation.md), so
//! each rule here is held by a test that a changed rule fails.

use super::*;
use crate::check::manifest::{Manifest, ResultEntry, Results, RESULTS_FORMAT};
use serde_json::json;

#[path = "../../tests/common/runs.rs"]
mod common_runs;
use common_runs::edit_results;

/// Depth scale the synthetic baselines are blessed with.
const Z_FAR: f64 = 4.0;

/// A verdict with the given counts and errors.
fn v(backend: &str, buffer: &str, status: Status, counts: &[(&str, u64)]) -> Verdict {
    Verdict {
        scene: "s".into(),
        backend: backend.into(),
        buffer: buffer.into(),
        status,
        reason: format!("{status} because"),
        counts: counts.iter().map(|(k, c)| (k.to_string(), *c)).collect(),
        errors: BTreeMap::new(),
    }
}

/// The same verdict with errors recorded.
fn with_errors(mut e: Verdict, errors: &[(&str, f64)]) -> Verdict {
    e.errors = errors.iter().map(|(k, x)| (k.to_string(), *x)).collect();
    e
}

fn baseline_of(list: &[Verdict]) -> Baseline {
    Baseline {
        format: BASELINE_FORMAT.into(),
        provenance: Provenance::default(),
        policy: String::new(),
        entries: list
            .iter()
            .map(|e| BaselineEntry::blessed(e, Z_FAR))
            .collect(),
    }
}

/// (kind, what) of every change, in the gate's order.
fn whats(o: &Outcome) -> Vec<(ChangeKind, String)> {
    o.changes.iter().map(|c| (c.kind, c.what.clone())).collect()
}

// ------------------------------------------------------------ crack counts (the held-out fault)

/// A crack count that grows is a regression whatever else moves: on every
/// buffer, every status an entry can keep, every kind of backend, from zero
/// (the usual crack count) and from a non-zero count, and while every other
/// count shrinks (a gate that summed the classes, or stopped at the first
/// change of an entry, or skipped counts it had no baseline above zero for,
/// or skipped entries that were already failing, passed these).
#[test]
fn a_growing_crack_count_is_a_regression_whatever_else_moves() {
    let statuses = [
        Status::Pass,
        Status::ExpectedFail,
        Status::Fail,
        Status::Error,
        Status::UnexpectedPass,
        Status::Skipped,
    ];
    for backend in ["raster", "trace", "embree", "povray", "my_renderer"] {
        for buffer in ["id", "Z", "N", "camera"] {
            for status in statuses {
                for from in [0u64, 7] {
                    let others = [
                        ("edge_mismatches", 5u64),
                        ("tie_mismatches", 3),
                        ("interior_mismatches", 2),
                        ("mask_mismatches", 1),
                    ];
                    let mut was: Vec<(&str, u64)> = others.to_vec();
                    was.push(("crack_mismatches", from));
                    let mut now: Vec<(&str, u64)> =
                        others.iter().map(|&(m, c)| (m, c - 1)).collect();
                    now.push(("crack_mismatches", from + 1));
                    let o = compare(
                        &baseline_of(&[v(backend, buffer, status, &was)]),
                        &[v(backend, buffer, status, &now)],
                    );
                    let crack: Vec<&Change> = o
                        .changes
                        .iter()
                        .filter(|c| c.what == "crack_mismatches worse")
                        .collect();
                    let at = format!("{backend} {buffer} {status} crack {from} -> {}", from + 1);
                    assert_eq!(crack.len(), 1, "{at}: {:#?}", o.changes);
                    assert_eq!(crack[0].kind, ChangeKind::Regression, "{at}");
                    assert_eq!(crack[0].before, from.to_string(), "{at}");
                    assert_eq!(crack[0].now, format!("{} (+1)", from + 1), "{at}");
                    assert_eq!(crack[0].detail, format!("limit {from}"), "{at}");
                    assert_eq!(o.regressions(), 1, "{at}: {:#?}", o.changes);
                    // The same counts unchanged: no regression at all.
                    let same = compare(
                        &baseline_of(&[v(backend, buffer, status, &was)]),
                        &[v(backend, buffer, status, &was)],
                    );
                    assert_eq!(same.regressions(), 0, "{at}: {:#?}", same.changes);
                }
            }
        }
    }
}

/// The same through the files: results.json with a grown crack count, read
/// by `load_verdicts`, against a baseline blessed by `bless` and read back by
/// `load_baseline`; `gate` fails and its summary names the crack count.
#[test]
fn gate_fails_a_run_whose_crack_count_grew_through_bless_and_the_files() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    json_run(&run, &["alpha", "beta"]);
    let baseline = dir.path().join("baseline.json");
    let b = bless(&run, &baseline, &BlessOptions::default()).unwrap();
    assert!(b
        .entries
        .iter()
        .all(|e| e.metrics["crack_mismatches"] == json!(0)));
    let (text, passed) = gate(&baseline, &run).unwrap();
    assert!(passed, "{text}");
    assert!(text.starts_with("## rendiff gate: PASS"), "{text}");
    edit_results(&run, |r| r["results"][0]["crack_mismatches"] = 1.into());
    let (text, passed) = gate(&baseline, &run).unwrap();
    assert!(!passed, "a crack count 0 -> 1 passed the gate:\n{text}");
    assert!(text.starts_with("## rendiff gate: FAIL"), "{text}");
    assert!(
        text.contains("crack_mismatches worse: 0 → 1 (+1)"),
        "{text}"
    );
    assert_eq!(
        std::fs::read_to_string(run.join("gate.md")).unwrap(),
        text,
        "gate writes its summary into the run"
    );
}

// ------------------------------------------------------------ noise bounds

#[test]
fn noise_for_exact_and_external_backends() {
    for be in EXACT_BACKENDS {
        assert_eq!(
            Noise::for_backend(be, 9.0),
            Noise {
                counts: 0,
                error_factor: 1.0,
                max_abs_error_slack: 0.0,
                max_rel_error_slack: 0.0
            },
            "{be}"
        );
    }
    assert_eq!(
        Noise::for_backend("povray", 8.0),
        Noise {
            counts: 0,
            error_factor: 1.5,
            max_abs_error_slack: F32_SLACK * 8.0,
            max_rel_error_slack: F32_SLACK,
        }
    );
    assert_eq!(F32_SLACK, 2f64.powi(-22), "two f32 roundings");
}

/// A noise with every field different, so each formula's terms are told apart.
fn odd_noise() -> Noise {
    Noise {
        counts: 2,
        error_factor: 3.0,
        max_abs_error_slack: 0.5,
        max_rel_error_slack: 0.25,
    }
}

#[test]
fn limits_and_improvement_thresholds_of_each_metric() {
    let n = odd_noise();
    for m in COUNT_METRICS {
        assert_eq!(n.limit(m, 5.0), 7.0, "{m}: base + counts");
        assert_eq!(n.improved_below(m, 5.0), 3.0, "{m}: base - counts");
    }
    assert_eq!(
        n.limit("max_abs_error", 2.0),
        6.5,
        "base x factor + abs slack"
    );
    assert_eq!(
        n.limit("max_rel_error", 2.0),
        6.25,
        "base x factor + rel slack"
    );
    assert_eq!(
        n.limit("rms_px", 2.0),
        8.0,
        "other numbers: counts as slack"
    );
    assert_eq!(n.improved_below("max_abs_error", 2.0), 0.5);
    assert_eq!(n.improved_below("max_rel_error", 2.0), 1.75 / 3.0);
    assert_eq!(n.improved_below("rms_px", 8.0), 2.0);
    // A factor below one does not make the improvement threshold larger than the base.
    let shrink = Noise {
        error_factor: 0.5,
        ..odd_noise()
    };
    assert_eq!(shrink.improved_below("max_abs_error", 2.0), 1.5);
}

#[test]
fn a_count_noise_is_honoured_on_both_sides() {
    let base = v("povray", "id", Status::Pass, &[("edge_mismatches", 5)]);
    let mut b = baseline_of(&[base]);
    b.entries[0].noise = odd_noise();
    let at = |c: u64| {
        whats(&compare(
            &b,
            &[v("povray", "id", Status::Pass, &[("edge_mismatches", c)])],
        ))
    };
    assert!(at(7).is_empty(), "5 + 2 is within the noise");
    assert_eq!(
        at(8),
        vec![(ChangeKind::Regression, "edge_mismatches worse".into())]
    );
    assert!(at(3).is_empty(), "5 - 2 is within the noise");
    assert_eq!(
        at(2),
        vec![(ChangeKind::Improvement, "edge_mismatches better".into())]
    );
}

// ------------------------------------------------------------ what each change says

#[test]
fn count_changes_say_before_now_difference_and_limit() {
    let b = baseline_of(&[v("trace", "id", Status::Pass, &[("tie_mismatches", 4)])]);
    let o = compare(
        &b,
        &[v("trace", "id", Status::Pass, &[("tie_mismatches", 6)])],
    );
    let c = &o.changes[0];
    assert_eq!(
        (c.before.as_str(), c.now.as_str(), c.detail.as_str()),
        ("4", "6 (+2)", "limit 4")
    );
    assert_eq!(c.phrase(), "tie_mismatches worse: 4 → 6 (+2) — limit 4");
    let o = compare(
        &b,
        &[v("trace", "id", Status::Pass, &[("tie_mismatches", 1)])],
    );
    let c = &o.changes[0];
    assert_eq!(
        (c.kind, c.now.as_str()),
        (ChangeKind::Improvement, "1 (-3)")
    );
    assert_eq!(c.phrase(), "tie_mismatches better: 4 → 1 (-3)");
}

#[test]
fn error_changes_say_the_ratio_or_the_new_value_from_zero() {
    let z = |x: f64| with_errors(v("trace", "Z", Status::Pass, &[]), &[("max_abs_error", x)]);
    let o = compare(&baseline_of(&[z(2e-6)]), &[z(3e-6)]);
    let c = &o.changes[0];
    assert_eq!(c.what, "max_abs_error worse");
    assert_eq!(
        (c.before.as_str(), c.now.as_str(), c.detail.as_str()),
        ("2.000e-6", "3.000e-6 (×1.50)", "limit 2.000e-6")
    );
    let o = compare(&baseline_of(&[z(0.0)]), &[z(1e-3)]);
    let c = &o.changes[0];
    assert_eq!(
        (c.before.as_str(), c.now.as_str(), c.detail.as_str()),
        ("0", "1.000e-3 (+1.000e-3)", "limit 0")
    );
    let o = compare(&baseline_of(&[z(4e-6)]), &[z(1e-6)]);
    assert_eq!(o.changes[0].now, "1.000e-6 (×0.25)");
    assert_eq!(o.changes[0].kind, ChangeKind::Improvement);
}

#[test]
fn numbers_are_formatted_by_kind() {
    assert_eq!(fmt_num("crack_mismatches", 12.0), "12");
    assert_eq!(fmt_num("max_rel_error", 0.0), "0");
    assert_eq!(fmt_num("max_rel_error", 1.5e-7), "1.500e-7");
}

#[test]
fn reasons_are_shortened_to_one_line() {
    assert_eq!(short("abc", 3), "abc", "n characters are kept whole");
    assert_eq!(short("abcd", 3), "abc…");
    assert_eq!(short("a\nb", 9), "a b");
    assert_eq!(short("ééé", 3), "ééé", "characters, not bytes");
}

// ------------------------------------------------------------ statuses and presence

/// The whole transition table, written out: what the gate says when an entry
/// blessed with the row's status comes back with the column's.
#[test]
fn every_status_transition_gets_its_verdict() {
    use ChangeKind::{Improvement as I, Note as N, Regression as R};
    use Status::*;
    let none: Option<(ChangeKind, &str)> = None;
    let new = Some((R, "new failure"));
    let lost = Some((R, "no longer compared"));
    let fixed = Some((I, "fixed"));
    let now_compared = Some((I, "now compared"));
    let still = Some((N, "still failing (accepted in the baseline)"));
    let changed = Some((N, "status changed"));
    let statuses = [Pass, Fail, Skipped, Error, ExpectedFail, UnexpectedPass];
    #[rustfmt::skip]
    let table = [
        //               Pass          Fail   Skipped Error  ExpectedFail  UnexpectedPass
        /* Pass */         [none,         new,   lost,   new,   changed,      new],
        /* Fail */         [fixed,        still, lost,   still, fixed,        still],
        /* Skipped */      [now_compared, new,   none,   new,   now_compared, new],
        /* Error */        [fixed,        still, lost,   still, fixed,        still],
        /* ExpectedFail */ [changed,      new,   lost,   new,   none,         new],
        /* UnexpectedPass */ [fixed,      still, lost,   still, fixed,        still],
    ];
    for (i, &was) in statuses.iter().enumerate() {
        for (j, &is) in statuses.iter().enumerate() {
            let got = whats(&compare(
                &baseline_of(&[v("povray", "id", was, &[])]),
                &[v("povray", "id", is, &[])],
            ));
            let want: Vec<(ChangeKind, String)> = table[i][j]
                .iter()
                .map(|(k, w)| (*k, w.to_string()))
                .collect();
            assert_eq!(got, want, "{was} -> {is}");
        }
    }
    assert_eq!(
        statuses.len(),
        Status::names().len(),
        "a status missing from the table"
    );
}

#[test]
fn a_failing_entry_carries_its_reason_and_a_fixed_one_none() {
    let b = baseline_of(&[v("povray", "id", Status::Pass, &[])]);
    let mut now = v("povray", "id", Status::Fail, &[]);
    now.reason = format!("{}\nmore", "x".repeat(200));
    let o = compare(&b, &[now]);
    assert_eq!(o.changes[0].detail, format!("{}…", "x".repeat(160)));
    let b = baseline_of(&[v("povray", "id", Status::Fail, &[])]);
    let o = compare(&b, &[v("povray", "id", Status::Pass, &[])]);
    assert_eq!(
        (o.changes[0].what.as_str(), o.changes[0].detail.as_str()),
        ("fixed", "")
    );
}

#[test]
fn entries_match_one_to_one() {
    let both = v("trace", "id", Status::Pass, &[]);
    let gone = v("trace", "Z", Status::Pass, &[]);
    let mut new_pass = v("trace", "N", Status::Pass, &[]);
    new_pass.reason = "all good".into();
    let mut new_fail = v("embree", "id", Status::Fail, &[]);
    new_fail.reason = "12 interior mismatches".into();
    let mut new_silent = v("embree", "Z", Status::Error, &[]);
    new_silent.reason = String::new();
    let o = compare(
        &baseline_of(&[both.clone(), gone]),
        &[both, new_pass, new_fail, new_silent],
    );
    assert_eq!(o.compared, 1, "only the entry on both sides is compared");
    assert_eq!(o.regressions(), 4, "{:#?}", o.changes);
    let row = |backend: &str, buffer: &str| {
        let c = o
            .changes
            .iter()
            .find(|c| c.backend == backend && c.buffer == buffer)
            .unwrap();
        (
            c.kind,
            c.what.as_str(),
            c.before.as_str(),
            c.now.as_str(),
            c.detail.as_str(),
        )
    };
    use ChangeKind::Regression as R;
    assert_eq!(
        row("trace", "Z"),
        (
            R,
            "missing result",
            "pass",
            "—",
            "in the baseline, not in this run"
        )
    );
    assert_eq!(
        row("trace", "N"),
        (R, "not in the baseline", "—", "pass", "bless to accept it"),
        "a passing newcomer's reason is not news"
    );
    assert_eq!(
        row("embree", "id"),
        (
            R,
            "not in the baseline",
            "—",
            "fail",
            "12 interior mismatches"
        )
    );
    assert_eq!(
        row("embree", "Z"),
        (R, "not in the baseline", "—", "error", "bless to accept it"),
        "a failure without a reason"
    );
    assert_eq!(o.changes.iter().filter(|c| c.scene == "s").count(), 4);
}

#[test]
fn regressions_come_first_then_improvements_then_notes() {
    let b = baseline_of(&[
        v("a", "id", Status::Fail, &[]),
        v("b", "id", Status::ExpectedFail, &[]),
        v("c", "id", Status::Pass, &[]),
    ]);
    let o = compare(
        &b,
        &[
            v("a", "id", Status::Pass, &[]),
            v("b", "id", Status::Pass, &[]),
            v("c", "id", Status::Fail, &[]),
        ],
    );
    let kinds: Vec<ChangeKind> = o.changes.iter().map(|c| c.kind).collect();
    assert_eq!(
        kinds,
        vec![
            ChangeKind::Regression,
            ChangeKind::Improvement,
            ChangeKind::Note
        ]
    );
    assert_eq!(o.regressions(), 1);
    assert_eq!(o.compared, 3);
}

#[test]
fn only_depth_entries_have_their_errors_gated() {
    let e = |buffer: &str, x: f64| {
        with_errors(
            v("trace", buffer, Status::Pass, &[]),
            &[("max_rel_error", x)],
        )
    };
    assert_eq!(
        whats(&compare(&baseline_of(&[e("Z", 0.0)]), &[e("Z", 1.0)])),
        vec![(ChangeKind::Regression, "max_rel_error worse".into())]
    );
    assert!(compare(&baseline_of(&[e("id", 0.0)]), &[e("id", 1.0)])
        .changes
        .is_empty());
}

// ------------------------------------------------------------ typed records

#[test]
fn a_verdict_names_itself_and_reads_counts_before_errors() {
    let mut e = with_errors(
        v("povray", "Z", Status::Pass, &[("edge_mismatches", 3)]),
        &[("max_abs_error", 0.5)],
    );
    assert_eq!(e.key(), "s::povray::Z");
    assert_eq!(e.metric("edge_mismatches"), Some(3.0));
    assert_eq!(e.metric("max_abs_error"), Some(0.5));
    assert_eq!(e.metric("tie_mismatches"), None);
    e.errors.insert("edge_mismatches".into(), 9.0);
    assert_eq!(e.metric("edge_mismatches"), Some(3.0));
    assert!(is_bad(Status::Fail) && !is_bad(Status::ExpectedFail));
}

#[test]
fn fields_are_typed_from_both_sides() {
    let j = |s: &str| serde_json::from_str::<Value>(s).unwrap();
    assert_eq!(typed_status(Some(&j("\"fail\""))), Ok(Status::Fail));
    assert_eq!(typed_status(None), Err("missing".into()));
    assert_eq!(
        typed_status(Some(&j("\"FAIL\""))),
        Err("unknown status \"FAIL\"".into())
    );
    assert_eq!(typed_status(Some(&j("3"))), Err("3 is not a status".into()));
    assert_eq!(typed_count(None), Ok(None));
    assert_eq!(typed_count(Some(&Value::Null)), Ok(None));
    assert_eq!(typed_count(Some(&j("0"))), Ok(Some(0)));
    assert_eq!(typed_count(Some(&j("-1"))), Err("-1 is not a count".into()));
    assert_eq!(
        typed_count(Some(&j("1.5"))),
        Err("1.5 is not a count".into())
    );
    assert_eq!(typed_error(None), Ok(None));
    assert_eq!(typed_error(Some(&Value::Null)), Ok(None));
    assert_eq!(
        typed_error(Some(&j("0.0"))),
        Ok(Some(0.0)),
        "zero is an error"
    );
    assert_eq!(typed_error(Some(&j("2"))), Ok(Some(2.0)));
    assert!(typed_error(Some(&j("-1e-9"))).is_err());
    assert!(typed_error(Some(&j("\"1\""))).is_err());
}

fn result(status: &str, details: Value) -> ResultEntry {
    ResultEntry {
        scene: "s".into(),
        backend: "trace".into(),
        buffer: "id".into(),
        status: status.into(),
        reason: "r".into(),
        details: details.as_object().unwrap().clone(),
    }
}

fn results(list: Vec<ResultEntry>) -> Results {
    Results {
        format: RESULTS_FORMAT.into(),
        reference: "raster".into(),
        results: list,
    }
}

#[test]
fn verdicts_keep_recorded_numbers_and_refuse_bad_ones() {
    let r = results(vec![result(
        "expected_fail",
        json!({"crack_mismatches": 4, "tie_mismatches": null, "max_abs_error": 0.25,
               "max_rel_error": null, "pixels": 64, "rms_px": -3.0}),
    )]);
    let list = verdicts(&r).unwrap();
    assert_eq!(list.len(), 1);
    let e = &list[0];
    assert_eq!(e.status, Status::ExpectedFail);
    assert_eq!(e.reason, "r");
    assert_eq!(
        e.counts,
        BTreeMap::from([("crack_mismatches".to_string(), 4)])
    );
    assert_eq!(
        e.errors,
        BTreeMap::from([("max_abs_error".to_string(), 0.25)])
    );
    for (details, why) in [
        (
            json!({"pixels": -1}),
            "results[1].pixels: -1 is not a count",
        ),
        (
            json!({"failing_pixels": 0.5}),
            "results[1].failing_pixels: 0.5 is not a count",
        ),
        (
            json!({"crack_mismatches": -2}),
            "results[1].crack_mismatches: -2 is not a count",
        ),
        (
            json!({"max_rel_error": -1.0}),
            "results[1].max_rel_error: -1.0 is not an error (a non-negative number)",
        ),
    ] {
        let mut bad = r.clone();
        let mut e = result("pass", details);
        e.buffer = "Z".into();
        bad.results.push(e);
        assert_eq!(verdicts(&bad).unwrap_err().to_string(), why);
    }
    let mut other = r.clone();
    other.format = "rendiff-results/2".into();
    assert_eq!(
        verdicts(&other).unwrap_err().to_string(),
        "format is \"rendiff-results/2\", expected \"rendiff-results/1\""
    );
    let mut twice = r.clone();
    twice.results.push(result("pass", json!({})));
    twice.results.push(result("pass", json!({})));
    assert_eq!(
        verdicts(&twice).unwrap_err().to_string(),
        "results[1]: a second verdict for scene s, backend trace, buffer id (the first is results[0])"
    );
}

#[test]
fn a_results_file_is_refused_naming_the_file_and_field() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("results.json");
    let write = |v: Value| std::fs::write(&path, v.to_string()).unwrap();
    write(json!({"format": RESULTS_FORMAT, "reference": "raster",
                 "results": [{"scene": "s", "backend": "trace", "buffer": "id", "status": "pass", "edge_mismatches": 2}]}));
    let list = load_verdicts(&path).unwrap();
    assert_eq!(list[0].counts["edge_mismatches"], 2);
    // A status of the wrong type is named like an unknown one (before serde sees it).
    write(json!({"format": RESULTS_FORMAT, "reference": "raster",
                 "results": [{"scene": "s", "backend": "trace", "buffer": "id", "status": 1}]}));
    assert_eq!(
        load_verdicts(&path).unwrap_err().to_string(),
        format!("{}: results[0].status: 1 is not a status", path.display())
    );
    write(json!({"format": RESULTS_FORMAT, "reference": "raster",
                 "results": [{"scene": "s", "backend": "trace", "buffer": "id", "status": "pass", "mask_mismatches": -4}]}));
    assert_eq!(
        load_verdicts(&path).unwrap_err().to_string(),
        format!(
            "{}: results[0].mask_mismatches: -4 is not a count",
            path.display()
        )
    );
}

#[test]
fn baseline_fields_are_checked_before_typing() {
    assert_eq!(check_baseline_fields(&json!({})), Ok(()));
    assert_eq!(check_baseline_fields(&json!({"entries": 3})), Ok(()));
    let ok = json!({"status": "pass", "metrics": {"edge_mismatches": 1, "max_abs_error": 0.5}});
    assert_eq!(
        check_baseline_fields(&json!({"entries": [ok.clone()]})),
        Ok(())
    );
    for (bad, why) in [
        (json!({"metrics": {}}), "entries[1].status: missing"),
        (
            json!({"status": "pass", "metrics": {"crack_mismatches": -1}}),
            "entries[1].metrics.crack_mismatches: -1 is not a count",
        ),
        (
            json!({"status": "pass", "metrics": {"max_rel_error": -1}}),
            "entries[1].metrics.max_rel_error: -1 is not an error (a non-negative number)",
        ),
    ] {
        assert_eq!(
            check_baseline_fields(&json!({"entries": [ok.clone(), bad]})),
            Err(why.to_string())
        );
    }
}

#[test]
fn a_baseline_file_is_read_back_or_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("baseline.json");
    let b = baseline_of(&[v("trace", "id", Status::Pass, &[("crack_mismatches", 2)])]);
    let write = |b: &Baseline| std::fs::write(&path, serde_json::to_string(b).unwrap()).unwrap();
    write(&b);
    let back = load_baseline(&path).unwrap();
    assert_eq!(back.entries.len(), 1);
    assert_eq!(back.entries[0].metrics["crack_mismatches"], json!(2));
    let mut other = b.clone();
    other.format = "rendiff-baseline/0".into();
    write(&other);
    assert_eq!(
        load_baseline(&path).unwrap_err().to_string(),
        format!(
            "{}: format is \"rendiff-baseline/0\", expected \"rendiff-baseline/1\"",
            path.display()
        )
    );
    let mut twice = b.clone();
    twice.entries.push(twice.entries[0].clone());
    write(&twice);
    assert!(load_baseline(&path)
        .unwrap_err()
        .to_string()
        .starts_with(&format!("{}: entries[1]: a second verdict", path.display())));
}

// ------------------------------------------------------------ the command on a run folder

/// A run folder with a manifest and results (no renders: bless reads them
/// only for depth scales and seeds, which then default).
fn json_run(run: &Path, scenes: &[&str]) {
    common_runs::json_run(
        run,
        scenes,
        &["trace"],
        &["id", "Z"],
        json!({"tie_mismatches": 1}),
    );
}

#[test]
fn gate_refuses_an_incomplete_run_and_a_garbled_manifest() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    json_run(&run, &["alpha"]);
    let baseline = dir.path().join("baseline.json");
    bless(&run, &baseline, &BlessOptions::default()).unwrap();
    std::fs::write(run.join("manifest.json"), "{not json").unwrap();
    let e = gate(&baseline, &run).unwrap_err().to_string();
    assert!(
        e.contains("manifest.json: not a valid rendiff manifest"),
        "{e}"
    );
    std::fs::remove_file(run.join("manifest.json")).unwrap();
    let (text, passed) = gate(&baseline, &run).unwrap();
    assert!(
        passed,
        "a run without a manifest is gated on its verdicts: {text}"
    );
    std::fs::write(
        run.join(crate::check::manifest::INCOMPLETE_MARKER),
        "stopped",
    )
    .unwrap();
    let e = gate(&baseline, &run).unwrap_err().to_string();
    assert!(e.contains("incomplete run"), "{e}");
}

// ------------------------------------------------------------ bless

#[test]
fn bless_writes_every_verdict_with_its_numbers_noise_and_provenance() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    json_run(&run, &["beta", "alpha"]);
    edit_results(&run, |r| {
        r["results"][1]["max_abs_error"] = Value::Null;
        r["expectations"] = "tests/expectations.toml".into();
    });
    // A depth buffer for alpha's reference, and a seed in beta's render info.
    let z = vec![1.5, -6.0, f32::INFINITY, 2.0];
    let frame = crate::frame::Frame {
        width: 2,
        height: 2,
        z,
        prim: vec![0; 4],
        object: vec![0; 4],
        normal: vec![[0.0; 3]; 4],
        coverage: None,
        counters: Default::default(),
        renderer: "raster".into(),
        seconds: 0.0,
    };
    let attrs = BTreeMap::from([("seed".to_string(), "42".to_string())]);
    std::fs::create_dir_all(run.join("scenes/alpha")).unwrap();
    crate::exr_io::write_frame(&run.join("scenes/alpha/raster.exr"), &frame, &attrs).unwrap();
    edit_manifest(&run, |m| {
        for s in m["scenes"].as_array_mut().unwrap() {
            let scene = s["scene"].as_str().unwrap().to_string();
            let renders = s["renders"].as_array_mut().unwrap();
            if scene == "alpha" {
                renders.push(
                    json!({"backend": "raster", "status": "ok", "version": "rendiff 0.1.0",
                                    "exr": "scenes/alpha/raster.exr"}),
                );
                renders.push(
                    json!({"backend": "mitsuba", "status": "ok", "version": "3.5",
                                    "exr": "scenes/alpha/raster.exr"}),
                );
            } else {
                // An EXR with a seed too: what the backend reported comes first.
                renders.push(
                    json!({"backend": "povray", "status": "ok", "version": "3.7",
                                    "exr": "scenes/alpha/raster.exr",
                                    "info": {"passes": [{"pass_seed": 3}, {"Seed": 9}]}}),
                );
                renders.push(json!({"backend": "pbrt", "status": "ok", "version": "4",
                                    "info": {"pass_seed": 5, "seed": 7}}));
            }
        }
        m["reference"] = "raster".into();
    });
    edit_results(&run, |r| {
        let list = r["results"].as_array_mut().unwrap();
        for e in list.iter_mut() {
            if e["scene"] == "alpha" && e["buffer"] == "Z" {
                e["backend"] = "povray".into();
            }
        }
    });
    let opts = BlessOptions {
        command: "rendiff bless RUN".into(),
        ..BlessOptions::default()
    };
    let b = baseline_from_run(&run, &opts).unwrap();
    let keys: Vec<String> = b
        .entries
        .iter()
        .map(|e| format!("{}::{}::{}", e.scene, e.backend, e.buffer))
        .collect();
    assert_eq!(
        keys,
        [
            "alpha::povray::Z",
            "alpha::trace::id",
            "beta::trace::Z",
            "beta::trace::id"
        ],
        "sorted by scene, backend, buffer"
    );
    let e = &b.entries[0];
    assert_eq!(
        e.noise,
        Noise::for_backend("povray", 6.0),
        "alpha's farthest finite depth is 6"
    );
    assert_eq!(b.entries[2].noise, Noise::for_backend("trace", 0.0));
    let beta_z = &b.entries[2];
    assert_eq!(
        beta_z.metrics["max_abs_error"],
        Value::Null,
        "not recorded: not compared"
    );
    assert_eq!(beta_z.metrics["max_rel_error"], json!(0.0));
    assert_eq!(beta_z.metrics["tie_mismatches"], json!(1));
    assert_eq!(
        beta_z.metrics.len(),
        COUNT_METRICS.len() + ERROR_METRICS.len()
    );
    let p = &b.provenance;
    assert_eq!(p.command, "rendiff bless RUN");
    assert_eq!(p.run, run.display().to_string());
    assert_eq!(p.run_created, crate::report::overview::utc(1_795_000_000));
    assert_eq!(p.rendiff_version, env!("CARGO_PKG_VERSION"));
    assert_eq!(p.cpu, cpu_model());
    assert_eq!(p.expectations.as_deref(), Some("tests/expectations.toml"));
    assert_eq!(p.renderers["povray"], "3.7");
    assert_eq!(p.renderers["trace"], "rendiff 0.1.0");
    assert_eq!(
        p.seeds["raster"],
        json!("42"),
        "from the EXR's rendiff:seed"
    );
    assert_eq!(p.seeds["mitsuba"], json!("42"));
    assert_eq!(p.seeds["pbrt"], json!(7), "a plain seed over a derived one");
    assert_eq!(
        p.seeds["povray"],
        json!(3),
        "the first derived seed without a plain one"
    );
    assert!(!p.seeds.contains_key("trace"), "no seed, no EXR");
    assert!(p.blessed.ends_with('Z'));
    assert!(p.dropped.is_none());
    assert_eq!(b.format, BASELINE_FORMAT);
    assert!(b.policy.contains("crack"));
}

fn edit_manifest(run: &Path, f: impl FnOnce(&mut Value)) {
    let path = run.join("manifest.json");
    let mut m: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    f(&mut m);
    std::fs::write(&path, m.to_string()).unwrap();
}

#[test]
fn seeds_are_found_at_any_depth_by_name() {
    let mut out = Vec::new();
    find_seeds(
        &json!({"a": {"RandomSeed": 1, "b": [{"seed": 2}, 3]}, "seed_list": [4], "c": "seed"}),
        &mut out,
    );
    out.sort_by(|a, b| a.0.cmp(&b.0));
    assert_eq!(
        out,
        vec![
            ("RandomSeed".to_string(), json!(1)),
            ("seed".to_string(), json!(2)),
            ("seed_list".to_string(), json!([4])),
        ]
    );
}

#[test]
fn the_cpu_model_comes_from_cpuinfo() {
    let cpu = cpu_model();
    let line = std::fs::read_to_string("/proc/cpuinfo").ok().and_then(|t| {
        t.lines()
            .find(|l| l.starts_with("model name"))
            .map(String::from)
    });
    match line {
        Some(l) => assert!(
            !cpu.is_empty() && l.ends_with(&cpu) && !cpu.contains(':'),
            "{cpu} from {l}"
        ),
        None => assert_eq!(cpu, "unknown"),
    }
}

#[test]
fn bless_refuses_failures_scene_changes_and_silent_drops() {
    let dir = tempfile::tempdir().unwrap();
    let baseline = dir.path().join("baseline.json");
    let run = dir.path().join("run");
    json_run(&run, &["alpha", "beta"]);
    bless(&run, &baseline, &BlessOptions::default()).unwrap();
    let blessed = std::fs::read(&baseline).unwrap();
    let refused = |opts: &BlessOptions| {
        let e = bless(&run, &baseline, opts).unwrap_err().to_string();
        assert_eq!(
            std::fs::read(&baseline).unwrap(),
            blessed,
            "a refused bless wrote: {e}"
        );
        e
    };
    // A failing verdict.
    edit_results(&run, |r| r["results"][0]["status"] = "fail".into());
    let e = refused(&BlessOptions::default());
    assert!(
        e.contains("1 failing verdict, e.g. alpha::trace::id (fail)")
            && e.contains("--allow-failures"),
        "{e}"
    );
    let allow = BlessOptions {
        allow_failures: true,
        ..BlessOptions::default()
    };
    bless(&run, &baseline, &allow).unwrap();
    std::fs::write(&baseline, &blessed).unwrap();
    edit_results(&run, |r| r["results"][0]["status"] = "pass".into());
    // A scene removed.
    json_run(&run, &["alpha"]);
    let e = refused(&BlessOptions::default());
    assert!(
        e.contains("removed 1: \"beta\"") && e.contains("--allow-scene-changes"),
        "{e}"
    );
    // An entry of a kept scene dropped: refused even with scene changes allowed.
    json_run(&run, &["alpha", "beta"]);
    edit_results(&run, |r| {
        r["results"].as_array_mut().unwrap().remove(3);
    });
    let changes = BlessOptions {
        allow_scene_changes: true,
        ..BlessOptions::default()
    };
    let e = refused(&changes);
    assert!(
        e.contains("1 entry of the baseline's scenes is not in the run and would be dropped: beta::trace::Z")
            && e.contains("--drop-reason"),
        "{e}"
    );
    let e = refused(&BlessOptions {
        drop_reason: Some("  ".into()),
        ..changes.clone()
    });
    assert!(e.contains("--drop-reason is empty"), "{e}");
    let b = bless(
        &run,
        &baseline,
        &BlessOptions {
            drop_reason: Some("Z is gone".into()),
            ..BlessOptions::default()
        },
    )
    .unwrap();
    let d = b.provenance.dropped.unwrap();
    assert_eq!(
        (d.reason.as_str(), d.entries),
        ("Z is gone", vec!["beta::trace::Z".to_string()])
    );
    assert_eq!(load_baseline(&baseline).unwrap().entries.len(), 3);
    // A baseline that cannot be read is replaced only with scene changes allowed.
    std::fs::write(&baseline, "garbage").unwrap();
    json_run(&run, &["alpha", "beta"]);
    let e = bless(&run, &baseline, &BlessOptions::default()).unwrap_err();
    assert!(format!("{e:#}").contains("--allow-scene-changes"), "{e:#}");
    assert_eq!(std::fs::read(&baseline).unwrap(), b"garbage");
    bless(&run, &baseline, &changes).unwrap();
    assert_eq!(load_baseline(&baseline).unwrap().entries.len(), 4);
}

#[test]
fn what_bless_would_drop_is_named_then_counted() {
    let scene = |s: &str, bufs: &[&str]| -> Vec<Verdict> {
        bufs.iter()
            .map(|b| Verdict {
                scene: s.into(),
                ..v("trace", b, Status::Pass, &[])
            })
            .collect()
    };
    let bufs: Vec<String> = (0..12).map(|i| format!("b{i:02}")).collect();
    let refs: Vec<&str> = bufs.iter().map(String::as_str).collect();
    let before = baseline_of(&[scene("a", &refs), scene("gone", &["id"])].concat());
    let now = baseline_of(&scene("a", &["b00"]));
    let dropped = dropped_entries(&before, &now);
    assert_eq!(
        dropped.len(),
        11,
        "entries of a removed scene are not drops: {dropped:?}"
    );
    assert_eq!(dropped[0], "a::trace::b01");
    let line = dropped_summary(&dropped);
    assert!(
        line.starts_with("11 entries of the baseline's scenes are not in the run"),
        "{line}"
    );
    assert!(
        line.contains("a::trace::b10") && !line.contains("a::trace::b11"),
        "{line}"
    );
    assert!(line.ends_with(" and 1 more"), "{line}");
    let ten = dropped_summary(&dropped[..10]);
    assert!(ten.ends_with("a::trace::b10"), "{ten}");
    let one = dropped_summary(&dropped[..1]);
    assert_eq!(
        one,
        "1 entry of the baseline's scenes is not in the run and would be dropped: a::trace::b01"
    );
}

#[test]
fn failure_summaries_name_scene_errors_then_failing_verdicts() {
    let mut broken = v("raster", SCENE_BUFFER, Status::Error, &[]);
    broken.scene = "zz".into();
    broken.reason = "cannot load scene: bad".into();
    let skipped_scene = v("raster", SCENE_BUFFER, Status::Skipped, &[]);
    let failing = |backend: &str, status| v(backend, "id", status, &[]);
    assert!(is_scene_error(&broken));
    assert!(!is_scene_error(&skipped_scene));
    assert!(!is_scene_error(&failing("trace", Status::Error)));
    assert_eq!(
        failure_summary(&[skipped_scene.clone(), failing("a", Status::Pass)]),
        None
    );
    assert_eq!(
        failure_summary(&[broken.clone()]).unwrap(),
        "1 scene could not be loaded: zz (cannot load scene: bad)"
    );
    let mut two = broken.clone();
    two.scene = "yy".into();
    let all = [
        broken,
        two,
        failing("a", Status::Fail),
        failing("b", Status::Error),
        failing("c", Status::UnexpectedPass),
        failing("d", Status::Error),
        failing("e", Status::ExpectedFail),
    ];
    assert_eq!(
        failure_summary(&all).unwrap(),
        "2 scenes could not be loaded: zz (cannot load scene: bad), yy (cannot load scene: bad); \
         4 failing verdicts (2 of them errors), e.g. s::a::id (fail), s::b::id (error), s::c::id (unexpected_pass)"
    );
    assert_eq!(
        failure_summary(&[failing("a", Status::Fail)]).unwrap(),
        "1 failing verdict, e.g. s::a::id (fail)"
    );
}

#[test]
fn scene_changes_are_listed_or_said_to_be_none() {
    let at = |scenes: &[&str]| {
        baseline_of(
            &scenes
                .iter()
                .map(|s| Verdict {
                    scene: s.to_string(),
                    ..v("trace", "id", Status::Pass, &[])
                })
                .collect::<Vec<_>>(),
        )
    };
    let (before, now) = (at(&["a", "b"]), at(&["a", "b", "c"]));
    assert_eq!(
        scene_changes(&before, &now),
        (vec!["c".to_string()], vec![])
    );
    assert_eq!(
        scene_change_summary(&before, &now).unwrap(),
        "the run's scenes differ from the baseline's: added 1: \"c\"; removed 0: none"
    );
    assert_eq!(
        scene_change_summary(&now, &before).unwrap(),
        "the run's scenes differ from the baseline's: added 0: none; removed 1: \"c\""
    );
    assert_eq!(scene_change_summary(&now, &now), None);
}

// ------------------------------------------------------------ the markdown summary

fn manifest_with(versions: &[(&str, &str)]) -> Manifest {
    serde_json::from_value(json!({
        "format": "rendiff-manifest/1", "reference": "raster", "created_unix": 0u64,
        "rendiff_version": "0.1.0",
        "scenes": [{"scene": "s", "scene_file": "s.toml", "resolved": "r", "requires": [],
                    "renders": versions.iter().map(|(b, v)| json!({"backend": b, "status": "ok", "version": v})).collect::<Vec<_>>()}]
    }))
    .unwrap()
}

#[test]
fn renderer_versions_are_joined_per_backend() {
    let m = manifest_with(&[("a", "1"), ("a", "2"), ("a", "1"), ("b", ""), ("c", "3")]);
    let got = renderer_versions(&m);
    assert_eq!(got["a"], "1; 2");
    assert_eq!(got["b"], "", "a backend without a version is still named");
    assert_eq!(got["c"], "3");
}

#[test]
fn the_summary_says_pass_or_fail_and_groups_changes_by_entry() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    std::fs::create_dir_all(&run).unwrap();
    let mut b = baseline_of(&[
        v(
            "a",
            "id",
            Status::Pass,
            &[("edge_mismatches", 1), ("tie_mismatches", 1)],
        ),
        v("b", "id", Status::Fail, &[]),
    ]);
    b.provenance.cpu = "CPU <x>".into();
    b.provenance.renderers = BTreeMap::from([("a".into(), "1".into()), ("b".into(), "1".into())]);
    let o = compare(
        &b,
        &[
            v(
                "a",
                "id",
                Status::Pass,
                &[("edge_mismatches", 2), ("tie_mismatches", 0)],
            ),
            v("b", "id", Status::Pass, &[]),
        ],
    );
    let m = manifest_with(&[("a", "2"), ("b", "1"), ("c", "9")]);
    let s = markdown(&o, &b, "base.json", &run, Some(&m));
    assert!(
        s.starts_with("## rendiff gate: FAIL — 1 regressed entry, 1 improved\n"),
        "{s}"
    );
    assert!(
        s.contains("CPU &lt;x&gt;") && s.contains("2 entries compared"),
        "{s}"
    );
    assert!(s.contains("### Regressions (fail the gate): 1\n"), "{s}");
    assert!(
        s.contains("| s | a | id | edge_mismatches worse: 1 → 2 (+1) — limit 1; tie_mismatches better: 1 → 0 (-1) |"),
        "one row per entry, in the section of its worst change:\n{s}"
    );
    assert!(
        s.contains("[report/s.html](") && s.contains("/run/report/s.html#b-a)"),
        "{s}"
    );
    assert!(
        s.contains("### Improvements (run `rendiff bless` to lock them in): 1\n"),
        "{s}"
    );
    assert!(!s.contains("### Notes"), "{s}");
    assert!(
        s.contains("- a: 1 → 2") && s.contains("- c: new backend (9)") && !s.contains("- b:"),
        "{s}"
    );
    assert!(s.contains("_No report in this run folder yet"), "{s}");
    assert!(!s.contains("Every verdict and number matches"), "{s}");
    let same = compare(
        &b,
        &[
            v(
                "a",
                "id",
                Status::Pass,
                &[("edge_mismatches", 1), ("tie_mismatches", 1)],
            ),
            v("b", "id", Status::Fail, &[]),
        ],
    );
    std::fs::create_dir_all(run.join("report")).unwrap();
    std::fs::write(run.join("report/index.html"), "").unwrap();
    let s = markdown(&same, &b, "base.json", &run, None);
    assert!(
        s.starts_with("## rendiff gate: PASS — 0 regressed entries, 0 improved\n"),
        "{s}"
    );
    assert!(s.contains("### Notes: 1\n"), "{s}");
    assert!(
        !s.contains("Every verdict and number matches"),
        "a note is a change: {s}"
    );
    assert!(
        !s.contains("_No report") && !s.contains("Renderer versions"),
        "{s}"
    );
    let clean = Baseline {
        entries: b.entries[..1].to_vec(),
        ..b.clone()
    };
    let s = markdown(
        &compare(
            &clean,
            &[v(
                "a",
                "id",
                Status::Pass,
                &[("edge_mismatches", 1), ("tie_mismatches", 1)],
            )],
        ),
        &clean,
        "base.json",
        &run,
        Some(&manifest_with(&[("a", "1")])),
    );
    assert!(
        s.contains("Every verdict and number matches the baseline"),
        "{s}"
    );
    assert!(!s.contains("###"), "{s}");
}

#[test]
fn a_long_summary_is_cut_at_max_rows_per_section() {
    let many: Vec<Verdict> = (0..MAX_ROWS + 3)
        .map(|i| v(&format!("be{i:03}"), "id", Status::Pass, &[]))
        .collect();
    let b = baseline_of(&many);
    let failing: Vec<Verdict> = many
        .iter()
        .map(|e| Verdict {
            status: Status::Fail,
            ..e.clone()
        })
        .collect();
    let o = compare(&b, &failing);
    let s = markdown(&o, &b, "b", Path::new("run"), None);
    assert_eq!(
        s.matches("new failure: pass → fail").count(),
        MAX_ROWS,
        "{s}"
    );
    assert!(
        s.contains("\n… and 3 more; every verdict is in the report.\n"),
        "{s}"
    );
    let o = compare(
        &b,
        &failing[..MAX_ROWS]
            .iter()
            .cloned()
            .chain(many[MAX_ROWS..].iter().cloned())
            .collect::<Vec<_>>(),
    );
    let s = markdown(&o, &b, "b", Path::new("run"), None);
    assert!(
        !s.contains("more; every verdict"),
        "exactly MAX_ROWS rows: {s}"
    );
}

// ------------------------------------------------------------ noise and markdown cells

#[test]
fn exact_backends_allow_nothing_and_external_ones_a_little() {
    let exact = Noise::for_backend("trace", 10.0);
    assert_eq!(exact.limit("max_abs_error", 0.0), 0.0);
    assert_eq!(exact.limit("edge_mismatches", 3.0), 3.0);
    let ext = Noise::for_backend("povray", 4.0);
    assert_eq!(ext.limit("edge_mismatches", 3.0), 3.0);
    let l = ext.limit("max_abs_error", 1e-6);
    assert!(l > 1.5e-6 && l < 1.5e-6 + 1e-6);
    assert!(ext.improved_below("max_abs_error", 1e-6) < 1e-6);
}

#[test]
fn markdown_cells_cannot_carry_markup() {
    let s = md("<img src=x onerror=alert(1)>|[a](b)`");
    assert_eq!(
        s, "&lt;img src=x onerror=alert(1)&gt;\\|\\[a\\](b)\\`",
        "no tag, link, cell break or code span survives"
    );
}

#[test]
fn markdown_cells_carry_no_terminal_escapes_and_no_line_breaks() {
    // The summary is printed on the terminal: a scene named with an
    // escape sequence recoloured it, a bidi override reordered it.
    let s = md("a\u{1b}[31mred\u{7}\u{202e}txt\nrow");
    assert!(
        !s.chars().any(|c| c.is_control() || c == '\u{202e}'),
        "{s:?}"
    );
    assert!(s.contains("\\u{1b}") && s.contains("\\u{202e}"), "{s:?}");
}

#[test]
fn markdown_escapes_each_special_character_and_keeps_the_rest() {
    assert_eq!(md("a&b\r*~\\_é"), "a&amp;b \\*\\~\\\\_é");
    for c in [
        '\u{200e}', '\u{200f}', '\u{202a}', '\u{202e}', '\u{2066}', '\u{2069}',
    ] {
        assert_eq!(md(&c.to_string()), c.escape_unicode().to_string(), "{c:?}");
    }
    for c in ['\u{200d}', '\u{2029}', '\u{202f}', '\u{2065}', '\u{206a}'] {
        assert_eq!(
            md(&c.to_string()),
            c.to_string(),
            "{c:?} is not a bidi control"
        );
    }
}
