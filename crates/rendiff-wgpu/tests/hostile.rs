//! Hostile input and interruption, without needing a GPU: special files
//! (FIFOs, devices, folders) and oversized files as scene inputs, special
//! files as the output, and a SIGTERM while the XDG runtime folder exists.
//! Each must give one line naming the file and exit 1 (or, for the signal,
//! leave nothing behind), never hang or read without end. Every child runs
//! under a deadline and an address-space limit, so a regression fails the
//! test instead of hanging it or exhausting the machine's memory.
#![cfg(unix)]

use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

/// Address space a child may use while it handles bad input (no GPU work
/// happens on these paths): enough for the process, far too little for a
/// read of /dev/zero to get anywhere.
const CHILD_ADDRESS_SPACE: u64 = 2 << 30;

/// Longest a child may take to refuse bad input.
const DEADLINE: Duration = Duration::from_secs(30);

fn bin() -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_rendiff-wgpu"));
    cmd.stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    // SAFETY: setrlimit(2) is async-signal-safe and touches only the child.
    unsafe {
        cmd.pre_exec(|| {
            let lim = libc::rlimit {
                rlim_cur: CHILD_ADDRESS_SPACE as libc::rlim_t,
                rlim_max: CHILD_ADDRESS_SPACE as libc::rlim_t,
            };
            libc::setrlimit(libc::RLIMIT_AS, &lim);
            Ok(())
        });
    }
    cmd
}

/// Waits for `child` at most [`DEADLINE`]; kills it and fails the test past it.
fn finish(mut child: Child, what: &str) -> Output {
    let start = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        if start.elapsed() > DEADLINE {
            let _ = child.kill();
            let out = child.wait_with_output().unwrap();
            panic!("{what}: still running after {DEADLINE:?} (hung); {out:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Renders `scene` to `out`, under the deadline.
fn render(scene: &Path, out: &Path) -> Output {
    let child = bin()
        .arg("--scene")
        .arg(scene)
        .arg("--out")
        .arg(out)
        .spawn()
        .unwrap();
    finish(child, &format!("rendiff-wgpu --scene {}", scene.display()))
}

/// The single stderr line of a refused render (exit 1).
fn refused(out: &Output) -> String {
    let s = String::from_utf8_lossy(&out.stderr).to_string();
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    assert_eq!(
        s.trim_end().lines().count(),
        1,
        "exactly one line on stderr, got {s:?}"
    );
    s
}

fn scene_json(triangle_count: u64) -> String {
    format!(
        r#"{{"format": "rendiff-resolved/1", "name": "t",
      "camera": {{"eye": [0, 0, 5], "forward": [0, 0, -1], "right": [1, 0, 0], "up_ortho": [0, 1, 0],
                 "tan_half_vfov": 0.5, "width": 8, "height": 6, "near": 0.001, "far": null}},
      "triangle_count": {triangle_count}, "files": {{"triangles": "triangles.f32", "object_ids": "object_ids.u32"}}}}"#
    )
}

/// A valid scene of one triangle (or of none).
fn write_scene(dir: &Path, triangle_count: u64) {
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("scene.json"), scene_json(triangle_count)).unwrap();
    let tri: Vec<u8> = [-1f32, -1.0, 0.0, 1.0, -1.0, 0.0, 0.0, 1.0, 0.0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .take(36 * triangle_count as usize)
        .collect();
    std::fs::write(dir.join("triangles.f32"), tri).unwrap();
    let ids: Vec<u8> = (0..triangle_count as u32)
        .flat_map(|i| i.to_le_bytes())
        .collect();
    std::fs::write(dir.join("object_ids.u32"), ids).unwrap();
}

fn mkfifo(path: &Path) {
    let _ = std::fs::remove_file(path);
    let status = Command::new("mkfifo").arg(path).status().unwrap();
    assert!(status.success(), "mkfifo {}", path.display());
}

fn is_fifo(path: &Path) -> bool {
    use std::os::unix::fs::FileTypeExt;
    std::fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_fifo())
}

fn dev_zero_link(path: &Path) {
    let _ = std::fs::remove_file(path);
    std::os::unix::fs::symlink("/dev/zero", path).unwrap();
}

#[test]
fn fifo_scene_json_is_refused_without_opening_it() {
    let tmp = tempfile::tempdir().unwrap();
    let s = tmp.path().join("s");
    write_scene(&s, 1);
    mkfifo(&s.join("scene.json"));
    let line = refused(&render(&s, &tmp.path().join("o.exr")));
    assert!(
        line.contains("s/scene.json") && line.contains("FIFO"),
        "{line}"
    );
    assert!(!tmp.path().join("o.exr").exists());
}

#[test]
fn fifo_data_files_of_an_empty_scene_are_refused() {
    for name in ["triangles.f32", "object_ids.u32"] {
        let tmp = tempfile::tempdir().unwrap();
        let s = tmp.path().join("s");
        // No triangles: the expected size (0) is what a FIFO's metadata says.
        write_scene(&s, 0);
        mkfifo(&s.join(name));
        let line = refused(&render(&s, &tmp.path().join("o.exr")));
        assert!(line.contains(name) && line.contains("FIFO"), "{line}");
    }
}

#[test]
fn dev_zero_scene_json_is_refused_without_reading_it() {
    let tmp = tempfile::tempdir().unwrap();
    let s = tmp.path().join("s");
    write_scene(&s, 1);
    dev_zero_link(&s.join("scene.json"));
    let line = refused(&render(&s, &tmp.path().join("o.exr")));
    assert!(
        line.contains("scene.json") && line.contains("character device"),
        "{line}"
    );
}

#[test]
fn dev_zero_data_files_of_an_empty_scene_are_refused() {
    for name in ["triangles.f32", "object_ids.u32"] {
        let tmp = tempfile::tempdir().unwrap();
        let s = tmp.path().join("s");
        write_scene(&s, 0);
        dev_zero_link(&s.join(name));
        let line = refused(&render(&s, &tmp.path().join("o.exr")));
        assert!(
            line.contains(name) && line.contains("character device"),
            "{line}"
        );
    }
}

#[test]
fn folders_as_input_files_are_refused() {
    for name in ["scene.json", "triangles.f32", "object_ids.u32"] {
        let tmp = tempfile::tempdir().unwrap();
        let s = tmp.path().join("s");
        write_scene(&s, 0);
        std::fs::remove_file(s.join(name)).unwrap();
        std::fs::create_dir(s.join(name)).unwrap();
        let line = refused(&render(&s, &tmp.path().join("o.exr")));
        assert!(line.contains(name) && line.contains("folder"), "{line}");
    }
}

#[test]
fn oversized_scene_json_is_refused_before_reading() {
    let tmp = tempfile::tempdir().unwrap();
    let s = tmp.path().join("s");
    write_scene(&s, 1);
    // Sparse: costs no disk, but reading it would take 4 GiB of memory.
    let f = std::fs::File::create(s.join("scene.json")).unwrap();
    f.set_len(4 << 30).unwrap();
    drop(f);
    let line = refused(&render(&s, &tmp.path().join("o.exr")));
    assert!(
        line.contains("scene.json") && line.contains("more than the limit"),
        "{line}"
    );
}

#[test]
fn huge_triangle_count_is_refused_before_reading() {
    let tmp = tempfile::tempdir().unwrap();
    let s = tmp.path().join("s");
    write_scene(&s, 1);
    // A sparse triangles.f32 of exactly the declared size: the count itself
    // must be bounded, or its size would be allocated.
    let n: u64 = 1 << 32;
    std::fs::write(s.join("scene.json"), scene_json(n)).unwrap();
    std::fs::File::create(s.join("triangles.f32"))
        .unwrap()
        .set_len(36 * n)
        .unwrap();
    std::fs::File::create(s.join("object_ids.u32"))
        .unwrap()
        .set_len(4 * n)
        .unwrap();
    let line = refused(&render(&s, &tmp.path().join("o.exr")));
    assert!(
        line.contains("scene.json") && line.contains("triangle_count"),
        "{line}"
    );
}

#[test]
fn special_outputs_are_refused_and_left_alone() {
    let tmp = tempfile::tempdir().unwrap();
    let s = tmp.path().join("s");
    write_scene(&s, 1);

    let fifo = tmp.path().join("fifo.exr");
    mkfifo(&fifo);
    let line = refused(&render(&s, &fifo));
    assert!(line.contains("fifo.exr") && line.contains("FIFO"), "{line}");
    assert!(is_fifo(&fifo), "the FIFO was replaced");

    let folder = tmp.path().join("folder.exr");
    std::fs::create_dir(&folder).unwrap();
    let line = refused(&render(&s, &folder));
    assert!(
        line.contains("folder.exr") && line.contains("folder"),
        "{line}"
    );
    assert!(folder.is_dir());

    // Nothing was left beside them either.
    let names: Vec<String> = std::fs::read_dir(tmp.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .collect();
    assert_eq!(names.len(), 3, "{names:?}");
}

#[test]
fn sigterm_removes_the_xdg_runtime_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let s = tmp.path().join("s");
    write_scene(&s, 1);
    // The folder goes to std::env::temp_dir(), which TMPDIR sets: a folder
    // of this test's own, so nothing else's leftovers count.
    let tmpdir = tmp.path().join("tmp");
    std::fs::create_dir(&tmpdir).unwrap();
    let mut child = bin()
        .env_remove("XDG_RUNTIME_DIR")
        .env("TMPDIR", &tmpdir)
        .arg("--scene")
        .arg(&s)
        .arg("--out")
        .arg(tmp.path().join("o.exr"))
        .arg("--pause-ms")
        .arg("20000")
        .spawn()
        .unwrap();
    let xdg = tmpdir.join(format!("rendiff-wgpu-xdg-{}", child.id()));
    let start = Instant::now();
    while !xdg.is_dir() {
        if start.elapsed() > DEADLINE || child.try_wait().unwrap().is_some() {
            let _ = child.kill();
            panic!(
                "{} never appeared: {:?}",
                xdg.display(),
                child.wait_with_output()
            );
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    // SAFETY: kill(2) on our own child's pid.
    assert_eq!(unsafe { libc::kill(child.id() as i32, libc::SIGTERM) }, 0);
    let out = finish(child, "rendiff-wgpu after SIGTERM");
    assert!(!out.status.success(), "{out:?}");
    let left: Vec<_> = std::fs::read_dir(&tmpdir).unwrap().collect();
    assert!(left.is_empty(), "left behind after SIGTERM: {left:?}");
    assert!(!tmp.path().join("o.exr").exists());
}
