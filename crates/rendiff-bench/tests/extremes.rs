//! Numerical extremes: raster and trace must stay identical (bit for bit) on
//! scene families pushed to large offsets and scales, tiny near planes,
//! sub-pixel and sliver triangles, grazing views and geometry next to the eye.

#[path = "../../../tests/common/scenes.rs"]
mod common_scenes;

use common_scenes::*;
use glam::{DVec3, Vec3};
use rendiff::camera::Camera;
use rendiff::scene::generators::{grid, icosphere};
use rendiff::scene::resolve::{ResolvedScene, Tri};
use rendiff_bench::stability::{families, judge};

fn to_f32(t: &[[DVec3; 3]], scale: f64, offset: DVec3) -> Vec<Tri> {
    t.iter()
        .map(|tri| tri.map(|v| (v * scale + offset).as_vec3()))
        .collect()
}

/// An icosphere over a ground grid, the camera looking at it from a fixed relative position.
fn family(scale: f64, offset: DVec3, near_ratio: f64) -> ResolvedScene {
    let mut tris = icosphere(2, 1.0);
    tris.extend(
        grid([-3.0, -3.0], [3.0, 3.0], 6, 6)
            .iter()
            .map(|t| t.map(|v| DVec3::new(v.x, -1.0, v.y))),
    );
    let eye = DVec3::new(1.3, 0.9, 3.1) * scale + offset;
    let at = offset;
    let dist = (eye - at).length();
    let cam = Camera::new(
        eye,
        at,
        DVec3::Y,
        45.0,
        48,
        36,
        dist * near_ratio,
        f64::INFINITY,
    )
    .unwrap();
    let f32_tris = to_f32(&tris, scale, offset);
    let mut s = ResolvedScene::from_triangles(cam, f32_tris);
    // Rounding to f32 at extreme offsets can collapse triangles; they must simply never show.
    s.degenerate = s
        .triangles
        .iter()
        .map(rendiff::scene::resolve::is_degenerate)
        .collect();
    s
}

fn check(what: &str, scene: &ResolvedScene) -> usize {
    let (r, t) = both(scene, true);
    assert_identical(what, &r, &t);
    assert_eq!(r.coverage, t.coverage, "{what}: coverage counts differ");
    r.prim.iter().filter(|&&p| p != u32::MAX).count()
}

#[test]
fn translation_offsets_from_1_to_1e7() {
    for k in 0..=7 {
        let off = DVec3::new(1.0, -0.5, 0.25) * 10f64.powi(k);
        let hits = check(&format!("offset 1e{k}"), &family(1.0, off, 1e-4));
        assert!(hits > 100, "offset 1e{k}: {hits} hits");
    }
}

#[test]
fn scales_from_1e_minus_6_to_1e6() {
    for k in -6..=6 {
        let s = 10f64.powi(k);
        let hits = check(&format!("scale 1e{k}"), &family(s, DVec3::ZERO, 1e-4));
        assert!(hits > 100, "scale 1e{k}: {hits} hits");
    }
}

#[test]
fn near_far_ratios_down_to_1e_minus_7() {
    for k in 1..=7 {
        check(
            &format!("near 1e-{k}"),
            &family(1.0, DVec3::ZERO, 10f64.powi(-k)),
        );
    }
}

#[test]
fn sub_pixel_and_sliver_triangles() {
    let cam = exact_camera(32);
    let mut tris = Vec::new();
    // Sub-pixel triangles scattered over the image.
    for i in 0..200 {
        let x = -0.9 + 1.8 * ((i * 37 % 200) as f32 / 200.0);
        let y = -0.9 + 1.8 * ((i * 91 % 200) as f32 / 200.0);
        let s = 0.003 * (1 + i % 5) as f32;
        tris.push(tri([x, y, -0.1], [x + s, y, -0.1], [x, y + s, -0.1]));
    }
    // Slivers with aspect ratios up to 1e6.
    for k in 0..7 {
        let h = 10f32.powi(-k);
        let y = -0.8 + 0.25 * k as f32;
        tris.push(tri([-0.95, y, 0.0], [0.95, y + h, 0.0], [0.95, y, 0.0]));
    }
    let scene = ResolvedScene::from_triangles(cam, tris);
    check("sub-pixel and slivers", &scene);
}

#[test]
fn grazing_views() {
    for k in 1..=6 {
        let tilt = 10f64.powi(-k);
        let cam = Camera::new(
            DVec3::new(0.0, tilt, 5.0),
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::Y,
            40.0,
            48,
            36,
            1e-4,
            f64::INFINITY,
        )
        .unwrap();
        let floor = grid([-4.0, -4.0], [4.0, 4.0], 16, 16)
            .iter()
            .map(|t| t.map(|v| Vec3::new(v.x as f32, 0.0, v.y as f32)))
            .collect();
        check(
            &format!("grazing 1e-{k}"),
            &ResolvedScene::from_triangles(cam, floor),
        );
    }
}

#[test]
fn geometry_next_to_the_eye() {
    for k in 3..=7 {
        let d = 10f32.powi(-k);
        let mut cam = exact_camera(16);
        cam.near = f64::from(d) * 0.5;
        let t = tri([-d, -d, 1.0 - d], [d, -d, 1.0 - d], [0.0, d, 1.0 - d]);
        let far = tri([-2.0, -2.0, -1.0], [2.0, -2.0, -1.0], [0.0, 2.0, -1.0]);
        check(
            &format!("1e-{k} from the eye"),
            &ResolvedScene::from_triangles(cam, vec![t, far]),
        );
    }
}

/// Parses and resolves a generated scene text.
fn from_toml(name: &str, text: &str) -> ResolvedScene {
    let path = std::path::Path::new(name);
    let s = rendiff::scene::Scene::parse(path, text).unwrap_or_else(|e| panic!("{e}"));
    ResolvedScene::resolve(&s).unwrap_or_else(|e| panic!("{e}"))
}

/// The fill-rule family (`bench stability`'s pixel-center scenes): every
/// vertex sits exactly on a pixel center after rounding to f32, both loops
/// agree bit for bit, and every pixel strictly inside a mesh is covered exactly
/// once (no crack, no double coverage) with the ties all decided by the rule.
#[test]
fn pixel_center_family_is_watertight_at_every_size_and_offset() {
    let mut cases: Vec<(u32, [f64; 3])> = [16, 64, 256].map(|w| (w, [0.0; 3])).to_vec();
    for k in 0..=5 {
        let o = 10f64.powi(k);
        cases.push((64, [o, -o, o]));
    }
    for (w, off) in cases {
        let what = format!("pixel centers {w} px, offset {}", off[0]);
        let (text, layout) = families::pixel_centers_scene(w, off);
        let scene = from_toml("pixel_centers.toml", &text);
        let wf = f64::from(w);
        for v in scene.triangles.iter().flatten() {
            let i = (f64::from(v.x) - off[0] + 1.0) * wf / 2.0 - 0.5;
            let j = (1.0 - (f64::from(v.y) - off[1])) * wf / 2.0 - 0.5;
            assert!(
                i.fract() == 0.0 && j.fract() == 0.0 && f64::from(v.z) == off[2],
                "{what}: vertex {v} is not on a pixel center"
            );
        }
        let (r, t) = both(&scene, true);
        assert_identical(&what, &r, &t);
        assert_eq!(r.coverage, t.coverage, "{what}: coverage counts differ");
        let (broken, stats) = judge::fill_rule_coverage(&layout, &r);
        assert!(broken.is_none(), "{what}: {broken:?} {stats}");
        let inside = (0..w * w).filter(|p| layout.inside(p % w, p / w)).count();
        assert!(
            inside > (w * w / 4) as usize,
            "{what}: only {inside} pixels inside"
        );
        assert!(
            r.counters.ties >= u64::from(w * w / 4),
            "{what}: {} ties: the centers are not on the edges",
            r.counters.ties
        );
    }
}

/// Coplanar overlaps and duplicates at offsets up to 1e5: wherever the truth
/// has an exact tie, the lower id wins, in both loops, bit for bit.
#[test]
fn coplanar_overlaps_go_to_the_lower_id() {
    for k in [0, 3, 5] {
        let o = 10f64.powi(k);
        let what = format!("coplanar at offset 1e{k}");
        let scene = from_toml("coplanar.toml", &families::coplanar_scene([o, o, -o]));
        let (r, t) = both(&scene, false);
        assert_identical(&what, &r, &t);
        let truth = judge::truth(&scene);
        let ties = truth
            .pixels
            .iter()
            .flatten()
            .filter(|p| !p.ties.is_empty())
            .count();
        assert!(ties > 100, "{what}: only {ties} tie pixels judged");
        let ids = judge::Ids {
            width: r.width as usize,
            prim: &r.prim,
        };
        let (broken, stats) =
            judge::judge_truth(&truth, &ids, "raster", &serde_json::Value::Null, true);
        assert!(broken.is_none(), "{what}: {broken:?} {stats}");
    }
}

/// Near-coplanar planes from 1e-1 to 1e-9 of the distance apart, and a
/// triangle 1e-1 to 1e-7 from the eye: both loops agree bit for bit, and the
/// nearer surface wins wherever its lead exceeds one f32 spacing of depth.
#[test]
fn zfighting_and_geometry_next_to_the_eye_follow_the_truth() {
    let mut cases = Vec::new();
    for k in 1..=9 {
        let r = 10f64.powi(-k);
        cases.push((
            format!("z-fighting 1e-{k}"),
            families::zfight_scene(r),
            false,
        ));
    }
    for k in 1..=7 {
        let d = 10f64.powi(-k);
        cases.push((
            format!("1e-{k} from the eye"),
            families::near_eye_scene(d),
            true,
        ));
    }
    for (what, text, ties_break) in cases {
        let scene = from_toml("case.toml", &text);
        let (r, t) = both(&scene, false);
        assert_identical(&what, &r, &t);
        let truth = judge::truth(&scene);
        let ids = judge::Ids {
            width: r.width as usize,
            prim: &r.prim,
        };
        let (broken, stats) =
            judge::judge_truth(&truth, &ids, "raster", &serde_json::Value::Null, ties_break);
        assert!(broken.is_none(), "{what}: {broken:?} {stats}");
        assert!(
            stats["judged_pixels"].as_u64().unwrap() > 500,
            "{what}: {stats}"
        );
    }
}
