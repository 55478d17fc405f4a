//! A standalone scene: a camera and objects made of literal triangles
//! (`shape = { kind = "triangles" }`), no mesh file, written as scene TOML.
//!
//! Both halves of the fuzzer write scenes through this one type: the
//! grammar (`grammar.rs`) builds them, and the reducer (`reduce.rs`) reads
//! any scene back from its resolved triangles, removes and snaps, and writes
//! the result. The writer is deterministic (fixed key order, Rust's
//! shortest round-trip float formatting), so equal scenes are equal files.

use crate::scene::resolve::ResolvedScene;
use anyhow::{bail, Result};
use std::fmt::Write;

/// A triangle's three vertices, in world space (or object space, under a
/// [`LiteralObject::mirror`]).
pub type Tri = [[f64; 3]; 3];

/// The pinhole camera of docs/DESIGN.md, as the scene file spells it.
#[derive(Debug, Clone, PartialEq)]
pub struct LiteralCamera {
    /// Center of projection.
    pub eye: [f64; 3],
    /// A point on the view axis.
    pub look_at: [f64; 3],
    /// Roll reference.
    pub up: [f64; 3],
    /// Vertical field of view, degrees.
    pub vfov: f64,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Nearest visible planar depth. Always written: the default (1e-4 x the
    /// scene's size) would move when the reducer removes triangles, and a
    /// huge off-screen triangle would push it past everything else.
    pub near: f64,
    /// Farthest visible planar depth; `None` is +infinity.
    pub far: Option<f64>,
}

/// One object: literal triangles, optionally under a mirroring transform.
#[derive(Debug, Clone, PartialEq)]
pub struct LiteralObject {
    /// Its triangles, in prim order.
    pub triangles: Vec<Tri>,
    /// `transform = { scale = S, translate = T }` with a negative scale
    /// component (a mirrored transform); `None` writes no transform.
    pub mirror: Option<([f64; 3], [f64; 3])>,
}

/// A whole standalone scene.
#[derive(Debug, Clone, PartialEq)]
pub struct LiteralScene {
    /// The first comment lines and the `description` (plain ASCII we write ourselves).
    pub description: String,
    /// `requires`.
    pub requires: Vec<String>,
    /// The camera.
    pub camera: LiteralCamera,
    /// The objects, in object-ID order.
    pub objects: Vec<LiteralObject>,
}

/// A float as TOML reads it back to the same f64 (Rust's `{:?}` is the
/// shortest round-trip form, and always has a `.` or an exponent).
fn num(x: f64) -> String {
    debug_assert!(x.is_finite());
    // `{:?}` writes -0.0 as "-0.0" and 1e-7 as "1e-7": both valid TOML floats.
    format!("{x:?}")
}

fn vec3(v: &[f64; 3]) -> String {
    format!("[{}, {}, {}]", num(v[0]), num(v[1]), num(v[2]))
}

impl LiteralScene {
    /// Triangles in all objects.
    pub fn triangle_count(&self) -> usize {
        self.objects.iter().map(|o| o.triangles.len()).sum()
    }

    /// The scene file's text.
    pub fn to_toml(&self) -> String {
        let mut s = String::new();
        // The description is ours (ASCII, no quotes), but escape anyway.
        let desc: String = self
            .description
            .chars()
            .filter(|c| c.is_ascii_graphic() || *c == ' ')
            .filter(|c| *c != '"' && *c != '\\')
            .collect();
        let _ = writeln!(s, "description = \"{desc}\"");
        let req: Vec<String> = self.requires.iter().map(|r| format!("\"{r}\"")).collect();
        let _ = writeln!(s, "requires = [{}]", req.join(", "));
        let c = &self.camera;
        let _ = writeln!(s, "\n[camera]");
        let _ = writeln!(s, "eye = {}", vec3(&c.eye));
        let _ = writeln!(s, "look_at = {}", vec3(&c.look_at));
        let _ = writeln!(s, "up = {}", vec3(&c.up));
        let _ = writeln!(s, "vfov = {}", num(c.vfov));
        let _ = writeln!(s, "width = {}", c.width);
        let _ = writeln!(s, "height = {}", c.height);
        let _ = writeln!(s, "near = {}", num(c.near));
        if let Some(far) = c.far {
            let _ = writeln!(s, "far = {}", num(far));
        }
        for (i, o) in self.objects.iter().enumerate() {
            let _ = writeln!(s, "\n[[objects]]");
            let _ = writeln!(s, "name = \"o{i}\"");
            if let Some((scale, translate)) = &o.mirror {
                let _ = writeln!(
                    s,
                    "transform = {{ scale = {}, translate = {} }}",
                    vec3(scale),
                    vec3(translate)
                );
            }
            let _ = writeln!(s, "[objects.shape]");
            let _ = writeln!(s, "kind = \"triangles\"");
            let _ = writeln!(s, "vertices = [");
            for t in &o.triangles {
                let _ = writeln!(s, "  {}, {}, {},", vec3(&t[0]), vec3(&t[1]), vec3(&t[2]));
            }
            let _ = writeln!(s, "]");
        }
        s
    }

    /// The scene a resolved scene is, rewritten standalone: every object's
    /// world-space f32 triangles as literal f64 (exact, so resolving the
    /// rewrite gives the same f32 bits), the camera's pose with its near and
    /// far written out. Only visibility scenes (depth, ids, normals): a
    /// shaded scene's materials and lights are not carried over yet, and it
    /// is refused with that reason rather than reduced into another scene.
    pub fn from_resolved(r: &ResolvedScene, description: &str) -> Result<LiteralScene> {
        let visibility = crate::check::visibility_features();
        if let Some(f) = r
            .requires
            .iter()
            .find(|f| !visibility.contains(&f.as_str()))
        {
            bail!(
                "the scene requires {f:?}: only visibility scenes (depth, ids, normals) can be rewritten standalone so far"
            );
        }
        let c = &r.camera;
        let camera = LiteralCamera {
            eye: c.eye.to_array(),
            look_at: c.look_at.to_array(),
            up: c.up.to_array(),
            vfov: c.vfov_deg,
            width: c.width,
            height: c.height,
            near: c.near,
            far: c.far.is_finite().then_some(c.far),
        };
        let mut objects: Vec<LiteralObject> = r
            .objects
            .iter()
            .map(|_| LiteralObject {
                triangles: Vec::new(),
                mirror: None,
            })
            .collect();
        for (t, &o) in r.triangles.iter().zip(&r.object_ids) {
            let tri = [0, 1, 2].map(|k| t[k].as_dvec3().to_array());
            objects[o as usize].triangles.push(tri);
        }
        objects.retain(|o| !o.triangles.is_empty());
        Ok(LiteralScene {
            description: description.to_string(),
            requires: r.requires.iter().cloned().collect(),
            camera,
            objects,
        })
    }
}

/// A scene for unit tests: the eye at (0, 0, 4) looking at the origin,
/// y up, near 0.01, one object per list of triangles.
#[cfg(test)]
pub(crate) fn test_scene(
    vfov: f64,
    width: u32,
    height: u32,
    objects: Vec<Vec<Tri>>,
) -> LiteralScene {
    LiteralScene {
        description: String::new(),
        requires: vec!["depth".into(), "ids".into()],
        camera: LiteralCamera {
            eye: [0.0, 0.0, 4.0],
            look_at: [0.0; 3],
            up: [0.0, 1.0, 0.0],
            vfov,
            width,
            height,
            near: 0.01,
            far: None,
        },
        objects: objects
            .into_iter()
            .map(|triangles| LiteralObject {
                triangles,
                mirror: None,
            })
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;
    use std::path::Path;

    fn one() -> LiteralScene {
        LiteralScene {
            description: "two triangles".into(),
            requires: vec!["depth".into(), "ids".into()],
            camera: LiteralCamera {
                eye: [0.0, 0.0, 4.0],
                look_at: [0.0, 0.0, 0.0],
                up: [0.0, 1.0, 0.0],
                vfov: 45.0,
                width: 33,
                height: 17,
                near: 1e-3,
                far: None,
            },
            objects: vec![
                LiteralObject {
                    triangles: vec![[[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.1, 1.0, -0.0]]],
                    mirror: None,
                },
                LiteralObject {
                    triangles: vec![[[-1.0, -1.0, 1e-7], [1.0, -1.0, 0.3], [0.0, 1.0, 0.5]]],
                    mirror: Some(([-1.0, 1.0, 1.0], [0.0, 0.0, 0.0])),
                },
            ],
        }
    }

    #[test]
    fn written_scenes_load_and_resolve_to_the_same_triangles() {
        let s = one();
        let text = s.to_toml();
        let scene = Scene::parse(Path::new("t.toml"), &text).unwrap();
        let r = ResolvedScene::resolve(&scene).unwrap();
        assert_eq!(r.triangles.len(), 2);
        assert_eq!(r.camera.width, 33);
        assert_eq!(r.camera.near, 1e-3);
        // The mirrored object's x went through scale -1.
        assert_eq!(r.triangles[1][0].x, 1.0);
        // Rewritten from the resolved scene: no transform, same bits.
        let back = LiteralScene::from_resolved(&r, "again").unwrap();
        let again = Scene::parse(Path::new("t.toml"), &back.to_toml()).unwrap();
        let r2 = ResolvedScene::resolve(&again).unwrap();
        assert_eq!(r.triangles, r2.triangles);
        assert_eq!(r.object_ids, r2.object_ids);
        assert_eq!(
            back.to_toml(),
            LiteralScene::from_resolved(&r2, "again").unwrap().to_toml()
        );
    }
}
