//! `rendiff bench`'s contract beyond its numbers: an interrupted benchmark
//! leaves no scratch folder and no child running; a benchmark's outputs are
//! written as one set (all or nothing, no stale plot of an earlier run);
//! options given explicitly are used as given, `--quick` or not; and the
//! defaults' files are found in rendiff's checkout from any folder.

use rendiff_bench::outputs::file_names;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .unwrap()
}

fn bench() -> Command {
    Command::new(env!("CARGO_BIN_EXE_rendiff-bench"))
}

/// Runs `rendiff-bench ARGS` from the checkout.
fn run(args: &[&str]) -> Output {
    bench()
        .current_dir(root())
        .args(args)
        .output()
        .expect("rendiff-bench runs")
}

fn text(o: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn mkfifo(p: &Path) {
    let c = std::ffi::CString::new(p.to_str().unwrap()).unwrap();
    // SAFETY: mkfifo(3) on a NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0);
}

/// Processes whose command line mentions `needle` (what a benchmark left running).
fn processes_mentioning(needle: &str) -> Vec<String> {
    let mut found = Vec::new();
    for e in std::fs::read_dir("/proc").unwrap().flatten() {
        if let Ok(cmd) = std::fs::read(e.path().join("cmdline")) {
            let cmd = String::from_utf8_lossy(&cmd).replace('\0', " ");
            if cmd.contains(needle) {
                found.push(format!("{}: {cmd}", e.file_name().to_string_lossy()));
            }
        }
    }
    found
}

/// SIGINT during `bench scale`: the scratch folder holding whole check runs
/// is removed and the `rendiff check` writing into it is killed (the folder
/// was not registered with the shutdown handler, and the child, in the
/// benchmark's process group but not killed by it, went on writing).
#[test]
fn interrupted_scale_leaves_no_scratch_and_no_child() {
    let tmp = tempfile::tempdir().unwrap();
    let out_dir = tmp.path().join("out");
    let mut child = bench()
        .current_dir(root())
        .env("TMPDIR", tmp.path())
        .args([
            "scale",
            "--scene",
            "scenes/three_triangles.toml",
            "--shards",
            "2",
            "--runs",
            "1",
            "-o",
        ])
        .arg(&out_dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let scratch = tmp
        .path()
        .join(format!("rendiff-bench-scale-{}-0", child.id()));
    // Once the warm-up check has started writing its run.
    let start = Instant::now();
    while !scratch.join("default").exists() {
        if let Some(st) = child.try_wait().unwrap() {
            panic!("bench scale ended before it was interrupted: {st}");
        }
        assert!(start.elapsed() < Duration::from_secs(120), "no scratch run");
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(500));
    // SAFETY: kill(2) on the child we started.
    unsafe {
        libc::kill(child.id() as i32, libc::SIGINT);
    }
    let status = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break st;
        }
        assert!(start.elapsed() < Duration::from_secs(180), "did not exit");
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    assert_eq!(status.code(), Some(130), "{err}");
    // Nothing may come back after the exit (a child still writing there).
    std::thread::sleep(Duration::from_millis(1500));
    assert!(
        !scratch.exists(),
        "{} left: {:?}",
        scratch.display(),
        file_names(&scratch)
    );
    assert_eq!(file_names(tmp.path()), Vec::<String>::new(), "{err}");
    let left = processes_mentioning(&scratch.to_string_lossy());
    assert!(left.is_empty(), "still running: {left:?}");
}

/// A path of the set that cannot be written (a folder, a FIFO) is refused
/// before anything is written: no new JSON beside an old HTML (the JSON
/// used to be written, then the HTML failed), no index page.
#[test]
fn an_unwritable_output_writes_no_part_of_the_set() {
    let t = tempfile::tempdir().unwrap();
    let d = t.path();
    std::fs::write(d.join("crossover.json"), "old").unwrap();
    std::fs::create_dir(d.join("crossover.html")).unwrap();
    let args = ["crossover", "--quick", "--nx", "1", "--size", "8", "-o"];
    let o = run(&[&args[..], &[d.to_str().unwrap()]].concat());
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.lines().next().unwrap().contains("crossover.html"),
        "{err}"
    );
    assert_eq!(file_names(d), ["crossover.html", "crossover.json"]);
    assert_eq!(
        std::fs::read_to_string(d.join("crossover.json")).unwrap(),
        "old"
    );

    std::fs::remove_dir(d.join("crossover.html")).unwrap();
    mkfifo(&d.join("crossover-times.svg"));
    let o = run(&[&args[..], &[d.to_str().unwrap()]].concat());
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(String::from_utf8_lossy(&o.stderr).contains("crossover-times.svg: is a FIFO"));
    assert_eq!(file_names(d), ["crossover-times.svg", "crossover.json"]);

    // The output folder itself a file: refused, nothing created.
    let f = d.join("file");
    std::fs::write(&f, "x").unwrap();
    let o = run(&[&args[..], &[f.to_str().unwrap()]].concat());
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(String::from_utf8_lossy(&o.stderr).contains("not a folder"));
}

/// A rerun on another scene replaces the benchmark's whole set: the
/// earlier scene's plot goes, files of other benchmarks and other names stay.
#[test]
fn a_rerun_removes_the_benchmarks_stale_plots_only() {
    let t = tempfile::tempdir().unwrap();
    let d = t.path().join("out");
    let dir = d.to_str().unwrap();
    let o = run(&["knobs", "--quick", "-o", dir]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(d.join("knobs-visibility-icosphere.svg").exists());
    for other in ["peers-throughput.svg", "knobs-notes.txt", "knobsy-a.svg"] {
        std::fs::write(d.join(other), "keep").unwrap();
    }
    let o = run(&[
        "knobs",
        "--quick",
        "--scene",
        "scenes/three_triangles.toml@16x12",
        "-o",
        dir,
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let files = file_names(&d);
    assert!(
        !files.contains(&"knobs-visibility-icosphere.svg".to_string()),
        "{files:?}"
    );
    for kept in [
        "knobs-visibility-three_triangles.svg",
        "peers-throughput.svg",
        "knobs-notes.txt",
        "knobsy-a.svg",
        "index.html",
    ] {
        assert!(files.contains(&kept.to_string()), "{kept}: {files:?}");
    }
    assert!(!files.iter().any(|f| f.starts_with('.')), "{files:?}");
}

/// `--quick` changes only the defaults: `--nx 1 --size 16` ran nx 1,4,16
/// at 64x64. Every subcommand's help says so.
#[test]
fn explicit_options_are_used_with_quick() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().to_str().unwrap();
    let o = run(&[
        "crossover",
        "--quick",
        "--nx",
        "1",
        "--size",
        "16",
        "-o",
        dir,
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let r: Value =
        serde_json::from_str(&std::fs::read_to_string(t.path().join("crossover.json")).unwrap())
            .unwrap();
    assert_eq!(r["config"]["size"], serde_json::json!([16, 16]));
    assert_eq!(r["config"]["nx"], serde_json::json!([1]));
    for sub in [
        "knobs",
        "peers",
        "crossover",
        "scale",
        "stability",
        "variance",
        "fuzz",
    ] {
        let o = run(&[sub, "--help"]);
        let help = String::from_utf8_lossy(&o.stdout)
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ");
        assert!(
            help.contains("an option given explicitly is used as given"),
            "{sub}: {help}"
        );
    }
}

/// From outside the checkout the defaults' scenes and references are read
/// from it (RENDIFF_HOME, else the checkout the binary was built from); the
/// output folder stays relative to the current folder.
#[test]
fn defaults_are_found_from_any_folder() {
    for home in [Some(root()), None] {
        let t = tempfile::tempdir().unwrap();
        let mut cmd = bench();
        cmd.current_dir(t.path())
            .args(["knobs", "--quick", "--spp", "1"]);
        match &home {
            Some(h) => cmd.env("RENDIFF_HOME", h),
            None => cmd.env_remove("RENDIFF_HOME"),
        };
        let o = cmd.output().unwrap();
        assert!(o.status.success(), "{home:?}: {}", text(&o));
        let json = t.path().join("reports/bench/knobs.json");
        let r: Value = serde_json::from_str(&std::fs::read_to_string(json).unwrap()).unwrap();
        let scene = r["config"]["scenes"][0]["path"].as_str().unwrap();
        assert_eq!(
            Path::new(scene).canonicalize().unwrap(),
            root().join("scenes/icosphere.toml"),
            "{home:?}"
        );
    }
    // The plain `rendiff bench` too (its default scene is scenes/million.toml).
    let t = tempfile::tempdir().unwrap();
    let o = bench()
        .current_dir(t.path())
        .env("RENDIFF_HOME", root())
        .args(["--runs", "1", "--threads", "1", "--size", "32x24"])
        .args(["-o", "core.json"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    assert!(t.path().join("core.json").is_file());
    // A RENDIFF_HOME that is no checkout is named.
    let t = tempfile::tempdir().unwrap();
    let o = bench()
        .current_dir(t.path())
        .env("RENDIFF_HOME", t.path())
        .args(["variance", "--quick"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(String::from_utf8_lossy(&o.stderr).contains("RENDIFF_HOME="));
}
