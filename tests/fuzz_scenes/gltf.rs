//! glTF input (issue 41 item 5): hostile `.gltf` and `.glb` files made
//! from one small valid file (two nodes, a quad of two indexed triangles)
//! by a few mutations each, so that most cases are near-valid and reach
//! the deep parts of the loader: malformed JSON and GLB containers (magic,
//! version, lengths, chunk types, truncation), accessor lies (counts,
//! offsets, strides, component types, views and buffers beyond their ends),
//! buffer URIs (malformed `data:` URIs, paths out of the folder, special
//! files, missing files, schemes, percent escapes), sparse accessors
//! (indices out of range, unsorted, repeated), primitive modes, huge
//! counts, NaN and infinite positions, node cycles and shared nodes, BOMs.
//! tests/hostile_meshes.rs holds the single regressions found before (an
//! accessor index past the end, a huge sparse accessor, a mesh of no
//! triangles, 80,000 named nodes); this generates their neighbourhood.
//!
//! Each mutation has a class. A case made only of mutations that keep the
//! file's meaning (a BOM, another container, padding, unknown fields and
//! chunks, a percent-escaped name) must export exactly the valid file's
//! triangles and object IDs, and render; a case of one mutation that the
//! glTF specification makes invalid and rendiff must refuse (a node cycle,
//! an index out of range, a NaN position, a broken container) must be
//! refused; anything else may load or be refused. Each is run through
//! `rendiff render --renderer raster` and `rendiff export` under the
//! failure contract of [`super::judge`].

use super::*;
use rendiff::scene::gltf::base64_encode;
use serde_json::{json, Value};

/// What a mutation does to the file's meaning.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Class {
    /// The file means the same: the same triangles must load.
    Same,
    /// The same, by other accessor data (a copy, a substitution): the
    /// file means the same, but a mutation of the original data may be
    /// hidden by it, so it never joins a case that must be refused.
    SameData,
    /// The file is invalid and rendiff must refuse it.
    Refuse,
    /// Either may be right (or the mutation may land where it changes nothing).
    Any,
}

/// When a mutation applies: to the JSON and the buffer's bytes, to the
/// buffer's URI once the container set it, or to the file's bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Phase {
    Structure,
    Uri,
    Bytes,
}

/// The file being mutated.
struct Doc {
    json: Value,
    bin: Vec<u8>,
    container: Container,
    /// The file's bytes (set in the Bytes phase).
    bytes: Vec<u8>,
    /// The JSON text's prefix and the GLB's extra chunk, if any.
    bom: bool,
    extra_chunk: bool,
    /// JSON pretty-printed (same meaning).
    pretty: bool,
    /// Set by a mutation that does not apply to this container (it then
    /// counts as no mutation).
    skipped: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Container {
    /// `.gltf`, its buffer a base64 `data:` URI.
    DataUri,
    /// `.gltf`, its buffer the file `b.bin` beside it.
    External,
    /// `.glb`, its buffer the BIN chunk.
    Glb,
}

impl Container {
    fn file_name(self) -> &'static str {
        match self {
            Container::Glb => "m.glb",
            _ => "m.gltf",
        }
    }
}

/// The valid file: scene 0 has node 0 ("root", translated) whose child
/// node 1 ("quad") has mesh 0: one TRIANGLES primitive, POSITION accessor 0
/// (4 float VEC3, bufferView 0, bytes 0..48) and indices accessor 1 (6
/// unsigned shorts, bufferView 1, bytes 48..60).
fn base() -> (Value, Vec<u8>) {
    let mut bin = Vec::new();
    for p in [
        [0.0f32, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ] {
        for x in p {
            bin.extend_from_slice(&x.to_le_bytes());
        }
    }
    for i in [0u16, 1, 2, 0, 2, 3] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let json = json!({
        "asset": {"version": "2.0", "generator": "rendiff fuzz"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [
            {"name": "root", "translation": [0.1, 0.0, 0.0], "children": [1]},
            {"name": "quad", "mesh": 0}
        ],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "mode": 4}]}],
        "buffers": [{"byteLength": 60}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48, "target": 34962},
            {"buffer": 0, "byteOffset": 48, "byteLength": 12, "target": 34963}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 0.0]},
            {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}
        ]
    });
    (json, bin)
}

/// A GLB container of `json` and (if any) `bin`, each chunk padded to 4
/// bytes as the specification says (JSON with spaces, BIN with zeros).
fn glb(json: &[u8], bin: Option<&[u8]>, extra_chunk: bool) -> Vec<u8> {
    let mut chunks = Vec::new();
    let mut chunk = |ty: &[u8; 4], data: &[u8], pad: u8| {
        let mut d = data.to_vec();
        while !d.len().is_multiple_of(4) {
            d.push(pad);
        }
        chunks.extend_from_slice(&(d.len() as u32).to_le_bytes());
        chunks.extend_from_slice(ty);
        chunks.extend_from_slice(&d);
    };
    chunk(b"JSON", json, b' ');
    if let Some(b) = bin {
        chunk(b"BIN\0", b, 0);
    }
    if extra_chunk {
        chunk(b"XTRA", b"ignored chunk", 0);
    }
    let mut out = b"glTF".to_vec();
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&((12 + chunks.len()) as u32).to_le_bytes());
    out.extend_from_slice(&chunks);
    out
}

/// A mutation: its name (shown on failure), class, phase and what it does
/// (`a` and `b` are random numbers it may use).
struct Mutation {
    name: &'static str,
    class: Class,
    phase: Phase,
    apply: fn(&mut Doc, u64, u64),
}

/// A hostile value for a JSON number field.
fn bad_number(a: u64) -> Value {
    [
        json!(-1),
        json!(0),
        json!(1),
        json!(3),
        json!(4294967295u64),
        json!(4294967296u64),
        json!(9007199254740993u64),
        json!(1.5),
        json!(-0.0),
        json!(1e300),
        json!("4"),
        json!(null),
        json!([]),
        json!({}),
        json!(true),
    ][(a % 15) as usize]
        .clone()
}

/// A pointer into the JSON of the fields a mutation may change.
const NUMBER_FIELDS: &[&str] = &[
    "/accessors/0/count",
    "/accessors/1/count",
    "/accessors/0/byteOffset",
    "/accessors/1/byteOffset",
    "/accessors/0/componentType",
    "/accessors/1/componentType",
    "/accessors/0/bufferView",
    "/accessors/1/bufferView",
    "/bufferViews/0/byteLength",
    "/bufferViews/1/byteLength",
    "/bufferViews/0/byteOffset",
    "/bufferViews/1/byteOffset",
    "/bufferViews/0/byteStride",
    "/bufferViews/0/buffer",
    "/buffers/0/byteLength",
    "/meshes/0/primitives/0/mode",
    "/meshes/0/primitives/0/indices",
    "/meshes/0/primitives/0/attributes/POSITION",
    "/nodes/1/mesh",
    "/scene",
    "/scenes/0/nodes/0",
    "/nodes/0/children/0",
];

fn set(doc: &mut Doc, pointer: &str, v: Value) {
    let (parent, key) = pointer.rsplit_once('/').unwrap();
    match doc.json.pointer_mut(parent) {
        Some(Value::Object(m)) => {
            m.insert(key.to_string(), v);
        }
        Some(Value::Array(a)) => {
            if let Ok(i) = key.parse::<usize>() {
                if i < a.len() {
                    a[i] = v;
                } else {
                    a.push(v);
                }
            }
        }
        _ => {}
    }
}

fn remove(doc: &mut Doc, pointer: &str) {
    let (parent, key) = pointer.rsplit_once('/').unwrap();
    if let Some(Value::Object(m)) = doc.json.pointer_mut(parent) {
        m.remove(key);
    }
}

/// Writes f32 `x` at byte `at` of the buffer (ignored past its end).
fn put_f32(doc: &mut Doc, at: usize, x: f32) {
    if at + 4 <= doc.bin.len() {
        doc.bin[at..at + 4].copy_from_slice(&x.to_le_bytes());
    }
}

/// Appends `bytes` to the buffer (4-byte aligned) as a new bufferView;
/// returns its index.
fn add_view(doc: &mut Doc, bytes: &[u8]) -> usize {
    while !doc.bin.len().is_multiple_of(4) {
        doc.bin.push(0);
    }
    let off = doc.bin.len();
    doc.bin.extend_from_slice(bytes);
    let len = doc.bin.len();
    set(doc, "/buffers/0/byteLength", json!(len));
    if !doc.json["bufferViews"].is_array() {
        doc.json["bufferViews"] = json!([]);
    }
    let views = doc.json["bufferViews"].as_array_mut().unwrap();
    views.push(json!({"buffer": 0, "byteOffset": off, "byteLength": bytes.len()}));
    views.len() - 1
}

/// Gives POSITION a sparse substitution of `indices` (as `ctype`) with
/// the points (k, k, 0.5).
fn sparse(doc: &mut Doc, indices: &[u32], ctype: u32) {
    let mut ib = Vec::new();
    for &i in indices {
        match ctype {
            5121 => ib.push(i as u8),
            5123 => ib.extend_from_slice(&(i as u16).to_le_bytes()),
            _ => ib.extend_from_slice(&i.to_le_bytes()),
        }
    }
    let mut vb = Vec::new();
    for k in 0..indices.len() {
        for x in [k as f32 * 0.25, k as f32 * 0.25, 0.5f32] {
            vb.extend_from_slice(&x.to_le_bytes());
        }
    }
    let iv = add_view(doc, &ib);
    let vv = add_view(doc, &vb);
    doc.json["accessors"][0]["sparse"] = json!({
        "count": indices.len(),
        "indices": {"bufferView": iv, "componentType": ctype},
        "values": {"bufferView": vv}
    });
    doc.json["accessors"][0]["max"] = json!([1.0, 1.0, 0.5]);
}

/// Every mutation. The weights of the classes come from how often each is
/// drawn ([`gltf_case`]).
const MUTATIONS: &[Mutation] = &[
    // ---- meaning kept
    Mutation {
        name: "BOM before the JSON",
        class: Class::Same,
        phase: Phase::Structure,
        apply: |d, _, _| d.bom = true,
    },
    Mutation {
        name: "pretty-printed JSON",
        class: Class::Same,
        phase: Phase::Structure,
        apply: |d, _, _| d.pretty = true,
    },
    Mutation {
        name: "unknown GLB chunk after the others",
        class: Class::Same,
        phase: Phase::Structure,
        apply: |d, _, _| {
            d.extra_chunk = true;
            d.skipped = d.container != Container::Glb;
        },
    },
    Mutation {
        name: "unknown fields and extras",
        class: Class::Same,
        phase: Phase::Structure,
        apply: |d, _, _| {
            d.json["extras"] = json!({"deep": [[[[1]]]], "s": "\u{1b}[31m"});
            d.json["nodes"][1]["colour"] = json!(3);
            d.json["extensionsUsed"] = json!(["VENDOR_unknown"]);
        },
    },
    Mutation {
        name: "materials, normals and a texture ignored",
        class: Class::Same,
        phase: Phase::Structure,
        apply: |d, _, _| {
            d.json["materials"] =
                json!([{"pbrMetallicRoughness": {"baseColorFactor": [1, 0, 0, 1]}}]);
            d.json["meshes"][0]["primitives"][0]["material"] = json!(0);
            d.json["images"] = json!([{"uri": "/etc/passwd"}]);
            d.json["textures"] = json!([{"source": 0}]);
        },
    },
    Mutation {
        name: "an interleaved copy of the positions, stride 16",
        class: Class::SameData,
        phase: Phase::Structure,
        apply: |d, _, _| {
            let pos: Vec<u8> = d.bin[..48].to_vec();
            let mut inter = Vec::new();
            for p in pos.chunks(12) {
                inter.extend_from_slice(p);
                inter.extend_from_slice(&[0xAB; 4]);
            }
            let v = add_view(d, &inter);
            d.json["bufferViews"][v]["byteStride"] = json!(16);
            d.json["accessors"][0]["bufferView"] = json!(v);
        },
    },
    Mutation {
        name: "percent-escaped buffer name",
        class: Class::Same,
        phase: Phase::Uri,
        apply: |d, _, _| {
            d.skipped = d.container != Container::External;
            if !d.skipped {
                set(d, "/buffers/0/uri", json!("b%2Ebin"));
            }
        },
    },
    Mutation {
        name: "upper-case data: URI scheme",
        class: Class::Same,
        phase: Phase::Uri,
        apply: |d, _, _| {
            d.skipped = d.container != Container::DataUri;
            if let Some(u) = d.json["buffers"][0]["uri"]
                .as_str()
                .and_then(|u| u.strip_prefix("data:"))
            {
                set(d, "/buffers/0/uri", json!(format!("DATA:{u}")));
            }
        },
    },
    Mutation {
        name: "a sorted sparse substitution of vertex 0 by itself",
        class: Class::SameData,
        phase: Phase::Structure,
        apply: |d, _, _| {
            let (v0, max) = (d.bin[..12].to_vec(), d.json["accessors"][0]["max"].clone());
            sparse(d, &[0], 5123);
            let n = d.bin.len();
            d.bin[n - 12..].copy_from_slice(&v0);
            d.json["accessors"][0]["max"] = max;
        },
    },
    // ---- invalid: must be refused
    Mutation {
        name: "JSON truncated",
        class: Class::Refuse,
        phase: Phase::Bytes,
        apply: |d, a, _| {
            d.skipped = d.container == Container::Glb;
            if !d.skipped {
                let body = if d.bom { 3 } else { 0 };
                let n = d.bytes.len() - body;
                d.bytes.truncate(body + 1 + (a as usize % (n - 1)));
            }
        },
    },
    Mutation {
        name: "file truncated",
        class: Class::Refuse,
        phase: Phase::Bytes,
        apply: |d, a, _| {
            let n = d.bytes.len();
            d.bytes.truncate(a as usize % n);
        },
    },
    Mutation {
        name: "GLB magic",
        class: Class::Refuse,
        phase: Phase::Bytes,
        apply: |d, a, _| {
            d.skipped = d.container != Container::Glb;
            if !d.skipped {
                d.bytes[(a % 4) as usize] ^= 0x20;
            }
        },
    },
    Mutation {
        name: "GLB version",
        class: Class::Refuse,
        phase: Phase::Bytes,
        apply: |d, a, _| {
            d.skipped = d.container != Container::Glb;
            if !d.skipped {
                let v = [0u32, 1, 3, u32::MAX][(a % 4) as usize];
                d.bytes[4..8].copy_from_slice(&v.to_le_bytes());
            }
        },
    },
    Mutation {
        name: "GLB total length",
        class: Class::Refuse,
        phase: Phase::Bytes,
        apply: |d, a, _| {
            d.skipped = d.container != Container::Glb;
            if !d.skipped {
                let n = d.bytes.len() as u32;
                let v = [0, 11, n - 1, n + 1, n + 4, u32::MAX][(a % 6) as usize];
                d.bytes[8..12].copy_from_slice(&v.to_le_bytes());
            }
        },
    },
    Mutation {
        name: "GLB JSON chunk length beyond the file",
        class: Class::Refuse,
        phase: Phase::Bytes,
        apply: |d, a, _| {
            d.skipped = d.container != Container::Glb;
            if !d.skipped {
                let left = d.bytes.len() as u32 - 20;
                let v = [left + 1, left + 4, u32::MAX, u32::MAX - 19][(a % 4) as usize];
                d.bytes[12..16].copy_from_slice(&v.to_le_bytes());
            }
        },
    },
    Mutation {
        name: "GLB first chunk not JSON",
        class: Class::Refuse,
        phase: Phase::Bytes,
        apply: |d, a, _| {
            d.skipped = d.container != Container::Glb;
            if !d.skipped {
                let ty: &[u8; 4] = [b"BIN\0", b"json", b"JSOX", b"\0\0\0\0"][(a % 4) as usize];
                d.bytes[16..20].copy_from_slice(ty);
            }
        },
    },
    Mutation {
        name: "node cycle",
        class: Class::Refuse,
        phase: Phase::Structure,
        apply: |d, a, _| match a % 3 {
            0 => d.json["nodes"][1]["children"] = json!([0]),
            1 => d.json["nodes"][1]["children"] = json!([1]),
            _ => d.json["nodes"][0]["children"] = json!([1, 1]),
        },
    },
    Mutation {
        name: "a node reached twice",
        class: Class::Refuse,
        phase: Phase::Structure,
        apply: |d, _, _| {
            d.json["scenes"][0]["nodes"] = json!([0, 1]);
        },
    },
    Mutation {
        name: "an index out of range",
        class: Class::Refuse,
        phase: Phase::Structure,
        apply: |d, a, _| {
            let i = [4u16, 5, 255, u16::MAX][(a % 4) as usize];
            let at = 48 + 2 * (a as usize / 4 % 6);
            if let Some(slot) = d.bin.get_mut(at..at + 2) {
                slot.copy_from_slice(&i.to_le_bytes());
            }
        },
    },
    Mutation {
        name: "a NaN or infinite position",
        class: Class::Refuse,
        phase: Phase::Structure,
        apply: |d, a, _| {
            let x = [
                f32::NAN,
                f32::INFINITY,
                f32::NEG_INFINITY,
                f32::from_bits(0x7fc0_0001),
            ][(a % 4) as usize];
            put_f32(d, 4 * (a as usize / 4 % 12), x);
        },
    },
    Mutation {
        name: "a NaN or infinite node transform",
        class: Class::Refuse,
        phase: Phase::Structure,
        apply: |d, a, _| {
            // JSON has no NaN: a number beyond f32 becomes infinite as f32.
            match a % 3 {
                0 => d.json["nodes"][0]["translation"] = json!([1e39, 0.0, 0.0]),
                1 => d.json["nodes"][1]["scale"] = json!([1.0, -1e300, 1.0]),
                _ => {
                    d.json["nodes"][1]["matrix"] =
                        json!([1e39, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1])
                }
            }
        },
    },
    Mutation {
        name: "a non-affine node matrix",
        class: Class::Refuse,
        phase: Phase::Structure,
        apply: |d, _, _| {
            d.json["nodes"][1]["matrix"] =
                json!([1, 0, 0, 0.5, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]);
        },
    },
    Mutation {
        name: "a zero rotation quaternion",
        class: Class::Refuse,
        phase: Phase::Structure,
        apply: |d, _, _| {
            d.json["nodes"][0]["rotation"] = json!([0.0, 0.0, 0.0, 0.0]);
        },
    },
    Mutation {
        name: "sparse index out of range",
        class: Class::Refuse,
        phase: Phase::Structure,
        apply: |d, a, _| {
            let ctype = [5121u32, 5123, 5125][(a % 3) as usize];
            sparse(d, &[1, 4 + (a as u32 / 3 % 250)], ctype);
        },
    },
    Mutation {
        name: "sparse count beyond the accessor's",
        class: Class::Refuse,
        phase: Phase::Structure,
        apply: |d, _, _| {
            sparse(d, &[0, 1, 2, 3, 3], 5125);
        },
    },
    Mutation {
        name: "accessor reads past its view",
        class: Class::Refuse,
        phase: Phase::Structure,
        apply: |d, a, _| match a % 4 {
            0 => d.json["accessors"][0]["count"] = json!(5),
            1 => d.json["accessors"][0]["byteOffset"] = json!(4),
            2 => d.json["accessors"][1]["byteOffset"] = json!(2),
            _ => d.json["accessors"][1]["count"] = json!(9),
        },
    },
    Mutation {
        name: "bufferView beyond its buffer",
        class: Class::Refuse,
        phase: Phase::Structure,
        apply: |d, a, _| match a % 3 {
            0 => d.json["bufferViews"][1]["byteLength"] = json!(16),
            1 => d.json["bufferViews"][1]["byteOffset"] = json!(52),
            _ => d.json["bufferViews"][0]["byteOffset"] = json!(18446744073709551615u64),
        },
    },
    Mutation {
        name: "buffer longer than its data",
        class: Class::Refuse,
        phase: Phase::Structure,
        apply: |d, a, _| {
            let n = d.bin.len();
            // By 4 bytes or more: a GLB's BIN chunk is padded to 4 bytes, and
            // a buffer may end up to 3 bytes before its chunk.
            match a % 2 {
                0 => d.bin.truncate(n - 4 - (a as usize / 2 % 8)),
                _ => d.json["buffers"][0]["byteLength"] = json!(n + 8),
            }
        },
    },
    Mutation {
        name: "a non-triangle mode",
        class: Class::Any,
        phase: Phase::Structure,
        apply: |d, a, _| {
            d.json["meshes"][0]["primitives"][0]["mode"] = json!(a % 4);
        },
    },
    Mutation {
        name: "strip or fan mode",
        class: Class::Any,
        phase: Phase::Structure,
        apply: |d, a, _| {
            d.json["meshes"][0]["primitives"][0]["mode"] = json!(5 + a % 2);
        },
    },
    Mutation {
        name: "POSITION not float VEC3",
        class: Class::Refuse,
        phase: Phase::Structure,
        apply: |d, a, _| match a % 3 {
            0 => d.json["accessors"][0]["type"] = json!("VEC2"),
            1 => d.json["accessors"][0]["componentType"] = json!(5123),
            _ => d.json["accessors"][0]["type"] = json!("MAT4"),
        },
    },
    Mutation {
        name: "indices not unsigned SCALAR",
        class: Class::Refuse,
        phase: Phase::Structure,
        apply: |d, a, _| match a % 3 {
            0 => d.json["accessors"][1]["componentType"] = json!(5126),
            1 => d.json["accessors"][1]["componentType"] = json!(5122),
            _ => d.json["accessors"][1]["type"] = json!("VEC2"),
        },
    },
    Mutation {
        name: "no scene to show",
        class: Class::Refuse,
        phase: Phase::Structure,
        apply: |d, a, _| match a % 3 {
            0 => d.json["scene"] = json!(7),
            1 => d.json["scenes"][0]["nodes"] = json!([]),
            _ => d.json["scenes"][0]["nodes"] = json!([9]),
        },
    },
    Mutation {
        name: "required extension",
        class: Class::Refuse,
        phase: Phase::Structure,
        apply: |d, a, _| {
            let e = [
                "KHR_draco_mesh_compression",
                "VENDOR_secret",
                "EXT_meshopt_compression",
            ][(a % 3) as usize];
            d.json["extensionsUsed"] = json!([e]);
            d.json["extensionsRequired"] = json!([e]);
        },
    },
    Mutation {
        name: "quantized positions",
        class: Class::Any,
        phase: Phase::Structure,
        apply: |d, a, _| {
            // Legal under KHR_mesh_quantization (issue 41 asks for it), not without.
            if a % 2 == 0 {
                d.json["extensionsUsed"] = json!(["KHR_mesh_quantization"]);
                d.json["extensionsRequired"] = json!(["KHR_mesh_quantization"]);
            }
            d.json["accessors"][0]["componentType"] =
                json!([5122u32, 5123, 5120, 5121][(a / 2 % 4) as usize]);
        },
    },
    Mutation {
        name: "skinned mesh node",
        class: Class::Refuse,
        phase: Phase::Structure,
        apply: |d, _, _| {
            d.json["skins"] = json!([{"joints": [0]}]);
            d.json["nodes"][1]["skin"] = json!(0);
        },
    },
    Mutation {
        name: "malformed data: URI",
        class: Class::Refuse,
        phase: Phase::Uri,
        apply: |d, a, _| {
            d.skipped = d.container != Container::DataUri;
            if let Some(u) = d.json["buffers"][0]["uri"].as_str().map(str::to_string) {
                if let Some((_, data)) = u.split_once(',') {
                    let bad = match a % 6 {
                        0 => "data:application/octet-stream;base64".to_string(),
                        1 => format!("data:application/octet-stream,{data}"),
                        2 => format!(
                            "data:application/octet-stream;base64,{}",
                            &data[..data.len() / 2]
                        ),
                        3 => format!(
                            "data:application/octet-stream;base64,{}%%",
                            &data[..data.len() - 2]
                        ),
                        4 => format!("data:application/octet-stream;base64,{data}==="),
                        _ => format!("data:application/octet-stream;base64,*{}", &data[1..]),
                    };
                    set(d, "/buffers/0/uri", json!(bad));
                }
            }
        },
    },
    Mutation {
        name: "buffer URI out of the folder, special or missing",
        class: Class::Refuse,
        phase: Phase::Uri,
        apply: |d, a, _| {
            let uri = [
                "../outside.bin",
                "%2e%2e/outside.bin",
                "/etc/passwd",
                "/dev/zero",
                "pipe.bin",
                "dir.bin",
                "zero.bin",
                "outlink.bin",
                "missing.bin",
                "file:///etc/passwd",
                "http://example.com/b.bin",
                "",
                "%ZZ.bin",
                "%ff.bin",
                "C:\\b.bin",
                "\\\\server\\b.bin",
                "b.bin\u{0}",
                "\u{1b}]0;title\u{7}.bin",
                "sub/../../outside.bin",
                "dir.bin/",
            ][(a % 20) as usize];
            set(d, "/buffers/0/uri", json!(uri));
        },
    },
    // ---- either may be right
    Mutation {
        name: "a number field set to a hostile value",
        class: Class::Any,
        phase: Phase::Structure,
        apply: |d, a, b| {
            let f = NUMBER_FIELDS[(a % NUMBER_FIELDS.len() as u64) as usize];
            set(d, f, bad_number(b));
        },
    },
    Mutation {
        name: "a huge count",
        class: Class::Any,
        phase: Phase::Structure,
        apply: |d, a, b| {
            let n = [65_536u64, 1 << 24, 89_478_485, 1 << 31, u32::MAX as u64][(b % 5) as usize];
            let f = ["/accessors/0/count", "/accessors/1/count"][(a % 2) as usize];
            set(d, f, json!(n));
        },
    },
    Mutation {
        name: "a field removed",
        class: Class::Any,
        phase: Phase::Structure,
        apply: |d, a, _| {
            let f = [
                "/asset",
                "/asset/version",
                "/accessors",
                "/buffers",
                "/bufferViews",
                "/meshes",
                "/nodes",
                "/scenes",
                "/scene",
                "/buffers/0/byteLength",
                "/accessors/0/bufferView",
                "/accessors/1/componentType",
                "/meshes/0/primitives/0/indices",
                "/meshes/0/primitives/0/attributes/POSITION",
                "/accessors/0/min",
                "/nodes/1/mesh",
                "/bufferViews/0/buffer",
                "/accessors/0/type",
            ][(a % 18) as usize];
            remove(d, f);
        },
    },
    Mutation {
        name: "asset version",
        class: Class::Any,
        phase: Phase::Structure,
        apply: |d, a, _| {
            d.json["asset"]["version"] = json!(["1.0", "3.0", "2.1", "", "2"][(a % 5) as usize]);
        },
    },
    Mutation {
        name: "sparse indices unsorted or repeated",
        class: Class::Any,
        phase: Phase::Structure,
        apply: |d, a, _| {
            let idx: &[u32] = [&[2, 1][..], &[1, 1], &[3, 0, 2], &[0, 0, 0, 0]][(a % 4) as usize];
            sparse(d, idx, 5125);
        },
    },
    Mutation {
        name: "sparse indices of another type",
        class: Class::Any,
        phase: Phase::Structure,
        apply: |d, a, _| {
            sparse(d, &[1], 5125);
            d.json["accessors"][0]["sparse"]["indices"]["componentType"] =
                json!([5120u32, 5126, 5122, 1][(a % 4) as usize]);
        },
    },
    Mutation {
        name: "sparse values or indices view beyond the buffer",
        class: Class::Any,
        phase: Phase::Structure,
        apply: |d, a, _| {
            sparse(d, &[1, 2], 5123);
            let which = ["indices", "values"][(a % 2) as usize];
            d.json["accessors"][0]["sparse"][which]["byteOffset"] =
                json!([4u64, 1 << 33, 1][(a / 2 % 3) as usize]);
        },
    },
    Mutation {
        name: "POSITION without a bufferView (zeros)",
        class: Class::Any,
        phase: Phase::Structure,
        apply: |d, _, _| {
            remove(d, "/accessors/0/bufferView");
        },
    },
    Mutation {
        name: "bufferView stride",
        class: Class::Any,
        phase: Phase::Structure,
        apply: |d, a, _| {
            d.json["bufferViews"][0]["byteStride"] =
                json!([0u32, 2, 4, 11, 12, 13, 252, 256, 4096][(a % 9) as usize]);
        },
    },
    Mutation {
        name: "node transforms (mirror, zero scale, huge)",
        class: Class::Any,
        phase: Phase::Structure,
        apply: |d, a, _| match a % 4 {
            0 => d.json["nodes"][1]["scale"] = json!([-1.0, 1.0, 1.0]),
            1 => d.json["nodes"][1]["scale"] = json!([0.0, 0.0, 0.0]),
            2 => d.json["nodes"][0]["translation"] = json!([3e38, 0.0, 0.0]),
            _ => d.json["nodes"][0]["rotation"] = json!([1e-30, 0.0, 0.0, 1e-30]),
        },
    },
    Mutation {
        name: "a large position",
        class: Class::Any,
        phase: Phase::Structure,
        apply: |d, a, _| {
            let x = [3.4e38f32, -3.4e38, 1e-45, 1e20][(a % 4) as usize];
            put_f32(d, 4 * (a as usize / 4 % 12), x);
        },
    },
    Mutation {
        name: "a random byte of the file changed",
        class: Class::Any,
        phase: Phase::Bytes,
        apply: |d, a, b| {
            let n = d.bytes.len();
            d.bytes[a as usize % n] = b as u8;
        },
    },
    Mutation {
        name: "a random byte inserted",
        class: Class::Any,
        phase: Phase::Bytes,
        apply: |d, a, b| {
            let n = d.bytes.len();
            d.bytes.insert(a as usize % (n + 1), b as u8);
        },
    },
    Mutation {
        name: "deeply nested JSON",
        class: Class::Any,
        phase: Phase::Structure,
        apply: |d, a, _| {
            // Past serde_json's recursion limit (128) or not; built as text below.
            let depth = [100usize, 127, 129, 5000][(a % 4) as usize];
            d.json["extras"] = json!({"nest": depth});
        },
    },
    Mutation {
        name: "duplicate key",
        class: Class::Any,
        phase: Phase::Bytes,
        apply: |d, _, _| {
            if d.container != Container::Glb {
                if let Some(at) = d.bytes.windows(8).position(|w| w == b"\"scene\":") {
                    d.bytes
                        .splice(at..at, b"\"scene\":5,".iter().copied())
                        .for_each(drop);
                }
            }
        },
    },
    Mutation {
        name: "not UTF-8",
        class: Class::Refuse,
        phase: Phase::Bytes,
        apply: |d, a, _| {
            d.skipped = d.container == Container::Glb;
            if !d.skipped {
                // Inside the generator string: the only place a byte can go
                // without breaking the syntax first.
                if let Some(at) = d.bytes.windows(6).position(|w| w == b"rendif") {
                    d.bytes[at + (a % 6) as usize] = 0xff;
                }
            }
        },
    },
];

/// Serializes the JSON (a `"nest": N` in `extras` becomes N nested arrays).
fn json_text(doc: &Doc) -> Vec<u8> {
    let mut text = if doc.pretty {
        serde_json::to_string_pretty(&doc.json).unwrap()
    } else {
        doc.json.to_string()
    };
    if let Some(depth) = doc.json["extras"]["nest"].as_u64() {
        let depth = depth as usize;
        let deep = format!("{}{}", "[".repeat(depth), "]".repeat(depth));
        text = text.replacen(&format!("\"nest\":{depth}"), &format!("\"nest\":{deep}"), 1);
        text = text.replacen(
            &format!("\"nest\": {depth}"),
            &format!("\"nest\": {deep}"),
            1,
        );
    }
    let mut out = if doc.bom {
        vec![0xEF, 0xBB, 0xBF]
    } else {
        Vec::new()
    };
    out.extend_from_slice(text.as_bytes());
    out
}

/// One case: the container and the mutations (index into [`MUTATIONS`]
/// and its two numbers).
#[derive(Debug, Clone)]
pub struct GltfCase {
    container: Container,
    mutations: Vec<(usize, u64, u64)>,
}

fn mutation_index() -> impl Strategy<Value = usize> {
    let (mut same, mut refuse, mut any) = (Vec::new(), Vec::new(), Vec::new());
    for (i, m) in MUTATIONS.iter().enumerate() {
        match m.class {
            Class::Same | Class::SameData => same.push(i),
            Class::Refuse => refuse.push(i),
            Class::Any => any.push(i),
        }
    }
    prop_oneof![
        3 => prop::sample::select(same),
        4 => prop::sample::select(refuse),
        4 => prop::sample::select(any),
    ]
}

pub fn gltf_case() -> impl Strategy<Value = GltfCase> {
    (
        prop::sample::select(vec![
            Container::DataUri,
            Container::External,
            Container::Glb,
        ]),
        prop_oneof![
            1 => Just(0usize),
            6 => Just(1),
            3 => Just(2),
            1 => Just(3),
        ]
        .prop_flat_map(|n| {
            prop::collection::vec((mutation_index(), any::<u64>(), any::<u64>()), n)
        }),
    )
        .prop_map(|(container, mutations)| GltfCase {
            container,
            mutations,
        })
}

impl GltfCase {
    /// The file's bytes, the buffer file's (External), and the class.
    fn build(&self) -> (Vec<u8>, Vec<u8>, Class) {
        let (json, bin) = base();
        let mut d = Doc {
            json,
            bin,
            container: self.container,
            bytes: Vec::new(),
            bom: false,
            extra_chunk: false,
            pretty: false,
            skipped: false,
        };
        let mut ms: Vec<&(usize, u64, u64)> = self.mutations.iter().collect();
        // By phase; within one, the data-copying ones last (they copy what
        // the others made).
        // Removing a field last (the others write into the JSON's tables).
        ms.sort_by_key(|(i, _, _)| {
            let m = &MUTATIONS[*i];
            (
                m.phase,
                m.class == Class::SameData,
                m.name == "a field removed",
            )
        });
        let mut classes = Vec::new();
        for phase in [Phase::Structure, Phase::Uri, Phase::Bytes] {
            if phase == Phase::Uri {
                self.encode_uri(&mut d);
            }
            if phase == Phase::Bytes {
                self.encode_bytes(&mut d);
            }
            for (i, a, b) in ms.iter().filter(|(i, _, _)| MUTATIONS[*i].phase == phase) {
                d.skipped = false;
                (MUTATIONS[*i].apply)(&mut d, *a, *b);
                if !d.skipped {
                    classes.push(MUTATIONS[*i].class);
                }
            }
        }
        let same = |c: &&Class| matches!(c, Class::Same | Class::SameData);
        let class = if classes.iter().all(|c| same(&c)) {
            Class::Same
        } else if classes.iter().filter(|c| !same(c)).count() == 1
            && classes.contains(&Class::Refuse)
            && !classes.contains(&Class::SameData)
        {
            Class::Refuse
        } else {
            Class::Any
        };
        (d.bytes, d.bin, class)
    }

    /// Sets the buffer's URI as the container has it.
    fn encode_uri(&self, d: &mut Doc) {
        match self.container {
            Container::DataUri => {
                let uri = format!(
                    "data:application/octet-stream;base64,{}",
                    base64_encode(&d.bin)
                );
                set(d, "/buffers/0/uri", json!(uri));
            }
            Container::External => set(d, "/buffers/0/uri", json!("b.bin")),
            Container::Glb => {}
        }
    }

    /// Writes the file's bytes.
    fn encode_bytes(&self, d: &mut Doc) {
        let text = json_text(d);
        d.bytes = match self.container {
            Container::Glb => glb(&text, Some(&d.bin), d.extra_chunk),
            _ => text,
        };
    }

    fn describe(&self) -> String {
        let names: Vec<String> = self
            .mutations
            .iter()
            .map(|(i, a, b)| format!("{} ({a}, {b})", MUTATIONS[*i].name))
            .collect();
        format!("{:?}: [{}]", self.container, names.join("; "))
    }
}

const SCENE: &str = "requires = [\"depth\", \"ids\"]\n\
[camera]\neye = [0.6, 0.5, 4.0]\nlook_at = [0.6, 0.5, 0.0]\nvfov = 40.0\nwidth = 24\nheight = 16\n\
[[objects]]\nname = \"m\"\n";

/// Writes the case's folder: `root/scenes/` with the scene, the glTF file,
/// its buffer file and the special entries the URI mutations name;
/// `root/outside.bin` a valid buffer outside the folder.
fn write_gltf_case(root: &Path, file: &str, bytes: &[u8], bin: &[u8]) -> PathBuf {
    let s = root.join("scenes");
    std::fs::create_dir_all(s.join("dir.bin")).unwrap();
    std::fs::create_dir_all(s.join("sub")).unwrap();
    std::fs::write(s.join(file), bytes).unwrap();
    std::fs::write(s.join("b.bin"), bin).unwrap();
    std::fs::write(root.join("outside.bin"), bin).unwrap();
    mkfifo(&s.join("pipe.bin"));
    std::os::unix::fs::symlink("/dev/zero", s.join("zero.bin")).unwrap();
    std::os::unix::fs::symlink("../outside.bin", s.join("outlink.bin")).unwrap();
    let scene = s.join("scene.toml");
    std::fs::write(&scene, format!("{SCENE}mesh = {file:?}\n")).unwrap();
    scene
}

/// The exported triangles and object IDs of a folder `rendiff export` wrote.
fn exported(dir: &Path) -> Option<(Vec<u8>, Vec<u8>)> {
    Some((
        std::fs::read(dir.join("triangles.f32")).ok()?,
        std::fs::read(dir.join("object_ids.u32")).ok()?,
    ))
}

/// Runs one glTF case; `want` is the valid file's export.
fn run_gltf_case(c: &GltfCase, want: &(Vec<u8>, Vec<u8>), t: &Tally) -> Vec<String> {
    let (bytes, bin, class) = c.build();
    let dir = tempfile::tempdir().unwrap();
    let scene = write_gltf_case(dir.path(), c.container.file_name(), &bytes, &bin);
    let out = dir.path().join("out");
    let mut problems = Vec::new();
    let (render, export, err) = render_and_export(&scene, &out, t, &mut problems);
    match class {
        Class::Same => {
            if render != End::Success || export != End::Success {
                wrong(
                    t,
                    &mut problems,
                    format!("a file of the same meaning was not loaded: {err}"),
                );
            } else if exported(&out.join("export")).as_ref() != Some(want) {
                wrong(
                    t,
                    &mut problems,
                    "a file of the same meaning exported other triangles".into(),
                );
            }
        }
        Class::Refuse => {
            for (what, end) in [("render", render), ("export", export)] {
                if end == End::Success {
                    wrong(
                        t,
                        &mut problems,
                        format!("{what}: an invalid file was loaded"),
                    );
                }
            }
        }
        Class::Any | Class::SameData => {}
    }
    problems
}

#[test]
fn hostile_gltf_files_fail_cleanly() {
    let cases: usize = env_number("RENDIFF_FUZZ_GLTF_CASES", 600);
    let seed: u64 = env_number("RENDIFF_FUZZ_SEED", 12);
    let all = generate(gltf_case(), cases, seed);
    // The valid file's export, once: what every case of the same meaning must give.
    let dir = tempfile::tempdir().unwrap();
    let valid = GltfCase {
        container: Container::External,
        mutations: Vec::new(),
    };
    let (bytes, bin, class) = valid.build();
    assert_eq!(class, Class::Same);
    let scene = write_gltf_case(dir.path(), "m.gltf", &bytes, &bin);
    let out = dir.path().join("out");
    let o = Command::new(binary())
        .arg("export")
        .arg(&scene)
        .arg("-o")
        .arg(out.join("export"))
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "the valid glTF file: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let want = exported(&out.join("export")).unwrap();
    assert_eq!(want.0.len(), 2 * 9 * 4, "the valid file has two triangles");
    let tally = Tally {
        kind_skip: 3, // program, file, field: the problem
        ..Tally::default()
    };
    let started = Instant::now();
    let failures = run_all(&all, 2, &tally, |c, t| run_gltf_case(c, &want, t));
    print_table("fuzz_scenes: glTF files", seed, started.elapsed(), &tally);
    let mut classes = std::collections::BTreeMap::new();
    for c in &all {
        *classes.entry(format!("{:?}", c.build().2)).or_insert(0) += 1;
    }
    eprintln!(
        "cases by class (Same: must load as the valid file; Refuse: must be refused): {classes:?}"
    );
    for (i, problems) in failures.iter().take(10) {
        let c = &all[*i];
        let (bytes, _, class) = c.build();
        let shown: String = String::from_utf8_lossy(&bytes).chars().take(1500).collect();
        eprintln!(
            "--- case {i} ({class:?}) {}:\n{}\nfile:\n{}",
            c.describe(),
            problems.join("\n"),
            shown.escape_debug()
        );
    }
    assert!(
        failures.is_empty(),
        "{} of {} glTF cases failed (first ones above)",
        failures.len(),
        all.len()
    );
}
