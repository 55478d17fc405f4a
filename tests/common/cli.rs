//! Helpers for the tests that drive the `rendiff` binary (`tests/common/`).

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

/// Runs `cmd` and fails with its stdout and stderr unless it exits 0.
pub fn succeeds(cmd: &mut Command) -> std::process::Output {
    let out = cmd.output().unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{cmd:?}\nstdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// `rendiff render SCENE --renderer RENDERER --quiet --no-preview EXTRA -o
/// OUT`, failing with its output unless it exits 0.
pub fn render_ok(scene: &str, renderer: &str, extra: &[&str], out: &Path) {
    succeeds(
        rendiff()
            .args([
                "render",
                scene,
                "--renderer",
                renderer,
                "--quiet",
                "--no-preview",
            ])
            .args(extra)
            .arg("-o")
            .arg(out),
    );
}

/// `rendiff bless RUN --baseline BASELINE`, to add flags to and run.
pub fn bless_command(run: &Path, baseline: &Path) -> Command {
    let mut c = rendiff();
    c.arg("bless").arg(run).arg("--baseline").arg(baseline);
    c
}

/// `rendiff export SCENE -o DIR/export` within `secs`: refused by the
/// failure contract ([`check_failure`], naming each of `must_mention`),
/// and nothing written. Returns its stderr.
pub fn export_refused(scene: &Path, dir: &Path, secs: u64, must_mention: &[&str]) -> String {
    let export_dir = dir.join("export");
    let res = output_within(
        rendiff()
            .arg("export")
            .arg(scene)
            .arg("-o")
            .arg(&export_dir),
        secs,
    );
    let stderr = check_failure(&res, must_mention);
    assert!(
        !export_dir.exists(),
        "export wrote {}",
        export_dir.display()
    );
    stderr
}

/// `rendiff render --renderer raster --quiet --no-preview SCENE -o OUT`
/// within `secs`.
pub fn raster_within(scene: &Path, out: &Path, secs: u64) -> std::process::Output {
    output_within(
        rendiff()
            .args(["render", "--renderer", "raster", "--quiet", "--no-preview"])
            .arg(scene)
            .arg("-o")
            .arg(out),
        secs,
    )
}

/// `rendiff gate --baseline BASELINE RUN`, to add flags to and run.
pub fn gate_command(run: &Path, baseline: &Path) -> Command {
    let mut c = rendiff();
    c.arg("gate").arg("--baseline").arg(baseline).arg(run);
    c
}

/// The binary run from `dir` with the venv's python3 first on PATH and
/// RENDIFF_HOME at the repository root: the planted renderers of
/// tests/fuzz_renderers/ run as `#!/usr/bin/env python3` and need numpy.
pub fn rendiff_with_venv(dir: &Path) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_rendiff"));
    let path = format!(
        "{}:{}",
        root().join(".venv/bin").display(),
        std::env::var("PATH").unwrap_or_default()
    );
    c.current_dir(dir)
        .env("PATH", path)
        .env("RENDIFF_HOME", root());
    c
}

/// A declaration file of the planted renderers, `tests/fuzz_renderers/FILE`,
/// as the argument of `--renderers`.
pub fn fuzz_renderers(file: &str) -> String {
    root()
        .join("tests/fuzz_renderers")
        .join(file)
        .display()
        .to_string()
}

/// What a finished command printed, stdout then stderr, for a failure message.
pub fn printed(o: &std::process::Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// `rendiff reduce RUN SCENE --backend BACKEND --buffer BUFFER -o OUT` from
/// `dir` with the planted renderers declared in `renderers`: it must succeed
/// within 600 s; what it printed.
pub fn reduce_planted(
    dir: &Path,
    renderers: &str,
    run: &str,
    scene: &str,
    backend: &str,
    buffer: &str,
    out: &str,
) -> String {
    let o = output_within(
        rendiff_with_venv(dir)
            .args([
                "reduce",
                run,
                scene,
                "--backend",
                backend,
                "--buffer",
                buffer,
            ])
            .args(["--renderers", renderers])
            .args(["--jobs", "2", "-o", out]),
        600,
    );
    assert_eq!(o.status.code(), Some(0), "{}", printed(&o));
    printed(&o)
}
