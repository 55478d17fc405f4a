//! A benchmark's outputs as one set: `STEM.json`, `STEM.html`, its plots
//! `STEM-NAME.svg` and the folder's `index.html` are all replaced, or none is.
//!
//! Every path is checked before anything is written (a folder, FIFO, device
//! or socket where a result goes is refused, also before the benchmark runs:
//! [`check_targets`]); the new files are written into a staging folder
//! `OUT/.STEM.tmp-PID` (registered with the shutdown handler, so an
//! interrupted run leaves none) and only then moved into place, the files
//! they replace kept as hard links until every move has succeeded, so that a
//! failed move puts the old set back. Plots of the same benchmark that the
//! new run does not write (`knobs-visibility-OLDSCENE.svg` after a knobs run
//! on another scene) are removed with the same rollback: the folder never
//! mixes two runs. Only names of the benchmark's own pattern are touched.

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

/// Whether `name` is one of the files benchmark `stem` writes: `STEM.json`,
/// `STEM.html` or a plot `STEM-NAME.svg`.
pub fn owned(stem: &str, name: &str) -> bool {
    name == format!("{stem}.json")
        || name == format!("{stem}.html")
        || name
            .strip_prefix(stem)
            .and_then(|r| r.strip_prefix('-'))
            .and_then(|r| r.strip_suffix(".svg"))
            .is_some_and(|n| !n.is_empty())
}

/// The names of the entries in `dir`, sorted; none where it cannot be read,
/// and no name that is not UTF-8 (no benchmark writes one): what a folder of
/// results holds, here and in the tests.
pub fn file_names(dir: &Path) -> Vec<String> {
    let Ok(list) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut names: Vec<String> = list
        .flatten()
        .filter_map(|e| e.file_name().to_str().map(String::from))
        .collect();
    names.sort();
    names
}

/// The plots of `stem` already in `dir` (names only).
fn existing_plots(dir: &Path, stem: &str) -> Vec<String> {
    file_names(dir)
        .into_iter()
        .filter(|n| n.ends_with(".svg") && owned(stem, n))
        .collect()
}

/// Refuses an output folder that is not a folder, and any path of the
/// benchmark's set in it (its JSON, HTML, `index.html` and every existing
/// `STEM-*.svg`) that is not a regular file: checked before the benchmark
/// runs, so that minutes of work are not lost to an unwritable output, and
/// again with the final names before anything is written. Creates nothing.
pub fn check_targets(dir: &Path, stem: &str) -> Result<()> {
    match std::fs::metadata(dir) {
        Ok(m) if !m.is_dir() => bail!(
            "{}: not a folder; -o names the folder the benchmark writes {stem}.json, {stem}.html and its plots into",
            dir.display()
        ),
        Ok(_) => {}
        Err(_) => return Ok(()), // created when the results are written
    }
    let mut names = vec![
        format!("{stem}.json"),
        format!("{stem}.html"),
        "index.html".to_string(),
    ];
    names.extend(existing_plots(dir, stem));
    for n in names {
        rendiff::exr_io::check_output(&dir.join(n))?;
    }
    Ok(())
}

/// Sweeps staging folders of `stem` left by processes that no longer run
/// (a SIGKILLed benchmark, which no handler sees).
fn remove_abandoned(dir: &Path, stem: &str) {
    let prefix = format!(".{stem}.tmp-");
    let Ok(list) = std::fs::read_dir(dir) else {
        return;
    };
    for e in list.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let Some(pid) = name
            .strip_prefix(&prefix)
            .and_then(|p| p.parse::<u32>().ok())
        else {
            continue;
        };
        if pid != std::process::id() && !Path::new(&format!("/proc/{pid}")).exists() {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}

/// Writes `files` (name, bytes) into `dir` as one set for benchmark `stem`
/// and removes the benchmark's plots that the set does not hold; returns the
/// paths written. On an error, `dir` holds what it held before.
pub fn write_set(dir: &Path, stem: &str, files: &[(String, Vec<u8>)]) -> Result<Vec<PathBuf>> {
    // A name given twice (two plots with one name) is written once, the last.
    let files: Vec<(String, Vec<u8>)> = files
        .iter()
        .enumerate()
        .filter(|(i, (n, _))| !files[i + 1..].iter().any(|(m, _)| m == n))
        .map(|(_, f)| f.clone())
        .collect();
    let files = &files[..];
    check_targets(dir, stem)?;
    for (name, _) in files {
        if name.contains('/') || name.starts_with('.') || name.is_empty() {
            bail!("{name:?}: not a plain file name");
        }
        rendiff::exr_io::check_output(&dir.join(name))?;
    }
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create output folder", dir.display()))?;
    remove_abandoned(dir, stem);
    let staging = dir.join(format!(".{stem}.tmp-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&staging);
    // Removed by the signal handler if the benchmark is interrupted here.
    let _pending = rendiff::shutdown::track_path(&staging);
    let result = stage_and_commit(dir, stem, &staging, files);
    let _ = std::fs::remove_dir_all(&staging);
    result
}

fn stage_and_commit(
    dir: &Path,
    stem: &str,
    staging: &Path,
    files: &[(String, Vec<u8>)],
) -> Result<Vec<PathBuf>> {
    let new = staging.join("new");
    let old = staging.join("old");
    for d in [&new, &old] {
        std::fs::create_dir_all(d)
            .with_context(|| format!("{}: cannot create staging folder", d.display()))?;
    }
    for (name, bytes) in files {
        let p = new.join(name);
        std::fs::write(&p, bytes).with_context(|| format!("{}: cannot write", p.display()))?;
    }
    let stale: Vec<String> = existing_plots(dir, stem)
        .into_iter()
        .filter(|n| !files.iter().any(|(f, _)| f == n))
        .filter(|n| {
            // Only files (or links) are the benchmark's; check_targets refused anything else.
            std::fs::symlink_metadata(dir.join(n))
                .is_ok_and(|m| m.is_file() || m.file_type().is_symlink())
        })
        .collect();
    // Keep what is replaced or removed, to put back if a step fails.
    let mut kept = Vec::new();
    for name in files.iter().map(|(n, _)| n).chain(&stale) {
        let target = dir.join(name);
        if std::fs::symlink_metadata(&target).is_err() {
            continue;
        }
        let backup = old.join(name);
        if std::fs::hard_link(&target, &backup).is_err() {
            std::fs::copy(&target, &backup)
                .with_context(|| format!("{}: cannot keep a copy to restore", target.display()))?;
        }
        kept.push(name.clone());
    }
    let mut done: Vec<&String> = Vec::new();
    let mut step = || -> Result<()> {
        for (name, _) in files {
            let target = dir.join(name);
            std::fs::rename(new.join(name), &target)
                .with_context(|| format!("{}: cannot move result into place", target.display()))?;
            done.push(name);
        }
        for name in &stale {
            let target = dir.join(name);
            std::fs::remove_file(&target).with_context(|| {
                format!("{}: cannot remove the earlier run's plot", target.display())
            })?;
            done.push(name);
        }
        Ok(())
    };
    if let Err(e) = step() {
        for name in done {
            let target = dir.join(name);
            if kept.contains(name) {
                let _ = std::fs::rename(old.join(name), &target);
            } else {
                let _ = std::fs::remove_file(&target);
            }
        }
        return Err(e);
    }
    Ok(files.iter().map(|(n, _)| dir.join(n)).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(names: &[&str], text: &str) -> Vec<(String, Vec<u8>)> {
        names
            .iter()
            .map(|n| (n.to_string(), format!("{text} {n}").into_bytes()))
            .collect()
    }

    #[test]
    fn own_names_only() {
        assert!(owned("knobs", "knobs.json"));
        assert!(owned("knobs", "knobs.html"));
        assert!(owned("knobs", "knobs-visibility-icosphere.svg"));
        for other in [
            "knobs-.svg",
            "knobs.svg",
            "knobsx-a.svg",
            "peers-a.svg",
            "knobs-a.png",
            "index.html",
            "knobs-a.svg.bak",
        ] {
            assert!(!owned("knobs", other), "{other}");
        }
    }

    #[test]
    fn a_folder_or_fifo_in_the_set_writes_nothing() {
        let t = tempfile::tempdir().unwrap();
        let dir = t.path();
        std::fs::write(dir.join("x.json"), "old").unwrap();
        std::fs::create_dir(dir.join("x.html")).unwrap();
        let e = write_set(dir, "x", &set(&["x.json", "x.html", "x-a.svg"], "new")).unwrap_err();
        assert!(format!("{e:#}").contains("x.html"), "{e:#}");
        assert_eq!(std::fs::read_to_string(dir.join("x.json")).unwrap(), "old");
        assert_eq!(file_names(dir), ["x.html", "x.json"]);

        std::fs::remove_dir(dir.join("x.html")).unwrap();
        let fifo = dir.join("x-a.svg");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: mkfifo(3) on a NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0);
        let e = write_set(dir, "x", &set(&["x.json", "x.html", "x-a.svg"], "new")).unwrap_err();
        assert!(format!("{e:#}").contains("FIFO"), "{e:#}");
        assert_eq!(std::fs::read_to_string(dir.join("x.json")).unwrap(), "old");
        assert_eq!(file_names(dir), ["x-a.svg", "x.json"]);
        // A FIFO among the plots is refused up front even when the new set
        // would not name it.
        assert!(check_targets(dir, "x").is_err());
    }

    #[test]
    fn stale_plots_of_the_same_benchmark_go_and_nothing_else() {
        let t = tempfile::tempdir().unwrap();
        let dir = t.path().join("out");
        write_set(&dir, "x", &set(&["x.json", "x-a.svg", "x-b.svg"], "one")).unwrap();
        for other in ["y-b.svg", "x-b.png", "notes.txt", "xx-b.svg"] {
            std::fs::write(dir.join(other), "keep").unwrap();
        }
        let written = write_set(&dir, "x", &set(&["x.json", "x-a.svg"], "two")).unwrap();
        assert_eq!(written, [dir.join("x.json"), dir.join("x-a.svg")]);
        assert_eq!(
            file_names(&dir),
            [
                "notes.txt",
                "x-a.svg",
                "x-b.png",
                "x.json",
                "xx-b.svg",
                "y-b.svg"
            ]
        );
        assert_eq!(
            std::fs::read_to_string(dir.join("x-a.svg")).unwrap(),
            "two x-a.svg"
        );
    }

    #[test]
    fn an_output_folder_that_is_a_file_is_refused() {
        let t = tempfile::tempdir().unwrap();
        let f = t.path().join("f");
        std::fs::write(&f, "x").unwrap();
        let e = check_targets(&f, "x").unwrap_err();
        assert!(format!("{e}").contains("not a folder"), "{e}");
        assert!(check_targets(&t.path().join("missing"), "x").is_ok());
        assert!(!t.path().join("missing").exists());
    }
}
