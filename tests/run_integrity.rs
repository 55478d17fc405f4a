//! What can change a finished run's verdicts besides the renderer under
//! test (issue 40): a renderer that rewrites its input scene, a bless that
//! drops entries, a merge of shards that are not one split run one way, a
//! second run into the same folder, records that are links out of the run,
//! and names that reach the terminal. Each case ends with a refusal or an
//! error entry naming the culprit; no other verdict changes.

use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

mod common;
use common::cli::{need_venv, root};

/// The rendiff binary, run from `dir`; the example renderer runs with
/// `python3` from PATH and needs numpy: the venv's comes first.
fn rendiff_in(dir: &Path) -> Command {
    let path = format!(
        "{}:{}",
        root().join(".venv/bin").display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let mut c = Command::new(env!("CARGO_BIN_EXE_rendiff"));
    c.current_dir(dir)
        .env("PATH", path)
        .env_remove("RENDIFF_HOME");
    c
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The statuses of `backend`'s verdicts in a run, by buffer.
fn statuses(run: &Path, backend: &str) -> Vec<(String, String, String)> {
    read_json(&run.join("results.json"))["results"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["backend"] == backend)
        .map(|e| {
            (
                e["buffer"].as_str().unwrap().to_string(),
                e["status"].as_str().unwrap().to_string(),
                e["reason"].as_str().unwrap_or("").to_string(),
            )
        })
        .collect()
}

fn executable(path: &Path, body: &str) {
    use std::os::unix::fs::PermissionsExt;
    std::fs::write(path, body).unwrap();
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o755)).unwrap();
}

/// A renderers file in `dir` declaring each `(name, script)` like the
/// example renderer (its precision, features and buffers); the example
/// renderer is copied beside it for the scripts to call.
fn declare(dir: &Path, renderers: &[(&str, &str)]) -> PathBuf {
    std::fs::copy(
        root().join("harness/examples/tiny_renderer.py"),
        dir.join("tiny_renderer.py"),
    )
    .unwrap();
    let example = std::fs::read_to_string(root().join("harness/examples/renderers.toml")).unwrap();
    let start = example.find("[[renderer]]").unwrap();
    let mut toml = String::new();
    for (name, script) in renderers {
        let file = format!("{name}.sh");
        executable(&dir.join(&file), script);
        toml.push_str(
            &example[start..]
                .replace("name = \"tiny\"", &format!("name = \"{name}\""))
                .replace("./tiny_renderer.py", &format!("./{file}")),
        );
        toml.push('\n');
    }
    let path = dir.join("renderers.toml");
    std::fs::write(&path, toml).unwrap();
    path
}

/// Renders as the example renderer does.
const HONEST: &str = "#!/bin/sh\nexec \"$(dirname \"$0\")/tiny_renderer.py\" \"$1\" \"$2\"\n";

/// Renders honestly, then halves the first triangle of `{scene}` (replacing
/// the file: it is read-only) as the tampering renderer did.
const TAMPERING: &str =
    "#!/bin/sh\n\"$(dirname \"$0\")/tiny_renderer.py\" \"$1\" \"$2\" || exit $?\n\
python3 - \"$1\" <<'PY'\n\
import os, sys, numpy as np\n\
p = os.path.join(sys.argv[1], 'triangles.f32')\n\
t = np.fromfile(p, dtype='<f4')\n\
t[:9] *= 0.5\n\
t.tofile(p + '.new')\n\
os.replace(p + '.new', p)\n\
PY\n";

fn check_in(dir: &Path, scenes: &[&Path], only: &str, run: &str) -> Output {
    need_venv();
    rendiff_in(dir)
        .arg("check")
        .args(scenes)
        .args(["--renderers", "renderers.toml", "--only", only])
        .args(["--no-calibration", "--jobs", "1", "--quiet", "-o", run])
        .output()
        .unwrap()
}

/// Item 1: the renderer that rewrote `{scene}` passed itself and failed the
/// correct renderer run after it. Now each render reads a copy of its own,
/// checked against the hash recorded in manifest.json: the tamperer gets
/// error entries that say what it did, the correct renderer still passes.
#[test]
fn a_renderer_that_rewrites_its_scene_is_caught_and_changes_no_other_verdict() {
    let dir = tempfile::tempdir().unwrap();
    declare(dir.path(), &[("tamper", TAMPERING), ("honest", HONEST)]);
    let scene = root().join("scenes/three_triangles.toml");
    let out = check_in(dir.path(), &[&scene], "tamper,honest", "run");
    let run = dir.path().join("run");
    assert_eq!(out.status.code(), Some(1), "{}", text(&out.stderr));
    let honest = statuses(&run, "honest");
    assert_eq!(honest.len(), 3, "{honest:?}");
    for (buffer, status, reason) in &honest {
        assert_eq!(status, "pass", "honest {buffer}: {reason}");
    }
    let tamper = statuses(&run, "tamper");
    assert!(!tamper.is_empty());
    for (buffer, status, reason) in &tamper {
        assert_eq!(status, "error", "tamper {buffer}: {reason}");
        assert!(
            reason.contains("tamper changed its input") && reason.contains("triangles.f32"),
            "{buffer}: {reason}"
        );
    }
    let manifest = read_json(&run.join("manifest.json"));
    let hash = manifest["scenes"][0]["resolved_sha256"].as_str().unwrap();
    assert!(hash.starts_with("sha256:") && hash.len() == 71, "{hash}");
}

fn json_run(run: &Path, scenes: &[&str], backends: &[&str]) {
    let pixels = json!({"pixels": 3072, "compared_pixels": 3072});
    common::runs::json_run(run, scenes, backends, &["id", "Z"], pixels);
}

fn bless(run: &Path, baseline: &Path, flags: &[&str]) -> Output {
    common::cli::bless_command(run, baseline)
        .args(flags)
        .output()
        .unwrap()
}

/// Item 2: a run with the baseline's scenes but fewer entries (a backend
/// gone) was blessed, dropping exactly the entries gate had failed on.
#[test]
fn bless_names_the_entries_it_would_drop_and_needs_a_reason() {
    let dir = tempfile::tempdir().unwrap();
    let baseline = dir.path().join("baseline.json");
    let full = dir.path().join("full");
    json_run(&full, &["alpha", "beta"], &["trace", "tiny"]);
    let o = bless(&full, &baseline, &[]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
    let before = std::fs::read(&baseline).unwrap();
    let fewer = dir.path().join("fewer");
    json_run(&fewer, &["alpha", "beta"], &["trace"]);
    let o = bless(&fewer, &baseline, &[]);
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    for key in [
        "alpha::tiny::id",
        "alpha::tiny::Z",
        "beta::tiny::id",
        "beta::tiny::Z",
    ] {
        assert!(err.contains(key), "{key} not named: {err}");
    }
    assert!(
        err.contains("4 entries") && err.contains("--drop-reason"),
        "{err}"
    );
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert_eq!(
        std::fs::read(&baseline).unwrap(),
        before,
        "baseline changed"
    );
    // --allow-scene-changes is no way around it: the scenes are the same.
    let o = bless(&fewer, &baseline, &["--allow-scene-changes"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    let o = bless(&fewer, &baseline, &["--drop-reason", "tiny retired"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
    let b = read_json(&baseline);
    assert_eq!(b["provenance"]["dropped"]["reason"], "tiny retired");
    assert_eq!(
        b["provenance"]["dropped"]["entries"]
            .as_array()
            .unwrap()
            .len(),
        4
    );
    assert_eq!(b["entries"].as_array().unwrap().len(), 4);
}

/// Item 6: a negative or fractional pixel count is no verdict; bless wrote
/// it into the baseline.
#[test]
fn bless_and_gate_refuse_negative_pixel_counts() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    for (field, bad) in [
        ("compared_pixels", json!(-5)),
        ("pixels", json!(-1)),
        ("failing_pixels", json!(-3)),
        ("compared_pixels", json!(2.5)),
    ] {
        json_run(&run, &["alpha"], &["trace"]);
        let path = run.join("results.json");
        let mut v = read_json(&path);
        v["results"][1][field] = bad.clone();
        std::fs::write(&path, v.to_string()).unwrap();
        let baseline = dir.path().join("baseline.json");
        let o = bless(&run, &baseline, &[]);
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{field} = {bad}: {err}");
        assert!(
            err.contains(&format!("results[1].{field}: {bad} is not a count")),
            "{err}"
        );
        assert!(!baseline.exists(), "{field} = {bad} blessed");
    }
}

/// Item 6: results.json or manifest.json linked to a file out of the run
/// was gated, blessed and reported as the run's own.
#[test]
fn records_linked_out_of_the_run_are_refused_by_gate_bless_and_report() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good");
    json_run(&good, &["alpha"], &["trace"]);
    let baseline = dir.path().join("baseline.json");
    let o = bless(&good, &baseline, &[]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
    for record in ["results.json", "manifest.json"] {
        let run = dir.path().join(format!("linked-{record}"));
        json_run(&run, &["alpha"], &["trace"]);
        std::fs::remove_file(run.join(record)).unwrap();
        std::os::unix::fs::symlink(good.join(record), run.join(record)).unwrap();
        for args in [
            vec![
                "gate".into(),
                run.display().to_string(),
                "--baseline".into(),
                baseline.display().to_string(),
            ],
            vec![
                "bless".into(),
                run.display().to_string(),
                "--baseline".into(),
                dir.path().join("b2.json").display().to_string(),
            ],
            vec!["report".into(), run.display().to_string()],
        ] {
            let o = common::cli::rendiff().args(&args).output().unwrap();
            let err = text(&o.stderr);
            assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
            assert!(
                err.contains(record) && err.contains("symbolic link"),
                "{args:?}: {err}"
            );
        }
    }
}

/// Item 4: two checks into one folder both printed success, the last
/// writer's run in place. The second is now refused while the first runs,
/// naming its process, and the first's run is published whole.
#[test]
fn a_second_check_into_a_running_folder_is_refused_naming_the_first() {
    need_venv();
    let dir = tempfile::tempdir().unwrap();
    let slow = "#!/bin/sh\nsleep 3\nexec \"$(dirname \"$0\")/tiny_renderer.py\" \"$1\" \"$2\"\n";
    declare(dir.path(), &[("slow", slow)]);
    let scene = root().join("scenes/three_triangles.toml");
    let mut first = rendiff_in(dir.path())
        .arg("check")
        .arg(&scene)
        .args(["--renderers", "renderers.toml", "--only", "slow"])
        .args(["--no-calibration", "--quiet", "-o", "run"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let marker = dir.path().join("run/INCOMPLETE");
    let start = std::time::Instant::now();
    while !marker.exists() {
        assert!(
            start.elapsed().as_secs() < 60,
            "the first check never started its run"
        );
        assert!(
            first.try_wait().unwrap().is_none(),
            "the first check ended early"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let pid = first.id();
    let second = check_in(dir.path(), &[&scene], "slow", "run");
    let err = text(&second.stderr);
    let first = first.wait_with_output().unwrap();
    assert_eq!(second.status.code(), Some(2), "second check: {err}");
    assert!(
        err.contains(&format!("another rendiff (process {pid})")),
        "{err}"
    );
    assert_eq!(first.status.code(), Some(0), "{}", text(&first.stderr));
    assert!(dir.path().join("run/results.json").is_file());
    assert!(!marker.exists());
}

/// A check of shard `k` of the given scenes (the core's tracer only) into
/// `dir/run`, with `extra` options; fails unless it exits 0.
fn shard_check(dir: &Path, scenes: &[PathBuf], k: &str, extra: &[&str], run: &str) -> PathBuf {
    need_venv();
    let o = rendiff_in(dir)
        .arg("check")
        .args(scenes)
        .args(["--shard", k, "--no-calibration", "--quiet", "-o", run])
        .args(extra)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
    dir.join(run)
}

/// The two shards (`one`, `two` under `d`) of a trace-only check of two
/// scenes, and the scene files.
fn two_trace_shards(d: &Path) -> (Vec<PathBuf>, PathBuf, PathBuf) {
    let scenes: Vec<PathBuf> = ["three_triangles", "pixel_grid"]
        .iter()
        .map(|s| root().join(format!("scenes/{s}.toml")))
        .collect();
    let trace = ["--only", "trace"];
    let one = shard_check(d, &scenes, "1/2", &trace, "one");
    let two = shard_check(d, &scenes, "2/2", &trace, "two");
    (scenes, one, two)
}

fn merge(dir: &Path, shards: &[&Path]) -> Output {
    rendiff_in(dir)
        .arg("merge")
        .args(shards)
        .args(["--quiet", "-o", "merged"])
        .output()
        .unwrap()
}

/// Item 3: merge took any set of shard runs: one shard alone, shards run
/// with different options or from different splits all merged into a run
/// that passed. Each is refused now, naming the runs; a whole split merges.
#[test]
fn merge_refuses_an_incomplete_or_inconsistent_shard_set() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (scenes, one, two) = two_trace_shards(d);
    let m = read_json(&one.join("manifest.json"));
    assert_eq!(m["shard"]["index"], 1);
    assert_eq!(m["shard"]["deal"].as_array().unwrap().len(), 2);
    assert_eq!(m["options"]["only"], json!(["trace"]));
    let refused = |shards: &[&Path], says: &[&str]| {
        let o = merge(d, shards);
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{shards:?}: {err}");
        for s in says {
            assert!(err.contains(s), "expected {s:?}: {err}");
        }
        assert!(!d.join("merged").exists(), "a refused merge made its run");
    };
    // A shard missing.
    refused(&[&one], &["shard 2/2 of the split missing"]);
    // A shard run with another --only.
    let raster = shard_check(d, &scenes, "2/2", &["--only", "raster"], "raster");
    refused(
        &[&one, &raster],
        &["different options", "--only trace and --only raster"],
    );
    // A shard of another split: more scenes.
    let mut more = scenes.clone();
    more.push(root().join("scenes/icosphere.toml"));
    let other = shard_check(d, &more, "2/2", &["--only", "trace"], "other");
    refused(&[&one, &other], &["different splits", "icosphere"]);
    // A shard of another split whose scene has the same name, another file.
    std::fs::create_dir_all(d.join("mine")).unwrap();
    let copy = d.join("mine/three_triangles.toml");
    let original = std::fs::read_to_string(&scenes[0]).unwrap();
    std::fs::write(&copy, original.replace("width = 96", "width = 95")).unwrap();
    let renamed = shard_check(
        d,
        &[copy, scenes[1].clone()],
        "2/2",
        &["--only", "trace"],
        "renamed",
    );
    refused(&[&one, &renamed], &["different splits"]);
    // A shard whose renderer is another version.
    let edited = d.join("edited");
    std::fs::create_dir_all(&edited).unwrap();
    let mut m = read_json(&two.join("manifest.json"));
    for s in m["scenes"].as_array_mut().unwrap() {
        for r in s["renders"].as_array_mut().unwrap() {
            if r["backend"] == "trace" {
                r["version"] = "rendiff 9.9.9".into();
            }
        }
    }
    std::fs::write(edited.join("manifest.json"), m.to_string()).unwrap();
    refused(&[&one, &edited], &["trace is version", "rendiff 9.9.9"]);
    // The whole split merges.
    let o = merge(d, &[&one, &two]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
}

/// Item 6: a failing renderer's message named the staging folder
/// (`.run.partial-PID`), gone by the time anyone reads it; a scene file
/// whose name holds a terminal escape reached the terminal raw.
#[test]
fn messages_name_the_run_folder_and_carry_no_raw_escapes() {
    let dir = tempfile::tempdir().unwrap();
    let loud = "#!/bin/sh\necho \"cannot write $2\" >&2\nexit 1\n";
    declare(dir.path(), &[("loud", loud)]);
    let scene = dir.path().join("esc\u{1b}[31mred.toml");
    std::fs::copy(root().join("scenes/three_triangles.toml"), &scene).unwrap();
    need_venv();
    let out = rendiff_in(dir.path())
        .arg("check")
        .arg(&scene)
        .args(["--renderers", "renderers.toml", "--only", "loud"])
        .args(["--no-calibration", "-o", "run"])
        .output()
        .unwrap();
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    let run = dir.path().join("run");
    let results = std::fs::read_to_string(run.join("results.json")).unwrap();
    let manifest = std::fs::read_to_string(run.join("manifest.json")).unwrap();
    assert!(
        results.contains(&format!("cannot write {}", run.display())),
        "the renderer's message, naming the run folder: {results}"
    );
    for (what, t) in [
        ("stdout", &stdout),
        ("stderr", &stderr),
        ("results.json", &results),
        ("manifest.json", &manifest),
    ] {
        assert!(
            !t.contains(".partial-"),
            "{what} names the staging folder: {t}"
        );
    }
    for (what, t) in [("stdout", &stdout), ("stderr", &stderr)] {
        assert!(!t.contains('\u{1b}'), "{what} carries a raw escape: {t:?}");
    }
}

/// Found by the fuzzer (tests/fuzz_scenes/runs.rs): gate ignored a
/// manifest.json it could not read and printed PASS on the damaged run.
#[test]
fn gate_refuses_a_damaged_manifest() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    json_run(&run, &["alpha"], &["trace"]);
    let baseline = dir.path().join("baseline.json");
    let o = bless(&run, &baseline, &[]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
    let gate = || common::cli::gate_command(&run, &baseline).output().unwrap();
    assert_eq!(gate().status.code(), Some(0));
    let manifest = run.join("manifest.json");
    let good = std::fs::read(&manifest).unwrap();
    for bad in [&good[..good.len() / 2], b"null", b"\xff{}"] {
        std::fs::write(&manifest, bad).unwrap();
        let o = gate();
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert!(err.contains("manifest.json"), "{err}");
        assert!(!text(&o.stdout).contains("PASS"));
    }
}

/// Found by the fuzzer: merge judged a shard's renders again against a
/// resolved scene changed after its check (or with its recorded hash
/// changed), and passed.
#[test]
fn merge_refuses_a_shard_whose_resolved_scene_changed() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (_, one, two) = two_trace_shards(d);
    let m = read_json(&one.join("manifest.json"));
    let name = m["scenes"][0]["scene"].as_str().unwrap().to_string();
    let refused = |says: &str| {
        let o = merge(d, &[&one, &two]);
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert!(
            err.contains("one/manifest.json") && err.contains(says),
            "{err}"
        );
        assert!(!d.join("merged").exists());
    };
    // A triangle changed after the check.
    let tri = one.join(format!("scenes/{name}/resolved/triangles.f32"));
    let good = std::fs::read(&tri).unwrap();
    let mut bad = good.clone();
    bad[0] ^= 0x40;
    std::fs::set_permissions(&tri, std::fs::Permissions::from_mode(0o644)).unwrap();
    std::fs::write(&tri, &bad).unwrap();
    refused("is not the one the shard rendered");
    std::fs::write(&tri, &good).unwrap();
    // The recorded hash changed, or removed.
    let path = one.join("manifest.json");
    for h in [json!("sha256:00"), json!("")] {
        let mut edited = m.clone();
        edited["scenes"][0]["resolved_sha256"] = h;
        std::fs::write(&path, edited.to_string()).unwrap();
        refused("resolved");
    }
    std::fs::write(&path, m.to_string()).unwrap();
    let o = merge(d, &[&one, &two]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o.stderr));
}
