//! The resolved scene is every render's input, never shared state.
//!
//! An external renderer gets `{scene}`, a folder it could write to: one that
//! rewrote it after rendering (halved a triangle) passed itself, and a
//! correct renderer run after it failed with hundreds of interior ID
//! mismatches, explained against the altered geometry. So each external
//! render reads a copy of its own ([`private_copy`], its files read-only),
//! the run records a hash of the resolved scene (`resolved_sha256` in
//! manifest.json, docs/run-format.md) and checks the copy against it after
//! the render: a renderer that changed its input gets an error entry saying
//! so, and no other renderer's verdict can change. The run's own
//! `scenes/<name>/resolved/`, which the comparison reads, is checked again
//! before the comparison.

use anyhow::{bail, Context, Result};
use sha2::{Digest, Sha256};
use std::collections::BTreeMap;
use std::path::Path;

/// A resolved scene folder's contents as hashes: one per entry, and the
/// folder's (`sha256:` and hex, over the sorted entries' names and hashes).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Seal {
    /// The folder's hash, as manifest.json records it.
    pub digest: String,
    /// Each entry's hash by file name (a non-file entry: its kind).
    files: BTreeMap<String, String>,
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Hashes a regular file without loading it whole (`sha256:` and hex; a
/// FIFO or device is refused, never read).
pub fn file_digest(path: &Path) -> Result<String> {
    if !std::fs::metadata(path).is_ok_and(|m| m.is_file()) {
        bail!("{}: not a regular file", path.display());
    }
    let mut f =
        std::fs::File::open(path).with_context(|| format!("{}: cannot read", path.display()))?;
    let mut h = Sha256::new();
    std::io::copy(&mut f, &mut h).with_context(|| format!("{}: cannot read", path.display()))?;
    Ok(format!("sha256:{}", hex(&h.finalize())))
}

impl Seal {
    /// Hashes every entry of `dir` (not following links: a link, a folder
    /// or anything but a regular file is recorded as its kind, so adding one
    /// changes the seal too).
    pub fn of(dir: &Path) -> Result<Seal> {
        let mut files = BTreeMap::new();
        for e in
            std::fs::read_dir(dir).with_context(|| format!("{}: cannot list", dir.display()))?
        {
            let e = e.with_context(|| format!("{}: cannot list", dir.display()))?;
            let name = e.file_name().to_string_lossy().into_owned();
            let kind = e.file_type()?;
            let h = if kind.is_file() {
                file_digest(&e.path())?
            } else if kind.is_symlink() {
                "a symbolic link".into()
            } else if kind.is_dir() {
                "a folder".into()
            } else {
                "a special file".into()
            };
            files.insert(name, h);
        }
        let mut all = Sha256::new();
        for (name, h) in &files {
            all.update(name.as_bytes());
            all.update([0]);
            all.update(h.as_bytes());
            all.update([b'\n']);
        }
        Ok(Seal {
            digest: format!("sha256:{}", hex(&all.finalize())),
            files,
        })
    }

    /// What differs in `now` from this seal, in words (None when nothing
    /// does): the files changed, added and removed.
    pub fn changes(&self, now: &Seal) -> Option<String> {
        if self == now {
            return None;
        }
        let name = |n: &String| crate::scene::printable(n, 100);
        let mut parts = Vec::new();
        let changed: Vec<String> = self
            .files
            .iter()
            .filter(|(n, h)| now.files.get(*n).is_some_and(|x| x != *h))
            .map(|(n, _)| name(n))
            .collect();
        let removed: Vec<String> = self
            .files
            .keys()
            .filter(|n| !now.files.contains_key(*n))
            .map(name)
            .collect();
        let added: Vec<String> = now
            .files
            .keys()
            .filter(|n| !self.files.contains_key(*n))
            .map(name)
            .collect();
        for (what, list) in [("changed", changed), ("removed", removed), ("added", added)] {
            if !list.is_empty() {
                parts.push(format!("{what} {}", list.join(", ")));
            }
        }
        Some(parts.join("; "))
    }
}

/// Copies the regular files of `from` into a new folder `to` and makes
/// them read-only (the folder stays writable, so the copy can be removed
/// by a user who is not root). Anything else in `from` is refused: an
/// export holds regular files only.
pub fn private_copy(from: &Path, to: &Path) -> Result<()> {
    use std::os::unix::fs::PermissionsExt;
    if std::fs::symlink_metadata(to).is_ok() {
        std::fs::remove_dir_all(to)
            .with_context(|| format!("{}: cannot remove an old copy", to.display()))?;
    }
    std::fs::create_dir_all(to).with_context(|| format!("{}: cannot create", to.display()))?;
    for e in std::fs::read_dir(from).with_context(|| format!("{}: cannot list", from.display()))? {
        let e = e?;
        if !e.file_type()?.is_file() {
            bail!(
                "{}: not a regular file in a resolved scene",
                e.path().display()
            );
        }
        let dst = to.join(e.file_name());
        std::fs::copy(e.path(), &dst)
            .with_context(|| format!("{}: cannot copy", e.path().display()))?;
        std::fs::set_permissions(&dst, std::fs::Permissions::from_mode(0o444))
            .with_context(|| format!("{}: cannot make read-only", dst.display()))?;
    }
    Ok(())
}

/// Makes the regular files of `dir` read-only (the run's own resolved
/// scene: the comparison reads it; nothing writes it after the export).
pub fn make_read_only(dir: &Path) -> Result<()> {
    use std::os::unix::fs::PermissionsExt;
    for e in std::fs::read_dir(dir).with_context(|| format!("{}: cannot list", dir.display()))? {
        let e = e?;
        if e.file_type()?.is_file() {
            std::fs::set_permissions(e.path(), std::fs::Permissions::from_mode(0o444))
                .with_context(|| format!("{}: cannot make read-only", e.path().display()))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_copy_seals_alike_and_any_change_is_named() {
        let t = tempfile::tempdir().unwrap();
        let (a, b) = (t.path().join("a"), t.path().join("b"));
        std::fs::create_dir_all(&a).unwrap();
        std::fs::write(a.join("scene.json"), "{}").unwrap();
        std::fs::write(a.join("triangles.f32"), [0u8; 36]).unwrap();
        let seal = Seal::of(&a).unwrap();
        assert!(seal.digest.starts_with("sha256:") && seal.digest.len() == 7 + 64);
        private_copy(&a, &b).unwrap();
        assert_eq!(seal.changes(&Seal::of(&b).unwrap()), None);
        assert!(std::fs::metadata(b.join("triangles.f32"))
            .unwrap()
            .permissions()
            .readonly());
        // Replaced (not written in place: the file is read-only), removed, added.
        std::fs::remove_file(b.join("triangles.f32")).unwrap();
        std::fs::write(b.join("triangles.f32"), [1u8; 36]).unwrap();
        std::fs::remove_file(b.join("scene.json")).unwrap();
        std::fs::write(b.join("extra"), "x").unwrap();
        let now = Seal::of(&b).unwrap();
        assert_ne!(now.digest, seal.digest);
        assert_eq!(
            seal.changes(&now).unwrap(),
            "changed triangles.f32; removed scene.json; added extra"
        );
        // A second copy replaces the first, and the copy can be removed.
        private_copy(&a, &b).unwrap();
        assert_eq!(seal.changes(&Seal::of(&b).unwrap()), None);
        std::fs::remove_dir_all(&b).unwrap();
    }
}
