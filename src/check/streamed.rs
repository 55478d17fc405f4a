//! The comparison started before the renders end: `check` hands it each
//! scene's record the moment the scene's last external render is in, so the
//! scenes already rendered are judged while the others still render, instead
//! of every comparison waiting for the slowest render of the run.
//!
//! Verdicts cannot change with this: a scene is judged from its own files,
//! and the comparison uses a streamed record only when it is exactly the
//! record manifest.json holds for that scene (`compare.py`, `compare_scenes`),
//! judging the scene again otherwise.

use super::manifest::{RenderRecord, SceneRuns};
use super::process::Fed;
use super::{compare_command, compared, CheckOptions, Results, COMPARE_TIMEOUT, REFERENCE};
use anyhow::Result;
use std::path::Path;
use std::sync::Mutex;

/// The running comparison (`python -m rendiff_harness compare --stream`),
/// or why it could not start (then the run compares after its renders,
/// where the same failure is reported as a comparison's).
pub(super) fn start(opts: &CheckOptions, scratch: &Path) -> Option<Fed> {
    Fed::spawn(compare_command(opts, true), &scratch.join("compare")).ok()
}

/// results.json and the verdict table, once manifest.json is written.
pub(super) fn finish(opts: &CheckOptions, fed: Fed, shown: &Path) -> Result<(Results, String)> {
    compared(opts, fed.finish(COMPARE_TIMEOUT), shown)
}

/// Each scene's external renders as they come in (in any order); the
/// scene's finished record, as manifest.json will hold it, goes to the
/// comparison with its last one.
pub(super) struct Scenes<'a> {
    fed: &'a Fed,
    /// The records so far (the core's and Embree's), by scene.
    base: &'a [SceneRuns],
    /// Per scene, its [`Arrivals`].
    pending: Vec<Mutex<Arrivals>>,
}

/// A scene's external renders still out, and those in with their position
/// in the scene's record.
type Arrivals = (usize, Vec<(usize, RenderRecord)>);

impl<'a> Scenes<'a> {
    /// `counts[si]`: how many external renders scene `si` waits for (a scene
    /// with none is left to the comparison's own reading of manifest.json).
    pub(super) fn new(fed: &'a Fed, base: &'a [SceneRuns], counts: &[usize]) -> Self {
        let pending = counts
            .iter()
            .map(|&n| Mutex::new((n, Vec::new())))
            .collect();
        Scenes { fed, base, pending }
    }

    /// Render `rec` of scene `si` is in; it is the scene's `position`-th
    /// external render in the record.
    pub(super) fn arrived(&self, si: usize, position: usize, rec: &RenderRecord) {
        let mut p = self.pending[si].lock().unwrap_or_else(|e| e.into_inner());
        p.1.push((position, rec.clone()));
        p.0 = p.0.saturating_sub(1);
        if p.0 > 0 {
            return;
        }
        let mut runs = self.base[si].clone();
        let mut recs = std::mem::take(&mut p.1);
        recs.sort_by_key(|(k, _)| *k);
        runs.renders.extend(recs.into_iter().map(|(_, r)| r));
        let line = serde_json::json!({ "reference": REFERENCE, "scene": runs });
        self.fed.send(line.to_string());
    }
}
