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

/// Runs a command with a time limit; a command still running then is killed
/// and the test fails (a hang is a bug, never a slow success).
pub fn output_within(cmd: &mut Command, secs: u64) -> std::process::Output {
    use std::io::Read;
    let mut child = cmd
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Drain both pipes on threads so a chatty child cannot block on a full pipe.
    let mut so = child.stdout.take().unwrap();
    let mut se = child.stderr.take().unwrap();
    let t_out = std::thread::spawn(move || {
        let mut v = Vec::new();
        so.read_to_end(&mut v).ok();
        v
    });
    let t_err = std::thread::spawn(move || {
        let mut v = Vec::new();
        se.read_to_end(&mut v).ok();
        v
    });
    let start = std::time::Instant::now();
    let status = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break st;
        }
        if start.elapsed().as_secs() >= secs {
            child.kill().ok();
            child.wait().ok();
            panic!("{cmd:?} still running after {secs} s (hang)");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    std::process::Output {
        status,
        stdout: t_out.join().unwrap(),
        stderr: t_err.join().unwrap(),
    }
}

/// Checks the failure contract of one run: exit 2, no panic, one line on
/// stderr (so no raw control character either).
pub fn check_failure(res: &std::process::Output, must_mention: &[&str]) -> String {
    let stderr = String::from_utf8_lossy(&res.stderr).to_string();
    assert_eq!(res.status.code(), Some(2), "exit code; stderr: {stderr}");
    assert!(!stderr.contains("panicked"), "panic: {stderr}");
    assert_eq!(
        stderr.trim_end().lines().count(),
        1,
        "not one line: {stderr:?}"
    );
    assert!(
        !stderr.trim_end().chars().any(char::is_control),
        "raw control character: {stderr:?}"
    );
    assert!(stderr.len() < 1200, "{} characters: {stderr}", stderr.len());
    for m in must_mention {
        assert!(stderr.contains(m), "expected {m:?} in: {stderr}");
    }
    stderr
}

/// `rendiff render` of the lesson's scene (scenes/three_triangles.toml) with
/// `renderer` into `out`: the render most CLI tests start from.
pub fn render_lesson(renderer: &str, out: &Path) -> Command {
    let mut c = rendiff();
    c.args([
        "render",
        "scenes/three_triangles.toml",
        "--renderer",
        renderer,
        "-o",
    ])
    .arg(out);
    c
}
