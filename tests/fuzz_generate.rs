//! `rendiff fuzz`'s generator is reproducible: the same seed writes the
//! same scene files, byte for byte; another seed writes other scenes; and
//! every file is a scene the core accepts; `--minutes` generates in
//! batches whose scenes are `--count`'s, file for file.

mod common;

use common::cli::{need_venv, output_within};
use std::path::Path;

fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let p = e.unwrap().path();
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            (name, std::fs::read(&p).unwrap())
        })
        .collect();
    v.sort();
    v
}

#[test]
fn the_same_seed_writes_the_same_files_byte_for_byte() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b, c) = (
        tmp.path().join("a"),
        tmp.path().join("b"),
        tmp.path().join("c"),
    );
    let (fa, fam_a) = rendiff::fuzz::write_scenes(42, 60, &a).unwrap();
    let (_, fam_b) = rendiff::fuzz::write_scenes(42, 60, &b).unwrap();
    rendiff::fuzz::write_scenes(43, 60, &c).unwrap();
    assert_eq!(fa.len(), 60);
    assert_eq!(fam_a, fam_b);
    let (x, y, z) = (files(&a), files(&b), files(&c));
    assert_eq!(x, y, "seed 42 twice");
    // Another seed: other names and other contents.
    let contents = |v: &[(String, Vec<u8>)]| v.iter().map(|(_, c)| c.clone()).collect::<Vec<_>>();
    let (cx, cz) = (contents(&x), contents(&z));
    assert!(
        cx.iter().all(|s| !cz.contains(s)),
        "seed 43 repeats a scene of seed 42"
    );
    // A prefix of a longer run is the shorter run: scene i depends on (seed, i) only.
    let d = tmp.path().join("d");
    rendiff::fuzz::write_scenes(42, 10, &d).unwrap();
    assert_eq!(files(&d), x[..10].to_vec());
    // Each is a scene the core loads and resolves.
    for f in &fa {
        let scene = rendiff::scene::Scene::load(f).unwrap();
        rendiff::scene::resolve::ResolvedScene::resolve(&scene).unwrap();
    }
}

/// Bad input to `fuzz` and `reduce` is one clear line and exit 2, before
/// anything renders: a folder fuzz did not write is never emptied, and a
/// run without the named failure says so.
#[test]
fn bad_fuzz_and_reduce_input_is_one_clear_line() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::create_dir(dir.join("mine")).unwrap();
    std::fs::write(dir.join("mine/keep.txt"), "mine").unwrap();
    let run = |args: &[&str]| {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_rendiff"))
            .current_dir(dir)
            .env("RENDIFF_HOME", env!("CARGO_MANIFEST_DIR"))
            .args(args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        (out.status.code(), err)
    };
    let (code, err) = run(&["fuzz", "--count", "3", "-o", "mine"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("not a fuzz folder"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(dir.join("mine/keep.txt").is_file());
    let (code, err) = run(&["fuzz", "--count", "0"]);
    assert_eq!(code, Some(2), "{err}");
    // --count and --minutes: exactly one of them.
    for args in [
        &["fuzz", "--count", "3", "--minutes", "1", "-o", "both"][..],
        &["fuzz", "-o", "neither"][..],
    ] {
        let (code, err) = run(args);
        assert_eq!(code, Some(2), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains("--count N or --minutes M"), "{args:?}: {err}");
        assert!(!dir.join(args[args.len() - 1]).exists(), "{args:?}");
    }
    let (code, err) = run(&["fuzz", "--minutes", "0"]);
    assert_eq!(code, Some(2), "{err}");
    // --from makes its own scenes; a missing source is named.
    let (code, err) = run(&["fuzz", "--from", "a.toml", "--count", "3", "-o", "f1"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("--from makes its own scenes"), "{err}");
    let (code, err) = run(&["fuzz", "--from", "absent.toml", "-o", "f2"]);
    assert_eq!(code, Some(2), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("absent.toml"), "{err}");
    // A bad known-finding declaration is refused before anything renders.
    std::fs::create_dir(dir.join("known")).unwrap();
    std::fs::write(dir.join("known/k.toml"), "classification = \"bug\"\n").unwrap();
    let (code, err) = run(&["fuzz", "--count", "1", "--known", "known", "-o", "f3"]);
    assert_eq!(code, Some(2), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(
        err.contains("k.toml") && err.contains("not a known-finding declaration"),
        "{err}"
    );
    assert!(!dir.join("f3").exists());
    let (code, err) = run(&["reduce", "nope", "s1_00000", "--backend", "trace"]);
    assert_eq!(code, Some(2), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("nope"), "{err}");
}

/// A fuzz whose check is refused (an unknown backend) leaves a folder the
/// next fuzz may reuse: it holds only what fuzz writes.
#[test]
fn a_refused_fuzz_leaves_a_reusable_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let fuzz = |dir: &Path| {
        std::process::Command::new(env!("CARGO_BIN_EXE_rendiff"))
            .current_dir(dir)
            .env("RENDIFF_HOME", env!("CARGO_MANIFEST_DIR"))
            .args([
                "fuzz",
                "--count",
                "2",
                "--only",
                "no_such_backend",
                "-o",
                "f",
            ])
            .output()
            .unwrap()
    };
    for _ in 0..2 {
        let out = fuzz(tmp.path());
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains("no_such_backend"), "{err}");
        assert!(!err.contains("not a fuzz folder"), "{err}");
    }
}

/// `--minutes 1` through the core alone: whole batches of 50 scenes, each
/// its own check run under `runs/`, until the minute is up; the scenes are
/// the first N of the seed, the files `--count N` writes, byte for byte;
/// and every scene was compared (a trace verdict for each).
#[test]
fn minutes_generates_whole_batches_of_the_seeds_first_scenes() {
    need_venv();
    let tmp = tempfile::tempdir().unwrap();
    let out = output_within(
        std::process::Command::new(env!("CARGO_BIN_EXE_rendiff"))
            .current_dir(tmp.path())
            .env("RENDIFF_HOME", env!("CARGO_MANIFEST_DIR"))
            .args(["fuzz", "--seed", "5", "--minutes", "1", "--only", "trace"])
            .args(["--jobs", "2", "--quiet", "-o", "fuzz"]),
        600,
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    let ledger: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(tmp.path().join("fuzz/findings.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(ledger["run"], "runs");
    let scenes = ledger["scenes"].as_u64().unwrap();
    let batch = rendiff::fuzz::BATCH;
    assert!(scenes >= batch && scenes.is_multiple_of(batch), "{ledger}");
    let expected = tmp.path().join("expected");
    rendiff::fuzz::write_scenes(5, scenes, &expected).unwrap();
    assert_eq!(files(&tmp.path().join("fuzz/scenes")), files(&expected));
    let mut compared = 0;
    for k in 0..scenes / batch {
        let run = tmp
            .path()
            .join("fuzz")
            .join(rendiff::fuzz::batch_run(k))
            .join("results.json");
        let results: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&run).unwrap()).unwrap();
        compared += results["results"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|e| {
                e["backend"] == "trace"
                    && e["buffer"] == "id"
                    && e["status"] == "pass"
                    // Not the calibration probes (batch 0 runs them).
                    && e["scene"].as_str().unwrap().starts_with("s5_")
            })
            .count() as u64;
    }
    assert_eq!(compared, scenes);
    assert!(!tmp
        .path()
        .join("fuzz")
        .join(rendiff::fuzz::batch_run(scenes / batch))
        .exists());
}

/// `--from`: a scene's base and its six variants go through one check (the
/// core's trace here); none changes the verdict class, so no finding, and
/// the ledger and the page say what was fuzzed.
#[test]
fn from_checks_a_scene_and_its_variants() {
    need_venv();
    let tmp = tempfile::tempdir().unwrap();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/three_triangles.toml");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .current_dir(tmp.path())
        .env("RENDIFF_HOME", env!("CARGO_MANIFEST_DIR"))
        .args(["fuzz", "--from"])
        .arg(&scene)
        .args([
            "--only",
            "trace",
            "--no-calibration",
            "--jobs",
            "2",
            "--quiet",
            "-o",
            "f",
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    let ledger: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(tmp.path().join("f/findings.json")).unwrap())
            .unwrap();
    assert_eq!(ledger["scenes"], 6, "{ledger}");
    assert_eq!(ledger["from"][0], scene.display().to_string());
    assert_eq!(ledger["findings"].as_array().unwrap().len(), 0, "{ledger}");
    let names: Vec<String> = files(&tmp.path().join("f/scenes"))
        .into_iter()
        .map(|(n, _)| n)
        .collect();
    assert_eq!(names.len(), 7, "{names:?}");
    for rel in rendiff::fuzz::variants::RELATIONS {
        assert!(
            names.contains(&format!("m0_three_triangles__{rel}.toml")),
            "{rel}: {names:?}"
        );
    }
    // Every variant was compared (a trace verdict for each, base included).
    let results = std::fs::read_to_string(tmp.path().join("f/run/results.json")).unwrap();
    for n in &names {
        let stem = n.trim_end_matches(".toml");
        assert!(
            results.contains(&format!("\"scene\": \"{stem}\"")),
            "{stem}"
        );
    }
    let page = std::fs::read_to_string(tmp.path().join("f/findings.html")).unwrap();
    assert!(page.contains("6 variants of"), "{page}");
}
