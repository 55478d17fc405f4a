//! Verdicts as tests for the `harness = false` suites that run a whole
//! check (`tests/common/`).

#![allow(dead_code)]

use libtest_mimic::{Failed, Trial};
use rendiff::check::manifest::ResultEntry;

/// One verdict of results.json as a test named by its key: failing with
/// its status, reason and details when the verdict is a failure, ignored
/// (its name saying why) when it was skipped.
pub fn verdict_trial(r: ResultEntry) -> Trial {
    let skipped = r.status == "skipped";
    let name = if skipped {
        format!("{} (skipped: {})", r.key(), r.reason)
    } else {
        r.key()
    };
    Trial::test(name, move || {
        if r.is_failure() {
            Err(Failed::from(format!(
                "{}: {}\n{}",
                r.status,
                r.reason,
                serde_json::to_string_pretty(&r.details).unwrap_or_default()
            )))
        } else {
            Ok(())
        }
    })
    .with_ignored_flag(skipped)
}
