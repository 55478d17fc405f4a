//! Temporary files and folders being written, so that an interrupted process
//! can remove them: the tool's signal handler calls [`remove_all`], and no
//! half-written EXR (`.NAME.tmp-PID`) or staging folder stays on disk.
//! Registering is all the core does here; it never handles signals itself.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

static PATHS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Keeps a temporary path registered; dropping the guard only deregisters it
/// (by then its owner has renamed it into place or removed it).
#[must_use = "the path is deregistered when the guard drops"]
pub struct PathGuard(PathBuf);

impl Drop for PathGuard {
    fn drop(&mut self) {
        let mut p = PATHS.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(i) = p.iter().position(|x| *x == self.0) {
            p.swap_remove(i);
        }
    }
}

/// Registers a temporary path (file or folder) to be removed on interruption.
pub fn track_path(path: &Path) -> PathGuard {
    PATHS
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .push(path.to_path_buf());
    PathGuard(path.to_path_buf())
}

/// Removes every registered path; returns how many there were. Each is
/// removed twice: a folder being written into can get a new entry between the
/// first removal and the process's exit.
pub fn remove_all() -> usize {
    let paths: Vec<PathBuf> = PATHS.lock().unwrap_or_else(|e| e.into_inner()).clone();
    remove_paths(&paths);
    paths.len()
}

fn remove_paths(paths: &[PathBuf]) {
    for _ in 0..2 {
        for p in paths {
            match std::fs::symlink_metadata(p) {
                Ok(m) if m.is_dir() => {
                    let _ = std::fs::remove_dir_all(p);
                }
                Ok(_) => {
                    let _ = std::fs::remove_file(p);
                }
                Err(_) => {}
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // remove_all itself is exercised end to end by the tool's interrupt test;
    // here it would race with other tests' registered files.
    #[test]
    fn guards_deregister_what_they_registered() {
        let p = std::env::temp_dir().join(format!("rendiff-pending-{}", std::process::id()));
        {
            let _g = track_path(&p);
            assert!(PATHS.lock().unwrap().contains(&p));
        }
        assert!(!PATHS.lock().unwrap().contains(&p));
    }

    #[test]
    fn files_and_folders_are_removed() {
        let t = tempfile::tempdir().unwrap();
        let dir = t.path().join("staging");
        std::fs::create_dir_all(dir.join("inner")).unwrap();
        let file = t.path().join(".out.exr.tmp-1");
        std::fs::write(&file, "half").unwrap();
        remove_paths(&[dir.clone(), file.clone(), t.path().join("missing")]);
        assert!(!dir.exists() && !file.exists());
    }
}
