//! The regression gate (`rendiff gate --baseline FILE RUN`) and its only way to
//! change thresholds (`rendiff bless RUN --baseline FILE`).
//!
//! A check run's verdicts say whether each renderer is within its *recorded*
//! bounds; the gate says whether anything got *worse than last time*, which is
//! what a pull request must not do. The baseline (reports/baseline.json) holds
//! every verdict of a blessed run with its numbers, the noise each number may
//! show, and where it came from (renderer versions, CPU, command, date).
//!
//! Noise policy (set by bless, per entry, so the file says what is allowed):
//! * mismatch counts (`edge_mismatches`, `tie_mismatches`, `crack_mismatches`,
//!   `interior_mismatches`, `mask_mismatches`, any buffer: `id`, `Z`, `N`, ...)
//!   may not grow at all, allowed classes included: every backend here is
//!   deterministic (one sample at each pixel center for IDs and depth; Monte
//!   Carlo radiance uses fixed seeds, recorded in the provenance).
//! * depth errors (`max_abs_error`, `max_rel_error` of `Z` entries) may grow to
//!   `baseline × error_factor + slack`. The core loops (raster, trace) are
//!   exact by construction: factor 1, slack 0. External renderers get factor
//!   1.5 plus two f32 roundings of slack (relative 2^-22; absolute 2^-22 × the
//!   scene's farthest reference depth), because a different CPU or SIMD path
//!   may round a last bit differently.
//! * every other entry (`N` normals, `camera` calibration probes, a scene that
//!   failed to load: buffer `scene`) is gated by its status and by being
//!   present on both sides. A number a side did not record (an older run or
//!   baseline) is not compared.
//!
//! Bless refuses a run with failing or erroring verdicts (scene load errors
//! named first) unless given `--allow-failures`, and a run whose set of
//! scenes differs from the current baseline's unless given
//! `--allow-scene-changes`.
//!
//! Both read results.json and the baseline into typed records ([`Verdict`],
//! [`BaselineEntry`]): a status is one of [`Status`], a count is unsigned and
//! an error a non-negative number (or null: not recorded). Anything else is
//! refused with one line naming the file and the field, e.g.
//! `RUN/results.json: results[12].status: unknown status "passs"`, never
//! read as an improvement.

use crate::check::manifest::{Manifest, ResultEntry, Results};
use crate::exr_io::{read_buffers, write_atomically};
use crate::report::data::run_relative;
use crate::report::overview::utc;
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::Path;

/// Format tag of the baseline file.
pub const BASELINE_FORMAT: &str = "rendiff-baseline/1";

/// Counts that must not grow: every mismatch class the verifier records
/// (edge and tie are allowed, crack is allowed only where a backend declares
/// it, interior never is), and hit/miss mask mismatches. Allowed is not
/// invisible: an allowed class that grows is still a regression.
pub const COUNT_METRICS: &[&str] = &[
    "edge_mismatches",
    "tie_mismatches",
    "crack_mismatches",
    "interior_mismatches",
    "mask_mismatches",
];

/// Buffer of the entry a scene that could not be loaded gets (backend: the reference).
pub const SCENE_BUFFER: &str = "scene";

/// Depth errors that may grow within their noise bound (gated on `Z` entries
/// only: a radiance error is a sample statistic, judged by its failing-pixel
/// counts and status instead).
pub const ERROR_METRICS: &[&str] = &["max_abs_error", "max_rel_error"];

/// The buffer whose errors are gated.
pub const ERROR_BUFFER: &str = "Z";

/// Backends that are exact by construction (no error may appear at all).
pub const EXACT_BACKENDS: &[&str] = &["raster", "trace"];

/// Relative slack of two f32 roundings.
pub const F32_SLACK: f64 = 1.0 / 4_194_304.0; // 2^-22

/// A verdict's status, as results.json and the baseline spell it (one home:
/// `vocab`).
pub use crate::vocab::Status;

/// Statuses that turn a run red.
pub fn is_bad(status: Status) -> bool {
    status.is_bad()
}

/// One verdict of results.json, typed: the gate's and bless's view of a
/// [`ResultEntry`] (see [`verdicts`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Verdict {
    /// Scene stem.
    pub scene: String,
    /// Backend compared with the reference.
    pub backend: String,
    /// Buffer (`id`, `Z`, `N`, `camera`, `scene`, ...).
    pub buffer: String,
    /// Status.
    pub status: Status,
    /// Why (skip reason, error message, failure summary, expectation reason).
    pub reason: String,
    /// The [`COUNT_METRICS`] it recorded (absent or null: not recorded).
    pub counts: BTreeMap<String, u64>,
    /// The [`ERROR_METRICS`] it recorded (absent or null: not recorded).
    pub errors: BTreeMap<String, f64>,
}

impl Verdict {
    /// `scene::backend::buffer`, the name a test or a report row uses.
    pub fn key(&self) -> String {
        format!("{}::{}::{}", self.scene, self.backend, self.buffer)
    }

    /// A recorded count or error, as a number.
    pub fn metric(&self, name: &str) -> Option<f64> {
        self.counts
            .get(name)
            .map(|&c| c as f64)
            .or_else(|| self.errors.get(name).copied())
    }
}

/// Checks a status field: a string naming a [`Status`].
fn typed_status(v: Option<&Value>) -> std::result::Result<Status, String> {
    match v {
        None => Err("missing".into()),
        Some(Value::String(s)) => Status::parse(s).ok_or_else(|| format!("unknown status {s:?}")),
        Some(other) => Err(format!("{other} is not a status")),
    }
}

/// Checks a count field: None when not recorded (absent or null).
fn typed_count(v: Option<&Value>) -> std::result::Result<Option<u64>, String> {
    match v {
        None | Some(Value::Null) => Ok(None),
        Some(x) => x
            .as_u64()
            .map(Some)
            .ok_or_else(|| format!("{x} is not a count")),
    }
}

/// Checks an error field: a non-negative number, None when not recorded.
fn typed_error(v: Option<&Value>) -> std::result::Result<Option<f64>, String> {
    match v {
        None | Some(Value::Null) => Ok(None),
        Some(x) => match x.as_f64() {
            Some(f) if f >= 0.0 => Ok(Some(f)),
            _ => Err(format!("{x} is not an error (a non-negative number)")),
        },
    }
}

/// Types one verdict; an error names the field (`status`, `edge_mismatches`, ...).
fn verdict(e: &ResultEntry) -> std::result::Result<Verdict, String> {
    let status =
        Status::parse(&e.status).ok_or_else(|| format!("status: unknown status {:?}", e.status))?;
    let mut counts = BTreeMap::new();
    for m in COUNT_METRICS {
        if let Some(c) = typed_count(e.details.get(*m)).map_err(|why| format!("{m}: {why}"))? {
            counts.insert(m.to_string(), c);
        }
    }
    let mut errors = BTreeMap::new();
    for m in ERROR_METRICS {
        if let Some(x) = typed_error(e.details.get(*m)).map_err(|why| format!("{m}: {why}"))? {
            errors.insert(m.to_string(), x);
        }
    }
    Ok(Verdict {
        scene: e.scene.clone(),
        backend: e.backend.clone(),
        buffer: e.buffer.clone(),
        status,
        reason: e.reason.clone(),
        counts,
        errors,
    })
}

/// Types every verdict of a results.json; the error is one line naming the
/// first bad field, e.g. `results[12].status: unknown status "passs"`.
pub fn verdicts(results: &Results) -> Result<Vec<Verdict>> {
    results
        .results
        .iter()
        .enumerate()
        .map(|(i, e)| verdict(e).map_err(|why| anyhow::anyhow!("results[{i}].{why}")))
        .collect()
}

/// Reads RUN/results.json into typed verdicts; an error names the file and the field.
pub fn load_verdicts(path: &Path) -> Result<Vec<Verdict>> {
    let what = "results.json (run `rendiff check` first)";
    let v: Value = read_json(path, what)?;
    // Statuses first, so that one of the wrong type is named like an unknown one.
    if let Some(list) = v.get("results").and_then(Value::as_array) {
        for (i, e) in list.iter().enumerate() {
            typed_status(e.get("status"))
                .map_err(|why| anyhow::anyhow!("{}: results[{i}].status: {why}", path.display()))?;
        }
    }
    let results: Results = serde_json::from_value(v)
        .with_context(|| format!("{}: not a valid {what}", path.display()))?;
    verdicts(&results).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

/// Checks a baseline's statuses and numbers before it is typed, naming the
/// first bad field (`entries[3].metrics.edge_mismatches: -1 is not a count`).
fn check_baseline_fields(v: &Value) -> std::result::Result<(), String> {
    let Some(entries) = v.get("entries").and_then(Value::as_array) else {
        return Ok(()); // the typed read names a missing or malformed list
    };
    for (i, e) in entries.iter().enumerate() {
        typed_status(e.get("status")).map_err(|why| format!("entries[{i}].status: {why}"))?;
        let metrics = e.get("metrics");
        for m in COUNT_METRICS {
            typed_count(metrics.and_then(|x| x.get(*m)))
                .map_err(|why| format!("entries[{i}].metrics.{m}: {why}"))?;
        }
        for m in ERROR_METRICS {
            typed_error(metrics.and_then(|x| x.get(*m)))
                .map_err(|why| format!("entries[{i}].metrics.{m}: {why}"))?;
        }
    }
    Ok(())
}

/// reports/baseline.json.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Baseline {
    /// Format tag.
    pub format: String,
    /// Where the numbers came from.
    pub provenance: Provenance,
    /// The noise policy in words (the numbers are per entry).
    pub policy: String,
    /// One entry per (scene, backend, buffer).
    pub entries: Vec<BaselineEntry>,
}

/// Where a baseline came from: enough to tell why numbers moved.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Provenance {
    /// When it was blessed (UTC).
    pub blessed: String,
    /// The bless command line.
    pub command: String,
    /// The run folder it was blessed from.
    pub run: String,
    /// When that run was made (UTC).
    pub run_created: String,
    /// rendiff's version.
    pub rendiff_version: String,
    /// CPU model (/proc/cpuinfo), since SIMD paths can change last bits.
    pub cpu: String,
    /// Version of each renderer, from the run's manifest.
    pub renderers: BTreeMap<String, String>,
    /// Random seeds any backend reported (none for the deterministic ones).
    pub seeds: BTreeMap<String, Value>,
    /// Expectations file the run was judged with.
    pub expectations: Option<String>,
}

/// One blessed verdict.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct BaselineEntry {
    /// Scene stem.
    pub scene: String,
    /// Backend.
    pub backend: String,
    /// Buffer (`id`, `Z`, ...).
    pub buffer: String,
    /// Blessed status.
    pub status: Status,
    /// Blessed reason (for the summary).
    #[serde(default)]
    pub reason: String,
    /// Blessed numbers as results.json has them (null: not compared).
    pub metrics: BTreeMap<String, Value>,
    /// How much each may move.
    pub noise: Noise,
}

/// Allowed movement of an entry's numbers.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Noise {
    /// How much a mismatch count may grow (0: not at all).
    pub counts: u64,
    /// Errors may grow to `baseline × error_factor + slack`.
    pub error_factor: f64,
    /// Absolute slack of `max_abs_error`.
    pub max_abs_error_slack: f64,
    /// Slack of `max_rel_error`.
    pub max_rel_error_slack: f64,
}

impl Noise {
    /// The policy's noise for a backend; `z_far` is the scene's farthest reference depth.
    pub fn for_backend(backend: &str, z_far: f64) -> Noise {
        if EXACT_BACKENDS.contains(&backend) {
            Noise {
                counts: 0,
                error_factor: 1.0,
                max_abs_error_slack: 0.0,
                max_rel_error_slack: 0.0,
            }
        } else {
            Noise {
                counts: 0,
                error_factor: 1.5,
                max_abs_error_slack: F32_SLACK * z_far,
                max_rel_error_slack: F32_SLACK,
            }
        }
    }

    fn slack(&self, metric: &str) -> f64 {
        match metric {
            "max_abs_error" => self.max_abs_error_slack,
            "max_rel_error" => self.max_rel_error_slack,
            _ => self.counts as f64,
        }
    }

    /// Largest value of `metric` that is not a regression from `base`.
    pub fn limit(&self, metric: &str, base: f64) -> f64 {
        if COUNT_METRICS.contains(&metric) {
            base + self.counts as f64
        } else {
            base * self.error_factor + self.slack(metric)
        }
    }

    /// Values below this are an improvement beyond the noise.
    pub fn improved_below(&self, metric: &str, base: f64) -> f64 {
        if COUNT_METRICS.contains(&metric) {
            base - self.counts as f64
        } else {
            (base - self.slack(metric)) / self.error_factor.max(1.0)
        }
    }
}

/// What happened to one entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum ChangeKind {
    /// Fails the gate.
    Regression,
    /// Better than the baseline: bless to lock it in.
    Improvement,
    /// Worth knowing, not failing (a known failure still failing, a version change).
    Note,
}

/// One line of the gate's summary.
#[derive(Debug, Clone)]
pub struct Change {
    /// Regression, improvement or note.
    pub kind: ChangeKind,
    /// Scene stem ("" for run-wide notes).
    pub scene: String,
    /// Backend.
    pub backend: String,
    /// Buffer.
    pub buffer: String,
    /// What changed.
    pub what: String,
    /// Baseline value.
    pub before: String,
    /// Value now, with the difference.
    pub now: String,
    /// Why, or the limit that was crossed ("" when nothing to add).
    pub detail: String,
}

impl Change {
    /// One readable phrase: `what: before → now — detail`.
    pub fn phrase(&self) -> String {
        let mut p = format!("{}: {} → {}", self.what, self.before, self.now);
        if !self.detail.is_empty() {
            p.push_str(" — ");
            p.push_str(&self.detail);
        }
        p
    }
}

/// The gate's verdict.
#[derive(Debug, Clone, Default)]
pub struct Outcome {
    /// Every change, regressions first.
    pub changes: Vec<Change>,
    /// Entries present on both sides.
    pub compared: usize,
}

impl Outcome {
    /// Number of regressions.
    pub fn regressions(&self) -> usize {
        self.changes
            .iter()
            .filter(|c| c.kind == ChangeKind::Regression)
            .count()
    }
}

fn key(scene: &str, backend: &str, buffer: &str) -> (String, String, String) {
    (scene.to_string(), backend.to_string(), buffer.to_string())
}

fn metric(e: &Verdict, k: &str) -> Option<f64> {
    e.metric(k)
}

fn fmt_num(metric: &str, v: f64) -> String {
    if COUNT_METRICS.contains(&metric) {
        format!("{v}")
    } else if v == 0.0 {
        "0".into()
    } else {
        format!("{v:.3e}")
    }
}

fn short(s: &str, n: usize) -> String {
    let s = s.replace('\n', " ");
    if s.chars().count() <= n {
        s
    } else {
        format!("{}…", s.chars().take(n).collect::<String>())
    }
}

/// Compares a run's verdicts ([`verdicts`] of its results.json) with the
/// baseline (see the module docs for the rules).
pub fn compare(baseline: &Baseline, results: &[Verdict]) -> Outcome {
    let mut out = Outcome::default();
    let mut now: BTreeMap<(String, String, String), &Verdict> = BTreeMap::new();
    for e in results {
        now.insert(key(&e.scene, &e.backend, &e.buffer), e);
    }
    let mut seen = std::collections::BTreeSet::new();
    for b in &baseline.entries {
        let k = key(&b.scene, &b.backend, &b.buffer);
        seen.insert(k.clone());
        let change = |kind, what: &str, before: String, now: String, detail: String| Change {
            kind,
            scene: b.scene.clone(),
            backend: b.backend.clone(),
            buffer: b.buffer.clone(),
            what: what.to_string(),
            before,
            now,
            detail,
        };
        let Some(e) = now.get(&k) else {
            out.changes.push(change(
                ChangeKind::Regression,
                "missing result",
                b.status.to_string(),
                "—".into(),
                "in the baseline, not in this run".into(),
            ));
            continue;
        };
        out.compared += 1;
        let (was, is) = (b.status, e.status);
        let why = short(&e.reason, 160);
        if is.is_bad() && !was.is_bad() {
            out.changes.push(change(
                ChangeKind::Regression,
                "new failure",
                was.to_string(),
                is.to_string(),
                why,
            ));
        } else if is == Status::Skipped && matches!(was, Status::Pass | Status::ExpectedFail) {
            out.changes.push(change(
                ChangeKind::Regression,
                "no longer compared",
                was.to_string(),
                is.to_string(),
                why,
            ));
        } else if was.is_bad() && !is.is_bad() {
            out.changes.push(change(
                ChangeKind::Improvement,
                "fixed",
                was.to_string(),
                is.to_string(),
                String::new(),
            ));
        } else if was == Status::Skipped && is != Status::Skipped {
            out.changes.push(change(
                ChangeKind::Improvement,
                "now compared",
                was.to_string(),
                is.to_string(),
                String::new(),
            ));
        } else if was.is_bad() && is.is_bad() {
            out.changes.push(change(
                ChangeKind::Note,
                "still failing (accepted in the baseline)",
                was.to_string(),
                is.to_string(),
                why,
            ));
        } else if was != is {
            out.changes.push(change(
                ChangeKind::Note,
                "status changed",
                was.to_string(),
                is.to_string(),
                why,
            ));
        }
        let errors: &[&str] = if b.buffer == ERROR_BUFFER {
            ERROR_METRICS
        } else {
            &[]
        };
        for m in COUNT_METRICS.iter().chain(errors) {
            let (Some(base), Some(v)) = (b.metrics.get(*m).and_then(Value::as_f64), metric(e, m))
            else {
                continue;
            };
            let base = &base;
            let limit = b.noise.limit(m, *base);
            let diff = if COUNT_METRICS.contains(m) {
                format!("{:+}", v - base)
            } else if *base > 0.0 {
                format!("×{:.2}", v / base)
            } else {
                format!("+{}", fmt_num(m, v))
            };
            if v > limit {
                out.changes.push(change(
                    ChangeKind::Regression,
                    &format!("{m} worse"),
                    fmt_num(m, *base),
                    format!("{} ({diff})", fmt_num(m, v)),
                    format!("limit {}", fmt_num(m, limit)),
                ));
            } else if v < b.noise.improved_below(m, *base) {
                out.changes.push(change(
                    ChangeKind::Improvement,
                    &format!("{m} better"),
                    fmt_num(m, *base),
                    format!("{} ({diff})", fmt_num(m, v)),
                    String::new(),
                ));
            }
        }
    }
    for (k, e) in &now {
        if seen.contains(k) {
            continue;
        }
        out.changes.push(Change {
            kind: ChangeKind::Regression,
            scene: e.scene.clone(),
            backend: e.backend.clone(),
            buffer: e.buffer.clone(),
            what: "not in the baseline".into(),
            before: "—".into(),
            now: e.status.to_string(),
            detail: if e.status.is_bad() && !e.reason.is_empty() {
                short(&e.reason, 160)
            } else {
                "bless to accept it".into()
            },
        });
    }
    out.changes.sort_by_key(|c| c.kind);
    out
}

/// Escapes text for a markdown table cell in a PR comment (markdown renders
/// inline HTML, so names from scene files must not reach it raw).
pub fn md(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '|' => out.push_str("\\|"),
            '\n' | '\r' => out.push(' '),
            '\\' | '`' | '*' | '[' | ']' | '~' => {
                out.push('\\');
                out.push(c);
            }
            c => out.push(c),
        }
    }
    out
}

fn link_target(path: &str) -> String {
    let mut out = String::new();
    for b in path.bytes() {
        if b.is_ascii_alphanumeric() || b"-_./#".contains(&b) {
            out.push(char::from(b));
        } else {
            let _ = write!(out, "%{b:02X}");
        }
    }
    out
}

/// The renderer versions of a run, one string per backend.
pub fn renderer_versions(m: &Manifest) -> BTreeMap<String, String> {
    let mut v: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for s in &m.scenes {
        for r in &s.renders {
            let e = v.entry(r.backend.clone()).or_default();
            if !r.version.is_empty() && !e.contains(&r.version) {
                e.push(r.version.clone());
            }
        }
    }
    v.into_iter().map(|(k, e)| (k, e.join("; "))).collect()
}

/// Rows per section of the summary: a PR comment must stay short; the report has the rest.
pub const MAX_ROWS: usize = 40;

/// The PR-comment summary: verdict, regressions, improvements, notes (one row
/// per changed entry), each row linking to its scene's report page
/// (RUN/report/<scene>.html).
pub fn markdown(
    outcome: &Outcome,
    baseline: &Baseline,
    baseline_path: &str,
    run: &Path,
    manifest: Option<&Manifest>,
) -> String {
    let mut s = String::new();
    // One row per (scene, backend, buffer), in the section of its worst change.
    let mut rows: Vec<(ChangeKind, Vec<&Change>)> = Vec::new();
    for c in &outcome.changes {
        let same = |r: &&mut (ChangeKind, Vec<&Change>)| {
            let f = r.1[0];
            (&f.scene, &f.backend, &f.buffer) == (&c.scene, &c.backend, &c.buffer)
        };
        match rows.iter_mut().find(same) {
            Some(r) => {
                r.0 = r.0.min(c.kind);
                r.1.push(c);
            }
            None => rows.push((c.kind, vec![c])),
        }
    }
    let count = |k: ChangeKind| rows.iter().filter(|r| r.0 == k).count();
    let (n, improvements) = (
        count(ChangeKind::Regression),
        count(ChangeKind::Improvement),
    );
    let run_s = run.display().to_string();
    let _ = writeln!(
        s,
        "## rendiff gate: {} — {n} regressed entr{}, {improvements} improved\n",
        if outcome.regressions() == 0 {
            "PASS"
        } else {
            "FAIL"
        },
        if n == 1 { "y" } else { "ies" },
    );
    let p = &baseline.provenance;
    let _ = writeln!(
        s,
        "Run `{}` against baseline `{}` (blessed {} on {}, rendiff {}); {} entries compared. Report: [{}]({}).\n",
        run_s.replace('`', "'"),
        baseline_path.replace('`', "'"),
        md(&p.blessed),
        md(&p.cpu),
        md(&p.rendiff_version),
        outcome.compared,
        md(&format!("{run_s}/report/index.html")),
        link_target(&format!("{run_s}/report/index.html"))
    );
    let sections = [
        (ChangeKind::Regression, "Regressions (fail the gate)"),
        (
            ChangeKind::Improvement,
            "Improvements (run `rendiff bless` to lock them in)",
        ),
        (ChangeKind::Note, "Notes"),
    ];
    for (kind, title) in sections {
        let mine: Vec<&Vec<&Change>> = rows.iter().filter(|r| r.0 == kind).map(|r| &r.1).collect();
        if mine.is_empty() {
            continue;
        }
        let _ = writeln!(
            s,
            "### {title}: {}\n\n| scene | backend | buffer | what changed | page |\n|---|---|---|---|---|",
            mine.len()
        );
        for changes in mine.iter().take(MAX_ROWS) {
            let c = changes[0];
            let rel = format!(
                "{run_s}/{}#b-{}",
                crate::report::scene_page_path(&c.scene),
                crate::report::page_stem(&c.backend)
            );
            let page = format!(
                "[{}]({})",
                md(&crate::report::scene_page_path(&c.scene)),
                link_target(&rel)
            );
            let what: Vec<String> = changes.iter().map(|c| md(&c.phrase())).collect();
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {page} |",
                md(&c.scene),
                md(&c.backend),
                md(&c.buffer),
                what.join("; ")
            );
        }
        if mine.len() > MAX_ROWS {
            let _ = writeln!(
                s,
                "\n… and {} more; every verdict is in the report.",
                mine.len() - MAX_ROWS
            );
        }
        s.push('\n');
    }
    if let Some(m) = manifest {
        let now = renderer_versions(m);
        let mut lines = Vec::new();
        for (be, v) in &now {
            match p.renderers.get(be) {
                Some(old) if old != v => {
                    lines.push(format!("- {}: {} → {}", md(be), md(old), md(v)))
                }
                None => lines.push(format!("- {}: new backend ({})", md(be), md(v))),
                _ => {}
            }
        }
        if !lines.is_empty() {
            let _ = writeln!(
                s,
                "### Renderer versions changed since the baseline\n\n{}\n",
                lines.join("\n")
            );
        }
    }
    if !run.join("report/index.html").exists() {
        let _ = writeln!(
            s,
            "_No report in this run folder yet: `rendiff report {}` writes it._\n",
            run_s.replace('`', "'")
        );
    }
    if outcome.changes.is_empty() {
        s.push_str("Every verdict and number matches the baseline within its noise bounds.\n");
    }
    s
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path, what: &str) -> Result<T> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read {what}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{}: not a valid {what}", path.display()))
}

/// Reads a baseline file and checks its format tag, statuses and numbers
/// (an error names the file and the field).
pub fn load_baseline(path: &Path) -> Result<Baseline> {
    let v: Value = read_json(path, "rendiff baseline")?;
    check_baseline_fields(&v).map_err(|why| anyhow::anyhow!("{}: {why}", path.display()))?;
    let b: Baseline = serde_json::from_value(v)
        .with_context(|| format!("{}: not a valid rendiff baseline", path.display()))?;
    if b.format != BASELINE_FORMAT {
        bail!(
            "{}: format is {:?}, expected {BASELINE_FORMAT:?}",
            path.display(),
            b.format
        );
    }
    Ok(b)
}

/// `rendiff gate`: compares RUN with the baseline, writes RUN/gate.md and
/// returns the summary and whether the gate passed.
pub fn gate(baseline_path: &Path, run: &Path) -> Result<(String, bool)> {
    crate::check::run_folder::ensure_complete(run)?;
    let baseline = load_baseline(baseline_path)?;
    let results = load_verdicts(&run.join("results.json"))?;
    let manifest: Option<Manifest> = read_json(&run.join("manifest.json"), "manifest").ok();
    let outcome = compare(&baseline, &results);
    let text = markdown(
        &outcome,
        &baseline,
        &baseline_path.display().to_string(),
        run,
        manifest.as_ref(),
    );
    write_atomically(&run.join("gate.md"), |tmp| {
        std::fs::write(tmp, &text)?;
        Ok(())
    })?;
    Ok((text, outcome.regressions() == 0))
}

/// The CPU model from /proc/cpuinfo ("unknown" elsewhere).
pub fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.trim().to_string())
        })
        .unwrap_or_else(|| "unknown".into())
}

/// Every `*seed*` field in a backend's reported info, with its key.
fn find_seeds(v: &Value, out: &mut Vec<(String, Value)>) {
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                if k.to_ascii_lowercase().contains("seed") {
                    out.push((k.clone(), x.clone()));
                } else {
                    find_seeds(x, out);
                }
            }
        }
        Value::Array(a) => a.iter().for_each(|x| find_seeds(x, out)),
        _ => {}
    }
}

/// Options of `rendiff bless`.
#[derive(Debug, Clone, Default)]
pub struct BlessOptions {
    /// The command line, for provenance.
    pub command: String,
    /// Bless even if the run has failing or erroring verdicts, scene load
    /// errors included (they become accepted).
    pub allow_failures: bool,
    /// Bless even if the run's set of scenes differs from the current baseline's.
    pub allow_scene_changes: bool,
}

/// True for the entry of a scene that could not be loaded (buffer `scene`).
pub fn is_scene_error(e: &Verdict) -> bool {
    e.buffer == SCENE_BUFFER && e.status.is_bad()
}

/// Why bless refuses a run's verdicts: one line naming the scenes that could
/// not be loaded first, then the failing verdicts; None when nothing fails.
pub fn failure_summary(results: &[Verdict]) -> Option<String> {
    let (scenes, verdicts): (Vec<&Verdict>, Vec<&Verdict>) = results
        .iter()
        .filter(|e| e.status.is_bad())
        .partition(|e| is_scene_error(e));
    let mut parts = Vec::new();
    if !scenes.is_empty() {
        let names: Vec<String> = scenes
            .iter()
            .map(|e| format!("{} ({})", e.scene, short(&e.reason, 120)))
            .collect();
        parts.push(format!(
            "{} scene{} could not be loaded: {}",
            scenes.len(),
            if scenes.len() == 1 { "" } else { "s" },
            names.join(", ")
        ));
    }
    if !verdicts.is_empty() {
        let errors = verdicts
            .iter()
            .filter(|e| e.status == Status::Error)
            .count();
        let names: Vec<String> = verdicts
            .iter()
            .take(3)
            .map(|e| format!("{} ({})", e.key(), e.status))
            .collect();
        parts.push(format!(
            "{} failing verdict{}{}, e.g. {}",
            verdicts.len(),
            if verdicts.len() == 1 { "" } else { "s" },
            if errors > 0 {
                format!(" ({errors} of them errors)")
            } else {
                String::new()
            },
            names.join(", ")
        ));
    }
    (!parts.is_empty()).then(|| parts.join("; "))
}

/// The scenes of a set of verdicts.
fn scene_set<'a>(names: impl Iterator<Item = &'a str>) -> std::collections::BTreeSet<String> {
    names.map(String::from).collect()
}

/// Scenes added in `now` and removed from `before` (each sorted).
pub fn scene_changes(before: &Baseline, now: &Baseline) -> (Vec<String>, Vec<String>) {
    let a = scene_set(before.entries.iter().map(|e| e.scene.as_str()));
    let b = scene_set(now.entries.iter().map(|e| e.scene.as_str()));
    (
        b.difference(&a).cloned().collect(),
        a.difference(&b).cloned().collect(),
    )
}

/// One line saying how the scene sets differ, None when they are the same.
pub fn scene_change_summary(before: &Baseline, now: &Baseline) -> Option<String> {
    let (added, removed) = scene_changes(before, now);
    if added.is_empty() && removed.is_empty() {
        return None;
    }
    let list = |v: &[String]| {
        if v.is_empty() {
            "none".to_string()
        } else {
            v.iter()
                .map(|s| format!("{s:?}"))
                .collect::<Vec<_>>()
                .join(", ")
        }
    };
    Some(format!(
        "the run's scenes differ from the baseline's: added {}: {}; removed {}: {}",
        added.len(),
        list(&added),
        removed.len(),
        list(&removed)
    ))
}

/// Builds a baseline from a run (numbers, noise bounds, provenance).
pub fn baseline_from_run(run: &Path, opts: &BlessOptions) -> Result<Baseline> {
    crate::check::run_folder::ensure_complete(run)?;
    let results = load_verdicts(&run.join("results.json"))?;
    let manifest: Manifest = read_json(&run.join("manifest.json"), "manifest")?;
    if let Some(bad) = failure_summary(&results).filter(|_| !opts.allow_failures) {
        bail!(
            "{}: {bad}; fix them, or pass --allow-failures to accept them into the baseline",
            run.display(),
        );
    }
    // The scale of each scene's depth, for the absolute error slack.
    let mut z_far: BTreeMap<String, f64> = BTreeMap::new();
    for s in &manifest.scenes {
        let far = s
            .renders
            .iter()
            .find(|r| r.backend == manifest.reference && r.status == "ok")
            .and_then(|r| run_relative(run, &r.exr))
            .and_then(|p| read_buffers(&p).ok())
            .and_then(|b| b.z)
            .map(|z| {
                z.iter()
                    .filter(|v| v.is_finite())
                    .fold(0.0f64, |a, &v| a.max(f64::from(v.abs())))
            })
            .unwrap_or(0.0);
        z_far.insert(s.scene.clone(), far);
    }
    // Seeds: from what a backend reported, else from its EXR's rendiff:seed.
    let mut seeds = BTreeMap::new();
    for s in &manifest.scenes {
        for r in &s.renders {
            let mut found = Vec::new();
            find_seeds(&r.info, &mut found);
            if found.is_empty() && r.status == "ok" {
                let attrs = run_relative(run, &r.exr).and_then(|p| read_buffers(&p).ok());
                if let Some(v) = attrs.and_then(|b| b.attrs.get("seed").cloned()) {
                    found.push(("seed".into(), Value::String(v)));
                }
            }
            // A plain `seed` says it best; derived ones (per-pass seeds) only without it.
            let best = found
                .iter()
                .position(|(k, _)| k == "seed")
                .or((!found.is_empty()).then_some(0));
            if let Some(i) = best {
                seeds
                    .entry(r.backend.clone())
                    .or_insert_with(|| found.swap_remove(i).1);
            }
        }
    }
    let expectations = std::fs::read_to_string(run.join("results.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<Value>(&t).ok())
        .and_then(|v| v.get("expectations")?.as_str().map(String::from));
    let mut entries: Vec<BaselineEntry> = results
        .iter()
        .map(|e| BaselineEntry {
            scene: e.scene.clone(),
            backend: e.backend.clone(),
            buffer: e.buffer.clone(),
            status: e.status,
            reason: short(&e.reason, 200),
            metrics: COUNT_METRICS
                .iter()
                .chain(ERROR_METRICS)
                .map(|m| {
                    let v = match (e.counts.get(*m), e.errors.get(*m)) {
                        (Some(&c), _) => Value::from(c),
                        (_, Some(&x)) => Value::from(x),
                        _ => Value::Null,
                    };
                    (m.to_string(), v)
                })
                .collect(),
            noise: Noise::for_backend(&e.backend, z_far.get(&e.scene).copied().unwrap_or(0.0)),
        })
        .collect();
    entries
        .sort_by(|a, b| (&a.scene, &a.backend, &a.buffer).cmp(&(&b.scene, &b.backend, &b.buffer)));
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    Ok(Baseline {
        format: BASELINE_FORMAT.into(),
        provenance: Provenance {
            blessed: utc(now),
            command: opts.command.clone(),
            run: run.display().to_string(),
            run_created: utc(manifest.created_unix),
            rendiff_version: env!("CARGO_PKG_VERSION").into(),
            cpu: cpu_model(),
            renderers: renderer_versions(&manifest),
            seeds,
            expectations,
        },
        policy: "Mismatch counts (edge, tie, crack, interior, mask; any buffer) may not grow. Depth errors (max_abs_error, max_rel_error of Z entries) may grow to baseline x error_factor + slack: exact for raster/trace; x1.5 plus two f32 roundings (2^-22 relative, 2^-22 x the scene's farthest reference depth absolute) for external renderers. Statuses (any buffer: id, Z, N, camera, scene) may not turn fail/error/unexpected_pass, nor pass -> skipped. Entries must match one to one. Change thresholds only with `rendiff bless`.".into(),
        entries,
    })
}

/// `rendiff bless`: writes the baseline from a run, atomically. Refuses (see
/// [`BlessOptions`]) a run with failures, or one whose scenes differ from
/// those of the baseline it would replace.
pub fn bless(run: &Path, baseline_path: &Path, opts: &BlessOptions) -> Result<Baseline> {
    let b = baseline_from_run(run, opts)?;
    if !opts.allow_scene_changes && baseline_path.exists() {
        let old = load_baseline(baseline_path).context(
            "cannot compare the run's scenes with the current baseline; pass --allow-scene-changes to replace it",
        )?;
        if let Some(why) = scene_change_summary(&old, &b) {
            bail!(
                "{}: {why}; pass --allow-scene-changes to bless them into {}",
                run.display(),
                baseline_path.display()
            );
        }
    }
    let text = serde_json::to_string_pretty(&b)? + "\n";
    write_atomically(baseline_path, |tmp| {
        std::fs::write(tmp, &text).with_context(|| format!("{}: cannot write", tmp.display()))?;
        Ok(())
    })?;
    Ok(b)
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
