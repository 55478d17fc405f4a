//! Temporary paths this process creates (the XDG runtime folder in `main.rs`,
//! the EXR's temporary name in [`crate::output`]) and their removal when the
//! process is interrupted. SIGINT, SIGTERM and SIGHUP (a terminal, `timeout`,
//! a harness giving up) end a process without running any destructor, which
//! would leave them behind.
//!
//! The same scheme as rendiff's own (`src/shutdown.rs` and rendiff-core's
//! `pending`), kept here so that this crate stays self-contained: every
//! temporary path is registered while it lives ([`track_path`]); on a signal
//! a watcher thread ([`Signals::watch`]) removes them, says so in one line and
//! ends the process by that signal.

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

/// Removes every registered path (a folder with its contents, never
/// following a link); returns how many there were. Each is removed twice: a
/// file being created can appear between the first removal and the exit.
pub fn remove_all() -> usize {
    let paths: Vec<PathBuf> = PATHS.lock().unwrap_or_else(|e| e.into_inner()).clone();
    for _ in 0..2 {
        for p in &paths {
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
    paths.len()
}

/// SIGINT, SIGTERM and SIGHUP, hooked by [`Signals::hook`] and handled once
/// [`Signals::watch`] starts the watcher thread.
pub struct Signals {
    #[cfg(unix)]
    inner: signal_hook::iterator::Signals,
}

impl Signals {
    /// Installs the handlers without starting any thread: `main` may still
    /// set environment variables afterwards, and a signal arriving before
    /// [`Signals::watch`] waits for it instead of killing the process with
    /// its temporary paths in place. An error means the signals could not be
    /// hooked (the process then keeps the default behaviour).
    pub fn hook() -> std::io::Result<Signals> {
        #[cfg(unix)]
        {
            use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
            Ok(Signals {
                inner: signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP])?,
            })
        }
        #[cfg(not(unix))]
        Ok(Signals {})
    }

    /// Starts the watcher thread: on the first signal it removes every
    /// registered path ([`remove_all`]), prints one line and ends the process
    /// by that same signal (its default action), so whoever sent it sees the
    /// process killed by it.
    pub fn watch(self) -> std::io::Result<()> {
        #[cfg(unix)]
        {
            let mut signals = self.inner;
            std::thread::Builder::new()
                .name("rendiff-wgpu-signals".into())
                .spawn(move || {
                    if let Some(sig) = signals.forever().next() {
                        let removed = remove_all();
                        // Not eprintln!: it panics on a closed stderr, which
                        // would end this thread before the process exits.
                        use std::io::Write;
                        let _ = writeln!(
                            std::io::stderr(),
                            "rendiff-wgpu: interrupted by {}: removed {removed} temporary file(s) or folder(s)",
                            signal_name(sig)
                        );
                        let _ = signal_hook::low_level::emulate_default_handler(sig);
                        std::process::exit(128 + sig);
                    }
                })?;
        }
        Ok(())
    }
}

#[cfg(unix)]
fn signal_name(sig: i32) -> String {
    match sig {
        signal_hook::consts::SIGINT => "SIGINT".into(),
        signal_hook::consts::SIGTERM => "SIGTERM".into(),
        signal_hook::consts::SIGHUP => "SIGHUP".into(),
        other => format!("signal {other}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn guards_deregister_what_they_registered() {
        let p = std::env::temp_dir().join(format!("rendiff-wgpu-pending-{}", std::process::id()));
        {
            let _g = track_path(&p);
            assert!(PATHS.lock().unwrap().contains(&p));
        }
        assert!(!PATHS.lock().unwrap().contains(&p));
    }
}
