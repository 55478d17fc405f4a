//! Cross-renderer conformance: every scene in scenes/ (and scenes/corpus/),
//! after the camera calibration probes of scenes/calibration/, on every backend (core
//! trace, Embree default and robust, POV-Ray, pyrender, Mitsuba 3, and
//! rendiff-wgpu through renderers/wgpu.toml as in the main job), compared
//! with the core's raster output. One test per (scene, backend, buffer), so a
//! failure names exactly what broke; skipped combinations show as ignored with
//! their reason in the name, never as passes.
//!
//! Known divergences live in tests/expectations.toml with a reason and a
//! two-sided bound; doing better than a bound fails as an unexpected pass.

mod common;
use common::trials::verdict_trial;
use libtest_mimic::{Arguments, Failed, Trial};
use rendiff::check::{self, CheckOptions};
use std::path::PathBuf;

fn main() {
    let args = Arguments::from_args();
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let run_dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("conformance-run");
    let _ = std::fs::remove_dir_all(&run_dir);
    let trials = if args.list {
        // Listing must not render anything.
        vec![Trial::test("conformance::all", || Ok(()))]
    } else {
        // scenes/ and the real-asset corpus scenes/corpus/ when it is there (not
        // recursive: the probes in scenes/calibration/ are no ordinary scenes).
        let mut folders = vec![root.join("scenes")];
        if root.join("scenes/corpus").is_dir() {
            folders.push(root.join("scenes/corpus"));
        }
        // rendiff-wgpu joins as in the main job (scripts/check.sh): declared in
        // renderers/wgpu.toml and found on PATH in the build's release folder,
        // which scripts/test.sh builds first. Without it, its verdicts are
        // errors that say it is not on PATH.
        let release = PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
            .parent()
            .expect("the target folder holds tmp/")
            .join("release");
        let path = std::env::var_os("PATH").unwrap_or_default();
        let path =
            std::env::join_paths(std::iter::once(release).chain(std::env::split_paths(&path)))
                .expect("PATH entries join");
        // Before any thread starts: nothing reads the environment concurrently.
        std::env::set_var("PATH", path);
        let opts = CheckOptions {
            quiet: false,
            references: Some(root.join("tests/references")),
            // The probes, as in every `rendiff check`: conformance is where each
            // backend's camera is measured against docs/DESIGN.md, and the run it
            // leaves is what `rendiff gate` holds against the baseline.
            calibration: Some(root.join("scenes/calibration")),
            renderers: Some(root.join("renderers/wgpu.toml")),
            ..CheckOptions::new(
                check::collect_scenes(&folders).expect("scene folders are readable"),
                run_dir.clone(),
                root.clone(),
            )
        };
        match check::run(&opts) {
            Err(e) => {
                let msg = format!("{e:#}");
                vec![Trial::test("conformance::harness", move || {
                    Err(Failed::from(msg))
                })]
            }
            Ok(outcome) => {
                eprintln!("{}", outcome.table);
                eprintln!("run folder: {}", run_dir.display());
                outcome
                    .results
                    .results
                    .into_iter()
                    .map(verdict_trial)
                    .collect()
            }
        }
    };
    libtest_mimic::run(&args, trials).exit();
}
