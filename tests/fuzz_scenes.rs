//! Fuzzer: hostile scenes, meshes, glTF files, renderer declarations and
//! tampered run folders through the real binary, one test per surface.
//!
//! proptest generates scene folders (TOML with wrong types, huge, NaN and
//! infinite numbers, degenerate cameras, budgets exceeded; OBJ text with bad
//! indices, quads and n-gons, `mtllib` lines naming /dev/zero or a FIFO,
//! control characters in names; meshes that are FIFOs, folders, symlinks,
//! non-UTF-8 or outside the folder). Each is run through `rendiff render
//! --renderer raster` and `rendiff export`. No run may panic (exit 101 or a
//! signal), hang past [`TIMEOUT`], exit with anything but 0 or 2, print more
//! or less than one line (or a raw control character) on stderr when it
//! fails, or leave a file in the output folder when it fails ([`judge`]).
//! The other surfaces, each with its own oracle for a wrong verdict:
//! fuzz_scenes/gltf.rs (glTF and GLB files), fuzz_scenes/renderers.rs
//! (`check --renderers`), fuzz_scenes/runs.rs (gate, bless, report and
//! merge on tampered runs).
//!
//! Each surface prints its table of counts by outcome (`cargo test --test
//! fuzz_scenes -- --nocapture`). The number of cases: `RENDIFF_FUZZ_CASES`
//! (scenes, default 2000), `RENDIFF_FUZZ_GLTF_CASES` (600),
//! `RENDIFF_FUZZ_RENDERERS_CASES` (24: each accepted file is a whole check,
//! about 3 s), `RENDIFF_FUZZ_RUNS_CASES` (120); the defaults keep the test
//! near a minute on two cores. `RENDIFF_FUZZ_SEED` changes the seed,
//! `RENDIFF_FUZZ_BIN` the binary, `RENDIFF_FUZZ_SHOW` prints every clean
//! error; a failure prints what reproduces it by hand.
//!
//! Larger runs (seed 12, on a 2-core machine shared with other builds):
//!
//! | surface | inputs | runs | clean errors | successes | failing verdicts | panics | hangs | leftovers | bad messages | other exits | wrong verdicts |
//! |---|---|---|---|---|---|---|---|---|---|---|---|
//! | scenes (default) | 2000 | 4000 | 3722 | 278 | - | 0 | 0 | 0 | 0 | 0 | 0 |
//! | glTF files | 2000 | 4000 | 2442 | 1558 | 0 | 0 | 0 | 0 | 0 | 0 | 0 |
//! | renderer declarations (300 cases: each a check) | 300 | 300 | 224 | 55 | 21 | 0 | 0 | 0 | 0 | 0 | 0 |
//! | tampered runs | 2000 | 4802 | 2766 | 1591 | 445 | 0 | 0 | 0 | 0 | 0 | 0 |
//!
//! (glTF: 639 cases of the valid file's meaning, each exported the same
//! triangles; 422 invalid by the specification, each refused. Tampered
//! runs, before the fixes that came with them: gate passed runs whose
//! manifest.json was damaged, merge passed shards whose resolved scene or
//! its recorded hash had been changed. One earlier 2000-case run of the
//! tampered runs also had 5 merges of a shard with a damaged EXR end in
//! "the comparison failed" on several lines, its marker left in the
//! unpublished output; not seen in the rerun above or in 30 tries by hand
//! (the Python comparison died, the machine shared: cause not found). The
//! message is one line now; why the comparison died is open.)

mod common;
use common::cli as common_cli;
#[path = "fuzz_scenes/gltf.rs"]
mod gltf;
#[path = "fuzz_scenes/renderers.rs"]
mod renderers;
#[path = "fuzz_scenes/runs.rs"]
mod runs;

use proptest::prelude::*;
use proptest::strategy::ValueTree;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Per-run limit; every accepted scene is tiny, so anything near this is a hang.
const TIMEOUT: Duration = Duration::from_secs(20);

// ---------------------------------------------------------------- generators

/// A TOML number (or something that is not one).
fn number(h: u32) -> impl Strategy<Value = String> {
    prop_oneof![
        300 => (-4.0f64..4.0).prop_map(|x| format!("{x:?}")),
        80 => (-3i64..4).prop_map(|x| x.to_string()),
        1 => Just("0.0".to_string()),
        1 => Just("-0.0".to_string()),
        h => prop::sample::select(vec![
            "nan", "+nan", "-nan", "inf", "-inf", "1e200", "-1e200", "1e39", "3.5e38",
            "1e-300", "5e-324", "1e308", "-1.7976931348623157e308", "1e-45",
        ])
        .prop_map(str::to_string),
        h => prop::sample::select(vec![
            "\"1.0\"", "true", "[]", "{}", "1979-05-27", "0x10", "1_000", "9223372036854775808",
        ])
        .prop_map(str::to_string),
    ]
}

fn vec3(h: u32) -> impl Strategy<Value = String> {
    prop_oneof![
        200 => (number(h), number(h), number(h)).prop_map(|(a, b, c)| format!("[{a}, {b}, {c}]")),
        h => (number(h), number(h)).prop_map(|(a, b)| format!("[{a}, {b}]")),
        h => Just("[1.0, 2.0, 3.0, 4.0]".to_string()),
        h => number(h),
    ]
}

/// Three numbers in `lo..hi` (valid by construction), or anything at weight h.
fn range3(h: u32, lo: f64, hi: f64) -> impl Strategy<Value = String> {
    prop_oneof![
        30 => (lo..hi, lo..hi, lo..hi).prop_map(|(a, b, c)| format!("[{a:?}, {b:?}, {c:?}]")),
        h => vec3(h),
    ]
}

/// Two numbers in `lo..hi`, or anything at weight h.
fn range2(h: u32, lo: f64, hi: f64) -> impl Strategy<Value = String> {
    prop_oneof![
        30 => (lo..hi, lo..hi).prop_map(|(a, b)| format!("[{a:?}, {b:?}]")),
        h => vec2(h),
    ]
}

fn vec2(h: u32) -> impl Strategy<Value = String> {
    prop_oneof![
        200 => (number(h), number(h)).prop_map(|(a, b)| format!("[{a}, {b}]")),
        h => vec3(h),
    ]
}

/// Image sides and counts: mostly small (so accepted scenes stay fast), some
/// at or beyond the limits and the integer types.
fn count(h: u32, small: u32) -> impl Strategy<Value = String> {
    prop_oneof![
        30 => (1..=small).prop_map(|x| x.to_string()),
        h => prop::sample::select(vec![
            "0", "-1", "4096", "4097", "16384", "16385", "100000", "4294967295", "4294967296",
            "99999999999999999999", "1.5", "\"8\"", "nan",
        ])
        .prop_map(str::to_string),
    ]
}

/// A string: plain, empty, long, with escaped control characters (valid TOML)
/// or with raw ones (invalid TOML, quoted back in the error).
fn name(h: u32) -> impl Strategy<Value = String> {
    prop_oneof![
        30 => "[a-z]{1,8}".prop_map(|s| format!("\"{s}\"")),
        1 => Just("\"\"".to_string()),
        1 => Just(format!("\"{}\"", "n".repeat(5000))),
        2 => prop::sample::select(vec![
            "\"a\\u001b[31mred\\u0000\"", "\"\\u0007bell\\r\\n\"", "\"\\u202eevil\"",
            "\"tab\\tname\"", "\"\\u009bcsi\"",
        ])
        .prop_map(str::to_string),
        h => prop::sample::select(vec!["\"raw\u{1b}[2Jesc\"", "\"raw\u{0}nul\"", "\"x\u{7f}y\""])
            .prop_map(str::to_string),
        h => Just("42".to_string()),
    ]
}

/// Mesh paths; the folder is set up so that each names something specific.
fn mesh_path(h: u32) -> impl Strategy<Value = String> {
    prop_oneof![
        6 => Just("m.obj"),
        3 => Just("n.obj"),
        1 => Just("inside_link.obj"),
        1 => Just("sub/../m.obj"),
        h => prop::sample::select(vec![
        "pipe.obj",
        "dir.obj",
        "zero.obj",
        "bin.obj",
        "inside_link.obj",
        "missing.obj",
        "../outside.obj",
        "/dev/zero",
        "/etc/passwd",
        "",
        ".",
        "x\\u001b]0;title\\u0007.obj",
        "nul\\u0000.obj",
    ]),
    ]
    .prop_map(|p| format!("\"{p}\""))
}

fn shape(h: u32) -> impl Strategy<Value = String> {
    prop_oneof![
        2 => Just("{ kind = \"three_triangles\" }".to_string()),
        2 => (
            prop_oneof![4 => (0u32..=4).prop_map(|x| x.to_string()), 1 => count(h, 4)],
            prop_oneof![30 => (0.1f64..3.0).prop_map(|x| format!("{x:?}")), h => number(h)]
        )
            .prop_map(|(s, r)| format!("{{ kind = \"icosphere\", subdivisions = {s}, radius = {r} }}")),
        2 => (range2(h, -3.0, -0.1), range2(h, 0.1, 3.0), count(h, 48), count(h, 48))
            .prop_map(|(a, b, x, y)| format!("{{ kind = \"grid\", min = {a}, max = {b}, nx = {x}, ny = {y} }}")),
        1 => range2(h, 0.1, 4.0).prop_map(|s| format!("{{ kind = \"quad\", size = {s} }}")),
        2 => (range3(h, -3.0, -0.1), range3(h, 0.1, 3.0), any::<bool>())
            .prop_map(|(a, b, i)| format!("{{ kind = \"box\", min = {a}, max = {b}, inward = {i} }}")),
        2 => (prop::collection::vec((vec3(h), vec3(h), vec3(h)), 1..4), prop::collection::vec(vec3(h), 0..3))
            .prop_map(|(tris, odd)| {
                let mut v: Vec<String> = tris.into_iter().flat_map(|(a, b, c)| [a, b, c]).collect();
                v.extend(odd);
                format!("{{ kind = \"triangles\", vertices = [{}] }}", v.join(", "))
            }),
        h => Just("{ kind = \"teapot\" }".to_string()),
        h => Just("\"three_triangles\"".to_string()),
    ]
}

fn object(h: u32) -> impl Strategy<Value = String> {
    (
        name(h),
        prop_oneof![12 => shape(h).prop_map(|s| format!("shape = {s}")), 8 => mesh_path(h).prop_map(|m| format!("mesh = {m}")), h => Just(String::new())],
        prop::option::weighted(0.05, name(h)),
        prop::option::weighted(0.3, (vec3(h), vec3(h), vec3(h))),
        prop::option::weighted(0.3, any::<bool>()),
    )
        .prop_map(|(n, geom, mat, tr, deg)| {
            let mut s = format!("[[objects]]\nname = {n}\n{geom}\n");
            if let Some(m) = mat {
                s += &format!("material = {m}\n");
            }
            if let Some((sc, ro, tr)) = tr {
                s += &format!("transform = {{ scale = {sc}, rotate = {ro}, translate = {tr} }}\n");
            }
            if let Some(d) = deg {
                s += &format!("allow_degenerate = {d}\n");
            }
            s
        })
}

fn requires(h: u32) -> impl Strategy<Value = String> {
    prop_oneof![
        20 => Just("[\"depth\", \"ids\"]"),
        2 => Just("[\"depth\", \"ids\", \"lambert\", \"point_light\", \"shadows\", \"one_sided\"]"),
        2 => Just("[\"depth\", \"ids\", \"emission\", \"lambert\", \"global_illumination\", \"area_light\", \"two_sided\"]"),
        h => Just("[\"depth\", \"teleport\"]"),
        h => Just("[\"lambert\"]"),
        h => Just("\"depth\""),
        h => Just("[]"),
    ]
    .prop_map(str::to_string)
}

fn camera(h: u32) -> impl Strategy<Value = String> {
    (
        prop_oneof![12 => Just("[0.0, 0.0, 5.0]".to_string()), h => Just("[0.0, 0.0, 0.0]".to_string()), 3 => vec3(h)],
        prop_oneof![12 => Just("[0.0, 0.0, 0.0]".to_string()), 3 => vec3(h)],
        prop::option::weighted(0.4, prop_oneof![12 => Just("[0.0, 1.0, 0.0]".to_string()), h => Just("[0.0, 0.0, 1.0]".to_string()), h => Just("[0.0, 0.0, 0.0]".to_string()), 3 => vec3(h)]),
        prop_oneof![20 => (1.0f64..170.0).prop_map(|x| format!("{x:?}")), 2 => number(h), h => Just("180.0".to_string()), 1 => Just("179.99999999999997".to_string())],
        count(h, 48),
        count(h, 48),
        prop::option::weighted(if h > 1 { 0.3 } else { 0.02 }, number(h)),
        prop::option::weighted(if h > 1 { 0.3 } else { 0.02 }, number(h)),
    )
        .prop_map(|(eye, look, up, vfov, w, h, near, far)| {
            let mut s = format!("[camera]\neye = {eye}\nlook_at = {look}\nvfov = {vfov}\nwidth = {w}\nheight = {h}\n");
            if let Some(u) = up {
                s += &format!("up = {u}\n");
            }
            if let Some(n) = near {
                s += &format!("near = {n}\n");
            }
            if let Some(f) = far {
                s += &format!("far = {f}\n");
            }
            s
        })
}

fn extras(h: u32) -> impl Strategy<Value = String> {
    (
        prop::option::weighted(0.3, (name(h), range3(h, 0.0, 1.0), prop_oneof![9 => Just("[0.0, 0.0, 0.0]".to_string()), 1 => vec3(h)])),
        prop::option::weighted(if h > 1 { 0.3 } else { 0.03 }, prop_oneof![
            h => (vec3(h), vec3(h)).prop_map(|(p, i)| format!("[[lights]]\nkind = \"point\"\nposition = {p}\nintensity = {i}\n")),
            h => (vec3(h), vec3(h)).prop_map(|(d, e)| format!("[[lights]]\nkind = \"directional\"\ndirection = {d}\nirradiance = {e}\n")),
            20 => Just("[[lights]]\nkind = \"point\"\nposition = [0.0, 2.0, 2.0]\nintensity = [5.0, 5.0, 5.0]\n".to_string()),
            h => Just("[[lights]]\nkind = \"spot\"\n".to_string()),
        ]),
        prop::option::weighted(0.3, (
            prop_oneof![8 => Just("-1".to_string()), 8 => Just("3".to_string()), h => Just("0".to_string()), h => Just("-2".to_string()), h => Just("2147483648".to_string())],
            prop_oneof![16 => (1u32..=2).prop_map(|x| x.to_string()), h => Just("0".to_string()), h => Just("65537".to_string()), h => Just("4000000000".to_string()), h => Just("-5".to_string())],
        )),
    )
        .prop_map(|(mat, light, integ)| {
            let mut s = String::new();
            if let Some((n, a, e)) = mat {
                s += &format!("[[materials]]\nname = {n}\nalbedo = {a}\nemission = {e}\n");
            }
            if let Some(l) = light {
                s += &l;
            }
            if let Some((d, spp)) = integ {
                s += &format!("[integrator]\nmax_depth = {d}\nspp = {spp}\n");
            }
            s
        })
}

/// A whole scene file, sometimes damaged afterwards.
fn scene_toml() -> impl Strategy<Value = Vec<u8>> {
    // h: how hostile this scene is (weight of each wrong choice against ~30
    // for the valid ones): most scenes are nearly valid, so they reach
    // resolution, meshes and rendering; a quarter are hostile throughout.
    prop_oneof![3 => Just(1u32), 1 => Just(30u32)].prop_flat_map(scene_with)
}

fn scene_with(h: u32) -> impl Strategy<Value = Vec<u8>> {
    (
        requires(h),
        camera(h),
        prop_oneof![20 => prop::collection::vec(object(h), 1..4), h => Just(vec![])],
        extras(h),
        prop_oneof![
            40 => Just(0u8),  // as generated
            h => Just(1),     // truncated
            h => Just(2),     // an unknown field
            h => Just(3),     // a random byte inserted
            h => Just(4),     // a duplicated table header
            h => Just(5),     // not UTF-8
        ],
        any::<prop::sample::Index>(),
        any::<u8>(),
    )
        .prop_map(|(req, cam, objs, extra, damage, at, byte)| {
            // Tables first: `requires` must precede the first [table].
            // A lit scene gets its light (the generated ones are hostile).
            let light = if req.contains("point_light") {
                "[[lights]]\nkind = \"point\"\nposition = [0.0, 2.0, 2.0]\nintensity = [5.0, 5.0, 5.0]\n"
            } else {
                ""
            };
            let text = format!("requires = {req}\n{light}{extra}{cam}{}", objs.concat());
            let mut b = text.into_bytes();
            let i = at.index(b.len() + 1);
            match damage {
                1 => b.truncate(i),
                2 => b
                    .splice(0..0, b"colour = 3\n".iter().copied())
                    .for_each(drop),
                3 => b.insert(i, byte),
                4 => b.extend_from_slice(b"[camera]\nvfov = 1.0\n"),
                5 => b.splice(0..0, [0xffu8, 0xfe, b'\n']).for_each(drop),
                _ => {}
            }
            b
        })
}

/// OBJ text: vertices (some NaN, infinite or beyond f32), faces with bad,
/// negative and mixed-format indices, quads and n-gons, groups with hostile
/// names, `mtllib`/`usemtl` lines, garbage.
fn obj_text(h: u32) -> impl Strategy<Value = String> {
    let coord = prop_oneof![
        400 => (-3.0f32..3.0).prop_map(|x| format!("{x}")),
        h => prop::sample::select(vec!["nan", "inf", "-inf", "1e39", "-1e40", "1e-45", "x", "0x1p3"])
            .prop_map(str::to_string),
    ];
    let index = prop_oneof![
        100 => (1i64..5).prop_map(|i| i.to_string()),
        h => (5i64..12).prop_map(|i| i.to_string()),
        h => (-6i64..=0).prop_map(|i| i.to_string()),
        h => prop::sample::select(vec!["99999", "4294967296", "1/1/1", "2//2", "3/3", "a", "1e3", ""])
            .prop_map(str::to_string),
    ];
    let line = prop_oneof![
        6 => (coord.clone(), coord.clone(), coord.clone()).prop_map(|(x, y, z)| format!("v {x} {y} {z}")),
        h => (coord.clone(), coord.clone(), coord.clone(), coord.clone()).prop_map(|(x, y, z, w)| format!("v {x} {y} {z} {w}")),
        h => (coord.clone(), coord.clone()).prop_map(|(x, y)| format!("v {x} {y}")),
        6 => prop::collection::vec(index, 3..9).prop_map(|v| format!("f {}", v.join(" "))),
        h => prop::collection::vec((1i64..5).prop_map(|i| i.to_string()), 1..3).prop_map(|v| format!("f {}", v.join(" "))),
        3 => prop::sample::select(vec![
            "mtllib /dev/zero", "mtllib pipe.mtl", "mtllib ../../../../etc/shadow", "mtllib dir.obj",
            "mtllib", "usemtl red", "o", "o second", "g grp", "g \u{1b}[31mred\u{7}",
            "o nul\u{0}name", "vt 0 0", "vn 0 0 1", "l 1 2", "p 1", "s off", "# comment",
            "\u{feff}v 0 0 0", "v 0 0 0\r", "vp 1", "",
        ])
        .prop_map(str::to_string),
        h => prop::sample::select(vec!["usemtl", "f 1 2 \\", "f", "v", "vt", "l 1 99"])
            .prop_map(str::to_string),
    ];
    prop::collection::vec(line, 0..40).prop_map(|lines| {
        // A valid triangle first, so that many meshes get past the parser.
        let mut s = String::from("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n");
        for l in lines {
            s += &l;
            s.push('\n');
        }
        s
    })
}

#[derive(Debug, Clone)]
struct Case {
    scene: Vec<u8>,
    m_obj: String,
    n_obj: String,
}

fn case() -> impl Strategy<Value = Case> {
    (
        scene_toml(),
        prop_oneof![3 => Just(1u32), 1 => Just(30u32)].prop_flat_map(obj_text),
        prop_oneof![3 => Just(1u32), 1 => Just(30u32)].prop_flat_map(obj_text),
    )
        .prop_map(|(scene, m_obj, n_obj)| Case {
            scene,
            m_obj,
            n_obj,
        })
}

// ---------------------------------------------------------------- running

/// The binary under test; `RENDIFF_FUZZ_BIN` runs another build (an older
/// one, to see what the fuzzer finds there).
fn binary() -> PathBuf {
    std::env::var_os("RENDIFF_FUZZ_BIN")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_BIN_EXE_rendiff")))
}

#[derive(Default)]
struct Tally {
    inputs: AtomicUsize,
    runs: AtomicUsize,
    clean_errors: AtomicUsize,
    successes: AtomicUsize,
    panics: AtomicUsize,
    hangs: AtomicUsize,
    leftovers: AtomicUsize,
    bad_messages: AtomicUsize,
    other_exits: AtomicUsize,
    /// Runs that ended without a panic but with the wrong answer: a success
    /// where a refusal is the only right end, a result that differs from
    /// the one the input must give, a PASS on tampered data.
    wrong_verdicts: AtomicUsize,
    /// Runs that ended with exit 1 where that is a verdict (check, gate).
    failed_runs: AtomicUsize,
    /// Clean errors by the part after the file name (field, or problem start).
    kinds: Mutex<std::collections::BTreeMap<String, usize>>,
    /// How many `": "`-separated parts of a clean error's line to skip for
    /// its kind (0: the default, 2: the program and the file).
    kind_skip: usize,
}

fn mkfifo(p: &Path) {
    let c = std::ffi::CString::new(p.as_os_str().as_encoded_bytes()).unwrap();
    // SAFETY: mkfifo reads the NUL-terminated path `c`, which outlives the call.
    let rc = unsafe { libc::mkfifo(c.as_ptr(), 0o644) };
    assert_eq!(rc, 0, "mkfifo");
}

/// Writes the case's folder: `root/scenes/` with the scene and its meshes
/// (and the hostile entries [`mesh_path`] names), `root/outside.obj`.
fn write_case(root: &Path, c: &Case) -> PathBuf {
    let s = root.join("scenes");
    std::fs::create_dir_all(s.join("dir.obj")).unwrap();
    std::fs::create_dir_all(s.join("sub")).unwrap();
    std::fs::write(s.join("scene.toml"), &c.scene).unwrap();
    std::fs::write(s.join("m.obj"), &c.m_obj).unwrap();
    std::fs::write(s.join("n.obj"), &c.n_obj).unwrap();
    std::fs::write(s.join("bin.obj"), b"v 0 0 0\n\xc3\x28\n").unwrap();
    std::fs::write(
        root.join("outside.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    )
    .unwrap();
    mkfifo(&s.join("pipe.obj"));
    mkfifo(&s.join("pipe.mtl"));
    std::os::unix::fs::symlink("/dev/zero", s.join("zero.obj")).unwrap();
    std::os::unix::fs::symlink("m.obj", s.join("inside_link.obj")).unwrap();
    s.join("scene.toml")
}

enum Outcome {
    Exited(Option<i32>, String),
    Hang,
}

fn run_limited(cmd: &mut Command) -> Outcome {
    run_within(cmd, TIMEOUT).0
}

/// Runs `cmd` in a process group of its own within `limit` (the group
/// killed after it: a hang), its stdin empty; returns how it ended (with
/// its stderr) and its stdout.
fn run_within(cmd: &mut Command, limit: Duration) -> (Outcome, String) {
    use std::os::unix::process::CommandExt;
    let mut child = cmd
        .process_group(0)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn rendiff");
    let drain = |mut r: Box<dyn Read + Send>| {
        std::thread::spawn(move || {
            let mut v = Vec::new();
            r.read_to_end(&mut v).ok();
            String::from_utf8_lossy(&v).into_owned()
        })
    };
    let err = drain(Box::new(child.stderr.take().unwrap()));
    let out = drain(Box::new(child.stdout.take().unwrap()));
    let start = Instant::now();
    loop {
        if let Some(st) = child.try_wait().unwrap() {
            let (err, out) = (err.join().unwrap(), out.join().unwrap());
            return (Outcome::Exited(st.code(), err), out);
        }
        if start.elapsed() > limit {
            let group = -(child.id() as i32);
            // SAFETY: kill() takes no pointers; the group is the child's own
            // (process_group(0) above), not yet reaped, so its id is not reused.
            unsafe { libc::kill(group, libc::SIGKILL) };
            child.wait().ok();
            return (Outcome::Hang, String::new());
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    if let Ok(rd) = std::fs::read_dir(dir) {
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                out.extend(files_under(&p));
            } else {
                out.push(p);
            }
        }
    }
    out
}

/// How one run ended, as the fuzzer judges it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum End {
    /// Exit 0.
    Success,
    /// Exit 2 with one clean line on stderr.
    Refused,
    /// Exit 1 (a finished check or gate with failing verdicts).
    Failed,
    /// Anything else (a panic, a hang, a bad message, another exit): a
    /// problem already recorded.
    Broken,
}

/// Judges one run of the binary against the failure contract: exit 0, or
/// exit 2 with one line on stderr that carries no control character and no
/// panic, and (on exit 2) nothing left in `folder` (None: the command's
/// output is not a folder of its own); exit 1 only when `exit_1_ok` (check
/// and gate end so with failing verdicts). Counts it in `t`, records
/// problems, and returns how it ended with its stderr.
fn judge(
    what: &str,
    outcome: Outcome,
    folder: Option<&Path>,
    exit_1_ok: bool,
    t: &Tally,
    problems: &mut Vec<String>,
) -> (End, String) {
    t.runs.fetch_add(1, Ordering::Relaxed);
    match outcome {
        Outcome::Hang => {
            t.hangs.fetch_add(1, Ordering::Relaxed);
            problems.push(format!("{what}: still running past its time limit"));
            (End::Broken, String::new())
        }
        Outcome::Exited(Some(0), err) => {
            t.successes.fetch_add(1, Ordering::Relaxed);
            let stray: Vec<_> = folder
                .map(files_under)
                .unwrap_or_default()
                .into_iter()
                .filter(|p| p.to_string_lossy().contains(".tmp-"))
                .collect();
            if !stray.is_empty() {
                t.leftovers.fetch_add(1, Ordering::Relaxed);
                problems.push(format!("{what}: temporary files left: {stray:?}"));
            }
            (End::Success, err)
        }
        Outcome::Exited(Some(1), err) if exit_1_ok => {
            t.failed_runs.fetch_add(1, Ordering::Relaxed);
            (End::Failed, err)
        }
        Outcome::Exited(Some(2), err) => {
            let body = err.strip_suffix('\n').unwrap_or(&err);
            let one_line = !body.is_empty() && !body.contains('\n');
            let clean_chars = !body.chars().any(char::is_control);
            let end = if one_line && clean_chars && body.len() < 2000 && !body.contains("panicked")
            {
                t.clean_errors.fetch_add(1, Ordering::Relaxed);
                let skip = if t.kind_skip == 0 { 2 } else { t.kind_skip };
                let key: String = body
                    .splitn(skip + 1, ": ")
                    .nth(skip)
                    .unwrap_or(body)
                    .chars()
                    .take(36)
                    .collect();
                *t.kinds.lock().unwrap().entry(key).or_default() += 1;
                if std::env::var_os("RENDIFF_FUZZ_SHOW").is_some() {
                    eprintln!("{what}: {body}");
                }
                End::Refused
            } else {
                t.bad_messages.fetch_add(1, Ordering::Relaxed);
                problems.push(format!(
                    "{what}: exit 2 but stderr is not one clean line: {err:?}"
                ));
                End::Broken
            };
            let left = folder.map(files_under).unwrap_or_default();
            if !left.is_empty() {
                t.leftovers.fetch_add(1, Ordering::Relaxed);
                problems.push(format!("{what}: failed but left {left:?}"));
            }
            (end, err)
        }
        Outcome::Exited(code, err) => {
            if code == Some(101) || code.is_none() {
                t.panics.fetch_add(1, Ordering::Relaxed);
            } else {
                t.other_exits.fetch_add(1, Ordering::Relaxed);
            }
            let tail: String = err.chars().take(600).collect();
            problems.push(format!("{what}: exit {code:?}: {tail}"));
            (End::Broken, err)
        }
    }
}

/// Records a wrong verdict: the run ended cleanly, with the wrong answer.
fn wrong(t: &Tally, problems: &mut Vec<String>, why: String) {
    t.wrong_verdicts.fetch_add(1, Ordering::Relaxed);
    problems.push(why);
}

/// `rendiff render --renderer raster` of `scene` into `out/render/r.exr`.
fn render_cmd(scene: &Path, out: &Path) -> Command {
    let mut cmd = Command::new(binary());
    cmd.args([
        "render",
        "--renderer",
        "raster",
        "--quiet",
        "--threads",
        "1",
    ])
    .arg(scene)
    .arg("-o")
    .arg(out.join("render").join("r.exr"));
    cmd
}

/// `rendiff export` of `scene` into `out/export`.
fn export_cmd(scene: &Path, out: &Path) -> Command {
    let mut cmd = Command::new(binary());
    cmd.arg("export")
        .arg(scene)
        .arg("-o")
        .arg(out.join("export"));
    cmd
}

/// Runs one case through render and export; returns the problems found.
fn run_case(c: &Case, t: &Tally) -> Vec<String> {
    let dir = tempfile::tempdir().unwrap();
    let scene = write_case(dir.path(), c);
    let out = dir.path().join("out");
    let mut problems = Vec::new();
    render_and_export(&scene, &out, t, &mut problems);
    problems
}

/// `scene` through render and export into `out`, each judged: their ends,
/// and export's stderr.
fn render_and_export(
    scene: &Path,
    out: &Path,
    t: &Tally,
    problems: &mut Vec<String>,
) -> (End, End, String) {
    let render = run_limited(&mut render_cmd(scene, out));
    let (render, _) = judge(
        "render",
        render,
        Some(&out.join("render")),
        false,
        t,
        problems,
    );
    let export = run_limited(&mut export_cmd(scene, out));
    let (export, err) = judge(
        "export",
        export,
        Some(&out.join("export")),
        false,
        t,
        problems,
    );
    (render, export, err)
}

/// A number from the environment variable `var`, else `default`.
fn env_number<T: std::str::FromStr>(var: &str, default: T) -> T {
    std::env::var(var)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// A deterministic runner for `seed`.
fn seeded_runner(seed: u64) -> TestRunner {
    let mut seed_bytes = [0u8; 32];
    seed_bytes[..8].copy_from_slice(&seed.to_le_bytes());
    TestRunner::new_with_rng(
        Config {
            failure_persistence: None,
            ..Config::default()
        },
        TestRng::from_seed(RngAlgorithm::ChaCha, &seed_bytes),
    )
}

/// `n` values of `strategy`, generated up front (deterministic for a seed).
fn generate<S: Strategy>(strategy: S, n: usize, seed: u64) -> Vec<S::Value> {
    let mut runner = seeded_runner(seed);
    (0..n)
        .map(|_| strategy.new_tree(&mut runner).unwrap().current())
        .collect()
}

/// Runs `each` on every case on `workers` threads; returns each failing
/// case's index and problems, in order.
fn run_all<C: Sync>(
    all: &[C],
    workers: usize,
    tally: &Tally,
    each: impl Fn(&C, &Tally) -> Vec<String> + Sync,
) -> Vec<(usize, Vec<String>)> {
    let next = AtomicUsize::new(0);
    let failures: Mutex<Vec<(usize, Vec<String>)>> = Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..workers {
            s.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(c) = all.get(i) else { break };
                tally.inputs.fetch_add(1, Ordering::Relaxed);
                let problems = each(c, tally);
                if !problems.is_empty() {
                    failures.lock().unwrap().push((i, problems));
                }
            });
        }
    });
    let mut failures = failures.into_inner().unwrap();
    failures.sort_by_key(|f| f.0);
    failures
}

/// Prints a surface's table of counts by outcome and its clean errors by
/// kind (the part after the file name and field).
fn print_table(surface: &str, seed: u64, elapsed: Duration, t: &Tally) {
    let g = |a: &AtomicUsize| a.load(Ordering::Relaxed);
    eprintln!(
        "\n{surface} (seed {seed}, {:.1} s):\n\
         | inputs | runs | clean errors (exit 2, one line) | successes | failing verdicts (exit 1) | panics | hangs | leftovers | bad messages | other exits | wrong verdicts |\n\
         |---|---|---|---|---|---|---|---|---|---|---|\n\
         | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
        elapsed.as_secs_f64(),
        g(&t.inputs),
        g(&t.runs),
        g(&t.clean_errors),
        g(&t.successes),
        g(&t.failed_runs),
        g(&t.panics),
        g(&t.hangs),
        g(&t.leftovers),
        g(&t.bad_messages),
        g(&t.other_exits),
        g(&t.wrong_verdicts),
    );
    let mut kinds: Vec<_> = t.kinds.lock().unwrap().clone().into_iter().collect();
    kinds.sort_by_key(|k| std::cmp::Reverse(k.1));
    let kinds: Vec<String> = kinds
        .iter()
        .take(30)
        .map(|(k, n)| format!("{n} {k}"))
        .collect();
    eprintln!("clean errors by kind (top 30): {}", kinds.join("; "));
}

#[test]
fn hostile_scenes_fail_cleanly() {
    // The nested strategies are large values: generate on a big stack.
    std::thread::Builder::new()
        .stack_size(256 << 20)
        .spawn(fuzz)
        .unwrap()
        .join()
        .unwrap();
}

fn fuzz() {
    let cases: usize = env_number("RENDIFF_FUZZ_CASES", 2000);
    let seed: u64 = env_number("RENDIFF_FUZZ_SEED", 12);
    let all: Vec<Case> = generate(case(), cases, seed);
    let tally = Tally::default();
    let started = Instant::now();
    let failures = run_all(&all, 2, &tally, run_case);
    print_table("fuzz_scenes", seed, started.elapsed(), &tally);
    for (i, problems) in failures.iter().take(10) {
        let c = &all[*i];
        eprintln!(
            "--- case {i}:\n{}\nscene.toml:\n{}\nm.obj:\n{}\nn.obj:\n{}",
            problems.join("\n"),
            String::from_utf8_lossy(&c.scene).escape_debug(),
            c.m_obj.escape_debug(),
            c.n_obj.escape_debug()
        );
    }
    assert!(
        failures.is_empty(),
        "{} of {} cases failed (first ones above)",
        failures.len(),
        all.len()
    );
}
