//! Bad input through the real binary: a clear message naming the file and the
//! problem, a non-zero exit that is not a panic, and no output file.

use std::path::{Path, PathBuf};
use std::process::Command;

const CAMERA: &str = r#"
[camera]
eye = [0.0, 0.0, 5.0]
look_at = [0.0, 0.0, 0.0]
vfov = 45.0
width = 16
height = 12
"#;

const OBJECT: &str = r#"
[[objects]]
name = "t"
shape = { kind = "three_triangles" }
"#;

fn rendiff() -> Command {
    Command::new(env!("CARGO_BIN_EXE_rendiff"))
}

/// Writes `scene.toml` (and optional extra files) in a fresh folder, renders it,
/// and checks the failure contract. Returns stderr.
fn expect_failure(toml: &str, extra: &[(&str, &str)], must_mention: &[&str]) -> String {
    let dir = tempfile::tempdir().unwrap();
    let scene_dir = dir.path().join("scenes");
    std::fs::create_dir_all(&scene_dir).unwrap();
    for (name, body) in extra {
        let p = dir.path().join(name);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, body).unwrap();
    }
    let scene = scene_dir.join("bad.toml");
    std::fs::write(&scene, toml).unwrap();
    let out = dir.path().join("out").join("bad.exr");
    let res = rendiff()
        .args(["render", "--renderer", "raster", "--quiet"])
        .arg(&scene)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&res.stderr).to_string();
    assert_eq!(res.status.code(), Some(2), "exit code; stderr: {stderr}");
    assert!(!stderr.contains("panicked"), "panic: {stderr}");
    assert!(
        stderr.contains("bad.toml") || must_mention.iter().any(|m| m.ends_with(".obj")),
        "file not named: {stderr}"
    );
    for m in must_mention {
        assert!(stderr.contains(m), "expected {m:?} in: {stderr}");
    }
    assert!(!out.exists(), "an output file was written");
    assert!(
        !out.parent().unwrap().exists()
            || std::fs::read_dir(out.parent().unwrap()).unwrap().count() == 0
    );
    stderr
}

#[test]
fn malformed_toml() {
    expect_failure(
        "requires = [\"depth\"\n[camera",
        &[],
        &["malformed scene file"],
    );
}

#[test]
fn unknown_field_is_named() {
    let s = format!("requires = [\"depth\"]\ncolour = 3\n{CAMERA}{OBJECT}");
    expect_failure(&s, &[], &["colour"]);
}

#[test]
fn missing_mesh_file() {
    let s = format!(
        "requires = [\"depth\"]\n{CAMERA}\n[[objects]]\nname = \"m\"\nmesh = \"nope.obj\"\n"
    );
    expect_failure(
        &s,
        &[],
        &["objects[0].mesh", "nope.obj", "cannot be opened"],
    );
}

#[test]
fn mesh_outside_scene_folder() {
    let s = format!(
        "requires = [\"depth\"]\n{CAMERA}\n[[objects]]\nname = \"m\"\nmesh = \"../secret.obj\"\n"
    );
    expect_failure(
        &s,
        &[("secret.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")],
        &["objects[0].mesh", "outside the scene's folder"],
    );
}

#[test]
fn absolute_mesh_path() {
    let s = format!(
        "requires = [\"depth\"]\n{CAMERA}\n[[objects]]\nname = \"m\"\nmesh = \"/etc/passwd\"\n"
    );
    expect_failure(&s, &[], &["must be relative"]);
}

#[test]
fn nan_vertex_in_obj() {
    let s =
        format!("requires = [\"depth\"]\n{CAMERA}\n[[objects]]\nname = \"m\"\nmesh = \"m.obj\"\n");
    expect_failure(
        &s,
        &[("scenes/m.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")],
        &["m.obj", "not finite"],
    );
}

#[test]
fn inf_vertex_in_scene() {
    let s = format!(
        "requires = [\"depth\"]\n{CAMERA}\n[[objects]]\nname = \"m\"\nshape = {{ kind = \"triangles\", vertices = [[0.0, 0.0, 0.0], [inf, 0.0, 0.0], [0.0, 1.0, 0.0]] }}\n"
    );
    expect_failure(&s, &[], &["objects[0].shape", "not finite"]);
}

#[test]
fn zero_area_triangle_without_permission() {
    let s = format!(
        "requires = [\"depth\"]\n{CAMERA}\n[[objects]]\nname = \"m\"\nshape = {{ kind = \"triangles\", vertices = [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [2.0, 2.0, 0.0]] }}\n"
    );
    expect_failure(&s, &[], &["zero area", "allow_degenerate"]);
}

fn camera_variant(from: &str, to: &str) -> String {
    format!(
        "requires = [\"depth\"]\n{}{OBJECT}",
        CAMERA.replace(from, to)
    )
}

#[test]
fn zero_sized_image() {
    expect_failure(
        &camera_variant("width = 16", "width = 0"),
        &[],
        &["camera.width", "at least 1x1"],
    );
}

#[test]
fn vfov_out_of_range() {
    expect_failure(
        &camera_variant("vfov = 45.0", "vfov = 0.0"),
        &[],
        &["camera.vfov"],
    );
    expect_failure(
        &camera_variant("vfov = 45.0", "vfov = 180.0"),
        &[],
        &["camera.vfov"],
    );
    expect_failure(
        &camera_variant("vfov = 45.0", "vfov = -5.0"),
        &[],
        &["camera.vfov"],
    );
    expect_failure(
        &camera_variant("vfov = 45.0", "vfov = nan"),
        &[],
        &["camera.vfov"],
    );
}

#[test]
fn look_at_equal_to_eye() {
    expect_failure(
        &camera_variant("look_at = [0.0, 0.0, 0.0]", "look_at = [0.0, 0.0, 5.0]"),
        &[],
        &["camera.look_at", "equals eye"],
    );
}

#[test]
fn up_parallel_to_view() {
    expect_failure(
        &format!(
            "requires = [\"depth\"]\n{}{OBJECT}",
            CAMERA.replace("vfov", "up = [0.0, 0.0, 2.0]\nvfov")
        ),
        &[],
        &["camera.up", "parallel"],
    );
}

#[test]
fn unknown_feature_in_requires() {
    expect_failure(
        &format!("requires = [\"teleport\"]\n{CAMERA}{OBJECT}"),
        &[],
        &["requires[0]", "teleport"],
    );
}

#[test]
fn missing_scene_file() {
    let res = rendiff()
        .args(["render", "--renderer", "trace", "/nonexistent/scene.toml"])
        .output()
        .unwrap();
    assert_eq!(res.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&res.stderr).contains("/nonexistent/scene.toml"));
}

#[test]
fn diff_exits_one_on_difference_and_zero_on_equal() {
    let dir = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let render = |scene: &str, renderer: &str, out: &PathBuf| {
        let st = rendiff()
            .current_dir(root)
            .args([
                "render",
                scene,
                "--renderer",
                renderer,
                "--quiet",
                "--no-preview",
                "-o",
            ])
            .arg(out)
            .status()
            .unwrap();
        assert!(st.success());
    };
    let a = dir.path().join("a.exr");
    let b = dir.path().join("b.exr");
    let c = dir.path().join("c.exr");
    render("scenes/three_triangles.toml", "raster", &a);
    render("scenes/three_triangles.toml", "trace", &b);
    render("scenes/obj_mesh.toml", "raster", &c);
    let diff = |x: &PathBuf, y: &PathBuf| rendiff().arg("diff").arg(x).arg(y).output().unwrap();
    let same = diff(&a, &b);
    assert_eq!(
        same.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&same.stdout)
    );
    let other = diff(&a, &c);
    assert_eq!(other.status.code(), Some(1));
    let missing = diff(&a, &dir.path().join("nope.exr"));
    assert_eq!(missing.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&missing.stderr).contains("nope.exr"));
}

#[test]
fn render_writes_exr_previews_and_counters() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("t.exr");
    let res = rendiff()
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args([
            "render",
            "scenes/three_triangles.toml",
            "--renderer",
            "trace",
            "--threads",
            "2",
            "-o",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(res.status.success());
    assert!(String::from_utf8_lossy(&res.stdout).contains("BVH nodes visited"));
    assert!(dir.path().join("t.ids.png").exists() && dir.path().join("t.depth.png").exists());
    let b = rendiff::exr_io::read_buffers(&out).unwrap();
    let counters: rendiff::visibility::Counters =
        serde_json::from_str(&b.attrs["counters"]).unwrap();
    assert!(counters.bvh_nodes_visited > 0 && counters.coverage_tests > 0);
}
