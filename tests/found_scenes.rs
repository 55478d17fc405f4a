//! The disagreements `rendiff fuzz` found and `rendiff reduce` shrank, held in CI
//! (scenes/found/README.md, docs/fuzzing.md "What it found").
//!
//! Every scene in scenes/found/ goes through `rendiff check` on the renderers at
//! fault (POV-Ray, Mitsuba), judged with tests/expectations.toml: each known bug is
//! an `[[expect]]` with a two-sided bound on its failing pixels, so a renderer that
//! changes (fixed, or worse) fails here as an unexpected pass or a count out of
//! bounds. One test per (scene, backend, buffer), as in tests/conformance.rs; a
//! backend that is not installed shows as ignored with its reason. One more test
//! keeps the folder and the expectations in step: every found scene has an
//! `[[expect]]`, and every `[[expect]]` naming a found scene met its verdict.
//! (The other backends were checked on these scenes by hand and pass; conformance
//! does not read scenes/found, so the regression baseline is unchanged.)

mod common;
use common::trials::verdict_trial;
use libtest_mimic::{Arguments, Failed, Trial};
use rendiff::check::manifest::ResultEntry;
use rendiff::check::{self, CheckOptions};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The renderers the found scenes are about.
const AT_FAULT: [&str; 2] = ["povray", "mitsuba"];

fn main() {
    let args = Arguments::from_args();
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let trials = if args.list {
        vec![Trial::test("found::all", || Ok(()))]
    } else {
        trials(&root)
    };
    libtest_mimic::run(&args, trials).exit();
}

fn trials(root: &Path) -> Vec<Trial> {
    let run_dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("found-scenes-run");
    let _ = std::fs::remove_dir_all(&run_dir);
    let scenes =
        check::collect_scenes(&[root.join("scenes/found")]).expect("scenes/found is readable");
    let opts = CheckOptions {
        only: Some(AT_FAULT.iter().map(|s| s.to_string()).collect()),
        timeout: Duration::from_secs(300),
        ..CheckOptions::new(scenes.clone(), run_dir, root.to_path_buf())
    };
    let results = match check::run(&opts) {
        Ok(outcome) => outcome.results.results,
        Err(e) => {
            let msg = format!("{e:#}");
            return vec![Trial::test("found::harness", move || {
                Err(Failed::from(msg))
            })];
        }
    };
    let names: BTreeSet<String> = scenes
        .iter()
        .filter_map(|p| p.file_stem().map(|s| s.to_string_lossy().into_owned()))
        .collect();
    let expects = found_expectations(&root.join("tests/expectations.toml"), &names);
    let mut out = vec![in_step(names, expects, results.clone())];
    out.extend(results.into_iter().map(verdict_trial));
    out
}

/// (scene, backend, buffer) of every `[[expect]]` in `file` naming one of `names`.
fn found_expectations(file: &Path, names: &BTreeSet<String>) -> Vec<(String, String, String)> {
    let text = std::fs::read_to_string(file).expect("tests/expectations.toml is readable");
    let doc: toml::Table = toml::from_str(&text).expect("tests/expectations.toml is TOML");
    let field =
        |e: &toml::Value, k: &str| e.get(k).and_then(|v| v.as_str()).unwrap_or("").to_string();
    doc.get("expect")
        .and_then(|v| v.as_array())
        .into_iter()
        .flatten()
        .filter(|e| names.contains(&field(e, "scene")))
        .map(|e| (field(e, "scene"), field(e, "backend"), field(e, "buffer")))
        .collect()
}

/// Every found scene has an `[[expect]]`; every such entry met a verdict that is
/// `expected_fail` (or its backend was skipped: not installed here).
fn in_step(
    names: BTreeSet<String>,
    expects: Vec<(String, String, String)>,
    results: Vec<ResultEntry>,
) -> Trial {
    Trial::test("found::every_scene_and_expectation_in_step", move || {
        let mut problems = Vec::new();
        for n in &names {
            if !expects.iter().any(|(s, _, _)| s == n) {
                problems.push(format!(
                    "scenes/found/{n}.toml has no [[expect]] in tests/expectations.toml"
                ));
            }
        }
        for (scene, backend, buffer) in &expects {
            let r = results
                .iter()
                .find(|r| &r.scene == scene && &r.backend == backend && &r.buffer == buffer);
            match r {
                None => problems.push(format!(
                    "[[expect]] {scene}/{backend}/{buffer} met no verdict (renamed scene or buffer?)"
                )),
                Some(r) if r.status == "expected_fail" || r.status == "skipped" => {}
                Some(r) => problems.push(format!(
                    "[[expect]] {scene}/{backend}/{buffer}: {} ({})",
                    r.status, r.reason
                )),
            }
        }
        if problems.is_empty() {
            Ok(())
        } else {
            Err(Failed::from(problems.join("\n")))
        }
    })
}
