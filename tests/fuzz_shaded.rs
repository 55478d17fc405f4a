//! `rendiff reduce` on a shaded scene (docs/fuzzing.md, "Shaded scenes"): a
//! declared renderer with a planted shading fault
//! (tests/fuzz_renderers/shaded.py, `red_albedo`: a coloured albedo shaded
//! with its red channel in all three) fails RGB on a scene of four quads
//! (one coloured), two point lights and a directional light. The reduction
//! through the CLI must keep the failing triangle's material and one light
//! (the fault needs a lit coloured surface: with no light every pixel is
//! black on both sides), and the reduced scene must (a) still fail RGB with
//! the same class on its own, from a fresh folder, and (b) come back from a
//! second reduction byte for byte unchanged.

mod common;

use common::cli::{
    fuzz_renderers, need_venv, output_within, printed, reduce_planted, rendiff_with_venv,
};
use rendiff::scene::resolve::ResolvedScene;
use rendiff::scene::Scene;
use std::path::Path;

const BACKEND: &str = "red_albedo";
const GREEN: [f64; 3] = [0.2, 0.7, 0.3];

const SCENE: &str = r#"
description = "four quads, one coloured, under two point lights and a directional light"
requires = ["depth", "ids", "lambert", "point_light", "directional_light", "shadowless", "two_sided"]

[camera]
eye = [0.0, 2.0, 4.0]
look_at = [0.0, 0.3, 0.0]
vfov = 45.0
width = 16
height = 12

[[materials]]
name = "grey"
albedo = [0.5, 0.5, 0.5]

[[materials]]
name = "green"
albedo = [0.2, 0.7, 0.3]

[[objects]]
name = "floor"
material = "grey"
shape = { kind = "quad", size = [4.0, 4.0] }
transform = { rotate = [-90.0, 0.0, 0.0] }

[[objects]]
name = "wall"
material = "grey"
shape = { kind = "quad", size = [4.0, 1.5] }
transform = { translate = [0.0, 0.75, -1.5] }

[[objects]]
name = "tile"
material = "green"
shape = { kind = "quad", size = [0.8, 0.8] }
transform = { rotate = [-90.0, 0.0, 0.0], translate = [0.6, 0.01, 0.4] }

[[objects]]
name = "post"
material = "grey"
shape = { kind = "quad", size = [0.4, 1.0] }
transform = { rotate = [0.0, 30.0, 0.0], translate = [-0.8, 0.5, 0.0] }

[[lights]]
kind = "point"
position = [1.0, 2.0, 1.5]
intensity = [6.0, 5.0, 4.0]

[[lights]]
kind = "point"
position = [-1.5, 1.5, 0.5]
intensity = [2.0, 3.0, 4.0]

[[lights]]
kind = "directional"
direction = [0.2, -1.0, -0.3]
irradiance = [0.5, 0.5, 0.5]
"#;

/// The planted renderers of this test.
fn renderers() -> String {
    fuzz_renderers("shaded.toml")
}

/// `rendiff check SCENE.toml --only red_albedo -o run` in `dir` (with
/// `extra`): it must exit 1; each verdict of the backend as (buffer, class).
fn check(dir: &Path, scene: &str, extra: &[&str]) -> Vec<(String, Option<String>)> {
    let o = output_within(
        rendiff_with_venv(dir)
            .args(["check", scene, "--only", BACKEND, "--renderers"])
            .arg(renderers())
            .args(extra)
            .args(["--jobs", "2", "--quiet", "-o", "run"]),
        300,
    );
    assert_eq!(o.status.code(), Some(1), "it must fail: {}", printed(&o));
    let verdicts = rendiff::gate::load_verdicts(&dir.join("run/results.json")).unwrap();
    verdicts
        .iter()
        .filter(|v| v.backend == BACKEND)
        .map(|v| (v.buffer.clone(), rendiff::fuzz::findings::failure_class(v)))
        .collect()
}

/// `rendiff reduce run STEM --backend red_albedo --buffer RGB -o OUT` in
/// `dir`: it must succeed; what it printed.
fn reduce(dir: &Path, stem: &str, out: &str) -> String {
    reduce_planted(dir, &renderers(), "run", stem, BACKEND, "RGB", out)
}

fn resolved(file: &Path) -> ResolvedScene {
    ResolvedScene::resolve(&Scene::load(file).unwrap()).unwrap()
}

#[test]
fn a_shaded_finding_is_reduced_with_its_material_and_one_light() {
    need_venv();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("shaded.toml"), SCENE).unwrap();
    // The planted fault is RGB's alone: ids, depth and normals pass.
    let verdicts = check(dir, "shaded.toml", &["--no-calibration"]);
    for (buffer, class) in &verdicts {
        let want = (buffer == "RGB").then(|| "interior".to_string());
        assert_eq!(class, &want, "{buffer}: {verdicts:?}");
    }
    assert!(verdicts.iter().any(|v| v.0 == "RGB"), "{verdicts:?}");

    let printed = reduce(dir, "shaded", "reduced.toml");
    assert!(
        printed.contains("red_albedo fails RGB with class interior: 8 -> 1 triangles, 4 -> 1 objects, 3 -> 1 lights"),
        "{printed}"
    );
    let reduced = std::fs::read_to_string(dir.join("reduced.toml")).unwrap();
    let r = resolved(&dir.join("reduced.toml"));
    let before = resolved(&dir.join("shaded.toml"));
    // One triangle of the coloured tile, its material carried over (the
    // fault needs a coloured albedo), and one of the lights as written.
    assert_eq!(r.triangles.len(), 1, "{reduced}");
    let m = &r.materials[r.objects[0].material as usize];
    assert_eq!((m.albedo, m.emission), (GREEN, [0.0; 3]), "{reduced}");
    assert_eq!(r.lights.len(), 1, "{reduced}");
    assert!(before.lights.contains(&r.lights[0]), "{reduced}");
    assert_eq!(r.requires, before.requires);
    assert_eq!(r.integrator, before.integrator);
    assert!(
        r.camera.width * r.camera.height < before.camera.width * before.camera.height,
        "{reduced}"
    );

    // (a) From a fresh folder, on its own: RGB still fails with the same
    // class. (No calibration: it judges the renderer's camera, not the
    // scene, and the first check skipped it too.)
    let fresh = dir.join("fresh");
    std::fs::create_dir(&fresh).unwrap();
    std::fs::write(fresh.join("repro.toml"), &reduced).unwrap();
    let again = check(&fresh, "repro.toml", &["--no-calibration"]);
    assert!(
        again.contains(&("RGB".to_string(), Some("interior".to_string()))),
        "{again:?}"
    );

    // (b) Reducing the reduced scene changes nothing, byte for byte.
    reduce(&fresh, "repro", "again.toml");
    assert_eq!(
        std::fs::read_to_string(fresh.join("again.toml")).unwrap(),
        reduced,
        "a second reduction changed the reduced scene"
    );
}
