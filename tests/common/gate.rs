//! The gate tests' synthetic baselines (`tests/common/`): verdicts
//! blessed the way `bless` blesses them, without a run folder.

#![allow(dead_code)]

use rendiff::check::manifest::{ResultEntry, Results};
use rendiff::gate::{self, Baseline, BaselineEntry, Provenance};

/// The farthest reference depth the synthetic baselines are blessed with
/// (it scales the depth noise bounds).
pub const Z_FAR: f64 = 4.0;

/// The gate's verdicts of a results.json list.
pub fn verdicts(entries: Vec<ResultEntry>) -> Vec<gate::Verdict> {
    gate::verdicts(&Results {
        format: "rendiff-results/1".into(),
        reference: "raster".into(),
        results: entries,
    })
    .unwrap()
}

/// The baseline `bless` writes for `entries` (every scene's farthest depth
/// [`Z_FAR`]), with empty provenance.
pub fn baseline_of(entries: &[ResultEntry]) -> Baseline {
    Baseline {
        format: gate::BASELINE_FORMAT.into(),
        provenance: Provenance::default(),
        policy: String::new(),
        entries: verdicts(entries.to_vec())
            .iter()
            .map(|v| BaselineEntry::blessed(v, Z_FAR))
            .collect(),
    }
}
