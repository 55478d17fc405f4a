//! OBJ mesh loading (tobj), confined to the scene's folder.

use super::generators::Tri64;
use super::SceneError;
use glam::DVec3;
use std::path::{Component, Path, PathBuf};

/// Resolves `rel` against `scene_dir` and refuses anything that leaves the folder
/// (absolute paths, `..`, or symlinks pointing outside), so a scene cannot read
/// arbitrary files through a renderer.
pub fn confined_path(
    scene_file: &Path,
    scene_dir: &Path,
    rel: &str,
    field: &str,
) -> Result<PathBuf, SceneError> {
    let p = Path::new(rel);
    if p.is_absolute() || p.components().any(|c| matches!(c, Component::Prefix(_))) {
        return Err(SceneError::new(
            scene_file,
            field,
            format!("mesh path {rel:?} must be relative to the scene's folder"),
        ));
    }
    let joined = scene_dir.join(p);
    let dir = scene_dir.canonicalize().map_err(|e| {
        SceneError::new(
            scene_file,
            field,
            format!(
                "cannot resolve the scene folder {}: {e}",
                scene_dir.display()
            ),
        )
    })?;
    let full = joined.canonicalize().map_err(|e| {
        SceneError::new(
            scene_file,
            field,
            format!("mesh file {} cannot be opened: {e}", joined.display()),
        )
    })?;
    if !full.starts_with(&dir) {
        return Err(SceneError::new(
            scene_file,
            field,
            format!(
                "mesh path {rel:?} points outside the scene's folder {}",
                dir.display()
            ),
        ));
    }
    Ok(full)
}

/// Loads every face of every model in an OBJ file as triangles (polygons are fan-triangulated).
pub fn load_obj(mesh: &Path, field: &str) -> Result<Vec<Tri64>, SceneError> {
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, _materials) = tobj::load_obj(mesh, &opts)
        .map_err(|e| SceneError::new(mesh, field, format!("cannot parse OBJ mesh: {e}")))?;
    let mut out = Vec::new();
    for model in &models {
        let m = &model.mesh;
        let pos = &m.positions;
        if let Some(i) = pos.iter().position(|x| !x.is_finite()) {
            return Err(SceneError::new(
                mesh,
                field,
                format!(
                    "vertex {} of model {:?} is not finite (NaN or Inf)",
                    i / 3 + 1,
                    model.name
                ),
            ));
        }
        let vert = |k: u32| -> Result<DVec3, SceneError> {
            let k = k as usize;
            if 3 * k + 2 >= pos.len() {
                return Err(SceneError::new(
                    mesh,
                    field,
                    format!("face refers to vertex {} which does not exist", k + 1),
                ));
            }
            Ok(DVec3::new(
                f64::from(pos[3 * k]),
                f64::from(pos[3 * k + 1]),
                f64::from(pos[3 * k + 2]),
            ))
        };
        for f in m.indices.chunks_exact(3) {
            out.push([vert(f[0])?, vert(f[1])?, vert(f[2])?]);
        }
    }
    if out.is_empty() {
        return Err(SceneError::new(mesh, field, "OBJ mesh has no faces"));
    }
    Ok(out)
}
