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
//!
//! Split by job: [`policy`] (noise bounds and the comparison of a run with
//! the baseline), [`markdown`] (the summary a pull request shows), [`bless`]
//! (writing a baseline with provenance); this module holds the typed records
//! both sides read and the `gate` command itself.

pub mod bless;
pub mod markdown;
pub mod policy;
#[cfg(test)]
mod tests;

pub use bless::*;
pub use markdown::*;
pub use policy::*;

use crate::check::manifest::{Manifest, ResultEntry, Results, RESULTS_FORMAT};
use crate::exr_io::write_atomically;
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

/// Pixel counts results.json records beside [`COUNT_METRICS`] (the pixels
/// compared, the failing and clustered RGB pixels): not gated, but a verdict
/// whose count is negative or fractional is no verdict, so `gate` and
/// `bless` refuse it like a bad mismatch count (`bless` used to write such a
/// run into the baseline).
pub const PIXEL_COUNTS: &[&str] = &[
    "pixels",
    "compared_pixels",
    "failing_pixels",
    "cluster_failures",
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
    for m in PIXEL_COUNTS {
        typed_count(e.details.get(*m)).map_err(|why| format!("{m}: {why}"))?;
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
/// first bad field, e.g. `results[12].status: unknown status "passs"`. A
/// results.json of another format, or with two verdicts for one (scene,
/// backend, buffer), is refused: the gate kept the last of two, so a failing
/// verdict followed by a passing copy passed.
pub fn verdicts(results: &Results) -> Result<Vec<Verdict>> {
    if results.format != RESULTS_FORMAT {
        bail!(
            "format is {:?}, expected {RESULTS_FORMAT:?}",
            crate::scene::printable(&results.format, 100)
        );
    }
    let list = results
        .results
        .iter()
        .enumerate()
        .map(|(i, e)| verdict(e).map_err(|why| anyhow::anyhow!("results[{i}].{why}")))
        .collect::<Result<Vec<_>>>()?;
    once_each(
        list.iter().map(|v| (&v.scene, &v.backend, &v.buffer)),
        "results",
    )?;
    Ok(list)
}

/// Refuses a list (`what`: results or entries) naming one (scene, backend,
/// buffer) twice, naming both places.
fn once_each<'a>(
    keys: impl Iterator<Item = (&'a String, &'a String, &'a String)>,
    what: &str,
) -> Result<()> {
    let mut first = std::collections::HashMap::new();
    for (i, k) in keys.enumerate() {
        if let Some(j) = first.insert(k, i) {
            bail!(
                "{what}[{i}]: a second verdict for scene {}, backend {}, buffer {} (the first is {what}[{j}])",
                crate::scene::printable(k.0, 100),
                crate::scene::printable(k.1, 100),
                crate::scene::printable(k.2, 100)
            );
        }
    }
    Ok(())
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
    /// Entries of the previous baseline's scenes this bless dropped, and
    /// why (`bless --drop-reason`); absent when it dropped none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dropped: Option<Dropped>,
}

/// What a bless dropped from the baseline it replaced, and the reason given.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Dropped {
    /// The `--drop-reason` text.
    pub reason: String,
    /// `scene::backend::buffer` of each dropped entry.
    pub entries: Vec<String>,
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

fn read_json<T: serde::de::DeserializeOwned>(path: &Path, what: &str) -> Result<T> {
    let text = crate::check::manifest::read_record(path)
        .map_err(|e| anyhow::anyhow!("{}: cannot read {what}: {e}", path.display()))?;
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
    once_each(
        b.entries.iter().map(|e| (&e.scene, &e.backend, &e.buffer)),
        "entries",
    )
    .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    Ok(b)
}

/// `rendiff gate`: compares RUN with the baseline, writes RUN/gate.md and
/// returns the summary and whether the gate passed.
pub fn gate(baseline_path: &Path, run: &Path) -> Result<(String, bool)> {
    crate::check::run_folder::ensure_complete(run)?;
    let baseline = load_baseline(baseline_path)?;
    let results = load_verdicts(&run.join("results.json"))?;
    // A run without one (written by hand, or by an older rendiff) is gated
    // on its verdicts; one that is there must be a manifest: a garbled one
    // was ignored, and the gate passed a run whose records had been damaged.
    let mpath = run.join("manifest.json");
    let manifest: Option<Manifest> = match std::fs::symlink_metadata(&mpath) {
        Ok(_) => Some(read_json(&mpath, "rendiff manifest")?),
        Err(_) => None,
    };
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
