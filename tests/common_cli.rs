//! Helpers for the tests that drive the `rendiff` binary (included with `mod`).

#![allow(dead_code)]

use std::path::Path;
use std::process::Command;

/// The repository root: scenes/ and .venv are found from here.
pub fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The `rendiff` binary under test, run from the repository root.
pub fn rendiff() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_rendiff"));
    c.current_dir(root());
    c
}

/// Fails with the set-up command when the Python harness is missing
/// (`check` needs it to compare).
pub fn need_venv() {
    let py = root().join(".venv/bin/python");
    assert!(
        py.exists(),
        "{} is missing: run scripts/setup.sh (check's comparison needs the Python harness)",
        py.display()
    );
}

/// A quick real run into `run`: two scenes, the core tracer and Embree
/// against the raster. Fails with check's output unless it exits 0.
pub fn small_check(run: &Path) {
    need_venv();
    let out = rendiff()
        .args([
            "check",
            "scenes/three_triangles.toml",
            "scenes/pixel_grid.toml",
            "--only",
            "trace,embree",
            "--quiet",
            "-o",
        ])
        .arg(run)
        .output()
        .unwrap();
    assert!(
        out.status.code() == Some(0),
        "check failed: {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}
