//! The command protocol, without needing a GPU: exit 3 and one line when
//! there is no Vulkan adapter, exit 1 and one line naming the file for bad
//! input, and the declared precision in renderers/wgpu.toml equal to the
//! derivation in the code.

use std::path::Path;
use std::process::{Command, Output};

/// Runs `rendiff-wgpu --scene DIR/SCENE --out DIR/o.exr` with `env` set.
fn render(dir: &Path, scene: &str, env: &[(&str, &str)]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rendiff-wgpu"))
        .envs(env.iter().copied())
        .arg("--scene")
        .arg(dir.join(scene))
        .arg("--out")
        .arg(dir.join("o.exr"))
        .output()
        .unwrap()
}

/// A tiny valid resolved scene (one triangle).
fn write_scene(dir: &Path, triangle_bytes: usize) {
    std::fs::create_dir_all(dir).unwrap();
    let json = r#"{"format": "rendiff-resolved/1", "name": "t",
      "camera": {"eye": [0, 0, 5], "forward": [0, 0, -1], "right": [1, 0, 0], "up_ortho": [0, 1, 0],
                 "tan_half_vfov": 0.5, "width": 8, "height": 6, "near": 0.001, "far": null},
      "triangle_count": 1, "files": {"triangles": "triangles.f32", "object_ids": "object_ids.u32"}}"#;
    std::fs::write(dir.join("scene.json"), json).unwrap();
    let tri: Vec<u8> = [-1f32, -1.0, 0.0, 1.0, -1.0, 0.0, 0.0, 1.0, 0.0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .take(triangle_bytes)
        .collect();
    std::fs::write(dir.join("triangles.f32"), tri).unwrap();
    std::fs::write(dir.join("object_ids.u32"), 0u32.to_le_bytes()).unwrap();
}

fn one_line(stderr: &[u8]) -> String {
    let s = String::from_utf8_lossy(stderr).to_string();
    assert_eq!(
        s.trim_end().lines().count(),
        1,
        "exactly one line on stderr, got {s:?}"
    );
    s
}

#[test]
fn no_adapter_is_skipped_with_status_3() {
    let tmp = tempfile::tempdir().unwrap();
    write_scene(&tmp.path().join("s"), 36);
    let out = render(
        tmp.path(),
        "s",
        &[
            ("VK_ICD_FILENAMES", "/nonexistent/icd.json"),
            ("VK_DRIVER_FILES", "/nonexistent/icd.json"),
        ],
    );
    assert_eq!(out.status.code(), Some(3), "{out:?}");
    assert!(one_line(&out.stderr).starts_with("no Vulkan adapter: "));
    assert!(!tmp.path().join("o.exr").exists());
}

#[test]
fn missing_scene_names_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let out = render(tmp.path(), "nowhere", &[]);
    assert_eq!(out.status.code(), Some(1));
    let line = one_line(&out.stderr);
    assert!(line.contains("nowhere/scene.json"), "{line}");
}

#[test]
fn truncated_triangles_name_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    write_scene(&tmp.path().join("s"), 20);
    let out = render(tmp.path(), "s", &[]);
    assert_eq!(out.status.code(), Some(1));
    let line = one_line(&out.stderr);
    assert!(
        line.contains("triangles.f32") && line.contains("20 bytes"),
        "{line}"
    );
}

#[test]
fn declared_precision_matches_the_code() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../renderers/wgpu.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let doc: toml::Value = toml::from_str(&text).unwrap();
    let r = &doc["renderer"][0];
    assert_eq!(r["name"].as_str(), Some("wgpu"));
    let p = &r["precision"];
    assert_eq!(
        p["edge_px"].as_float(),
        Some(rendiff_wgpu::precision::EDGE_PX)
    );
    assert_eq!(
        p["depth_relative"].as_float(),
        Some(rendiff_wgpu::precision::DEPTH_RELATIVE)
    );
    let features: Vec<&str> = r["features"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|v| v.as_str())
        .collect();
    assert_eq!(features, ["depth", "ids"]);
}
