//! External processes with a timeout: a renderer that hangs is killed and
//! reported, and never stops the other backends.

use anyhow::{Context, Result};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// What an external process did.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// Exit code; `None` when killed (timeout or signal).
    pub code: Option<i32>,
    /// True when it ran past its time limit and was killed.
    pub timed_out: bool,
    /// Captured standard output.
    pub stdout: String,
    /// Captured standard error.
    pub stderr: String,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// Peak resident memory in bytes of the process and every descendant it
    /// waited for (the kernel's `ru_maxrss` from `wait4`); `None` where the
    /// platform does not report it or the process was killed.
    pub max_rss_bytes: Option<u64>,
}

impl Outcome {
    /// The last `n` lines of stderr, for error messages.
    pub fn stderr_tail(&self, n: usize) -> String {
        let lines: Vec<&str> = self.stderr.lines().collect();
        lines[lines.len().saturating_sub(n)..].join("\n")
    }
}

/// Runs `cmd` with stdin closed and output captured to files in `scratch`
/// (pipes could fill up and deadlock a chatty renderer); kills it after `timeout`.
pub fn run_with_timeout(mut cmd: Command, timeout: Duration, scratch: &Path) -> Result<Outcome> {
    std::fs::create_dir_all(scratch)
        .with_context(|| format!("{}: cannot create scratch folder", scratch.display()))?;
    let out_path = scratch.join("stdout.txt");
    let err_path = scratch.join("stderr.txt");
    let out = std::fs::File::create(&out_path)?;
    let err = std::fs::File::create(&err_path)?;
    let start = Instant::now();
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::from(out))
        .stderr(Stdio::from(err))
        .spawn()
        .with_context(|| format!("cannot start {:?}", cmd.get_program()))?;
    let (status, timed_out, max_rss_bytes) = wait_with_timeout(&mut child, start, timeout)?;
    let read = |p: &Path| {
        std::fs::read(p)
            .map(|b| String::from_utf8_lossy(&b).into_owned())
            .unwrap_or_default()
    };
    Ok(Outcome {
        code: status,
        timed_out,
        stdout: read(&out_path),
        stderr: read(&err_path),
        seconds: start.elapsed().as_secs_f64(),
        max_rss_bytes,
    })
}

/// Waits for `child` (killing it after `timeout`) and returns its exit code,
/// whether it timed out, and its peak memory. On Unix the child is reaped with
/// `wait4`, whose rusage covers the child and its own reaped descendants (a
/// harness process and the renderer it ran), so each render's peak is its own.
#[cfg(unix)]
fn wait_with_timeout(
    child: &mut std::process::Child,
    start: Instant,
    timeout: Duration,
) -> Result<(Option<i32>, bool, Option<u64>)> {
    let pid = child.id() as libc::pid_t;
    let reap = |flags: libc::c_int| -> Result<Option<(libc::c_int, libc::rusage)>> {
        loop {
            let mut status: libc::c_int = 0;
            // SAFETY: zeroed rusage is a valid value of a plain C struct; wait4
            // only writes through the two pointers, which outlive the call.
            let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
            let r = unsafe { libc::wait4(pid, &mut status, flags, &mut usage) };
            if r == pid {
                return Ok(Some((status, usage)));
            }
            if r == 0 {
                return Ok(None);
            }
            let err = std::io::Error::last_os_error();
            if err.kind() != std::io::ErrorKind::Interrupted {
                return Err(err).context("wait4 on a child process failed");
            }
        }
    };
    loop {
        if let Some((status, usage)) = reap(libc::WNOHANG)? {
            let code = libc::WIFEXITED(status).then(|| libc::WEXITSTATUS(status));
            // ru_maxrss is in KiB on Linux.
            let rss = u64::try_from(usage.ru_maxrss).ok().map(|k| k * 1024);
            return Ok((code, false, rss));
        }
        if start.elapsed() > timeout {
            let _ = child.kill();
            reap(0)?;
            return Ok((None, true, None));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Portable fallback: no peak memory.
#[cfg(not(unix))]
fn wait_with_timeout(
    child: &mut std::process::Child,
    start: Instant,
    timeout: Duration,
) -> Result<(Option<i32>, bool, Option<u64>)> {
    loop {
        if let Some(st) = child.try_wait()? {
            return Ok((st.code(), false, None));
        }
        if start.elapsed() > timeout {
            let _ = child.kill();
            let _ = child.wait();
            return Ok((None, true, None));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Quotes one word for a POSIX shell, so reproduction commands can be pasted safely.
pub fn shell_quote(s: &str) -> String {
    if !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c))
    {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

/// A command line as one pasteable string.
pub fn shell_line<I: IntoIterator<Item = S>, S: AsRef<str>>(words: I) -> String {
    words
        .into_iter()
        .map(|w| shell_quote(w.as_ref()))
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quoting_neutralizes_shell_syntax() {
        assert_eq!(shell_quote("scenes/a.toml"), "scenes/a.toml");
        assert_eq!(shell_quote("a b"), "'a b'");
        assert_eq!(shell_quote("x'; rm -rf /; '"), r"'x'\''; rm -rf /; '\'''");
        assert_eq!(shell_quote(""), "''");
        assert_eq!(shell_quote("$(id)"), "'$(id)'");
    }

    #[test]
    fn hanging_process_is_killed() {
        let dir = tempfile::tempdir().unwrap();
        let mut cmd = Command::new("sleep");
        cmd.arg("30");
        let o = run_with_timeout(cmd, Duration::from_millis(200), dir.path()).unwrap();
        assert!(o.timed_out && o.code.is_none());
        assert!(o.seconds < 5.0);
    }

    #[test]
    fn output_and_exit_code_are_captured() {
        let dir = tempfile::tempdir().unwrap();
        let mut cmd = Command::new("sh");
        cmd.args(["-c", "echo out; echo err >&2; exit 3"]);
        let o = run_with_timeout(cmd, Duration::from_secs(10), dir.path()).unwrap();
        assert_eq!(o.code, Some(3));
        assert_eq!(o.stdout.trim(), "out");
        assert_eq!(o.stderr_tail(1), "err");
    }

    #[test]
    fn peak_memory_of_the_child_is_measured() {
        let dir = tempfile::tempdir().unwrap();
        // A shell whose child (dd) fills a 64 MiB buffer: the peak covers the grandchild too.
        let mut cmd = Command::new("sh");
        cmd.args([
            "-c",
            "dd if=/dev/zero of=/dev/null bs=64M count=1 2>/dev/null; true",
        ]);
        let big = run_with_timeout(cmd, Duration::from_secs(30), dir.path()).unwrap();
        let mut cmd = Command::new("true");
        cmd.arg("x");
        let small = run_with_timeout(cmd, Duration::from_secs(30), dir.path()).unwrap();
        let (b, s) = (big.max_rss_bytes.unwrap(), small.max_rss_bytes.unwrap());
        assert!(s > 0 && s < 32 << 20, "true: {s} bytes");
        assert!(b >= 32 << 20, "sh running dd bs=64M: {b} bytes");
    }
}
