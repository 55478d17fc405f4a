//! Atomic run folders. A `check` renders into a fresh staging folder beside
//! the run folder and swaps it into place only once results.json is written,
//! so a run folder holds one finished run or is marked incomplete: an
//! interrupted or failed `check` never leaves old verdicts beside new buffers
//! for `gate` to pass (docs/run-format.md, "Incomplete runs").
//!
//! Order of events, and what an interruption at each step leaves:
//! 1. `RUN/INCOMPLETE` is written: the previous run, if any, is now refused by
//!    `gate`, `report` and `bless` (its verdicts no longer describe the
//!    scenes a user just asked about).
//! 2. Everything renders into `PARENT/.NAME.partial-PID/` (removed by the
//!    signal handler, or by the next check if rendiff was SIGKILLed).
//! 3. [`Staging::publish`] renames RUN away, renames the staging folder to
//!    RUN (it has no marker) and removes the old one.
//!
//! One run per folder at a time: [`Staging::begin`] takes an advisory lock
//! (`flock`) on RUN itself before it writes the marker, and one on the
//! staging folder as it creates it, and holds both until the run is published
//! or dropped; [`Staging::publish`] swaps the two folders in one step
//! (`renameat2` with `RENAME_EXCHANGE`), so the path RUN always names a
//! folder this run has locked. A second `check -o RUN` (or `merge -o RUN`) is
//! refused, naming the process in RUN's marker, before it writes anything or
//! sweeps a staging folder: two runs used to both print success, the last
//! writer's buffers beside the first's verdicts. The kernel drops the locks
//! with their process, so a killed run leaves no stale lock, and no lock
//! file is left beside RUN.

use super::manifest::INCOMPLETE_MARKER;
use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};

/// A run being written: where it goes, where it is staged.
pub struct Staging {
    /// The folder the user named (`check -o`).
    pub run_dir: PathBuf,
    /// Where this run is written until it is published.
    pub dir: PathBuf,
    _guard: crate::shutdown::PathGuard,
    /// The locks on RUN and on the staging folder, held until this value is
    /// dropped (after the staging folder is removed or published): declared
    /// last, so they are released last.
    _locks: [FolderLock; 2],
}

/// An advisory lock on a folder (see the module's doc); released when
/// dropped, or by the kernel when the process dies.
struct FolderLock {
    _folder: std::fs::File,
}

/// Why a folder's lock was not taken.
enum NotLocked {
    /// Another process holds it.
    Held,
    /// It could not be taken at all.
    Failed(anyhow::Error),
}

/// Locks `dir` (a folder, never through a link) without waiting, and makes
/// sure the path still names the folder locked: one swapped in meanwhile
/// (a run published between the open and the lock) is locked afresh.
fn lock_folder(dir: &Path) -> std::result::Result<FolderLock, NotLocked> {
    use std::os::unix::fs::{MetadataExt, OpenOptionsExt};
    use std::os::unix::io::AsRawFd;
    for _ in 0..100 {
        let file = std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_DIRECTORY | libc::O_NOFOLLOW | libc::O_CLOEXEC)
            .open(dir)
            .with_context(|| format!("{}: cannot open the run folder to lock it", dir.display()))
            .map_err(NotLocked::Failed)?;
        // SAFETY: flock(2) on a descriptor `file` owns for the call.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
            let err = std::io::Error::last_os_error();
            return Err(if err.raw_os_error() == Some(libc::EWOULDBLOCK) {
                NotLocked::Held
            } else {
                NotLocked::Failed(anyhow::anyhow!(
                    "{}: cannot lock the run folder: {err}",
                    dir.display()
                ))
            });
        }
        let same = match (file.metadata(), std::fs::symlink_metadata(dir)) {
            (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
            _ => false,
        };
        if same {
            return Ok(FolderLock { _folder: file });
        }
    }
    Err(NotLocked::Failed(anyhow::anyhow!(
        "{}: the folder kept changing while it was being locked",
        dir.display()
    )))
}

/// Locks the run folder for this run; refused, naming the process that
/// holds it (from its INCOMPLETE marker), when another run has it.
fn lock_run_folder(run_dir: &Path) -> Result<FolderLock> {
    match lock_folder(run_dir) {
        Ok(lock) => Ok(lock),
        Err(NotLocked::Failed(e)) => Err(e),
        Err(NotLocked::Held) => {
            use std::io::Read;
            let marker = run_dir.join(INCOMPLETE_MARKER);
            let mut text = String::new();
            if std::fs::symlink_metadata(&marker).is_ok_and(|m| m.is_file()) {
                let _ = std::fs::File::open(&marker)
                    .map(|f| f.take(MARKER_READ_BYTES).read_to_string(&mut text));
            }
            let pid = text
                .split("(process ")
                .nth(1)
                .and_then(|t| t.split(')').next())
                .and_then(|n| n.parse::<u32>().ok());
            let holder = pid.map_or("another rendiff".to_string(), |p| {
                format!("another rendiff (process {p})")
            });
            bail!(
                "{}: {holder} is writing this run folder; wait for it to finish, or choose another -o",
                run_dir.display()
            )
        }
    }
}

/// A folder `check` may replace: missing, empty, or a rendiff run (it has a
/// manifest.json or an incomplete-run marker). Anything else is refused, so
/// `-o ~/Documents` cannot delete a user's files.
fn replaceable(run_dir: &Path) -> Result<()> {
    let meta = match std::fs::symlink_metadata(run_dir) {
        Err(_) => return Ok(()),
        Ok(m) => m,
    };
    if !meta.is_dir() {
        bail!(
            "{}: run folder exists and is not a folder; choose another -o",
            run_dir.display()
        );
    }
    let mut entries = std::fs::read_dir(run_dir)
        .with_context(|| format!("{}: cannot list the run folder", run_dir.display()))?;
    let empty = entries.next().is_none();
    if empty || run_dir.join("manifest.json").is_file() || run_dir.join(INCOMPLETE_MARKER).is_file()
    {
        return Ok(());
    }
    bail!(
        "{}: run folder exists but holds no rendiff run (no manifest.json); rendiff check replaces its run folder, so choose an empty or new -o",
        run_dir.display()
    )
}

fn sibling(run_dir: &Path, what: &str) -> Result<PathBuf> {
    let name = run_dir
        .file_name()
        .with_context(|| format!("{}: not a folder name", run_dir.display()))?
        .to_string_lossy()
        .into_owned();
    let parent = run_dir
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    Ok(parent.join(format!(".{name}.{what}-{}", std::process::id())))
}

/// Removes staging folders of this run folder left by a rendiff that was
/// killed outright (its process id no longer runs).
fn sweep_abandoned(run_dir: &Path) {
    let (Some(parent), Some(name)) = (run_dir.parent(), run_dir.file_name()) else {
        return;
    };
    let parent = if parent.as_os_str().is_empty() {
        Path::new(".")
    } else {
        parent
    };
    let prefixes = [
        format!(".{}.partial-", name.to_string_lossy()),
        format!(".{}.old-", name.to_string_lossy()),
    ];
    remove_abandoned(parent, &prefixes);
}

/// Removes the folders in `parent` named `<prefix><pid>` whose process no
/// longer runs: what a rendiff killed outright (or interrupted while another
/// thread still wrote there) left of its temporary folders.
pub(crate) fn remove_abandoned(parent: &Path, prefixes: &[String]) {
    let Ok(list) = std::fs::read_dir(parent) else {
        return;
    };
    for e in list.flatten() {
        let file = e.file_name().to_string_lossy().into_owned();
        let Some(pid) = prefixes
            .iter()
            .find_map(|p| file.strip_prefix(p.as_str()))
            .and_then(|pid| pid.parse::<u32>().ok())
        else {
            continue;
        };
        if !Path::new(&format!("/proc/{pid}")).exists() {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}

impl Staging {
    /// Marks `run_dir` incomplete and creates a fresh staging folder for the run.
    pub fn begin(run_dir: &Path) -> Result<Staging> {
        replaceable(run_dir)?;
        std::fs::create_dir_all(run_dir)
            .with_context(|| format!("{}: cannot create run folder", run_dir.display()))?;
        let run_lock = lock_run_folder(run_dir)?;
        let marker = run_dir.join(INCOMPLETE_MARKER);
        std::fs::write(
            &marker,
            format!(
                "rendiff check (process {}) started writing this run and has not finished it\n",
                std::process::id()
            ),
        )
        .with_context(|| format!("{}: cannot mark the run incomplete", marker.display()))?;
        sweep_abandoned(run_dir);
        let dir = sibling(run_dir, "partial")?;
        let _ = std::fs::remove_dir_all(&dir);
        let guard = crate::shutdown::track_path(&dir);
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("{}: cannot create staging folder", dir.display()))?;
        let staging_lock = lock_folder(&dir).map_err(|e| match e {
            NotLocked::Held => anyhow::anyhow!("{}: locked by another process", dir.display()),
            NotLocked::Failed(e) => e,
        })?;
        Ok(Staging {
            run_dir: run_dir.to_path_buf(),
            dir,
            _guard: guard,
            _locks: [run_lock, staging_lock],
        })
    }

    /// Puts the finished run in place of the old one.
    pub fn publish(self) -> Result<()> {
        // One step where the file system allows it: RUN never goes missing,
        // and always names a folder this run holds locked.
        if exchange(&self.dir, &self.run_dir).is_ok() {
            // The staging path now holds the previous run (removed on drop).
            return Ok(());
        }
        let old = sibling(&self.run_dir, "old")?;
        let _old_guard = crate::shutdown::track_path(&old);
        std::fs::rename(&self.run_dir, &old).with_context(|| {
            format!(
                "{}: cannot move the previous run aside",
                self.run_dir.display()
            )
        })?;
        std::fs::rename(&self.dir, &self.run_dir).with_context(|| {
            format!(
                "{}: cannot move the finished run into place from {}",
                self.run_dir.display(),
                self.dir.display()
            )
        })?;
        let _ = std::fs::remove_dir_all(&old);
        Ok(())
    }
}

/// Swaps two folders atomically (`renameat2(RENAME_EXCHANGE)`, Linux 3.15+;
/// an error where the file system has no such operation).
fn exchange(a: &Path, b: &Path) -> std::io::Result<()> {
    let c = |p: &Path| {
        std::ffi::CString::new(p.as_os_str().as_encoded_bytes())
            .map_err(|_| std::io::Error::from(std::io::ErrorKind::InvalidInput))
    };
    let (ca, cb) = (c(a)?, c(b)?);
    // SAFETY: two valid NUL-terminated paths, relative to the current folder.
    let r = unsafe {
        libc::renameat2(
            libc::AT_FDCWD,
            ca.as_ptr(),
            libc::AT_FDCWD,
            cb.as_ptr(),
            libc::RENAME_EXCHANGE,
        )
    };
    if r == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

impl Drop for Staging {
    /// A run that was not published leaves no staging folder behind (the
    /// run folder keeps its marker).
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// The records of a run folder that `gate`, `bless`, `report` and `merge`
/// read as the run's own ([`ensure_complete`] refuses links).
pub const RUN_RECORDS: [&str; 2] = ["manifest.json", "results.json"];

/// Most of a marker's text that is read: check writes one line naming its
/// process; a marker is never read whole (a 1.3 MB one was quoted whole).
const MARKER_READ_BYTES: u64 = 4096;

/// Refuses a run folder whose run did not finish (`INCOMPLETE` present): what
/// `gate`, `report` and `bless` call before reading anything. Any entry by
/// that name marks the run, whatever it is (a dangling symlink passed as no
/// marker); only a regular file's first bytes are read, never through a
/// link: a FIFO there blocked every reader, `/dev/zero` ran them out of memory.
///
/// A record that is a symbolic link is refused here too: a run's verdicts
/// are the files its check wrote, and a `results.json` linked to a file out
/// of the run (another run's, a hand-written one) was gated, blessed and
/// reported as this run's.
pub fn ensure_complete(run_dir: &Path) -> Result<()> {
    for name in RUN_RECORDS {
        let path = run_dir.join(name);
        if std::fs::symlink_metadata(&path).is_ok_and(|m| m.file_type().is_symlink()) {
            let to = std::fs::read_link(&path)
                .map(|t| crate::scene::printable(&t.display().to_string(), 200))
                .unwrap_or_default();
            bail!(
                "{}: a symbolic link (to {to}), not a record of this run; a run's records are files of its own: run rendiff check again",
                path.display()
            );
        }
    }
    let marker = run_dir.join(INCOMPLETE_MARKER);
    let Ok(meta) = std::fs::symlink_metadata(&marker) else {
        return Ok(());
    };
    let why = if meta.is_file() {
        use std::io::Read;
        let mut text = String::new();
        let _ = std::fs::File::open(&marker)
            .map(|f| f.take(MARKER_READ_BYTES).read_to_string(&mut text));
        text
    } else {
        format!("its {INCOMPLETE_MARKER} marker is not a regular file")
    };
    bail!(
        "{}: incomplete run ({}); its verdicts are not trustworthy: run rendiff check again",
        run_dir.display(),
        crate::scene::printable(why.trim(), 200)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The entries of `dir`.
    fn entries(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    fn finished_run(dir: &Path) {
        std::fs::create_dir_all(dir.join("scenes/a")).unwrap();
        std::fs::write(dir.join("manifest.json"), "{}").unwrap();
        std::fs::write(dir.join("results.json"), "{}").unwrap();
        std::fs::write(dir.join("scenes/a/trace.exr"), "old").unwrap();
    }

    #[test]
    fn an_unpublished_run_is_marked_incomplete_and_leaves_no_staging() {
        let t = tempfile::tempdir().unwrap();
        let run = t.path().join("latest");
        finished_run(&run);
        ensure_complete(&run).unwrap();
        let staged = {
            let s = Staging::begin(&run).unwrap();
            std::fs::write(s.dir.join("manifest.json"), "{}").unwrap();
            s.dir.clone()
        }; // dropped: the check failed or was interrupted
        assert!(!staged.exists(), "staging folder left behind");
        let err = ensure_complete(&run).unwrap_err().to_string();
        assert!(err.contains("incomplete run"), "{err}");
        assert_eq!(entries(t.path()), ["latest"], "only the run folder remains");
    }

    #[test]
    fn a_published_run_replaces_the_old_one_entirely() {
        let t = tempfile::tempdir().unwrap();
        let run = t.path().join("latest");
        finished_run(&run);
        let s = Staging::begin(&run).unwrap();
        std::fs::write(s.dir.join("manifest.json"), "{\"new\":1}").unwrap();
        s.publish().unwrap();
        ensure_complete(&run).unwrap();
        assert!(!run.join("scenes/a/trace.exr").exists(), "old buffer kept");
        assert_eq!(
            std::fs::read_to_string(run.join("manifest.json")).unwrap(),
            "{\"new\":1}"
        );
        assert_eq!(entries(t.path()), ["latest"]);
    }

    #[test]
    fn a_folder_that_is_no_run_is_never_replaced() {
        let t = tempfile::tempdir().unwrap();
        let docs = t.path().join("docs");
        std::fs::create_dir_all(&docs).unwrap();
        std::fs::write(docs.join("thesis.tex"), "precious").unwrap();
        let err = Staging::begin(&docs).err().unwrap().to_string();
        assert!(err.contains("holds no rendiff run"), "{err}");
        assert!(docs.join("thesis.tex").exists());
        assert!(!docs.join(INCOMPLETE_MARKER).exists());
    }

    /// Two runs into one folder at once: the second is refused, naming the
    /// first's process, before it touches anything; once the first is done,
    /// the folder is free again (a lock, not a file whose presence counts:
    /// a crashed run leaves nothing stale).
    #[test]
    fn a_second_run_into_the_same_folder_is_refused_while_the_first_runs() {
        let t = tempfile::tempdir().unwrap();
        let run = t.path().join("latest");
        finished_run(&run);
        let first = Staging::begin(&run).unwrap();
        let err = Staging::begin(&run)
            .err()
            .expect("second run refused")
            .to_string();
        let me = format!("process {}", std::process::id());
        assert!(
            err.contains("another rendiff") && err.contains(&me),
            "{err}"
        );
        assert!(
            first.dir.is_dir(),
            "the refused run removed the first's staging"
        );
        first.publish().unwrap();
        let again = Staging::begin(&run).unwrap();
        drop(again);
    }

    #[test]
    fn staging_left_by_a_killed_check_is_swept() {
        let t = tempfile::tempdir().unwrap();
        let run = t.path().join("latest");
        // No process has pid 4194304 (above Linux's pid_max limit).
        let dead = t.path().join(".latest.partial-4194304");
        std::fs::create_dir_all(&dead).unwrap();
        let s = Staging::begin(&run).unwrap();
        assert!(!dead.exists());
        s.publish().unwrap();
    }

    #[test]
    fn any_marker_marks_the_run_and_none_is_read_whole() {
        // A FIFO (blocked every reader), a link to /dev/zero (read until the
        // kernel killed the reader), a dangling link (read as no marker), a
        // folder, and a marker of 1 MiB (quoted whole): each marks the run,
        // in one short line.
        let t = tempfile::tempdir().unwrap();
        let run = t.path().join("latest");
        finished_run(&run);
        let marker = run.join(INCOMPLETE_MARKER);
        let fifo = |p: &Path| {
            let c = std::ffi::CString::new(p.as_os_str().as_encoded_bytes()).unwrap();
            // SAFETY: a valid NUL-terminated path.
            assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        };
        type Maker<'a> = (&'a str, &'a dyn Fn(&Path));
        let makers: [Maker; 5] = [
            ("a FIFO", &|p| fifo(p)),
            ("/dev/zero", &|p| {
                std::os::unix::fs::symlink("/dev/zero", p).unwrap()
            }),
            ("dangling", &|p| {
                std::os::unix::fs::symlink("/no/such/file", p).unwrap()
            }),
            ("a folder", &|p| std::fs::create_dir(p).unwrap()),
            ("1 MiB", &|p| {
                std::fs::write(p, "x".repeat(1 << 20)).unwrap()
            }),
        ];
        for (what, make) in makers {
            make(&marker);
            let err = ensure_complete(&run).unwrap_err().to_string();
            assert!(err.contains("incomplete run"), "{what}: {err}");
            assert!(err.len() < 600 && !err.contains('\n'), "{what}: {err}");
            if marker.is_dir() {
                std::fs::remove_dir(&marker).unwrap();
            } else {
                std::fs::remove_file(&marker).unwrap();
            }
        }
        ensure_complete(&run).unwrap();
    }

    #[test]
    fn records_that_are_links_are_refused() {
        let t = tempfile::tempdir().unwrap();
        let run = t.path().join("latest");
        finished_run(&run);
        let elsewhere = t.path().join("elsewhere.json");
        std::fs::write(&elsewhere, "{}").unwrap();
        for name in RUN_RECORDS {
            let record = run.join(name);
            let keep = std::fs::read(&record).unwrap();
            std::fs::remove_file(&record).unwrap();
            std::os::unix::fs::symlink(&elsewhere, &record).unwrap();
            let err = ensure_complete(&run).unwrap_err().to_string();
            assert!(err.contains(name) && err.contains("symbolic link"), "{err}");
            std::fs::remove_file(&record).unwrap();
            std::fs::write(&record, keep).unwrap();
        }
        ensure_complete(&run).unwrap();
    }

    #[test]
    fn abandoned_folders_of_dead_processes_are_removed_and_live_ones_kept() {
        let t = tempfile::tempdir().unwrap();
        // No process has pid 4194304 (above Linux's pid_max limit).
        let dead = t.path().join(".report.tmp-4194304");
        let live = t.path().join(format!(".report.tmp-{}", std::process::id()));
        let other = t.path().join(".reporting-4194304");
        for d in [&dead, &live, &other] {
            std::fs::create_dir_all(d.join("img")).unwrap();
        }
        remove_abandoned(t.path(), &[".report.tmp-".to_string()]);
        assert!(!dead.exists() && live.exists() && other.exists());
    }
}
