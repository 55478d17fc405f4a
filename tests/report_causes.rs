//! A new user's path from "something failed" to "I know what is wrong", on a
//! run of two renderers of one's own with planted camera-convention faults
//! (tests/fuzz_renderers/cameras.toml: one samples pixel corners, one writes
//! radial distance in Z), declared by command and run from a folder outside
//! the checkout:
//!
//! - the report's "Needs attention" shows one row per root cause, the failed
//!   calibrations first, with the verdicts they leave unjudged under them and
//!   without their stale counts;
//! - `check` prints the failing verdicts and its summary, not every verdict;
//! - the calibration names the radial depth on its message's first line;
//! - the report's reproduction command runs as printed, to the same verdicts,
//!   into a new folder.

mod common;

use common::cli::{need_venv, output_within, root};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// The scenes of the run, copied into the user's folder.
const SCENES: &[&str] = &["three_triangles", "pixel_grid", "icosphere"];

struct Run {
    _dir: tempfile::TempDir,
    /// The user's folder (check's working folder).
    cwd: PathBuf,
    /// The run folder.
    run: PathBuf,
    stdout: String,
    code: Option<i32>,
}

/// PATH with the venv's python3 (numpy, for planted.py) and the rendiff under test first.
fn path_env() -> String {
    let bin = Path::new(env!("CARGO_BIN_EXE_rendiff")).parent().unwrap();
    format!(
        "{}:{}:{}",
        bin.display(),
        root().join(".venv/bin").display(),
        std::env::var("PATH").unwrap_or_default()
    )
}

fn the_run() -> &'static Run {
    static RUN: OnceLock<Run> = OnceLock::new();
    RUN.get_or_init(|| {
        need_venv();
        let dir = tempfile::tempdir().unwrap();
        let cwd = dir.path().join("user");
        std::fs::create_dir(&cwd).unwrap();
        for s in SCENES {
            std::fs::copy(
                root().join(format!("scenes/{s}.toml")),
                cwd.join(format!("{s}.toml")),
            )
            .unwrap();
        }
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_rendiff"));
        cmd.current_dir(&cwd)
            .env("PATH", path_env())
            .env("RENDIFF_HOME", root())
            .arg("check")
            .args(SCENES.iter().map(|s| format!("{s}.toml")))
            .arg("--renderers")
            .arg(root().join("tests/fuzz_renderers/cameras.toml"))
            .args(["--only", "corner_sample,radial_depth"])
            .args(["--jobs", "2", "--quiet", "-o", "run"]);
        let out = output_within(&mut cmd, 600);
        let run = Run {
            cwd: cwd.clone(),
            run: cwd.join("run"),
            stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
            code: out.status.code(),
            _dir: dir,
        };
        assert_eq!(
            run.code,
            Some(1),
            "the planted faults must fail the run: {}\n{}",
            run.stdout,
            String::from_utf8_lossy(&out.stderr)
        );
        run
    })
}

fn results(run: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(run.join("results.json")).unwrap()).unwrap()
}

fn failing(results: &Value) -> Vec<&Value> {
    results["results"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| ["fail", "error", "unexpected_pass"].contains(&e["status"].as_str().unwrap()))
        .collect()
}

/// The text from `start` to the next `end` after it (`start` included).
fn between<'a>(text: &'a str, start: &str, end: &str) -> &'a str {
    let i = text
        .find(start)
        .unwrap_or_else(|| panic!("no {start:?} in the page"));
    let rest = &text[i..];
    let stop = rest[start.len()..]
        .find(end)
        .map_or(rest.len(), |j| j + start.len());
    &rest[..stop]
}

fn unescape(s: &str) -> String {
    s.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&#39;", "'")
        .replace("&amp;", "&")
}

/// The rows of a table section that carry `class="NAME"`.
fn rows<'a>(html: &'a str, class: &str) -> Vec<&'a str> {
    let tag = format!("<tr class=\"{class}\"");
    html.match_indices(&tag)
        .map(|(i, _)| {
            let r = &html[i..];
            &r[..r.find("</tr>").unwrap()]
        })
        .collect()
}

#[test]
fn needs_attention_shows_one_row_per_cause_calibration_first() {
    let r = the_run();
    let res = results(&r.run);
    let bad = failing(&res);
    let index = std::fs::read_to_string(r.run.join("report/index.html")).unwrap();
    let attention = between(&index, "<h2 id=\"attention\">", "<h2 ");
    let causes = rows(attention, "cause");
    // Two renderers, each with a camera fault: two causes, for many verdicts.
    assert_eq!(causes.len(), 2, "{attention}");
    assert!(
        bad.len() >= 3 * causes.len(),
        "the run should spoil many verdicts: {}",
        bad.len()
    );
    for c in &causes {
        assert!(c.contains("data-kind=\"calibration\""), "{c}");
        assert!(c.contains("failed calibration"), "{c}");
    }
    assert!(causes[0].contains("corner_sample") || causes[0].contains("radial_depth"));
    // Every failing verdict is under exactly one cause, and the counts say so.
    let count = |c: &str| -> usize {
        let cell = between(c, "<td class=\"num\">", "</td>");
        cell.trim_start_matches("<td class=\"num\">")
            .parse()
            .unwrap()
    };
    assert_eq!(
        causes.iter().map(|c| count(c)).sum::<usize>(),
        bad.len(),
        "{attention}"
    );
    let members = rows(attention, "member");
    assert_eq!(members.len(), bad.len(), "{attention}");
    // The unjudged verdicts hang under their calibration, without the counts
    // measured with the wrong camera.
    let unjudged: Vec<&&Value> = bad
        .iter()
        .filter(|e| e["not_judged"] == "calibration")
        .collect();
    assert!(!unjudged.is_empty(), "{res}");
    for m in &members {
        assert!(!m.contains("class=\"num\""), "stale counts shown: {m}");
    }
    // The evidence of a calibration cause is a probe's camera section.
    assert!(causes[0].contains("#camera\""), "{}", causes[0]);
    // Before the causes' table: nothing else lists verdicts.
    assert!(!attention.contains("<th>interior</th></tr><tr><td><span class=\"badge"));
}

#[test]
fn check_prints_the_failing_rows_and_its_summary_only() {
    let r = the_run();
    let res = results(&r.run);
    let all = res["results"].as_array().unwrap().len();
    let bad = failing(&res).len();
    let rows: Vec<&str> = r
        .stdout
        .lines()
        .filter(|l| {
            l.contains("corner_sample") || l.contains("radial_depth") || l.contains(" raster ")
        })
        .collect();
    assert_eq!(rows.len(), bad, "{}", r.stdout);
    for row in &rows {
        assert!(!row.contains(" pass "), "a passing row printed: {row}");
    }
    assert!(
        r.stdout.contains(&format!(
            "{} passing, skipped or known-failing verdicts not listed",
            all - bad
        )),
        "{}",
        r.stdout
    );
    assert!(r.stdout.contains("check: "), "{}", r.stdout);
}

#[test]
fn a_radial_depth_renderer_is_told_its_depth_is_radial_first() {
    let r = the_run();
    let res = results(&r.run);
    let reason = res["calibration"]["radial_depth"]["reason"]
        .as_str()
        .unwrap();
    // The renderer's own name says "radial" too: the words must be the diagnosis's.
    let first = reason.lines().next().unwrap().replace("radial_depth", "");
    assert!(first.contains("radial distance"), "{reason}");
    // The report's cause row leads with it too.
    let index = std::fs::read_to_string(r.run.join("report/index.html")).unwrap();
    let attention = between(&index, "<h2 id=\"attention\">", "<h2 ");
    let row = rows(attention, "cause")
        .into_iter()
        .find(|c| c.contains("radial_depth"))
        .unwrap();
    assert!(row.contains("radial distance"), "{row}");
    // The corner-sampling renderer is told about its pixel centers, first.
    let corner = res["calibration"]["corner_sample"]["reason"]
        .as_str()
        .unwrap();
    assert!(
        corner
            .lines()
            .next()
            .unwrap()
            .contains("pixel-center offset"),
        "{corner}"
    );
}

#[test]
fn the_printed_reproduction_reruns_to_the_same_verdicts_in_a_new_folder() {
    let r = the_run();
    let before = std::fs::read(r.run.join("results.json")).unwrap();
    let page = std::fs::read_to_string(r.run.join("report/three_triangles.html")).unwrap();
    let section = between(&page, "<h3 id=\"b-corner_sample\">", "<h3 ");
    let cmd = unescape(
        between(section, "verdict: <pre class=\"cmd\"><code>", "</code>")
            .trim_start_matches("verdict: <pre class=\"cmd\"><code>"),
    );
    for word in [
        "--renderers",
        "--only corner_sample",
        "three_triangles.toml",
    ] {
        assert!(cmd.contains(word), "{cmd}");
    }
    let out = output_within(
        Command::new("sh")
            .arg("-c")
            .arg(&cmd)
            .current_dir(std::env::temp_dir())
            .env("PATH", path_env())
            .env("RENDIFF_HOME", root()),
        600,
    );
    assert_eq!(
        out.status.code(),
        r.code,
        "{cmd}\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    // It wrote a new folder, and left the run being viewed as it was.
    assert_eq!(std::fs::read(r.run.join("results.json")).unwrap(), before);
    let repro = r.cwd.join("run.repro/three_triangles-corner_sample");
    let again = results(&repro);
    let verdicts = |res: &Value| -> Vec<(String, String)> {
        let mut v: Vec<(String, String)> = res["results"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|e| e["scene"] == "three_triangles" && e["backend"] == "corner_sample")
            .map(|e| {
                (
                    e["buffer"].as_str().unwrap().to_string(),
                    e["status"].as_str().unwrap().to_string(),
                )
            })
            .collect();
        v.sort();
        v
    };
    let original = verdicts(&results(&r.run));
    assert!(!original.is_empty());
    assert_eq!(verdicts(&again), original);

    // The render command reproduces the buffer beside the run, not over it.
    let render = unescape(
        between(section, "render: <pre class=\"cmd\"><code>", "</code>")
            .trim_start_matches("render: <pre class=\"cmd\"><code>"),
    );
    let exr = r.run.join("scenes/three_triangles/corner_sample.exr");
    let before = std::fs::read(&exr).unwrap();
    let out = output_within(
        Command::new("sh")
            .arg("-c")
            .arg(&render)
            .current_dir(std::env::temp_dir())
            .env("PATH", path_env()),
        300,
    );
    assert!(
        out.status.success(),
        "{render}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(std::fs::read(&exr).unwrap(), before, "{render}");
    let copy = r
        .cwd
        .join("run.repro/render/scenes/three_triangles/corner_sample.exr");
    assert!(copy.is_file(), "{render}");
}
