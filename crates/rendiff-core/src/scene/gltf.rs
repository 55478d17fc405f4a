//! glTF 2.0 loading (`.gltf` JSON with its buffers, or a binary `.glb`),
//! confined to the scene's folder like OBJ meshes.
//!
//! The `gltf` crate parses and validates the JSON (every index reference in
//! range, known enum values; the accessors a primitive names are checked
//! here first, as the crate's check of POSITION panics on a bad index);
//! everything that touches bytes is done here, so that each error names the
//! file and the problem in one line and no input can panic: the GLB
//! container is split here (the crate's own GLB reader underflows on a short
//! header), buffers are read here (relative file names inside the scene's
//! folder, or base64 `data:` URIs; never images), and accessors are read here
//! with every byte range checked. Only geometry is
//! read: positions (float, or quantized as `KHR_mesh_quantization` allows),
//! indices, primitive modes (points and lines skipped with a warning), the
//! node hierarchy with `EXT_mesh_gpu_instancing` instances, the scene the
//! user chose and, when the scene asks for it, one perspective camera.
//! Materials, textures, normals, animations and extensions that do not change
//! geometry are ignored; skins and non-zero morph weights are refused (the
//! geometry would not be the one a glTF viewer shows). The rules and the
//! naming are documented in docs/resolved-scene.md.

use super::generators::Tri64;
use super::{read_regular_file, GltfRef, SceneError, MAX_MESH_FILE_BYTES, MAX_SCENE_TRIANGLES};
use glam::{DMat3, DMat4, DQuat, DVec3};
use gltf::json;
use gltf::json::accessor::{ComponentType, Type as AccType};
use gltf::json::mesh::{Mode, Semantic};
use gltf::json::validation::Checked;
use std::collections::hash_map::Entry;
use std::collections::{HashMap, HashSet};
use std::path::{Component, Path};
use std::rc::Rc;

/// True when a mesh path names a glTF file (`.gltf` or `.glb`, any case):
/// the scene's `mesh` key takes OBJ and glTF alike, told apart by extension.
pub fn is_gltf_path(rel: &str) -> bool {
    let ext = Path::new(rel)
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    matches!(ext.as_deref(), Some("gltf" | "glb"))
}

/// One glTF node with a mesh, flattened: it becomes one rendiff object.
#[derive(Debug, Clone)]
pub struct GltfMeshNode {
    /// The node's label: its name, or its index when it has none (or shares
    /// its name with another mesh node: then `<name>#<index>`), untrusted text.
    pub label: String,
    /// Its triangles in the file's world space (node hierarchy applied in
    /// f64, not rounded), primitives in order, each in index order.
    pub triangles: Vec<Tri64>,
}

/// The camera the scene asked for, as the file states it (not yet mapped onto
/// rendiff's camera: the scene object's transform and the image size are
/// needed for that, see [`camera_spec`]).
#[derive(Debug, Clone)]
pub struct GltfCamera {
    /// Index of the node that places the camera.
    pub node: usize,
    /// Index into the file's `cameras`.
    pub camera: usize,
    /// The node's world matrix in the file (f64).
    pub world: DMat4,
    /// Vertical field of view in radians, as stored (f32).
    pub yfov: f32,
    /// Width / height, when the file states it.
    pub aspect: Option<f32>,
    /// Near clipping distance in the camera node's space.
    pub znear: f32,
    /// Far clipping distance in the camera node's space (infinite when absent).
    pub zfar: Option<f32>,
}

/// Which camera of the file to return, if any.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CameraRequest<'a> {
    /// The scene does not take its camera from this file.
    None,
    /// The first camera node in traversal order.
    First,
    /// The camera node whose node name or camera name is this.
    Named(&'a str),
    /// The node placing the file's camera of this index (`cameras[i]`).
    Index(usize),
}

impl<'a> CameraRequest<'a> {
    /// The request a scene file's `camera.gltf.camera` makes (none: the first).
    pub fn of(choice: Option<&'a GltfRef>) -> CameraRequest<'a> {
        match choice {
            None => CameraRequest::First,
            Some(GltfRef::Name(n)) => CameraRequest::Named(n),
            Some(GltfRef::Index(i)) => CameraRequest::Index(*i as usize),
        }
    }
}

/// What a glTF file contributes to a scene.
#[derive(Debug, Clone)]
pub struct GltfFile {
    /// The index of the glTF scene shown (the one chosen, else the file's
    /// default): recorded with each object so the import check reads the same.
    pub scene: usize,
    /// Mesh nodes in traversal order (see [`load_gltf`]).
    pub nodes: Vec<GltfMeshNode>,
    /// The requested camera ([`CameraRequest::None`] gives `None`).
    pub camera: Option<GltfCamera>,
    /// What was left out and why (a POINTS or LINES primitive), one line each,
    /// without the file name (the caller adds it, as for errors).
    pub warnings: Vec<String>,
}

/// The glTF extensions rendiff reads itself, so a file may require them:
/// the `gltf` crate refuses every required extension it does not know, and
/// it knows neither of these.
pub const READ_EXTENSIONS: [&str; 2] = ["KHR_mesh_quantization", "EXT_mesh_gpu_instancing"];

/// Most `EXT_mesh_gpu_instancing` instances a glTF file may place, all nodes
/// together: 2^20 = 1,048,576. Each instance is a rendiff object (a name and
/// its record, about 100 B with the export's JSON), so this keeps a hostile
/// file's objects near 100 MB; a forest of 100,000 instanced trees loads.
/// Instances also count their triangles against the scene's triangle budget.
pub const MAX_INSTANCES: u64 = 1 << 20;

/// Splits a GLB container into its JSON chunk and optional BIN chunk, or says
/// what is wrong with it. Chunks after the first two are ignored, as the
/// glTF specification requires for unknown chunks.
fn split_glb(bytes: &[u8]) -> Result<(&[u8], Option<&[u8]>), String> {
    let u32_at = |at: usize| -> u32 {
        u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
    };
    if bytes.len() < 12 {
        return Err(format!(
            "bad GLB header: the file has {} bytes, fewer than the 12-byte header",
            bytes.len()
        ));
    }
    if &bytes[..4] != b"glTF" {
        return Err(format!(
            "bad GLB header: the file starts with {:?}, not \"glTF\"",
            String::from_utf8_lossy(&bytes[..4])
        ));
    }
    let version = u32_at(4);
    if version != 2 {
        return Err(format!(
            "bad GLB header: version {version}, only version 2 is supported"
        ));
    }
    let length = u32_at(8) as usize;
    if length != bytes.len() {
        return Err(format!(
            "bad GLB header: it states a length of {length} bytes, the file has {}",
            bytes.len()
        ));
    }
    let mut at = 12usize;
    let mut chunks: Vec<([u8; 4], &[u8])> = Vec::new();
    while at < bytes.len() && chunks.len() < 2 {
        if bytes.len() - at < 8 {
            return Err(format!("GLB chunk {} header is truncated", chunks.len()));
        }
        let len = u32_at(at) as usize;
        let ty = [bytes[at + 4], bytes[at + 5], bytes[at + 6], bytes[at + 7]];
        let start = at + 8;
        if len > bytes.len() - start {
            return Err(format!(
                "GLB chunk {} ({}) states {len} bytes, only {} are left in the file",
                chunks.len(),
                String::from_utf8_lossy(&ty).trim_end_matches('\0'),
                bytes.len() - start
            ));
        }
        chunks.push((ty, &bytes[start..start + len]));
        at = start + len;
    }
    match chunks.first() {
        Some((ty, json)) if *ty == *b"JSON" => {
            let bin = chunks
                .get(1)
                .filter(|(ty, _)| ty == b"BIN\0")
                .map(|(_, b)| *b);
            Ok((json, bin))
        }
        _ => Err("GLB file does not start with a JSON chunk".into()),
    }
}

/// Decodes standard base64 (RFC 4648, `=` padding optional), refusing any
/// other character.
fn base64_decode(text: &str) -> Result<Vec<u8>, String> {
    let body = text.trim_end_matches('=');
    if text.len() - body.len() > 2 {
        return Err("bad base64 padding".into());
    }
    let mut out = Vec::with_capacity(body.len() / 4 * 3 + 3);
    let (mut acc, mut bits) = (0u32, 0u32);
    for (i, c) in body.bytes().enumerate() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return Err(format!("invalid base64 character at offset {i}")),
        };
        acc = (acc << 6) | u32::from(v);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    if bits >= 6 {
        return Err("truncated base64 data".into());
    }
    Ok(out)
}

/// Encodes standard base64 with `=` padding, the inverse of [`base64_decode`]:
/// what the tests that write glTF `data:` URIs use (this module's and
/// `tests/fuzz_scenes`), so that the encoding has one home, next to the
/// decoder it must agree with.
pub fn base64_encode(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let n = c
            .iter()
            .enumerate()
            .fold(0u32, |n, (i, b)| n | u32::from(*b) << (16 - 8 * i));
        for k in 0..=c.len() {
            s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
        }
    }
    while !s.len().is_multiple_of(4) {
        s.push('=');
    }
    s
}

/// Percent-decodes a URI reference into a relative path (UTF-8), or None when
/// an escape is malformed or not UTF-8.
fn percent_decode(uri: &str) -> Option<String> {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = std::str::from_utf8(b.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// Reads buffer `i`'s bytes (exactly its byteLength): the GLB BIN chunk, a
/// base64 `data:` URI, or a relative file next to the glTF file that must stay
/// inside `scene_dir` (no `..`, no absolute path, no scheme, no symlink out).
fn load_buffer(
    file: &Path,
    scene_dir: &Path,
    i: usize,
    b: &json::buffer::Buffer,
    bin: Option<&[u8]>,
    left: u64,
) -> Result<Vec<u8>, String> {
    let want = b.byte_length.0;
    if want > left {
        return Err(format!(
            "buffer {i} has a byteLength of {want} bytes; with the file's other buffers that is \
             more than the limit of {MAX_MESH_FILE_BYTES} bytes (1 GiB) per glTF file"
        ));
    }
    let want = want as usize;
    let (bytes, what): (Vec<u8>, String) = match b.uri.as_deref() {
        None => {
            let bin = bin.ok_or_else(|| {
                format!("buffer {i} has no uri and the file has no GLB BIN chunk")
            })?;
            (bin.to_vec(), format!("buffer {i} (GLB BIN chunk)"))
        }
        Some(uri)
            if uri
                .get(..5)
                .is_some_and(|h| h.eq_ignore_ascii_case("data:")) =>
        {
            let (head, data) = uri
                .split_once(',')
                .ok_or_else(|| format!("buffer {i}: data: URI without a comma"))?;
            if !head.to_ascii_lowercase().ends_with(";base64") {
                return Err(format!(
                    "buffer {i}: only base64 data: URIs are supported, got {:?}",
                    super::printable(head, 60)
                ));
            }
            if data.len() as u64 / 4 * 3 > left + 3 {
                return Err(format!(
                    "buffer {i}: its data: URI is larger than the limit of {MAX_MESH_FILE_BYTES} bytes"
                ));
            }
            let bytes = base64_decode(data).map_err(|p| format!("buffer {i}: data: URI: {p}"))?;
            (bytes, format!("buffer {i} (data: URI)"))
        }
        Some(uri) => {
            let shown = super::printable(uri, 80);
            let rel = percent_decode(uri).ok_or_else(|| {
                format!("buffer {i} ({shown}): malformed percent-escape in the uri")
            })?;
            let scheme = rel
                .split_once(':')
                .is_some_and(|(s, _)| !s.is_empty() && !s.contains('/'));
            if scheme {
                return Err(format!(
                    "buffer {i} ({shown}): only relative file names and base64 data: URIs are supported"
                ));
            }
            let p = Path::new(&rel);
            if rel.is_empty()
                || rel.starts_with('/')
                || rel.contains('\\')
                || p.is_absolute()
                || p.components()
                    .any(|c| matches!(c, Component::Prefix(_) | Component::RootDir))
            {
                return Err(format!(
                    "buffer {i} ({shown}) must be a relative path inside the scene's folder"
                ));
            }
            if p.components().any(|c| matches!(c, Component::ParentDir)) {
                return Err(format!(
                    "buffer {i} ({shown}) contains \"..\"; buffers must stay inside the scene's folder"
                ));
            }
            let joined = file.parent().unwrap_or(Path::new(".")).join(p);
            let full = match joined.canonicalize() {
                Ok(f) => f,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                    return Err(format!("buffer {i} ({shown}) is missing"))
                }
                Err(e) => return Err(format!("buffer {i} ({shown}) cannot be opened: {e}")),
            };
            let dir = scene_dir
                .canonicalize()
                .map_err(|e| format!("cannot resolve the scene folder: {e}"))?;
            if !full.starts_with(&dir) {
                return Err(format!(
                    "buffer {i} ({shown}) points outside the scene's folder {}",
                    dir.display()
                ));
            }
            let bytes = read_regular_file(&full, MAX_MESH_FILE_BYTES)
                .map_err(|p| format!("buffer {i} ({shown}) {p}"))?;
            (bytes, format!("buffer {i} ({shown})"))
        }
    };
    if bytes.len() < want {
        return Err(format!(
            "{what} is truncated: {} bytes, its byteLength is {want}",
            bytes.len()
        ));
    }
    let mut bytes = bytes;
    bytes.truncate(want);
    Ok(bytes)
}

/// Bytes per component of a glTF component type.
fn component_size(c: ComponentType) -> usize {
    match c {
        ComponentType::I8 | ComponentType::U8 => 1,
        ComponentType::I16 | ComponentType::U16 => 2,
        ComponentType::U32 | ComponentType::F32 => 4,
    }
}

/// Reads the accessor's elements (`count` x `elem` bytes, packed) from its
/// buffer view (zeros without one), with the sparse substitution applied;
/// every range is checked against its view and buffer.
fn accessor_bytes(
    root: &json::Root,
    buffers: &[Vec<u8>],
    ai: usize,
    elem: usize,
) -> Result<Vec<u8>, String> {
    let acc = root
        .accessors
        .get(ai)
        .ok_or_else(|| format!("accessor {ai} does not exist"))?;
    let count = acc.count.0;
    let total = count
        .checked_mul(elem as u64)
        .filter(|n| *n <= MAX_MESH_FILE_BYTES)
        .ok_or_else(|| {
            format!("accessor {ai} has {count} elements, more than a glTF file may hold")
        })? as usize;
    let count = count as usize;
    // (offset, length) of a buffer view within its buffer, checked.
    let view_bytes = |vi: usize| -> Result<&[u8], String> {
        let v = root
            .buffer_views
            .get(vi)
            .ok_or_else(|| format!("bufferView {vi} does not exist"))?;
        let bi = v.buffer.value();
        let buf = buffers
            .get(bi)
            .ok_or_else(|| format!("bufferView {vi}: buffer {bi} does not exist"))?;
        let off = v.byte_offset.map_or(0, |o| o.0);
        let end = off.checked_add(v.byte_length.0);
        match end {
            Some(end) if end <= buf.len() as u64 => Ok(&buf[off as usize..end as usize]),
            _ => Err(format!(
                "bufferView {vi} (bytes {off}..{}) lies outside buffer {bi} ({} bytes)",
                off.saturating_add(v.byte_length.0),
                buf.len()
            )),
        }
    };
    let mut out = vec![0u8; total];
    if let Some(vi) = acc.buffer_view.as_ref().map(|v| v.value()) {
        let data = view_bytes(vi)?;
        let stride = root.buffer_views[vi].byte_stride.map_or(elem, |s| s.0);
        if stride < elem {
            return Err(format!(
                "accessor {ai}: bufferView {vi} has byteStride {stride}, less than the element size {elem}"
            ));
        }
        let off = acc.byte_offset.map_or(0, |o| o.0) as usize;
        if count > 0 {
            let need = (count as u64 - 1)
                .checked_mul(stride as u64)
                .and_then(|n| n.checked_add(off as u64))
                .and_then(|n| n.checked_add(elem as u64));
            if need.is_none_or(|n| n > data.len() as u64) {
                return Err(format!(
                    "accessor {ai} ({count} elements from byte {off}, stride {stride}) reads past \
                     the end of bufferView {vi} ({} bytes)",
                    data.len()
                ));
            }
            for k in 0..count {
                let s = off + k * stride;
                out[k * elem..(k + 1) * elem].copy_from_slice(&data[s..s + elem]);
            }
        }
    }
    if let Some(sp) = &acc.sparse {
        let n = sp.count.0 as usize;
        if n > count {
            return Err(format!(
                "accessor {ai}: sparse count {n} exceeds the accessor's count {count}"
            ));
        }
        let isize = match sp.indices.component_type {
            Checked::Valid(json::accessor::IndexComponentType(c))
                if matches!(
                    c,
                    ComponentType::U8 | ComponentType::U16 | ComponentType::U32
                ) =>
            {
                component_size(c)
            }
            _ => {
                return Err(format!(
                    "accessor {ai}: sparse indices must be unsigned bytes, shorts or ints"
                ))
            }
        };
        let range = |vi: usize, off: u64, len: usize, what: &str| -> Result<&[u8], String> {
            let data = view_bytes(vi)?;
            let end = off.checked_add(len as u64);
            match end {
                Some(end) if end <= data.len() as u64 => Ok(&data[off as usize..end as usize]),
                _ => Err(format!(
                    "accessor {ai}: sparse {what} read past the end of bufferView {vi}"
                )),
            }
        };
        let idx = range(
            sp.indices.buffer_view.value(),
            sp.indices.byte_offset.0,
            n * isize,
            "indices",
        )?;
        let vals = range(
            sp.values.buffer_view.value(),
            sp.values.byte_offset.0,
            n * elem,
            "values",
        )?;
        for k in 0..n {
            let ib = &idx[k * isize..(k + 1) * isize];
            let t = match isize {
                1 => ib[0] as usize,
                2 => u16::from_le_bytes([ib[0], ib[1]]) as usize,
                _ => u32::from_le_bytes([ib[0], ib[1], ib[2], ib[3]]) as usize,
            };
            if t >= count {
                return Err(format!(
                    "accessor {ai}: sparse index {t} out of range (count {count})"
                ));
            }
            out[t * elem..(t + 1) * elem].copy_from_slice(&vals[k * elem..(k + 1) * elem]);
        }
    }
    Ok(out)
}

/// The accessor's element count (for budgeting before anything is read).
fn accessor_count(root: &json::Root, ai: usize) -> Result<u64, String> {
    root.accessors
        .get(ai)
        .map(|a| a.count.0)
        .ok_or_else(|| format!("accessor {ai} does not exist"))
}

/// One component of a float or quantized accessor, dequantized as the glTF
/// 2.0 specification defines normalized integers (`KHR_mesh_quantization`
/// refers to its table), in f64:
/// a normalized signed byte `c` is `max(c / 127, -1)`, an unsigned one
/// `c / 255`, a signed short `max(c / 32767, -1)`, an unsigned one
/// `c / 65535`; an unnormalized integer is its value; a float is itself.
fn dequantize(c: ComponentType, normalized: bool, b: &[u8]) -> f64 {
    let v = match c {
        ComponentType::F32 => return f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        ComponentType::I8 => f64::from(b[0] as i8),
        ComponentType::U8 => f64::from(b[0]),
        ComponentType::I16 => f64::from(i16::from_le_bytes([b[0], b[1]])),
        ComponentType::U16 => f64::from(u16::from_le_bytes([b[0], b[1]])),
        ComponentType::U32 => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
    };
    if !normalized {
        return v;
    }
    match c {
        ComponentType::I8 => (v / 127.0).max(-1.0),
        ComponentType::U8 => v / 255.0,
        ComponentType::I16 => (v / 32767.0).max(-1.0),
        ComponentType::U16 => v / 65535.0,
        _ => v / f64::from(u32::MAX),
    }
}

/// Reads a float or quantized accessor of `n` components per element
/// (`what` names it in messages) as f64 values, element after element,
/// refusing NaN and Inf. `signed_normalized_only` restricts integers to
/// normalized signed bytes and shorts (an instance ROTATION); otherwise any
/// byte or short, normalized or not, is read (`KHR_mesh_quantization`).
fn read_floats(
    root: &json::Root,
    buffers: &[Vec<u8>],
    ai: usize,
    what: &str,
    n: usize,
    signed_normalized_only: bool,
) -> Result<Vec<f64>, String> {
    let acc = root
        .accessors
        .get(ai)
        .ok_or_else(|| format!("accessor {ai} ({what}) does not exist"))?;
    let ty = match n {
        3 => AccType::Vec3,
        _ => AccType::Vec4,
    };
    let comp = match acc.component_type {
        Checked::Valid(json::accessor::GenericComponentType(c)) => Some(c),
        _ => None,
    };
    let ok = match comp {
        Some(ComponentType::F32) => true,
        Some(ComponentType::I8 | ComponentType::I16) if signed_normalized_only => acc.normalized,
        Some(ComponentType::I8 | ComponentType::I16 | ComponentType::U8 | ComponentType::U16) => {
            !signed_normalized_only
        }
        _ => false,
    };
    let (Some(comp), true, true) = (comp, ok, acc.type_ == Checked::Valid(ty)) else {
        let types = if signed_normalized_only {
            "float, or normalized signed byte or short"
        } else {
            "float, or (KHR_mesh_quantization) byte or short, signed or unsigned, normalized or not"
        };
        return Err(format!(
            "accessor {ai} ({what}) must be {} of {types}",
            if n == 3 { "VEC3" } else { "VEC4" }
        ));
    };
    let size = component_size(comp);
    let elem = n * size;
    let bytes = accessor_bytes(root, buffers, ai, elem)?;
    let mut out = Vec::with_capacity(bytes.len() / size);
    for (k, e) in bytes.chunks_exact(elem).enumerate() {
        let start = out.len();
        out.extend(
            e.chunks_exact(size)
                .map(|b| dequantize(comp, acc.normalized, b)),
        );
        if out[start..].iter().any(|x| !x.is_finite()) {
            return Err(format!(
                "accessor {ai} ({what}) element {k} is not finite (NaN or Inf): {:?}",
                &out[start..]
            ));
        }
    }
    Ok(out)
}

/// Reads a POSITION accessor (VEC3: float, or quantized as
/// `KHR_mesh_quantization` allows, dequantized by [`dequantize`]) as f64
/// points, refusing NaN and Inf.
fn read_positions(root: &json::Root, buffers: &[Vec<u8>], ai: usize) -> Result<Vec<DVec3>, String> {
    let v = read_floats(root, buffers, ai, "POSITION", 3, false)?;
    Ok(v.chunks_exact(3)
        .map(|p| DVec3::new(p[0], p[1], p[2]))
        .collect())
}

/// Reads an index accessor (unsigned SCALAR) and checks every index against
/// the vertex count.
fn read_indices(
    root: &json::Root,
    buffers: &[Vec<u8>],
    ai: usize,
    vertices: usize,
) -> Result<Vec<u32>, String> {
    let acc = &root.accessors[ai];
    let size = match (acc.component_type, acc.type_) {
        (
            Checked::Valid(json::accessor::GenericComponentType(c)),
            Checked::Valid(AccType::Scalar),
        ) if matches!(
            c,
            ComponentType::U8 | ComponentType::U16 | ComponentType::U32
        ) =>
        {
            component_size(c)
        }
        _ => {
            return Err(format!(
                "accessor {ai} (indices) must be an unsigned byte, short or int SCALAR"
            ))
        }
    };
    let bytes = accessor_bytes(root, buffers, ai, size)?;
    let mut out = Vec::with_capacity(bytes.len() / size);
    for e in bytes.chunks_exact(size) {
        let i = match size {
            1 => u32::from(e[0]),
            2 => u32::from(u16::from_le_bytes([e[0], e[1]])),
            _ => u32::from_le_bytes([e[0], e[1], e[2], e[3]]),
        };
        if i as usize >= vertices {
            return Err(format!(
                "accessor {ai} index {i} out of range (vertex count {vertices})"
            ));
        }
        out.push(i);
    }
    Ok(out)
}

/// The name of a primitive mode that is not a surface (points and lines),
/// or None for the three triangle modes.
fn non_surface(mode: Mode) -> Option<&'static str> {
    match mode {
        Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan => None,
        Mode::Points => Some("POINTS"),
        Mode::Lines => Some("LINES"),
        Mode::LineLoop => Some("LINE_LOOP"),
        Mode::LineStrip => Some("LINE_STRIP"),
    }
}

/// Triangles a primitive of a surface mode makes from `n` vertex references.
fn triangle_count(mode: Mode, n: u64, where_: &str) -> Result<u64, String> {
    match mode {
        Mode::Triangles if n.is_multiple_of(3) => Ok(n / 3),
        Mode::Triangles => Err(format!(
            "{where_} has {n} vertex references, not a multiple of 3 (mode TRIANGLES)"
        )),
        _ => Ok(n.saturating_sub(2)),
    }
}

/// The node's local matrix in f64: `matrix` (column-major, must be affine) or
/// T * R * S with the rotation quaternion normalized in f64.
fn local_matrix(n: &json::scene::Node, ni: usize) -> Result<DMat4, String> {
    if let Some(m) = n.matrix {
        if m.iter().any(|x| !x.is_finite()) {
            return Err(format!("node {ni} has a non-finite matrix"));
        }
        if m[3] != 0.0 || m[7] != 0.0 || m[11] != 0.0 || m[15] != 1.0 {
            return Err(format!(
                "node {ni}'s matrix is not affine (its last row is {:?}, not [0, 0, 0, 1])",
                [m[3], m[7], m[11], m[15]]
            ));
        }
        return Ok(DMat4::from_cols_array(&m.map(f64::from)));
    }
    let t = n.translation.unwrap_or([0.0; 3]);
    let r = n.rotation.unwrap_or_default().0;
    let s = n.scale.unwrap_or([1.0; 3]);
    if t.iter().chain(&r).chain(&s).any(|x| !x.is_finite()) {
        return Err(format!(
            "node {ni} has a non-finite translation, rotation or scale"
        ));
    }
    let q = DQuat::from_xyzw(r[0].into(), r[1].into(), r[2].into(), r[3].into());
    let len = q.length();
    if len.is_nan() || len <= 0.0 {
        return Err(format!("node {ni}'s rotation quaternion is zero"));
    }
    Ok(DMat4::from_scale_rotation_translation(
        DVec3::from(s.map(f64::from)),
        q / len,
        DVec3::from(t.map(f64::from)),
    ))
}

/// Vertices a glTF file's POSITION accessors may hold, all of them together,
/// beyond the vertex references of the scene's triangles in it (each mesh
/// primitive counted once however many nodes use it): 65,536 (2.4 MB as read).
///
/// Accessors are read whole, and one without a bufferView is zeros made from
/// nothing: a 789-byte file with a sparse POSITION accessor of 89 million
/// elements and one triangle made rendiff allocate 3 GB. A triangle refers to
/// at most three vertices and one no triangle refers to cannot change the
/// image, so the vertices read are held to the references (three per triangle
/// counted against [`MAX_SCENE_TRIANGLES`], two more per strip or fan); the
/// allowance keeps files with a few stray vertices (left by an editor, or a
/// vertex buffer shared with a mesh the scene does not show) loading.
pub const MAX_UNREFERENCED_VERTICES: u64 = 1 << 16;

/// A node with a mesh or a camera: (node index, world matrix, mesh or camera index).
type NodeAt = (usize, DMat4, usize);

/// The crate's validation reads each primitive's POSITION accessor without
/// checking that it exists (gltf-json 1.4.1, mesh.rs: an index past the end
/// panicked), so every accessor a primitive names (attributes, indices, morph
/// targets) is checked here first, all with the same message.
fn check_primitive_accessors(root: &json::Root) -> Result<(), String> {
    let n = root.accessors.len();
    for (mi, m) in root.meshes.iter().enumerate() {
        for (pi, p) in m.primitives.iter().enumerate() {
            let check = |ai: usize, what: &dyn Fn() -> String| {
                if ai < n {
                    return Ok(());
                }
                Err(format!(
                    "invalid glTF: meshes[{mi}].primitives[{pi}].{}: accessor {ai} does not \
                     exist (the file has {n} accessors)",
                    what()
                ))
            };
            for (semantic, a) in &p.attributes {
                check(a.value(), &|| {
                    format!("attributes.{}", semantic.to_string())
                })?;
            }
            if let Some(a) = &p.indices {
                check(a.value(), &|| "indices".into())?;
            }
            for (ti, t) in p.targets.iter().flatten().enumerate() {
                for (name, a) in [
                    ("POSITION", &t.positions),
                    ("NORMAL", &t.normals),
                    ("TANGENT", &t.tangents),
                ] {
                    if let Some(a) = a {
                        check(a.value(), &|| format!("targets[{ti}].{name}"))?;
                    }
                }
            }
        }
    }
    Ok(())
}

/// The crate's validation errors as one line: the first problem and how many more.
fn validation_problem(e: gltf::Error) -> String {
    match e {
        gltf::Error::Validation(list) => {
            let more = match list.len() {
                0 | 1 => String::new(),
                n => format!(" (and {} more problems)", n - 1),
            };
            match list.first() {
                Some((path, json::validation::Error::Unsupported)) => format!(
                    "invalid glTF: {path}: the file requires an extension rendiff's glTF \
                     reader does not support{more}"
                ),
                Some((path, e)) => format!("invalid glTF: {path}: {e}{more}"),
                None => "invalid glTF".into(),
            }
        }
        other => format!("invalid glTF: {other}"),
    }
}

/// The scene to show: the one the scene file chose (by index or by name,
/// which must name exactly one), else the file's `scene`, else its first.
fn pick_scene(root: &json::Root, choice: Option<&GltfRef>) -> Result<usize, String> {
    let n = root.scenes.len();
    match choice {
        Some(GltfRef::Index(i)) if (*i as usize) < n => Ok(*i as usize),
        Some(GltfRef::Index(i)) => Err(format!(
            "gltf_scene {i} does not exist (the file has {n} scene{})",
            if n == 1 { "" } else { "s" }
        )),
        Some(GltfRef::Name(name)) => {
            let hits: Vec<usize> = (0..n)
                .filter(|&i| root.scenes[i].name.as_deref() == Some(name.as_str()))
                .collect();
            let shown = super::printable(name, 80);
            match hits.as_slice() {
                [one] => Ok(*one),
                [] => Err(format!("gltf_scene: no glTF scene is named {shown:?}")),
                _ => Err(format!(
                    "gltf_scene: {} glTF scenes are named {shown:?} (scenes {hits:?}); choose one by index",
                    hits.len()
                )),
            }
        }
        None => root
            .scene
            .map(|s| s.value())
            .or(if n == 0 { None } else { Some(0) })
            .ok_or_else(|| "the glTF file has no scene".into()),
    }
}

/// The chosen scene's mesh nodes and camera nodes, depth first, pre-order,
/// with their world matrices; the hierarchy must be a tree and mesh nodes
/// unskinned.
fn scene_nodes(
    root: &json::Root,
    choice: Option<&GltfRef>,
) -> Result<(usize, Vec<NodeAt>, Vec<NodeAt>), String> {
    let scene = pick_scene(root, choice)?;
    let roots = &root
        .scenes
        .get(scene)
        .ok_or_else(|| format!("scene {scene} does not exist"))?
        .nodes;
    let mut visited = vec![false; root.nodes.len()];
    let mut stack: Vec<(usize, DMat4)> = roots
        .iter()
        .rev()
        .map(|n| (n.value(), DMat4::IDENTITY))
        .collect();
    let (mut mesh_nodes, mut camera_nodes) = (Vec::new(), Vec::new());
    while let Some((ni, parent)) = stack.pop() {
        let node = root
            .nodes
            .get(ni)
            .ok_or_else(|| format!("node {ni} does not exist"))?;
        if std::mem::replace(&mut visited[ni], true) {
            return Err(format!(
                "node {ni} is reached twice from scene {scene}: the node hierarchy must be a tree"
            ));
        }
        let world = parent * local_matrix(node, ni)?;
        if let Some(m) = &node.mesh {
            if node.skin.is_some() {
                return Err(format!(
                    "node {ni} has a skin; rendiff reads static geometry only"
                ));
            }
            mesh_nodes.push((ni, world, m.value()));
        }
        if let Some(c) = &node.camera {
            camera_nodes.push((ni, world, c.value()));
        }
        for c in node.children.iter().flatten().rev() {
            stack.push((c.value(), world));
        }
    }
    Ok((scene, mesh_nodes, camera_nodes))
}

/// What one mesh's primitives make: triangles, and vertex references (what
/// bounds the vertices worth reading, see [`MAX_UNREFERENCED_VERTICES`]).
#[derive(Debug, Clone, Copy, Default)]
struct MeshCount {
    triangles: u64,
    refs: u64,
    /// POINTS and LINES primitives left out.
    skipped: u64,
}

/// The index of a primitive's POSITION accessor (present: checked while counting).
fn position_accessor(p: &json::mesh::Primitive) -> Option<usize> {
    p.attributes
        .get(&Checked::Valid(Semantic::Positions))
        .map(|a| a.value())
}

/// The POSITION accessor of a primitive that makes triangles (None for a
/// POINTS or LINES primitive, which is never read).
fn surface_positions(p: &json::mesh::Primitive) -> Option<usize> {
    match p.mode {
        Checked::Valid(mode) if non_surface(mode).is_none() => position_accessor(p),
        _ => None,
    }
}

/// Counts mesh `mi` (first used by node `ni`) from its accessors' counts,
/// before any geometry is read, or says why it cannot be read. A POINTS or
/// LINES primitive is left out, with a line in `warnings` naming it.
fn count_mesh(
    root: &json::Root,
    mi: usize,
    ni: usize,
    warnings: &mut Vec<String>,
) -> Result<MeshCount, String> {
    let mesh = root
        .meshes
        .get(mi)
        .ok_or_else(|| format!("mesh {mi} does not exist"))?;
    if mesh.weights.iter().flatten().any(|w| *w != 0.0) {
        return Err(format!(
            "mesh {mi} (node {ni}) has non-zero morph weights; rendiff reads static geometry only"
        ));
    }
    let mut count = MeshCount::default();
    for (pi, p) in mesh.primitives.iter().enumerate() {
        let where_ = format!("mesh {mi} primitive {pi}");
        let Checked::Valid(mode) = p.mode else {
            return Err(format!("{where_} has an invalid mode"));
        };
        if let Some(name) = non_surface(mode) {
            let mesh_name = match mesh.name.as_deref() {
                Some(n) if !n.is_empty() => format!(" ({:?})", super::printable(n, 80)),
                _ => String::new(),
            };
            warnings.push(format!(
                "mesh {mi}{mesh_name} primitive {pi} has mode {name}: skipped (rendiff renders \
                 triangles only)"
            ));
            count.skipped += 1;
            continue;
        }
        let pos =
            position_accessor(p).ok_or_else(|| format!("{where_} has no POSITION attribute"))?;
        let refs = accessor_count(root, p.indices.map_or(pos, |i| i.value()))?;
        let triangles = triangle_count(mode, refs, &where_)?;
        count.triangles = count.triangles.saturating_add(triangles);
        count.refs = count.refs.saturating_add(refs);
    }
    Ok(count)
}

/// Each distinct mesh the nodes use, counted once, in order of first use (the
/// first problem reported is the one the first node meets).
fn count_meshes(
    root: &json::Root,
    mesh_nodes: &[NodeAt],
    warnings: &mut Vec<String>,
) -> Result<(Vec<usize>, HashMap<usize, MeshCount>), String> {
    let mut order = Vec::new();
    let mut counts = HashMap::new();
    for &(ni, _, mi) in mesh_nodes {
        if let Entry::Vacant(slot) = counts.entry(mi) {
            slot.insert(count_mesh(root, mi, ni, warnings)?);
            order.push(mi);
        }
    }
    Ok((order, counts))
}

/// Holds the POSITION accessors of `meshes` (each counted once) to the
/// vertex references `refs` plus [`MAX_UNREFERENCED_VERTICES`], before any is read.
fn check_vertex_bound(root: &json::Root, meshes: &[usize], refs: u64) -> Result<(), String> {
    let allowed = refs.saturating_add(MAX_UNREFERENCED_VERTICES);
    let mut seen = HashSet::new();
    let mut vertices = 0u64;
    for &mi in meshes {
        for ai in root.meshes[mi]
            .primitives
            .iter()
            .filter_map(surface_positions)
        {
            if !seen.insert(ai) {
                continue;
            }
            let n = accessor_count(root, ai)?;
            vertices = vertices.saturating_add(n);
            if vertices > allowed {
                let all = if vertices > n {
                    format!(" ({vertices} with the file's other POSITION accessors)")
                } else {
                    String::new()
                };
                return Err(format!(
                    "accessor {ai} (POSITION) has {n} vertices{all}, but the file's triangles \
                     refer to at most {refs}: more than {MAX_UNREFERENCED_VERTICES} vertices \
                     that no triangle uses are refused"
                ));
            }
        }
    }
    Ok(())
}

/// One primitive's triangles as vertex indices into its positions, which
/// are shared by every primitive (and node) using the same accessor.
struct Part {
    positions: Rc<Vec<DVec3>>,
    tris: Vec<[u32; 3]>,
}

/// The triangles a primitive's vertex references make (`mode` is one of the
/// three surface modes: the others were refused while counting), numbered as
/// the glTF specification defines strips and fans.
fn triangles_of(mode: Mode, idx: &[u32]) -> Vec<[u32; 3]> {
    let n = idx.len().saturating_sub(2);
    match mode {
        Mode::Triangles => idx.chunks_exact(3).map(|f| [f[0], f[1], f[2]]).collect(),
        Mode::TriangleStrip => (0..n)
            .map(|i| {
                if i % 2 == 0 {
                    [idx[i], idx[i + 1], idx[i + 2]]
                } else {
                    [idx[i], idx[i + 2], idx[i + 1]]
                }
            })
            .collect(),
        Mode::TriangleFan => (0..n).map(|i| [idx[i + 1], idx[i + 2], idx[0]]).collect(),
        _ => unreachable!("left out while counting"),
    }
}

/// Reads mesh `mi`'s primitives once, however many nodes use it; a POSITION
/// accessor already read (`cache`) is not read again. Primitives without
/// triangles are left out.
fn read_mesh(
    root: &json::Root,
    buffers: &[Vec<u8>],
    mi: usize,
    cache: &mut HashMap<usize, Rc<Vec<DVec3>>>,
) -> Result<Vec<Part>, String> {
    let mut parts = Vec::new();
    for p in &root.meshes[mi].primitives {
        let Checked::Valid(mode) = p.mode else {
            unreachable!("checked while counting")
        };
        // POINTS and LINES were left out (with a warning) while counting.
        let Some(pa) = surface_positions(p) else {
            continue;
        };
        let positions = match cache.entry(pa) {
            Entry::Occupied(e) => Rc::clone(e.get()),
            Entry::Vacant(e) => Rc::clone(e.insert(Rc::new(read_positions(root, buffers, pa)?))),
        };
        let idx: Vec<u32> = match &p.indices {
            Some(i) => read_indices(root, buffers, i.value(), positions.len())?,
            None => (0..positions.len() as u32).collect(),
        };
        let tris = triangles_of(mode, &idx);
        if !tris.is_empty() {
            parts.push(Part { positions, tris });
        }
    }
    Ok(parts)
}

/// A mesh's triangles placed by a node's world matrix (f64), the winding
/// reversed when the matrix mirrors.
fn place(parts: &[Part], world: DMat4) -> Vec<Tri64> {
    let identity = world == DMat4::IDENTITY;
    let flip = world.determinant() < 0.0;
    let mut out = Vec::with_capacity(parts.iter().map(|p| p.tris.len()).sum());
    for part in parts {
        let at = |k: u32| {
            let v = part.positions[k as usize];
            if identity {
                v
            } else {
                world.transform_point3(v)
            }
        };
        for &[a, b, c] in &part.tris {
            let t = [at(a), at(b), at(c)];
            out.push(if flip { [t[0], t[2], t[1]] } else { t });
        }
    }
    out
}

/// Labels: the node's name, its index when unnamed, `<name>#<index>` when
/// mesh nodes share the name (names counted once: comparing every pair hung
/// on 80,000 named nodes).
fn node_labels(root: &json::Root, mesh_nodes: &[NodeAt]) -> Vec<String> {
    let name_of = |ni: usize| root.nodes[ni].name.as_deref().filter(|s| !s.is_empty());
    let mut uses: HashMap<&str, usize> = HashMap::new();
    for &(ni, _, _) in mesh_nodes {
        if let Some(name) = name_of(ni) {
            *uses.entry(name).or_default() += 1;
        }
    }
    mesh_nodes
        .iter()
        .map(|&(ni, _, _)| match name_of(ni) {
            Some(name) if uses[name] > 1 => format!("{name}#{ni}"),
            Some(name) => name.to_string(),
            None => ni.to_string(),
        })
        .collect()
}

/// A node's `EXT_mesh_gpu_instancing` attributes: the accessors of its
/// instances' TRANSLATION, ROTATION and SCALE (each optional) and their
/// common count.
struct Instancing {
    translation: Option<usize>,
    rotation: Option<usize>,
    scale: Option<usize>,
    count: u64,
}

/// Reads node `ni`'s `EXT_mesh_gpu_instancing` object (None: the node has
/// none), checking its accessors exist and agree on their count, before any
/// is read. Attributes other than the three (an application's own, such as
/// `_ID`) are ignored.
fn instancing(root: &json::Root, ni: usize) -> Result<Option<Instancing>, String> {
    let Some(ext) = root.nodes[ni]
        .extensions
        .as_ref()
        .and_then(|e| e.others.get("EXT_mesh_gpu_instancing"))
    else {
        return Ok(None);
    };
    let bad = |p: String| format!("node {ni}: EXT_mesh_gpu_instancing {p}");
    let attrs = ext
        .get("attributes")
        .and_then(|a| a.as_object())
        .ok_or_else(|| bad("has no \"attributes\" object".into()))?;
    let n = root.accessors.len();
    let mut found = [None; 3];
    for (slot, name) in found.iter_mut().zip(["TRANSLATION", "ROTATION", "SCALE"]) {
        if let Some(v) = attrs.get(name) {
            let ai = v.as_u64().filter(|a| *a < n as u64).ok_or_else(|| {
                bad(format!(
                    "attribute {name} is not an accessor index (the file has {n} accessors)"
                ))
            })?;
            *slot = Some(ai as usize);
        }
    }
    let present: Vec<usize> = found.iter().flatten().copied().collect();
    let Some(&first) = present.first() else {
        return Err(bad("has none of TRANSLATION, ROTATION and SCALE".into()));
    };
    let count = root.accessors[first].count.0;
    if let Some(&other) = present
        .iter()
        .find(|&&a| root.accessors[a].count.0 != count)
    {
        return Err(bad(format!(
            "attributes have different counts (accessor {first}: {count}, accessor {other}: {})",
            root.accessors[other].count.0
        )));
    }
    let [translation, rotation, scale] = found;
    Ok(Some(Instancing {
        translation,
        rotation,
        scale,
        count,
    }))
}

/// The instances' matrices, `T * R * S` each (absent attributes: identity),
/// the rotation quaternion normalized in f64 like a node's; the node's world
/// matrix is applied after them (the extension's rule).
fn instance_matrices(
    root: &json::Root,
    buffers: &[Vec<u8>],
    ni: usize,
    inst: &Instancing,
) -> Result<Vec<DMat4>, String> {
    let n = inst.count as usize;
    let read = |ai: Option<usize>, what: &str, k: usize, signed: bool, default: &[f64]| match ai {
        Some(ai) => read_floats(root, buffers, ai, what, k, signed),
        None => Ok(default.repeat(n)),
    };
    let t = read(
        inst.translation,
        "instance TRANSLATION",
        3,
        false,
        &[0.0; 3],
    )?;
    let r = read(
        inst.rotation,
        "instance ROTATION",
        4,
        true,
        &[0.0, 0.0, 0.0, 1.0],
    )?;
    let s = read(inst.scale, "instance SCALE", 3, false, &[1.0; 3])?;
    (0..n)
        .map(|k| {
            let q = DQuat::from_xyzw(r[4 * k], r[4 * k + 1], r[4 * k + 2], r[4 * k + 3]);
            let len = q.length();
            if len.is_nan() || len <= 0.0 {
                return Err(format!(
                    "node {ni}: EXT_mesh_gpu_instancing instance {k}'s rotation quaternion is zero"
                ));
            }
            Ok(DMat4::from_scale_rotation_translation(
                DVec3::new(s[3 * k], s[3 * k + 1], s[3 * k + 2]),
                q / len,
                DVec3::new(t[3 * k], t[3 * k + 1], t[3 * k + 2]),
            ))
        })
        .collect()
}

/// The UTF-8 byte order mark. glTF forbids writers to add one before the
/// JSON but lets loaders ignore it (glTF 2.0, 3.2 "JSON encoding"), and
/// editors on Windows add it: ignored, rather than refused as malformed JSON.
const UTF8_BOM: [u8; 3] = [0xEF, 0xBB, 0xBF];

/// Loads a glTF 2.0 file (`.gltf` or `.glb`, told apart by the GLB magic;
/// a `.glb` without it is refused) as its mesh nodes and, if asked, a camera.
///
/// The scene used is the file's `scene`, else its first; its nodes are
/// visited depth first, pre-order, roots and children in the order the file
/// lists them; each node with a mesh is one [`GltfMeshNode`] in that order,
/// its primitives in order. World matrices are products of the local ones in
/// f64. TRIANGLE_STRIP and TRIANGLE_FAN are converted as the glTF
/// specification defines them; other non-triangle modes are refused. A node
/// whose world matrix has a negative determinant gets its triangles' winding
/// reversed (glTF's rule). The file, its buffers and all its triangles are
/// held to [`MAX_MESH_FILE_BYTES`] and `budget` (the triangles the scene has
/// left of [`MAX_SCENE_TRIANGLES`]), and its vertices to
/// [`MAX_UNREFERENCED_VERTICES`], before geometry is read; a file whose mesh
/// nodes make no triangle is refused like an OBJ file without faces. A
/// UTF-8 byte order mark before the JSON (of a `.gltf` or a GLB's JSON
/// chunk) is ignored.
pub fn load_gltf(
    file: &Path,
    scene_dir: &Path,
    field: &str,
    budget: u64,
    camera: CameraRequest<'_>,
) -> Result<GltfFile, SceneError> {
    load_gltf_scene(file, scene_dir, field, budget, None, camera)
}

/// [`load_gltf`] showing the glTF scene the scene file chose (`gltf_scene`:
/// an index into the file's `scenes`, or a name that must match exactly one;
/// None: the file's `scene`, else its first).
///
/// A node with `EXT_mesh_gpu_instancing` is drawn once per instance (and not
/// by itself, as the extension says), each instance one [`GltfMeshNode`]
/// labelled `<node label>/<k>` in instance order, its world matrix the
/// node's times the instance's `T * R * S`; instances are held to
/// [`MAX_INSTANCES`] and their triangles to `budget` before anything is
/// read. POINTS and LINES primitives are left out, each with a line in
/// [`GltfFile::warnings`]; a node whose mesh has nothing else is no object,
/// and a file with no triangle left is refused.
pub fn load_gltf_scene(
    file: &Path,
    scene_dir: &Path,
    field: &str,
    budget: u64,
    scene_choice: Option<&GltfRef>,
    camera: CameraRequest<'_>,
) -> Result<GltfFile, SceneError> {
    let err = |p: String| SceneError::new(file, field, p);
    let bytes =
        read_regular_file(file, MAX_MESH_FILE_BYTES).map_err(|p| err(format!("mesh file {p}")))?;
    let is_glb_ext = file
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("glb"));
    let (json_bytes, bin) = if is_glb_ext || bytes.starts_with(b"glTF") {
        split_glb(&bytes).map_err(err)?
    } else {
        (&bytes[..], None)
    };
    let json_bytes = json_bytes.strip_prefix(&UTF8_BOM[..]).unwrap_or(json_bytes);
    let mut root =
        json::Root::from_slice(json_bytes).map_err(|e| err(format!("malformed glTF JSON: {e}")))?;
    check_primitive_accessors(&root).map_err(err)?;
    // Read here, so a file may require them; the crate refuses every required
    // extension it does not know, these two included.
    root.extensions_required
        .retain(|e| !READ_EXTENSIONS.contains(&e.as_str()));
    let doc = gltf::Document::from_json(root).map_err(|e| err(validation_problem(e)))?;
    let root = doc.as_json();
    // Buffers, all of them, each exactly its byteLength.
    let mut left = MAX_MESH_FILE_BYTES.saturating_sub(bytes.len() as u64);
    let mut buffers = Vec::with_capacity(root.buffers.len());
    for (i, b) in root.buffers.iter().enumerate() {
        let data = load_buffer(file, scene_dir, i, b, bin, left).map_err(err)?;
        left = left.saturating_sub(data.len() as u64);
        buffers.push(data);
    }
    drop(bytes);
    let (scene, mesh_nodes, camera_nodes) = scene_nodes(root, scene_choice).map_err(err)?;
    // Count first, against the budget, before any geometry is read.
    let mut warnings = Vec::new();
    let (order, counts) = count_meshes(root, &mesh_nodes, &mut warnings).map_err(err)?;
    let mut instanced = Vec::with_capacity(mesh_nodes.len());
    let (mut count, mut instances) = (0u64, 0u64);
    for &(ni, _, mi) in &mesh_nodes {
        let inst = instancing(root, ni).map_err(err)?;
        let copies = inst.as_ref().map_or(1, |i| i.count);
        if inst.is_some() {
            instances = instances.saturating_add(copies);
            if instances > MAX_INSTANCES {
                return Err(err(format!(
                    "node {ni}: EXT_mesh_gpu_instancing brings the file's instances to {instances}, \
                     more than the limit of {MAX_INSTANCES} (each instance is an object)"
                )));
            }
        }
        count = count.saturating_add(counts[&mi].triangles.saturating_mul(copies));
        instanced.push(inst);
    }
    if count > budget {
        return Err(err(format!(
            "glTF file has {count} triangles; with the scene's other objects ({} triangles) \
             that is more than the limit of {MAX_SCENE_TRIANGLES} (64 Mi) per scene",
            MAX_SCENE_TRIANGLES.saturating_sub(budget)
        )));
    }
    if mesh_nodes.is_empty() {
        return Err(err(format!("glTF scene {scene} has no node with a mesh")));
    }
    if count == 0 {
        let skipped: u64 = counts.values().map(|c| c.skipped).sum();
        return Err(err(if skipped == 0 {
            super::NO_FACES.into()
        } else {
            format!(
                "{}: its {skipped} POINTS/LINES primitive(s) are skipped, and rendiff renders \
                 triangles only",
                super::NO_FACES
            )
        }));
    }
    let refs = counts.values().fold(0u64, |n, c| n.saturating_add(c.refs));
    check_vertex_bound(root, &order, refs).map_err(err)?;
    let mut cache = HashMap::new();
    let mut meshes = HashMap::new();
    for &mi in &order {
        meshes.insert(mi, read_mesh(root, &buffers, mi, &mut cache).map_err(err)?);
    }
    let mut nodes = Vec::with_capacity(mesh_nodes.len());
    for ((&(ni, world, mi), label), inst) in mesh_nodes
        .iter()
        .zip(node_labels(root, &mesh_nodes))
        .zip(&instanced)
    {
        // A mesh of points and lines only is no object (nothing of it is drawn).
        let c = counts[&mi];
        if c.skipped > 0 && c.skipped as usize == root.meshes[mi].primitives.len() {
            continue;
        }
        match inst {
            None => nodes.push(GltfMeshNode {
                label,
                triangles: place(&meshes[&mi], world),
            }),
            Some(inst) => {
                for (k, m) in instance_matrices(root, &buffers, ni, inst)
                    .map_err(err)?
                    .into_iter()
                    .enumerate()
                {
                    nodes.push(GltfMeshNode {
                        label: format!("{label}/{k}"),
                        triangles: place(&meshes[&mi], world * m),
                    });
                }
            }
        }
    }
    let camera = match camera {
        CameraRequest::None => None,
        request => Some(pick_camera(root, &camera_nodes, request).map_err(err)?),
    };
    Ok(GltfFile {
        scene,
        nodes,
        camera,
        warnings,
    })
}

/// The requested camera among the scene's camera nodes (traversal order).
fn pick_camera(
    root: &json::Root,
    camera_nodes: &[(usize, DMat4, usize)],
    request: CameraRequest<'_>,
) -> Result<GltfCamera, String> {
    let (ni, world, ci) = match request {
        CameraRequest::Named(name) => {
            let hits: Vec<_> = camera_nodes
                .iter()
                .filter(|(ni, _, ci)| {
                    root.nodes[*ni].name.as_deref() == Some(name)
                        || root.cameras.get(*ci).and_then(|c| c.name.as_deref()) == Some(name)
                })
                .collect();
            match hits.as_slice() {
                [one] => **one,
                [] => {
                    return Err(format!(
                        "no camera node or camera named {:?} in the glTF scene",
                        super::printable(name, 80)
                    ))
                }
                _ => {
                    return Err(format!(
                        "{} camera nodes match the name {:?}; name the node instead",
                        hits.len(),
                        super::printable(name, 80)
                    ))
                }
            }
        }
        CameraRequest::Index(want) => {
            let hits: Vec<_> = camera_nodes
                .iter()
                .filter(|(_, _, ci)| *ci == want)
                .collect();
            match hits.as_slice() {
                [one] => **one,
                [] if want >= root.cameras.len() => {
                    return Err(format!(
                        "camera {want} does not exist (the file has {} cameras)",
                        root.cameras.len()
                    ))
                }
                [] => {
                    return Err(format!(
                        "camera {want} is placed by no node of the chosen glTF scene"
                    ))
                }
                _ => {
                    return Err(format!(
                        "camera {want} is placed by {} nodes; choose one by its node's name",
                        hits.len()
                    ))
                }
            }
        }
        _ => *camera_nodes
            .first()
            .ok_or("the glTF scene has no camera node")?,
    };
    let cam = root
        .cameras
        .get(ci)
        .ok_or_else(|| format!("camera {ci} does not exist"))?;
    let persp = match (cam.type_, &cam.perspective) {
        (Checked::Valid(json::camera::Type::Perspective), Some(p)) => p,
        (Checked::Valid(json::camera::Type::Orthographic), _) => {
            return Err(format!(
                "camera {ci} (node {ni}) is orthographic; rendiff's camera is a pinhole \
                 (perspective only)"
            ))
        }
        _ => {
            return Err(format!(
                "camera {ci} (node {ni}) has no perspective projection"
            ))
        }
    };
    Ok(GltfCamera {
        node: ni,
        camera: ci,
        world,
        yfov: persp.yfov,
        aspect: persp.aspect_ratio,
        znear: persp.znear,
        zfar: persp.zfar,
    })
}

/// Relative tolerance for the camera's frame being a rotation times a uniform
/// scale, and for `aspectRatio` agreeing with width/height: a file stores both
/// in f32 (about 6e-8) after a decimal text of 7 or more digits; anything
/// further off is a different camera, refused rather than approximated.
pub const CAMERA_MATCH_TOLERANCE: f64 = 1e-6;

/// Maps the file's camera onto rendiff's pinhole camera, with the scene
/// object's transform (`m`, `tr`) applied after the camera node's world
/// matrix, or says why it cannot be mapped exactly.
///
/// eye = the node's origin; look_at = eye + the node's -Z axis (normalized);
/// up = its +Y axis (normalized); vfov = yfov in degrees (f64). The frame must
/// be a rotation times a uniform scale `s` (no shear, no mirror), within
/// [`CAMERA_MATCH_TOLERANCE`]; `aspectRatio`, when present, must equal
/// width / height within that tolerance (rendiff's pixels are square and the
/// image is never stretched). Unless the scene sets them, near = s * znear and
/// far = s * zfar (none: infinite).
pub fn camera_spec(
    cam: &GltfCamera,
    m: DMat3,
    tr: DVec3,
    spec: &super::CameraSpec,
) -> Result<super::CameraSpec, String> {
    let world = cam.world;
    let lin = m * DMat3::from_mat4(world);
    let eye = m * world.w_axis.truncate() + tr;
    let f = lin * DVec3::NEG_Z;
    let u = lin * DVec3::Y;
    let r = lin * DVec3::X;
    let (lf, lu, lr) = (f.length(), u.length(), r.length());
    let who = format!("camera {} (node {})", cam.camera, cam.node);
    let tol = CAMERA_MATCH_TOLERANCE;
    let finite = eye.is_finite() && [lf, lu, lr].iter().all(|x| x.is_finite() && *x > 0.0);
    if !finite {
        return Err(format!("{who}: its transform is degenerate or not finite"));
    }
    let uniform = (lf - lu).abs() <= tol * lf && (lr - lu).abs() <= tol * lu;
    let orthogonal = f.dot(u).abs() <= tol * lf * lu
        && f.dot(r).abs() <= tol * lf * lr
        && u.dot(r).abs() <= tol * lu * lr;
    if !(uniform && orthogonal) {
        return Err(format!(
            "{who}: its transform (with the object's) is not a rotation times a uniform scale, \
             so the view cannot be mapped onto a pinhole camera exactly"
        ));
    }
    if r.cross(u).dot(f) >= 0.0 {
        return Err(format!(
            "{who}: its transform (with the object's) mirrors the view; rendiff's camera \
             cannot be mirrored"
        ));
    }
    let (w, h) = (f64::from(spec.width), f64::from(spec.height));
    if let Some(a) = cam.aspect {
        let want = w / h;
        let a = f64::from(a);
        let off = (a - want).abs();
        if off.is_nan() || off > tol * want {
            return Err(format!(
                "{who} has aspectRatio {a}, but the image is {}x{} (aspect {want}); set \
                 camera.width/height to match (rendiff never stretches the picture)",
                spec.width, spec.height
            ));
        }
    }
    let yfov = f64::from(cam.yfov);
    if !(yfov.is_finite() && yfov > 0.0 && yfov < std::f64::consts::PI) {
        return Err(format!(
            "{who} has yfov {yfov} radians; it must be strictly between 0 and pi"
        ));
    }
    let znear = f64::from(cam.znear);
    if !(znear.is_finite() && znear > 0.0) {
        return Err(format!(
            "{who} has znear {znear}; it must be finite and > 0"
        ));
    }
    let zfar = cam.zfar.map(f64::from);
    if let Some(z) = zfar {
        if z.is_nan() || z <= znear {
            return Err(format!(
                "{who} has zfar {z}; it must be greater than znear {znear}"
            ));
        }
    }
    let dir = f / lf;
    Ok(super::CameraSpec {
        eye: Some(eye.to_array()),
        look_at: Some((eye + dir).to_array()),
        up: Some((u / lu).to_array()),
        vfov: Some(yfov.to_degrees()),
        width: spec.width,
        height: spec.height,
        near: spec.near.or(Some(znear * lu)),
        far: spec.far.or(zfar.map(|z| z * lu)),
        gltf: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    #[test]
    fn base64_encoding_is_the_decoders_inverse() {
        // Every length modulo 3 (padding of 0, 1 and 2 `=`), every byte value.
        let bytes: Vec<u8> = (0..=255u8).chain([0, 255, 7]).collect();
        for n in 0..bytes.len() {
            let text = base64_encode(&bytes[..n]);
            assert_eq!(text.len() % 4, 0, "{n} bytes: {text}");
            assert_eq!(
                base64_decode(&text).as_deref(),
                Ok(&bytes[..n]),
                "{n} bytes"
            );
        }
        assert_eq!(base64_encode(b"glTF"), "Z2xURg==");
    }

    /// A small glTF written by the test: accessor 0 = u16 indices (when
    /// any), accessor 1 = f32 VEC3 positions, mesh 0 = one primitive of
    /// `mode`; `nodes`/`roots`/`cameras` are JSON text.
    struct Doc {
        positions: Vec<[f32; 3]>,
        indices: Option<Vec<u16>>,
        mode: u32,
        nodes: String,
        roots: String,
        cameras: String,
        uri: Option<String>,
        byte_length: Option<usize>,
    }

    impl Doc {
        fn tri() -> Doc {
            Doc {
                positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                indices: Some(vec![0, 1, 2]),
                mode: 4,
                nodes: r#"[{"mesh": 0, "name": "tri"}]"#.into(),
                roots: "[0]".into(),
                cameras: "[]".into(),
                uri: Some("m.bin".into()),
                byte_length: None,
            }
        }

        fn index_bytes(&self) -> usize {
            self.indices
                .as_ref()
                .map_or(0, |i| (i.len() * 2).div_ceil(4) * 4)
        }

        fn bin(&self) -> Vec<u8> {
            let mut b = Vec::new();
            for i in self.indices.iter().flatten() {
                b.extend_from_slice(&i.to_le_bytes());
            }
            b.resize(self.index_bytes(), 0);
            for p in &self.positions {
                for c in p {
                    b.extend_from_slice(&c.to_le_bytes());
                }
            }
            b
        }

        fn json(&self) -> String {
            let ib = self.index_bytes();
            let pb = self.positions.len() * 12;
            let uri = match &self.uri {
                Some(u) => format!(r#""uri": {u:?}, "#),
                None => String::new(),
            };
            let (views, accessors, indices) = match &self.indices {
                Some(i) => (
                    format!(
                        r#"{{"buffer": 0, "byteOffset": 0, "byteLength": {}}},
                           {{"buffer": 0, "byteOffset": {ib}, "byteLength": {pb}}}"#,
                        i.len() * 2
                    ),
                    format!(
                        r#"{{"bufferView": 0, "componentType": 5123, "count": {}, "type": "SCALAR"}},
                           {{"bufferView": 1, "componentType": 5126, "count": {}, "type": "VEC3"}}"#,
                        i.len(),
                        self.positions.len()
                    ),
                    r#", "indices": 0"#,
                ),
                None => (
                    format!(r#"{{"buffer": 0, "byteOffset": 0, "byteLength": {pb}}}"#),
                    format!(
                        r#"{{"bufferView": 0, "componentType": 5126, "count": {}, "type": "VEC3"}}"#,
                        self.positions.len()
                    ),
                    "",
                ),
            };
            let pos = if self.indices.is_some() { 1 } else { 0 };
            // POSITION's min and max are required by the specification (and the crate).
            let bound = |f: fn(f32, f32) -> f32| {
                let b = (0..3).map(|k| {
                    let v = self
                        .positions
                        .iter()
                        .map(|p| p[k])
                        .fold(self.positions[0][k], f);
                    if v.is_finite() {
                        v.to_string()
                    } else {
                        "0".into()
                    }
                });
                b.collect::<Vec<_>>().join(", ")
            };
            let accessors = accessors.replacen(
                r#""type": "VEC3""#,
                &format!(
                    r#""type": "VEC3", "min": [{}], "max": [{}]"#,
                    bound(f32::min),
                    bound(f32::max)
                ),
                1,
            );
            format!(
                r#"{{"asset": {{"version": "2.0"}}, "scene": 0,
                   "scenes": [{{"nodes": {roots}}}],
                   "nodes": {nodes},
                   "cameras": {cameras},
                   "meshes": [{{"primitives": [{{"attributes": {{"POSITION": {pos}}}{indices}, "mode": {mode}}}]}}],
                   "buffers": [{{{uri}"byteLength": {len}}}],
                   "bufferViews": [{views}],
                   "accessors": [{accessors}]}}"#,
                roots = self.roots,
                nodes = self.nodes,
                cameras = self.cameras,
                mode = self.mode,
                len = self.byte_length.unwrap_or(ib + pb),
            )
        }

        /// Writes `m.gltf` and `m.bin` into `dir`.
        fn write(&self, dir: &Path) -> PathBuf {
            std::fs::write(dir.join("m.bin"), self.bin()).unwrap();
            let p = dir.join("m.gltf");
            std::fs::write(&p, self.json()).unwrap();
            p
        }

        /// The same document as a GLB (buffer 0 is the BIN chunk).
        fn glb(&self) -> Vec<u8> {
            let mut json = Doc {
                uri: None,
                nodes: self.nodes.clone(),
                roots: self.roots.clone(),
                cameras: self.cameras.clone(),
                indices: self.indices.clone(),
                positions: self.positions.clone(),
                ..*self
            }
            .json()
            .into_bytes();
            while !json.len().is_multiple_of(4) {
                json.push(b' ');
            }
            let bin = self.bin();
            let mut out = Vec::new();
            out.extend_from_slice(b"glTF");
            out.extend_from_slice(&2u32.to_le_bytes());
            out.extend_from_slice(&((12 + 8 + json.len() + 8 + bin.len()) as u32).to_le_bytes());
            out.extend_from_slice(&(json.len() as u32).to_le_bytes());
            out.extend_from_slice(b"JSON");
            out.extend_from_slice(&json);
            out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
            out.extend_from_slice(b"BIN\0");
            out.extend_from_slice(&bin);
            out
        }
    }

    /// A glTF file whose mesh 0 is one indexed triangle (indices 0 1 2) over
    /// a POSITION accessor of `count` vertices without a bufferView (zeros,
    /// the first three replaced by a sparse substitution), used by `nodes`
    /// unnamed root nodes.
    fn sparse_positions(count: u64, nodes: usize) -> String {
        let mut bin: Vec<u8> = [0u32, 1, 2].iter().flat_map(|i| i.to_le_bytes()).collect();
        for c in [0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
            bin.extend_from_slice(&c.to_le_bytes());
        }
        bin.extend([0u32, 1, 2].iter().flat_map(|i| i.to_le_bytes()));
        let list = vec![r#"{"mesh": 0}"#; nodes].join(", ");
        let roots: Vec<String> = (0..nodes).map(|i| i.to_string()).collect();
        format!(
            r#"{{"asset": {{"version": "2.0"}}, "scene": 0,
               "scenes": [{{"nodes": [{roots}]}}], "nodes": [{list}],
               "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1}}]}}],
               "buffers": [{{"byteLength": 60, "uri": "data:application/octet-stream;base64,{data}"}}],
               "bufferViews": [{{"buffer": 0, "byteLength": 12}},
                               {{"buffer": 0, "byteOffset": 12, "byteLength": 36}},
                               {{"buffer": 0, "byteOffset": 48, "byteLength": 12}}],
               "accessors": [{{"componentType": 5126, "count": {count}, "type": "VEC3",
                               "min": [0, 0, 0], "max": [1, 1, 0],
                               "sparse": {{"count": 3,
                                           "indices": {{"bufferView": 0, "componentType": 5125}},
                                           "values": {{"bufferView": 1}}}}}},
                             {{"bufferView": 2, "componentType": 5125, "count": 3, "type": "SCALAR"}}]}}"#,
            roots = roots.join(", "),
            data = base64_encode(&bin),
        )
    }

    fn load(p: &Path, dir: &Path) -> Result<GltfFile, SceneError> {
        load_gltf(
            p,
            dir,
            "objects[0].mesh",
            MAX_SCENE_TRIANGLES,
            CameraRequest::None,
        )
    }

    fn load_err(p: &Path, dir: &Path) -> String {
        let e = load(p, dir).expect_err("loaded").to_string();
        assert_eq!(e.lines().count(), 1, "{e}");
        assert!(e.contains(&*p.display().to_string()), "{e}");
        e
    }

    fn close(a: DVec3, b: [f64; 3]) -> bool {
        (a - DVec3::from(b)).abs().max_element() < 1e-6
    }

    #[test]
    fn node_hierarchy_is_applied_in_traversal_order() {
        let dir = tempfile::tempdir().unwrap();
        let mut d = Doc::tri();
        // Root 0 (translated) with children 1 (rotated 90 deg about z, scaled
        // by 2) and 2 (a matrix: translate y by 5); root 3 has no name.
        let s = std::f32::consts::FRAC_1_SQRT_2;
        d.nodes = format!(
            r#"[{{"name": "base", "translation": [10, 0, 0], "children": [1, 2]}},
                {{"name": "arm", "mesh": 0, "rotation": [0, 0, {s}, {s}], "scale": [2, 2, 2]}},
                {{"name": "lifted", "mesh": 0,
                  "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,5,0,1]}},
                {{"mesh": 0}}]"#
        );
        d.roots = "[3, 0]".into();
        let f = load(&d.write(dir.path()), dir.path()).unwrap();
        let labels: Vec<&str> = f.nodes.iter().map(|n| n.label.as_str()).collect();
        assert_eq!(labels, ["3", "arm", "lifted"]);
        let t = &f.nodes[1].triangles[0];
        assert!(close(t[0], [10.0, 0.0, 0.0]), "{t:?}");
        assert!(close(t[1], [10.0, 2.0, 0.0]), "{t:?}");
        assert!(close(t[2], [8.0, 0.0, 0.0]), "{t:?}");
        let t = &f.nodes[2].triangles[0];
        assert_eq!(t[1], DVec3::new(11.0, 5.0, 0.0));
        // The unnamed root is untransformed: its vertices are the file's.
        assert_eq!(f.nodes[0].triangles[0][1], DVec3::new(1.0, 0.0, 0.0));
    }

    #[test]
    fn a_mirroring_node_reverses_the_winding() {
        let dir = tempfile::tempdir().unwrap();
        let mut d = Doc::tri();
        d.nodes = r#"[{"mesh": 0, "scale": [-1, 1, 1]}]"#.into();
        let f = load(&d.write(dir.path()), dir.path()).unwrap();
        let t = f.nodes[0].triangles[0];
        assert_eq!(t, [DVec3::ZERO, DVec3::Y, DVec3::NEG_X]);
    }

    #[test]
    fn strips_fans_non_indexed_glb_and_data_uris_load() {
        let dir = tempfile::tempdir().unwrap();
        let quad = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
        ];
        let mut d = Doc::tri();
        d.positions = quad.clone();
        d.indices = None;
        d.mode = 5; // TRIANGLE_STRIP: (0 1 2), (1 3 2)
        let f = load(&d.write(dir.path()), dir.path()).unwrap();
        let v = |i: usize| DVec3::from(quad[i].map(f64::from));
        assert_eq!(
            f.nodes[0].triangles,
            vec![[v(0), v(1), v(2)], [v(1), v(3), v(2)]]
        );
        d.mode = 6; // TRIANGLE_FAN: (1 2 0), (2 3 0)
        let f = load(&d.write(dir.path()), dir.path()).unwrap();
        assert_eq!(
            f.nodes[0].triangles,
            vec![[v(1), v(2), v(0)], [v(2), v(3), v(0)]]
        );

        let d = Doc::tri();
        let p = dir.path().join("m.glb");
        std::fs::write(&p, d.glb()).unwrap();
        let f = load(&p, dir.path()).unwrap();
        assert_eq!(f.nodes[0].triangles[0][2], DVec3::Y);

        let mut d = Doc::tri();
        let b64 = base64_encode(&d.bin());
        d.uri = Some(format!("data:application/octet-stream;base64,{b64}"));
        let p = dir.path().join("embedded.gltf");
        std::fs::write(&p, d.json()).unwrap();
        let f = load(&p, dir.path()).unwrap();
        assert_eq!(f.nodes[0].triangles[0][1], DVec3::X);
    }

    #[test]
    fn a_utf8_bom_before_the_json_is_ignored() {
        // Editors on Windows write one; glTF tells loaders they may ignore it.
        let dir = tempfile::tempdir().unwrap();
        let d = Doc::tri();
        let plain = load(&d.write(dir.path()), dir.path()).unwrap();
        let p = dir.path().join("m.gltf");
        std::fs::write(&p, [&UTF8_BOM[..], d.json().as_bytes()].concat()).unwrap();
        let with_bom = load(&p, dir.path()).unwrap();
        assert_eq!(with_bom.nodes.len(), plain.nodes.len());
        assert_eq!(with_bom.nodes[0].triangles, plain.nodes[0].triangles);
        // Only a leading one: a BOM anywhere else is still malformed JSON, named as such.
        std::fs::write(&p, [b" ", &UTF8_BOM[..], d.json().as_bytes()].concat()).unwrap();
        assert!(load_err(&p, dir.path()).contains("malformed glTF JSON"));
    }

    #[test]
    fn bad_input_gives_one_line_naming_file_and_problem() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path();
        let p = Doc::tri().write(path);
        std::fs::remove_file(path.join("m.bin")).unwrap();
        assert!(load_err(&p, path).contains("buffer 0 (m.bin) is missing"));

        let mut d = Doc::tri();
        d.indices = Some(vec![0, 1, 912]);
        assert!(load_err(&d.write(path), path)
            .contains("accessor 0 index 912 out of range (vertex count 3)"));

        let mut d = Doc::tri();
        d.positions[1][1] = f32::NAN;
        assert!(load_err(&d.write(path), path)
            .contains("accessor 1 (POSITION) element 1 is not finite"));

        std::fs::write(path.parent().unwrap().join("x.bin"), Doc::tri().bin()).unwrap();
        let mut d = Doc::tri();
        d.uri = Some("../x.bin".into());
        assert!(load_err(&d.write(path), path).contains("contains \"..\""));
        d.uri = Some(path.join("m.bin").display().to_string());
        assert!(load_err(&d.write(path), path).contains("must be a relative path"));
        d.uri = Some("file:///etc/passwd".into());
        assert!(load_err(&d.write(path), path).contains("only relative file names"));

        let mut d = Doc::tri();
        d.byte_length = Some(1000);
        assert!(load_err(&d.write(path), path)
            .contains("buffer 0 (m.bin) is truncated: 44 bytes, its byteLength is 1000"));

        let mut d = Doc::tri();
        d.mode = 1;
        let e = load_err(&d.write(path), path);
        assert!(
            e.ends_with(&format!(
                "{}: its 1 POINTS/LINES primitive(s) are skipped, and rendiff renders triangles only",
                super::super::NO_FACES
            )),
            "{e}"
        );

        let p = path.join("broken.gltf");
        std::fs::write(&p, "{\"asset\": {\"version\": \"2.0\"},\n\"nodes\": [}").unwrap();
        assert!(load_err(&p, path).contains("malformed glTF JSON"));

        let p = path.join("bad.glb");
        let mut glb = Doc::tri().glb();
        glb[4] = 1;
        std::fs::write(&p, &glb).unwrap();
        assert!(load_err(&p, path).contains("bad GLB header: version 1"));
        std::fs::write(&p, b"{\"asset\": {}}").unwrap();
        assert!(load_err(&p, path).contains("bad GLB header"));
        std::fs::write(&p, b"glTF\x02\0\0\0\x04\0\0\0").unwrap();
        assert!(load_err(&p, path).contains("bad GLB header"));
    }

    #[test]
    fn hostile_values_are_errors_not_panics() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path();
        let d = Doc::tri();
        let json = d.json().replacen(
            r#""bufferView": 1, "componentType""#,
            r#""bufferView": 1, "byteOffset": 18446744073709551615, "componentType""#,
            1,
        );
        std::fs::write(path.join("m.bin"), d.bin()).unwrap();
        let p = path.join("off.gltf");
        std::fs::write(&p, json).unwrap();
        assert!(load_err(&p, path).contains("reads past the end of bufferView 1"));

        let mut d = Doc::tri();
        d.uri = Some("ééé.bin".into());
        assert!(load_err(&d.write(path), path).contains("(ééé.bin) is missing"));

        let mut d = Doc::tri();
        d.nodes = r#"[{"children": [1]}, {"mesh": 0, "children": [0]}]"#.into();
        assert!(load_err(&d.write(path), path).contains("node 0 is reached twice"));

        let mut d = Doc::tri();
        d.nodes = r#"[{"mesh": 0, "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,1, 0,0,0,1]}]"#.into();
        assert!(load_err(&d.write(path), path).contains("node 0's matrix is not affine"));
    }

    #[test]
    fn no_panic_on_truncated_or_mangled_glb() {
        let dir = tempfile::tempdir().unwrap();
        let glb = Doc::tri().glb();
        let p = dir.path().join("t.glb");
        for n in 0..glb.len() {
            std::fs::write(&p, &glb[..n]).unwrap();
            assert!(load(&p, dir.path()).is_err(), "prefix of {n} bytes loaded");
        }
        for i in 0..glb.len() {
            let mut g = glb.clone();
            g[i] ^= 0xff;
            std::fs::write(&p, &g).unwrap();
            let _ = load(&p, dir.path());
        }
    }

    #[test]
    fn cameras_map_or_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut d = Doc::tri();
        d.cameras = r#"[{"type": "perspective", "name": "main",
                         "perspective": {"yfov": 0.5, "znear": 0.1, "aspectRatio": 1.5}},
                        {"type": "orthographic",
                         "orthographic": {"xmag": 1, "ymag": 1, "znear": 0.1, "zfar": 9}}]"#
            .into();
        d.nodes = r#"[{"mesh": 0}, {"camera": 0, "name": "cam", "translation": [0, 0, 4]},
                      {"camera": 1, "name": "ortho"}]"#
            .into();
        d.roots = "[0, 1, 2]".into();
        let p = d.write(dir.path());
        let get = |r| {
            load_gltf(&p, dir.path(), "objects[0].mesh", MAX_SCENE_TRIANGLES, r)
                .map(|f| f.camera.expect("camera"))
        };
        let spec = |w, h| super::super::CameraSpec {
            eye: None,
            look_at: None,
            up: None,
            vfov: None,
            width: w,
            height: h,
            near: None,
            far: None,
            gltf: None,
        };
        let c = get(CameraRequest::First).unwrap();
        assert_eq!(c.node, 1);
        let (m, tr) = (
            DMat3::from_diagonal(DVec3::splat(2.0)),
            DVec3::new(1.0, 0.0, 0.0),
        );
        let s = camera_spec(&c, m, tr, &spec(96, 64)).unwrap();
        assert_eq!(s.eye, Some([1.0, 0.0, 8.0]));
        assert_eq!(s.look_at, Some([1.0, 0.0, 7.0]));
        assert_eq!(s.up, Some([0.0, 1.0, 0.0]));
        assert_eq!(s.vfov, Some(f64::from(0.5f32).to_degrees()));
        assert_eq!(s.near, Some(f64::from(0.1f32) * 2.0));
        assert_eq!(s.far, None);
        assert_eq!(get(CameraRequest::Named("main")).unwrap().node, 1);
        let e = camera_spec(&c, DMat3::IDENTITY, DVec3::ZERO, &spec(64, 64)).unwrap_err();
        assert!(e.contains("aspectRatio 1.5"), "{e}");
        let squash = DMat3::from_diagonal(DVec3::new(1.0, 2.0, 1.0));
        let e = camera_spec(&c, squash, DVec3::ZERO, &spec(96, 64)).unwrap_err();
        assert!(e.contains("not a rotation times a uniform scale"), "{e}");
        let mirror = DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0));
        let e = camera_spec(&c, mirror, DVec3::ZERO, &spec(96, 64)).unwrap_err();
        assert!(e.contains("mirrors"), "{e}");
        let e = get(CameraRequest::Named("ortho")).unwrap_err().to_string();
        assert!(e.contains("orthographic"), "{e}");
        let e = get(CameraRequest::Named("nope")).unwrap_err().to_string();
        assert!(e.contains("no camera node or camera named \"nope\""), "{e}");
    }

    #[test]
    fn accessor_indices_past_the_end_are_an_error_not_a_panic() {
        // The crate's validation indexed POSITION's accessor unchecked and panicked.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path();
        let d = Doc::tri();
        std::fs::write(path.join("m.bin"), d.bin()).unwrap();
        let cases = [
            (
                r#""POSITION": 1}"#,
                r#""POSITION": 9}"#,
                "attributes.POSITION: accessor 9",
            ),
            (
                r#""POSITION": 1}"#,
                r#""POSITION": 1, "NORMAL": 8}"#,
                "attributes.NORMAL: accessor 8",
            ),
            (r#""indices": 0"#, r#""indices": 5"#, "indices: accessor 5"),
            (
                r#""mode": 4"#,
                r#""mode": 4, "targets": [{"NORMAL": 0}, {"POSITION": 7}]"#,
                "targets[1].POSITION: accessor 7",
            ),
        ];
        let p = path.join("bad.gltf");
        for (from, to, want) in cases {
            let json = d.json().replacen(from, to, 1);
            assert_ne!(json, d.json());
            std::fs::write(&p, json).unwrap();
            let e = load_err(&p, path);
            let want = format!(
                "invalid glTF: meshes[0].primitives[0].{want} does not exist (the file has 2 accessors)"
            );
            assert!(e.contains(&want), "{e}");
        }
    }

    #[test]
    fn many_named_nodes_sharing_a_mesh_load_in_linear_time() {
        // Comparing every pair of names took 6-9 s for 20,000 nodes (and hung
        // on 80,000): at 60,000 that is over a minute, against a few hundredths
        // of a second now. The bound below is a hang guard, not a speed claim.
        let dir = tempfile::tempdir().unwrap();
        let n = 60_000;
        let mut d = Doc::tri();
        let nodes: Vec<String> = (0..n)
            .map(|i| {
                let name = if i < 2 {
                    "twin".into()
                } else {
                    format!("n{i}")
                };
                format!(r#"{{"mesh": 0, "name": "{name}"}}"#)
            })
            .collect();
        d.nodes = format!("[{}]", nodes.join(", "));
        d.roots = format!("{:?}", (0..n).collect::<Vec<_>>());
        let p = d.write(dir.path());
        let start = std::time::Instant::now();
        let f = load(&p, dir.path()).unwrap();
        let took = start.elapsed();
        let labels: Vec<&str> = f.nodes.iter().map(|n| n.label.as_str()).collect();
        assert_eq!(labels[..3], ["twin#0", "twin#1", "n2"]);
        assert_eq!(labels.len(), n);
        assert!(took < std::time::Duration::from_secs(5), "took {took:?}");
    }

    #[test]
    fn vertices_no_triangle_can_use_are_refused_before_they_are_read() {
        // One triangle over 10 million zero vertices made from nothing (a
        // sparse accessor without a bufferView) was read whole: 360 MB; the
        // probe's 89 million, 3 GB.
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("z.gltf");
        let most = 3 + MAX_UNREFERENCED_VERTICES;
        std::fs::write(&p, sparse_positions(most, 1)).unwrap();
        let f = load(&p, dir.path()).unwrap();
        assert_eq!(
            f.nodes[0].triangles,
            vec![[DVec3::ZERO, DVec3::X, DVec3::Y]]
        );
        for count in [most + 1, 10_000_000] {
            std::fs::write(&p, sparse_positions(count, 1)).unwrap();
            let e = load_err(&p, dir.path());
            let want = format!(
                "accessor 0 (POSITION) has {count} vertices, but the file's triangles refer to at most 3"
            );
            assert!(e.contains(&want), "{e}");
        }
    }

    #[test]
    fn a_mesh_used_by_many_nodes_is_read_once() {
        // 100,000 nodes over one mesh of 65,539 vertices: read per node, that
        // was 6.6 billion vertices (20,000 nodes took 4.3 s), against a few
        // hundredths of a second now. The bound below is a hang guard.
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("z.gltf");
        let n = 100_000;
        std::fs::write(&p, sparse_positions(3 + MAX_UNREFERENCED_VERTICES, n)).unwrap();
        let start = std::time::Instant::now();
        let f = load(&p, dir.path()).unwrap();
        let took = start.elapsed();
        assert_eq!(f.nodes.len(), n);
        let tri = vec![[DVec3::ZERO, DVec3::X, DVec3::Y]];
        assert!(f.nodes.iter().all(|node| node.triangles == tri));
        assert!(took < std::time::Duration::from_secs(5), "took {took:?}");
    }

    #[test]
    fn mesh_nodes_without_triangles_are_refused_like_an_obj_without_faces() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path();
        let obj = path.join("e.obj");
        std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\n").unwrap();
        let want = super::super::obj::load_obj(&obj, "objects[0].mesh", MAX_SCENE_TRIANGLES)
            .unwrap_err()
            .problem;
        assert_eq!(want, super::super::NO_FACES);
        let d = Doc::tri();
        let prim = r#"{"attributes": {"POSITION": 1}, "indices": 0, "mode": 4}"#;
        let cases = [
            (prim, ""),
            (
                r#""componentType": 5123, "count": 3"#,
                r#""componentType": 5123, "count": 0"#,
            ),
        ];
        let p = path.join("e.gltf");
        std::fs::write(path.join("m.bin"), d.bin()).unwrap();
        for (from, to) in cases {
            let json = d.json().replacen(from, to, 1);
            assert_ne!(json, d.json());
            std::fs::write(&p, json).unwrap();
            let e = load(&p, path).expect_err("loaded");
            assert_eq!(e.problem, want, "{e}");
            assert!(load_err(&p, path).ends_with(&format!("objects[0].mesh: {want}")));
        }
        // A strip of two vertex references makes no triangle either.
        let mut d = Doc::tri();
        d.indices = Some(vec![0, 1]);
        d.mode = 5;
        assert!(load_err(&d.write(path), path).ends_with(&want));
    }

    /// `json` with a second buffer (a `data:` URI of `bin`) as bufferView 2,
    /// and `accessors` (JSON objects reading bufferView 2) appended after the
    /// document's own accessors (0: indices, 1: positions).
    fn with_accessors(json: &str, bin: &[u8], accessors: &str) -> String {
        let json = json.replacen(
            r#""buffers": [{"#,
            &format!(
                r#""buffers": [{{"byteLength": {}, "uri": "data:application/octet-stream;base64,{}"}}, {{"#,
                bin.len(),
                base64_encode(bin)
            ),
            1,
        );
        // The data: buffer went first: the document's own is now buffer 1.
        let json = json.replace(r#""buffer": 0"#, r#""buffer": 1"#);
        let json = json.replacen(
            r#""bufferViews": ["#,
            &format!(
                r#""bufferViews": [{{"buffer": 0, "byteLength": {}}}, "#,
                bin.len()
            ),
            1,
        );
        // Views shift by one: 0 -> 1 (indices), 1 -> 2 (positions).
        let json = json
            .replace(r#""bufferView": 1"#, r#""bufferView": 2"#)
            .replace(r#""bufferView": 0"#, r#""bufferView": 1"#);
        let accessors = accessors.replace("\"bufferView\": 9", "\"bufferView\": 0");
        let at = json.rfind(']').expect("accessors close the document");
        format!("{}, {accessors}{}", &json[..at], &json[at..])
    }

    fn f32_bytes(v: &[f32]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_le_bytes()).collect()
    }

    fn write_json(dir: &Path, name: &str, json: &str) -> PathBuf {
        std::fs::write(dir.join("m.bin"), Doc::tri().bin()).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, json).unwrap();
        p
    }

    #[test]
    fn points_and_lines_are_skipped_with_a_warning_naming_mesh_and_primitive() {
        let dir = tempfile::tempdir().unwrap();
        let d = Doc::tri();
        let plain = load(&d.write(dir.path()), dir.path()).unwrap();
        assert!(plain.warnings.is_empty());
        let line = |mode: u32| format!(r#"{{"attributes": {{"POSITION": 1}}, "mode": {mode}}}"#);
        let json = d
            .json()
            .replacen(
                r#""mode": 4}]}]"#,
                &format!(
                    r#""mode": 4}}, {}, {}], "name": "wire"}}, {{"primitives": [{}, {}]}}]"#,
                    line(1),
                    line(0),
                    line(2),
                    line(3)
                ),
                1,
            )
            .replacen(
                r#"[{"mesh": 0, "name": "tri"}]"#,
                r#"[{"mesh": 0, "name": "tri"}, {"mesh": 1, "name": "lines"}]"#,
                1,
            );
        let d2 = Doc {
            roots: "[0, 1]".into(),
            ..Doc::tri()
        };
        let json = json.replacen(r#""nodes": [0]"#, &format!(r#""nodes": {}"#, d2.roots), 1);
        let p = write_json(dir.path(), "lines.gltf", &json);
        let f = load(&p, dir.path()).unwrap();
        // The triangle is read as before; the node of lines only is no object.
        assert_eq!(f.nodes.len(), 1);
        assert_eq!(f.nodes[0].triangles, plain.nodes[0].triangles);
        assert_eq!(
            f.warnings,
            [
                r#"mesh 0 ("wire") primitive 1 has mode LINES: skipped (rendiff renders triangles only)"#,
                r#"mesh 0 ("wire") primitive 2 has mode POINTS: skipped (rendiff renders triangles only)"#,
                "mesh 1 primitive 0 has mode LINE_LOOP: skipped (rendiff renders triangles only)",
                "mesh 1 primitive 1 has mode LINE_STRIP: skipped (rendiff renders triangles only)",
            ]
        );
        // Nothing but points and lines: refused, saying why nothing is left.
        for mode in 0..4 {
            let mut d = Doc::tri();
            d.mode = mode;
            let e = load_err(&d.write(dir.path()), dir.path());
            assert!(e.contains("POINTS/LINES primitive(s) are skipped"), "{e}");
        }
    }

    #[test]
    fn quantized_positions_are_dequantized_as_the_specification_says() {
        // (componentType, normalized, stored components, expected values).
        let cases: [(u32, bool, [i64; 6], [f64; 6]); 6] = [
            (
                5120,
                true,
                [127, -128, 0, -127, 64, 1],
                [1.0, -1.0, 0.0, -1.0, 64.0 / 127.0, 1.0 / 127.0],
            ),
            (
                5121,
                true,
                [255, 0, 51, 1, 2, 3],
                [1.0, 0.0, 0.2, 1.0 / 255.0, 2.0 / 255.0, 3.0 / 255.0],
            ),
            (
                5122,
                true,
                [32767, -32768, 0, -16384, 3, 0],
                [1.0, -1.0, 0.0, -16384.0 / 32767.0, 3.0 / 32767.0, 0.0],
            ),
            (
                5123,
                true,
                [65535, 0, 1, 2, 3, 4],
                [
                    1.0,
                    0.0,
                    1.0 / 65535.0,
                    2.0 / 65535.0,
                    3.0 / 65535.0,
                    4.0 / 65535.0,
                ],
            ),
            (
                5122,
                false,
                [-300, 7, 0, 1, -1, 2],
                [-300.0, 7.0, 0.0, 1.0, -1.0, 2.0],
            ),
            (
                5121,
                false,
                [200, 7, 0, 1, 0, 2],
                [200.0, 7.0, 0.0, 1.0, 0.0, 2.0],
            ),
        ];
        let dir = tempfile::tempdir().unwrap();
        for (ct, normalized, stored, want) in cases {
            let size = if ct < 5122 { 1 } else { 2 };
            // Three vertices, the third (0, 0, 0); elements aligned to 4 bytes
            // (byteStride), as glTF requires of vertex attributes.
            let stride = (3 * size as usize).div_ceil(4) * 4;
            let mut bin = vec![0u8; 3 * stride];
            for (k, v) in stored.iter().enumerate() {
                let at = (k / 3) * stride + (k % 3) * size as usize;
                let b = (*v as i16).to_le_bytes();
                bin[at..at + size as usize].copy_from_slice(&b[..size as usize]);
            }
            let (lo, hi) = (stored.iter().min().unwrap(), stored.iter().max().unwrap());
            let json = format!(
                r#"{{"asset": {{"version": "2.0"}}, "extensionsUsed": ["KHR_mesh_quantization"],
                   "extensionsRequired": ["KHR_mesh_quantization"],
                   "scenes": [{{"nodes": [0]}}], "nodes": [{{"mesh": 0}}],
                   "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}}}]}}],
                   "buffers": [{{"byteLength": {len}, "uri": "data:application/octet-stream;base64,{b64}"}}],
                   "bufferViews": [{{"buffer": 0, "byteLength": {len}, "byteStride": {stride}}}],
                   "accessors": [{{"bufferView": 0, "componentType": {ct}, "normalized": {normalized},
                                   "count": 3, "type": "VEC3", "min": [{lo}, {lo}, {lo}], "max": [{hi}, {hi}, {hi}]}}]}}"#,
                len = bin.len(),
                b64 = base64_encode(&bin),
            );
            let p = dir.path().join("q.gltf");
            std::fs::write(&p, json).unwrap();
            let f = load(&p, dir.path()).unwrap_or_else(|e| panic!("{ct} {normalized}: {e}"));
            let t = f.nodes[0].triangles[0];
            let got = [t[0].x, t[0].y, t[0].z, t[1].x, t[1].y, t[1].z];
            assert_eq!(got, want, "componentType {ct}, normalized {normalized}");
            assert_eq!(t[2], DVec3::ZERO);
        }
    }

    #[test]
    fn gpu_instances_are_objects_placed_by_node_times_instance() {
        let dir = tempfile::tempdir().unwrap();
        // Two instances: (T, R, S) = ((10,0,0), identity, 1) and ((0,5,0),
        // 90 degrees about z as normalized shorts, (-2,2,2): a mirror).
        let h = 23170i16; // 0.7071 in normalized shorts
        let mut bin = f32_bytes(&[10.0, 0.0, 0.0, 0.0, 5.0, 0.0]);
        for v in [0i16, 0, 0, 32767, 0, 0, h, h] {
            bin.extend_from_slice(&v.to_le_bytes());
        }
        bin.extend(f32_bytes(&[1.0, 1.0, 1.0, -2.0, 2.0, 2.0]));
        let acc = |off: usize, ct: u32, norm: bool, ty: &str| {
            format!(
                r#"{{"bufferView": 9, "byteOffset": {off}, "componentType": {ct}, "normalized": {norm}, "count": 2, "type": "{ty}"}}"#
            )
        };
        let accessors = [
            acc(0, 5126, false, "VEC3"),
            acc(24, 5122, true, "VEC4"),
            acc(40, 5126, false, "VEC3"),
        ]
        .join(", ");
        let mut d = Doc::tri();
        d.nodes = r#"[{"mesh": 0, "name": "tri", "translation": [0, 0, 1],
            "extensions": {"EXT_mesh_gpu_instancing": {"attributes":
                {"TRANSLATION": 2, "ROTATION": 3, "SCALE": 4, "_ID": 1}}}}]"#
            .into();
        let json = with_accessors(&d.json(), &bin, &accessors).replacen(
            r#""scene": 0,"#,
            r#""scene": 0, "extensionsUsed": ["EXT_mesh_gpu_instancing"],
               "extensionsRequired": ["EXT_mesh_gpu_instancing"],"#,
            1,
        );
        let p = write_json(dir.path(), "inst.gltf", &json);
        let f = load(&p, dir.path()).unwrap();
        let labels: Vec<&str> = f.nodes.iter().map(|n| n.label.as_str()).collect();
        assert_eq!(labels, ["tri/0", "tri/1"]);
        assert_eq!(
            f.nodes[0].triangles,
            vec![[
                DVec3::new(10.0, 0.0, 1.0),
                DVec3::new(11.0, 0.0, 1.0),
                DVec3::new(10.0, 1.0, 1.0)
            ]]
        );
        // Mirrored: the winding is reversed (a, c, b).
        let t = f.nodes[1].triangles[0];
        assert!(close(t[0], [0.0, 5.0, 1.0]), "{t:?}");
        assert!(close(t[1], [-2.0, 5.0, 1.0]), "{t:?}");
        assert!(close(t[2], [0.0, 3.0, 1.0]), "{t:?}");

        // Instances multiply the triangles counted against the budget.
        let e = load_gltf(&p, dir.path(), "objects[0].mesh", 1, CameraRequest::None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("glTF file has 2 triangles"), "{e}");

        // Each broken form is one line naming the node and the problem.
        let cases = [
            (
                r#""ROTATION": 3"#,
                r#""ROTATION": 2"#,
                "accessor 2 (instance ROTATION) must be VEC4",
            ),
            (
                r#""SCALE": 4"#,
                r#""SCALE": 3"#,
                "accessor 3 (instance SCALE) must be VEC3",
            ),
            (
                r#""SCALE": 4"#,
                r#""SCALE": 40"#,
                "attribute SCALE is not an accessor index",
            ),
            (
                r#""TRANSLATION": 2, "ROTATION": 3, "SCALE": 4"#,
                r#""_ID": 2"#,
                "has none of TRANSLATION",
            ),
            (
                r#""TRANSLATION": 2"#,
                r#""TRANSLATION": 1"#,
                "attributes have different counts (accessor 1: 3, accessor 3: 2)",
            ),
            (
                r#""normalized": true"#,
                r#""normalized": false"#,
                "normalized signed byte or short",
            ),
        ];
        for (from, to, want) in cases {
            let bad = json.replacen(from, to, 1);
            assert_ne!(bad, json);
            let p = write_json(dir.path(), "bad.gltf", &bad);
            let e = load_err(&p, dir.path());
            assert!(e.contains(want), "{e}");
        }
        // A zero rotation is refused, not turned into a collapse.
        let zero = with_accessors(
            &d.json(),
            &bin.iter().map(|_| 0).collect::<Vec<u8>>(),
            &accessors,
        );
        let p = write_json(dir.path(), "zero.gltf", &zero);
        assert!(load_err(&p, dir.path()).contains("instance 0's rotation quaternion is zero"));
    }

    #[test]
    fn instances_beyond_the_limit_are_refused_before_they_are_read() {
        let dir = tempfile::tempdir().unwrap();
        let mut d = Doc::tri();
        d.nodes = r#"[{"mesh": 0, "extensions": {"EXT_mesh_gpu_instancing":
            {"attributes": {"TRANSLATION": 2}}}}]"#
            .into();
        for (count, ok) in [(MAX_INSTANCES, true), (MAX_INSTANCES + 1, false)] {
            // Zeros made from nothing (no bufferView, one sparse value):
            // cheap to state, costly to read.
            let acc = format!(
                r#"{{"componentType": 5126, "count": {count}, "type": "VEC3",
                    "sparse": {{"count": 1, "indices": {{"bufferView": 9, "componentType": 5125}},
                                "values": {{"bufferView": 9}}}}}}"#
            );
            let json = with_accessors(&d.json(), &[0; 12], &acc);
            let p = write_json(dir.path(), "many.gltf", &json);
            if ok {
                assert_eq!(load(&p, dir.path()).unwrap().nodes.len() as u64, count);
            } else {
                let e = load_err(&p, dir.path());
                assert!(e.contains("more than the limit of 1048576"), "{e}");
            }
        }
    }

    #[test]
    fn a_required_extension_rendiff_does_not_read_is_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let json = Doc::tri().json().replacen(
            r#""scene": 0,"#,
            r#""scene": 0, "extensionsUsed": ["KHR_draco_mesh_compression"],
               "extensionsRequired": ["KHR_draco_mesh_compression"],"#,
            1,
        );
        let p = write_json(dir.path(), "draco.gltf", &json);
        let e = load_err(&p, dir.path());
        assert!(e.contains("KHR_draco_mesh_compression"), "{e}");
        assert!(
            e.contains("requires an extension rendiff's glTF reader does not support"),
            "{e}"
        );
    }

    #[test]
    fn scenes_and_cameras_are_chosen_by_index_or_name() {
        let dir = tempfile::tempdir().unwrap();
        let mut d = Doc::tri();
        d.nodes = r#"[{"mesh": 0, "name": "a"}, {"mesh": 0, "name": "b", "translation": [0, 0, 2]},
                      {"camera": 0, "name": "cam0"}, {"camera": 1, "name": "cam1"}]"#
            .into();
        d.cameras = r#"[{"type": "perspective", "perspective": {"yfov": 0.5, "znear": 0.1}},
                        {"type": "perspective", "name": "wide", "perspective": {"yfov": 1.0, "znear": 0.1}},
                        {"type": "perspective", "perspective": {"yfov": 1.0, "znear": 0.1}}]"#
            .into();
        let json = d.json().replacen(
            r#""scenes": [{"nodes": [0]}]"#,
            r#""scenes": [{"nodes": [0, 2], "name": "A"}, {"nodes": [1, 3], "name": "B"},
                          {"nodes": [], "name": "twin"}, {"nodes": [], "name": "twin"}]"#,
            1,
        );
        let p = write_json(dir.path(), "scenes.gltf", &json);
        let get = |scene: Option<GltfRef>, cam: CameraRequest<'_>| {
            load_gltf_scene(
                &p,
                dir.path(),
                "objects[0].mesh",
                MAX_SCENE_TRIANGLES,
                scene.as_ref(),
                cam,
            )
        };
        let labels = |f: &GltfFile| f.nodes.iter().map(|n| n.label.clone()).collect::<Vec<_>>();
        // Default: the file's `scene` (0).
        assert_eq!(labels(&get(None, CameraRequest::None).unwrap()), ["a"]);
        assert_eq!(
            labels(&get(Some(GltfRef::Index(1)), CameraRequest::None).unwrap()),
            ["b"]
        );
        let b = get(Some(GltfRef::Name("B".into())), CameraRequest::Index(1)).unwrap();
        assert_eq!(labels(&b), ["b"]);
        assert_eq!(b.camera.unwrap().node, 3);
        let c = get(Some(GltfRef::Index(0)), CameraRequest::Index(0))
            .unwrap()
            .camera
            .unwrap();
        assert_eq!((c.node, c.camera), (2, 0));
        let c = get(Some(GltfRef::Index(1)), CameraRequest::Named("wide"))
            .unwrap()
            .camera
            .unwrap();
        assert_eq!((c.node, c.camera), (3, 1));
        let err = |scene: Option<GltfRef>, cam: CameraRequest<'_>| {
            let e = get(scene, cam).unwrap_err().to_string();
            assert_eq!(e.lines().count(), 1, "{e}");
            e
        };
        let e = err(Some(GltfRef::Index(4)), CameraRequest::None);
        assert!(
            e.contains("gltf_scene 4 does not exist (the file has 4 scenes)"),
            "{e}"
        );
        let e = err(Some(GltfRef::Name("C".into())), CameraRequest::None);
        assert!(e.contains("no glTF scene is named \"C\""), "{e}");
        let e = err(Some(GltfRef::Name("twin".into())), CameraRequest::None);
        assert!(
            e.contains("2 glTF scenes are named \"twin\" (scenes [2, 3])"),
            "{e}"
        );
        let e = err(None, CameraRequest::Index(1));
        assert!(
            e.contains("camera 1 is placed by no node of the chosen glTF scene"),
            "{e}"
        );
        let e = err(None, CameraRequest::Index(3));
        assert!(
            e.contains("camera 3 does not exist (the file has 3 cameras)"),
            "{e}"
        );
    }
}
