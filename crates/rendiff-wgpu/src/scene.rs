//! Reading a resolved scene folder (docs/resolved-scene.md): `scene.json`,
//! `triangles.f32` and `object_ids.u32`.
//!
//! A renderer reads the scene *after* rendiff resolved it, so triangle and
//! object IDs, vertices (already rounded to f32) and the camera basis are the
//! same for every backend. Nothing here recomputes them.

use anyhow::{bail, Context, Result};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The only format version this reader understands.
pub const FORMAT: &str = "rendiff-resolved/1";

/// The exported camera: the basis and `tan(vfov/2)` are used as written so
/// that no backend evaluates `tan` or normalizes vectors differently.
#[derive(Debug, Clone, Deserialize, PartialEq)]
pub struct CameraJson {
    /// Center of projection.
    pub eye: [f64; 3],
    /// Unit view direction `f`.
    pub forward: [f64; 3],
    /// Unit `r = normalize(f x up)`.
    pub right: [f64; 3],
    /// Unit `u = r x f`.
    pub up_ortho: [f64; 3],
    /// `tan(vfov/2)`, evaluated once by rendiff.
    pub tan_half_vfov: f64,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Nearest visible planar depth.
    pub near: f64,
    /// Farthest visible planar depth; `None` (JSON `null`) is +infinity.
    pub far: Option<f64>,
}

#[derive(Debug, Deserialize)]
struct Files {
    triangles: String,
    object_ids: String,
}

#[derive(Debug, Deserialize)]
struct SceneJson {
    format: String,
    #[serde(default)]
    name: String,
    camera: CameraJson,
    triangle_count: u64,
    files: Files,
}

/// A resolved scene in memory: what the renderer draws.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The scene's name (user text: only ever stored, never interpreted).
    pub name: String,
    /// The camera, exactly as exported.
    pub camera: CameraJson,
    /// `triangle_count x 9` f32: a.xyz b.xyz c.xyz per triangle; row = prim ID.
    pub triangles: Vec<f32>,
    /// Object index of each triangle.
    pub object_ids: Vec<u32>,
}

impl Scene {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.object_ids.len()
    }

    /// Triangle `i`'s three vertices.
    pub fn triangle(&self, i: usize) -> [[f32; 3]; 3] {
        let t = &self.triangles[9 * i..9 * i + 9];
        [[t[0], t[1], t[2]], [t[3], t[4], t[5]], [t[6], t[7], t[8]]]
    }
}

/// A data file named by scene.json: a plain file name inside the scene folder,
/// never a path that leaves it.
fn data_file(dir: &Path, json: &Path, name: &str) -> Result<PathBuf> {
    let plain = !name.is_empty()
        && !name.contains(['/', '\\'])
        && name != "."
        && name != ".."
        && !name.contains('\0');
    if !plain {
        bail!(
            "{}: files entry {name:?} must be a file name inside the scene folder",
            json.display()
        );
    }
    Ok(dir.join(name))
}

/// Reads `path` and checks it holds exactly `expected` bytes.
fn read_exact_len(path: &Path, expected: u64, what: &str) -> Result<Vec<u8>> {
    let meta =
        std::fs::metadata(path).with_context(|| format!("{}: cannot read", path.display()))?;
    if meta.len() != expected {
        bail!(
            "{}: {} bytes, expected {expected} ({what})",
            path.display(),
            meta.len()
        );
    }
    std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))
}

/// Loads and validates a resolved scene folder. Every error names the file
/// and the problem, on one line.
pub fn load(dir: &Path) -> Result<Scene> {
    let json_path = dir.join("scene.json");
    let text = std::fs::read_to_string(&json_path)
        .with_context(|| format!("{}: cannot read", json_path.display()))?;
    let meta: SceneJson = serde_json::from_str(&text)
        .map_err(|e| anyhow::anyhow!("{}: not a resolved scene: {e}", json_path.display()))?;
    if meta.format != FORMAT {
        bail!(
            "{}: format {:?} is not {FORMAT:?}",
            json_path.display(),
            meta.format
        );
    }
    check_camera(&meta.camera).map_err(|p| anyhow::anyhow!("{}: {p}", json_path.display()))?;
    let n = meta.triangle_count;
    let tri_path = data_file(dir, &json_path, &meta.files.triangles)?;
    let ids_path = data_file(dir, &json_path, &meta.files.object_ids)?;
    let tri_bytes = n
        .checked_mul(36)
        .with_context(|| format!("{}: triangle_count {n} too large", json_path.display()))?;
    let tri = read_exact_len(&tri_path, tri_bytes, &format!("{n} triangles x 9 f32"))?;
    let ids = read_exact_len(&ids_path, n * 4, &format!("{n} u32 object IDs"))?;
    let triangles: Vec<f32> = tri
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let object_ids: Vec<u32> = ids
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    Ok(Scene {
        name: meta.name,
        camera: meta.camera,
        triangles,
        object_ids,
    })
}

/// The conditions the renderer relies on; rendiff's export guarantees them,
/// a hand-written scene.json might not.
fn check_camera(c: &CameraJson) -> std::result::Result<(), String> {
    if c.width == 0 || c.height == 0 {
        return Err(format!(
            "camera size must be at least 1x1, got {}x{}",
            c.width, c.height
        ));
    }
    if !(c.tan_half_vfov > 0.0 && c.tan_half_vfov.is_finite()) {
        return Err(format!(
            "camera.tan_half_vfov must be > 0, got {}",
            c.tan_half_vfov
        ));
    }
    if !(c.near > 0.0 && c.near.is_finite()) {
        return Err(format!("camera.near must be > 0, got {}", c.near));
    }
    if let Some(far) = c.far {
        if far.partial_cmp(&c.near) != Some(std::cmp::Ordering::Greater) {
            return Err(format!(
                "camera.far must be greater than near ({}), got {far}",
                c.near
            ));
        }
    }
    let finite = |v: &[f64; 3]| v.iter().all(|x| x.is_finite());
    if !(finite(&c.eye) && finite(&c.forward) && finite(&c.right) && finite(&c.up_ortho)) {
        return Err("camera vectors must be finite".into());
    }
    Ok(())
}
