//! Where rendiff's own files are: the Python harness, the Python that runs
//! it, and rendiff's data (calibration probes, expectations, references).
//!
//! Two layouts are supported, and one search finds either:
//! - a **checkout** (the repository, set up by `scripts/setup.sh`): the
//!   harness is `harness/rendiff_harness`, put first on `PYTHONPATH` so a
//!   venv shared between checkouts cannot mix them; the data is the
//!   checkout's own `tests/` and `scenes/calibration`;
//! - an **installed harness** (`pip install ./harness`, or a built wheel): the
//!   package carries the data in `rendiff_harness/data/`, which mirrors the
//!   checkout's layout, and `python -m rendiff_harness where --json` says where.
//!
//! The search, in order (each step is named in the error when it fails):
//! 1. `RENDIFF_HOME`, when set: a checkout, else the folder of a venv with the
//!    harness installed (`.venv/bin/python` in it, or `bin/python` when it is
//!    the venv itself); anything else is an error, never a guess elsewhere;
//! 2. the current folder, when it is a checkout;
//! 3. `RENDIFF_PYTHON`, when set: the harness installed for that Python
//!    (asked with `python -m rendiff_harness where --json`), else an error;
//! 4. the checkout this binary was built from (what `cargo install --path .`
//!    leaves), when it is still there.
//!
//! The Python of a checkout is `RENDIFF_PYTHON` if set, else the checkout's
//! `.venv/bin/python`; an installed harness's is the one that was asked.

use super::process::{run_with_timeout, shell_quote};
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

/// The variable naming a rendiff checkout, or the folder of the venv that
/// has the harness installed.
pub const HOME_ENV: &str = "RENDIFF_HOME";

/// The variable naming the Python that runs the harness.
pub const PYTHON_ENV: &str = "RENDIFF_PYTHON";

/// How long `python -m rendiff_harness where` may take (an import of the
/// package and nothing else; a cold start of a big venv is a few seconds).
const WHERE_TIMEOUT: Duration = Duration::from_secs(60);

/// The harness's package folder inside a checkout.
const CHECKOUT_HARNESS: &str = "harness/rendiff_harness";

/// True when `dir` is a rendiff checkout (it has the harness's source).
pub fn is_checkout(dir: &Path) -> bool {
    dir.join(CHECKOUT_HARNESS).is_dir()
}

/// Where rendiff's own files live: the folder whose `tests/expectations.toml`,
/// `tests/references` and `scenes/calibration` are rendiff's (a checkout, or
/// an installed harness's `data/` folder), found by the search in the module
/// documentation. The error lists every step and the command that fixes it.
pub fn find_root() -> Result<PathBuf> {
    Ok(search()?.root)
}

/// What the search found, and how (for `rendiff doctor`).
#[derive(Debug, Clone)]
pub struct Found {
    /// The folder with rendiff's data, laid out like a checkout.
    pub root: PathBuf,
    /// The Python that runs the harness.
    pub python: PathBuf,
    /// The step of the search that found it, in words.
    pub how: String,
}

/// Runs the search of the module documentation.
pub fn search() -> Result<Found> {
    let fix = format!(
        "fix: run rendiff from its checkout (after scripts/setup.sh), or `python3 -m venv VENV && VENV/bin/pip install ./harness` in the checkout and set {PYTHON_ENV}=VENV/bin/python"
    );
    if let Some(home) = std::env::var_os(HOME_ENV).map(PathBuf::from) {
        // Set on purpose: it is that folder or an error, never a guess elsewhere.
        if is_checkout(&home) {
            let root = std::path::absolute(&home)?;
            return Ok(found_checkout(root, format!("{HOME_ENV} (a checkout)")));
        }
        let not = format!(
            "{HOME_ENV}={}: not a rendiff checkout (no {CHECKOUT_HARNESS})",
            home.display()
        );
        return match configured_python(&home) {
            Ok((python, how)) => match installed_data(&python) {
                Ok(root) => Ok(Found {
                    root,
                    python,
                    how: format!("the harness installed for {how}"),
                }),
                Err(why) => bail!("{not}, and {how} {}: {why}; {fix}", python.display()),
            },
            Err(why) => bail!("{not}; {why}; {fix}"),
        };
    }
    let cwd = std::env::current_dir().context("cannot read the current folder")?;
    if is_checkout(&cwd) {
        return Ok(found_checkout(
            cwd,
            "the current folder (a checkout)".into(),
        ));
    }
    let mut tried = vec![
        format!("{HOME_ENV}: not set"),
        format!("current folder {}: not a checkout", cwd.display()),
    ];
    if let Some(python) = std::env::var_os(PYTHON_ENV).map(PathBuf::from) {
        // Configured on purpose: its harness or an error, never a guess elsewhere.
        return match installed_data(&python) {
            Ok(root) => Ok(Found {
                root,
                python,
                how: format!("the harness installed for {PYTHON_ENV}"),
            }),
            Err(why) => bail!(
                "cannot find rendiff's harness; tried {}; {PYTHON_ENV}={}: {why}; {fix}",
                tried.join("; "),
                python.display()
            ),
        };
    }
    tried.push(format!("{PYTHON_ENV}: not set"));
    let built = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    if is_checkout(&built) {
        return Ok(found_checkout(
            built,
            "the checkout this binary was built from".into(),
        ));
    }
    tried.push(format!(
        "the checkout this binary was built from ({}): gone",
        built.display()
    ));
    bail!(
        "cannot find rendiff's harness; tried {}; {fix}",
        tried.join("; ")
    )
}

fn found_checkout(root: PathBuf, how: String) -> Found {
    let python = python(&root);
    Found { root, python, how }
}

/// The Python an installed harness is asked through when `RENDIFF_HOME` is
/// no checkout (`RENDIFF_PYTHON`, else the venv of `home`), and how it was
/// chosen; the error says why none was.
fn configured_python(home: &Path) -> std::result::Result<(PathBuf, String), String> {
    if let Some(py) = std::env::var_os(PYTHON_ENV) {
        return Ok((PathBuf::from(py), PYTHON_ENV.to_string()));
    }
    for rel in [".venv/bin/python", "bin/python"] {
        let py = home.join(rel);
        if py.exists() {
            return Ok((py, format!("the venv of {HOME_ENV}")));
        }
    }
    Err(format!(
        "{PYTHON_ENV}: not set, and {HOME_ENV}={} has no venv (.venv/bin/python or bin/python)",
        home.display()
    ))
}

/// Asks `python` where its installed harness keeps rendiff's data.
fn installed_data(python: &Path) -> std::result::Result<PathBuf, String> {
    if !python.exists() {
        return Err("no such file".into());
    }
    let scratch = std::env::temp_dir();
    let mut cmd = Command::new(python);
    cmd.args(["-m", "rendiff_harness", "where", "--json"])
        .env_remove("PYTHONPATH");
    let o = run_with_timeout(cmd, WHERE_TIMEOUT, &scratch).map_err(|e| format!("{e:#}"))?;
    if o.code != Some(0) {
        return Err(format!(
            "no harness installed ({}: {})",
            o.how(),
            o.stderr_tail(1)
        ));
    }
    #[derive(serde::Deserialize)]
    struct Where {
        data: PathBuf,
    }
    let w: Where = serde_json::from_str(o.stdout.trim())
        .map_err(|e| format!("unreadable `where --json` answer: {e}"))?;
    for rel in [
        "tests/expectations.toml",
        "tests/references",
        "scenes/calibration",
    ] {
        if !w.data.join(rel).exists() {
            return Err(format!(
                "the installed harness lacks its data ({} is missing): reinstall it from a checkout",
                w.data.join(rel).display()
            ));
        }
    }
    Ok(w.data)
}

/// `rel` (one of rendiff's own files) inside `root`: relative as given when
/// the root is the current folder (tidy paths in records), absolute otherwise.
pub fn in_root(root: &Path, rel: &str) -> PathBuf {
    match std::env::current_dir() {
        Ok(cwd) if cwd == root => PathBuf::from(rel),
        _ => root.join(rel),
    }
}

/// The Python that runs the harness for `root`: `RENDIFF_PYTHON` if set;
/// else a checkout's own `.venv`; else (an installed harness found through
/// `RENDIFF_HOME`) that folder's venv, the one [`search`] asked.
pub fn python(root: &Path) -> PathBuf {
    if let Some(py) = std::env::var_os(PYTHON_ENV) {
        return PathBuf::from(py);
    }
    if is_checkout(root) {
        return root.join(".venv/bin/python");
    }
    let configured = std::env::var_os(HOME_ENV).and_then(|h| configured_python(Path::new(&h)).ok());
    match configured {
        Some((py, _)) => py,
        None => root.join(".venv/bin/python"),
    }
}

/// When the harness's Python for `root` does not exist: what is missing, how
/// rendiff's files were found, and the commands that fix it (one line).
pub fn missing_python(root: &Path) -> Option<String> {
    let py = python(root);
    if py.exists() {
        return None;
    }
    let how = search().map_or_else(
        |e| format!("{e:#}"),
        |f| format!("rendiff's files were found through {}", f.how),
    );
    Some(format!(
        "Python harness not installed ({} is missing; {how}): run scripts/setup.sh in {}, or install the harness with pip and set {}=VENV/bin/python",
        py.display(),
        root.display(),
        PYTHON_ENV
    ))
}

/// Puts a checkout's harness first on the command's `PYTHONPATH`; an
/// installed harness is found by its Python alone.
pub fn harness_path(cmd: &mut Command, root: &Path) {
    if is_checkout(root) {
        cmd.env("PYTHONPATH", root.join("harness"));
    }
}

/// The `PYTHONPATH=... ` prefix of a printed command, empty for an installed harness.
pub fn harness_path_words(root: &Path) -> String {
    if is_checkout(root) {
        format!(
            "PYTHONPATH={} ",
            shell_quote(&root.join("harness").display().to_string())
        )
    } else {
        String::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_checkout_is_known_by_its_harness_source() {
        let here = Path::new(env!("CARGO_MANIFEST_DIR"));
        assert!(is_checkout(here));
        assert!(!is_checkout(&here.join("src")));
        let mut cmd = Command::new("true");
        harness_path(&mut cmd, here);
        assert!(cmd.get_envs().any(|(k, _)| k == "PYTHONPATH"));
        let mut cmd = Command::new("true");
        harness_path(&mut cmd, &here.join("src"));
        assert!(!cmd.get_envs().any(|(k, _)| k == "PYTHONPATH"));
        assert!(harness_path_words(&here.join("src")).is_empty());
        assert!(harness_path_words(here).starts_with("PYTHONPATH="));
    }

    #[test]
    fn the_data_of_an_installed_harness_mirrors_the_checkout() {
        // The package's data/ links into the checkout; a wheel carries the files.
        let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("harness/rendiff_harness/data");
        for rel in [
            "tests/expectations.toml",
            "tests/references",
            "scenes/calibration",
        ] {
            assert!(
                data.join(rel).exists(),
                "{rel} missing from the package data"
            );
        }
    }
}
