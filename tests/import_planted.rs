//! The `import` verdict catches planted import bugs (docs/verifier.md, "The
//! import verdict"). A buggy importer's output for a file F is rendiff's
//! correct output for a file F' that says what the bug reads (sparse values one
//! element off, a strip's indices as a list, a mirrored node's vertices mirrored
//! in the file with its winding kept, an OBJ's negative indices one off), so
//! each case exports F' and labels the result as F's import (scene.json's
//! `objects[].mesh.file`), exactly what the buggy importer would have written.
//! `python -m rendiff_harness import` must then fail, naming the primitive;
//! F's own export must pass, so every case can fail both ways.

mod common;

use common::cli::{need_venv, output_within, root};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::Command;

/// `rendiff export` of a scene showing `mesh` (a file in `dir`) into `dir/<out>`.
fn export(dir: &Path, mesh: &str, out: &str) -> PathBuf {
    let toml = dir.join(format!("{out}.toml"));
    std::fs::write(
        &toml,
        format!(
            "requires = [\"depth\", \"ids\"]\n[camera]\neye = [0.3, 0.2, 9.0]\nlook_at = [0.0, 0.0, 0.0]\n\
             vfov = 45.0\nwidth = 16\nheight = 16\n[[objects]]\nname = \"m\"\nmesh = \"{mesh}\"\n"
        ),
    )
    .unwrap();
    let dest = dir.join(out);
    let o = Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .arg("export")
        .arg(&toml)
        .arg("-o")
        .arg(&dest)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "export {mesh}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    dest
}

/// The import verdict of a resolved scene: (exit status, its lines).
fn verdict(resolved: &Path) -> (Option<i32>, String) {
    need_venv();
    let mut cmd = Command::new(root().join(".venv/bin/python"));
    cmd.current_dir(root())
        .env("PYTHONPATH", root().join("harness"))
        .args(["-m", "rendiff_harness", "import"])
        .arg(resolved);
    let o = output_within(&mut cmd, 120);
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    (o.status.code(), text)
}

/// Labels the export of F' in `bad` as the import of `good` (the file the scene names).
fn relabel(bad: &Path, good: &Path) {
    let meta = bad.join("scene.json");
    let mut v: Value = serde_json::from_slice(&std::fs::read(&meta).unwrap()).unwrap();
    for o in v["objects"].as_array_mut().unwrap() {
        o["mesh"]["file"] = json!(good.display().to_string());
    }
    std::fs::write(&meta, serde_json::to_vec(&v).unwrap()).unwrap();
}

/// F passes; F' labelled as F fails with every `needles` in the verdict.
fn planted(dir: &Path, good: &str, bad: &str, decoder: &str, needles: &[&str]) {
    let ok = export(dir, good, "good");
    let (code, text) = verdict(&ok);
    assert_eq!(code, Some(0), "the correct import must pass: {text}");
    let wrong = export(dir, bad, "bad");
    relabel(&wrong, &ok_file(dir, good));
    let (code, text) = verdict(&wrong);
    assert_eq!(code, Some(1), "the planted bug must fail: {text}");
    let line = text
        .lines()
        .find(|l| l.contains(&format!(" {decoder} import fail")))
        .unwrap_or_else(|| panic!("no failing {decoder} entry: {text}"));
    for n in needles {
        assert!(line.contains(n), "{n:?} not in {line}");
    }
}

fn ok_file(dir: &Path, name: &str) -> PathBuf {
    dir.join(name).canonicalize().unwrap()
}

fn f32s(v: &[[f32; 3]]) -> Vec<u8> {
    v.iter().flatten().flat_map(|x| x.to_le_bytes()).collect()
}

fn u16s(v: &[u16]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

const QUAD: [[f32; 3]; 4] = [[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [1., 1., 0.]];
const QUAD_INDICES: [u16; 6] = [0, 1, 2, 1, 3, 2];

/// A glTF with one node (extra node JSON merged in) over a quad whose
/// positions come from `positions` and whose buffer is the file `bin`.
fn gltf(dir: &Path, name: &str, bin: &str, data: &[u8], node: Value, accessor: Value) {
    std::fs::write(dir.join(bin), data).unwrap();
    let mut n = json!({"mesh": 0, "name": "quad"});
    for (k, v) in node.as_object().unwrap() {
        n[k] = v.clone();
    }
    let doc = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"children": [1], "translation": [0.25, 0.0, 0.0]}, n],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 1}, "indices": 0}]}],
        "buffers": [{"uri": bin, "byteLength": data.len()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 12},
            {"buffer": 0, "byteOffset": 12, "byteLength": 48},
            {"buffer": 0, "byteOffset": 60, "byteLength": 2},
            {"buffer": 0, "byteOffset": 64, "byteLength": 12}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5123, "count": 6, "type": "SCALAR"},
            accessor
        ]
    });
    std::fs::write(dir.join(name), serde_json::to_vec_pretty(&doc).unwrap()).unwrap();
}

/// Indices, the quad, one sparse index (u16, padded to 4 bytes), one sparse value.
fn quad_buffer(positions: &[[f32; 3]; 4], sparse_index: u16) -> Vec<u8> {
    let mut b = u16s(&QUAD_INDICES);
    b.extend(f32s(positions));
    b.extend(u16s(&[sparse_index, 0]));
    b.extend(f32s(&[[0.0, 2.0, 0.0]]));
    b
}

fn position_accessor(sparse: bool) -> Value {
    let mut a = json!({"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0]});
    if sparse {
        a["sparse"] = json!({"count": 1,
            "indices": {"bufferView": 2, "componentType": 5123},
            "values": {"bufferView": 3}});
    }
    a
}

/// F (`f.gltf`) and F' (`g.gltf`): the quad with each one's positions
/// and node JSON over one accessor, planted as [`planted`] does with the
/// glTF decoder written from the specification.
fn planted_quads(f: (Vec<u8>, Value), g: (Vec<u8>, Value), accessor: Value, needles: &[&str]) {
    let t = tempfile::tempdir().unwrap();
    gltf(t.path(), "f.gltf", "f.bin", &f.0, f.1, accessor.clone());
    gltf(t.path(), "g.gltf", "g.bin", &g.0, g.1, accessor);
    planted(t.path(), "f.gltf", "g.gltf", "gltf_spec", needles);
}

#[test]
fn sparse_values_at_the_wrong_index_fail_naming_the_primitive() {
    // Vertex 2 is replaced by (0, 2, 0); the buggy importer writes it over vertex 3.
    planted_quads(
        (quad_buffer(&QUAD, 2), json!({})),
        (quad_buffer(&QUAD, 3), json!({})),
        position_accessor(true),
        &[
            "object 'm/quad'",
            "mesh 0 primitive 0 (TRIANGLES sparse POSITION)",
            "rendiff departs from it",
        ],
    );
}

#[test]
fn a_mirrored_node_whose_winding_is_kept_fails_naming_the_primitive() {
    let mirrored = QUAD.map(|[x, y, z]| [-x, y, z]);
    // The same world positions without the mirror: what an importer that forgot to flip wrote.
    planted_quads(
        (quad_buffer(&QUAD, 0), json!({"scale": [-1.0, 1.0, 1.0]})),
        (quad_buffer(&mirrored, 0), json!({})),
        position_accessor(false),
        &[
            "object 'm/quad'",
            "(mirrored: winding reversed)",
            "mesh 0 primitive 0 (TRIANGLES) triangle 0",
            "the winding reversed",
        ],
    );
}

#[test]
fn a_strip_decoded_as_a_list_fails_naming_the_primitive() {
    let t = tempfile::tempdir().unwrap();
    let corpus = root().join("scenes/corpus/meshes/mesh_primitive_modes_triangles.gltf");
    let text = std::fs::read_to_string(corpus).unwrap();
    std::fs::write(t.path().join("f.gltf"), &text).unwrap();
    // The strip primitive's six indices read as two TRIANGLES.
    assert_eq!(text.matches("\"mode\": 5").count(), 1);
    std::fs::write(
        t.path().join("g.gltf"),
        text.replace("\"mode\": 5", "\"mode\": 4"),
    )
    .unwrap();
    planted(
        t.path(),
        "f.gltf",
        "g.gltf",
        "gltf_spec",
        &[
            "object 'm/5'",
            "mesh 5 primitive 0 (TRIANGLE_STRIP)",
            "rendiff has 2 triangles, gltf_spec 4",
        ],
    );
}

#[test]
fn an_obj_negative_index_off_by_one_fails_naming_the_face() {
    let t = tempfile::tempdir().unwrap();
    let v = "v 9 9 0\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n";
    // -k is vertex n - k + 1 (1-based, n = 5 read so far); the buggy importer takes n - k.
    std::fs::write(
        t.path().join("f.obj"),
        format!("{v}f -4 -3 -2\nf -3 -1 -2\n"),
    )
    .unwrap();
    std::fs::write(t.path().join("g.obj"), format!("{v}f 1 2 3\nf 2 4 3\n")).unwrap();
    planted(
        t.path(),
        "f.obj",
        "g.obj",
        "trimesh",
        &[
            "object 'm'",
            "triangle 0 (prim_id 0)",
            "tobj (rendiff) and trimesh disagree",
        ],
    );
}
