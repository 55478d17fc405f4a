//! `rendiff bless`: the only way thresholds change. Writes a baseline from a
//! finished run with its provenance (renderer versions, CPU, command, seeds),
//! refusing failing runs and changed scene sets unless told otherwise.

use super::*;
use crate::exr_io::read_buffers;
use crate::report::data::run_relative;
use crate::report::overview::utc;
use crate::vocab::RenderStatus;

impl BaselineEntry {
    /// The entry `bless` writes for verdict `e` of a scene whose farthest
    /// reference depth is `z_far`: every count and error metric (null where
    /// the verdict recorded none), the reason shortened, the backend's noise.
    pub fn blessed(e: &Verdict, z_far: f64) -> Self {
        BaselineEntry {
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
            noise: Noise::for_backend(&e.backend, z_far),
        }
    }
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
pub(super) fn find_seeds(v: &Value, out: &mut Vec<(String, Value)>) {
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
    /// Why entries of the baseline's scenes that the run lacks may be dropped
    /// (`--drop-reason`); recorded in the provenance. Without it such a run
    /// is refused: `gate` fails on exactly those entries ("missing result"),
    /// and a bless used to drop them silently.
    pub drop_reason: Option<String>,
}

/// Most dropped entries a refusal names one by one (the rest are counted).
const DROPPED_NAMED: usize = 10;

/// The baseline's entries (`scene::backend::buffer`) of scenes the run still
/// has but that the run does not: what blessing it would drop. Entries of
/// scenes the run no longer has are [`scene_changes`]' business.
pub fn dropped_entries(before: &Baseline, now: &Baseline) -> Vec<String> {
    let scenes = scene_set(now.entries.iter().map(|e| e.scene.as_str()));
    let keys: std::collections::BTreeSet<(&str, &str, &str)> = now
        .entries
        .iter()
        .map(|e| (e.scene.as_str(), e.backend.as_str(), e.buffer.as_str()))
        .collect();
    before
        .entries
        .iter()
        .filter(|e| scenes.contains(&e.scene))
        .filter(|e| !keys.contains(&(e.scene.as_str(), e.backend.as_str(), e.buffer.as_str())))
        .map(|e| {
            format!(
                "{}::{}::{}",
                crate::scene::printable(&e.scene, 100),
                crate::scene::printable(&e.backend, 100),
                crate::scene::printable(&e.buffer, 100)
            )
        })
        .collect()
}

/// One line naming what would be dropped (the first [`DROPPED_NAMED`], then a count).
pub(super) fn dropped_summary(dropped: &[String]) -> String {
    let shown = dropped[..dropped.len().min(DROPPED_NAMED)].join(", ");
    let more = dropped.len().saturating_sub(DROPPED_NAMED);
    let more = if more > 0 {
        format!(" and {more} more")
    } else {
        String::new()
    };
    format!(
        "{} entr{} of the baseline's scenes {} not in the run and would be dropped: {shown}{more}",
        dropped.len(),
        if dropped.len() == 1 { "y" } else { "ies" },
        if dropped.len() == 1 { "is" } else { "are" },
    )
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
            .find(|r| r.backend == manifest.reference && r.status == RenderStatus::Ok)
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
            if found.is_empty() && r.status == RenderStatus::Ok {
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
    let expectations = crate::check::manifest::read_record(&run.join("results.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<Value>(&t).ok())
        .and_then(|v| v.get("expectations")?.as_str().map(String::from));
    let mut entries: Vec<BaselineEntry> = results
        .iter()
        .map(|e| BaselineEntry::blessed(e, z_far.get(&e.scene).copied().unwrap_or(0.0)))
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
            dropped: None,
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
/// [`BlessOptions`]) a run with failures, one whose scenes differ from those
/// of the baseline it would replace, and one that lacks entries of the
/// baseline's scenes (unless a reason for dropping them is given).
pub fn bless(run: &Path, baseline_path: &Path, opts: &BlessOptions) -> Result<Baseline> {
    let mut b = baseline_from_run(run, opts)?;
    if let Some(reason) = &opts.drop_reason {
        if reason.trim().is_empty() {
            bail!("--drop-reason is empty: say why the entries may be dropped");
        }
    }
    if std::fs::symlink_metadata(baseline_path).is_ok() {
        let old = match load_baseline(baseline_path) {
            Ok(old) => Some(old),
            // Replacing what cannot be read is what --allow-scene-changes says.
            Err(_) if opts.allow_scene_changes => None,
            Err(e) => {
                return Err(e.context(
                    "cannot compare the run with the current baseline; pass --allow-scene-changes to replace it",
                ))
            }
        };
        if let Some(old) = old {
            if !opts.allow_scene_changes {
                if let Some(why) = scene_change_summary(&old, &b) {
                    bail!(
                        "{}: {why}; pass --allow-scene-changes to bless them into {}",
                        run.display(),
                        baseline_path.display()
                    );
                }
            }
            let dropped = dropped_entries(&old, &b);
            match (&opts.drop_reason, dropped.is_empty()) {
                (_, true) => {}
                (None, false) => bail!(
                    "{}: {}; gate fails on each (missing result): fix the run, or pass --drop-reason \"WHY\" to bless without them into {}",
                    run.display(),
                    dropped_summary(&dropped),
                    baseline_path.display()
                ),
                (Some(reason), false) => {
                    b.provenance.dropped = Some(Dropped {
                        reason: reason.clone(),
                        entries: dropped,
                    });
                }
            }
        }
    }
    let text = serde_json::to_string_pretty(&b)? + "\n";
    write_atomically(baseline_path, |tmp| {
        std::fs::write(tmp, &text).with_context(|| format!("{}: cannot write", tmp.display()))?;
        Ok(())
    })?;
    Ok(b)
}
