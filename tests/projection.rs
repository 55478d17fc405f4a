//! Projection and visibility basics: known points land on predicted pixels, a
//! triangle facing away is visible, a zero-area triangle never is.

mod common;

use common::scenes::*;
use glam::DVec3;
use rendiff::camera::Camera;
use rendiff::scene::resolve::ResolvedScene;

#[test]
fn known_points_land_on_predicted_pixels() {
    // A tiny triangle around a world point covers exactly the pixel the camera predicts.
    let cam = Camera::new(
        DVec3::new(1.0, 2.0, 6.0),
        DVec3::new(0.2, 0.1, -0.3),
        DVec3::Y,
        50.0,
        80,
        60,
        1e-3,
        f64::INFINITY,
    )
    .unwrap();
    for (x, y) in [(0u32, 0u32), (79, 0), (0, 59), (40, 30), (13, 47)] {
        let center = cam.eye + cam.direction(x, y) * 4.0;
        // A small triangle in the plane facing the camera, around the pixel's center point.
        let s = 0.2 * 4.0 * cam.tan_half_vfov * 2.0 / 60.0; // ~0.2 pixel
        let a = center + cam.right * -s + cam.up_ortho * -s;
        let b = center + cam.right * s + cam.up_ortho * -s;
        let c = center + cam.up_ortho * s;
        let t = [a.as_vec3(), b.as_vec3(), c.as_vec3()];
        let scene = ResolvedScene::from_triangles(cam.clone(), vec![t]);
        let (r, tr) = both(&scene, false);
        assert_identical("projection", &r, &tr);
        let hits: Vec<usize> = (0..r.prim.len()).filter(|&i| r.prim[i] == 0).collect();
        assert_eq!(hits, vec![r.index(x, y)], "point for pixel ({x},{y})");
        assert!(
            (r.z[r.index(x, y)] - 4.0).abs() < 1e-5,
            "planar depth {}",
            r.z[r.index(x, y)]
        );
    }
}

#[test]
fn triangle_facing_away_is_still_visible() {
    let cam = exact_camera(16);
    // Clockwise seen from the eye: back-facing.
    let t = tri([-0.5, -0.5, 0.0], [0.0, 0.5, 0.0], [0.5, -0.5, 0.0]);
    let scene = ResolvedScene::from_triangles(cam, vec![t]);
    let (r, tr) = both(&scene, true);
    assert_identical("back-facing", &r, &tr);
    let cov = r.coverage.as_ref().unwrap();
    let visible = r.prim.iter().filter(|&&p| p == 0).count();
    assert!(visible > 20, "back-facing triangle drew {visible} pixels");
    assert!(
        cov.iter().all(|c| c[0] == 0),
        "no front-facing coverage expected"
    );
}

#[test]
fn zero_area_triangles_are_never_visible() {
    let cam = exact_camera(16);
    let tris = vec![
        tri([-0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [0.0, 0.0, 0.0]), // collinear
        tri([0.1, 0.1, 0.0], [0.1, 0.1, 0.0], [0.6, -0.3, 0.0]),  // repeated vertex
        tri([-0.9, 0.3, 0.0], [-0.9, 0.3, 0.0], [-0.9, 0.3, 0.0]), // a point
        // Seen exactly edge-on: its plane contains the eye.
        tri([0.0, -0.5, 0.0], [0.0, 0.5, 0.0], [0.0, 0.0, 0.5]),
    ];
    let scene = ResolvedScene::from_triangles(cam, tris);
    assert_eq!(scene.degenerate, vec![true, true, true, false]);
    let (r, t) = both(&scene, true);
    assert_identical("zero-area", &r, &t);
    assert!(
        r.prim.iter().all(|&p| p == u32::MAX),
        "a zero-area triangle was drawn"
    );
    assert!(r.coverage.unwrap().iter().all(|c| c == &[0, 0]));
}

#[test]
fn nearer_triangle_wins_and_equal_depth_goes_to_lower_id() {
    let cam = exact_camera(16);
    let big = |z: f32| tri([-2.0, -2.0, z], [2.0, -2.0, z], [0.0, 2.0, z]);
    // prim 0 far, prim 1 near, prims 2 and 3 coplanar duplicates at the same depth.
    let scene = ResolvedScene::from_triangles(cam.clone(), vec![big(-1.0), big(-0.5)]);
    let (r, t) = both(&scene, false);
    assert_identical("nearest", &r, &t);
    assert_eq!(r.prim[r.index(8, 8)], 1);
    assert_eq!(r.z[r.index(8, 8)], 1.5);
    let scene = ResolvedScene::from_triangles(cam, vec![big(0.25), big(0.25)]);
    let (r, t) = both(&scene, false);
    assert_identical("equal depth", &r, &t);
    assert!(r.prim.iter().all(|&p| p == 0 || p == u32::MAX));
}

#[test]
fn near_and_far_bound_visibility() {
    let mut cam = exact_camera(8);
    cam.near = 1.2;
    cam.far = 1.8;
    let big = |z: f32| tri([-9.0, -9.0, z], [9.0, -9.0, z], [0.0, 9.0, z]);
    // Depths 1.0 (too near), 1.5 (visible), 2.0 (too far).
    let scene = ResolvedScene::from_triangles(cam, vec![big(0.0), big(-0.5), big(-1.0)]);
    let (r, t) = both(&scene, false);
    assert_identical("near/far", &r, &t);
    assert!(r.prim.iter().all(|&p| p == 1));
}

#[test]
fn triangle_crossing_the_eye_plane_is_clipped_not_lost() {
    let cam = exact_camera(16);
    // Spans from behind the eye (z = 3) to in front (z = -3).
    let t = tri([-1.0, -0.3, 3.0], [1.0, -0.3, 3.0], [0.0, -0.3, -3.0]);
    let scene = ResolvedScene::from_triangles(cam, vec![t]);
    let (r, tr) = both(&scene, false);
    assert_identical("crossing", &r, &tr);
    assert!(r.prim.contains(&0));
}
