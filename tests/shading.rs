//! Radiance in the core: closed-form checks of local shading, a furnace test of
//! the path tracer, determinism, and that deliberate biases change the answer.

mod common;

use common::scenes::*;
use glam::DVec3;
use rendiff::scene::resolve::ResolvedScene;
use rendiff::scene::Scene;
use rendiff::shade::{self, Bias, ShadeOptions};
use rendiff::trace::{BvhQuality, TraceBvh};
use std::f64::consts::FRAC_1_PI;
use std::path::Path;

fn scene_file(name: &str) -> ResolvedScene {
    load(
        &Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("scenes")
            .join(name),
    )
}

fn shade_with(scene: &ResolvedScene, spp: u32, seed: u64, bias: Option<Bias>) -> shade::Radiance {
    let (r, _) = both(scene, false);
    let bvh = TraceBvh::build(scene, BvhQuality::Medium);
    shade::shade(
        scene,
        &r,
        &bvh,
        ShadeOptions {
            spp,
            seed,
            bias,
            deadline: None,
        },
    )
}

/// World point seen at pixel i on the plane y = 0.
fn floor_point(scene: &ResolvedScene, i: usize) -> DVec3 {
    let cam = &scene.camera;
    let w = cam.width as usize;
    let d = cam.direction((i % w) as u32, (i / w) as u32);
    let t = -cam.eye.y / d.y;
    cam.eye + d * t
}

#[test]
fn lambert_plane_under_point_light_matches_closed_form() {
    let scene = scene_file("lambert_point.toml");
    let rad = shade_with(&scene, 1, 1, None);
    let (r, _) = both(&scene, false);
    let light = DVec3::new(0.3, 2.0, -0.2);
    let albedo = DVec3::new(0.5, 0.6, 0.7);
    let mut checked = 0;
    for (i, &prim) in r.prim.iter().enumerate() {
        if prim == u32::MAX {
            continue;
        }
        let x = floor_point(&scene, i);
        let v = light - x;
        let r2 = v.length_squared();
        let cos = v.y / r2.sqrt();
        let expect = albedo * FRAC_1_PI * 10.0 * cos / r2;
        for k in 0..3 {
            let got = f64::from(rad.rgb[i][k]);
            let rel = (got - expect[k]).abs() / expect[k];
            assert!(
                rel < 2e-6,
                "pixel {i} channel {k}: {got} vs {} (rel {rel:e})",
                expect[k]
            );
        }
        checked += 1;
    }
    assert!(checked > 1000, "only {checked} floor pixels");
    assert!(rad.var.is_none() && rad.spp == 1);
}

#[test]
fn directional_light_matches_closed_form_and_casts_a_shadow() {
    let scene = scene_file("directional_shadows.toml");
    let rad = shade_with(&scene, 1, 1, None);
    let (r, _) = both(&scene, false);
    let dir = DVec3::new(0.7, -1.0, 0.4).normalize();
    let lit = 0.7 * FRAC_1_PI * 3.0 * (-dir.y);
    let (mut lit_px, mut shadow_px) = (0, 0);
    for (i, &prim) in r.prim.iter().enumerate() {
        if prim == u32::MAX || r.object[i] != 0 {
            continue;
        }
        let got = f64::from(rad.rgb[i][0]);
        if got == 0.0 {
            shadow_px += 1;
        } else {
            assert!(
                (got - lit).abs() / lit < 2e-6,
                "floor pixel {i}: {got} vs {lit}"
            );
            lit_px += 1;
        }
    }
    assert!(
        lit_px > 1000 && shadow_px > 20,
        "lit {lit_px}, shadowed {shadow_px}"
    );
    // Without shadows the same floor is lit everywhere.
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/directional_shadows.toml"),
    )
    .unwrap()
    .replace("\"shadows\"", "\"shadowless\"");
    let s = Scene::parse(Path::new("scenes/shadowless.toml"), &text).unwrap();
    let scene = ResolvedScene::resolve(&s).unwrap();
    let rad = shade_with(&scene, 1, 1, None);
    for (i, &prim) in r.prim.iter().enumerate() {
        if prim != u32::MAX && r.object[i] == 0 {
            assert!(rad.rgb[i][0] > 0.0, "shadowless floor pixel {i} is dark");
        }
    }
}

fn furnace(albedo: f64, one_sided: bool) -> ResolvedScene {
    // The camera inside a closed sphere whose inner side emits Le = 1 and reflects
    // with albedo rho: every pixel sees L = Le / (1 - rho).
    let side = if one_sided { "one_sided" } else { "two_sided" };
    let text = format!(
        r#"requires = ["depth", "ids", "lambert", "emission", "area_light", "global_illumination", "{side}"]
[camera]
eye = [0.1, -0.2, 0.15]
look_at = [1.0, 0.3, -0.5]
vfov = 70.0
width = 12
height = 10
[[materials]]
name = "glow"
albedo = [{albedo}, {albedo}, {albedo}]
emission = [1.0, 1.0, 1.0]
[[objects]]
name = "inside-out sphere"
material = "glow"
shape = {{ kind = "icosphere", subdivisions = 2, radius = 1.0 }}
transform = {{ scale = [1.0, 1.0, -1.0] }}
"#
    );
    let s = Scene::parse(Path::new("furnace.toml"), &text).unwrap();
    ResolvedScene::resolve(&s).unwrap()
}

/// Mean over all pixels and channels, and the standard error of that mean.
fn image_mean(r: &shade::Radiance) -> (f64, f64) {
    let n = (r.rgb.len() * 3) as f64;
    let mean = r.rgb.iter().flatten().map(|&v| f64::from(v)).sum::<f64>() / n;
    let var = r
        .var
        .as_ref()
        .unwrap()
        .iter()
        .flatten()
        .map(|&v| f64::from(v))
        .sum::<f64>()
        / (n * n);
    (mean, var.sqrt())
}

#[test]
fn path_tracer_passes_the_furnace_test() {
    for one_sided in [true, false] {
        let scene = furnace(0.5, one_sided);
        let rad = shade_with(&scene, 64, 7, None);
        assert_eq!(rad.integrator, "path");
        let (mean, se) = image_mean(&rad);
        // Channels are perfectly correlated here, so use a generous 6 sigma on the pooled mean.
        assert!(
            (mean - 2.0).abs() < 6.0 * se * 3f64.sqrt() + 1e-3,
            "furnace (one_sided={one_sided}): mean {mean}, expected 2, se {se}"
        );
    }
}

#[test]
fn path_tracer_is_deterministic_per_seed_and_independent_of_the_loop() {
    let scene = scene_file("cornell_gi.toml");
    let a = shade_with(&scene, 4, 3, None);
    let b = shade_with(&scene, 4, 3, None);
    assert_eq!(a.rgb, b.rgb);
    let c = shade_with(&scene, 4, 4, None);
    assert_ne!(a.rgb, c.rgb);
    let bvh = TraceBvh::build(&scene, BvhQuality::Medium);
    let (r, t) = both(&scene, false);
    let opts = ShadeOptions {
        spp: 1,
        seed: 9,
        bias: None,
        deadline: None,
    };
    assert_eq!(
        shade::shade(&scene, &r, &bvh, opts).rgb,
        shade::shade(&scene, &t, &bvh, opts).rgb
    );
}

#[test]
fn deliberate_biases_move_the_furnace_answer() {
    let scene = furnace(0.5, true);
    let (base, se) = image_mean(&shade_with(&scene, 64, 11, None));
    for (bias, expect) in [
        (Bias::Albedo2Percent, 1.0 / (1.0 - 0.51)),
        (Bias::OneBounceFewer, 2.0 - 0.5f64.powi(6) * 2.0),
    ] {
        let (m, se_b) = image_mean(&shade_with(&scene, 64, 11, Some(bias)));
        let sigma = (se * se + se_b * se_b).sqrt() * 3f64.sqrt();
        assert!(
            (m - expect).abs() < 6.0 * sigma + 1e-3,
            "{bias:?}: {m} vs expected {expect}"
        );
        assert!(
            (m - base).abs() > 3.0 * sigma,
            "{bias:?} not distinguishable: {m} vs {base}"
        );
    }
}

#[test]
fn scenes_that_ask_for_no_shading_get_none() {
    let scene = scene_file("three_triangles.toml");
    assert!(!shade::needs_shading(&scene));
    assert!(shade::needs_shading(&scene_file("lambert_point.toml")));
}
