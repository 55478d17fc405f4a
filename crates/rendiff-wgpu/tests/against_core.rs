//! Runs the `rendiff-wgpu` binary on resolved scenes and compares its IDs and
//! depth with rendiff's core (`rendiff render --renderer trace`), pixel by
//! pixel. A pixel may differ only where the precision model allows it:
//! its center within `EDGE_PX` of an edge of one of the two triangles
//! involved (*edge*), and depth on the same triangle within
//! `DEPTH_RELATIVE * Z / |cos|`.
//!
//! Needs a Vulkan adapter (lavapipe: `apt-get install mesa-vulkan-drivers`)
//! and the `rendiff` binary (`cargo build --release -p rendiff`, found in
//! `$RENDIFF_BIN`, `$CARGO_TARGET_DIR/release` or `target/release`). Without
//! either it prints why and skips; set `RENDIFF_WGPU_REQUIRE=1` to make a
//! skip a failure (on machines that have both).

use rendiff_wgpu::camera::{self, View};
use rendiff_wgpu::output::read_exr;
use rendiff_wgpu::precision::{DEPTH_RELATIVE, EDGE_PX};
use rendiff_wgpu::scene;
use std::path::{Path, PathBuf};
use std::process::Command;

const BACKGROUND: u32 = u32::MAX;

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn rendiff_bin() -> Option<PathBuf> {
    let mut candidates = vec![];
    if let Some(p) = std::env::var_os("RENDIFF_BIN") {
        candidates.push(PathBuf::from(p));
    }
    if let Some(t) = std::env::var_os("CARGO_TARGET_DIR") {
        candidates.push(PathBuf::from(t).join("release/rendiff"));
    }
    candidates.push(repo_root().join("target/release/rendiff"));
    // The test binary lives in <target>/<profile>/deps.
    if let Ok(exe) = std::env::current_exe() {
        if let Some(target) = exe
            .parent()
            .and_then(|p| p.parent())
            .and_then(|p| p.parent())
        {
            candidates.push(target.join("release/rendiff"));
        }
    }
    candidates.into_iter().find(|p| p.is_file())
}

fn skip(reason: &str) {
    if std::env::var_os("RENDIFF_WGPU_REQUIRE").is_some() {
        panic!("RENDIFF_WGPU_REQUIRE is set but: {reason}");
    }
    eprintln!("SKIPPED: {reason}");
}

fn run(cmd: &mut Command) -> std::process::Output {
    cmd.output().expect("spawn")
}

/// Distance (px) from `(px, py)` to the segment `a`-`b`.
fn seg_dist(p: (f64, f64), a: (f64, f64), b: (f64, f64)) -> f64 {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    ((p.0 - a.0 - t * dx).powi(2) + (p.1 - a.1 - t * dy).powi(2)).sqrt()
}

/// Distance (px) from pixel center `p` to triangle `i`'s projected outline,
/// its edges clipped to the near plane first (infinite for the background).
fn edge_distance(view: &View, sc: &scene::Scene, i: u32, p: (f64, f64)) -> f64 {
    if i == BACKGROUND {
        return f64::INFINITY;
    }
    let m = view.view_projection(view.near);
    let clip: Vec<[f64; 4]> = sc
        .triangle(i as usize)
        .iter()
        .map(|v| camera::mul(&m, [f64::from(v[0]), f64::from(v[1]), f64::from(v[2]), 1.0]))
        .collect();
    let mut best = f64::INFINITY;
    for k in 0..3 {
        let (mut a, mut b) = (clip[k], clip[(k + 1) % 3]);
        // Keep the part with w >= near (planar depth in front of the near plane).
        let near = view.near;
        if a[3] < near && b[3] < near {
            continue;
        }
        let cut = |a: [f64; 4], b: [f64; 4]| {
            let t = (near - a[3]) / (b[3] - a[3]);
            [0, 1, 2, 3].map(|j| a[j] + t * (b[j] - a[j]))
        };
        if a[3] < near {
            a = cut(a, b);
        } else if b[3] < near {
            b = cut(b, a);
        }
        if let (Some(pa), Some(pb)) = (view.clip_to_pixel(a), view.clip_to_pixel(b)) {
            best = best.min(seg_dist(p, pa, pb));
        }
    }
    best
}

/// Planar depth of triangle `i`'s plane on pixel (x, y)'s ray (f64).
fn plane_depth(view: &View, sc: &scene::Scene, i: u32, x: u32, y: u32) -> f64 {
    let t = sc.triangle(i as usize).map(|v| v.map(f64::from));
    let n = camera::cross(camera::sub(t[1], t[0]), camera::sub(t[2], t[0]));
    camera::dot(n, camera::sub(t[0], view.eye)) / camera::dot(n, view.pixel_direction(x, y))
}

/// |cos| between pixel (x, y)'s ray and triangle `i`'s normal.
fn cos_at(view: &View, sc: &scene::Scene, i: u32, x: u32, y: u32) -> f64 {
    let t = sc.triangle(i as usize).map(|v| v.map(f64::from));
    let n = camera::cross(camera::sub(t[1], t[0]), camera::sub(t[2], t[0]));
    let d = view.pixel_direction(x, y);
    (camera::dot(n, d) / (camera::dot(n, n).sqrt() * camera::dot(d, d).sqrt())).abs()
}

#[derive(Debug, Default)]
struct Tally {
    pixels: usize,
    same: usize,
    covered: usize,
    edge: usize,
    tie: usize,
    interior: Vec<String>,
    bad_object: usize,
    depth_fail: Vec<String>,
    max_rel_depth: f64,
    max_edge_dist: f64,
}

fn compare_scene(toml: &str, also_chunked: Option<usize>) {
    let Some(rendiff) = rendiff_bin() else {
        skip("rendiff binary not built (cargo build --release -p rendiff)");
        return;
    };
    let root = repo_root();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("scene");
    let scene_toml = root.join(toml);
    let out = run(Command::new(&rendiff)
        .arg("export")
        .arg(&scene_toml)
        .arg("-o")
        .arg(&dir));
    assert!(
        out.status.success(),
        "rendiff export: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let core_exr = tmp.path().join("core.exr");
    let out = run(Command::new(&rendiff)
        .args([
            "render",
            "--renderer",
            "trace",
            "--no-preview",
            "--quiet",
            "-o",
        ])
        .arg(&core_exr)
        .arg(&scene_toml));
    assert!(
        out.status.success(),
        "rendiff render: {}",
        String::from_utf8_lossy(&out.stderr)
    );

    let wgpu_exr = tmp.path().join("out/wgpu.exr");
    let t0 = std::time::Instant::now();
    let out = run(Command::new(env!("CARGO_BIN_EXE_rendiff-wgpu"))
        .arg("--scene")
        .arg(&dir)
        .arg("--out")
        .arg(&wgpu_exr));
    let secs = t0.elapsed().as_secs_f64();
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    if out.status.code() == Some(3) {
        skip(stderr.trim());
        return;
    }
    assert!(
        out.status.success(),
        "rendiff-wgpu failed ({:?}): {stderr}",
        out.status
    );
    assert!(
        stderr.trim().is_empty(),
        "a successful render prints nothing, got: {stderr}"
    );

    let sc = scene::load(&dir).unwrap();
    let view = View::from_json(&sc.camera);
    let core = read_exr(&core_exr).unwrap();
    let gpu = read_exr(&wgpu_exr).unwrap();
    assert_eq!((gpu.width, gpu.height), (core.width, core.height));
    assert_eq!(gpu.attrs.get("renderer").map(String::as_str), Some("wgpu"));
    let leftovers = std::fs::read_dir(tmp.path().join("out")).unwrap().count();
    assert_eq!(leftovers, 1, "no temporary file left next to the EXR");

    let mut t = Tally::default();
    for y in 0..view.height {
        for x in 0..view.width {
            let i = (y * view.width + x) as usize;
            t.pixels += 1;
            let (pc, pg) = (core.prim[i], gpu.prim[i]);
            // Objects follow prims.
            let expect_obj = if pg == BACKGROUND {
                BACKGROUND
            } else {
                sc.object_ids[pg as usize]
            };
            if gpu.object[i] != expect_obj {
                t.bad_object += 1;
            }
            if pg == BACKGROUND && !gpu.z[i].is_infinite() {
                t.depth_fail
                    .push(format!("({x},{y}) background with Z {}", gpu.z[i]));
            }
            if pg != BACKGROUND {
                t.covered += 1;
            }
            if pc == pg {
                t.same += 1;
                if pg != BACKGROUND {
                    let (zc, zg) = (f64::from(core.z[i]), f64::from(gpu.z[i]));
                    let cos = cos_at(&view, &sc, pg, x, y);
                    let tol = zc * (DEPTH_RELATIVE / cos.max(DEPTH_RELATIVE / 1e-3));
                    let rel = (zg - zc).abs() / zc;
                    t.max_rel_depth = t.max_rel_depth.max(rel * cos);
                    if (zg - zc).abs() > tol {
                        t.depth_fail.push(format!(
                            "({x},{y}) prim {pg}: Z {zg} vs core {zc} (cos {cos:.3})"
                        ));
                    }
                }
                continue;
            }
            let p = (f64::from(x) + 0.5, f64::from(y) + 0.5);
            let d = edge_distance(&view, &sc, pc, p).min(edge_distance(&view, &sc, pg, p));
            let tie = pc != BACKGROUND && pg != BACKGROUND && {
                let (zc, zg) = (
                    plane_depth(&view, &sc, pc, x, y),
                    plane_depth(&view, &sc, pg, x, y),
                );
                let cos = cos_at(&view, &sc, pc, x, y).min(cos_at(&view, &sc, pg, x, y));
                (zc - zg).abs()
                    <= zc.abs()
                        * (DEPTH_RELATIVE / cos.max(DEPTH_RELATIVE / 1e-3) + 2.0 * 2f64.powi(-24))
            };
            if d <= EDGE_PX {
                t.edge += 1;
                t.max_edge_dist = t.max_edge_dist.max(d);
            } else if tie {
                t.tie += 1;
            } else {
                t.interior.push(format!(
                    "({x},{y}) core {pc} wgpu {pg}: {d:.3e} px from an edge"
                ));
            }
        }
    }
    eprintln!(
        "{toml}: {} pixels ({} covered by wgpu), {} identical IDs, {} differ: {} edge (within {EDGE_PX} px; farthest {:.2e} px), {} tie, {} interior; \
         depth on shared prims: max |dZ|/Z*|cos| = {:.3e} (allowed {DEPTH_RELATIVE:e}); \
         wgpu wall time {secs:.3} s",
        t.pixels,
        t.covered,
        t.same,
        t.pixels - t.same,
        t.edge,
        t.max_edge_dist,
        t.tie,
        t.interior.len(),
        t.max_rel_depth,
    );
    assert!(
        t.interior.is_empty(),
        "interior mismatches: {:?}",
        &t.interior[..t.interior.len().min(10)]
    );
    assert!(
        t.depth_fail.is_empty(),
        "depth out of tolerance: {:?}",
        &t.depth_fail[..t.depth_fail.len().min(10)]
    );
    assert_eq!(t.bad_object, 0, "id.object must be object_ids[id.prim]");

    if let Some(chunk) = also_chunked {
        // Small draw calls: split draws give the same bits.
        let chunked_exr = tmp.path().join("out/chunked.exr");
        let out = run(Command::new(env!("CARGO_BIN_EXE_rendiff-wgpu"))
            .arg("--scene")
            .arg(&dir)
            .arg("--out")
            .arg(&chunked_exr)
            .arg("--chunk-triangles")
            .arg(chunk.to_string()));
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let c = read_exr(&chunked_exr).unwrap();
        assert_eq!(c.prim, gpu.prim);
        assert_eq!(c.object, gpu.object);
        let bits = |v: &[f32]| v.iter().map(|z| z.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&c.z), bits(&gpu.z));
    }
}

#[test]
fn three_triangles_matches_the_core() {
    compare_scene("scenes/three_triangles.toml", Some(1));
}

#[test]
fn pixel_grid_matches_the_core() {
    compare_scene("scenes/pixel_grid.toml", Some(7));
}

/// The real-asset corpus (slower; run with `--ignored`): scans, CAD parts,
/// slivers, a mesh far from the origin, duplicated surfaces.
#[test]
#[ignore]
fn corpus_scenes_match_the_core() {
    for name in [
        "demosthenes_scan",
        "mountain_terrain",
        "spot_far_from_origin",
        "spot_duplicated",
        "sword_quads_sliver",
        "rj11_cad_part",
        "wingnut_part",
        "plane_cabin_interior",
        "hand_inside_open",
        "control_meshes_ngons",
    ] {
        compare_scene(&format!("scenes/corpus/{name}.toml"), None);
    }
}

/// 1.3M triangles (slower; run with `--ignored`), also drawn in 14 chunks.
#[test]
#[ignore]
fn million_triangles_match_the_core() {
    compare_scene("scenes/million.toml", Some(100_000));
}

/// The camera calibration probes: tilted planes, a near plane of 1e-4 and a
/// finite far plane.
#[test]
fn calibration_probes_match_the_core() {
    compare_scene("scenes/calibration/camera_near.toml", None);
    compare_scene("scenes/calibration/camera_far.toml", None);
}
