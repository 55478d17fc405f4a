//! The harness installed like other tools (README "Install"): built from
//! `./harness` by pip into a folder of its own, with rendiff's data carried in
//! the package, then found by the binary through `RENDIFF_PYTHON` from an
//! empty folder, with no checkout on the way. `rendiff doctor` says what it
//! found, and a `check` runs an external renderer through that harness.

mod common;
use common::cli::{need_venv, output_within, root};
use std::path::Path;
use std::process::Command;

/// Installs the harness (no dependencies: the checkout's venv has them) into
/// `site` with pip, as a wheel would lay it out.
fn pip_install(site: &Path) {
    let o = Command::new(root().join(".venv/bin/pip"))
        .current_dir(root())
        .args(["install", "--quiet", "--no-deps", "--target"])
        .arg(site)
        .arg("./harness")
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "pip install ./harness failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// A Python that imports the harness from `site` (and its dependencies from
/// the checkout's venv): what a venv with the harness installed is.
fn python_for(site: &Path, dir: &Path) -> std::path::PathBuf {
    use std::os::unix::fs::PermissionsExt;
    let py = dir.join("python");
    let script = format!(
        "#!/bin/sh\nPYTHONPATH='{}' exec '{}' \"$@\"\n",
        site.display(),
        root().join(".venv/bin/python").display()
    );
    std::fs::write(&py, script).unwrap();
    std::fs::set_permissions(&py, std::fs::Permissions::from_mode(0o755)).unwrap();
    py
}

fn rendiff_in(dir: &Path, python: &Path) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_rendiff"));
    c.current_dir(dir)
        .env("RENDIFF_PYTHON", python)
        .env_remove("RENDIFF_HOME")
        .env_remove("PYTHONPATH");
    c
}

#[test]
fn an_installed_harness_is_found_and_runs_a_check_from_an_empty_folder() {
    need_venv();
    let t = tempfile::tempdir().unwrap();
    let site = t.path().join("site");
    pip_install(&site);
    // The package carries the files themselves, not links into the checkout.
    let data = site.join("rendiff_harness/data");
    for rel in [
        "tests/expectations.toml",
        "tests/references/cornell_gi.json",
        "scenes/calibration/camera_near.toml",
    ] {
        let meta = std::fs::symlink_metadata(data.join(rel))
            .unwrap_or_else(|e| panic!("{rel} not in the installed package: {e}"));
        assert!(meta.file_type().is_file(), "{rel} is not a regular file");
        assert_eq!(
            std::fs::read(data.join(rel)).unwrap(),
            std::fs::read(root().join(rel)).unwrap(),
            "{rel} differs from the checkout's"
        );
    }
    let python = python_for(&site, t.path());
    let empty = t.path().join("work");
    std::fs::create_dir(&empty).unwrap();

    let o = output_within(rendiff_in(&empty, &python).arg("doctor"), 300);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "doctor failed: {out}");
    assert!(out.contains("installed for RENDIFF_PYTHON"), "{out}");
    assert!(out.contains(&data.display().to_string()), "{out}");
    assert!(out.contains("povray:"), "{out}");

    std::fs::copy(
        root().join("scenes/three_triangles.toml"),
        empty.join("mine.toml"),
    )
    .unwrap();
    let o = output_within(
        rendiff_in(&empty, &python).args([
            "check",
            "mine.toml",
            "--only",
            "povray",
            "--quiet",
            "-o",
            "out",
        ]),
        600,
    );
    assert!(
        o.status.success(),
        "check failed: {}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    let results = std::fs::read_to_string(empty.join("out/results.json")).unwrap();
    assert!(results.contains("\"povray\""), "POV-Ray was judged");
    assert!(results.contains("camera_near"), "the packaged probes ran");
    // The renders went through the installed harness, not a checkout's.
    let manifest = std::fs::read_to_string(empty.join("out/manifest.json")).unwrap();
    assert!(
        !manifest.contains("PYTHONPATH="),
        "a render was pointed at a checkout"
    );
    assert!(manifest.contains(&python.display().to_string()));
}

#[test]
fn a_python_without_the_harness_is_one_line_naming_every_step_and_the_fix() {
    let t = tempfile::tempdir().unwrap();
    let o = output_within(
        rendiff_in(t.path(), Path::new("/usr/bin/python3")).arg("doctor"),
        120,
    );
    assert_eq!(o.status.code(), Some(2));
    let out = String::from_utf8_lossy(&o.stdout);
    for step in [
        "RENDIFF_HOME: not set",
        "not a checkout",
        "RENDIFF_PYTHON=/usr/bin/python3",
        "pip install ./harness",
    ] {
        assert!(out.contains(step), "{step:?} not said: {out}");
    }
    let o = output_within(
        rendiff_in(t.path(), Path::new("/usr/bin/python3")).args(["check", "x.toml"]),
        120,
    );
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("RENDIFF_PYTHON=/usr/bin/python3"), "{err}");
}

/// A checkout that was never set up (no venv): one line saying what is
/// missing, how rendiff's files were found, and both fixes; not "cannot
/// start .../.venv/bin/python".
#[test]
fn a_checkout_without_its_venv_says_how_it_was_found_and_how_to_fix_it() {
    let t = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(t.path().join("harness/rendiff_harness")).unwrap();
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_rendiff"));
    cmd.current_dir(t.path())
        .env("RENDIFF_HOME", t.path())
        .env_remove("RENDIFF_PYTHON")
        .args(["check", "--no-calibration", "-o", "out"])
        .arg(root().join("scenes/three_triangles.toml"));
    let o = output_within(&mut cmd, 120);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    for said in [
        "Python harness not installed",
        ".venv/bin/python is missing",
        "found through RENDIFF_HOME",
        "scripts/setup.sh",
        "RENDIFF_PYTHON=",
    ] {
        assert!(err.contains(said), "{said:?} not said: {err}");
    }
}
