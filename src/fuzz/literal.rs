//! A standalone scene: a camera and objects made of literal triangles
//! (`shape = { kind = "triangles" }`), no mesh file, written as scene TOML.
//!
//! Both halves of the fuzzer write scenes through this one type: the
//! grammar (`grammar.rs`) builds them, and the reducer (`reduce.rs`) reads
//! any scene back from its resolved triangles, removes and snaps, and writes
//! the result. The writer is deterministic (fixed key order, Rust's
//! shortest round-trip float formatting), so equal scenes are equal files.
//!
//! A shaded scene (one that requires more than visibility) keeps what its
//! shading reads: each object's material (albedo, emission), the lights and
//! the integrator, all written inline, so the rewrite resolves to the same
//! triangles, materials, lights, camera and `requires`.

use crate::scene::resolve::ResolvedScene;
use crate::scene::{IntegratorSpec, LightSpec};
use anyhow::Result;
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
    /// Index into [`LiteralScene::materials`]; `None` is the scene's first
    /// material, as the scene format says for an object without one.
    pub material: Option<usize>,
    /// Writes `allow_degenerate = true`: the object has a zero-area
    /// triangle the scene it came from allowed.
    pub allow_degenerate: bool,
}

impl LiteralObject {
    /// An object of these triangles, with no transform, the scene's first
    /// material and no zero-area triangle allowed.
    pub fn new(triangles: Vec<Tri>) -> LiteralObject {
        LiteralObject {
            triangles,
            mirror: None,
            material: None,
            allow_degenerate: false,
        }
    }
}

/// A diffuse material (docs/radiance.md): what shading reads of it. Its
/// name is not kept (names are untrusted text): the writer names materials
/// `m0`, `m1`, ... in the order of those the objects use.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiteralMaterial {
    /// Diffuse reflectance per channel.
    pub albedo: [f64; 3],
    /// Emitted radiance per channel.
    pub emission: [f64; 3],
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
    /// Materials the objects index; empty writes none (the format's default
    /// grey), as for a visibility scene.
    pub materials: Vec<LiteralMaterial>,
    /// The lights, in order; each is one unit the reducer may remove.
    pub lights: Vec<LightSpec>,
    /// The Monte Carlo settings; `None` writes none (the defaults).
    pub integrator: Option<IntegratorSpec>,
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
        if let Some(i) = &self.integrator {
            let _ = writeln!(s, "\n[integrator]");
            let _ = writeln!(s, "max_depth = {}", i.max_depth);
            let _ = writeln!(s, "spp = {}", i.spp);
        }
        // Only the materials some object uses, renumbered densely in index
        // order: the same scene gives the same file however many materials
        // the reducer's removals left unused.
        let used = self.used_materials();
        for (k, &m) in used.iter().enumerate() {
            let mat = &self.materials[m];
            let _ = writeln!(s, "\n[[materials]]");
            let _ = writeln!(s, "name = \"m{k}\"");
            let _ = writeln!(s, "albedo = {}", vec3(&mat.albedo));
            let _ = writeln!(s, "emission = {}", vec3(&mat.emission));
        }
        for (i, o) in self.objects.iter().enumerate() {
            let _ = writeln!(s, "\n[[objects]]");
            let _ = writeln!(s, "name = \"o{i}\"");
            if !used.is_empty() {
                let m = o.material.unwrap_or(0);
                let k = used.iter().position(|&u| u == m).unwrap_or(0);
                let _ = writeln!(s, "material = \"m{k}\"");
            }
            if o.allow_degenerate {
                let _ = writeln!(s, "allow_degenerate = true");
            }
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
        for l in &self.lights {
            let _ = writeln!(s, "\n[[lights]]");
            match l {
                LightSpec::Point {
                    position,
                    intensity,
                } => {
                    let _ = writeln!(s, "kind = \"point\"");
                    let _ = writeln!(s, "position = {}", vec3(position));
                    let _ = writeln!(s, "intensity = {}", vec3(intensity));
                }
                LightSpec::Directional {
                    direction,
                    irradiance,
                } => {
                    let _ = writeln!(s, "kind = \"directional\"");
                    let _ = writeln!(s, "direction = {}", vec3(direction));
                    let _ = writeln!(s, "irradiance = {}", vec3(irradiance));
                }
            }
        }
        s
    }

    /// The indices of the materials the objects use (an object without
    /// one uses the first), ascending; empty when the scene has none.
    fn used_materials(&self) -> Vec<usize> {
        if self.materials.is_empty() {
            return Vec::new();
        }
        let used: std::collections::BTreeSet<usize> = self
            .objects
            .iter()
            .map(|o| o.material.unwrap_or(0).min(self.materials.len() - 1))
            .collect();
        used.into_iter().collect()
    }

    /// The scene a resolved scene is, rewritten standalone: every object's
    /// world-space f32 triangles as literal f64 (exact, so resolving the
    /// rewrite gives the same f32 bits), the camera's pose with its near and
    /// far written out. A shaded scene (one that requires anything beyond
    /// visibility: depth, ids, normals) also keeps each object's material,
    /// the lights and the integrator; a visibility scene's materials are
    /// left out (no buffer it is judged on reads them).
    pub fn from_resolved(r: &ResolvedScene, description: &str) -> Result<LiteralScene> {
        let visibility = crate::check::visibility_features();
        let shaded = r.requires.iter().any(|f| !visibility.contains(&f.as_str()));
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
            .map(|info| LiteralObject {
                material: shaded.then_some(info.material as usize),
                ..LiteralObject::new(Vec::new())
            })
            .collect();
        for ((t, &o), &deg) in r.triangles.iter().zip(&r.object_ids).zip(&r.degenerate) {
            let tri = [0, 1, 2].map(|k| t[k].as_dvec3().to_array());
            let obj = &mut objects[o as usize];
            obj.triangles.push(tri);
            obj.allow_degenerate |= deg;
        }
        objects.retain(|o| !o.triangles.is_empty());
        let materials = if shaded {
            r.materials
                .iter()
                .map(|m| LiteralMaterial {
                    albedo: m.albedo,
                    emission: m.emission,
                })
                .collect()
        } else {
            Vec::new()
        };
        Ok(LiteralScene {
            description: description.to_string(),
            requires: r.requires.iter().cloned().collect(),
            camera,
            objects,
            materials,
            lights: if shaded { r.lights.clone() } else { Vec::new() },
            integrator: shaded.then_some(r.integrator),
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
        objects: objects.into_iter().map(LiteralObject::new).collect(),
        materials: Vec::new(),
        lights: Vec::new(),
        integrator: None,
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
                LiteralObject::new(vec![[
                    [-1.0, -1.0, 0.0],
                    [1.0, -1.0, 0.0],
                    [0.1, 1.0, -0.0],
                ]]),
                LiteralObject {
                    mirror: Some(([-1.0, 1.0, 1.0], [0.0, 0.0, 0.0])),
                    ..LiteralObject::new(vec![[
                        [-1.0, -1.0, 1e-7],
                        [1.0, -1.0, 0.3],
                        [0.0, 1.0, 0.5],
                    ]])
                },
            ],
            materials: Vec::new(),
            lights: Vec::new(),
            integrator: None,
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

#[cfg(test)]
mod shaded_tests {
    use super::*;
    use crate::scene::Scene;
    use std::path::Path;

    /// A shaded scene with what the format has: materials (one unused, one
    /// emissive), point and directional lights, an integrator, shapes under
    /// transforms, a camera with near and far.
    const SHADED: &str = r#"
requires = ["depth", "ids", "lambert", "emission", "point_light", "directional_light", "shadowless", "two_sided"]
[camera]
eye = [1.5, 2.5, 4.0]
look_at = [0.0, 0.2, 0.0]
vfov = 45.0
width = 24
height = 16
near = 0.01
far = 100.0
[integrator]
max_depth = 3
spp = 16
[[materials]]
name = "unused"
albedo = [0.1, 0.1, 0.1]
[[materials]]
name = "floor"
albedo = [0.6, 0.5, 0.4]
[[materials]]
name = "lamp"
albedo = [0.0, 0.0, 0.0]
emission = [2.0, 1.5, 1.0]
[[objects]]
name = "floor"
material = "floor"
shape = { kind = "quad", size = [6.0, 6.0] }
transform = { rotate = [-90.0, 0.0, 0.0] }
[[objects]]
name = "lamp"
material = "lamp"
shape = { kind = "box", min = [-0.4, 0.0, -0.4], max = [0.4, 0.8, 0.4] }
transform = { rotate = [0.0, 30.0, 0.0], translate = [0.1, 0.0, 0.2] }
[[lights]]
kind = "point"
position = [1.0, 2.0, 1.0]
intensity = [6.0, 5.0, 4.0]
[[lights]]
kind = "directional"
direction = [0.3, -1.0, 0.2]
irradiance = [0.5, 0.5, 0.7]
"#;

    fn resolve(text: &str) -> ResolvedScene {
        let scene = Scene::parse(Path::new("s.toml"), text).unwrap();
        ResolvedScene::resolve(&scene).unwrap()
    }

    /// Each triangle's (albedo, emission).
    fn shading(r: &ResolvedScene) -> Vec<([f64; 3], [f64; 3])> {
        r.object_ids
            .iter()
            .map(|&o| {
                let m = &r.materials[r.objects[o as usize].material as usize];
                (m.albedo, m.emission)
            })
            .collect()
    }

    #[test]
    fn a_shaded_scene_round_trips_to_the_same_resolved_scene() {
        let r = resolve(SHADED);
        let lit = LiteralScene::from_resolved(&r, "round trip").unwrap();
        let text = lit.to_toml();
        let r2 = resolve(&text);
        assert_eq!(r.triangles, r2.triangles);
        assert_eq!(r.object_ids, r2.object_ids);
        assert_eq!(shading(&r), shading(&r2));
        // Both materials in use kept, the unused one left out.
        assert_eq!(r2.materials.len(), 2, "{text}");
        assert_eq!(r.lights, r2.lights);
        assert_eq!(r.integrator, r2.integrator);
        assert_eq!(r.requires, r2.requires);
        let (c, c2) = (&r.camera, &r2.camera);
        assert_eq!(
            (c.eye, c.look_at, c.up, c.vfov_deg, c.width, c.height, c.near, c.far),
            (
                c2.eye,
                c2.look_at,
                c2.up,
                c2.vfov_deg,
                c2.width,
                c2.height,
                c2.near,
                c2.far
            )
        );
        // A fixed point: the rewrite of the rewrite is the same file.
        assert_eq!(
            text,
            LiteralScene::from_resolved(&r2, "round trip")
                .unwrap()
                .to_toml()
        );
    }

    #[test]
    fn removed_objects_take_their_materials_and_the_rest_keep_theirs() {
        let r = resolve(SHADED);
        let mut lit = LiteralScene::from_resolved(&r, "").unwrap();
        // Keep only the lamp (material 2 of 3): it is written as m0 and
        // still emits; the floor's material goes with the floor.
        lit.objects.remove(0);
        let r2 = resolve(&lit.to_toml());
        assert_eq!(r2.materials.len(), 1);
        assert_eq!(r2.materials[0].emission, [2.0, 1.5, 1.0]);
        assert!(shading(&r2).iter().all(|s| s.1 == [2.0, 1.5, 1.0]));
        // Lights removed one by one stay a valid scene.
        lit.lights.truncate(1);
        let r3 = resolve(&lit.to_toml());
        assert_eq!(r3.lights.len(), 1);
        assert!(matches!(r3.lights[0], LightSpec::Point { .. }));
    }

    #[test]
    fn a_visibility_scene_is_written_without_materials_or_lights() {
        let text = SHADED.replace(
            r#"requires = ["depth", "ids", "lambert", "emission", "point_light", "directional_light", "shadowless", "two_sided"]"#,
            r#"requires = ["depth", "ids"]"#,
        );
        // Lights need their features: a visibility scene has none.
        let text = text.split("[[lights]]").next().unwrap().to_string();
        let lit = LiteralScene::from_resolved(&resolve(&text), "").unwrap();
        let out = lit.to_toml();
        assert!(
            !out.contains("[[materials]]") && !out.contains("material ="),
            "{out}"
        );
        assert!(
            !out.contains("[integrator]") && !out.contains("[[lights]]"),
            "{out}"
        );
    }
}
