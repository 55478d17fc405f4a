//! Clean shutdown on SIGINT, SIGTERM and SIGHUP (what a terminal, `timeout`
//! and CI runners send). rendiff starts renderers in process groups of their
//! own, so a signal aimed at rendiff's group no longer reaches them: without
//! this, an interrupted `check` would leave POV-Ray or the harness running and
//! a half-written EXR or a staging folder on disk.
//!
//! Every child process group and every temporary path is registered here while
//! it lives (a guard deregisters it). On a signal, a watcher thread kills the
//! registered groups, removes the registered paths, says so in one line and
//! exits with 128 + the signal number. Children are also started with
//! `PR_SET_PDEATHSIG` (see [`die_with_parent`]), so even a SIGKILL of rendiff,
//! which no handler sees, takes its direct children with it.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

static GROUPS: Mutex<Vec<i32>> = Mutex::new(Vec::new());
static INTERRUPTED: AtomicBool = AtomicBool::new(false);

/// Called by whoever just saw a child end: if the child ended because
/// rendiff is being interrupted, wait here for the handler to exit the
/// process, instead of carrying on (recording the killed renderer as failed,
/// writing into a staging folder being removed) and racing it to the exit.
pub fn hold_if_interrupted() {
    while INTERRUPTED.load(Ordering::SeqCst) {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// Keeps a child's process group registered for [`install`]'s handler; drop
/// it once the child has been waited for.
#[must_use = "the group is deregistered when the guard drops"]
pub struct GroupGuard(i32);

impl Drop for GroupGuard {
    fn drop(&mut self) {
        let mut g = GROUPS.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(i) = g.iter().position(|&p| p == self.0) {
            g.swap_remove(i);
        }
    }
}

/// Registers the process group `pgid` (a child started with `process_group(0)`,
/// whose pid is its group id) to be killed if rendiff is interrupted.
pub fn track_group(pgid: u32) -> GroupGuard {
    let id = pgid as i32;
    GROUPS.lock().unwrap_or_else(|e| e.into_inner()).push(id);
    GroupGuard(id)
}

pub use rendiff_core::pending::{track_path, PathGuard};

/// Starts the watcher thread. Called once by `main`; library users (tests)
/// keep the default signal behaviour. An error means the signals could not be
/// hooked, which is reported but never stops a command.
pub fn install() -> std::io::Result<()> {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP])?;
    std::thread::Builder::new()
        .name("rendiff-shutdown".into())
        .spawn(move || {
            if let Some(sig) = signals.forever().next() {
                INTERRUPTED.store(true, Ordering::SeqCst);
                let (groups, paths) = clean_up();
                // Not eprintln!: it panics when stderr is a closed pipe, and a
                // panic here ended this thread before the exit, leaving the
                // process running with its interrupt flag set, forever.
                use std::io::Write;
                let _ = writeln!(
                    std::io::stderr(),
                    "rendiff: interrupted by {}: killed {groups} child process group(s), removed {paths} temporary file(s) or folder(s)",
                    crate::check::process::signal_name(sig)
                );
                std::process::exit(128 + sig);
            }
        })?;
    Ok(())
}

/// Kills every registered group and removes every registered temporary path
/// ([`rendiff_core::pending`]); returns how many of each.
fn clean_up() -> (usize, usize) {
    let groups: Vec<i32> = GROUPS.lock().unwrap_or_else(|e| e.into_inner()).clone();
    for &g in &groups {
        kill_group(g);
    }
    (groups.len(), rendiff_core::pending::remove_all())
}

/// SIGKILL to a whole process group (the renderer and whatever it forked).
pub fn kill_group(pgid: i32) {
    #[cfg(unix)]
    // SAFETY: kill(2) with a negative pid signals that process group; no memory is touched.
    unsafe {
        libc::kill(-pgid, libc::SIGKILL);
    }
    #[cfg(not(unix))]
    let _ = pgid;
}

/// Makes a child about to be started (a `pre_exec` hook) die with SIGKILL when
/// the rendiff thread that started it ends, which covers a SIGKILL of rendiff
/// itself. Linux only; elsewhere a no-op.
pub fn die_with_parent(cmd: &mut std::process::Command) {
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::process::CommandExt;
        // SAFETY: prctl(2) is async-signal-safe and touches no memory of the parent.
        unsafe {
            cmd.pre_exec(|| {
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
                Ok(())
            });
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = cmd;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn guards_deregister_what_they_registered() {
        {
            let _g = track_group(999_999);
            assert!(GROUPS.lock().unwrap().contains(&999_999));
        }
        assert!(!GROUPS.lock().unwrap().contains(&999_999));
    }
}
