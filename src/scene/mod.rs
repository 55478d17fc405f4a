//! Scene files: the TOML model a user writes, and its validation.
//!
//! A scene is parsed once, validated field by field (so an error can name the
//! file, the field and the problem), and then resolved into one world-space
//! triangle list that every renderer reads (see [`resolve`]).

pub mod export;
pub mod generators;
pub mod obj;
pub mod resolve;

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
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.field.is_empty() {
            write!(f, "{}: {}", self.file.display(), self.problem)
        } else {
            write!(
                f,
                "{}: {}: {}",
                self.file.display(),
                self.field,
                self.problem
            )
        }
    }
}

impl std::error::Error for SceneError {}

/// Scene features a renderer may or may not model (DESIGN.md "Scene").
/// A backend runs a scene only if it models every feature the scene requires.
pub const KNOWN_FEATURES: &[&str] = &[
    "depth",
    "ids",
    "normals",
    "emission",
    "lambert",
    "point_light",
    "directional_light",
    "shadows",
    "area_light",
    "global_illumination",
    "two_sided",
    "one_sided",
    "shadowless",
];

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

/// Pinhole camera as DESIGN.md defines it.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    pub eye: [f64; 3],
    pub look_at: [f64; 3],
    #[serde(default = "default_up")]
    pub up: [f64; 3],
    /// Vertical field of view in degrees, strictly between 0 and 180.
    pub vfov: f64,
    pub width: u32,
    pub height: u32,
    /// Nearest visible planar depth; default 1e-4 x scene size.
    pub near: Option<f64>,
    /// Farthest visible planar depth; default +infinity.
    pub far: Option<f64>,
}

fn default_up() -> [f64; 3] {
    [0.0, 1.0, 0.0]
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
    /// OBJ file, relative to the scene's folder (never outside it).
    pub mesh: Option<String>,
    /// A built-in generator; exactly one of `mesh` and `shape` is given.
    pub shape: Option<generators::Shape>,
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
#[derive(Debug, Clone, Deserialize)]
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
#[derive(Debug, Clone, Deserialize, serde::Serialize)]
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
    /// Reads, parses and validates a scene file.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| SceneError::new(path, "", format!("cannot read scene file: {e}")))?;
        Self::parse(path, &text)
    }

    /// Parses and validates scene text; `path` is used for messages and for mesh paths.
    pub fn parse(path: &Path, text: &str) -> Result<Scene, SceneError> {
        let file: SceneFile = toml::from_str(text).map_err(|e| {
            let field = String::new();
            let msg = e.to_string().trim_end().replace('\n', "\n  ");
            SceneError::new(path, field, format!("malformed scene file: {msg}"))
        })?;
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
    if i.spp == 0 {
        return Err(SceneError::new(
            path,
            "integrator.spp",
            "must be at least 1",
        ));
    }
    Ok(())
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

fn validate(path: &Path, s: &SceneFile) -> Result<BTreeSet<String>, SceneError> {
    let mut requires = BTreeSet::new();
    for (i, r) in s.requires.iter().enumerate() {
        if !KNOWN_FEATURES.contains(&r.as_str()) {
            return Err(SceneError::new(
                path,
                format!("requires[{i}]"),
                format!(
                    "unknown feature {r:?}; known features: {}",
                    KNOWN_FEATURES.join(", ")
                ),
            ));
        }
        requires.insert(r.clone());
    }
    validate_feature_pairs(path, s, &requires)?;
    let c = &s.camera;
    finite3(path, "camera.eye", &c.eye)?;
    finite3(path, "camera.look_at", &c.look_at)?;
    finite3(path, "camera.up", &c.up)?;
    if c.width == 0 || c.height == 0 {
        return Err(SceneError::new(
            path,
            "camera.width/height",
            format!(
                "image size must be at least 1x1, got {}x{}",
                c.width, c.height
            ),
        ));
    }
    if c.width > MAX_IMAGE_SIDE || c.height > MAX_IMAGE_SIDE {
        return Err(SceneError::new(
            path,
            "camera.width/height",
            format!(
                "image size {}x{} exceeds the limit of {MAX_IMAGE_SIDE} per side",
                c.width, c.height
            ),
        ));
    }
    if !(c.vfov.is_finite() && c.vfov > 0.0 && c.vfov < 180.0) {
        return Err(SceneError::new(
            path,
            "camera.vfov",
            format!(
                "vertical field of view must be strictly between 0 and 180 degrees, got {}",
                c.vfov
            ),
        ));
    }
    let f = [
        c.look_at[0] - c.eye[0],
        c.look_at[1] - c.eye[1],
        c.look_at[2] - c.eye[2],
    ];
    let flen = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
    if !(flen > 0.0 && flen.is_finite()) {
        return Err(SceneError::new(
            path,
            "camera.look_at",
            "look_at equals eye: the view direction is undefined",
        ));
    }
    let ulen = (c.up[0] * c.up[0] + c.up[1] * c.up[1] + c.up[2] * c.up[2]).sqrt();
    let cross = [
        f[1] * c.up[2] - f[2] * c.up[1],
        f[2] * c.up[0] - f[0] * c.up[2],
        f[0] * c.up[1] - f[1] * c.up[0],
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
