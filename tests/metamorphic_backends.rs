//! Metamorphic relations on every backend (issue 6, item 5; docs/metamorphic.md).
//!
//! One base scene (an icosphere, a box in front of it, a tilted backdrop) and
//! one variant per relation: flipped winding, reordered triangles and objects,
//! every triangle split at an edge midpoint, scene and camera translated
//! together, scene and camera scaled by 2^6 about the eye. Vertices lie on a
//! 2^-10 grid, so every variant is the exact transform of the base in f32 and
//! any difference is the renderer's own. All scenes go through `rendiff check`
//! (every backend, with its timeouts and skip rules); then
//! `python -m rendiff_harness metamorphic` compares each backend's variant with
//! the same backend's base, IDs mapped back, against the bound stated for that
//! relation and backend (harness/rendiff_harness/judge/metamorphic.py). One test per
//! (relation, backend, buffer); skipped ones show as ignored with the reason.
//!
//! The core's own relations are also held exactly by proptest in
//! tests/metamorphic.rs; here raster and trace are one more row of the matrix.

use glam::{DMat3, DVec3};
use libtest_mimic::{Arguments, Failed, Trial};
use rendiff::check::{self, process, CheckOptions};
use rendiff::scene::generators::{cube, grid, icosphere, Tri64};
use serde_json::{json, Value};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Grid every vertex lies on: sums, midpoints and power-of-two scales stay exact in f32.
const GRID: f64 = 1024.0;
/// Translation of scene and camera (about 3x the scene's depth; exact on the grid).
const OFFSET: [f64; 3] = [12.5, -6.25, 9.75];
/// Scale of scene and camera about the eye (the eye is at the origin).
const SCALE: f64 = 64.0;
const LOOK_AT: [f64; 3] = [0.25, 0.125, -4.5];
const NEAR: f64 = 1.0 / 1024.0;

fn snap(v: DVec3) -> DVec3 {
    (v * GRID).round() / GRID
}

/// The base scene's objects, world space, on the grid.
fn base_objects() -> Vec<(&'static str, Vec<Tri64>)> {
    let place = |tris: Vec<Tri64>, rot: DMat3, at: DVec3| -> Vec<Tri64> {
        tris.into_iter()
            .map(|t| t.map(|v| snap(rot * v + at)))
            .collect()
    };
    let sphere = place(
        icosphere(2, 1.0),
        DMat3::from_rotation_y(0.3),
        DVec3::new(0.3, 0.15, -4.5),
    );
    let boxy = place(
        cube(DVec3::splat(-0.4), DVec3::splat(0.4), false),
        DMat3::from_rotation_y(0.6) * DMat3::from_rotation_x(0.4),
        DVec3::new(-0.7, -0.35, -3.3),
    );
    let backdrop = place(
        grid([-3.0, -2.0], [3.0, 2.0], 6, 4),
        DMat3::from_rotation_y(-0.35),
        DVec3::new(0.0, 0.0, -7.5),
    );
    vec![("sphere", sphere), ("box", boxy), ("backdrop", backdrop)]
}

/// One scene of the family, and how its IDs map back to the base's.
struct Variant {
    relation: &'static str,
    objects: Vec<(&'static str, Vec<Tri64>)>,
    eye: DVec3,
    look_at: DVec3,
    near: f64,
    /// Variant prim -> base prim.
    prim_map: Vec<u32>,
    /// Variant object -> base object.
    object_map: Vec<u32>,
    /// Variant depth = base depth x this.
    depth_scale: f64,
    what: &'static str,
}

fn identity(n: usize) -> Vec<u32> {
    (0..n as u32).collect()
}

fn map_tris(
    objects: &[(&'static str, Vec<Tri64>)],
    f: impl Fn(&Tri64) -> Tri64,
) -> Vec<(&'static str, Vec<Tri64>)> {
    objects
        .iter()
        .map(|(n, t)| (*n, t.iter().map(&f).collect()))
        .collect()
}

/// A permutation of 0..n from a seed (xorshift Fisher-Yates).
fn permutation(n: usize, seed: u64) -> Vec<usize> {
    let mut order: Vec<usize> = (0..n).collect();
    let mut s = seed | 1;
    for i in (1..n).rev() {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        order.swap(i, (s % (i as u64 + 1)) as usize);
    }
    order
}

fn variants() -> Vec<Variant> {
    let base = base_objects();
    let n: usize = base.iter().map(|(_, t)| t.len()).sum();
    let look = DVec3::from(LOOK_AT);
    let plain = |relation, objects, prim_map, what| Variant {
        relation,
        objects,
        eye: DVec3::ZERO,
        look_at: look,
        near: NEAR,
        prim_map,
        object_map: identity(base.len()),
        depth_scale: 1.0,
        what,
    };
    let mut out = vec![plain("base", base.clone(), identity(n), "the base scene")];
    out.push(plain(
        "flip_winding",
        map_tris(&base, |t| [t[0], t[2], t[1]]),
        identity(n),
        "every triangle's winding flipped",
    ));

    // Reorder: objects in reverse order, triangles shuffled inside each.
    let firsts: Vec<u32> = base
        .iter()
        .scan(0u32, |acc, (_, t)| {
            let f = *acc;
            *acc += t.len() as u32;
            Some(f)
        })
        .collect();
    let mut objects = Vec::new();
    let mut prim_map = Vec::new();
    let mut object_map = Vec::new();
    for (oi, (name, tris)) in base.iter().enumerate().rev() {
        let order = permutation(tris.len(), 0x9e37_79b9_7f4a_7c15 ^ oi as u64);
        objects.push((*name, order.iter().map(|&i| tris[i]).collect()));
        prim_map.extend(order.iter().map(|&i| firsts[oi] + i as u32));
        object_map.push(oi as u32);
    }
    out.push(Variant {
        object_map,
        ..plain(
            "reorder",
            objects,
            prim_map,
            "objects reversed, triangles shuffled within each (IDs permuted to match)",
        )
    });

    // Split: every triangle into two at the midpoint of its first edge (exact on the grid).
    let mut objects = Vec::new();
    let mut prim_map = Vec::new();
    let mut next = 0u32;
    for (name, tris) in &base {
        let mut halves = Vec::new();
        for t in tris {
            let m = (t[0] + t[1]) * 0.5;
            halves.push([t[0], m, t[2]]);
            halves.push([m, t[1], t[2]]);
            prim_map.extend([next, next]);
            next += 1;
        }
        objects.push((*name, halves));
    }
    out.push(plain(
        "split",
        objects,
        prim_map,
        "every triangle split in two at its first edge's midpoint (both halves map to the parent)",
    ));

    let off = DVec3::from(OFFSET);
    out.push(Variant {
        eye: off,
        look_at: look + off,
        ..plain(
            "translate",
            map_tris(&base, |t| t.map(|v| v + off)),
            identity(n),
            "scene and camera translated by (12.5, -6.25, 9.75)",
        )
    });
    out.push(Variant {
        look_at: look * SCALE,
        near: NEAR * SCALE,
        depth_scale: SCALE,
        ..plain(
            "scale",
            map_tris(&base, |t| t.map(|v| v * SCALE)),
            identity(n),
            "scene and camera scaled by 64 about the eye",
        )
    });
    out
}

fn v3(v: DVec3) -> String {
    format!("[{:?}, {:?}, {:?}]", v.x, v.y, v.z)
}

fn scene_toml(v: &Variant) -> String {
    let mut s = format!(
        "# metamorphic family ({}): {}\nrequires = [\"depth\", \"ids\"]\n\n[camera]\neye = {}\nlook_at = {}\nvfov = 45.0\nwidth = 96\nheight = 72\nnear = {:?}\n",
        v.relation,
        v.what,
        v3(v.eye),
        v3(v.look_at),
        v.near
    );
    for (name, tris) in &v.objects {
        let verts: Vec<String> = tris.iter().flatten().map(|p| v3(*p)).collect();
        let _ = write!(
            s,
            "\n[[objects]]\nname = \"{name}\"\nshape = {{ kind = \"triangles\", vertices = [{}] }}\n",
            verts.join(", ")
        );
    }
    s
}

fn scene_name(relation: &str) -> String {
    format!("meta_{relation}")
}

/// The premise of the family: every number is exact in f32, so resolution
/// rounds nothing and the variant is the exact transform of the base.
fn exact_in_f32(v: &Variant) -> Result<(), String> {
    let points = v.objects.iter().flat_map(|(_, t)| t.iter().flatten());
    for p in points.chain([&v.eye, &v.look_at]) {
        if p.to_array().iter().any(|&x| f64::from(x as f32) != x) {
            return Err(format!("{}: {p} is not exact in f32", v.relation));
        }
    }
    Ok(())
}

/// Writes the scenes and the spec the harness reads; returns the scene files.
fn write_family(dir: &Path, spec: &Path) -> Result<Vec<PathBuf>, String> {
    std::fs::create_dir_all(dir).map_err(|e| e.to_string())?;
    let vs = variants();
    let mut files = Vec::new();
    let mut cases = Vec::new();
    for v in &vs {
        exact_in_f32(v)?;
        let p = dir.join(format!("{}.toml", scene_name(v.relation)));
        std::fs::write(&p, scene_toml(v)).map_err(|e| format!("{}: {e}", p.display()))?;
        files.push(p);
        if v.relation != "base" {
            cases.push(json!({
                "relation": v.relation,
                "description": v.what,
                "base": scene_name("base"),
                "variant": scene_name(v.relation),
                "prim_map": v.prim_map,
                "object_map": v.object_map,
                "depth_scale": v.depth_scale,
            }));
        }
    }
    let doc = json!({"format": "rendiff-metamorphic-spec/1", "cases": cases});
    std::fs::write(
        spec,
        serde_json::to_vec_pretty(&doc).map_err(|e| e.to_string())?,
    )
    .map_err(|e| format!("{}: {e}", spec.display()))?;
    Ok(files)
}

/// Runs the family through `rendiff check`, then the harness's metamorphic comparison.
fn run_family(root: &Path, run_dir: &Path) -> Result<Vec<Value>, String> {
    // The inputs live beside the run folder: `check` replaces the run folder
    // with the finished run, so nothing it did not write may be kept in it.
    let inputs = run_dir.with_file_name("metamorphic-inputs");
    let _ = std::fs::remove_dir_all(&inputs);
    std::fs::create_dir_all(&inputs).map_err(|e| e.to_string())?;
    let spec = inputs.join("metamorphic-spec.json");
    let scenes = write_family(&inputs.join("scene-files"), &spec)?;
    let none = inputs.join("no-expectations.toml");
    std::fs::write(
        &none,
        "# the relations are judged by the metamorphic comparison\n",
    )
    .map_err(|e| e.to_string())?;
    let opts = CheckOptions {
        scenes,
        run_dir: run_dir.to_path_buf(),
        root: root.to_path_buf(),
        only: None,
        timeout: Duration::from_secs(120),
        expectations: none,
        quiet: true,
        references: None,
        core: check::CoreShading::default(),
        // No calibration probes: each backend is compared with itself, so its camera offset cancels.
        calibration: None,
        jobs: check::default_jobs(),
        wait_slots: check::default_jobs(),
        workers: true,
        renderers: None,
        renderers_snapshot: None,
        memory_budget: check::pool::default_memory_budget(),
    };
    check::run(&opts).map_err(|e| format!("rendiff check failed: {e:#}"))?;
    let out = run_dir.join("metamorphic.json");
    let mut cmd = std::process::Command::new(check::python(root));
    cmd.current_dir(root)
        .env("PYTHONPATH", root.join("harness"))
        .args(["-m", "rendiff_harness", "metamorphic", "--run"])
        .arg(run_dir)
        .arg("--spec")
        .arg(&spec)
        .arg("--expectations")
        .arg(root.join("tests/metamorphic_expectations.toml"))
        .arg("--out")
        .arg(&out);
    let o = process::run_with_timeout(cmd, Duration::from_secs(300), &run_dir.join("scratch/meta"))
        .map_err(|e| format!("cannot run the metamorphic comparison: {e:#}"))?;
    eprint!("{}", o.stdout);
    if o.timed_out || o.code != Some(0) {
        return Err(format!(
            "python -m rendiff_harness metamorphic failed (exit {:?}): {}",
            o.code,
            o.stderr_tail(12)
        ));
    }
    let text = std::fs::read_to_string(&out).map_err(|e| format!("{}: {e}", out.display()))?;
    let doc: Value =
        serde_json::from_str(&text).map_err(|e| format!("{}: unreadable: {e}", out.display()))?;
    Ok(doc["results"].as_array().cloned().unwrap_or_default())
}

fn trial(e: Value) -> Trial {
    let s = |k: &str| e[k].as_str().unwrap_or("?").to_string();
    let status = s("status");
    let key = format!(
        "metamorphic::{}::{}::{}",
        s("relation"),
        s("backend"),
        s("buffer")
    );
    let skipped = status == "skipped";
    let name = if skipped {
        format!("{key} (skipped: {})", s("reason"))
    } else {
        key
    };
    Trial::test(name, move || match status.as_str() {
        "pass" | "expected_fail" | "skipped" => Ok(()),
        _ => Err(Failed::from(format!(
            "{status}: {}\n{}",
            e["reason"].as_str().unwrap_or(""),
            serde_json::to_string_pretty(&e).unwrap_or_default()
        ))),
    })
    .with_ignored_flag(skipped)
}

fn main() {
    let args = Arguments::from_args();
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let run_dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("metamorphic-run");
    let trials = if args.list {
        // Listing must not render anything.
        vec![Trial::test("metamorphic::all", || Ok(()))]
    } else {
        let _ = std::fs::remove_dir_all(&run_dir);
        match run_family(&root, &run_dir) {
            Err(msg) => vec![Trial::test("metamorphic::harness", move || {
                Err(Failed::from(msg))
            })],
            Ok(results) => {
                eprintln!("run folder: {}", run_dir.display());
                results.into_iter().map(trial).collect()
            }
        }
    };
    libtest_mimic::run(&args, trials).exit();
}
