//! Scene files: the TOML model a user writes, and its validation.
//!
//! A scene is parsed once, validated field by field (so an error can name the
//! file, the field and the problem), and then resolved into one world-space
//! triangle list that every renderer reads (see [`resolve`]).

pub mod export;
pub mod generators;
pub mod gltf;
pub mod model;
pub mod obj;
pub mod resolve;
pub mod vertex_ids;

use serde::Deserialize;
use std::collections::BTreeSet;
use std::fmt;
use std::path::{Path, PathBuf};

/// An error in a scene file: which file, which field, what is wrong.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneError {
    /// The scene (or mesh) file the problem is in.
    pub file: PathBuf,
    /// Dotted path of the offending field, e.g. `camera.vfov` or `objects[2].mesh`.
    pub field: String,
    /// What is wrong, in words a user can act on.
    pub problem: String,
}

impl SceneError {
    /// Builds an error; a helper so call sites stay one line.
    pub fn new(file: &Path, field: impl Into<String>, problem: impl Into<String>) -> Self {
        Self {
            file: file.to_path_buf(),
            field: field.into(),
            problem: problem.into(),
        }
    }
}

impl fmt::Display for SceneError {
    /// One line: `file: field: problem`, each part through [`printable`] (no
    /// raw control characters from file names or scene text reach a terminal)
    /// and clipped, so a hostile value cannot make a 10,000-character message.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let file = printable(&self.file.display().to_string(), 300);
        let problem = printable(&self.problem, 600);
        if self.field.is_empty() {
            write!(f, "{file}: {problem}")
        } else {
            write!(f, "{file}: {}: {problem}", printable(&self.field, 200))
        }
    }
}

/// Text from a file name or a scene, made safe for one line of a terminal:
/// control characters (NUL, ESC, newlines, DEL, C1) and bidirectional
/// overrides are escaped as `char::escape_debug` writes them (`\0`, `\u{1b}`,
/// `\n`), and text longer than `max_chars` is cut with `...` and the count of
/// characters left out. Every message of this module goes through it (via
/// [`SceneError`]'s `Display`).
pub fn printable(text: &str, max_chars: usize) -> String {
    let mut out = String::with_capacity(text.len().min(4 * max_chars));
    for (i, c) in text.chars().enumerate() {
        if i >= max_chars {
            let left = text.chars().count() - i;
            out.push_str(&format!("... ({left} more characters)"));
            break;
        }
        if is_bidi_control(c) {
            // escape_debug leaves these (printable but reordering) alone.
            out.extend(c.escape_unicode());
        } else if c.is_control() {
            out.extend(c.escape_debug());
        } else {
            out.push(c);
        }
    }
    out
}

/// The bidirectional marks, embeddings, overrides and isolates (U+200E,
/// U+200F, U+202A..U+202E, U+2066..U+2069): printable characters that reorder
/// the text around them, so a name can show other than it reads. The one list
/// that [`printable`] and the gate's markdown escape use.
pub fn is_bidi_control(c: char) -> bool {
    matches!(c, '\u{200e}' | '\u{200f}' | '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}')
}

impl std::error::Error for SceneError {}

/// The whole scene file as written by a user.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// Display name; defaults to the file stem. Never trusted in SDL/HTML/shell.
    pub name: Option<String>,
    /// Free text for people reading `rendiff scenes`.
    #[serde(default)]
    pub description: String,
    /// Features the scene uses; decides which backends may run it.
    pub requires: Vec<String>,
    /// The pinhole camera.
    pub camera: CameraSpec,
    /// Materials referenced by objects, by name.
    #[serde(default)]
    pub materials: Vec<MaterialSpec>,
    /// Objects, in prim-id order.
    pub objects: Vec<ObjectSpec>,
    /// Lights (used only when the scene requires shading).
    #[serde(default)]
    pub lights: Vec<LightSpec>,
    /// Monte Carlo settings (used only with `global_illumination`).
    #[serde(default)]
    pub integrator: IntegratorSpec,
}

/// Path-tracing settings every backend follows (docs/radiance.md).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct IntegratorSpec {
    /// Longest path in vertices, Mitsuba's convention: 1 = emitters seen directly,
    /// 2 = direct lighting, -1 = unlimited.
    #[serde(default = "default_max_depth")]
    pub max_depth: i32,
    /// Default samples per pixel.
    #[serde(default = "default_spp")]
    pub spp: u32,
}

fn default_max_depth() -> i32 {
    -1
}
fn default_spp() -> u32 {
    64
}

impl Default for IntegratorSpec {
    fn default() -> Self {
        Self {
            max_depth: default_max_depth(),
            spp: default_spp(),
        }
    }
}

/// Pinhole camera as docs/DESIGN.md defines it: either its pose (`eye`,
/// `look_at`, `up`, `vfov`) or `gltf`, a camera taken from one object's glTF
/// file (then the pose keys are absent); the image size always comes from here.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    /// Center of projection; required unless `gltf` is given.
    pub eye: Option<[f64; 3]>,
    /// A point on the view axis; required unless `gltf` is given.
    pub look_at: Option<[f64; 3]>,
    /// Roll reference; default +y (see [`CameraSpec::up_or_default`]).
    pub up: Option<[f64; 3]>,
    /// Vertical field of view in degrees, strictly between 0 and 180;
    /// required unless `gltf` is given.
    pub vfov: Option<f64>,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Nearest visible planar depth; default 1e-4 x scene size (or the glTF
    /// camera's znear, see docs/resolved-scene.md).
    pub near: Option<f64>,
    /// Farthest visible planar depth; default +infinity (or the glTF camera's zfar).
    pub far: Option<f64>,
    /// Take the pose and field of view from a glTF file's camera instead.
    pub gltf: Option<GltfCameraSpec>,
}

impl CameraSpec {
    /// `up`, or +y when the scene leaves it out (the default every scene had).
    pub fn up_or_default(&self) -> [f64; 3] {
        self.up.unwrap_or([0.0, 1.0, 0.0])
    }
}

/// `camera.gltf = { object = "...", camera = "..." }`: which scene object's
/// glTF file holds the camera, and which of its cameras (a scene's camera can
/// then come with the model it was authored for).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GltfCameraSpec {
    /// Name of the scene object whose `mesh` is the `.gltf`/`.glb` file.
    pub object: String,
    /// Node name or camera name, or an index into the file's `cameras`; the
    /// first camera node (traversal order) when absent.
    pub camera: Option<GltfRef>,
}

/// A glTF scene or camera chosen in the scene file, as glTF viewers let
/// users choose them: by its index in the file's own array, or by its name.
#[derive(Debug, Clone, PartialEq)]
pub enum GltfRef {
    /// Index into the file's `scenes` (or `cameras`), as the file numbers them.
    Index(u32),
    /// The `name` the file gives it (a camera may also be chosen by its node's name).
    Name(String),
}

impl<'de> Deserialize<'de> for GltfRef {
    /// An integer from 0 or a string; anything else is refused in words a
    /// user can act on (serde's untagged enums only say "did not match").
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl serde::de::Visitor<'_> for V {
            type Value = GltfRef;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("an index into the glTF file's array (0, 1, ...) or a name (a string)")
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<GltfRef, E> {
                u32::try_from(v)
                    .map(GltfRef::Index)
                    .map_err(|_| E::invalid_value(serde::de::Unexpected::Signed(v), &self))
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<GltfRef, E> {
                u32::try_from(v)
                    .map(GltfRef::Index)
                    .map_err(|_| E::invalid_value(serde::de::Unexpected::Unsigned(v), &self))
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<GltfRef, E> {
                Ok(GltfRef::Name(v.to_string()))
            }
        }
        d.deserialize_any(V)
    }
}

/// A diffuse material: albedo and emitted radiance.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    pub name: String,
    #[serde(default = "default_albedo")]
    pub albedo: [f64; 3],
    #[serde(default)]
    pub emission: [f64; 3],
}

fn default_albedo() -> [f64; 3] {
    [0.8, 0.8, 0.8]
}

/// One object: a mesh file or a built-in generator, with a transform.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectSpec {
    pub name: String,
    /// OBJ or glTF (`.gltf`, `.glb`) file, relative to the scene's folder
    /// (never outside it).
    pub mesh: Option<String>,
    /// A built-in generator; exactly one of `mesh` and `shape` is given.
    pub shape: Option<generators::Shape>,
    /// For a glTF `mesh`: which of the file's scenes to show (index or name);
    /// the file's `scene`, else its first, when absent.
    pub gltf_scene: Option<GltfRef>,
    /// Material name; the first material (or a default grey) when absent.
    pub material: Option<String>,
    /// Scale, then rotate (XYZ Euler, degrees), then translate.
    #[serde(default)]
    pub transform: Transform,
    /// Zero-area triangles are an error unless the scene says they are intended.
    #[serde(default)]
    pub allow_degenerate: bool,
}

/// Affine transform applied as scale, then rotation (X, then Y, then Z), then translation.
/// Serialized as written into the resolved scene's mesh provenance, so the harness's
/// independent decoders place a mesh file's triangles as resolution did.
#[derive(Debug, Clone, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct Transform {
    #[serde(default = "one3")]
    pub scale: [f64; 3],
    #[serde(default)]
    pub rotate: [f64; 3],
    #[serde(default)]
    pub translate: [f64; 3],
}

fn one3() -> [f64; 3] {
    [1.0; 3]
}

impl Default for Transform {
    fn default() -> Self {
        Self {
            scale: one3(),
            rotate: [0.0; 3],
            translate: [0.0; 3],
        }
    }
}

/// Lights; the shading issue gives them meaning, the core only validates and exports them.
#[derive(Debug, Clone, PartialEq, Deserialize, serde::Serialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum LightSpec {
    /// Isotropic point light of radiant intensity I (W/sr per channel).
    Point {
        position: [f64; 3],
        intensity: [f64; 3],
    },
    /// Distant light arriving along `direction` with irradiance E at normal incidence.
    Directional {
        direction: [f64; 3],
        irradiance: [f64; 3],
    },
}

/// A parsed and validated scene, still in the user's terms (before resolution).
#[derive(Debug, Clone)]
pub struct Scene {
    /// The scene file it came from.
    pub path: PathBuf,
    /// Folder mesh paths are resolved against (and confined to).
    pub dir: PathBuf,
    /// Display name.
    pub name: String,
    /// The validated contents.
    pub file: SceneFile,
    /// `requires`, deduplicated.
    pub requires: BTreeSet<String>,
}

impl Scene {
    /// Reads, parses and validates a scene file. The file must be a regular
    /// file (never a FIFO or device: those are refused before they are opened)
    /// of at most [`MAX_SCENE_FILE_BYTES`], in UTF-8. A model file (`.obj`,
    /// `.gltf`, `.glb`) is taken as the scene [`model`] makes of it.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        if model::is_model_path(path) {
            return Scene::from_model(path);
        }
        let bytes = read_regular_file(path, MAX_SCENE_FILE_BYTES)
            .map_err(|p| SceneError::new(path, "", format!("cannot read scene file: {p}")))?;
        let text = utf8_text(bytes)
            .map_err(|p| SceneError::new(path, "", format!("cannot read scene file: {p}")))?;
        Self::parse(path, &text)
    }

    /// Parses and validates scene text; `path` is used for messages and for mesh paths.
    pub fn parse(path: &Path, text: &str) -> Result<Scene, SceneError> {
        let file: SceneFile =
            toml::from_str(text).map_err(|e| SceneError::new(path, "", toml_problem(text, &e)))?;
        let dir = path
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from("."));
        let dir = if dir.as_os_str().is_empty() {
            PathBuf::from(".")
        } else {
            dir
        };
        let name = file.name.clone().unwrap_or_else(|| {
            path.file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "scene".into())
        });
        let requires = validate(path, &file)?;
        Ok(Scene {
            path: path.to_path_buf(),
            dir,
            name,
            file,
            requires,
        })
    }
}

/// A shaded scene states both polarities of sidedness and shadowing, so that
/// "a backend runs a scene only if it models every required feature" is enough
/// (a renderer that always shadows cannot claim a shadowless scene); and every
/// light in the file is covered by a required feature.
fn validate_feature_pairs(
    path: &Path,
    s: &SceneFile,
    requires: &BTreeSet<String>,
) -> Result<(), SceneError> {
    let has = |f: &str| requires.contains(f);
    let shaded = has("lambert") || has("emission") || has("global_illumination");
    if shaded && has("one_sided") == has("two_sided") {
        return Err(SceneError::new(
            path,
            "requires",
            "a shaded scene must require exactly one of \"one_sided\" and \"two_sided\"",
        ));
    }
    let lit = has("point_light") || has("directional_light");
    if lit && has("shadows") == has("shadowless") {
        return Err(SceneError::new(
            path,
            "requires",
            "a scene with lights must require exactly one of \"shadows\" and \"shadowless\"",
        ));
    }
    if (has("point_light") || has("directional_light") || has("area_light")) && !has("lambert") {
        return Err(SceneError::new(
            path,
            "requires",
            "lights need a surface model: add \"lambert\"",
        ));
    }
    if has("area_light") && !has("global_illumination") {
        return Err(SceneError::new(
            path,
            "requires",
            "area lights are rendered by path tracing: add \"global_illumination\"",
        ));
    }
    for (i, l) in s.lights.iter().enumerate() {
        let need = match l {
            LightSpec::Point { .. } => "point_light",
            LightSpec::Directional { .. } => "directional_light",
        };
        if !has(need) {
            return Err(SceneError::new(
                path,
                format!("lights[{i}]"),
                format!("the scene has a {need} but does not require \"{need}\""),
            ));
        }
    }
    let i = &s.integrator;
    if i.max_depth == 0 || i.max_depth < -1 {
        return Err(SceneError::new(
            path,
            "integrator.max_depth",
            format!("must be -1 (unlimited) or >= 1, got {}", i.max_depth),
        ));
    }
    check_spp(i.spp).map_err(|p| SceneError::new(path, "integrator.spp", p))?;
    Ok(())
}

/// Triangles the scene's built-in shapes generate, all objects together
/// (OBJ meshes are counted when they are read).
pub fn shape_triangles(s: &SceneFile) -> u64 {
    s.objects
        .iter()
        .filter_map(|o| o.shape.as_ref())
        .fold(0u64, |n, sh| n.saturating_add(sh.triangle_count()))
}

fn finite3(path: &Path, field: &str, v: &[f64; 3]) -> Result<(), SceneError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(SceneError::new(
            path,
            field,
            format!("must be finite, got {v:?}"),
        ))
    }
}

/// Largest image side accepted; bigger is almost surely a typo and would exhaust memory.
pub const MAX_IMAGE_SIDE: u32 = 16384;

/// Most pixels (width x height) an image may have: 2^26 = 67,108,864, 64
/// Mpixel (8192 x 8192, or 16384 x 4096; 8K UHD is 33 Mpixel).
///
/// Derivation: a visibility render holds about 36 B per pixel while it runs
/// (the u64 winner key, Z f32, id.prim and id.object u32, the normal 3 x f32),
/// and a shaded one another 24 B (RGB and its variance), before the EXR and
/// PNG encoders' copies; at this limit that is 2.4 to 4 GiB. A 16384 x 16384
/// image (268 Mpixel, about 10 GiB before encoding) aborted the process in
/// `Frame::from_keys` instead of giving an error.
pub const MAX_IMAGE_PIXELS: u64 = 1 << 26;

/// Most triangles a scene may have, all objects together: 2^26 = 67,108,864
/// (64 Mi).
///
/// Derivation: peak memory per triangle measured by `rendiff bench stability`
/// (docs/benchmarks.md, "Triangle count"; marginal bytes from 4M to 16M triangles) is
/// 113 B for the raster, 305 B for the tracer (BVH included) and 185 B for
/// Embree, so this limit is about 7 GiB for the raster and 19 GiB for the
/// tracer: the most a well-equipped workstation can render, four times the
/// bench's 16M-triangle family, and room for the largest single generator
/// (a 4096 x 4096 grid, 33.5M triangles). Eight such grids (268M triangles,
/// about 80 GB to trace) are refused before anything is generated.
pub const MAX_SCENE_TRIANGLES: u64 = 1 << 26;

/// Most samples per pixel a path-traced render may ask for: 2^16 = 65,536,
/// sixteen times the 4,096 spp of the cached Mitsuba references
/// (tests/references/). More is a typo in practice: `spp = 4000000000` would
/// render for years instead of failing.
pub const MAX_SPP: u32 = 1 << 16;

/// Largest scene (TOML) file read: 64 MiB, checked from metadata before
/// reading. Hand-written scenes are a few KiB; 64 MiB holds about 700k literal
/// triangles (`shape = { kind = "triangles" }`), and larger geometry belongs in
/// an OBJ file.
pub const MAX_SCENE_FILE_BYTES: u64 = 64 << 20;

/// Largest mesh (OBJ) file read: 1 GiB, checked from metadata before reading.
/// A 16M-triangle OBJ is about 700 MB of text; the whole text is held while
/// tobj parses it (about 12 B per triangle of indices and 12 B per vertex on
/// top), so one mesh at this limit needs about 2 to 3 GiB before resolution.
pub const MAX_MESH_FILE_BYTES: u64 = 1 << 30;

/// The problem for a mesh file that makes no triangle (an OBJ file without
/// faces, a glTF file whose mesh nodes have no triangle primitive): the
/// object would be empty, a mistake in the scene whatever the format, so
/// both formats say it alike.
pub const NO_FACES: &str = "mesh has no faces: it makes no triangles";

/// Checks an image size against [`MAX_IMAGE_SIDE`] and [`MAX_IMAGE_PIXELS`]
/// (scene files, and generated scenes such as `bench crossover`'s grid).
pub fn check_image_size(width: u32, height: u32) -> Result<(), String> {
    if width == 0 || height == 0 {
        return Err(format!(
            "image size must be at least 1x1, got {width}x{height}"
        ));
    }
    if width > MAX_IMAGE_SIDE || height > MAX_IMAGE_SIDE {
        return Err(format!(
            "image size {width}x{height} exceeds the limit of {MAX_IMAGE_SIDE} per side"
        ));
    }
    let pixels = u64::from(width) * u64::from(height);
    if pixels > MAX_IMAGE_PIXELS {
        return Err(format!(
            "image size {width}x{height} is {pixels} pixels, more than the limit of \
             {MAX_IMAGE_PIXELS} (64 Mpixel, e.g. 8192x8192)"
        ));
    }
    Ok(())
}

/// Checks a samples-per-pixel count against [`MAX_SPP`] (also for `--spp`).
pub fn check_spp(spp: u32) -> Result<(), String> {
    if spp == 0 {
        Err("must be at least 1".into())
    } else if spp > MAX_SPP {
        Err(format!(
            "{spp} samples per pixel is more than the limit of {MAX_SPP} (16x the references' 4096)"
        ))
    } else {
        Ok(())
    }
}

/// Largest magnitude of a camera coordinate: f32's range, where all geometry
/// lives; beyond it no renderer can place the camera relative to the scene
/// (and `look_at - eye` may overflow f64 when squared).
pub const MAX_CAMERA_COORDINATE: f64 = f32::MAX as f64;

/// Says what a file system entry is when it is not a regular file.
fn special_kind(ft: &std::fs::FileType) -> Option<&'static str> {
    #[cfg(unix)]
    use std::os::unix::fs::FileTypeExt;
    if ft.is_file() {
        return None;
    }
    if ft.is_dir() {
        return Some("is a folder, not a file");
    }
    #[cfg(unix)]
    {
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

/// What the entry at `path` is, when it exists and is neither a regular file
/// nor a symlink (a rename replaces a symlink itself, never its target):
/// outputs are never written over such an entry
/// ([`crate::exr_io::write_atomically`]; as root, `render -o /dev/full`
/// replaced the device node with an EXR).
pub fn special_entry(path: &Path) -> Option<&'static str> {
    let meta = std::fs::symlink_metadata(path).ok()?;
    if meta.file_type().is_symlink() {
        return None;
    }
    special_kind(&meta.file_type())
}

/// Human size of a byte limit (the limits are powers of two).
fn bytes_in_words(n: u64) -> String {
    if n >= 1 << 30 && n.is_multiple_of(1 << 30) {
        format!("{} GiB", n >> 30)
    } else if n >= 1 << 20 && n.is_multiple_of(1 << 20) {
        format!("{} MiB", n >> 20)
    } else {
        format!("{n} bytes")
    }
}

/// Opens a regular file of at most `limit` bytes for reading, and its
/// metadata. The kind and size are checked from metadata (symlinks
/// followed) before the file is opened, so a FIFO, device, socket or folder
/// is never opened (opening a FIFO blocks, `/dev/zero` never ends); the open
/// itself is non-blocking and re-checked on the open handle, so a file
/// swapped in between cannot slip through. The problem in words otherwise.
pub fn open_regular_file(
    path: &Path,
    limit: u64,
) -> Result<(std::fs::File, std::fs::Metadata), String> {
    let check = |meta: &std::fs::Metadata| -> Result<(), String> {
        if let Some(kind) = special_kind(&meta.file_type()) {
            return Err(kind.to_string());
        }
        if meta.len() > limit {
            return Err(format!(
                "is {} bytes, more than the limit of {} ({limit} bytes)",
                meta.len(),
                bytes_in_words(limit)
            ));
        }
        Ok(())
    };
    let meta = std::fs::metadata(path).map_err(|e| format!("cannot be opened: {e}"))?;
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
        .map_err(|e| format!("cannot be opened: {e}"))?;
    let meta = file
        .metadata()
        .map_err(|e| format!("cannot be read: {e}"))?;
    check(&meta)?;
    Ok((file, meta))
}

/// Reads a whole regular file of at most `limit` bytes, opened by
/// [`open_regular_file`]. Returns the problem in words (the caller names the
/// file and field).
pub fn read_regular_file(path: &Path, limit: u64) -> Result<Vec<u8>, String> {
    use std::io::Read;
    let (file, meta) = open_regular_file(path, limit)?;
    let mut buf = Vec::with_capacity(meta.len() as usize);
    file.take(limit + 1)
        .read_to_end(&mut buf)
        .map_err(|e| format!("read error: {e}"))?;
    if buf.len() as u64 > limit {
        return Err(format!(
            "grew past the limit of {} while being read",
            bytes_in_words(limit)
        ));
    }
    Ok(buf)
}

/// The bytes as UTF-8 text, or the problem in words (with the first bad byte's line).
pub fn utf8_text(bytes: Vec<u8>) -> Result<String, String> {
    String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        let line = 1 + e.as_bytes()[..at].iter().filter(|b| **b == b'\n').count();
        format!(
            "is not UTF-8 text (invalid byte 0x{:02x} at offset {at}, line {line})",
            e.as_bytes()[at]
        )
    })
}

/// One line for a TOML or serde error: line and column, toml's message (clipped),
/// and the start of the offending line, instead of toml's multi-line report
/// (which quotes the whole source line, however long).
fn toml_problem(text: &str, e: &toml::de::Error) -> String {
    let msg = printable(e.message().trim(), 160);
    let Some(span) = e.span() else {
        return format!("malformed scene file: {msg}");
    };
    let start = span.start.min(text.len());
    let start = (0..=start)
        .rev()
        .find(|i| text.is_char_boundary(*i))
        .unwrap_or(0);
    let before = &text[..start];
    let line = 1 + before.matches('\n').count();
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let column = 1 + text[line_start..start].chars().count();
    let line_text = text[line_start..].lines().next().unwrap_or("").trim();
    format!(
        "malformed scene file at line {line}, column {column}: {msg} (in `{}`)",
        printable(line_text, 60)
    )
}

/// Checks a camera pose (eye, look_at, up, vfov): finite, in range, a defined
/// view direction and roll. Scene validation calls it on the TOML's pose, and
/// resolution on the pose mapped from a glTF camera.
pub fn validate_pose(path: &Path, c: &CameraSpec) -> Result<(), SceneError> {
    let missing = |field: &str| {
        SceneError::new(
            path,
            format!("camera.{field}"),
            "missing: give eye, look_at and vfov (up is optional), \
             or take the camera from a glTF file with camera.gltf = { object = \"...\" }",
        )
    };
    let eye = c.eye.ok_or_else(|| missing("eye"))?;
    let look_at = c.look_at.ok_or_else(|| missing("look_at"))?;
    let vfov = c.vfov.ok_or_else(|| missing("vfov"))?;
    let up = c.up_or_default();
    for (field, v) in [
        ("camera.eye", &eye),
        ("camera.look_at", &look_at),
        ("camera.up", &up),
    ] {
        finite3(path, field, v)?;
        if v.iter().any(|x| x.abs() > MAX_CAMERA_COORDINATE) {
            return Err(SceneError::new(
                path,
                field,
                format!(
                    "coordinates out of range: {v:?} exceeds the limit of {MAX_CAMERA_COORDINATE:e} \
                     in magnitude (f32's range, where all geometry lives)"
                ),
            ));
        }
    }
    if !(vfov.is_finite() && vfov > 0.0 && vfov < 180.0) {
        return Err(SceneError::new(
            path,
            "camera.vfov",
            format!(
                "vertical field of view must be strictly between 0 and 180 degrees, got {}",
                vfov
            ),
        ));
    }
    let f = [
        look_at[0] - eye[0],
        look_at[1] - eye[1],
        look_at[2] - eye[2],
    ];
    let flen = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
    if !flen.is_finite() {
        return Err(SceneError::new(
            path,
            "camera.look_at",
            "coordinates out of range: the distance from eye to look_at overflows",
        ));
    }
    if flen <= 0.0 {
        let problem = if f.iter().all(|x| *x == 0.0) {
            "look_at equals eye: the view direction is undefined"
        } else {
            "look_at is too close to eye (the distance underflows): the view direction is undefined"
        };
        return Err(SceneError::new(path, "camera.look_at", problem));
    }
    let ulen = (up[0] * up[0] + up[1] * up[1] + up[2] * up[2]).sqrt();
    let cross = [
        f[1] * up[2] - f[2] * up[1],
        f[2] * up[0] - f[0] * up[2],
        f[0] * up[1] - f[1] * up[0],
    ];
    let clen = (cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]).sqrt();
    let parallel = ulen.is_nan() || ulen <= 0.0 || clen.is_nan() || clen <= 1e-9 * flen * ulen;
    if parallel {
        return Err(SceneError::new(
            path,
            "camera.up",
            "up is zero or parallel to the view direction: the camera's roll is undefined",
        ));
    }
    check_ray_precision(path, &eye, vfov, c.width, c.height)
}

/// How far the core's pixel rays may stray from DESIGN.md's pixel-center
/// rays, in pixels. The core forms a ray's direction as `(eye + d) - eye` in
/// f64, which loses `d`'s low bits to the eye's magnitude: with the eye 1e15
/// from the origin a 48x32 reference missed 9% of its hits, at 1e18 all of
/// them, and a renderer that was right would have been blamed.
pub const MAX_RAY_ERROR_PX: f64 = 1.0 / 64.0;

/// Refuses an eye so far from the origin that the core's rays would miss
/// their pixel centers by more than [`MAX_RAY_ERROR_PX`]. The direction's
/// error is at most `u (|eye_k| + 2 |d_k|)` per component (two roundings,
/// `u = 2^-53`; taken as `4u` here, for margin), against one pixel's step
/// `2 tan(vfov/2) / height` at the unit distance `d` has along the view.
fn check_ray_precision(
    path: &Path,
    eye: &[f64; 3],
    vfov: f64,
    width: u32,
    height: u32,
) -> Result<(), SceneError> {
    let (w, h) = (f64::from(width), f64::from(height));
    let tan_half = (vfov.to_radians() / 2.0).tan();
    let step = 2.0 * tan_half / h;
    let d_max = 1.0 + tan_half * (w / h + 1.0);
    let e_max = eye.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let error = 2.0 * f64::EPSILON * (e_max + 2.0 * d_max);
    if error > MAX_RAY_ERROR_PX * step {
        return Err(SceneError::new(
            path,
            "camera.eye",
            format!(
                "{e_max:e} from the origin is too far for the core's f64 pixel rays at \
                 {width}x{height} and vfov {vfov}: their directions ((eye + d) - eye) would miss \
                 the pixel centers by up to {:.3} pixels (the limit is 1/64); move the scene \
                 toward the origin",
                error / step
            ),
        ));
    }
    Ok(())
}

/// `camera.gltf` excludes the pose keys and must name an object whose mesh is
/// a glTF file.
fn validate_camera_source(path: &Path, s: &SceneFile) -> Result<(), SceneError> {
    let c = &s.camera;
    let Some(g) = &c.gltf else {
        return Ok(());
    };
    if c.eye.is_some() || c.look_at.is_some() || c.up.is_some() || c.vfov.is_some() {
        return Err(SceneError::new(
            path,
            "camera.gltf",
            "give either `gltf` or the pose (`eye`, `look_at`, `up`, `vfov`), not both",
        ));
    }
    let named: Vec<&ObjectSpec> = s.objects.iter().filter(|o| o.name == g.object).collect();
    match named.as_slice() {
        [o] if o.mesh.as_deref().is_some_and(gltf::is_gltf_path) => Ok(()),
        [_] => Err(SceneError::new(
            path,
            "camera.gltf.object",
            format!(
                "object {:?} has no glTF mesh (a .gltf or .glb file) to take the camera from",
                g.object
            ),
        )),
        [] => Err(SceneError::new(
            path,
            "camera.gltf.object",
            format!("no object named {:?}", g.object),
        )),
        _ => Err(SceneError::new(
            path,
            "camera.gltf.object",
            format!(
                "{} objects are named {:?}; name one uniquely",
                named.len(),
                g.object
            ),
        )),
    }
}

fn validate(path: &Path, s: &SceneFile) -> Result<BTreeSet<String>, SceneError> {
    let mut requires = BTreeSet::new();
    for (i, r) in s.requires.iter().enumerate() {
        if crate::vocab::Feature::parse(r).is_none() {
            return Err(SceneError::new(
                path,
                format!("requires[{i}]"),
                format!(
                    "unknown feature {r:?}; known features: {}",
                    crate::vocab::Feature::names().join(", ")
                ),
            ));
        }
        requires.insert(r.clone());
    }
    validate_feature_pairs(path, s, &requires)?;
    let c = &s.camera;
    validate_camera_source(path, s)?;
    if c.gltf.is_none() {
        validate_pose(path, c)?;
    }
    check_image_size(c.width, c.height)
        .map_err(|p| SceneError::new(path, "camera.width/height", p))?;
    if let Some(n) = c.near {
        if !(n.is_finite() && n > 0.0) {
            return Err(SceneError::new(
                path,
                "camera.near",
                format!("must be finite and > 0, got {n}"),
            ));
        }
    }
    if let Some(fa) = c.far {
        if fa.is_nan() || fa <= c.near.unwrap_or(0.0) {
            return Err(SceneError::new(
                path,
                "camera.far",
                format!("must be greater than near, got {fa}"),
            ));
        }
    }
    let mut names = BTreeSet::new();
    for (i, m) in s.materials.iter().enumerate() {
        let field = format!("materials[{i}]");
        if !names.insert(m.name.as_str()) {
            return Err(SceneError::new(
                path,
                format!("{field}.name"),
                format!("duplicate material name {:?}", m.name),
            ));
        }
        finite3(path, &format!("{field}.albedo"), &m.albedo)?;
        finite3(path, &format!("{field}.emission"), &m.emission)?;
        if m.albedo.iter().any(|a| !(0.0..=1.0).contains(a)) {
            return Err(SceneError::new(
                path,
                format!("{field}.albedo"),
                format!("each component must be in [0, 1], got {:?}", m.albedo),
            ));
        }
        if m.emission.iter().any(|e| *e < 0.0) {
            return Err(SceneError::new(
                path,
                format!("{field}.emission"),
                "must not be negative",
            ));
        }
    }
    if s.objects.is_empty() {
        return Err(SceneError::new(
            path,
            "objects",
            "a scene needs at least one object",
        ));
    }
    for (i, o) in s.objects.iter().enumerate() {
        let field = format!("objects[{i}]");
        match (&o.mesh, &o.shape) {
            (Some(_), Some(_)) => {
                return Err(SceneError::new(
                    path,
                    field,
                    "give either `mesh` or `shape`, not both",
                ))
            }
            (None, None) => {
                return Err(SceneError::new(
                    path,
                    field,
                    "needs a `mesh` (OBJ file) or a `shape` (built-in generator)",
                ))
            }
            _ => {}
        }
        if o.gltf_scene.is_some() && !o.mesh.as_deref().is_some_and(gltf::is_gltf_path) {
            return Err(SceneError::new(
                path,
                format!("{field}.gltf_scene"),
                "chooses a glTF scene, but the object's mesh is not a glTF file (.gltf or .glb)",
            ));
        }
        if let Some(m) = &o.material {
            if !names.contains(m.as_str()) {
                return Err(SceneError::new(
                    path,
                    format!("{field}.material"),
                    format!("no material named {m:?}"),
                ));
            }
        }
        finite3(
            path,
            &format!("{field}.transform.scale"),
            &o.transform.scale,
        )?;
        finite3(
            path,
            &format!("{field}.transform.rotate"),
            &o.transform.rotate,
        )?;
        finite3(
            path,
            &format!("{field}.transform.translate"),
            &o.transform.translate,
        )?;
        if let Some(shape) = &o.shape {
            shape
                .validate()
                .map_err(|p| SceneError::new(path, format!("{field}.shape"), p))?;
        }
    }
    let generated = shape_triangles(s);
    if generated > MAX_SCENE_TRIANGLES {
        return Err(SceneError::new(
            path,
            "objects",
            format!(
                "the scene's shapes have {generated} triangles together, more than the limit of \
                 {MAX_SCENE_TRIANGLES} (64 Mi) per scene"
            ),
        ));
    }
    for (i, l) in s.lights.iter().enumerate() {
        let field = format!("lights[{i}]");
        match l {
            LightSpec::Point {
                position,
                intensity,
            } => {
                finite3(path, &format!("{field}.position"), position)?;
                finite3(path, &format!("{field}.intensity"), intensity)?;
            }
            LightSpec::Directional {
                direction,
                irradiance,
            } => {
                finite3(path, &format!("{field}.direction"), direction)?;
                finite3(path, &format!("{field}.irradiance"), irradiance)?;
                if direction.iter().all(|d| *d == 0.0) {
                    return Err(SceneError::new(
                        path,
                        format!("{field}.direction"),
                        "must not be zero",
                    ));
                }
            }
        }
    }
    Ok(requires)
}

#[cfg(test)]
mod message_tests {
    use super::*;

    #[test]
    fn printable_escapes_control_and_bidi_characters_and_clips() {
        assert_eq!(
            printable("a\u{1b}[2J\0\n\u{7f}\u{9b}b", 100),
            "a\\u{1b}[2J\\0\\n\\u{7f}\\u{9b}b"
        );
        assert_eq!(printable("x\u{202e}y", 100), "x\\u{202e}y");
        assert_eq!(printable("éé\ttab", 100), "éé\\ttab");
        assert_eq!(
            printable(&"n".repeat(50), 10),
            format!("{}... (40 more characters)", "n".repeat(10))
        );
    }

    #[test]
    fn scene_error_display_is_one_escaped_line() {
        let e = SceneError::new(Path::new("a\u{1b}b.toml"), "f\n", "p\u{0}".repeat(1000));
        let s = e.to_string();
        assert!(!s.chars().any(char::is_control), "{s:?}");
        assert!(s.starts_with("a\\u{1b}b.toml: f\\n: p\\0"), "{s}");
        assert!(s.len() < 1000, "{}", s.len());
    }

    #[test]
    fn a_gltf_scene_or_camera_is_an_index_or_a_name_and_nothing_else() {
        let text = |v: &str| {
            format!(
                "requires = [\"depth\"]\n[camera]\nwidth = 8\nheight = 8\n\
                 gltf = {{ object = \"m\", camera = {v} }}\n\
                 [[objects]]\nname = \"m\"\nmesh = \"m.glb\"\ngltf_scene = {v}\n"
            )
        };
        let parse = |v: &str| Scene::parse(Path::new("s.toml"), &text(v));
        let s = parse("3").unwrap();
        assert_eq!(s.file.objects[0].gltf_scene, Some(GltfRef::Index(3)));
        let c = s.file.camera.gltf.unwrap().camera;
        assert_eq!(c, Some(GltfRef::Index(3)));
        let s = parse("\"Main\"").unwrap();
        assert_eq!(
            s.file.objects[0].gltf_scene,
            Some(GltfRef::Name("Main".into()))
        );
        for bad in ["-1", "1.5", "4294967296", "true", "[0]"] {
            let e = parse(bad).unwrap_err().to_string();
            assert!(
                e.contains("expected an index into the glTF file's array (0, 1, ...) or a name"),
                "{bad}: {e}"
            );
        }
    }

    #[test]
    fn toml_errors_are_one_line_with_position() {
        let text = format!(
            "requires = [\"depth\"]\nname = 3\ncamera = \"{}\"\n",
            "x".repeat(10_000)
        );
        let e = Scene::parse(Path::new("s.toml"), &text)
            .unwrap_err()
            .to_string();
        assert!(
            !e.contains('\n') && e.len() < 400,
            "{} characters: {e}",
            e.len()
        );
        assert!(e.contains("line 3, column 10"), "{e}");
    }
}
