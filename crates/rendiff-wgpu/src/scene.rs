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

/// Largest `scene.json` read: 256 MiB, checked from metadata before reading
/// (rendiff reads a resolved scene.json with the same limit). A resolved
/// scene.json is the camera and one entry per object, material and light:
/// kilobytes in practice, a few hundred MB for millions of named objects.
pub const MAX_SCENE_JSON_BYTES: u64 = 256 << 20;

/// Most triangles a resolved scene may declare: 2^26 = 67,108,864, rendiff's
/// own scene limit (`rendiff_core::scene::MAX_SCENE_TRIANGLES`), so no export
/// has more. `triangles.f32` is then at most 2.25 GiB; a larger count is a
/// malformed scene.json, refused before its files are sized or read.
pub const MAX_TRIANGLES: u64 = 1 << 26;

/// What is wrong with a file of type `ft` as an input or output file: `None`
/// for a regular file.
pub fn special_kind(ft: &std::fs::FileType) -> Option<&'static str> {
    if ft.is_file() {
        return None;
    }
    if ft.is_dir() {
        return Some("is a folder, not a file");
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if ft.is_fifo() {
            return Some("is a FIFO (named pipe), not a regular file");
        }
        if ft.is_socket() {
            return Some("is a socket, not a regular file");
        }
        if ft.is_char_device() {
            return Some("is a character device, not a regular file");
        }
        if ft.is_block_device() {
            return Some("is a block device, not a regular file");
        }
    }
    Some("is not a regular file")
}

/// Opens a regular file of at most `limit` bytes for reading, with its
/// length. The kind and size are checked from metadata (links followed)
/// before the file is opened, so a FIFO, device, socket or folder is never
/// opened (opening a FIFO blocks, `/dev/zero` never ends); the open itself is
/// non-blocking and checked again on the open handle, so a file swapped in
/// between cannot slip through. Errors name the file and the problem.
fn open_regular_file(path: &Path, limit: u64) -> Result<(std::fs::File, u64)> {
    let check = |meta: &std::fs::Metadata| -> Result<()> {
        if let Some(kind) = special_kind(&meta.file_type()) {
            bail!("{}: {kind}", path.display());
        }
        if meta.len() > limit {
            bail!(
                "{}: {} bytes, more than the limit of {limit} bytes",
                path.display(),
                meta.len()
            );
        }
        Ok(())
    };
    let meta =
        std::fs::metadata(path).with_context(|| format!("{}: cannot read", path.display()))?;
    check(&meta)?;
    let mut opts = std::fs::OpenOptions::new();
    opts.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        opts.custom_flags(libc::O_NONBLOCK);
    }
    let file = opts
        .open(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    let meta = file
        .metadata()
        .with_context(|| format!("{}: cannot read", path.display()))?;
    check(&meta)?;
    Ok((file, meta.len()))
}

/// Reads at most `limit` bytes of the regular file `path` (see
/// [`open_regular_file`]), holding `len` bytes when opened; errors name the
/// file.
fn read_opened(path: &Path, file: std::fs::File, len: u64, limit: u64) -> Result<Vec<u8>> {
    use std::io::Read;
    let mut buf = Vec::new();
    buf.try_reserve_exact(len as usize)
        .map_err(|_| anyhow::anyhow!("{}: {len} bytes do not fit in memory", path.display()))?;
    file.take(limit + 1)
        .read_to_end(&mut buf)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    if buf.len() as u64 > limit {
        bail!(
            "{}: grew past {limit} bytes while being read",
            path.display()
        );
    }
    Ok(buf)
}

/// Reads a whole regular file of at most `limit` bytes.
pub fn read_regular_file(path: &Path, limit: u64) -> Result<Vec<u8>> {
    let (file, len) = open_regular_file(path, limit)?;
    read_opened(path, file, len, limit)
}

/// Opens the regular file `path`, which must hold exactly `expected` bytes
/// (checked here, before anything is read, and again by [`read_exact`]).
fn open_exact_len(path: &Path, expected: u64, what: &str) -> Result<std::fs::File> {
    // No limit of its own: the size must match `expected`, checked next.
    let (file, len) = open_regular_file(path, u64::MAX)?;
    if len != expected {
        bail!(
            "{}: {len} bytes, expected {expected} ({what})",
            path.display()
        );
    }
    Ok(file)
}

/// Reads `file`, opened by [`open_exact_len`], which must still hold exactly
/// `expected` bytes.
fn read_exact(path: &Path, file: std::fs::File, expected: u64) -> Result<Vec<u8>> {
    let bytes = read_opened(path, file, expected, expected)?;
    if bytes.len() as u64 != expected {
        bail!(
            "{}: shrank from {expected} to {} bytes while being read",
            path.display(),
            bytes.len()
        );
    }
    Ok(bytes)
}

/// Loads and validates a resolved scene folder. Every error names the file
/// and the problem, on one line. Only regular files are read, each with a
/// size limit checked before reading: scene.json at most
/// [`MAX_SCENE_JSON_BYTES`], the data files exactly the size that
/// `triangle_count` (at most [`MAX_TRIANGLES`]) implies.
pub fn load(dir: &Path) -> Result<Scene> {
    let json_path = dir.join("scene.json");
    let bytes = read_regular_file(&json_path, MAX_SCENE_JSON_BYTES)?;
    let meta: SceneJson = serde_json::from_slice(&bytes)
        .map_err(|e| anyhow::anyhow!("{}: not a resolved scene: {e}", json_path.display()))?;
    drop(bytes);
    if meta.format != FORMAT {
        bail!(
            "{}: format {:?} is not {FORMAT:?}",
            json_path.display(),
            meta.format
        );
    }
    check_camera(&meta.camera).map_err(|p| anyhow::anyhow!("{}: {p}", json_path.display()))?;
    let n = meta.triangle_count;
    if n > MAX_TRIANGLES {
        bail!(
            "{}: triangle_count {n} is more than the limit of {MAX_TRIANGLES}",
            json_path.display()
        );
    }
    let tri_path = data_file(dir, &json_path, &meta.files.triangles)?;
    let ids_path = data_file(dir, &json_path, &meta.files.object_ids)?;
    // Both sizes are checked before either file is read.
    let tri_file = open_exact_len(&tri_path, n * 36, &format!("{n} triangles x 9 f32"))?;
    let ids_file = open_exact_len(&ids_path, n * 4, &format!("{n} u32 object IDs"))?;
    let tri = read_exact(&tri_path, tri_file, n * 36)?;
    let ids = read_exact(&ids_path, ids_file, n * 4)?;
    let triangles: Vec<f32> = tri
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    drop(tri);
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
