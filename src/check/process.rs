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
    /// The signal that ended it, when one did.
    pub signal: Option<i32>,
    /// True when it ran past its time limit and was killed.
    pub timed_out: bool,
    /// Captured standard output.
    pub stdout: String,
    /// Captured standard error.
    pub stderr: String,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// Peak resident memory in bytes of the command and the children it waited
    /// for, from [`run_measured`]; `None` otherwise or when it was killed.
    pub max_rss_bytes: Option<u64>,
}

impl Outcome {
    /// How it ended, for messages: "exit 3", "killed by signal 11 (SIGSEGV)", "timed out".
    pub fn how(&self) -> String {
        match (self.code, self.signal) {
            (Some(c), _) => format!("exit {c}"),
            (None, _) if self.timed_out => "timed out and killed".into(),
            (None, Some(s)) => format!("killed by signal {s} ({})", signal_name(s)),
            (None, None) => "killed by a signal".into(),
        }
    }

    /// The last `n` lines of stderr, for error messages.
    pub fn stderr_tail(&self, n: usize) -> String {
        let lines: Vec<&str> = self.stderr.lines().collect();
        lines[lines.len().saturating_sub(n)..].join("\n")
    }
    /// The last `n` non-empty lines of stderr as one line (`|` between
    /// them, control characters escaped): for an error that ends rendiff,
    /// which is one line (a dying harness's traceback made it many).
    pub fn stderr_line(&self, n: usize) -> String {
        let lines: Vec<&str> = self
            .stderr
            .lines()
            .filter(|l| !l.trim().is_empty())
            .collect();
        let tail = lines[lines.len().saturating_sub(n)..].join(" | ");
        crate::scene::printable(&tail, 2000)
    }
}

/// Runs `cmd` with stdin closed and output captured to files in `scratch`
/// (pipes could fill up and deadlock a chatty renderer), in a process group of
/// its own; after `timeout` the whole group is killed, so nothing the command
/// forked outlives it. The group is registered with [`crate::shutdown`], so an
/// interrupted rendiff kills it too.
pub fn run_with_timeout(cmd: Command, timeout: Duration, scratch: &Path) -> Result<Outcome> {
    run(cmd, timeout, scratch)
}

/// Like [`run_with_timeout`], and measures the command's peak memory: it runs
/// under `helper` (the rendiff binary's hidden `peak-rss` command), which
/// starts it from its own small process and reports `wait4`'s max RSS of it
/// and the children it waited for. Started directly from a large process, a
/// child's max RSS would include its parent's resident memory at the moment
/// of the spawn (Linux records the pre-exec image). Like every command here
/// the helper runs in a process group of its own, and a timeout kills the group.
pub fn run_measured(
    cmd: Command,
    timeout: Duration,
    scratch: &Path,
    helper: &Path,
) -> Result<Outcome> {
    std::fs::create_dir_all(scratch)
        .with_context(|| format!("{}: cannot create scratch folder", scratch.display()))?;
    let report = scratch.join("peak_rss.txt");
    let _ = std::fs::remove_file(&report);
    let mut wrapped = Command::new(helper);
    wrapped
        .arg("peak-rss")
        .arg("--report")
        .arg(&report)
        .arg("--")
        .arg(cmd.get_program())
        .args(cmd.get_args());
    if let Some(d) = cmd.get_current_dir() {
        wrapped.current_dir(d);
    }
    for (k, v) in cmd.get_envs() {
        match v {
            Some(v) => wrapped.env(k, v),
            None => wrapped.env_remove(k),
        };
    }
    let mut o = run(wrapped, timeout, scratch)?;
    o.max_rss_bytes = std::fs::read_to_string(&report)
        .ok()
        .and_then(|t| t.trim().parse::<u64>().ok());
    Ok(o)
}

fn run(cmd: Command, timeout: Duration, scratch: &Path) -> Result<Outcome> {
    let started = Started::spawn(cmd, scratch, Stdio::null())?;
    let from = started.start;
    started.wait(timeout, from)
}

/// A child started in a process group of its own, registered with
/// [`crate::shutdown`], its output going to files in its scratch folder.
struct Started {
    child: std::process::Child,
    group: crate::shutdown::GroupGuard,
    start: Instant,
    out_path: std::path::PathBuf,
    err_path: std::path::PathBuf,
}

impl Started {
    fn spawn(mut cmd: Command, scratch: &Path, stdin: Stdio) -> Result<Self> {
        std::fs::create_dir_all(scratch)
            .with_context(|| format!("{}: cannot create scratch folder", scratch.display()))?;
        let out_path = scratch.join("stdout.txt");
        let err_path = scratch.join("stderr.txt");
        let out = std::fs::File::create(&out_path)?;
        let err = std::fs::File::create(&err_path)?;
        #[cfg(unix)]
        {
            use std::os::unix::process::CommandExt;
            cmd.process_group(0);
        }
        crate::shutdown::die_with_parent(&mut cmd);
        let start = Instant::now();
        let child = cmd
            .stdin(stdin)
            .stdout(Stdio::from(out))
            .stderr(Stdio::from(err))
            .spawn()
            .with_context(|| format!("cannot start {:?}", cmd.get_program()))?;
        let group = crate::shutdown::track_group(child.id());
        Ok(Started {
            child,
            group,
            start,
            out_path,
            err_path,
        })
    }

    /// Waits until the child exits, or kills its group once `timeout` has
    /// passed since `from`.
    fn wait(mut self, timeout: Duration, from: Instant) -> Result<Outcome> {
        let child = &mut self.child;
        let mut timed_out = false;
        let status = loop {
            if let Some(st) = child.try_wait()? {
                break Some(st);
            }
            if from.elapsed() > timeout {
                timed_out = true;
                crate::shutdown::kill_group(child.id() as i32);
                let _ = child.kill();
                let _ = child.wait();
                break None;
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        // The leader is reaped; kill what it may have left in its group (a forked
        // child that outlived a clean exit) before the group id can be reused.
        crate::shutdown::kill_group(child.id() as i32);
        drop(self.group);
        crate::shutdown::hold_if_interrupted();
        let read = |p: &Path| {
            std::fs::read(p)
                .map(|b| String::from_utf8_lossy(&b).into_owned())
                .unwrap_or_default()
        };
        #[cfg(unix)]
        let signal = {
            use std::os::unix::process::ExitStatusExt;
            status.and_then(|s| s.signal())
        };
        #[cfg(not(unix))]
        let signal = None;
        Ok(Outcome {
            code: status.and_then(|s| s.code()),
            signal,
            timed_out,
            stdout: read(&self.out_path),
            stderr: read(&self.err_path),
            seconds: self.start.elapsed().as_secs_f64(),
            max_rss_bytes: None,
        })
    }
}

/// A command fed lines on its stdin while it runs, as [`run_with_timeout`]
/// runs one otherwise (process group, output to files, killed with rendiff):
/// `check` hands the comparison each scene as soon as its renders are in, so
/// judging overlaps rendering. A thread of its own writes the lines, so a
/// child that stops reading never blocks the sender; dropped unfinished (an
/// error on the way), the child's group is killed.
pub struct Fed {
    started: Option<Started>,
    lines: Option<std::sync::mpsc::Sender<String>>,
    writer: Option<std::thread::JoinHandle<()>>,
}

impl Fed {
    /// Starts `cmd` with its stdin a pipe; output goes to `scratch`.
    pub fn spawn(cmd: Command, scratch: &Path) -> Result<Fed> {
        let mut started = Started::spawn(cmd, scratch, Stdio::piped())?;
        let mut stdin = started.child.stdin.take().context("no stdin pipe")?;
        let (tx, rx) = std::sync::mpsc::channel::<String>();
        let writer = std::thread::spawn(move || {
            use std::io::Write;
            for line in rx {
                // A child that exited or closed its stdin reads no more: what
                // it did is its outcome, told by `finish`.
                if stdin.write_all(line.as_bytes()).is_err() {
                    break;
                }
            }
        });
        Ok(Fed {
            started: Some(started),
            lines: Some(tx),
            writer: Some(writer),
        })
    }

    /// Queues one line (a newline is added); never blocks.
    pub fn send(&self, mut line: String) {
        line.push('\n');
        if let Some(tx) = &self.lines {
            let _ = tx.send(line);
        }
    }

    /// Closes the child's stdin once every queued line is written, then
    /// waits for it; `timeout` counts from here.
    pub fn finish(mut self, timeout: Duration) -> Result<Outcome> {
        let from = Instant::now();
        drop(self.lines.take());
        let started = self.started.take().context("already finished")?;
        let outcome = started.wait(timeout, from);
        if let Some(w) = self.writer.take() {
            let _ = w.join();
        }
        outcome
    }
}

impl Drop for Fed {
    fn drop(&mut self) {
        drop(self.lines.take());
        if let Some(mut s) = self.started.take() {
            crate::shutdown::kill_group(s.child.id() as i32);
            let _ = s.child.kill();
            let _ = s.child.wait();
        }
        if let Some(w) = self.writer.take() {
            let _ = w.join();
        }
    }
}

/// The usual name of a POSIX signal number, or "unknown signal".
pub fn signal_name(sig: i32) -> &'static str {
    match sig {
        1 => "SIGHUP",
        2 => "SIGINT",
        3 => "SIGQUIT",
        4 => "SIGILL",
        6 => "SIGABRT",
        7 => "SIGBUS",
        8 => "SIGFPE",
        9 => "SIGKILL",
        11 => "SIGSEGV",
        13 => "SIGPIPE",
        15 => "SIGTERM",
        _ => "unknown signal",
    }
}

/// The hidden `rendiff peak-rss --report FILE -- PROGRAM ARGS...`: runs the
/// program (stdio, environment and folder inherited), waits for it with
/// `wait4`, writes its max RSS in bytes to FILE, and returns its exit code
/// (128 + the signal when a signal ended it).
#[cfg(unix)]
pub fn peak_rss_main(report: &Path, argv: &[std::ffi::OsString]) -> Result<i32> {
    let (prog, args) = argv.split_first().context("peak-rss: no command given")?;
    let child = Command::new(prog)
        .args(args)
        .spawn()
        .with_context(|| format!("peak-rss: cannot start {prog:?}"))?;
    let pid = child.id() as libc::pid_t;
    let (status, usage) = loop {
        let mut status: libc::c_int = 0;
        // SAFETY: a zeroed rusage is a valid plain C struct (integers only).
        let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
        // SAFETY: wait4 writes only through the two pointers, which point to
        // locals that outlive the call.
        let r = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
        if r == pid {
            break (status, usage);
        }
        let e = std::io::Error::last_os_error();
        if e.kind() != std::io::ErrorKind::Interrupted {
            return Err(e).context("peak-rss: wait4 failed");
        }
    };
    // ru_maxrss is in KiB on Linux.
    let bytes = u64::try_from(usage.ru_maxrss).unwrap_or(0) * 1024;
    std::fs::write(report, format!("{bytes}\n"))
        .with_context(|| format!("{}: cannot write the peak", report.display()))?;
    Ok(if libc::WIFEXITED(status) {
        libc::WEXITSTATUS(status)
    } else {
        128 + libc::WTERMSIG(status)
    })
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

/// `text` for the terminal, line by line ([`crate::scene::printable`] on
/// each, at most [`PRINTABLE_LINE_CHARS`] characters a line): the lines an
/// error has stay lines, every other control character (a terminal escape
/// in a file name or a renderer's stderr) is written as an escape.
pub fn printable_lines(text: &str) -> String {
    text.split('\n')
        .map(|l| crate::scene::printable(l, PRINTABLE_LINE_CHARS))
        .collect::<Vec<_>>()
        .join("\n")
}

/// Most characters of one line of an error (see [`printable_lines`]).
pub const PRINTABLE_LINE_CHARS: usize = 4000;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_traceback_becomes_one_escaped_line() {
        let o = Outcome {
            code: Some(1),
            signal: None,
            timed_out: false,
            stdout: String::new(),
            stderr: "Traceback (most recent call last):\n  File \"x\"\n\nBrokenProcessPool: \u{1b}[31mdied\n".into(),
            seconds: 0.0,
            max_rss_bytes: None,
        };
        let line = o.stderr_line(2);
        assert_eq!(line, "  File \"x\" | BrokenProcessPool: \\u{1b}[31mdied");
        assert!(!line.contains('\n') && !line.contains('\u{1b}'));
    }

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
    fn fed_lines_reach_the_child_in_order() {
        let dir = tempfile::tempdir().unwrap();
        let fed = Fed::spawn(Command::new("cat"), dir.path()).unwrap();
        for k in 0..1000 {
            fed.send(format!("line {k}"));
        }
        let o = fed.finish(Duration::from_secs(20)).unwrap();
        assert_eq!(o.code, Some(0));
        let want: Vec<String> = (0..1000).map(|k| format!("line {k}")).collect();
        assert_eq!(o.stdout.lines().collect::<Vec<_>>(), want);
    }

    #[test]
    fn a_fed_child_that_stops_reading_blocks_no_one_and_is_killed() {
        let dir = tempfile::tempdir().unwrap();
        let mut cmd = Command::new("sleep");
        cmd.arg("30");
        let fed = Fed::spawn(cmd, dir.path()).unwrap();
        let start = Instant::now();
        // Far more than a pipe holds: sending must not wait for the child.
        for _ in 0..64 {
            fed.send("x".repeat(64 << 10));
        }
        assert!(start.elapsed() < Duration::from_secs(2));
        let o = fed.finish(Duration::from_millis(200)).unwrap();
        assert!(o.timed_out && o.code.is_none());
        assert!(start.elapsed() < Duration::from_secs(10));
    }

    #[test]
    fn a_fed_child_dropped_unfinished_is_killed() {
        let dir = tempfile::tempdir().unwrap();
        let pid_file = dir.path().join("pid");
        let mut cmd = Command::new("sh");
        cmd.args(["-c", "echo $$ > \"$0\"; exec sleep 30"])
            .arg(&pid_file);
        let fed = Fed::spawn(cmd, dir.path()).unwrap();
        let start = Instant::now();
        while !pid_file.exists() && start.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(10));
        }
        drop(fed);
        let pid = std::fs::read_to_string(&pid_file).unwrap();
        // Reaped by the drop: no process of that id is left (not even a zombie).
        assert!(!Path::new(&format!("/proc/{}", pid.trim())).exists());
    }
}
