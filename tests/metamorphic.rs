//! Metamorphic relations of the core: transformations of the input that must
//! not change depth or IDs. Where the arithmetic is exact (winding flips,
//! reordering, power-of-two scales about the eye), the core is held to exact
//! equality. Translating scene and camera together is not exact: the
//! image-plane point `P = eye + d` is rounded at the eye's magnitude, so IDs may
//! change only at centers within 1e-6 px of an edge and depth by 1e-6 relative.
//! The same relations on every backend: tests/metamorphic_backends.rs.

mod common;

use common::scenes::*;
use glam::{DVec3, Vec3};
use proptest::prelude::*;
use rendiff::camera::Camera;
use rendiff::frame::Frame;
use rendiff::scene::resolve::{ResolvedScene, Tri};

fn camera_at(eye: DVec3, look_at: DVec3, w: u32) -> Camera {
    Camera::new(
        eye,
        look_at,
        DVec3::Y,
        60.0,
        w,
        w * 3 / 4,
        1e-3,
        f64::INFINITY,
    )
    .unwrap()
}

/// Dyadic coordinates (multiples of 1/64 in [-2, 2]) keep translations and power-of-two scales exact.
fn dyadic() -> impl Strategy<Value = f32> {
    (-128i32..=128).prop_map(|k| k as f32 / 64.0)
}

fn arb_tri() -> impl Strategy<Value = Tri> {
    [
        [dyadic(), dyadic(), dyadic()],
        [dyadic(), dyadic(), dyadic()],
        [dyadic(), dyadic(), dyadic()],
    ]
    .prop_map(|[a, b, c]| [Vec3::from(a), Vec3::from(b), Vec3::from(c)])
}

fn render(cam: Camera, tris: Vec<Tri>) -> Frame {
    let scene = ResolvedScene::from_triangles(cam, tris);
    let (r, t) = both(&scene, false);
    assert_identical("metamorphic", &r, &t);
    r
}

fn same_depth_bits(a: &Frame, b: &Frame) -> bool {
    a.z.iter()
        .zip(&b.z)
        .all(|(x, y)| x.to_bits() == y.to_bits())
}

/// Distance in pixels from (x, y) to the nearest edge of the triangle's projection
/// (triangles here lie in front of the camera).
fn edge_distance_px(cam: &Camera, t: &Tri, x: f64, y: f64) -> f64 {
    let p: Vec<(f64, f64)> = t
        .iter()
        .map(|v| cam.camera_to_pixel(cam.to_camera(v.as_dvec3())))
        .collect();
    (0..3)
        .map(|i| {
            let (a, b) = (p[i], p[(i + 1) % 3]);
            let (dx, dy) = (b.0 - a.0, b.1 - a.1);
            let len2 = dx * dx + dy * dy;
            let u = if len2 > 0.0 {
                (((x - a.0) * dx + (y - a.1) * dy) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            ((a.0 + u * dx - x).powi(2) + (a.1 + u * dy - y).powi(2)).sqrt()
        })
        .fold(f64::INFINITY, f64::min)
}

fn eye() -> DVec3 {
    DVec3::new(0.75, 0.5, 5.0)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn flipping_winding_changes_nothing(tris in prop::collection::vec(arb_tri(), 1..10)) {
        let flipped: Vec<Tri> = tris.iter().map(|t| [t[0], t[2], t[1]]).collect();
        let a = render(camera_at(eye(), DVec3::ZERO, 40), tris);
        let b = render(camera_at(eye(), DVec3::ZERO, 40), flipped);
        prop_assert_eq!(&a.prim, &b.prim);
        prop_assert!(same_depth_bits(&a, &b));
    }

    #[test]
    fn translating_scene_and_camera_together_changes_only_edge_pixels(
        tris in prop::collection::vec(arb_tri(), 1..10),
        k in (-64i32..=64, -64i32..=64, -64i32..=64),
    ) {
        let off = Vec3::new(k.0 as f32 * 2.0, k.1 as f32 * 2.0, k.2 as f32 * 2.0);
        let moved: Vec<Tri> = tris.iter().map(|t| t.map(|v| v + off)).collect();
        let cam = camera_at(eye(), DVec3::ZERO, 40);
        let a = render(cam.clone(), tris.clone());
        let b = render(camera_at(eye() + off.as_dvec3(), off.as_dvec3(), 40), moved);
        for i in 0..a.prim.len() {
            let (x, y) = ((i % 40) as f64 + 0.5, (i / 40) as f64 + 0.5);
            if a.prim[i] != b.prim[i] {
                let d = [a.prim[i], b.prim[i]]
                    .iter()
                    .filter(|&&p| p != u32::MAX)
                    .map(|&p| edge_distance_px(&cam, &tris[p as usize], x, y))
                    .fold(f64::INFINITY, f64::min);
                prop_assert!(d < 1e-6, "pixel {} changed {} -> {} at {} px from an edge", i, a.prim[i], b.prim[i], d);
            } else if a.z[i].is_finite() {
                prop_assert!(((a.z[i] - b.z[i]) / a.z[i]).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn scaling_scene_and_camera_by_a_power_of_two_scales_depth_exactly(
        tris in prop::collection::vec(arb_tri(), 1..10),
        p in -20i32..=20,
    ) {
        // About the eye (at the origin): P = eye + d is then exact at every scale.
        let s = 2f32.powi(p);
        let shift = Vec3::new(-0.75, -0.5, -5.0);
        let tris: Vec<Tri> = tris.iter().map(|t| t.map(|v| v + shift)).collect();
        let scaled: Vec<Tri> = tris.iter().map(|t| t.map(|v| v * s)).collect();
        let look = DVec3::new(-0.75, -0.5, -5.0);
        let mut cam_b = camera_at(DVec3::ZERO, look * f64::from(s), 40);
        cam_b.near = 1e-3 * f64::from(s);
        let a = render(camera_at(DVec3::ZERO, look, 40), tris);
        let b = render(cam_b, scaled);
        prop_assert_eq!(&a.prim, &b.prim);
        for (x, y) in a.z.iter().zip(&b.z) {
            prop_assert_eq!((x * s).to_bits(), y.to_bits());
        }
    }

    #[test]
    fn reordering_triangles_permutes_ids(
        tris in prop::collection::vec(arb_tri(), 2..10),
        seed in any::<u64>(),
    ) {
        // A permutation from the seed.
        let n = tris.len();
        let mut order: Vec<usize> = (0..n).collect();
        let mut s = seed | 1;
        for i in (1..n).rev() {
            s ^= s << 13; s ^= s >> 7; s ^= s << 17;
            order.swap(i, (s % (i as u64 + 1)) as usize);
        }
        let reordered: Vec<Tri> = order.iter().map(|&i| tris[i]).collect();
        let a = render(camera_at(eye(), DVec3::ZERO, 40), tris.clone());
        let b = render(camera_at(eye(), DVec3::ZERO, 40), reordered);
        prop_assert!(same_depth_bits(&a, &b));
        for i in 0..a.prim.len() {
            let (pa, pb) = (a.prim[i], b.prim[i]);
            if pa == u32::MAX || pb == u32::MAX {
                prop_assert_eq!(pa, pb);
                continue;
            }
            let mapped = order[pb as usize] as u32;
            if mapped != pa {
                // Only an exact depth tie may change the winner (lower id wins in each order).
                prop_assert_eq!(a.z[i].to_bits(), b.z[i].to_bits());
                prop_assert!(pa < mapped, "the original order's winner must be the lower id");
            }
        }
    }

    #[test]
    fn splitting_a_triangle_at_an_edge_midpoint_keeps_its_pixels(t in arb_tri()) {
        // The midpoint of dyadic coordinates is dyadic, hence exact in f32.
        let m = (t[0] + t[1]) * 0.5;
        let halves = vec![[t[0], m, t[2]], [m, t[1], t[2]]];
        let a = render(camera_at(eye(), DVec3::ZERO, 40), vec![t]);
        let b = render(camera_at(eye(), DVec3::ZERO, 40), halves);
        for i in 0..a.prim.len() {
            prop_assert_eq!(a.prim[i] == u32::MAX, b.prim[i] == u32::MAX, "coverage differs at {}", i);
            if a.z[i].is_finite() {
                // The halves lie in the same plane; their f64 planes differ only by rounding.
                let rel = ((a.z[i] - b.z[i]) / a.z[i]).abs();
                prop_assert!(rel < 1e-6, "depth {} vs {}", a.z[i], b.z[i]);
            }
        }
    }
}
