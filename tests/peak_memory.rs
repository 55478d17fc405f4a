//! Peak memory of a render's process (`check::process::run_measured`): the
//! figure is the command's own, never its (large) parent's, it covers the
//! command's children, and a timeout kills the whole process tree.

use rendiff::check::process::{run_measured, run_with_timeout};
use std::path::Path;
use std::process::Command;
use std::time::Duration;

fn helper() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_rendiff"))
}

#[test]
fn peak_is_the_commands_own_and_covers_its_children() {
    // Make this (parent) process large: a child started directly from it would
    // report at least this much, whatever it did itself.
    let ballast = vec![1u8; 256 << 20];
    let dir = tempfile::tempdir().unwrap();
    let small = run_measured(
        Command::new("true"),
        Duration::from_secs(30),
        dir.path(),
        helper(),
    )
    .unwrap();
    let s = small.max_rss_bytes.expect("peak of true");
    assert!(s > 0 && s < 64 << 20, "true: {s} bytes");
    assert_eq!(small.code, Some(0));
    let mut cmd = Command::new("sh");
    cmd.args([
        "-c",
        "dd if=/dev/zero of=/dev/null bs=96M count=1 2>/dev/null; exit 4",
    ]);
    let big = run_measured(cmd, Duration::from_secs(30), dir.path(), helper()).unwrap();
    let b = big.max_rss_bytes.expect("peak of sh running dd");
    assert!(
        (96 << 20..200 << 20).contains(&b),
        "sh running dd bs=96M: {b} bytes"
    );
    assert_eq!(big.code, Some(4), "the exit code passes through");
    let plain =
        run_with_timeout(Command::new("true"), Duration::from_secs(30), dir.path()).unwrap();
    assert_eq!(plain.max_rss_bytes, None, "unmeasured runs report no peak");
    assert_eq!(
        ballast.iter().map(|&x| u64::from(x)).sum::<u64>(),
        256 << 20
    );
}

#[test]
fn timeout_kills_the_measured_process_tree() {
    let dir = tempfile::tempdir().unwrap();
    let pid_file = dir.path().join("pid");
    let mut cmd = Command::new("sh");
    cmd.arg("-c")
        .arg("sleep 30 & echo $! > \"$0\"; wait")
        .arg(&pid_file);
    let o = run_measured(cmd, Duration::from_millis(500), dir.path(), helper()).unwrap();
    assert!(o.timed_out && o.seconds < 10.0);
    let pid = std::fs::read_to_string(&pid_file).unwrap();
    let stat = Path::new("/proc").join(pid.trim()).join("stat");
    // Dead: gone, or a zombie waiting for a reaper (PID 1 of a container may never reap it).
    let gone = (0..50).any(|_| {
        std::thread::sleep(Duration::from_millis(20));
        std::fs::read_to_string(&stat).map_or(true, |s| {
            s.rsplit(')')
                .next()
                .and_then(|r| r.split_whitespace().next())
                == Some("Z")
        })
    });
    assert!(
        gone,
        "the grandchild (sleep {}) outlived the timeout",
        pid.trim()
    );
}
