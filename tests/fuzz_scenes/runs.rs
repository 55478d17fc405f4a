//! Tampered run folders (issue 40 item 8): a finished run of two tiny
//! scenes (the core's tracer against the raster) and the two shard runs of
//! the same check are made once; each case copies them, tampers with one
//! (results.json or manifest.json truncated, emptied, garbled, linked out
//! of the run, deleted; statuses, counts and names changed, negative or
//! huge numbers, entries removed or doubled, control characters and path
//! separators in names; the resolved scene or its recorded hash changed;
//! EXR buffers deleted, truncated, swapped or replaced by a FIFO, a folder
//! or a link; an INCOMPLETE marker added) and runs `gate` (against a
//! baseline blessed from the untouched run), `bless` (over a copy of that
//! baseline), `report` and `merge` on it. Each tamper says, per command,
//! whether it must be refused (exit 2, one line naming the file), must not
//! succeed, or may do either (a change the command does not read, or one
//! no record can tell from a real run). No command may panic, hang, print
//! a raw control character, write outside its run folder or its baseline,
//! leave half a baseline, or print PASS (gate exit 0) where it must not.

use super::*;
use serde_json::{json, Value};

/// What one command must do with a tampered run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Must {
    /// Exit 2 with one line naming the tampered file.
    Refuse,
    /// Anything but exit 0 (a refusal, or failing verdicts).
    NotSucceed,
    /// A refusal, or (report only) a report whose banner says "No verdicts"
    /// (the report shows the renders of a run whose results.json cannot be
    /// read, without verdicts: docs/run-format.md).
    Banner,
    /// Either.
    Any,
}
use Must::{Any as A, Banner as B, NotSucceed as N, Refuse as R};

/// Which runs a tamper is applied to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Target {
    /// The whole run: gate, bless and report run on it.
    Full,
    /// Shard 1 of the split: merge runs on it and shard 2.
    Shard,
}

/// A tamper: its name, the file it names (a refusal must mention it),
/// what gate, bless, report and merge must do, and the change.
struct Tamper {
    name: &'static str,
    file: &'static str,
    must: [Must; 4],
    apply: fn(&Path, u64, u64),
}

const COMMANDS: [&str; 4] = ["gate", "bless", "report", "merge"];

/// One row of [`TAMPERS`].
const fn tamper(
    target: Target,
    name: &'static str,
    file: &'static str,
    must: [Must; 4],
    apply: fn(&Path, u64, u64),
) -> (Target, Tamper) {
    (
        target,
        Tamper {
            name,
            file,
            must,
            apply,
        },
    )
}
use Target::{Full, Shard};

/// Rewrites the file at `path` with `f`'s change to its bytes.
fn edit_bytes(path: &Path, f: impl FnOnce(&mut Vec<u8>)) {
    let mut b = std::fs::read(path).unwrap();
    f(&mut b);
    std::fs::write(path, b).unwrap();
}

/// The run's `file` replaced by a link to a copy of it beside the run.
fn link_out(run: &Path, file: &str) {
    let p = run.join(file);
    let out = run.parent().unwrap().join(format!("outside-{file}"));
    std::fs::copy(&p, &out).unwrap();
    replace_with_link(&p, &out);
}

/// The run's `file` replaced by a FIFO (`a` even) or a folder.
fn fifo_or_dir(p: &Path, a: u64) {
    std::fs::remove_file(p).unwrap();
    if a.is_multiple_of(2) {
        mkfifo(p);
    } else {
        std::fs::create_dir(p).unwrap();
    }
}

/// EXR file `p` spoiled in way `k` of four: deleted, cut in half,
/// replaced by a FIFO or by a link to `/dev/zero`.
fn spoil_exr(p: &Path, k: u64) {
    match k {
        0 => std::fs::remove_file(p).unwrap(),
        1 => edit_bytes(p, |b| b.truncate(b.len() / 2)),
        2 => fifo_or_dir(p, 0),
        _ => replace_with_link(p, Path::new("/dev/zero")),
    }
}

fn edit_json(path: &Path, f: impl FnOnce(&mut Value)) {
    let mut v: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    f(&mut v);
    std::fs::write(path, v.to_string()).unwrap();
}

/// Entry `a` (modulo their number) of results.json.
fn entry(v: &mut Value, a: u64) -> &mut Value {
    let list = v["results"].as_array_mut().unwrap();
    let n = list.len() as u64;
    &mut list[(a % n) as usize]
}

/// The run's scene folders, and one of them (by `a`).
fn scene_dir(run: &Path, a: u64) -> PathBuf {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(run.join("scenes"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .collect();
    dirs.sort();
    dirs[(a % dirs.len() as u64) as usize].clone()
}

/// The EXR files of the run, and one of them (by `a`).
fn exr(run: &Path, a: u64) -> PathBuf {
    let mut all: Vec<PathBuf> = files_under(&run.join("scenes"))
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e == "exr"))
        .collect();
    all.sort();
    all[(a % all.len() as u64) as usize].clone()
}

fn replace_with_link(path: &Path, to: &Path) {
    std::fs::remove_file(path).unwrap();
    std::os::unix::fs::symlink(to, path).unwrap();
}

const COUNT_FIELDS: &[&str] = &[
    "pixels",
    "compared_pixels",
    "edge_mismatches",
    "tie_mismatches",
    "crack_mismatches",
    "interior_mismatches",
    "mask_mismatches",
];

/// Every tamper. `must` is [gate, bless, report, merge]; a tamper of the
/// whole run has merge Any (merge reads shards), a tamper of a shard has
/// the others Any (they read the whole run, untouched).
const TAMPERS: &[(Target, Tamper)] = &[
    tamper(
        Full,
        "results.json truncated",
        "results.json",
        [R, R, B, A],
        |run, a, _| {
            edit_bytes(&run.join("results.json"), |b| {
                b.truncate(1 + (a as usize % (b.len() - 2)))
            });
        },
    ),
    tamper(
        Full,
        "results.json emptied or not an object",
        "results.json",
        [R, R, B, A],
        |run, a, _| {
            let t = [
                "",
                "null",
                "[]",
                "{}",
                "\"results\"",
                "{\"format\": \"rendiff-results/1\"}",
                "\u{feff}{}",
            ][(a % 7) as usize];
            std::fs::write(run.join("results.json"), t).unwrap();
        },
    ),
    tamper(
        Full,
        "results.json not UTF-8",
        "results.json",
        [R, R, B, A],
        |run, _, _| {
            edit_bytes(&run.join("results.json"), |b| b.insert(1, 0xff));
        },
    ),
    tamper(
        Full,
        "results.json a link to a copy outside the run",
        "results.json",
        [R, R, R, R],
        |run, _, _| {
            link_out(run, "results.json");
        },
    ),
    tamper(
        Full,
        "results.json a FIFO or a folder",
        "results.json",
        [R, R, B, A],
        |run, a, _| {
            fifo_or_dir(&run.join("results.json"), a);
        },
    ),
    tamper(
        Full,
        "results.json deleted",
        "results.json",
        [R, R, B, A],
        |run, _, _| {
            std::fs::remove_file(run.join("results.json")).unwrap();
        },
    ),
    tamper(
        Full,
        "results.json a random byte changed",
        "results.json",
        [A, A, A, A],
        |run, a, b| {
            edit_bytes(&run.join("results.json"), |bytes| {
                let n = bytes.len();
                bytes[a as usize % n] = b as u8;
            });
        },
    ),
    tamper(
        Full,
        "a verdict's status made fail",
        "results.json",
        [N, N, A, A],
        |run, a, _| {
            edit_json(&run.join("results.json"), |v| {
                entry(v, a)["status"] = json!("fail")
            });
        },
    ),
    tamper(
        Full,
        "a verdict's status unknown or not a string",
        "results.json",
        [R, R, A, A],
        |run, a, b| {
            let s = [
                json!("passs"),
                json!("PASS"),
                json!(1),
                json!(null),
                json!(["pass"]),
                json!(""),
            ][(b % 6) as usize]
                .clone();
            edit_json(&run.join("results.json"), |v| entry(v, a)["status"] = s);
        },
    ),
    tamper(
        Full,
        "a passing verdict given mismatches",
        "results.json",
        [N, A, A, A],
        |run, a, b| {
            let f = COUNT_FIELDS[2 + (b % 5) as usize];
            edit_json(&run.join("results.json"), |v| {
                let e = entry(v, a);
                e[f] = json!(7);
                e["max_abs_error"] = json!(0.5);
            });
        },
    ),
    tamper(
        Full,
        "a count negative, fractional or not a number",
        "results.json",
        [R, R, A, A],
        |run, a, b| {
            let f = COUNT_FIELDS[(b % 7) as usize];
            let x = [
                json!(-1),
                json!(-9223372036854775808i64),
                json!(2.5),
                json!("3"),
                json!(true),
                json!(-0.5),
            ][(b / 7 % 6) as usize]
                .clone();
            edit_json(&run.join("results.json"), |v| entry(v, a)[f] = x);
        },
    ),
    tamper(
        Full,
        "an error number negative or not a number",
        "results.json",
        [R, R, A, A],
        |run, a, b| {
            let x = [json!(-1.0), json!(-1e-300), json!("0"), json!([0])][(b % 4) as usize].clone();
            edit_json(&run.join("results.json"), |v| {
                entry(v, a)["max_abs_error"] = x
            });
        },
    ),
    tamper(
        Full,
        "a number huge",
        "results.json",
        [N, A, A, A],
        |run, a, b| {
            // The gate holds the errors of the Z buffer only (ERROR_BUFFER).
            edit_json(&run.join("results.json"), |v| {
                if b % 2 == 0 {
                    let list = v["results"].as_array_mut().unwrap();
                    let z: Vec<usize> = (0..list.len())
                        .filter(|i| list[*i]["buffer"] == "Z")
                        .collect();
                    list[z[(a % z.len() as u64) as usize]]["max_abs_error"] = json!(1e308);
                } else {
                    entry(v, a)["interior_mismatches"] = json!(u64::MAX);
                }
            });
        },
    ),
    tamper(
        Full,
        "an entry removed",
        "would be dropped",
        [N, R, A, A],
        |run, a, _| {
            edit_json(&run.join("results.json"), |v| {
                let list = v["results"].as_array_mut().unwrap();
                let n = list.len() as u64;
                list.remove((a % n) as usize);
            });
        },
    ),
    tamper(
        Full,
        "an entry doubled",
        "results.json",
        [R, R, A, A],
        |run, a, _| {
            edit_json(&run.join("results.json"), |v| {
                let e = entry(v, a).clone();
                v["results"].as_array_mut().unwrap().push(e);
            });
        },
    ),
    tamper(
        Full,
        "results.json of another format",
        "results.json",
        [R, R, A, A],
        |run, a, _| {
            let f = ["rendiff-results/2", "", "rendiff-manifest/1"][(a % 3) as usize];
            edit_json(&run.join("results.json"), |v| v["format"] = json!(f));
        },
    ),
    tamper(
        Full,
        "control characters and path separators in names",
        "results.json",
        [A, A, A, A],
        |run, a, b| {
            let s = [
                "\u{1b}[31mred\u{7}",
                "../../escaped",
                "/etc/x",
                "a\nb",
                "nul\u{0}x",
                "\u{202e}rtl",
                "..",
                "x/../../y",
                "<script>",
                "a|b",
            ][(b % 10) as usize];
            let f = ["scene", "backend", "buffer", "reason"][(b / 10 % 4) as usize];
            edit_json(&run.join("results.json"), |v| entry(v, a)[f] = json!(s));
        },
    ),
    tamper(
        Full,
        "an INCOMPLETE marker added",
        "incomplete run",
        [R, R, R, A],
        |run, _, _| {
            std::fs::write(run.join("INCOMPLETE"), "check started by process 1\n").unwrap();
        },
    ),
    tamper(
        Full,
        "manifest.json truncated or garbled",
        "manifest.json",
        [R, R, R, A],
        |run, a, _| {
            edit_bytes(&run.join("manifest.json"), |b| match a % 3 {
                0 => b.truncate(1 + (a as usize / 3 % (b.len() - 2))),
                1 => *b = b"null".to_vec(),
                _ => b.insert(0, 0xff),
            });
        },
    ),
    tamper(
        Full,
        "manifest.json a link out of the run",
        "manifest.json",
        [R, R, R, A],
        |run, _, _| {
            link_out(run, "manifest.json");
        },
    ),
    tamper(
        Full,
        "manifest.json deleted",
        "manifest.json",
        [A, A, A, A],
        |run, _, _| {
            std::fs::remove_file(run.join("manifest.json")).unwrap();
        },
    ),
    tamper(
        Full,
        "manifest.json control characters in names and versions",
        "manifest.json",
        [A, A, A, A],
        |run, a, b| {
            let s = ["\u{1b}[31mred\u{7}", "a\nb", "nul\u{0}x", "<b>x</b>"][(b % 4) as usize];
            edit_json(&run.join("manifest.json"), |v| {
                let scenes = v["scenes"].as_array_mut().unwrap();
                let n = scenes.len() as u64;
                let sc = &mut scenes[(a % n) as usize];
                match b / 4 % 3 {
                    0 => sc["renders"][0]["version"] = json!(s),
                    1 => sc["scene_file"] = json!(s),
                    _ => sc["renders"][0]["reason"] = json!(s),
                }
            });
        },
    ),
    tamper(
        Full,
        "an EXR deleted, truncated or replaced",
        ".exr",
        [A, A, A, A],
        |run, a, b| {
            let p = exr(run, a);
            match b % 5 {
                4 => fifo_or_dir(&p, 1),
                k => spoil_exr(&p, k),
            }
        },
    ),
    // ---- the shard: merge re-judges its renders
    tamper(
        Shard,
        "shard manifest.json truncated, garbled or deleted",
        "manifest.json",
        [A, A, A, R],
        |run, a, _| {
            let p = run.join("manifest.json");
            match a % 4 {
                0 => edit_bytes(&p, |b| b.truncate(1 + (a as usize / 4 % (b.len() - 2)))),
                1 => std::fs::write(&p, b"{}").unwrap(),
                2 => edit_bytes(&p, |b| b.insert(0, 0xff)),
                _ => std::fs::remove_file(&p).unwrap(),
            }
        },
    ),
    tamper(
        Shard,
        "shard manifest.json a link out of the run",
        "manifest.json",
        [A, A, A, R],
        |run, _, _| {
            link_out(run, "manifest.json");
        },
    ),
    tamper(
        Shard,
        "shard's recorded resolved scene hash changed",
        "manifest.json",
        [A, A, A, R],
        |run, a, _| {
            let h = [
                "sha256:0000000000000000000000000000000000000000000000000000000000000000",
                "",
                "sha256:",
                "md5:x",
            ][(a % 4) as usize];
            edit_json(&run.join("manifest.json"), |v| {
                v["scenes"][0]["resolved_sha256"] = json!(h)
            });
        },
    ),
    tamper(
        Shard,
        "shard's resolved scene changed",
        "manifest.json",
        [A, A, A, R],
        |run, a, _| {
            edit_bytes(&scene_dir(run, 0).join("resolved/triangles.f32"), |b| {
                let n = b.len();
                b[a as usize % n] ^= 0x40;
            });
        },
    ),
    tamper(
        Shard,
        "shard manifest numbers negative or of the wrong type",
        "manifest.json",
        [A, A, A, R],
        |run, a, _| {
            edit_json(&run.join("manifest.json"), |v| match a % 4 {
                0 => v["created_unix"] = json!(-1),
                1 => v["shard"]["index"] = json!(-1),
                2 => v["shard"]["total"] = json!("2"),
                _ => v["scenes"] = json!({}),
            });
        },
    ),
    tamper(
        Shard,
        "shard scene name leaves the run",
        "manifest.json",
        [A, A, A, R],
        |run, a, _| {
            let s = ["../x", "/etc", "", "..", "a/b", "\u{1b}[2J"][(a % 6) as usize];
            edit_json(&run.join("manifest.json"), |v| {
                v["scenes"][0]["scene"] = json!(s)
            });
        },
    ),
    tamper(
        Shard,
        "shard EXR deleted, truncated, garbled or special",
        ".exr",
        [A, A, A, N],
        |run, a, b| {
            // The renders' (not the raster reference's, which merge also reads).
            let p = exr(run, a);
            match b % 5 {
                4 => edit_bytes(&p, |bytes| {
                    let n = bytes.len();
                    for k in (n / 2..n).step_by(7) {
                        bytes[k] ^= 0x5a;
                    }
                }),
                k => spoil_exr(&p, k),
            }
        },
    ),
    tamper(
        Shard,
        "shard EXR replaced by another scene's",
        ".exr",
        [A, A, A, N],
        |run, _, _| {
            // Shard 1 holds one scene; shard 2's (another size) is beside it.
            let p = scene_dir(run, 0).join("trace.exr");
            let other = run.parent().unwrap().join("s2");
            let q = scene_dir(&other, 0).join("trace.exr");
            std::fs::remove_file(&p).unwrap();
            std::fs::copy(q, &p).unwrap();
        },
    ),
    tamper(
        Shard,
        "shard INCOMPLETE marker added",
        "incomplete run",
        [A, A, A, R],
        |run, _, _| {
            std::fs::write(run.join("INCOMPLETE"), "check \u{1b}[31mstarted\n").unwrap();
        },
    ),
];

/// One case: a tamper (index into [`TAMPERS`]) and its two numbers.
#[derive(Debug, Clone)]
pub struct RunCase {
    tamper: usize,
    a: u64,
    b: u64,
}

pub fn run_case_strategy() -> impl Strategy<Value = RunCase> {
    (0..TAMPERS.len(), any::<u64>(), any::<u64>()).prop_map(|(tamper, a, b)| RunCase {
        tamper,
        a,
        b,
    })
}

/// Copies a folder (links as links), its files writable.
fn copy_tree(from: &Path, to: &Path) {
    use std::os::unix::fs::PermissionsExt;
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        let (src, dst) = (e.path(), to.join(e.file_name()));
        let ty = e.file_type().unwrap();
        if ty.is_dir() {
            copy_tree(&src, &dst);
        } else if ty.is_symlink() {
            std::os::unix::fs::symlink(std::fs::read_link(&src).unwrap(), &dst).unwrap();
        } else {
            std::fs::copy(&src, &dst).unwrap();
            std::fs::set_permissions(&dst, std::fs::Permissions::from_mode(0o644)).unwrap();
        }
    }
}

/// The runs every case starts from, made once: `full` (two scenes),
/// `s1` and `s2` (the shards of the same check), and `base.json` blessed
/// from `full`.
struct Made {
    dir: tempfile::TempDir,
}

fn rendiff_in(dir: &Path) -> Command {
    let path = format!(
        "{}/.venv/bin:{}",
        env!("CARGO_MANIFEST_DIR"),
        std::env::var("PATH").unwrap_or_default()
    );
    let mut cmd = Command::new(binary());
    cmd.current_dir(dir)
        .env("PATH", path)
        .env_remove("RENDIFF_HOME");
    cmd
}

const SCENE: &str = "requires = [\"depth\", \"ids\"]\n\
[camera]\neye = [0.3, 0.3, 5.0]\nlook_at = [0.3, 0.3, 0.0]\nvfov = 45.0\nwidth = WIDTH\nheight = 12\n\
[[objects]]\nname = \"t\"\nshape = { kind = \"three_triangles\" }\n";

fn make_runs() -> Made {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("a.toml"), SCENE.replace("WIDTH", "16")).unwrap();
    std::fs::write(d.join("b.toml"), SCENE.replace("WIDTH", "20")).unwrap();
    for (out, shard) in [("full", None), ("s1", Some("1/2")), ("s2", Some("2/2"))] {
        let mut cmd = rendiff_in(d);
        cmd.args([
            "check",
            "a.toml",
            "b.toml",
            "--only",
            "trace",
            "--no-calibration",
        ])
        .args(["--jobs", "1", "--quiet", "-o", out]);
        if let Some(k) = shard {
            cmd.args(["--shard", k]);
        }
        let o = cmd.output().unwrap();
        assert!(
            o.status.success(),
            "check -o {out}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    let o = rendiff_in(d)
        .args(["bless", "full", "--baseline", "base.json"])
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "bless: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    Made { dir }
}

/// The entries of a folder, by name.
fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn run_tamper_case(c: &RunCase, made: &Made, t: &Tally) -> Vec<String> {
    let (target, tamper) = &TAMPERS[c.tamper];
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for run in ["full", "s1", "s2"] {
        copy_tree(&made.dir.path().join(run), &d.join(run));
    }
    let base = std::fs::read(made.dir.path().join("base.json")).unwrap();
    std::fs::write(d.join("b2.json"), &base).unwrap();
    let tampered = d.join(match target {
        Target::Full => "full",
        Target::Shard => "s1",
    });
    (tamper.apply)(&tampered, c.a, c.b);
    let before = names(d);
    let mut problems = Vec::new();
    let commands: Vec<(usize, Vec<&str>)> = match target {
        Target::Full => vec![
            (0, vec!["gate", "full", "--baseline", "b2.json"]),
            (1, vec!["bless", "full", "--baseline", "b2.json"]),
            (2, vec!["report", "full"]),
        ],
        Target::Shard => vec![(3, vec!["merge", "s1", "s2", "--quiet", "-o", "merged"])],
    };
    for (k, args) in commands {
        let what = COMMANDS[k];
        let (outcome, stdout) = run_within(rendiff_in(d).args(&args), Duration::from_secs(60));
        let folder = (k == 3).then(|| d.join("merged"));
        let (end, stderr) = judge(
            what,
            outcome,
            folder.as_deref(),
            k == 0 || k == 3,
            t,
            &mut problems,
        );
        for (stream, s) in [("stdout", &stdout), ("stderr", &stderr)] {
            if s.chars().any(|ch| ch.is_control() && ch != '\n') {
                wrong(
                    t,
                    &mut problems,
                    format!("{what}: {stream} carries a raw control character: {s:?}"),
                );
            }
        }
        match tamper.must[k] {
            Must::Refuse if end == End::Refused && !stderr.contains(tamper.file) => {
                wrong(
                    t,
                    &mut problems,
                    format!(
                        "{what}: the refusal does not name {}: {stderr}",
                        tamper.file
                    ),
                );
            }
            Must::Refuse if matches!(end, End::Success | End::Failed) => {
                wrong(
                    t,
                    &mut problems,
                    format!("{what}: not refused (exit {end:?}): {stdout}"),
                );
            }
            Must::Banner if end == End::Refused && !stderr.contains(tamper.file) => {
                wrong(
                    t,
                    &mut problems,
                    format!(
                        "{what}: the refusal does not name {}: {stderr}",
                        tamper.file
                    ),
                );
            }
            Must::Banner if end == End::Success => {
                let index =
                    std::fs::read_to_string(d.join("full/report/index.html")).unwrap_or_default();
                if !index.contains("No verdicts") {
                    wrong(
                        t,
                        &mut problems,
                        format!(
                            "{what}: a report of a run whose {} is damaged shows verdicts",
                            tamper.file
                        ),
                    );
                }
            }
            Must::NotSucceed if end == End::Success => {
                wrong(
                    t,
                    &mut problems,
                    format!("{what}: succeeded on tampered data: {stdout}"),
                );
            }
            _ => {}
        }
        if k == 1 {
            let now = std::fs::read(d.join("b2.json")).unwrap_or_default();
            if end != End::Success && now != base {
                wrong(
                    t,
                    &mut problems,
                    "bless: refused, but the baseline changed".into(),
                );
            }
            if end == End::Success
                && serde_json::from_slice::<Value>(&now).map_or(true, |v| !v["entries"].is_array())
            {
                wrong(
                    t,
                    &mut problems,
                    "bless: the baseline it wrote is not a baseline".into(),
                );
            }
        }
    }
    let after = names(d);
    let new: Vec<&String> = after
        .iter()
        .filter(|n| !before.contains(n) && *n != "merged")
        .collect();
    if !new.is_empty() {
        wrong(
            t,
            &mut problems,
            format!("written outside the runs: {new:?}"),
        );
    }
    problems
}

#[test]
fn tampered_runs_are_refused_never_passed() {
    super::common_cli::need_venv();
    let cases: usize = env_number("RENDIFF_FUZZ_RUNS_CASES", 120);
    let seed: u64 = env_number("RENDIFF_FUZZ_SEED", 12);
    let all = generate(run_case_strategy(), cases, seed);
    let made = make_runs();
    let tally = Tally {
        kind_skip: 2,
        ..Tally::default()
    };
    let started = Instant::now();
    let failures = run_all(&all, 2, &tally, |c, t| run_tamper_case(c, &made, t));
    print_table(
        "fuzz_scenes: tampered run folders",
        seed,
        started.elapsed(),
        &tally,
    );
    let mut kinds = std::collections::BTreeMap::new();
    for (i, problems) in &failures {
        for p in problems {
            let key = format!(
                "{}: {}",
                TAMPERS[all[*i].tamper].1.name,
                p.chars().take(70).collect::<String>()
            );
            *kinds.entry(key).or_insert(0) += 1;
        }
    }
    for (k, n) in &kinds {
        eprintln!("{n} x {k}");
    }
    for (i, problems) in failures.iter().take(12) {
        let c = &all[*i];
        eprintln!(
            "--- case {i}: {} ({}, {}):\n{}",
            TAMPERS[c.tamper].1.name,
            c.a,
            c.b,
            problems.join("\n")
        );
    }
    assert!(
        failures.is_empty(),
        "{} of {} tampered runs failed (first ones above)",
        failures.len(),
        all.len()
    );
}
