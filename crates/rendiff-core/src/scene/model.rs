//! A scene made from a model file alone: `rendiff check model.glb` (or
//! `.gltf`, `.obj`) and `rendiff scene new model.glb -o scene.toml`.
//!
//! A user's first question is "does my model render the same everywhere?",
//! and they have a model, not a scene file. The scene made here is the one a
//! user would write for it: the model as one object under identity, a camera
//! that frames its bounding sphere from a fixed direction, visibility only
//! (`depth`, `ids`: every backend runs it, no lights needed). It is made as
//! TOML text and parsed like any scene, so `check model.glb` and the file
//! `scene new` writes are one scene, not two implementations of one. The rule
//! is documented in docs/resolved-scene.md, "A scene from a model file".

use super::resolve::ResolvedScene;
use super::{printable, Scene, SceneError};
use std::path::{Component, Path, PathBuf};

/// Image width of a model's scene, in pixels (4:3, like most scenes here).
pub const MODEL_WIDTH: u32 = 320;
/// Image height of a model's scene, in pixels.
pub const MODEL_HEIGHT: u32 = 240;
/// Vertical field of view of a model's scene, in degrees: a normal lens
/// (about a 50 mm lens on 35 mm film, 40 degrees), little perspective
/// distortion of the model.
pub const MODEL_VFOV_DEG: f64 = 40.0;
/// Direction from the bounding sphere's center to the eye, before
/// normalizing: mostly from the front (+z, glTF's "front"), a little from
/// the right and above (azimuth 26.6 degrees toward +x, elevation 24.1
/// degrees), so that a box-like model shows three of its faces and no face
/// is seen exactly edge-on.
pub const MODEL_VIEW_FROM: [f64; 3] = [1.0, 1.0, 2.0];

/// True when `path` names a model file rendiff reads as a mesh (`.obj`,
/// `.gltf`, `.glb`, any case), which `check` and `render` accept in place of
/// a scene file.
pub fn is_model_path(path: &Path) -> bool {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    matches!(ext.as_deref(), Some("obj" | "gltf" | "glb"))
}

/// A string as a TOML basic string (quoted and escaped by the toml crate).
fn toml_string(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

/// f64 as TOML: Rust's shortest round-trip form, which TOML reads back to
/// the same f64 (always with a `.` or an exponent, so it stays a float).
fn toml_f64(x: f64) -> String {
    let s = format!("{x:?}");
    if s.contains(['.', 'e', 'E']) {
        s
    } else {
        format!("{s}.0")
    }
}

fn toml_vec(v: [f64; 3]) -> String {
    format!(
        "[{}, {}, {}]",
        toml_f64(v[0]),
        toml_f64(v[1]),
        toml_f64(v[2])
    )
}

/// The camera framing a bounding sphere: `(eye, look_at, near, far)`.
///
/// The eye is on the ray from the center along [`MODEL_VIEW_FROM`], at the
/// distance `d = r / sin(vfov / 2)` where the cone of half-angle vfov/2 from
/// the eye is tangent to the sphere: the sphere fills the image's height
/// (the width is larger, 4:3). Every point of the sphere then has a planar
/// depth in `[d - r, d + r]`; near and far are half and twice those, so no
/// vertex of the model is near either plane whatever the rounding, and
/// far/near stays about 8 (a 24-bit depth buffer's resolution is not wasted).
pub fn frame_sphere(center: [f64; 3], radius: f64) -> ([f64; 3], [f64; 3], f64, f64) {
    let [x, y, z] = MODEL_VIEW_FROM;
    let len = (x * x + y * y + z * z).sqrt();
    let dist = radius / (MODEL_VFOV_DEG.to_radians() / 2.0).sin();
    let eye = [
        center[0] + dist * x / len,
        center[1] + dist * y / len,
        center[2] + dist * z / len,
    ];
    (eye, center, (dist - radius) / 2.0, 2.0 * (dist + radius))
}

/// The model's bounding sphere as rendiff resolves it (f32 world-space
/// vertices, zero-area triangles included): center = the middle of the
/// axis-aligned box, radius = the largest distance from it to a vertex, in
/// f64. Not the smallest sphere, but a deterministic one, simple to restate.
pub fn bounding_sphere(r: &ResolvedScene) -> Option<([f64; 3], f64)> {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for v in r.triangles.iter().flatten() {
        for (k, c) in v.to_array().into_iter().enumerate() {
            lo[k] = lo[k].min(f64::from(c));
            hi[k] = hi[k].max(f64::from(c));
        }
    }
    if r.triangles.is_empty() {
        return None;
    }
    let center = [0, 1, 2].map(|k| lo[k] / 2.0 + hi[k] / 2.0);
    let radius = r
        .triangles
        .iter()
        .flatten()
        .map(|v| {
            let d = [0, 1, 2].map(|k| f64::from(v[k]) - center[k]);
            (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
        })
        .fold(0.0f64, f64::max);
    Some((center, radius))
}

/// The scene text for `model` with its mesh written as `mesh_rel` (relative
/// to the folder the scene will be read from); `None` for the camera writes
/// a placeholder pose, used once to resolve the model for its bounds.
fn scene_text(
    model: &Path,
    mesh_rel: &str,
    camera: Option<([f64; 3], [f64; 3], f64, f64)>,
) -> String {
    let stem = model
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "model".into());
    let shown = printable(&model.display().to_string(), 200);
    let (eye, look_at, near_far) = match camera {
        Some((eye, look_at, near, far)) => (
            eye,
            look_at,
            format!("near = {}\nfar = {}\n", toml_f64(near), toml_f64(far)),
        ),
        None => ([0.0, 0.0, 1.0], [0.0; 3], String::new()),
    };
    let description = format!(
        "{} seen whole: the camera frames its bounding sphere (made by rendiff)",
        printable(&stem, 100)
    );
    format!(
        "# A scene made by rendiff from the model {shown}: the model under identity, a camera\n\
         # framing its bounding sphere from the direction {from:?} (docs/resolved-scene.md,\n\
         # \"A scene from a model file\"), visibility only. Edit freely.\n\
         description = {description}\n\
         requires = [\"depth\", \"ids\"]\n\
         \n\
         [camera]\n\
         eye = {eye}\n\
         look_at = {look_at}\n\
         up = [0.0, 1.0, 0.0]\n\
         vfov = {vfov}\n\
         width = {MODEL_WIDTH}\n\
         height = {MODEL_HEIGHT}\n\
         {near_far}\
         \n\
         [[objects]]\n\
         name = {name}\n\
         mesh = {mesh}\n\
         # The model is taken as it is: its zero-area triangles (never visible) are allowed.\n\
         allow_degenerate = true\n",
        from = MODEL_VIEW_FROM,
        description = toml_string(&description),
        eye = toml_vec(eye),
        look_at = toml_vec(look_at),
        vfov = toml_f64(MODEL_VFOV_DEG),
        name = toml_string(&stem),
        mesh = toml_string(mesh_rel),
    )
}

/// The scene text for `model` (a path as the user gave it), its mesh written
/// as `mesh_rel` relative to the scene's folder, with the camera framing the
/// model ([`frame_sphere`] of [`bounding_sphere`]). The model is read and
/// resolved once here for its bounds; every error names the model file.
pub fn model_scene_text(model: &Path, mesh_rel: &str) -> Result<String, SceneError> {
    let own = own_name(model)?;
    // Named as the user gave it (not as the scene's mesh field) when it is
    // missing, a folder or a device.
    super::open_regular_file(model, super::MAX_MESH_FILE_BYTES)
        .map_err(|p| SceneError::new(model, "", format!("model file {p}")))?;
    // Resolved from the model's own folder, as `check model.glb` reads it.
    let draft = Scene::parse(model, &scene_text(model, &own, None))?;
    let resolved = ResolvedScene::resolve(&draft)?;
    let (center, radius) =
        bounding_sphere(&resolved).ok_or_else(|| SceneError::new(model, "", super::NO_FACES))?;
    if !(radius > 0.0 && radius.is_finite()) {
        return Err(SceneError::new(
            model,
            "",
            "the model has no extent (all its vertices are one point): no camera can frame it",
        ));
    }
    Ok(scene_text(
        model,
        mesh_rel,
        Some(frame_sphere(center, radius)),
    ))
}

/// The model's file name, the mesh path of a scene read from its own folder.
fn own_name(model: &Path) -> Result<String, SceneError> {
    model
        .file_name()
        .and_then(|n| n.to_str())
        .map(str::to_string)
        .ok_or_else(|| SceneError::new(model, "", "the model's file name is not UTF-8 text"))
}

impl Scene {
    /// The scene made from a model file (see the module doc), read as if it
    /// were a scene file beside the model: `check model.glb` and
    /// `render model.glb` take it in place of a TOML file.
    pub fn from_model(model: &Path) -> Result<Scene, SceneError> {
        let text = model_scene_text(model, &own_name(model)?)?;
        Scene::parse(model, &text)
    }
}

/// `rendiff scene new MODEL -o OUT`: writes the model's scene to `out` for
/// editing, its mesh path relative to `out`'s folder, which must hold the
/// model (a scene's meshes never leave its folder). Never overwrites: an
/// existing `out` is an error. Returns the mesh path written.
pub fn write_model_scene(model: &Path, out: &Path) -> Result<String, SceneError> {
    let out_dir = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let dir = out_dir
        .canonicalize()
        .map_err(|e| SceneError::new(out, "", format!("its folder cannot be opened: {e}")))?;
    let full = model
        .canonicalize()
        .map_err(|e| SceneError::new(model, "", format!("cannot be opened: {e}")))?;
    let rel = full.strip_prefix(&dir).map_err(|_| {
        SceneError::new(
            model,
            "",
            format!(
                "is not inside {}, the folder of {}: a scene's meshes never leave its folder; \
                 write the scene beside the model or in a folder above it",
                dir.display(),
                out.display()
            ),
        )
    })?;
    let parts: Option<Vec<&str>> = rel
        .components()
        .map(|c| match c {
            Component::Normal(s) => s.to_str(),
            _ => None,
        })
        .collect();
    let rel = parts
        .map(|p| p.join("/"))
        .ok_or_else(|| SceneError::new(model, "", "its path is not UTF-8 text"))?;
    let text = model_scene_text(model, &rel)?;
    // The written file must read back as the same scene.
    Scene::parse(out, &text)?;
    use std::io::Write;
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(out)
        .map_err(|e| {
            let why = if e.kind() == std::io::ErrorKind::AlreadyExists {
                "already exists; rendiff never overwrites a scene file (remove it or choose another name)"
                    .to_string()
            } else {
                format!("cannot be created: {e}")
            };
            SceneError::new(out, "", why)
        })?;
    f.write_all(text.as_bytes())
        .and_then(|_| f.sync_all())
        .map_err(|e| SceneError::new(out, "", format!("cannot be written: {e}")))?;
    Ok(rel)
}

#[cfg(test)]
mod tests {
    use super::*;

    const TETRA: &str = "v 0 0 0\nv 2 0 0\nv 0 4 0\nv 0 0 6\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";

    #[test]
    fn the_camera_frames_the_bounding_sphere_as_documented() {
        let dir = tempfile::tempdir().unwrap();
        let model = dir.path().join("tetra.obj");
        std::fs::write(&model, TETRA).unwrap();
        let s = Scene::from_model(&model).unwrap();
        let r = ResolvedScene::resolve(&s).unwrap();
        let c = &r.camera;
        // Box [0,2]x[0,4]x[0,6]: center (1,2,3), farthest vertex (0,0,6) or (2,...).
        let (center, radius) = ([1.0, 2.0, 3.0], 14f64.sqrt());
        assert_eq!(bounding_sphere(&r), Some((center, radius)));
        let dist = radius / 20f64.to_radians().sin();
        let dir = glam::DVec3::new(1.0, 1.0, 2.0).normalize();
        let want_eye = glam::DVec3::from(center) + dir * dist;
        assert!((c.eye - want_eye).length() < 1e-12 * dist, "{:?}", c.eye);
        assert!((c.forward + dir).length() < 1e-12);
        assert_eq!(c.vfov_deg, 40.0);
        assert_eq!((c.width, c.height), (320, 240));
        assert!((c.near - (dist - radius) / 2.0).abs() < 1e-12 * dist);
        assert!((c.far - 2.0 * (dist + radius)).abs() < 1e-12 * dist);
        // The sphere fits: every vertex projects inside the image and
        // between near and far, and the sphere touches the frame: its
        // silhouette's angular radius is half the vertical field of view.
        for v in r.triangles.iter().flatten() {
            let p = v.as_dvec3() - c.eye;
            let z = p.dot(c.forward);
            assert!(z > c.near && z < c.far, "{v:?}");
            let t = (MODEL_VFOV_DEG / 2.0).to_radians().tan();
            assert!(p.dot(c.up_ortho).abs() / z < t, "{v:?}");
            assert!(p.dot(c.right).abs() / z < t * 4.0 / 3.0, "{v:?}");
        }
        assert!(((radius / dist).asin() - 20f64.to_radians()).abs() < 1e-12);
        assert_eq!(s.name, "tetra");
        assert_eq!(r.objects[0].name, "tetra");
    }

    #[test]
    fn scene_new_writes_the_same_scene_and_never_overwrites() {
        let dir = tempfile::tempdir().unwrap();
        let sub = dir.path().join("models");
        std::fs::create_dir(&sub).unwrap();
        let model = sub.join("tetra.obj");
        std::fs::write(&model, TETRA).unwrap();
        let out = dir.path().join("scene.toml");
        assert_eq!(write_model_scene(&model, &out).unwrap(), "models/tetra.obj");
        let written = ResolvedScene::resolve(&Scene::load(&out).unwrap()).unwrap();
        let direct = ResolvedScene::resolve(&Scene::from_model(&model).unwrap()).unwrap();
        assert_eq!(written.triangles, direct.triangles);
        assert_eq!(written.object_ids, direct.object_ids);
        let (a, b) = (&written.camera, &direct.camera);
        assert_eq!((a.eye, a.look_at, a.up), (b.eye, b.look_at, b.up));
        assert_eq!((a.near, a.far, a.vfov_deg), (b.near, b.far, b.vfov_deg));
        let before = std::fs::read(&out).unwrap();
        let e = write_model_scene(&model, &out).unwrap_err().to_string();
        assert!(
            e.contains("scene.toml: already exists; rendiff never overwrites"),
            "{e}"
        );
        assert_eq!(std::fs::read(&out).unwrap(), before);
        // A scene outside the model's folder tree cannot reach it.
        let e = write_model_scene(&model, &sub.join("inner").join("s.toml"));
        assert!(e.is_err());
        std::fs::create_dir(sub.join("inner")).unwrap();
        let e = write_model_scene(&model, &sub.join("inner/s.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("tetra.obj: is not inside"), "{e}");
        assert!(e.contains("a scene's meshes never leave its folder"), "{e}");
    }

    #[test]
    fn odd_file_names_stay_inside_their_toml_strings_and_comments() {
        let dir = tempfile::tempdir().unwrap();
        let name = "a\"b\\c\nd].obj";
        let model = dir.path().join(name);
        std::fs::write(&model, TETRA).unwrap();
        let s = Scene::from_model(&model).unwrap();
        assert_eq!(s.file.objects.len(), 1);
        assert_eq!(s.file.objects[0].mesh.as_deref(), Some(name));
        assert_eq!(s.file.objects[0].name, "a\"b\\c\nd]");
    }

    #[test]
    fn a_model_of_one_point_or_no_faces_is_refused_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let model = dir.path().join("dot.obj");
        std::fs::write(&model, "v 1 1 1\nf 1 1 1\n").unwrap();
        let e = Scene::from_model(&model).unwrap_err().to_string();
        assert!(e.contains("dot.obj: the model has no extent"), "{e}");
        let e = Scene::from_model(&dir.path().join("none.glb"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("none.glb: model file cannot be opened"), "{e}");
        let e = Scene::from_model(dir.path()).unwrap_err().to_string();
        assert!(e.contains(": model file is a folder"), "{e}");
        std::fs::write(&model, "v 1 1 1\n").unwrap();
        let e = Scene::from_model(&model).unwrap_err().to_string();
        assert!(
            e.contains("dot.obj") && e.contains(super::super::NO_FACES),
            "{e}"
        );
    }
}
