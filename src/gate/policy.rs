//! The gate's policy: how much each recorded number may move (noise bounds
//! set per entry by bless) and the comparison of a run's verdicts with the
//! baseline, change by change.

use super::*;

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

pub(super) fn key(scene: &str, backend: &str, buffer: &str) -> (String, String, String) {
    (scene.to_string(), backend.to_string(), buffer.to_string())
}

pub(super) fn metric(e: &Verdict, k: &str) -> Option<f64> {
    e.metric(k)
}

pub(super) fn fmt_num(metric: &str, v: f64) -> String {
    if COUNT_METRICS.contains(&metric) {
        format!("{v}")
    } else if v == 0.0 {
        "0".into()
    } else {
        format!("{v:.3e}")
    }
}

pub(super) fn short(s: &str, n: usize) -> String {
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
        } else if is == Status::Skipped && was != Status::Skipped {
            // A failure that is now skipped is no more fixed than a pass that
            // is now skipped is still passing: nothing was compared.
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
        } else if was.is_bad() {
            // `is` is bad too: every change of badness took a branch above.
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
