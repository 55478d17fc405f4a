//! Renderer declarations (issue 40 item 8): hostile renderers files run
//! through `rendiff check --renderers FILE` on a tiny scene with the core's
//! tracer: wrong types; huge, negative, NaN and infinite precision numbers
//! and time limits; commands that do not exist, are folders, FIFOs,
//! devices, not executable, or print garbage; control characters, NUL and
//! shell metacharacters in names and arguments; placeholders missing or
//! unknown; duplicate names and the names of built-in backends; damaged
//! TOML. Each must end in a clear one-line refusal (exit 2, no run left)
//! or a finished run in which every declared renderer named in `--only`
//! has entries of its own, none of them a pass unless its command is the
//! honest example renderer, and the built-in renderers' verdicts are the
//! ones a run without the file gives. Nothing the file says may reach the
//! terminal raw (no escape, bell or NUL on stdout or stderr).

use super::*;

/// One declared renderer, as TOML lines, and whether its command renders
/// honestly (the example renderer, called as it expects).
#[derive(Debug, Clone)]
pub struct Declared {
    name: String,
    lines: String,
    honest: bool,
}

/// The example renderer, by absolute path (it finds the harness from there).
fn example() -> String {
    format!(
        "{}/harness/examples/tiny_renderer.py",
        env!("CARGO_MANIFEST_DIR")
    )
}

/// A TOML value standing for a number (or something else).
fn hostile_number() -> impl Strategy<Value = String> {
    prop::sample::select(vec![
        "nan",
        "+nan",
        "-nan",
        "inf",
        "-inf",
        "-1",
        "0",
        "-0.0",
        "1e6",
        "1e300",
        "1e-300",
        "5e-324",
        "0.5",
        "0.49999",
        "1",
        "\"1e-6\"",
        "true",
        "[]",
        "{}",
        "1979-05-27",
        "9223372036854775807",
        "0x10",
    ])
    .prop_map(str::to_string)
}

/// A name: legal (`r` and a number), or hostile.
fn name() -> impl Strategy<Value = (String, String)> {
    prop_oneof![
        12 => (0u32..3).prop_map(|i| (format!("r{i}"), format!("\"r{i}\""))),
        1 => Just(("tiny-2".to_string(), "\"tiny-2\"".to_string())),
        3 => prop::sample::select(vec![
            "\"\"", "\"Bad Name\"", "\"trace\"", "\"raster\"", "\"embree\"", "\"pyrender\"",
            "\"a;rm -rf ~\"", "\"x\\u001b[31mred\"", "\"bell\\u0007\"", "\"nul\\u0000\"",
            "\"a/b\"", "\"..\"", "\"-x\"", "42", "[\"r0\"]", "\"r\\n1\"", "\"$(id)\"",
            "\"\\u202eevil\"",
        ])
        .prop_map(|s| (String::new(), s.to_string())),
        1 => Just(("n".repeat(64), format!("\"{}\"", "n".repeat(64)))),
        1 => Just((String::new(), format!("\"{}\"", "n".repeat(65)))),
    ]
}

/// The command: (TOML array, honest).
fn command() -> impl Strategy<Value = (String, bool)> {
    let ex = example();
    let honest = format!("[{ex:?}, \"{{scene}}\", \"{{out}}\"]");
    prop_oneof![
        10 => Just((honest, true)),
        10 => prop::sample::select(vec![
            "[]".to_string(),
            format!("{ex:?}"),
            "[\"./missing\", \"{scene}\", \"{out}\"]".into(),
            "[\"./adir\", \"{scene}\", \"{out}\"]".into(),
            "[\"./apipe\", \"{scene}\", \"{out}\"]".into(),
            "[\"/dev/null\", \"{scene}\", \"{out}\"]".into(),
            "[\"/dev/zero\", \"{scene}\", \"{out}\"]".into(),
            "[\"./noexec.sh\", \"{scene}\", \"{out}\"]".into(),
            "[\"./garbage.sh\", \"{scene}\", \"{out}\"]".into(),
            "[\"./silent.sh\", \"{scene}\", \"{out}\"]".into(),
            "[\"./loud.sh\", \"{scene}\", \"{out}\"]".into(),
            "[\"./skip.sh\", \"{scene}\", \"{out}\"]".into(),
            "[\"./killed.sh\", \"{scene}\", \"{out}\"]".into(),
            format!("[{ex:?}, \"{{scene}}\"]"),
            format!("[{ex:?}, \"{{out}}\", \"{{scene}}\"]"),
            format!("[{ex:?}, \"{{scene}}\", \"{{out}}\", \"{{bogus}}\"]"),
            format!("[{ex:?}, \"{{scene}}\", \"{{out}}\", \"; rm -rf ~ && echo $HOME `id`\"]"),
            format!("[{ex:?}, \"{{scene}}\", \"{{out}}\\u0000x\"]"),
            format!("[{ex:?}, \"{{scene}}\\u001b]0;title\\u0007\", \"{{out}}\"]"),
            "[\"sh\", \"-c\", \"echo \\u001b[2J >&2; exit 1\"]".into(),
            "[\"{scene}\", \"{out}\"]".into(),
            "[\"\", \"{scene}\", \"{out}\"]".into(),
            "[1, 2]".into(),
            "[\"./loud.sh\", \"{width}\", \"{height}\", \"{here}\"]".into(),
            "\"./loud.sh {scene} {out}\"".into(),
        ])
        .prop_map(|c| (c, false)),
    ]
}

fn declared() -> impl Strategy<Value = Declared> {
    let h = 1u32; // weight of a hostile value against 10 or 12 for the valid ones
    (
        name(),
        command(),
        prop_oneof![
            20 => Just(None),
            1 => Just(Some("[\"./missing\", \"--version\"]".to_string())),
            1 => Just(Some("[\"./loud.sh\"]".to_string())),
            1 => Just(Some("[\"./adir\"]".to_string())),
            1 => Just(Some("\"v1\"".to_string())),
            1 => Just(Some("[\"./garbage.sh\", \"x\", \"y\"]".to_string())),
        ],
        prop_oneof![
            20 => Just("[\"depth\", \"ids\", \"normals\"]".to_string()),
            h => prop::sample::select(vec!["[]", "[\"teleport\"]", "\"depth\"", "[1]", "[\"depth\", \"depth\"]", "[\"depth\"]"])
                .prop_map(str::to_string),
        ],
        prop_oneof![
            20 => Just("[\"Z\", \"id\", \"N\"]".to_string()),
            4 => Just("[\"Z\", \"id\"]".to_string()),
            h => prop::sample::select(vec!["[]", "[\"Q\"]", "[\"Z\", \"Z\"]", "\"Z\"", "[\"RGB\"]", "[\"id\"]", "[\"z\"]"])
                .prop_map(str::to_string),
        ],
        prop_oneof![
            20 => Just(Some("30".to_string())),
            4 => Just(None),
            h => hostile_number().prop_map(Some),
        ],
        prop_oneof![6 => Just(0usize), 3 => Just(1), 1 => Just(2)].prop_flat_map(|n| {
            prop::collection::vec(
                (
                    prop::sample::select(vec![
                        "edge_px", "depth_relative", "normal_relative", "depth_absolute",
                        "rgb_relative", "rgb_absolute", "depth_grazing", "colour",
                    ]),
                    prop_oneof![
                        2 => prop::sample::select(vec!["1e-5", "0.01", "1e-7", "0.4", "0.49", "1e-9", "0.0009"])
                            .prop_map(str::to_string),
                        1 => hostile_number(),
                    ],
                ),
                n,
            )
        }),
        prop::option::weighted(0.05, Just("unknown_key = 1\n".to_string())),
    )
        .prop_map(|((name, name_toml), (cmd, honest), version, features, buffers, timeout, precision, extra)| {
            let mut s = format!("[[renderer]]\nname = {name_toml}\ncommand = {cmd}\nfeatures = {features}\nbuffers = {buffers}\n");
            if let Some(v) = version {
                s += &format!("version = {v}\n");
            }
            if let Some(t) = timeout {
                s += &format!("timeout_s = {t}\n");
            }
            s += extra.as_deref().unwrap_or("");
            // The example's precision, then the hostile keys (a key given
            // twice is a TOML error: the hostile one replaces it).
            let mut keys: Vec<(String, String)> = [
                ("depth_relative", "1.2e-7"),
                ("edge_px", "1e-6"),
                ("normal_relative", "2.4e-7"),
            ]
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
            for (k, v) in precision {
                keys.retain(|(x, _)| x != k);
                keys.push((k.to_string(), v));
            }
            s += "[renderer.precision]\n";
            for (k, v) in keys {
                s += &format!("{k} = {v}\n");
            }
            Declared { name, lines: s, honest }
        })
}

/// A renderers file: 1 to 3 declarations, sometimes damaged; and the file
/// the command line names (the file itself, or a special entry).
#[derive(Debug, Clone)]
pub struct RenderersCase {
    declared: Vec<Declared>,
    text: Vec<u8>,
    given: &'static str,
}

pub fn renderers_case() -> impl Strategy<Value = RenderersCase> {
    (
        prop_oneof![6 => Just(1usize), 2 => Just(2), 1 => Just(3)]
            .prop_flat_map(|n| prop::collection::vec(declared(), n)),
        prop_oneof![
            30 => Just(0u8),
            1 => Just(1), // truncated
            1 => Just(2), // a random byte inserted
            1 => Just(3), // not UTF-8
            1 => Just(4), // a BOM
            1 => Just(5), // an unknown table
        ],
        any::<prop::sample::Index>(),
        any::<u8>(),
        prop_oneof![
            40 => Just("renderers.toml"),
            1 => Just("adir"),
            1 => Just("apipe"),
            1 => Just("/dev/zero"),
            1 => Just("missing.toml"),
            1 => Just("outlink.toml"),
        ],
    )
        .prop_map(|(declared, damage, at, byte, given)| {
            let mut text: Vec<u8> = declared
                .iter()
                .map(|d| d.lines.clone())
                .collect::<Vec<_>>()
                .join("\n")
                .into_bytes();
            let i = at.index(text.len() + 1);
            match damage {
                1 => text.truncate(i),
                2 => text.insert(i, byte),
                3 => text.splice(0..0, [0xffu8, 0xfe, b'\n']).for_each(drop),
                4 => text.splice(0..0, [0xEFu8, 0xBB, 0xBF]).for_each(drop),
                5 => text.extend_from_slice(b"\n[settings]\nfast = true\n"),
                _ => {}
            }
            RenderersCase {
                declared,
                text,
                given,
            }
        })
}

const SCENE: &str = "requires = [\"depth\", \"ids\"]\n\
[camera]\neye = [0.3, 0.3, 5.0]\nlook_at = [0.3, 0.3, 0.0]\nvfov = 45.0\nwidth = 16\nheight = 12\n\
[[objects]]\nname = \"t\"\nshape = { kind = \"three_triangles\" }\n";

fn executable(path: &Path, body: &str, mode: u32) {
    use std::os::unix::fs::PermissionsExt;
    std::fs::write(path, body).unwrap();
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).unwrap();
}

/// Writes the case's folder: the scene, the renderers file, the programs
/// the commands name (and the special entries).
fn write_renderers_case(dir: &Path, text: &[u8]) {
    std::fs::write(dir.join("s.toml"), SCENE).unwrap();
    std::fs::write(dir.join("renderers.toml"), text).unwrap();
    std::fs::create_dir_all(dir.join("adir")).unwrap();
    mkfifo(&dir.join("apipe"));
    std::os::unix::fs::symlink("/etc/passwd", dir.join("outlink.toml")).unwrap();
    executable(&dir.join("noexec.sh"), "#!/bin/sh\nexit 0\n", 0o644);
    executable(
        &dir.join("garbage.sh"),
        "#!/bin/sh\nhead -c 3000 /dev/urandom > \"$2\"\nprintf 'v\\033[31m1\\n'\n",
        0o755,
    );
    executable(&dir.join("silent.sh"), "#!/bin/sh\nexit 0\n", 0o755);
    executable(
        &dir.join("loud.sh"),
        "#!/bin/sh\nprintf 'bad \\033]0;title\\007 \\000 news\\r\\n' >&2\nprintf 'out \\033[2J\\n'\nexit 1\n",
        0o755,
    );
    executable(
        &dir.join("skip.sh"),
        "#!/bin/sh\nprintf 'cannot \\033[31mhere\\n' >&2\nexit 3\n",
        0o755,
    );
    executable(&dir.join("killed.sh"), "#!/bin/sh\nkill -9 $$\n", 0o755);
}

/// `rendiff check` of the tiny scene in `dir` with the core's tracer and
/// `names` from the renderers file `given`, into `dir/run`.
fn check_cmd(dir: &Path, given: Option<&str>, names: &[&str]) -> Command {
    let path = format!(
        "{}/.venv/bin:{}",
        env!("CARGO_MANIFEST_DIR"),
        std::env::var("PATH").unwrap_or_default()
    );
    let mut only = vec!["trace"];
    only.extend(names);
    let mut cmd = Command::new(binary());
    cmd.current_dir(dir)
        .env("PATH", path)
        .env_remove("RENDIFF_HOME")
        .arg("check")
        .arg("s.toml");
    if let Some(f) = given {
        cmd.args(["--renderers", f]);
    }
    cmd.args(["--only", &only.join(",")]).args([
        "--no-calibration",
        "--jobs",
        "1",
        "--quiet",
        "-o",
        "run",
    ]);
    cmd
}

/// A run's verdicts: (backend, buffer) -> status.
fn run_statuses(run: &Path) -> Option<Vec<(String, String, String)>> {
    let text = std::fs::read_to_string(run.join("results.json")).ok()?;
    let v: serde_json::Value = serde_json::from_str(&text).ok()?;
    let mut out: Vec<(String, String, String)> = v["results"]
        .as_array()?
        .iter()
        .map(|e| {
            let s = |k: &str| e[k].as_str().unwrap_or("?").to_string();
            (s("backend"), s("buffer"), s("status"))
        })
        .collect();
    out.sort();
    Some(out)
}

/// Raw control characters a renderers file may carry to the terminal.
fn raw_controls(s: &str) -> bool {
    s.chars().any(|c| c.is_control() && c != '\n' && c != '\t')
}

fn run_renderers_case(
    c: &RenderersCase,
    builtin: &[(String, String, String)],
    t: &Tally,
) -> Vec<String> {
    let dir = tempfile::tempdir().unwrap();
    write_renderers_case(dir.path(), &c.text);
    // The legal names only (a hostile one in --only is a test of --only).
    let legal = |n: &str| {
        !n.is_empty()
            && n.len() <= 64
            && n.starts_with(|ch: char| ch.is_ascii_lowercase())
            && n.chars()
                .all(|ch| ch.is_ascii_lowercase() || ch.is_ascii_digit() || ch == '_' || ch == '-')
    };
    let mut names: Vec<&str> = c
        .declared
        .iter()
        .map(|d| d.name.as_str())
        .filter(|n| legal(n))
        .collect();
    names.sort_unstable();
    names.dedup();
    let run = dir.path().join("run");
    let mut problems = Vec::new();
    let (outcome, stdout) = run_within(
        &mut check_cmd(dir.path(), Some(c.given), &names),
        Duration::from_secs(90),
    );
    let (end, stderr) = judge("check", outcome, Some(&run), true, t, &mut problems);
    for (what, s) in [("stdout", &stdout), ("stderr", &stderr)] {
        if raw_controls(s) {
            wrong(
                t,
                &mut problems,
                format!("{what} carries a raw control character: {s:?}"),
            );
        }
    }
    if !matches!(end, End::Success | End::Failed) {
        return problems;
    }
    let Some(got) = run_statuses(&run) else {
        wrong(
            t,
            &mut problems,
            "a finished check without a readable results.json".into(),
        );
        return problems;
    };
    let mine: Vec<_> = got
        .iter()
        .filter(|(b, _, _)| b == "trace" || b == "raster")
        .cloned()
        .collect();
    if mine != builtin {
        wrong(
            t,
            &mut problems,
            format!("the built-in verdicts changed: {mine:?}, without the file {builtin:?}"),
        );
    }
    for n in &names {
        let entries: Vec<_> = got.iter().filter(|(b, _, _)| b == n).collect();
        if entries.is_empty() {
            wrong(
                t,
                &mut problems,
                format!("declared renderer {n} has no entry"),
            );
        }
        let honest = c.declared.iter().filter(|d| d.name == *n).all(|d| d.honest);
        if !honest && entries.iter().any(|(_, _, s)| s == "pass") {
            wrong(
                t,
                &mut problems,
                format!("declared renderer {n}, whose command cannot render, passed: {entries:?}"),
            );
        }
    }
    let bad = got
        .iter()
        .any(|(_, _, s)| matches!(s.as_str(), "fail" | "error" | "unexpected_pass"));
    if (end == End::Failed) != bad {
        wrong(
            t,
            &mut problems,
            format!("exit {end:?} with verdicts {got:?}"),
        );
    }
    problems
}

#[test]
fn hostile_renderer_declarations_end_cleanly() {
    super::common_cli::need_venv();
    let cases: usize = env_number("RENDIFF_FUZZ_RENDERERS_CASES", 24);
    let seed: u64 = env_number("RENDIFF_FUZZ_SEED", 12);
    let all = generate(renderers_case(), cases, seed);
    // The built-in verdicts without a renderers file, once.
    let dir = tempfile::tempdir().unwrap();
    write_renderers_case(dir.path(), b"");
    let (outcome, _) = run_within(
        &mut check_cmd(dir.path(), None, &[]),
        Duration::from_secs(120),
    );
    let ok = matches!(&outcome, Outcome::Exited(Some(0), _));
    let err = match outcome {
        Outcome::Exited(_, e) => e,
        Outcome::Hang => "hung".into(),
    };
    assert!(ok, "the check without a renderers file: {err}");
    let builtin = run_statuses(&dir.path().join("run")).unwrap();
    assert!(
        builtin.iter().any(|(b, _, s)| b == "trace" && s == "pass"),
        "{builtin:?}"
    );
    let tally = Tally {
        kind_skip: 3, // program, file, entry: the problem
        ..Tally::default()
    };
    let started = Instant::now();
    let failures = run_all(&all, 2, &tally, |c, t| run_renderers_case(c, &builtin, t));
    print_table(
        "fuzz_scenes: renderer declarations",
        seed,
        started.elapsed(),
        &tally,
    );
    for (i, problems) in failures.iter().take(10) {
        let c = &all[*i];
        eprintln!(
            "--- case {i} (--renderers {}):\n{}\nrenderers.toml:\n{}",
            c.given,
            problems.join("\n"),
            String::from_utf8_lossy(&c.text).escape_debug()
        );
    }
    assert!(
        failures.is_empty(),
        "{} of {} renderer cases failed (first ones above)",
        failures.len(),
        all.len()
    );
}
