//! Fault injection for `rendiff check`: an external renderer that hangs, one
//! that crashes, and one that claims success without writing its buffers are
//! each reported as an error for that renderer only; the core and the other
//! renderers still run, and the run still produces results.json.

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

mod common;

const FAKE_PYTHON: &str = r#"#!/bin/bash
# Stands in for the venv's python: fakes three broken backends, delegates the rest.
if [ "$3" = "info" ]; then
  b='"version":"0","features":["depth","ids"],"buffers":["Z","id"],"peak_memory":[1000000,100],"available":true,"reason":null'
  echo "{\"backends\":[{\"name\":\"hang\",$b},{\"name\":\"crash\",$b},{\"name\":\"liar\",$b},{\"name\":\"partial\",$b},{\"name\":\"forkhang\",$b}]}"
  exit 0
fi
if [ "$3" = "render" ]; then
  out=""; prev=""
  for a in "$@"; do [ "$prev" = "--out" ] && out="$a"; prev="$a"; done
  case "$5" in
    hang) exec sleep 600 ;;
    forkhang) sleep 600 & echo $! > "$FAKE_PIDS/forkhang.pid"; wait ;;
    crash) kill -SEGV $$ ;;
    liar) echo '{"status":"ok"}'; exit 0 ;;
    partial) printf 'half an EXR' > "$out"; echo "renderer died mid-write" >&2; exit 1 ;;
  esac
fi
if [ "$3" = "serve" ]; then
  # The long-lived worker (harness worker.py): one JSON request per line.
  while IFS= read -r line; do
    out=$(printf '%s' "$line" | sed -n 's/.*"--out","\([^"]*\)".*/\1/p')
    case "$line" in
      *'"--backend","hang"'*) exec sleep 600 ;;
      *'"--backend","forkhang"'*) sleep 600 & echo $! > "$FAKE_PIDS/forkhang.pid"; wait ;;
      *'"--backend","crash"'*) kill -SEGV $$ ;;
      *'"--backend","liar"'*) printf '%s\n' '{"code":0,"stdout":"{\"status\":\"ok\"}\n","stderr":""}' ;;
      *'"--backend","partial"'*) printf 'half an EXR' > "$out"
        printf '%s\n' '{"code":1,"stdout":"","stderr":"renderer died mid-write\n"}' ;;
    esac
  done
  exit 0
fi
exec "$REAL_PYTHON" "$@"
"#;

/// Through the long-lived harness workers (the default) and through a
/// process per render (`--no-workers`), faults are reported alike.
#[test]
fn broken_renderers_are_reported_per_renderer_and_do_not_stop_the_run() {
    broken_renderers(&[]);
    broken_renderers(&["--no-workers"]);
}

fn broken_renderers(mode: &[&str]) {
    let root = common::cli::root();
    common::cli::need_venv();
    let real = root.join(".venv/bin/python");
    let dir = tempfile::tempdir().unwrap();
    let fake = dir.path().join("python");
    std::fs::write(&fake, FAKE_PYTHON).unwrap();
    Command::new("chmod").arg("+x").arg(&fake).status().unwrap();
    let run = dir.path().join("run");
    let started = std::time::Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .current_dir(root)
        .env("RENDIFF_PYTHON", &fake)
        .env("REAL_PYTHON", &real)
        .env("FAKE_PIDS", dir.path())
        // No calibration probes: the fakes would hang, crash and lie on each probe
        // too (a hang costs the 1 s timeout per scene); one scene shows the faults.
        .args([
            "check",
            "scenes/three_triangles.toml",
            "--no-calibration",
            "--timeout",
            "1",
            "--quiet",
        ])
        .args(mode)
        .arg("-o")
        .arg(&run)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(1),
        "stdout: {stdout}\nstderr: {stderr}"
    );
    assert!(
        started.elapsed().as_secs() < 60,
        "the hanging renderer was not killed in time"
    );
    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("results.json")).unwrap()).unwrap();
    let status = |backend: &str, buffer: &str| -> (String, String) {
        let e = results["results"]
            .as_array()
            .unwrap()
            .iter()
            .find(|e| e["backend"] == backend && e["buffer"] == buffer)
            .unwrap_or_else(|| panic!("no result for {backend}/{buffer}"));
        (
            e["status"].as_str().unwrap().to_string(),
            e["reason"].as_str().unwrap_or("").to_string(),
        )
    };
    let (s, why) = status("hang", "id");
    assert_eq!(s, "error");
    assert!(why.contains("timed out"), "{why}");
    // The limit it names is the one applied, with the slack explained.
    assert!(why.contains("--timeout"), "{why}");
    let (s, why) = status("crash", "Z");
    assert_eq!(s, "error");
    assert!(why.contains("killed by signal 11 (SIGSEGV)"), "{why}");
    let (s, why) = status("liar", "id");
    assert_eq!(s, "error");
    assert!(why.contains("wrote no buffer file"), "{why}");
    let (s, why) = status("partial", "id");
    assert_eq!(s, "error");
    assert!(why.contains("died mid-write"), "{why}");
    assert!(
        !run.join("scenes/three_triangles/partial.exr").exists(),
        "a partial output was kept"
    );
    for healthy in ["trace", "embree", "embree_robust"] {
        assert_eq!(status(healthy, "id").0, "pass", "{healthy} must still run");
    }
    // A timeout kills the renderer's whole process group: what it forked too.
    let (s, why) = status("forkhang", "id");
    assert_eq!(s, "error");
    assert!(why.contains("timed out"), "{why}");
    let pid = read_pid(&dir.path().join("forkhang.pid"));
    assert!(
        gone_within(pid, Duration::from_secs(5)),
        "process {pid}, forked by a renderer that timed out, still runs"
    );
}

fn read_pid(path: &Path) -> i32 {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .trim()
        .parse()
        .unwrap()
}

/// True when `pid` is gone (or a zombie) within `limit`.
fn gone_within(pid: i32, limit: Duration) -> bool {
    let start = Instant::now();
    while start.elapsed() < limit {
        match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
            Err(_) => return true,
            // Field 3, after the parenthesized command name, is the state.
            Ok(stat)
                if stat
                    .rsplit(')')
                    .next()
                    .is_some_and(|r| r.trim_start().starts_with('Z')) =>
            {
                return true
            }
            Ok(_) => std::thread::sleep(Duration::from_millis(50)),
        }
    }
    false
}

fn fake_python(dir: &Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let root = common::cli::root();
    common::cli::need_venv();
    let real = root.join(".venv/bin/python");
    let fake = dir.join("python");
    std::fs::write(&fake, FAKE_PYTHON).unwrap();
    Command::new("chmod").arg("+x").arg(&fake).status().unwrap();
    (fake, real)
}

/// Starts `rendiff check` into `run` with the fake harness's `forkhang`
/// renderer (it forks a grandchild and hangs), stderr piped, and waits until
/// the renderer runs; returns the check and the grandchild's pid.
fn start_forkhang(dir: &Path, run: &Path) -> (std::process::Child, i32) {
    let (fake, real) = fake_python(dir);
    let child = Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env("RENDIFF_PYTHON", &fake)
        .env("REAL_PYTHON", &real)
        .env("FAKE_PIDS", dir)
        .args(["check", "scenes/three_triangles.toml", "--no-calibration"])
        .args(["--only", "trace,forkhang", "--timeout", "600", "-o"])
        .arg(run)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let pid_file = dir.join("forkhang.pid");
    let start = Instant::now();
    while !pid_file.exists() {
        assert!(start.elapsed().as_secs() < 60, "the renderer never started");
        std::thread::sleep(Duration::from_millis(50));
    }
    (child, read_pid(&pid_file))
}

/// SIGTERM (what `timeout` and CI runners send) and SIGINT during a check:
/// rendiff kills every renderer's process group, leaves no staging folder or
/// temporary file, exits 128 + the signal, and the run folder, which held a
/// finished run, is now marked incomplete: `gate`, `report` and `bless` refuse
/// it instead of passing stale verdicts.
#[test]
fn an_interrupted_check_stops_its_renderers_and_leaves_no_stale_verdict() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for (sig, name) in [(libc::SIGTERM, "SIGTERM"), (libc::SIGINT, "SIGINT")] {
        let dir = tempfile::tempdir().unwrap();
        let runs = dir.path().join("runs");
        let run = runs.join("latest");
        // A finished run whose verdicts all pass: what an interrupted rerun used to leave.
        let finished = Command::new(env!("CARGO_BIN_EXE_rendiff"))
            .current_dir(root)
            .args(["check", "scenes/three_triangles.toml", "--no-calibration"])
            .args(["--only", "trace", "--quiet", "-o"])
            .arg(&run)
            .output()
            .unwrap();
        assert_eq!(finished.status.code(), Some(0), "{finished:?}");
        let gate = |run: &Path| {
            Command::new(env!("CARGO_BIN_EXE_rendiff"))
                .current_dir(root)
                .args(["gate", "--baseline", "reports/baseline.json"])
                .arg(run)
                .output()
                .unwrap()
        };
        let (child, grandchild) = start_forkhang(dir.path(), &run);
        // SAFETY: kill(2) on our own child's pid; no memory is touched.
        unsafe {
            libc::kill(child.id() as i32, sig);
        }
        let out = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(128 + sig), "{name}: {stderr}");
        assert!(
            stderr.contains(&format!("interrupted by {name}")),
            "{stderr}"
        );
        assert!(
            gone_within(grandchild, Duration::from_secs(5)),
            "{name}: process {grandchild}, forked by a renderer, outlived rendiff"
        );
        let left: Vec<String> = std::fs::read_dir(&runs)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(
            left,
            vec!["latest".to_string()],
            "{name}: leftovers beside the run"
        );
        assert!(
            run.join("INCOMPLETE").exists(),
            "{name}: run not marked incomplete"
        );
        let g = gate(&run);
        let gerr = String::from_utf8_lossy(&g.stderr);
        assert_eq!(g.status.code(), Some(2), "{name}: gate must refuse: {gerr}");
        assert!(gerr.contains("incomplete run"), "{gerr}");
        for cmd in [vec!["report"], vec!["bless", "--baseline"]] {
            let mut c = Command::new(env!("CARGO_BIN_EXE_rendiff"));
            c.current_dir(root).args(&cmd);
            if cmd[0] == "bless" {
                c.arg(dir.path().join("baseline.json"));
            }
            let o = c.arg(&run).output().unwrap();
            assert_eq!(o.status.code(), Some(2), "{name}: {cmd:?} must refuse");
        }
    }
}

/// An interrupted rendiff whose stderr is a closed pipe (its reader gone, as
/// when `rendiff check | head` ends, or a bench's parent dropped the pipe)
/// still cleans up and exits: its handler's message used to panic on the
/// closed pipe, ending the handler's thread, and the process ran on forever.
#[test]
fn an_interrupt_with_stderr_closed_still_exits() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let (mut child, grandchild) = start_forkhang(dir.path(), &run);
    // Its stderr's only reader goes.
    drop(child.stderr.take());
    // SAFETY: kill(2) on our own child's pid; no memory is touched.
    unsafe {
        libc::kill(child.id() as i32, libc::SIGTERM);
    }
    let start = Instant::now();
    let status = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break st;
        }
        if start.elapsed() > Duration::from_secs(30) {
            child.kill().unwrap();
            child.wait().unwrap();
            panic!("rendiff still running 30 s after SIGTERM with its stderr closed");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    assert_eq!(status.code(), Some(128 + libc::SIGTERM));
    assert!(
        gone_within(grandchild, Duration::from_secs(5)),
        "process {grandchild}, forked by a renderer, outlived rendiff"
    );
}

/// `check --timeout` bounds the core's own renders, not only external ones:
/// a path-traced scene at 65,536 samples per pixel stops at the limit and is
/// reported as timed out, with no buffer kept.
#[test]
fn the_timeout_bounds_the_cores_own_renders() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let start = Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .current_dir(root)
        .args(["check", "scenes/cornell_gi.toml", "--no-calibration"])
        .args([
            "--only",
            "trace",
            "--spp",
            "65536",
            "--timeout",
            "2",
            "--quiet",
        ])
        .arg("-o")
        .arg(&run)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{stdout}");
    assert!(
        start.elapsed() < Duration::from_secs(120),
        "the core's render ran past its timeout"
    );
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("manifest.json")).unwrap()).unwrap();
    let trace = manifest["scenes"][0]["renders"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["backend"] == "trace")
        .unwrap();
    assert_eq!(trace["status"], "error");
    let msg = trace["message"].as_str().unwrap();
    assert!(msg.contains("timed out"), "{msg}");
    assert!(!run.join("scenes/cornell_gi/trace.exr").exists());
}
