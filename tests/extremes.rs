//! Numerical extremes: raster and trace must stay identical (bit for bit) on
//! scene families pushed to large offsets and scales, tiny near planes,
//! sub-pixel and sliver triangles, grazing views and geometry next to the eye.

mod common_scenes;

use common_scenes::*;
use glam::{DVec3, Vec3};
use rendiff::camera::Camera;
use rendiff::scene::generators::{grid, icosphere};
use rendiff::scene::resolve::{ResolvedScene, Tri};

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
