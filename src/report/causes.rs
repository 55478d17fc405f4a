//! The report's "Needs attention": failing verdicts grouped by the cause they
//! share, one row per cause, so that three root causes read as three rows and
//! not as the seventy verdicts they spoil. A run used to list every failing
//! entry, and the calibration failure that explained most of them came after
//! all of them.
//!
//! Causes, in the order a reviewer should fix them:
//! 1. a camera calibration that failed (results.json `calibration`): its probe
//!    verdicts and the entries it left unjudged (`not_judged: "calibration"`)
//!    hang under it, without their class counts (measured with a wrong camera,
//!    they say nothing);
//! 2. a scene that could not be loaded;
//! 3. a renderer error (a render or a comparison that failed), one per renderer;
//! 4. a class of mismatch on one renderer, one buffer, across scenes (the
//!    verdict's worst non-zero class: interior, then crack, edge, tie), or an
//!    unexpected pass.

use super::data::{is_scene_error, num, status_rank, RunData, SceneData};
use crate::check::manifest::ResultEntry;
use crate::vocab::{RenderStatus, Status};
use serde_json::Value;

/// The results.json field naming what left an entry unjudged
/// (harness `calibration.NOT_JUDGED_FIELD`).
pub const NOT_JUDGED_FIELD: &str = "not_judged";

/// What kind of cause a group is (its order in the report).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Kind {
    /// A backend's camera failed calibration.
    Calibration,
    /// A scene could not be loaded.
    Scene,
    /// A renderer failed to render (or its render could not be compared).
    RendererError,
    /// One class of mismatch on one renderer and buffer, across scenes.
    Mismatch,
}

/// One member of a cause: a verdict, or a failed render with no verdict.
#[derive(Debug, Clone)]
pub struct Member<'a> {
    /// Its scene.
    pub scene: &'a SceneData,
    /// Its buffer ("render" for a render with no verdict).
    pub buffer: String,
    /// Its status.
    pub status: String,
    /// Its reason or message.
    pub reason: String,
    /// The verdict, when there is one (its counts are shown unless stale).
    pub entry: Option<&'a ResultEntry>,
}

/// One root cause and the failures it explains.
#[derive(Debug, Clone)]
pub struct Cause<'a> {
    /// Its kind (its order).
    pub kind: Kind,
    /// The renderer it concerns (the reference for a scene error).
    pub backend: String,
    /// What went wrong, in a few words (plain text).
    pub title: String,
    /// The first reason, the one that names the fault (plain text).
    pub why: String,
    /// Where the evidence is: a scene (its page) and an anchor on it.
    pub evidence: Option<(&'a SceneData, String)>,
    /// The failures it explains.
    pub members: Vec<Member<'a>>,
    /// Whether the members' class counts mean anything (false under a
    /// failed calibration).
    pub counts_valid: bool,
}

/// The page anchor of a backend's section on a scene page.
fn backend_anchor(backend: &str) -> String {
    format!("#b-{}", super::data::page_stem(backend))
}

/// True for an entry left unjudged by a failed calibration of its backend.
fn unjudged_by_calibration(e: &ResultEntry, failed: &[String]) -> bool {
    if !failed.contains(&e.backend) || status_rank(&e.status) != 0 {
        return false;
    }
    match e.details.get(NOT_JUDGED_FIELD).and_then(Value::as_str) {
        Some(v) => v == "calibration",
        // Runs of an older harness: the reason is all that says so.
        None => e.reason.starts_with("not judged:") && e.reason.contains("calibration"),
    }
}

fn is_probe(s: &SceneData) -> bool {
    s.runs.as_ref().is_some_and(|r| r.role == "calibration")
        || s.results.iter().any(|e| e.buffer == "camera")
}

/// The worst non-zero mismatch class of a failing verdict, in words.
fn mismatch_class(e: &ResultEntry) -> &'static str {
    if e.status == "unexpected_pass" {
        return "unexpected pass";
    }
    let has = |k: &str| num(e, k).is_some_and(|v| v > 0.0);
    if has("interior_mismatches") {
        "interior mismatches"
    } else if has("crack_mismatches") {
        "cracks"
    } else if has("mask_mismatches") {
        "hit/miss mismatches"
    } else if has("edge_mismatches") || has("tie_mismatches") {
        "edge or tie mismatches beyond the declared bound"
    } else {
        "failures"
    }
}

/// A verdict's mismatching pixels (all classes), for choosing the worst scene.
fn weight(e: &ResultEntry) -> f64 {
    ["interior_mismatches", "crack_mismatches", "mask_mismatches"]
        .iter()
        .filter_map(|k| num(e, k))
        .sum()
}

fn member<'a>(s: &'a SceneData, e: &'a ResultEntry) -> Member<'a> {
    Member {
        scene: s,
        buffer: e.buffer.clone(),
        status: e.status.clone(),
        reason: e.reason.clone(),
        entry: Some(e),
    }
}

/// Every failure of the run, grouped by cause, causes in report order.
pub fn group(data: &RunData) -> Vec<Cause<'_>> {
    let mut causes: Vec<Cause<'_>> = Vec::new();
    let failed: Vec<String> = data
        .calibration
        .iter()
        .flat_map(|c| c.iter())
        .filter(|(_, v)| v.get("status").and_then(Value::as_str) == Some(Status::Fail.as_str()))
        .map(|(b, _)| b.clone())
        .collect();
    // 1. failed calibrations
    for backend in &failed {
        let cal = &data.calibration.as_ref().expect("failed is non-empty")[backend];
        let probe = cal.get("scene").and_then(Value::as_str).unwrap_or("");
        let evidence = data
            .scenes
            .iter()
            .find(|s| s.name == probe)
            .map(|s| (s, "#camera".to_string()));
        causes.push(Cause {
            kind: Kind::Calibration,
            backend: backend.clone(),
            title: format!("{backend}'s camera failed calibration"),
            why: cal
                .get("reason")
                .and_then(Value::as_str)
                .unwrap_or("")
                .to_string(),
            evidence,
            members: Vec::new(),
            counts_valid: false,
        });
    }
    let bad = data
        .scenes
        .iter()
        .flat_map(|s| s.results.iter().map(move |e| (s, e)))
        .filter(|(_, e)| status_rank(&e.status) == 0);
    let mut rest: Vec<(&SceneData, &ResultEntry)> = Vec::new();
    for (s, e) in bad {
        let cal = causes
            .iter_mut()
            .find(|c| c.kind == Kind::Calibration && c.backend == e.backend);
        match cal {
            Some(c) if (is_probe(s) || unjudged_by_calibration(e, &failed)) => {
                c.members.push(member(s, e));
            }
            _ => rest.push((s, e)),
        }
    }
    // 2. scenes that could not be loaded
    for (s, e) in rest.iter().filter(|(_, e)| is_scene_error(e)) {
        causes.push(Cause {
            kind: Kind::Scene,
            backend: e.backend.clone(),
            title: format!("scene {} could not be loaded", s.name),
            why: e.reason.clone(),
            evidence: Some((s, String::new())),
            members: vec![member(s, e)],
            counts_valid: false,
        });
    }
    // 3. renderer errors: verdicts in error, and failed renders with no verdict
    let mut errors: Vec<(String, Member<'_>)> = rest
        .iter()
        .filter(|(_, e)| !is_scene_error(e) && e.status == Status::Error.as_str())
        .map(|(s, e)| (e.backend.clone(), member(s, e)))
        .collect();
    for s in &data.scenes {
        for r in s.unjudged_renders(RenderStatus::Error) {
            errors.push((
                r.backend.clone(),
                Member {
                    scene: s,
                    buffer: "render".into(),
                    status: r.status.to_string(),
                    reason: r.message.clone(),
                    entry: None,
                },
            ));
        }
    }
    for (backend, m) in errors {
        match causes
            .iter_mut()
            .find(|c| c.kind == Kind::RendererError && c.backend == backend)
        {
            Some(c) => c.members.push(m),
            None => causes.push(Cause {
                kind: Kind::RendererError,
                title: format!("{backend} failed to render or to be compared"),
                why: m.reason.clone(),
                evidence: Some((m.scene, backend_anchor(&backend))),
                backend,
                members: vec![m],
                counts_valid: false,
            }),
        }
    }
    // 4. classes of mismatch per renderer and buffer
    for (s, e) in rest
        .iter()
        .filter(|(_, e)| e.status != Status::Error.as_str())
    {
        let class = mismatch_class(e);
        let title = format!("{}: {} {class}", e.backend, e.buffer);
        match causes
            .iter_mut()
            .find(|c| c.kind == Kind::Mismatch && c.title == title)
        {
            Some(c) => c.members.push(member(s, e)),
            None => causes.push(Cause {
                kind: Kind::Mismatch,
                backend: e.backend.clone(),
                title,
                why: e.reason.clone(),
                evidence: Some((s, backend_anchor(&e.backend))),
                members: vec![member(s, e)],
                counts_valid: true,
            }),
        }
    }
    // The evidence of a mismatch class: its worst scene.
    for c in causes.iter_mut().filter(|c| c.kind == Kind::Mismatch) {
        if let Some(worst) = c
            .members
            .iter()
            .filter_map(|m| m.entry.map(|e| (m, weight(e))))
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(m, _)| m.clone())
        {
            c.why = worst.reason.clone();
            c.evidence = Some((worst.scene, backend_anchor(&c.backend)));
        }
    }
    causes.sort_by(|a, b| {
        a.kind
            .cmp(&b.kind)
            .then(b.members.len().cmp(&a.members.len()))
            .then(a.title.cmp(&b.title))
    });
    for c in &mut causes {
        c.members.sort_by(|a, b| {
            (a.scene.name.as_str(), a.buffer.as_str())
                .cmp(&(b.scene.name.as_str(), b.buffer.as_str()))
        });
    }
    causes
}

/// The number of failing verdicts and failed renders that no cause explains
/// (none: every one is in exactly one cause; a test holds it).
pub fn unexplained(data: &RunData, causes: &[Cause<'_>]) -> usize {
    let listed: usize = causes.iter().map(|c| c.members.len()).sum();
    let failing = data
        .scenes
        .iter()
        .flat_map(|s| s.results.iter())
        .filter(|e| status_rank(&e.status) == 0)
        .count();
    let renders = data
        .scenes
        .iter()
        .flat_map(|s| s.unjudged_renders(RenderStatus::Error))
        .count();
    (failing + renders).saturating_sub(listed)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check::manifest::Manifest;
    use serde_json::json;
    use std::path::PathBuf;

    fn entry(scene: &str, backend: &str, buffer: &str, status: &str, extra: Value) -> ResultEntry {
        let mut v = json!({"scene": scene, "backend": backend, "buffer": buffer, "status": status,
                           "reason": format!("{backend} {buffer} on {scene}")});
        v.as_object_mut()
            .unwrap()
            .extend(extra.as_object().unwrap().clone());
        serde_json::from_value(v).unwrap()
    }

    fn scene(name: &str, results: Vec<ResultEntry>) -> SceneData {
        SceneData {
            name: name.into(),
            page: name.into(),
            runs: None,
            results,
            resolved: None,
        }
    }

    /// A run with one cause of each kind: a failed calibration and an entry it
    /// left unjudged, a scene that could not load, a renderer's errors on two
    /// scenes, and one class of mismatch on one renderer across two scenes.
    fn run() -> RunData {
        let manifest: Manifest = serde_json::from_value(json!({
            "format": crate::check::manifest::MANIFEST_FORMAT, "reference": "raster",
            "created_unix": 0, "rendiff_version": "0", "scenes": []}))
        .unwrap();
        let interior = |n: u64| json!({"interior_mismatches": n, "edge_mismatches": 3});
        let scenes = vec![
            scene(
                "a",
                vec![
                    entry(
                        "a",
                        "bent",
                        "id",
                        "error",
                        json!({"not_judged": "calibration"}),
                    ),
                    entry("a", "crashy", "Z", "error", json!({})),
                    entry("a", "leaky", "id", "fail", interior(2)),
                    entry("a", "leaky", "N", "pass", json!({})),
                ],
            ),
            scene(
                "b",
                vec![
                    entry("b", "crashy", "Z", "error", json!({})),
                    entry("b", "leaky", "id", "fail", interior(40)),
                ],
            ),
            scene(
                "broken",
                vec![entry("broken", "raster", "scene", "error", json!({}))],
            ),
        ];
        let mut calibration = serde_json::Map::new();
        calibration.insert(
            "bent".into(),
            json!({"status": "fail", "reason": "pixel-center offset", "scene": "probe"}),
        );
        calibration.insert("leaky".into(), json!({"status": "pass"}));
        RunData {
            dir: PathBuf::from("/run"),
            manifest,
            results: None,
            results_problem: None,
            expectations: None,
            calibration: Some(calibration),
            scenes,
        }
    }

    #[test]
    fn one_cause_per_root_in_the_order_to_fix_them() {
        let data = run();
        let causes = group(&data);
        let kinds: Vec<(Kind, &str, usize)> = causes
            .iter()
            .map(|c| (c.kind, c.backend.as_str(), c.members.len()))
            .collect();
        assert_eq!(
            kinds,
            [
                (Kind::Calibration, "bent", 1),
                (Kind::Scene, "raster", 1),
                (Kind::RendererError, "crashy", 2),
                (Kind::Mismatch, "leaky", 2),
            ]
        );
        assert!(!causes[0].counts_valid && causes[3].counts_valid);
        // A mismatch class points at its worst scene and names its class.
        let (worst, anchor) = causes[3].evidence.as_ref().unwrap();
        assert_eq!((worst.name.as_str(), anchor.as_str()), ("b", "#b-leaky"));
        assert_eq!(causes[3].title, "leaky: id interior mismatches");
        assert_eq!(unexplained(&data, &causes), 0);
    }
}
