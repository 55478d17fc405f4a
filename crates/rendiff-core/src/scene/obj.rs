//! OBJ mesh loading (tobj), confined to the scene's folder.
//!
//! The mesh is read here (a regular file of at most [`MAX_MESH_FILE_BYTES`],
//! in UTF-8, its triangles counted against the scene's budget) and tobj parses
//! the text in memory: tobj never opens a file itself. Materials are not
//! loaded: rendiff's materials come from the scene file, so an OBJ's `mtllib`
//! lines are ignored (never opened, wherever they point) and so are its
//! `usemtl` lines; objects come from `o`/`g` groups only.

use super::generators::Tri64;
use super::{read_regular_file, utf8_text, SceneError, MAX_MESH_FILE_BYTES, MAX_SCENE_TRIANGLES};
use glam::DVec3;
use std::path::{Component, Path, PathBuf};

/// Resolves `rel` against `scene_dir` and refuses anything that leaves the folder
/// (absolute paths, `..`, or symlinks pointing outside), so a scene cannot read
/// arbitrary files through a renderer. An empty path and a folder (`"."`,
/// `"meshes/"`) are refused here, naming the scene file and its field: the
/// mesh reader would name only the folder the path resolves to.
pub fn confined_path(
    scene_file: &Path,
    scene_dir: &Path,
    rel: &str,
    field: &str,
) -> Result<PathBuf, SceneError> {
    if rel.is_empty() {
        return Err(SceneError::new(
            scene_file,
            field,
            "mesh path is empty: name an OBJ or glTF file inside the scene's folder",
        ));
    }
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
    if full.is_dir() {
        return Err(SceneError::new(
            scene_file,
            field,
            format!("mesh path {rel:?} is a folder, not a file"),
        ));
    }
    Ok(full)
}

/// One `o`/`g` group of an OBJ file (a tobj model), fan-triangulated.
#[derive(Debug, Clone)]
pub struct ObjGroup {
    /// The group's name as written in the file (untrusted text); tobj names a
    /// file without `o`/`g` lines `unnamed_object`.
    pub name: String,
    /// Its faces as triangles, in file order.
    pub triangles: Vec<Tri64>,
}

/// Upper bound of the triangles an OBJ text makes: each `f` line of n
/// vertices is fan-triangulated into n - 2 (exact for a file tobj accepts).
pub fn count_face_triangles(text: &str) -> u64 {
    text.lines()
        .filter_map(|line| {
            let mut words = line.split_whitespace();
            (words.next() == Some("f")).then(|| (words.count() as u64).saturating_sub(2))
        })
        .sum()
}

/// The first line that explains tobj's error, with its 1-based number: tobj
/// names the problem but not where it is, and a user with a 50 MB scan needs
/// the line. Only the error kinds a line can show are located (a number that
/// does not parse, a face with fewer than three corners or an index out of
/// range); `None` when no line shows the problem the way tobj saw it.
fn offending_line<'a>(text: &'a str, err: &tobj::LoadError) -> Option<(usize, &'a str)> {
    use tobj::LoadError as E;
    let floats = |rest: &str, min: usize| {
        let v: Vec<&str> = rest.split_whitespace().collect();
        v.len() < min || v.iter().any(|t| t.parse::<f32>().is_err())
    };
    // Vertex counts of the whole file: tobj resolves indices against them.
    let (mut nv, mut nvt, mut nvn) = (0i64, 0i64, 0i64);
    for l in text.lines() {
        match l.split_whitespace().next() {
            Some("v") => nv += 1,
            Some("vt") => nvt += 1,
            Some("vn") => nvn += 1,
            _ => {}
        }
    }
    let (mut sv, mut svt, mut svn) = (0i64, 0i64, 0i64);
    let bad_index = |t: &str, seen: i64, total: i64| match t.parse::<i64>() {
        Ok(i) if i > 0 => i > total,
        Ok(i) if i < 0 => -i > seen,
        _ => true,
    };
    for (n, l) in text.lines().enumerate() {
        let mut words = l.split_whitespace();
        let key = words.next();
        let rest = l.trim_start().get(key.map_or(0, str::len)..).unwrap_or("");
        let hit = match (key, err) {
            (Some("v"), E::PositionParseError) => floats(rest, 3),
            (Some("vn"), E::NormalParseError) => floats(rest, 3),
            (Some("vt"), E::TexcoordParseError) => floats(rest, 1),
            (Some("f"), E::FaceParseError | E::InvalidPolygon) => {
                let corners: Vec<&str> = rest.split_whitespace().collect();
                corners.len() < 3
                    || corners.iter().any(|c| {
                        c.split('/')
                            .next()
                            .is_none_or(|i| i.parse::<i64>().is_err())
                    })
            }
            (Some("f"), E::FaceVertexOutOfBounds) => rest
                .split_whitespace()
                .any(|c| bad_index(c.split('/').next().unwrap_or(""), sv, nv)),
            (Some("f"), E::FaceTexCoordOutOfBounds) => rest.split_whitespace().any(|c| {
                c.split('/')
                    .nth(1)
                    .is_some_and(|t| !t.is_empty() && bad_index(t, svt, nvt))
            }),
            (Some("f"), E::FaceNormalOutOfBounds) => rest.split_whitespace().any(|c| {
                c.split('/')
                    .nth(2)
                    .is_some_and(|t| !t.is_empty() && bad_index(t, svn, nvn))
            }),
            _ => false,
        };
        if hit {
            return Some((n + 1, l));
        }
        match key {
            Some("v") => sv += 1,
            Some("vt") => svt += 1,
            Some("vn") => svn += 1,
            _ => {}
        }
    }
    None
}

/// Loads an OBJ file as its `o`/`g` groups (tobj models), in file order; each
/// group's polygons are fan-triangulated in file order. Groups without faces
/// (only points or lines) are left out; a file with no faces at all is an error.
/// The file must be a regular file (see [`super::read_regular_file`]) of at
/// most [`MAX_MESH_FILE_BYTES`] in UTF-8 with at most `budget` triangles (what
/// the scene's other objects leave of [`MAX_SCENE_TRIANGLES`]), all checked
/// before tobj parses it. `mtllib` and `usemtl` are ignored (module docs).
pub fn load_obj(mesh: &Path, field: &str, budget: u64) -> Result<Vec<ObjGroup>, SceneError> {
    let bytes = read_regular_file(mesh, MAX_MESH_FILE_BYTES)
        .map_err(|p| SceneError::new(mesh, field, format!("mesh file {p}")))?;
    let text =
        utf8_text(bytes).map_err(|p| SceneError::new(mesh, field, format!("mesh file {p}")))?;
    let count = count_face_triangles(&text);
    if count > budget {
        return Err(SceneError::new(
            mesh,
            field,
            format!(
                "mesh has {count} triangles; with the scene's other objects ({} triangles) \
                 that is more than the limit of {MAX_SCENE_TRIANGLES} (64 Mi) per scene",
                MAX_SCENE_TRIANGLES.saturating_sub(budget)
            ),
        ));
    }
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    // The material loader refuses without touching the file system; tobj keeps
    // going without materials (its error is only reported in the unused
    // materials result).
    let parsed = tobj::load_obj_buf(&mut text.as_bytes(), &opts, |_| {
        Err(tobj::LoadError::OpenFileFailed)
    });
    let (models, _materials) = parsed.map_err(|e| {
        let at = match offending_line(&text, &e) {
            Some((n, line)) => format!(" at line {n}: {}", super::printable(line.trim(), 80)),
            None => String::new(),
        };
        SceneError::new(mesh, field, format!("cannot parse OBJ mesh: {e}{at}"))
    })?;
    drop(text);
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
        let mut triangles = Vec::with_capacity(m.indices.len() / 3);
        for f in m.indices.chunks_exact(3) {
            triangles.push([vert(f[0])?, vert(f[1])?, vert(f[2])?]);
        }
        if !triangles.is_empty() {
            out.push(ObjGroup {
                name: model.name.clone(),
                triangles,
            });
        }
    }
    if out.is_empty() {
        return Err(SceneError::new(mesh, field, super::NO_FACES));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `<name>.obj` in a folder of its own, removed when the returned
    /// handle drops (a fixed folder under /tmp stayed after every run).
    fn write_obj(name: &str, text: &str) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(format!("{name}.obj"));
        std::fs::write(&p, text).unwrap();
        (dir, p)
    }

    #[test]
    fn parse_errors_name_the_line() {
        let cases = [
            (
                "bad_position",
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 x 0\nf 1 2 3\n",
                "line 4: v 1 x 0",
            ),
            (
                "out_of_range",
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n",
                "line 5: f 1 2 9",
            ),
            (
                "bad_normal",
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0\nf 1 2 3\n",
                "line 4: vn 0 0",
            ),
        ];
        for (name, text, want) in cases {
            let e = load_obj(&write_obj(name, text).1, "objects[0].mesh", u64::MAX)
                .err()
                .unwrap_or_else(|| panic!("{name}: loaded"))
                .to_string();
            assert!(e.contains(want), "{name}: {e}");
            assert_eq!(e.lines().count(), 1, "{e}");
        }
    }

    #[test]
    fn groups_are_kept_in_file_order() {
        let (_dir, p) = write_obj(
            "two_groups",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 2 0 0\n\
             o first\nf 1 2 3\nf 2 4 3\n\
             o second\nf 2 5 4 3\n",
        );
        let groups = load_obj(&p, "objects[0].mesh", MAX_SCENE_TRIANGLES).unwrap();
        assert_eq!(groups.len(), 2);
        assert_eq!(groups[0].name, "first");
        assert_eq!(groups[0].triangles.len(), 2);
        assert_eq!(groups[1].name, "second");
        // A quad is fan-triangulated: (2 5 4), (2 4 3).
        assert_eq!(groups[1].triangles.len(), 2);
        assert_eq!(groups[1].triangles[0][1], DVec3::new(2.0, 0.0, 0.0));
    }

    #[test]
    fn a_file_without_groups_is_one_group() {
        let (_dir, p) = write_obj("no_groups", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
        let groups = load_obj(&p, "objects[0].mesh", MAX_SCENE_TRIANGLES).unwrap();
        assert_eq!(groups.len(), 1);
        assert_eq!(groups[0].triangles.len(), 1);
    }

    #[test]
    fn groups_without_faces_are_left_out() {
        let (_dir, p) = write_obj(
            "empty_group",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\no lines_only\nl 1 2\no tri\nf 1 2 3\n",
        );
        let groups = load_obj(&p, "objects[0].mesh", MAX_SCENE_TRIANGLES).unwrap();
        assert_eq!(groups.len(), 1);
        assert_eq!(groups[0].name, "tri");
    }
}
