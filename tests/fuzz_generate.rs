//! `rendiff fuzz`'s generator is reproducible: the same seed writes the
//! same scene files, byte for byte; another seed writes other scenes; and
//! every file is a scene the core accepts.

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
