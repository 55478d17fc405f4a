//! Long-lived harness workers (`python -m rendiff_harness serve`): one
//! process renders many scenes, so Python's start-up and a backend's imports
//! (0.3–1 s per render, most of a small scene's cost) are paid once per
//! worker instead of once per render.
//!
//! A request is the argument vector of a one-shot `rendiff_harness render`;
//! the reply is what that process would have exited with and printed
//! (harness `worker.py` states the protocol). So [`Worker::request`] returns
//! the same [`Outcome`] as [`super::process::run_with_timeout`], and callers
//! judge both alike. Fault isolation is kept: a render that runs past its
//! limit kills the worker's whole process group, a crash ends the worker, and
//! either way the next request starts a fresh one ([`Slot`]).

use super::process::Outcome;
use anyhow::{Context, Result};
use std::collections::HashMap;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

/// The reply line of `worker.py`.
#[derive(serde::Deserialize)]
struct Reply {
    code: i32,
    stdout: String,
    stderr: String,
}

/// One running `serve` process, in a process group of its own.
pub struct Worker {
    child: Child,
    stdin: Option<ChildStdin>,
    replies: Receiver<String>,
    stderr_path: PathBuf,
    _group: crate::shutdown::GroupGuard,
}

impl Worker {
    /// Starts `cmd` (the harness command with `serve` appended by the
    /// caller); its stderr goes to `scratch/worker-stderr.txt`, whose tail
    /// explains a worker that died.
    pub fn start(mut cmd: Command, scratch: &Path) -> Result<Worker> {
        std::fs::create_dir_all(scratch)
            .with_context(|| format!("{}: cannot create scratch folder", scratch.display()))?;
        let stderr_path = scratch.join("worker-stderr.txt");
        let err = std::fs::File::create(&stderr_path)
            .with_context(|| format!("{}: cannot create", stderr_path.display()))?;
        #[cfg(unix)]
        {
            use std::os::unix::process::CommandExt;
            cmd.process_group(0);
        }
        crate::shutdown::die_with_parent(&mut cmd);
        let mut child = cmd
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::from(err))
            .spawn()
            .with_context(|| format!("cannot start the harness worker {:?}", cmd.get_program()))?;
        let group = crate::shutdown::track_group(child.id());
        let stdout = child.stdout.take().context("worker stdout")?;
        let (tx, replies) = std::sync::mpsc::channel();
        // A reader thread, so that a reply can be awaited with a deadline; it
        // ends when the worker's stdout closes (the worker exited or was killed).
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Ok(Worker {
            stdin: child.stdin.take(),
            child,
            replies,
            stderr_path,
            _group: group,
        })
    }

    /// Sends one request and waits at most `limit` for its reply. The second
    /// value is false when the worker is gone (timed out and killed, or died)
    /// and must not be used again.
    pub fn request(&mut self, argv: &[String], limit: Duration) -> (Outcome, bool) {
        let start = Instant::now();
        let line = serde_json::json!({ "argv": argv }).to_string();
        let sent = self
            .stdin
            .as_mut()
            .map(|w| writeln!(w, "{line}").and_then(|_| w.flush()).is_ok())
            .unwrap_or(false);
        let got = if sent {
            self.replies.recv_timeout(limit)
        } else {
            Err(RecvTimeoutError::Disconnected)
        };
        let mut outcome = Outcome {
            code: None,
            signal: None,
            timed_out: false,
            stdout: String::new(),
            stderr: String::new(),
            seconds: 0.0,
            max_rss_bytes: None,
        };
        let alive = match got {
            Ok(text) => match serde_json::from_str::<Reply>(&text) {
                Ok(r) => {
                    outcome.code = Some(r.code);
                    outcome.stdout = r.stdout;
                    outcome.stderr = r.stderr;
                    true
                }
                Err(e) => {
                    outcome.code = Some(1);
                    outcome.stderr =
                        format!("unreadable reply from the harness worker ({e}): {text}");
                    self.stop();
                    false
                }
            },
            Err(RecvTimeoutError::Timeout) => {
                outcome.timed_out = true;
                self.stop();
                false
            }
            Err(RecvTimeoutError::Disconnected) => {
                // The worker died mid-render: report it as the one-shot process's death.
                let status = self.stop();
                #[cfg(unix)]
                {
                    use std::os::unix::process::ExitStatusExt;
                    outcome.signal = status.and_then(|s| s.signal());
                }
                outcome.code = status.and_then(|s| s.code());
                outcome.stderr = std::fs::read(&self.stderr_path)
                    .map(|b| String::from_utf8_lossy(&b).into_owned())
                    .unwrap_or_default();
                false
            }
        };
        crate::shutdown::hold_if_interrupted();
        outcome.seconds = start.elapsed().as_secs_f64();
        (outcome, alive)
    }

    /// Kills the worker's group and reaps it; returns how it ended.
    fn stop(&mut self) -> Option<std::process::ExitStatus> {
        self.stdin = None;
        crate::shutdown::kill_group(self.child.id() as i32);
        let _ = self.child.kill();
        self.child.wait().ok()
    }

    /// Asks the worker to finish (stdin closed) and waits a moment before
    /// killing it: the normal end of a run.
    fn finish(&mut self) {
        self.stdin = None;
        let deadline = Instant::now() + Duration::from_secs(5);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.child.try_wait() {
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        self.stop();
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.finish();
    }
}

/// The workers of one job slot, one per backend, started on first use and
/// replaced after a worker is lost.
pub struct Slot {
    workers: HashMap<String, Worker>,
    scratch: PathBuf,
}

impl Slot {
    /// A slot whose workers keep their stderr under `scratch`.
    pub fn new(scratch: PathBuf) -> Self {
        Self {
            workers: HashMap::new(),
            scratch,
        }
    }

    /// Runs one render request on this slot's worker for `backend`, starting
    /// it with `start()` if there is none.
    pub fn request(
        &mut self,
        backend: &str,
        start: impl FnOnce() -> Command,
        argv: &[String],
        limit: Duration,
    ) -> Result<Outcome> {
        if !self.workers.contains_key(backend) {
            let w = Worker::start(start(), &self.scratch.join(backend))?;
            self.workers.insert(backend.to_string(), w);
        }
        let w = self.workers.get_mut(backend).expect("inserted above");
        let (outcome, alive) = w.request(argv, limit);
        if !alive {
            self.workers.remove(backend);
        }
        Ok(outcome)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stand-in worker in shell: answers "ok" to every request, sleeps on
    /// one that mentions "hang", exits on one that mentions "die".
    fn fake() -> Command {
        let mut c = Command::new("sh");
        c.arg("-c").arg(
            r#"while read -r line; do
                 case "$line" in
                   *hang*) sleep 30 ;;
                   *die*) echo "dying now" >&2; kill -SEGV $$ ;;
                   *) printf '%s\n' '{"code": 0, "stdout": "done\n", "stderr": ""}' ;;
                 esac
               done"#,
        );
        c
    }

    fn argv(word: &str) -> Vec<String> {
        vec!["render".into(), word.into()]
    }

    #[test]
    fn one_worker_answers_many_requests() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = Worker::start(fake(), dir.path()).unwrap();
        let pid = w.child.id();
        for _ in 0..3 {
            let (o, alive) = w.request(&argv("x"), Duration::from_secs(10));
            assert!(alive);
            assert_eq!((o.code, o.stdout.as_str()), (Some(0), "done\n"));
        }
        assert_eq!(w.child.id(), pid);
    }

    #[test]
    fn a_hung_render_kills_the_worker_and_the_slot_starts_another() {
        let dir = tempfile::tempdir().unwrap();
        let mut slot = Slot::new(dir.path().to_path_buf());
        let t = Instant::now();
        let o = slot
            .request("b", fake, &argv("hang"), Duration::from_millis(300))
            .unwrap();
        assert!(o.timed_out && o.code.is_none(), "{o:?}");
        assert!(t.elapsed() < Duration::from_secs(10));
        assert!(slot.workers.is_empty(), "a timed-out worker is not reused");
        let o = slot
            .request("b", fake, &argv("x"), Duration::from_secs(10))
            .unwrap();
        assert_eq!(o.code, Some(0), "a fresh worker answers the next request");
    }

    #[test]
    fn a_crashed_worker_is_reported_like_a_crashed_process() {
        let dir = tempfile::tempdir().unwrap();
        let mut slot = Slot::new(dir.path().to_path_buf());
        let o = slot
            .request("b", fake, &argv("die"), Duration::from_secs(10))
            .unwrap();
        assert_eq!(o.code, None);
        assert_eq!(o.signal, Some(libc::SIGSEGV), "{o:?}");
        assert!(o.stderr.contains("dying now"), "{o:?}");
        assert!(o.how().contains("SIGSEGV"));
        let o = slot
            .request("b", fake, &argv("x"), Duration::from_secs(10))
            .unwrap();
        assert_eq!(o.code, Some(0));
    }
}
