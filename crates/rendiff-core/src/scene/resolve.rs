//! Resolution: one world-space triangle list with global IDs, rounded to f32 once.
//!
//! Every renderer, internal or external, reads this list, so `prim_id`,
//! `object_id` and vertex values mean the same thing everywhere.

use super::generators::Tri64;
use super::gltf::{camera_spec, is_gltf_path, load_gltf_scene, CameraRequest};
use super::obj::{confined_path, load_obj};
use super::{LightSpec, Scene, SceneError};
use crate::camera::Camera;
use glam::{DMat3, DVec3, Vec3};
use std::collections::{BTreeSet, HashMap};
use std::path::PathBuf;

/// A triangle as every renderer sees it: three f32 vertices.
pub type Tri = [Vec3; 3];

/// Per-object bookkeeping that maps ID ranges back to the scene file.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ObjectInfo {
    /// Name from the scene file (untrusted text); for an OBJ with several
    /// `o`/`g` groups, `<scene object name>/<group name>`, one object per group;
    /// for a glTF file, `<scene object name>/<node label>`, one per mesh node.
    pub name: String,
    /// Index into `materials`.
    pub material: u32,
    /// First `prim_id` of this object.
    pub first_prim: u32,
    /// Number of triangles.
    pub prim_count: u32,
    /// For a part of a mesh file: which file and part, and the scene object's
    /// transform, so that an independent decoder can read the same file and
    /// check these triangles (the harness's `import` verdict); absent for shapes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mesh: Option<MeshSource>,
}

/// Where a mesh-file object's triangles came from (docs/resolved-scene.md,
/// `objects[].mesh`): the import is checked against a second decoder, not trusted.
#[derive(Debug, Clone, serde::Serialize)]
pub struct MeshSource {
    /// The mesh file as resolution opened it (confined to the scene's folder).
    pub file: PathBuf,
    /// `"gltf"` or `"obj"`: the loader that read it.
    pub format: &'static str,
    /// This object's index among the file's parts: glTF mesh nodes in
    /// traversal order, OBJ groups in file order (0 for a one-group OBJ).
    pub part: u32,
    /// For a glTF file, the index of the glTF scene shown (`gltf_scene`, else
    /// the file's default): the decoder must read the same scene.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gltf_scene: Option<u32>,
    /// The scene object's transform as written, applied after the file's own.
    pub transform: super::Transform,
}

/// A resolved material (see docs/DESIGN.md: albedo and emission).
#[derive(Debug, Clone, serde::Serialize)]
pub struct Material {
    /// Name from the scene file (untrusted text).
    pub name: String,
    /// Diffuse reflectance per channel.
    pub albedo: [f64; 3],
    /// Emitted radiance per channel.
    pub emission: [f64; 3],
}

/// The scene after resolution: what renderers consume.
#[derive(Debug, Clone)]
pub struct ResolvedScene {
    /// Display name (untrusted text).
    pub name: String,
    /// The scene file it came from.
    pub source: PathBuf,
    /// Features the scene requires.
    pub requires: BTreeSet<String>,
    /// The camera, with its basis and near/far resolved.
    pub camera: Camera,
    /// All triangles; index = `prim_id`.
    pub triangles: Vec<Tri>,
    /// `object_id` of each triangle.
    pub object_ids: Vec<u32>,
    /// True for exactly zero-area triangles, which are never visible.
    pub degenerate: Vec<bool>,
    /// Objects in ID order.
    pub objects: Vec<ObjectInfo>,
    /// Materials (a default grey is added when the scene has none).
    pub materials: Vec<Material>,
    /// Lights, as written.
    pub lights: Vec<LightSpec>,
    /// Monte Carlo settings.
    pub integrator: super::IntegratorSpec,
    /// What resolution left out of a mesh file and why (a glTF POINTS or
    /// LINES primitive), one line each naming the file, field and part:
    /// the tool prints them, the core never does.
    pub warnings: Vec<String>,
}

/// Exact test for a zero-area triangle: all three coordinate-plane projections
/// have zero signed area (Shewchuk's exact orient2d), so no float tolerance is involved.
pub fn is_degenerate(t: &Tri) -> bool {
    let proj = |i: usize, j: usize| {
        let c = |v: Vec3| robust::Coord {
            x: f64::from(v[i]),
            y: f64::from(v[j]),
        };
        robust::orient2d(c(t[0]), c(t[1]), c(t[2])) == 0.0
    };
    proj(0, 1) && proj(1, 2) && proj(2, 0)
}

/// Each material name's index, the first when names repeat (validation
/// refuses repeats; a name not here means material 0, as for an object
/// without one). One lookup per object: searching the list for each object
/// hung on 300,000 materials and objects.
fn material_indices(materials: &[Material]) -> HashMap<&str, u32> {
    let mut index = HashMap::with_capacity(materials.len());
    for (i, m) in materials.iter().enumerate() {
        index.entry(m.name.as_str()).or_insert(i as u32);
    }
    index
}

fn transform_matrix(t: &super::Transform) -> (DMat3, DVec3) {
    let [rx, ry, rz] = t.rotate.map(f64::to_radians);
    let rot = DMat3::from_rotation_z(rz) * DMat3::from_rotation_y(ry) * DMat3::from_rotation_x(rx);
    (
        rot * DMat3::from_diagonal(DVec3::from(t.scale)),
        DVec3::from(t.translate),
    )
}

impl ResolvedScene {
    /// The scene with its camera at another resolution (same eye, field of
    /// view, near and far): benchmarks and tests render one scene at many sizes.
    pub fn resized(&self, w: u32, h: u32) -> Result<ResolvedScene, String> {
        let mut s = self.clone();
        let c = &self.camera;
        s.camera =
            crate::camera::Camera::new(c.eye, c.look_at, c.up, c.vfov_deg, w, h, c.near, c.far)?;
        s.camera.precision = c.precision;
        Ok(s)
    }

    /// Resolves a validated scene: loads meshes, runs generators, applies transforms,
    /// rounds to f32, assigns IDs and builds the camera.
    pub fn resolve(scene: &Scene) -> Result<ResolvedScene, SceneError> {
        let path = &scene.path;
        let mut materials: Vec<Material> = scene
            .file
            .materials
            .iter()
            .map(|m| Material {
                name: m.name.clone(),
                albedo: m.albedo,
                emission: m.emission,
            })
            .collect();
        if materials.is_empty() {
            materials.push(Material {
                name: "default".into(),
                albedo: [0.8, 0.8, 0.8],
                emission: [0.0; 3],
            });
        }
        // Every OBJ mesh is read and counted first, against what the shapes leave
        // of the scene's triangle budget (validation refused shapes beyond it), so
        // a scene over budget is refused before any shape is generated.
        let mut budget =
            super::MAX_SCENE_TRIANGLES.saturating_sub(super::shape_triangles(&scene.file));
        let mut meshes = Vec::with_capacity(scene.file.objects.len());
        let mut gltf_camera = None;
        let mut warnings = Vec::new();
        for (si, o) in scene.file.objects.iter().enumerate() {
            meshes.push(match &o.mesh {
                Some(rel) if is_gltf_path(rel) => {
                    let mesh_field = format!("objects[{si}].mesh");
                    let full = confined_path(path, &scene.dir, rel, &mesh_field)?;
                    let request = match &scene.file.camera.gltf {
                        Some(g) if g.object == o.name => CameraRequest::of(g.camera.as_ref()),
                        _ => CameraRequest::None,
                    };
                    let file = load_gltf_scene(
                        &full,
                        &scene.dir,
                        &mesh_field,
                        budget,
                        o.gltf_scene.as_ref(),
                        request,
                    )?;
                    warnings.extend(
                        file.warnings
                            .iter()
                            .map(|w| SceneError::new(&full, &mesh_field, w.as_str()).to_string()),
                    );
                    let n: usize = file.nodes.iter().map(|g| g.triangles.len()).sum();
                    budget = budget.saturating_sub(n as u64);
                    if let Some(c) = file.camera {
                        gltf_camera = Some((c, si, full.clone()));
                    }
                    // One rendiff object per mesh node, always under
                    // `<object>/<node label>` (docs/resolved-scene.md).
                    let parts = file
                        .nodes
                        .into_iter()
                        .map(|n| (format!("{}/{}", o.name, n.label), n.triangles))
                        .collect();
                    Some((parts, full, Some(file.scene as u32)))
                }
                Some(rel) => {
                    let mesh_field = format!("objects[{si}].mesh");
                    let full = confined_path(path, &scene.dir, rel, &mesh_field)?;
                    let groups = load_obj(&full, &mesh_field, budget)?;
                    let n: usize = groups.iter().map(|g| g.triangles.len()).sum();
                    budget = budget.saturating_sub(n as u64);
                    // One rendiff object per OBJ `o`/`g` group (file order); a
                    // single-group OBJ stays one object under the scene's name.
                    let parts: Vec<(String, Vec<Tri64>)> = if groups.len() == 1 {
                        let g = groups.into_iter().next().expect("one group");
                        vec![(o.name.clone(), g.triangles)]
                    } else {
                        groups
                            .into_iter()
                            .map(|g| (format!("{}/{}", o.name, g.name), g.triangles))
                            .collect()
                    };
                    Some((parts, full, None))
                }
                None => None,
            });
        }
        let total = super::MAX_SCENE_TRIANGLES - budget;
        let total = usize::try_from(total).unwrap_or(usize::MAX);
        // (On huge pages where the OS has them: the raster's bins name
        // triangles all over the array, `crate::huge_pages`.)
        let mut triangles: Vec<Tri> = crate::huge_pages::with_capacity(total);
        let mut object_ids = Vec::with_capacity(total);
        let mut degenerate = Vec::with_capacity(total);
        let mut objects = Vec::new();
        let material_index = material_indices(&materials);
        for ((si, o), mesh) in scene.file.objects.iter().enumerate().zip(meshes) {
            let field = format!("objects[{si}]");
            // A mesh file's parts (OBJ groups, glTF mesh nodes) were named when
            // it was read; a generator is one object under the scene's name.
            let from_file = mesh.is_some();
            let (parts, origin, gltf_scene): (Vec<(String, Vec<Tri64>)>, PathBuf, _) =
                match (mesh, &o.shape) {
                    (Some((parts, full, gltf_scene)), _) => (parts, full, gltf_scene),
                    (None, Some(shape)) => (
                        vec![(o.name.clone(), shape.triangles())],
                        path.clone(),
                        None,
                    ),
                    (None, None) => unreachable!("validated: mesh or shape"),
                };
            let material = match &o.material {
                Some(m) => material_index.get(m.as_str()).copied().unwrap_or(0),
                None => 0,
            };
            let (m, tr) = transform_matrix(&o.transform);
            // Triangle index within the scene object (file order across groups), for messages.
            let mut ti = 0usize;
            for (part, (name, tris64)) in parts.into_iter().enumerate() {
                let oi = objects.len();
                if oi >= u32::MAX as usize {
                    return Err(SceneError::new(path, "objects", "more than 2^32-1 objects"));
                }
                let first = triangles.len();
                for t in &tris64 {
                    let w = t.map(|v| (m * v + tr).as_vec3());
                    if w.iter().any(|v| !v.is_finite()) {
                        return Err(SceneError::new(
                            &origin,
                            &field,
                            format!("triangle {ti} is not finite after the transform (overflow to Inf or NaN)"),
                        ));
                    }
                    let deg = is_degenerate(&w);
                    if deg && !o.allow_degenerate {
                        return Err(SceneError::new(
                            &origin,
                            &field,
                            format!(
                                "triangle {ti} has zero area after rounding to f32; \
                                 set `allow_degenerate = true` on the object if this is intended"
                            ),
                        ));
                    }
                    triangles.push(w);
                    degenerate.push(deg);
                    object_ids.push(oi as u32);
                    ti += 1;
                }
                if triangles.len() >= u32::MAX as usize {
                    return Err(SceneError::new(
                        path,
                        "objects",
                        "more than 2^32-2 triangles",
                    ));
                }
                objects.push(ObjectInfo {
                    name,
                    material,
                    first_prim: first as u32,
                    prim_count: (triangles.len() - first) as u32,
                    mesh: from_file.then(|| MeshSource {
                        file: origin.clone(),
                        format: if o.mesh.as_deref().is_some_and(is_gltf_path) {
                            "gltf"
                        } else {
                            "obj"
                        },
                        part: part as u32,
                        gltf_scene,
                        transform: o.transform.clone(),
                    }),
                });
            }
        }
        let spec = match gltf_camera {
            // The glTF camera, placed by its object's transform like the
            // object's triangles, then checked like a pose written in the TOML.
            Some((c, si, file)) => {
                let (m, tr) = transform_matrix(&scene.file.objects[si].transform);
                let spec = camera_spec(&c, m, tr, &scene.file.camera)
                    .map_err(|p| SceneError::new(&file, "camera.gltf", p))?;
                super::validate_pose(&file, &spec).map_err(|e| {
                    SceneError::new(
                        &file,
                        "camera.gltf",
                        format!(
                            "the glTF camera maps to an invalid {}: {}",
                            e.field, e.problem
                        ),
                    )
                })?;
                spec
            }
            None => scene.file.camera.clone(),
        };
        let camera = Camera::from_spec(&spec, scene_size(&triangles))
            .map_err(|(field, problem)| SceneError::new(path, field, problem))?;
        Ok(ResolvedScene {
            name: scene.name.clone(),
            source: path.clone(),
            requires: scene.requires.clone(),
            camera,
            triangles,
            object_ids,
            degenerate,
            objects,
            materials,
            lights: scene.file.lights.clone(),
            integrator: scene.file.integrator,
            warnings,
        })
    }

    /// Builds a scene directly from triangles (tests and generated scene families).
    pub fn from_triangles(camera: Camera, triangles: Vec<Tri>) -> ResolvedScene {
        let n = triangles.len();
        let degenerate = triangles.iter().map(is_degenerate).collect();
        ResolvedScene {
            name: "generated".into(),
            source: PathBuf::from("<generated>"),
            requires: ["depth", "ids"].iter().map(|s| s.to_string()).collect(),
            camera,
            triangles,
            object_ids: vec![0; n],
            degenerate,
            objects: vec![ObjectInfo {
                name: "generated".into(),
                material: 0,
                first_prim: 0,
                prim_count: n as u32,
                mesh: None,
            }],
            materials: vec![Material {
                name: "default".into(),
                albedo: [0.8; 3],
                emission: [0.0; 3],
            }],
            lights: vec![],
            integrator: super::IntegratorSpec::default(),
            warnings: vec![],
        }
    }
}

/// Diagonal of the triangles' bounding box: the "scene size" that scales the default near plane.
pub fn scene_size(tris: &[Tri]) -> f64 {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for t in tris {
        for v in t {
            lo = lo.min(v.as_dvec3());
            hi = hi.max(v.as_dvec3());
        }
    }
    if tris.is_empty() {
        0.0
    } else {
        (hi - lo).length()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn resolve_with_obj(tag: &str, obj: &str) -> ResolvedScene {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join(tag);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("m.obj"), obj).unwrap();
        let scene = dir.join("s.toml");
        let text = format!(
            r#"{HEADER}[[objects]]
name = "gen"
shape = {{ kind = "three_triangles" }}
[[objects]]
name = "file"
mesh = "m.obj"
[[objects]]
name = "after"
shape = {{ kind = "three_triangles" }}
"#
        );
        std::fs::write(&scene, text).unwrap();
        ResolvedScene::resolve(&super::super::Scene::load(&scene).unwrap()).unwrap()
    }

    fn summary(r: &ResolvedScene) -> Vec<(String, u32, u32)> {
        r.objects
            .iter()
            .map(|o| (o.name.clone(), o.first_prim, o.prim_count))
            .collect()
    }

    #[test]
    fn obj_groups_become_objects() {
        let r = resolve_with_obj(
            "groups",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 2 0 0\n\
             o first\nf 1 2 3\n\
             g second\nf 2 4 3\nf 2 5 4 3\n",
        );
        let s = |n: &str, a, b| (n.to_string(), a, b);
        assert_eq!(
            summary(&r),
            vec![
                s("gen", 0, 3),
                s("file/first", 3, 1),
                s("file/second", 4, 3),
                s("after", 7, 3)
            ]
        );
        let ids: Vec<u32> = r.object_ids.clone();
        assert_eq!(ids, vec![0, 0, 0, 1, 2, 2, 2, 3, 3, 3]);
        // prim order is object order, then file order.
        assert_eq!(r.triangles[3][1], Vec3::new(1.0, 0.0, 0.0));
        assert_eq!(r.triangles[4][1], Vec3::new(1.0, 1.0, 0.0));
        assert_eq!(r.triangles[5][1], Vec3::new(2.0, 0.0, 0.0));
    }

    #[test]
    fn single_group_obj_is_one_object_under_the_scene_name() {
        for (tag, obj) in [
            (
                "nogroup",
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n",
            ),
            (
                "onegroup",
                "o only\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n",
            ),
        ] {
            let r = resolve_with_obj(tag, obj);
            let s = |n: &str, a, b| (n.to_string(), a, b);
            assert_eq!(
                summary(&r),
                vec![s("gen", 0, 3), s("file", 3, 2), s("after", 5, 3)],
                "{tag}"
            );
            assert_eq!(r.object_ids, vec![0, 0, 0, 1, 1, 2, 2, 2], "{tag}");
        }
    }

    /// Writes `files` and the scene text into a fresh folder and resolves it.
    fn resolve_files(files: &[(&str, &[u8])], toml: &str) -> Result<ResolvedScene, SceneError> {
        let dir = tempfile::tempdir().unwrap();
        for (name, bytes) in files {
            std::fs::write(dir.path().join(name), bytes).unwrap();
        }
        let scene = dir.path().join("s.toml");
        std::fs::write(&scene, toml).unwrap();
        ResolvedScene::resolve(&super::super::Scene::load(&scene)?)
    }

    /// A glTF (JSON + .bin) with one node holding the given triangles
    /// (non-indexed), named `node`, under `matrix` (column-major) if given.
    fn gltf_of(tris: &[[[f32; 3]; 3]], matrix: Option<[f64; 16]>) -> (String, Vec<u8>) {
        let bin: Vec<u8> = tris
            .iter()
            .flatten()
            .flatten()
            .flat_map(|c| c.to_le_bytes())
            .collect();
        let all = || tris.iter().flatten();
        let min: Vec<f32> = (0..3)
            .map(|k| all().map(|v| v[k]).fold(f32::MAX, f32::min))
            .collect();
        let max: Vec<f32> = (0..3)
            .map(|k| all().map(|v| v[k]).fold(f32::MIN, f32::max))
            .collect();
        let matrix = matrix.map_or(String::new(), |m| format!(r#", "matrix": {m:?}"#));
        let json = format!(
            r#"{{"asset": {{"version": "2.0"}}, "scenes": [{{"nodes": [0]}}],
               "nodes": [{{"mesh": 0, "name": "node"{matrix}}}],
               "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}}}]}}],
               "buffers": [{{"uri": "m.bin", "byteLength": {n}}}],
               "bufferViews": [{{"buffer": 0, "byteLength": {n}}}],
               "accessors": [{{"bufferView": 0, "componentType": 5126, "count": {c},
                               "type": "VEC3", "min": {min:?}, "max": {max:?}}}]}}"#,
            n = bin.len(),
            c = tris.len() * 3,
        );
        (json, bin)
    }

    const HEADER: &str = r#"
requires = ["depth", "ids"]
[camera]
eye = [0.0, 0.0, 5.0]
look_at = [0.0, 0.0, 0.0]
vfov = 45.0
width = 8
height = 6
"#;

    #[test]
    fn obj_and_gltf_of_the_same_triangles_resolve_bit_identically() {
        // Values that are not short decimals, a negative zero, and an object
        // transform that rotates, scales and translates: both paths must give
        // the same f32 bits.
        let tris: Vec<[[f32; 3]; 3]> = vec![
            [[0.1, -0.0, 0.3], [1.7, 0.2, -0.45], [0.3, 1.1, 0.77]],
            [
                [-2.5e-3, 3.25, 1e-7],
                [1.0 / 3.0, 2.0, 0.5],
                [0.9, -1.3, 2.2],
            ],
        ];
        let obj: String = tris
            .iter()
            .flatten()
            .map(|v| format!("v {:?} {:?} {:?}\n", v[0], v[1], v[2]))
            .chain(["f 1 2 3\nf 4 5 6\n".to_string()])
            .collect();
        let (json, bin) = gltf_of(&tris, None);
        let object = |mesh: &str| {
            format!(
                "{HEADER}[[objects]]\nname = \"m\"\nmesh = \"{mesh}\"\n\
                 transform = {{ scale = [1.5, 0.7, 2.0], rotate = [10.0, 33.0, -71.0], translate = [0.25, -3.0, 1e3] }}\n"
            )
        };
        let a = resolve_files(&[("m.obj", obj.as_bytes())], &object("m.obj")).unwrap();
        let b = resolve_files(
            &[("m.gltf", json.as_bytes()), ("m.bin", &bin)],
            &object("m.gltf"),
        )
        .unwrap();
        let bits = |r: &ResolvedScene| -> Vec<u32> {
            r.triangles
                .iter()
                .flatten()
                .flat_map(|v| v.to_array().map(f32::to_bits))
                .collect()
        };
        assert_eq!(bits(&a), bits(&b));
        assert_eq!(a.objects[0].name, "m");
        assert_eq!(b.objects[0].name, "m/node");
    }

    #[test]
    fn gltf_nodes_become_objects_and_zero_area_is_refused_as_for_obj() {
        let tri = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let (json, bin) = gltf_of(
            &[tri, tri],
            Some([
                1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 2.0, 0.0, 0.0, 1.0,
            ]),
        );
        let files: [(&str, &[u8]); 2] = [("m.gltf", json.as_bytes()), ("m.bin", &bin)];
        let text = format!(
            "{HEADER}[[objects]]\nname = \"gen\"\nshape = {{ kind = \"three_triangles\" }}\n\
             [[objects]]\nname = \"model\"\nmesh = \"m.gltf\"\n"
        );
        let r = resolve_files(&files, &text).unwrap();
        let s = |n: &str, a, b| (n.to_string(), a, b);
        assert_eq!(summary(&r), vec![s("gen", 0, 3), s("model/node", 3, 2)]);
        assert_eq!(r.triangles[3][1], Vec3::new(3.0, 0.0, 0.0));

        let flat = [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]];
        let (json, bin) = gltf_of(&[tri, flat], None);
        let files: [(&str, &[u8]); 2] = [("m.gltf", json.as_bytes()), ("m.bin", &bin)];
        let e = resolve_files(&files, &text).unwrap_err().to_string();
        assert!(
            e.contains("m.gltf: objects[1]: triangle 1 has zero area"),
            "{e}"
        );
        let ok = text.replace(
            "mesh = \"m.gltf\"",
            "mesh = \"m.gltf\"\nallow_degenerate = true",
        );
        let r = resolve_files(&files, &ok).unwrap();
        assert_eq!(r.degenerate, vec![false, false, false, false, true]);
    }

    #[test]
    fn the_scene_camera_can_come_from_the_gltf_file() {
        let tri = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let (json, bin) = gltf_of(&[tri], None);
        let json = json.replacen(
            r#""nodes": [{"#,
            r#""cameras": [{"type": "perspective", "perspective": {"yfov": 0.7, "znear": 0.01, "aspectRatio": 1.0}}],
               "nodes": [{"camera": 0, "translation": [0.5, 0.5, 3]}, {"#,
            1,
        )
        // Node 0 is now the camera, node 1 the mesh: both are roots.
        .replace(r#""scenes": [{"nodes": [0]}]"#, r#""scenes": [{"nodes": [0, 1]}]"#);
        let files: [(&str, &[u8]); 2] = [("m.gltf", json.as_bytes()), ("m.bin", &bin)];
        let text = |size: &str| {
            format!(
                "requires = [\"depth\", \"ids\"]\n[camera]\n{size}\ngltf = {{ object = \"model\" }}\n\
                 [[objects]]\nname = \"model\"\nmesh = \"m.gltf\"\n\
                 transform = {{ translate = [0.0, 0.0, -1.0] }}\n"
            )
        };
        let r = resolve_files(&files, &text("width = 16\nheight = 16")).unwrap();
        let c = &r.camera;
        assert_eq!(c.eye, DVec3::new(0.5, 0.5, 2.0));
        assert_eq!(c.forward, DVec3::NEG_Z);
        assert_eq!(c.vfov_deg, f64::from(0.7f32).to_degrees());
        assert_eq!(c.near, f64::from(0.01f32));
        assert_eq!(c.far, f64::INFINITY);
        assert_eq!(r.objects[0].name, "model/node");
        let e = resolve_files(&files, &text("width = 16\nheight = 9"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("m.gltf: camera.gltf: camera 0 (node 0) has aspectRatio 1"),
            "{e}"
        );
        let both = text("width = 16\nheight = 16\nvfov = 40.0");
        let e = resolve_files(&files, &both).unwrap_err().to_string();
        assert!(e.contains("camera.gltf: give either"), "{e}");
        let e = resolve_files(
            &files,
            &text("width = 16\nheight = 16").replace("object = \"model\"", "object = \"x\""),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("camera.gltf.object: no object named \"x\""),
            "{e}"
        );
    }

    #[test]
    fn the_toml_chooses_the_gltf_scene_and_camera_and_warnings_name_the_file() {
        let tri = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let (json, bin) = gltf_of(&[tri], None);
        // Scene 0 (the default) holds the mesh node and camera 0; scene 1
        // ("far") the camera node of camera 1 and the mesh node again, whose
        // mesh also has a LINES primitive.
        let json = json
            .replacen(
                r#""nodes": [{"#,
                r#""cameras": [{"type": "perspective", "perspective": {"yfov": 0.7, "znear": 0.01}},
                               {"type": "perspective", "perspective": {"yfov": 0.5, "znear": 0.01}}],
                   "nodes": [{"camera": 0, "translation": [0, 0, 3]},
                             {"camera": 1, "translation": [0, 0, 9]}, {"#,
                1,
            )
            .replace(
                r#""scenes": [{"nodes": [0]}]"#,
                r#""scenes": [{"nodes": [0, 2]}, {"nodes": [1, 2], "name": "far"}]"#,
            )
            .replacen(
                r#""attributes": {"POSITION": 0}"#,
                r#""attributes": {"POSITION": 0}}, {"attributes": {"POSITION": 0}, "mode": 1"#,
                1,
            );
        let files: [(&str, &[u8]); 2] = [("m.gltf", json.as_bytes()), ("m.bin", &bin)];
        let text = |scene: &str, camera: &str| {
            format!(
                "requires = [\"depth\", \"ids\"]\n[camera]\nwidth = 8\nheight = 8\n\
                 gltf = {{ object = \"model\"{camera} }}\n\
                 [[objects]]\nname = \"model\"\nmesh = \"m.gltf\"\n{scene}"
            )
        };
        let r = resolve_files(&files, &text("", "")).unwrap();
        assert_eq!(r.camera.eye, DVec3::new(0.0, 0.0, 3.0));
        assert_eq!(r.warnings.len(), 1, "{:?}", r.warnings);
        let w = &r.warnings[0];
        assert!(
            w.contains("m.gltf: objects[0].mesh: mesh 0 primitive 1 has mode LINES: skipped"),
            "{w}"
        );
        for scene in ["gltf_scene = 1\n", "gltf_scene = \"far\"\n"] {
            for camera in [", camera = 1", ""] {
                let r = resolve_files(&files, &text(scene, camera)).unwrap();
                assert_eq!(r.camera.eye, DVec3::new(0.0, 0.0, 9.0), "{scene} {camera}");
            }
            let e = resolve_files(&files, &text(scene, ", camera = 0")).unwrap_err();
            assert!(
                e.to_string().contains("camera 0 is placed by no node"),
                "{e}"
            );
        }
        let obj: [(&str, &[u8]); 1] = [("m.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")];
        let e = resolve_files(
            &obj,
            "requires = [\"depth\"]\n[camera]\neye = [0, 0, 3]\nlook_at = [0, 0, 0]\nvfov = 40\n\
             width = 8\nheight = 8\n[[objects]]\nname = \"o\"\nmesh = \"m.obj\"\ngltf_scene = 0\n",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("objects[0].gltf_scene: chooses a glTF scene"),
            "{e}"
        );
    }

    #[test]
    fn degenerate_detection_is_exact() {
        let v = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
        assert!(is_degenerate(&[
            v(0., 0., 0.),
            v(1., 1., 1.),
            v(2., 2., 2.)
        ]));
        assert!(is_degenerate(&[
            v(1., 2., 3.),
            v(1., 2., 3.),
            v(4., 5., 6.)
        ]));
        // A sliver: collinear but for one ulp.
        let y = f32::from_bits(2f32.to_bits() + 1);
        assert!(!is_degenerate(&[
            v(0., 0., 0.),
            v(1., 1., 0.),
            v(2., y, 0.)
        ]));
    }

    #[test]
    fn materials_are_found_by_name_in_linear_time() {
        // Searching the list for each object took 5.4 s for 60,000 materials
        // and objects (and hung on 300,000): at 150,000 over 30 s, against
        // about 0.2 s now. The bound below is a hang guard, not a speed claim.
        let n = 150_000;
        let text = format!(
            "{HEADER}[[materials]]\nname = \"m\"\n\
             [[objects]]\nname = \"o\"\nmaterial = \"m\"\n\
             shape = {{ kind = \"triangles\", vertices = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] }}\n"
        );
        let mut scene = super::super::Scene::parse(Path::new("s.toml"), &text).unwrap();
        let (material, object) = (
            scene.file.materials[0].clone(),
            scene.file.objects[0].clone(),
        );
        scene.file.materials = (0..n)
            .map(|i| super::super::MaterialSpec {
                name: format!("m{i}"),
                ..material.clone()
            })
            .collect();
        // Validation refuses both, but resolution keeps its rule: the first
        // of two equal names, material 0 for an unknown one.
        scene.file.materials.push(super::super::MaterialSpec {
            name: "m7".into(),
            ..material
        });
        let named = |m: String| super::super::ObjectSpec {
            material: Some(m),
            ..object.clone()
        };
        scene.file.objects = (0..n).rev().map(|i| named(format!("m{i}"))).collect();
        scene.file.objects.push(named("nope".into()));
        let start = std::time::Instant::now();
        let r = ResolvedScene::resolve(&scene).unwrap();
        let took = start.elapsed();
        let got: Vec<u32> = r.objects.iter().map(|o| o.material).collect();
        let want: Vec<u32> = (0..n as u32).rev().chain([0]).collect();
        assert_eq!(got, want);
        assert_eq!(r.objects[n - 1 - 7].material, 7);
        assert!(took < std::time::Duration::from_secs(5), "took {took:?}");
    }

    #[test]
    fn an_empty_or_folder_mesh_path_names_the_scene_file_and_field() {
        // The error named the folder the path resolved to, not the scene.
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("sub.obj")).unwrap();
        let scene = dir.path().join("s.toml");
        for (mesh, problem) in [
            ("", "mesh path is empty".to_string()),
            (".", "mesh path \".\" is a folder, not a file".into()),
            (
                "sub.obj",
                "mesh path \"sub.obj\" is a folder, not a file".into(),
            ),
            (
                "sub.obj/.",
                "mesh path \"sub.obj/.\" is a folder, not a file".into(),
            ),
        ] {
            let text = format!(
                "{HEADER}[[objects]]\nname = \"gen\"\nshape = {{ kind = \"three_triangles\" }}\n\
                 [[objects]]\nname = \"m\"\nmesh = \"{mesh}\"\n"
            );
            std::fs::write(&scene, text).unwrap();
            let e = ResolvedScene::resolve(&super::super::Scene::load(&scene).unwrap())
                .unwrap_err()
                .to_string();
            let want = format!("{}: objects[1].mesh: {problem}", scene.display());
            assert!(e.starts_with(&want), "{mesh:?}: {e}");
        }
    }
}
