//! `rendiff check MODEL` and `rendiff scene new MODEL -o SCENE.toml`: a user
//! with a model and no scene file checks it directly, from any folder, on
//! every backend the machine has; the scene written for editing is the same
//! scene (docs/resolved-scene.md, "A scene from a model file").

mod common;

use common::cli::{check_failure, need_venv, output_within, rendiff};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;

/// A GLB written here: a regular tetrahedron with quantized positions
/// (normalized shorts, `KHR_mesh_quantization`), drawn twice by
/// `EXT_mesh_gpu_instancing` (the second instance moved and turned 90
/// degrees about y), under a node scaled by 1/2; its mesh also has a LINES
/// primitive, which is skipped with a warning. Both extensions are required.
fn instanced_quantized_glb() -> Vec<u8> {
    let mut bin = Vec::new();
    let q = 32767i16;
    for p in [[q, q, q], [q, -q, -q], [-q, q, -q], [-q, -q, q]] {
        for c in p.into_iter().chain([0]) {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    for i in [0u16, 1, 2, 0, 3, 1, 0, 2, 3, 1, 3, 2] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let h = std::f32::consts::FRAC_1_SQRT_2;
    for f in [
        0.0f32, 0.0, 0.0, 3.0, 0.5, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, h, 0.0, h,
    ] {
        bin.extend_from_slice(&f.to_le_bytes());
    }
    assert_eq!(bin.len(), 112);
    let json = r#"{"asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_mesh_quantization", "EXT_mesh_gpu_instancing"],
        "extensionsRequired": ["KHR_mesh_quantization", "EXT_mesh_gpu_instancing"],
        "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "tet", "mesh": 0, "scale": [0.5, 0.5, 0.5],
                   "extensions": {"EXT_mesh_gpu_instancing":
                       {"attributes": {"TRANSLATION": 2, "ROTATION": 3}}}}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1},
                                   {"attributes": {"POSITION": 0}, "mode": 1}]}],
        "buffers": [{"byteLength": 112}],
        "bufferViews": [{"buffer": 0, "byteLength": 32, "byteStride": 8},
                        {"buffer": 0, "byteOffset": 32, "byteLength": 24},
                        {"buffer": 0, "byteOffset": 56, "byteLength": 56}],
        "accessors": [{"bufferView": 0, "componentType": 5122, "normalized": true, "count": 4,
                       "type": "VEC3", "min": [-32767, -32767, -32767], "max": [32767, 32767, 32767]},
                      {"bufferView": 1, "componentType": 5123, "count": 12, "type": "SCALAR"},
                      {"bufferView": 2, "componentType": 5126, "count": 2, "type": "VEC3"},
                      {"bufferView": 2, "byteOffset": 24, "componentType": 5126, "count": 2,
                       "type": "VEC4"}]}"#;
    let mut json = json.as_bytes().to_vec();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let mut glb = Vec::new();
    glb.extend_from_slice(b"glTF");
    glb.extend_from_slice(&2u32.to_le_bytes());
    glb.extend_from_slice(&((12 + 8 + json.len() + 8 + bin.len()) as u32).to_le_bytes());
    glb.extend_from_slice(&(json.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"JSON");
    glb.extend_from_slice(&json);
    glb.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"BIN\0");
    glb.extend_from_slice(&bin);
    glb
}

fn read_json(p: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// (backend, buffer) -> (status, the mismatch counts) of one scene's verdicts.
type Verdicts = BTreeMap<(String, String), (String, String)>;

fn verdicts(results: &Value, scene: &str) -> Verdicts {
    let counts = std::iter::once(&"pixels").chain(rendiff::gate::COUNT_METRICS);
    results["results"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["scene"] == scene)
        .map(|r| {
            let key = (
                r["backend"].as_str().unwrap().to_string(),
                r["buffer"].as_str().unwrap().to_string(),
            );
            let n: Vec<String> = counts.clone().map(|c| r[c].to_string()).collect();
            (
                key,
                (r["status"].as_str().unwrap().to_string(), n.join(" ")),
            )
        })
        .collect()
}

#[test]
fn check_of_a_model_from_an_empty_folder_judges_every_backend_and_scene_new_matches_it() {
    need_venv();
    let tmp = tempfile::tempdir().unwrap();
    let models = tmp.path().join("models");
    let work = tmp.path().join("work");
    std::fs::create_dir(&models).unwrap();
    std::fs::create_dir(&work).unwrap();
    let model = models.join("model.glb");
    std::fs::write(&model, instanced_quantized_glb()).unwrap();

    // The scene for editing: beside the model, its mesh path relative.
    let edit = models.join("edit.toml");
    let scene_new = || {
        rendiff()
            .current_dir(&work)
            .args(["scene", "new"])
            .arg(&model)
            .arg("-o")
            .arg(&edit)
            .output()
            .unwrap()
    };
    let out = scene_new();
    assert_eq!(out.status.code(), Some(0), "{out:?}");
    let text = std::fs::read_to_string(&edit).unwrap();
    assert!(text.contains("mesh = \"model.glb\""), "{text}");
    // Never overwritten.
    check_failure(&scene_new(), &["edit.toml: already exists"]);
    assert_eq!(std::fs::read_to_string(&edit).unwrap(), text);

    // From an empty folder: the model itself, and the written scene, in one
    // run on every backend this machine has (no calibration probes: the
    // scenes are what this test is about).
    let run = work.join("run");
    let out = output_within(
        rendiff()
            .current_dir(&work)
            .arg("check")
            .arg(&model)
            .arg(&edit)
            .args(["--no-calibration", "-o"])
            .arg(&run),
        900,
    );
    let log = format!(
        "stdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(out.status.code(), Some(0), "{log}");
    // The skipped LINES primitive is said once per scene, naming file and primitive.
    let warning = "model.glb: objects[0].mesh: mesh 0 primitive 1 has mode LINES: skipped";
    assert_eq!(
        String::from_utf8_lossy(&out.stderr)
            .matches(warning)
            .count(),
        2,
        "{log}"
    );

    // Both scenes resolved to the same triangles, objects and camera.
    let scene_dir = |s: &str| run.join("scenes").join(s).join("resolved");
    let tris = |s: &str| std::fs::read(scene_dir(s).join("triangles.f32")).unwrap();
    assert_eq!(tris("model"), tris("edit"));
    assert_eq!(
        tris("model").len(),
        2 * 4 * 9 * 4,
        "two instances of four triangles"
    );
    let meta = |s: &str| read_json(&scene_dir(s).join("scene.json"));
    let (a, b) = (meta("model"), meta("edit"));
    assert_eq!(a["camera"], b["camera"]);
    assert_eq!(a["objects"], b["objects"]);
    let names: Vec<&str> = a["objects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|o| o["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["model/tet/0", "model/tet/1"]);

    // Every backend judged the model (or was skipped with its reason, as
    // conformance reports a backend this machine lacks), nothing failed, and
    // the written scene got the same verdicts with the same counts.
    let results = read_json(&run.join("results.json"));
    let (direct, written) = (verdicts(&results, "model"), verdicts(&results, "edit"));
    assert_eq!(direct, written);
    let judged: Vec<&str> = direct
        .iter()
        .filter(|(_, (status, _))| status != "skipped")
        .map(|((backend, _), _)| backend.as_str())
        .collect();
    for ((backend, buffer), (status, _)) in &direct {
        assert!(
            status == "pass" || status == "skipped",
            "{backend}/{buffer}: {status}\n{log}"
        );
    }
    // The core's tracer always runs; each built-in backend present is judged
    // on depth and IDs.
    assert!(judged.contains(&"trace"), "{direct:?}");
    let manifest = read_json(&run.join("manifest.json"));
    for scene in manifest["scenes"].as_array().unwrap() {
        for r in scene["renders"].as_array().unwrap() {
            let backend = r["backend"].as_str().unwrap();
            if r["status"] == "ok" && backend != "raster" {
                for buffer in ["Z", "id"] {
                    let key = (backend.to_string(), buffer.to_string());
                    let status = direct.get(&key).map(|v| v.0.as_str());
                    assert_eq!(status, Some("pass"), "{backend}/{buffer}\n{log}");
                }
            }
        }
    }
}

#[test]
fn scene_new_refuses_a_scene_outside_the_model_folder_and_bad_models() {
    let tmp = tempfile::tempdir().unwrap();
    let models = tmp.path().join("models");
    std::fs::create_dir(&models).unwrap();
    let model = models.join("model.glb");
    std::fs::write(&model, instanced_quantized_glb()).unwrap();
    let elsewhere = tmp.path().join("other");
    std::fs::create_dir(&elsewhere).unwrap();
    let res = rendiff()
        .args(["scene", "new"])
        .arg(&model)
        .arg("-o")
        .arg(elsewhere.join("s.toml"))
        .output()
        .unwrap();
    check_failure(
        &res,
        &["model.glb: is not inside", "never leave its folder"],
    );
    assert!(!elsewhere.join("s.toml").exists());

    // A broken model is one line naming it, from `scene new` and from `check`.
    let bad = models.join("bad.glb");
    std::fs::write(&bad, b"glTF\x01\0\0\0\x0c\0\0\0").unwrap();
    let res = rendiff()
        .args(["scene", "new"])
        .arg(&bad)
        .arg("-o")
        .arg(models.join("bad.toml"))
        .output()
        .unwrap();
    check_failure(&res, &["bad.glb", "bad GLB header: version 1"]);
    let res = rendiff()
        .args(["render", "--renderer", "raster", "-o"])
        .arg(tmp.path().join("x.exr"))
        .arg(&bad)
        .output()
        .unwrap();
    check_failure(&res, &["bad.glb", "bad GLB header: version 1"]);
}
