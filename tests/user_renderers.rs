//! A user's own renderer, declared by command in a renderers file
//! (`check --renderers`, docs/your-renderer.md), runs from a folder outside
//! the checkout, goes through calibration and the verifier like a built-in
//! backend, and a missing or malformed file is a clear error.

use std::path::Path;
use std::process::Command;

fn rendiff(dir: &Path) -> Command {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut c = Command::new(env!("CARGO_BIN_EXE_rendiff"));
    // The example renderer runs with `python3` from PATH and needs numpy: the venv's.
    let path = format!(
        "{}:{}",
        root.join(".venv/bin").display(),
        std::env::var("PATH").unwrap_or_default()
    );
    c.current_dir(dir)
        .env("PATH", path)
        .env_remove("RENDIFF_HOME");
    c
}

/// A user's glTF scene (two mesh nodes under a translated parent, the
/// camera a node of the file, the buffer in a .bin beside it).
fn write_gltf_scene(dir: &Path) {
    let mut bin: Vec<u8> = Vec::new();
    let quad = [
        [-1.0f32, -1.0, 0.0],
        [1.0, -1.0, 0.0],
        [1.0, 1.0, 0.0],
        [-1.0, 1.0, 0.0],
    ];
    let tri = [[-0.5f32, -0.5, 0.0], [0.5, -0.5, 0.0], [0.0, 0.5, 0.0]];
    for v in quad.iter().chain(tri.iter()) {
        for c in v {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    for i in [0u16, 1, 2, 0, 2, 3] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    std::fs::write(dir.join("model.bin"), &bin).unwrap();
    let gltf = serde_json::json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0, 3]}],
        "nodes": [
            {"name": "group", "translation": [0.2, 0.0, 0.0], "children": [1, 2]},
            {"name": "quad", "mesh": 0},
            {"name": "tri", "mesh": 1, "translation": [0.0, 0.0, 0.5],
             "rotation": [0.0, 0.0, 0.382_683_43, 0.923_879_5]},
            {"name": "cam", "camera": 0, "translation": [0.0, 0.0, 5.0]}
        ],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}}],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": 0}, "indices": 2}]},
            {"primitives": [{"attributes": {"POSITION": 1}}]}
        ],
        "buffers": [{"uri": "model.bin", "byteLength": bin.len()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 36},
            {"buffer": 0, "byteOffset": 84, "byteLength": 12}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [-1.0, -1.0, 0.0], "max": [1.0, 1.0, 0.0]},
            {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3",
             "min": [-0.5, -0.5, 0.0], "max": [0.5, 0.5, 0.0]},
            {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}
        ]
    });
    std::fs::write(dir.join("model.gltf"), gltf.to_string()).unwrap();
    std::fs::write(
        dir.join("my_scene.toml"),
        "requires = [\"depth\", \"ids\"]\n\n[camera]\nwidth = 96\nheight = 72\n\
         gltf = { object = \"model\", camera = \"cam\" }\n\n\
         [[objects]]\nname = \"model\"\nmesh = \"model.gltf\"\n",
    )
    .unwrap();
}

/// The user story: in an empty folder outside the checkout, a
/// renderer of one's own (declared in renderers.toml) and a glTF scene;
/// `rendiff check` gives calibration figures, verdicts and a report.
#[test]
fn a_declared_renderer_is_calibrated_and_judged_from_any_folder() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    for f in ["renderers.toml", "tiny_renderer.py"] {
        std::fs::copy(root.join("harness/examples").join(f), dir.path().join(f)).unwrap();
    }
    write_gltf_scene(dir.path());
    let out = rendiff(dir.path())
        .arg("check")
        .arg("my_scene.toml")
        .args(["--renderers", "renderers.toml", "--only", "tiny", "--quiet"])
        .args(["-o", "run"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    let results: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("run/results.json")).unwrap(),
    )
    .unwrap();
    let of = |scene: &str, buffer: &str| -> String {
        results["results"]
            .as_array()
            .unwrap()
            .iter()
            .find(|e| e["backend"] == "tiny" && e["scene"] == scene && e["buffer"] == buffer)
            .unwrap_or_else(|| panic!("no tiny/{scene}/{buffer} in results"))["status"]
            .as_str()
            .unwrap()
            .to_string()
    };
    for buffer in ["id", "Z", "N"] {
        assert_eq!(of("my_scene", buffer), "pass", "{buffer}");
    }
    // Both glTF mesh nodes became objects, named after their nodes.
    let manifest: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("run/scenes/my_scene/resolved/scene.json"))
            .unwrap(),
    )
    .unwrap();
    let names: Vec<&str> = manifest["objects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|o| o["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["model/quad", "model/tri"]);
    assert!(dir.path().join("run/report/index.html").is_file());
    // The calibration figures are in results.json for the user's renderer.
    assert!(
        results["calibration"]["tiny"]["offset_x_px"].is_number(),
        "{}",
        results["calibration"]
    );
    // Calibrated on both probes, like a built-in backend.
    assert_eq!(of("camera_near", "camera"), "pass");
    assert_eq!(of("camera_far", "camera"), "pass");
    // The manifest's reproduction command names the renderers file.
    let manifest = std::fs::read_to_string(dir.path().join("run/manifest.json")).unwrap();
    assert!(manifest.contains("RENDIFF_RENDERERS="), "{manifest}");
}

#[test]
fn a_missing_or_malformed_renderers_file_is_one_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/three_triangles.toml");
    // A missing file, and a device, which is refused, never read.
    for (file, said) in [
        ("nope.toml", "nope.toml: renderers file not found"),
        (
            "/dev/zero",
            "/dev/zero: the renderers file is not a regular file",
        ),
    ] {
        let out = rendiff(dir.path())
            .arg("check")
            .arg(&scene)
            .args(["--renderers", file, "--quiet", "-o", "run"])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{stderr}");
        assert!(stderr.contains(said), "{stderr}");
        assert!(
            !dir.path().join("run").exists(),
            "no run folder for a refused command"
        );
    }

    std::fs::write(
        dir.path().join("bad.toml"),
        "[[renderer]]\nname = \"x\"\ncommand = [\"./x\", \"{nope}\"]\n",
    )
    .unwrap();
    let out = rendiff(dir.path())
        .arg("check")
        .arg(&scene)
        .args([
            "--renderers",
            "bad.toml",
            "--no-calibration",
            "--quiet",
            "-o",
            "run",
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    // Refused before anything runs, in one line naming the file (once) and
    // the entry: the harness's own words, not "failed to start; run setup".
    assert!(stderr.starts_with("error: "), "{stderr}");
    assert!(
        stderr.contains("bad.toml: [[renderer]] #1 (x): missing key 'features'"),
        "{stderr}"
    );
    assert_eq!(stderr.matches("bad.toml").count(), 1, "{stderr}");
    assert!(!stderr.contains("setup.sh"), "{stderr}");
    assert!(
        !dir.path().join("run").exists(),
        "no run folder for a refused file"
    );
}

/// The run keeps a copy of the renderers file (RUN/renderers.toml), taken as
/// it begins, and every later step reads the declarations from the copy: a
/// renderer (or a user) that rewrites the file during the run changes nothing
/// the run judges by. Here the renderer breaks the file after its render;
/// the comparison, which read the file again, used to fail on it.
#[test]
fn a_run_judges_by_the_renderers_file_it_began_with() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(
        root.join("harness/examples/tiny_renderer.py"),
        dir.path().join("tiny_renderer.py"),
    )
    .unwrap();
    let script = dir.path().join("render_then_edit.sh");
    std::fs::write(
        &script,
        "#!/bin/sh\nhere=$(dirname \"$0\")\n\"$here/tiny_renderer.py\" \"$1\" \"$2\" || exit $?\n\
         printf 'not = [toml\\n' > \"$here/renderers.toml\"\n",
    )
    .unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&script, std::fs::Permissions::from_mode(0o755)).unwrap();
    let original = std::fs::read_to_string(root.join("harness/examples/renderers.toml"))
        .unwrap()
        .replace("./tiny_renderer.py", "./render_then_edit.sh");
    std::fs::write(dir.path().join("renderers.toml"), &original).unwrap();
    let out = rendiff(dir.path())
        .arg("check")
        .arg(root.join("scenes/three_triangles.toml"))
        .args(["--renderers", "renderers.toml", "--only", "tiny", "--quiet"])
        .args(["--no-calibration", "-o", "run"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(
        std::fs::read_to_string(dir.path().join("renderers.toml"))
            .unwrap()
            .starts_with("not = ["),
        "the renderer did not edit the file"
    );
    assert_eq!(
        std::fs::read_to_string(dir.path().join("run/renderers.toml")).unwrap(),
        original
    );
    let results = std::fs::read_to_string(dir.path().join("run/results.json")).unwrap();
    assert!(results.contains("\"backend\": \"tiny\""), "{results}");
}
