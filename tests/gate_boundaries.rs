//! Every boundary of the gate's policy, from both sides: each count metric one
//! above and one below its baseline on an exact and an external backend, each
//! error metric at its limit and one ulp past it, and a crack count that
//! grows, named as such. A change that moves a boundary (a count the gate
//! stops holding, a limit that admits one ulp more) fails one of these; the
//! whole table of status transitions is a unit test beside the gate
//! (src/gate/tests.rs), where mutation testing runs it.

use rendiff::check::manifest::ResultEntry;
use rendiff::gate::{self, ChangeKind, Noise, Status};
use rendiff::vocab::MismatchClass;
use serde_json::{Map, Value};

mod common;
use common::gate::{baseline_of, verdicts, Z_FAR};

fn entry(backend: &str, buffer: &str, status: Status, metrics: &[(&str, f64)]) -> ResultEntry {
    let mut details = Map::new();
    for (k, v) in metrics {
        let v = if gate::COUNT_METRICS.contains(k) {
            Value::from(*v as u64)
        } else {
            Value::from(*v)
        };
        details.insert((*k).to_string(), v);
    }
    ResultEntry {
        scene: "s".into(),
        backend: backend.into(),
        buffer: buffer.into(),
        status: status.as_str().into(),
        reason: String::new(),
        details,
    }
}

/// The gate's changes for one entry blessed as `before` and run as `now`.
fn changes(before: &ResultEntry, now: &ResultEntry) -> Vec<(ChangeKind, String)> {
    let run = verdicts(vec![now.clone()]);
    gate::compare(&baseline_of(std::slice::from_ref(before)), &run)
        .changes
        .into_iter()
        .map(|c| (c.kind, c.what))
        .collect()
}

#[test]
fn every_mismatch_class_has_a_count_the_gate_holds() {
    for class in MismatchClass::names() {
        let m = format!("{class}_mismatches");
        assert!(
            gate::COUNT_METRICS.contains(&m.as_str()),
            "the verifier's class {class:?} has no count the gate holds ({m})"
        );
    }
}

#[test]
fn every_count_grows_by_one_into_a_regression_and_shrinks_by_one_into_an_improvement() {
    for backend in ["trace", "raster", "povray", "embree", "my_renderer"] {
        for m in gate::COUNT_METRICS {
            let base = entry(backend, "id", Status::Pass, &[(m, 5.0)]);
            let same = changes(&base, &base);
            assert!(same.is_empty(), "{backend} {m} unchanged: {same:?}");
            let up = changes(&base, &entry(backend, "id", Status::Pass, &[(m, 6.0)]));
            assert_eq!(
                up,
                vec![(ChangeKind::Regression, format!("{m} worse"))],
                "{backend}: {m} 5 -> 6"
            );
            let down = changes(&base, &entry(backend, "id", Status::Pass, &[(m, 4.0)]));
            assert_eq!(
                down,
                vec![(ChangeKind::Improvement, format!("{m} better"))],
                "{backend}: {m} 5 -> 4"
            );
        }
    }
}

#[test]
fn an_error_at_its_limit_passes_and_one_ulp_past_it_fails() {
    for backend in ["trace", "povray", "my_renderer"] {
        let noise = Noise::for_backend(backend, Z_FAR);
        for m in gate::ERROR_METRICS {
            for base_v in [0.0, 1e-6, 0.25] {
                let base = entry(backend, gate::ERROR_BUFFER, Status::Pass, &[(m, base_v)]);
                let at = |v: f64| {
                    changes(
                        &base,
                        &entry(backend, gate::ERROR_BUFFER, Status::Pass, &[(m, v)]),
                    )
                };
                let limit = noise.limit(m, base_v);
                assert!(
                    limit >= base_v,
                    "{backend} {m}: limit {limit} below base {base_v}"
                );
                assert!(
                    at(limit).is_empty(),
                    "{backend} {m} {base_v}: at the limit {limit}"
                );
                assert_eq!(
                    at(limit.next_up()),
                    vec![(ChangeKind::Regression, format!("{m} worse"))],
                    "{backend} {m} {base_v}: one ulp past the limit {limit}"
                );
                let better = noise.improved_below(m, base_v);
                if better > 0.0 {
                    assert!(at(better).is_empty(), "{backend} {m} {base_v}: at {better}");
                    assert_eq!(
                        at(better.next_down()),
                        vec![(ChangeKind::Improvement, format!("{m} better"))],
                        "{backend} {m} {base_v}: one ulp below {better}"
                    );
                }
            }
        }
    }
}

#[test]
fn the_exact_loops_may_not_move_at_all_and_external_ones_by_their_f32_noise() {
    let exact = Noise::for_backend("trace", Z_FAR);
    assert_eq!(exact.limit("max_abs_error", 0.0), 0.0);
    assert_eq!(exact.limit("max_abs_error", 1e-3), 1e-3);
    let external = Noise::for_backend("povray", Z_FAR);
    // Derivation (src/gate/mod.rs): x1.5 plus two f32 roundings of the farthest depth.
    assert_eq!(
        external.limit("max_abs_error", 0.0),
        gate::F32_SLACK * Z_FAR
    );
    assert_eq!(external.limit("max_rel_error", 0.0), gate::F32_SLACK);
    assert_eq!(
        external.limit("max_abs_error", 2.0),
        3.0 + gate::F32_SLACK * Z_FAR
    );
    for n in [exact, external] {
        for m in gate::COUNT_METRICS {
            assert_eq!(n.limit(m, 7.0), 7.0, "a count may not grow: {m}");
        }
    }
}

#[test]
fn errors_are_held_on_depth_entries_only() {
    for buffer in ["id", "N", "RGB"] {
        let base = entry("povray", buffer, Status::Pass, &[("max_abs_error", 1e-6)]);
        let now = entry("povray", buffer, Status::Pass, &[("max_abs_error", 1.0)]);
        assert!(changes(&base, &now).is_empty(), "{buffer}");
    }
}

/// The crack count by name (not through [`gate::COUNT_METRICS`], which a gate
/// that forgot it would forget here too): from zero and from a non-zero
/// count, on entries that pass and on accepted failures, while every other
/// count shrinks, it fails the gate.
#[test]
fn a_crack_count_that_grows_fails_the_gate_by_name() {
    let others = [
        ("edge_mismatches", 4.0),
        ("tie_mismatches", 4.0),
        ("interior_mismatches", 4.0),
        ("mask_mismatches", 4.0),
    ];
    let shrunk: Vec<(&str, f64)> = others.iter().map(|&(m, c)| (m, c - 1.0)).collect();
    for backend in ["raster", "trace", "embree", "povray"] {
        for status in [Status::Pass, Status::ExpectedFail, Status::Fail] {
            for from in [0.0, 3.0] {
                let with = |rest: &[(&str, f64)], crack: f64| {
                    let mut m = rest.to_vec();
                    m.push(("crack_mismatches", crack));
                    entry(backend, "id", status, &m)
                };
                let got = changes(&with(&others, from), &with(&shrunk, from + 1.0));
                let crack: Vec<_> = got
                    .iter()
                    .filter(|(_, what)| what == "crack_mismatches worse")
                    .collect();
                assert_eq!(
                    crack,
                    vec![&(ChangeKind::Regression, "crack_mismatches worse".to_string())],
                    "{backend} {status}: crack {from} -> {}: {got:?}",
                    from + 1.0
                );
                assert!(
                    changes(&with(&others, from), &with(&others, from))
                        .iter()
                        .all(|(k, _)| *k != ChangeKind::Regression),
                    "{backend} {status}: unchanged"
                );
            }
        }
    }
}
