//! The subcommands' bodies, one module per family (`main.rs` holds the
//! command line and dispatches): `render`, `check` (and `merge`), `fuzz` (and
//! `reduce`), `scenes` (listing, export, `scene new`, `vocab`) and `records`
//! (`report`, `gate`, `bless`, `diff`, `bench`). What several share (the
//! user's and rendiff's own files, exit codes) is here.

pub mod check;
pub mod fuzz;
pub mod records;
pub mod render;
pub mod scenes;

use anyhow::Result;
use rendiff::scene::resolve::ResolvedScene;
use rendiff::scene::Scene;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Success, or exit status `code` (1: a verdict failed; 2: an error).
pub fn exit(ok: bool, code: u8) -> ExitCode {
    if ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(code)
    }
}

/// The `--renderers` file, made absolute and checked to exist here, so that
/// a typo is one clear line and the harness (which runs in rendiff's
/// checkout) finds it.
pub fn renderers_file(file: Option<PathBuf>) -> Result<Option<PathBuf>> {
    file.map(|f| user_file(&f, "renderers")).transpose()
}

/// A file the user names for the harness to read (`--renderers`,
/// `--expectations`), absolute, checked here to exist and to be a regular
/// file (the harness reads it later, after the renders: a typo or a device
/// is one line before anything runs).
pub fn user_file(file: &Path, what: &str) -> Result<PathBuf> {
    let abs = std::path::absolute(file)?;
    if !abs.exists() {
        anyhow::bail!("{}: {what} file not found", file.display());
    }
    if !abs.is_file() {
        anyhow::bail!("{}: the {what} file is not a regular file", file.display());
    }
    Ok(abs)
}

/// One of rendiff's own files: as the user gave it, else `rel` in its
/// checkout ([`rendiff::check::in_root`]); absolute, because the harness runs
/// in the checkout, not in the user's folder.
pub fn own_file(root: &Path, given: Option<PathBuf>, rel: &str) -> Result<PathBuf> {
    Ok(std::path::absolute(
        given.unwrap_or_else(|| rendiff::check::in_root(root, rel)),
    )?)
}

/// The expectations file: the user's (checked), else rendiff's own.
pub fn expectations_file(root: &Path, given: Option<PathBuf>) -> Result<PathBuf> {
    match given {
        Some(f) => user_file(&f, "expectations"),
        None => own_file(root, None, "tests/expectations.toml"),
    }
}

/// A scene file (or model) loaded and resolved, its import warnings said.
pub fn load_scene(path: &Path) -> Result<ResolvedScene> {
    let scene = Scene::load(path)?;
    let resolved = ResolvedScene::resolve(&scene)?;
    for w in &resolved.warnings {
        rendiff::errln!("warning: {w}");
    }
    Ok(resolved)
}
