//! Hostile meshes through the real binary (found by a probe): a glTF
//! accessor index past the end panicked inside the gltf crate, a tiny file
//! with a huge zero accessor allocated gigabytes once per node, a mesh
//! without triangles loaded as an empty object, an empty mesh path was
//! blamed on the scene's folder, and many named nodes took quadratic time.
//! Each must be refused (or loaded) promptly: exit 2 and one line naming
//! the file and the problem, never a panic or a hang.

mod common;
use common::cli::{check_failure, export_refused, output_within, raster_within, rendiff};

const CAMERA: &str =
    crate::camera_toml!(eye [0.3, 0.3, 5.0], look_at [0.3, 0.3, 0.0], vfov 45.0, 32 x 24);

/// One triangle's data for a glTF `data:` URI: positions (36 bytes) then
/// u16 indices 0 1 2 (6 bytes) and 2 bytes of padding.
const TRIANGLE_B64: &str = "data:application/octet-stream;base64,\
    AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAABAAIAAAA=";

/// Writes `files` and `s.toml` (one object whose `mesh` is `mesh`) into a
/// fresh folder, then exports it and renders it with the raster, each within
/// 10 s, and checks the failure contract of both and that neither wrote
/// anything. Returns export's stderr.
fn refused(mesh: &str, files: &[(&str, &str)], must_mention: &[&str]) -> String {
    let dir = tempfile::tempdir().unwrap();
    for (name, body) in files {
        std::fs::write(dir.path().join(name), body).unwrap();
    }
    let scene = dir.path().join("s.toml");
    let text =
        format!("requires = [\"depth\"]\n{CAMERA}\n[[objects]]\nname = \"m\"\nmesh = {mesh:?}\n");
    std::fs::write(&scene, text).unwrap();
    let stderr = export_refused(&scene, dir.path(), 10, must_mention);
    let out = dir.path().join("o.exr");
    check_failure(&raster_within(&scene, &out, 10), must_mention);
    assert!(!out.exists(), "render wrote {}", out.display());
    stderr
}

/// A glTF file of one triangle (accessor 0: positions, accessor 1: indices)
/// whose primitive is `primitive` (JSON) and whose nodes are `nodes` roots
/// using mesh 0.
fn gltf(primitive: &str, nodes: usize) -> String {
    let list = vec![r#"{"mesh": 0}"#; nodes].join(", ");
    let roots: Vec<String> = (0..nodes).map(|i| i.to_string()).collect();
    format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0,
           "scenes": [{{"nodes": [{roots}]}}], "nodes": [{list}],
           "meshes": [{{"primitives": [{primitive}]}}],
           "buffers": [{{"byteLength": 44, "uri": "{TRIANGLE_B64}"}}],
           "bufferViews": [{{"buffer": 0, "byteLength": 36}},
                           {{"buffer": 0, "byteOffset": 36, "byteLength": 6}}],
           "accessors": [{{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                           "min": [0, 0, 0], "max": [1, 1, 0]}},
                         {{"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}}]}}"#,
        roots = roots.join(", "),
    )
}

#[test]
fn an_accessor_that_does_not_exist_is_exit_2_not_a_panic() {
    // The gltf crate's validation indexed POSITION's accessor unchecked: exit 101.
    let file = gltf(r#"{"attributes": {"POSITION": 9}, "indices": 1}"#, 1);
    refused(
        "m.gltf",
        &[("m.gltf", &file)],
        &[
            "m.gltf: objects[0].mesh: invalid glTF: meshes[0].primitives[0].attributes.POSITION: \
             accessor 9 does not exist (the file has 2 accessors)",
        ],
    );
}

#[test]
fn a_tiny_file_with_89_million_zero_vertices_is_refused_at_once() {
    // 789 bytes: one triangle over a sparse POSITION accessor without a
    // bufferView, used by 20 nodes: 3 GB allocated, 26 s.
    let sparse = r#"{"componentType": 5126, "count": 89478485, "type": "VEC3",
        "min": [0, 0, 0], "max": [1, 1, 0],
        "sparse": {"count": 3, "indices": {"bufferView": 1, "componentType": 5123},
                   "values": {"bufferView": 0}}}"#;
    let file = gltf(r#"{"attributes": {"POSITION": 0}, "indices": 1}"#, 20).replacen(
        r#"{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                           "min": [0, 0, 0], "max": [1, 1, 0]}"#,
        sparse,
        1,
    );
    assert!(file.contains("89478485"));
    refused(
        "m.gltf",
        &[("m.gltf", &file)],
        &[
            "m.gltf: objects[0].mesh: accessor 0 (POSITION) has 89478485 vertices, but the \
             file's triangles refer to at most 3",
        ],
    );
}

#[test]
fn a_mesh_without_faces_is_the_same_error_for_obj_and_gltf() {
    // Both glTF files loaded as an object of no triangles (exit 0).
    let problem = |e: &str| e.split("objects[0].mesh: ").nth(1).unwrap().to_string();
    let obj = refused(
        "e.obj",
        &[("e.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n")],
        &["e.obj: objects[0].mesh: mesh has no faces"],
    );
    let cases = [
        gltf("", 1),
        gltf(r#"{"attributes": {"POSITION": 0}, "indices": 1}"#, 1).replacen(
            r#""componentType": 5123, "count": 3"#,
            r#""componentType": 5123, "count": 0"#,
            1,
        ),
    ];
    for file in cases {
        let e = refused(
            "e.gltf",
            &[("e.gltf", &file)],
            &["e.gltf: objects[0].mesh: "],
        );
        assert_eq!(problem(&e), problem(&obj), "{e}");
    }
}

#[test]
fn an_empty_or_folder_mesh_path_names_the_scene_file_and_field() {
    // The error named the scene's folder ("is a folder, not a file"), not s.toml.
    refused("", &[], &["s.toml: objects[0].mesh: mesh path is empty"]);
    refused(
        ".",
        &[],
        &["s.toml: objects[0].mesh: mesh path \".\" is a folder, not a file"],
    );
}

#[test]
fn eighty_thousand_named_nodes_export_promptly() {
    // Each node's label compared its name with every other: a hang.
    let dir = tempfile::tempdir().unwrap();
    let n = 80_000;
    let named: Vec<String> = (0..n)
        .map(|i| format!(r#"{{"mesh": 0, "name": "node{i}"}}"#))
        .collect();
    let file = gltf(r#"{"attributes": {"POSITION": 0}, "indices": 1}"#, n).replacen(
        &vec![r#"{"mesh": 0}"#; n].join(", "),
        &named.join(", "),
        1,
    );
    assert!(file.contains("node79999"));
    std::fs::write(dir.path().join("m.gltf"), file).unwrap();
    let scene = dir.path().join("s.toml");
    let text =
        format!("requires = [\"depth\"]\n{CAMERA}\n[[objects]]\nname = \"m\"\nmesh = \"m.gltf\"\n");
    std::fs::write(&scene, text).unwrap();
    let out = dir.path().join("export");
    let res = output_within(rendiff().arg("export").arg(&scene).arg("-o").arg(&out), 10);
    let stderr = String::from_utf8_lossy(&res.stderr);
    assert!(res.status.success(), "{:?}: {stderr}", res.status);
    assert!(out.exists());
}
