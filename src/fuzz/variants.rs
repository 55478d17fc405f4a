//! The fuzzer's second source (`rendiff fuzz --from SCENE...`): metamorphic
//! variants of real scenes (the corpus, or your own), each judged by the
//! verifier against the core's reference like any scene, and reported when
//! its verdict class differs from its base's on the same backend and buffer
//! (docs/fuzzing.md, "Variants of your scenes").
//!
//! The relations are those of docs/metamorphic.md, applied to any scene's
//! standalone rewrite (`literal.rs`) instead of the one constructed scene of
//! tests/metamorphic_backends.rs: there the variant is compared with the same
//! backend's base render, bound by bound; here each variant only has to get
//! the same verdict class as its base, so no ID map or depth scale is needed
//! and any scene will do. Where a relation is exact in f32 (rotation by a
//! quarter turn, mirror, permutation, winding, duplication) the variant is
//! the same picture up to the transform; translation rounds every coordinate
//! at the offset's magnitude, which is the point (scenes far from the origin).

use super::literal::{LiteralObject, LiteralScene};
use crate::scene::LightSpec;
use anyhow::{bail, Result};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The relations, in the order the variants are written.
pub const RELATIONS: [&str; 6] = [
    "translate",
    "rotate",
    "mirror",
    "permute",
    "flip_winding",
    "duplicate",
];

/// The translation's offset is the smallest power of two at least this many
/// times the scene's largest coordinate (the eye included): every coordinate
/// then rounds at 2^8 times its own f32 step, 8 bits of each vertex lost to
/// the offset, as a scene built far from the origin would be.
pub const TRANSLATE_FACTOR: f64 = 256.0;

/// Name of the base of source `i` (its file stem, cleaned, after `m<i>_`).
pub fn base_name(i: usize, source: &Path) -> String {
    let stem = source
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let clean: String = stem
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .take(40)
        .collect();
    format!("m{i}_{clean}")
}

/// Name of a variant of `base`.
pub fn variant_name(base: &str, relation: &str) -> String {
    format!("{base}__{relation}")
}

/// A permutation of 0..n, fixed by `seed` (xorshift Fisher-Yates): the
/// `permute` relation's order here and in tests/metamorphic_backends.rs.
pub fn permutation(n: usize, seed: u64) -> Vec<usize> {
    let mut order: Vec<usize> = (0..n).collect();
    let mut s = seed | 1;
    for i in (1..n).rev() {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        order.swap(i, (s % (i as u64 + 1)) as usize);
    }
    order
}

/// The scene under `f`, a linear map (rotate, mirror) or a translation
/// (translate): vertices, the camera's eye and look-at, point lights'
/// positions, and directional lights' directions (through a linear `f`; a
/// translation leaves them as they are, exactly), so the lighting moves
/// with the geometry.
fn map_points(s: &LiteralScene, f: impl Fn([f64; 3]) -> [f64; 3]) -> LiteralScene {
    let mut out = s.clone();
    out.camera.eye = f(s.camera.eye);
    out.camera.look_at = f(s.camera.look_at);
    for o in &mut out.objects {
        for t in &mut o.triangles {
            *t = t.map(&f);
        }
    }
    let linear = f([0.0; 3]) == [0.0; 3];
    for l in &mut out.lights {
        match l {
            LightSpec::Point { position, .. } => *position = f(*position),
            LightSpec::Directional { direction, .. } if linear => *direction = f(*direction),
            LightSpec::Directional { .. } => {}
        }
    }
    out
}

/// The variant of `base` under `relation`.
pub fn variant(base: &LiteralScene, relation: &str) -> Result<LiteralScene> {
    let mut v = match relation {
        "translate" => {
            let largest = base
                .objects
                .iter()
                .flat_map(|o| o.triangles.iter().flatten().flatten())
                .chain(base.camera.eye.iter())
                .chain(base.camera.look_at.iter())
                .fold(0.0f64, |m, x| m.max(x.abs()));
            let exp = (TRANSLATE_FACTOR * largest.max(1.0)).log2().ceil() as i32;
            let off = 2f64.powi(exp);
            map_points(base, |p| [p[0] + off, p[1] - off, p[2] + off])
        }
        // A quarter turn about y through the origin: (x, y, z) -> (z, y, -x), exact.
        "rotate" => {
            let r = |p: [f64; 3]| [p[2], p[1], -p[0]];
            let mut v = map_points(base, r);
            v.camera.up = r(base.camera.up);
            v
        }
        // x -> -x for the scene and the camera: the image mirrors left to right.
        "mirror" => {
            let m = |p: [f64; 3]| [-p[0], p[1], p[2]];
            let mut v = map_points(base, m);
            v.camera.up = m(base.camera.up);
            v
        }
        "permute" => {
            let mut v = base.clone();
            v.objects.reverse();
            for (i, o) in v.objects.iter_mut().enumerate() {
                let order = permutation(o.triangles.len(), 0x9e37_79b9_7f4a_7c15 ^ i as u64);
                o.triangles = order.iter().map(|&k| o.triangles[k]).collect();
            }
            v
        }
        "flip_winding" => {
            let mut v = base.clone();
            for o in &mut v.objects {
                for t in &mut o.triangles {
                    *t = [t[0], t[2], t[1]];
                }
            }
            v
        }
        // Every object followed by an exact copy of itself: ties everywhere.
        "duplicate" => {
            let mut v = base.clone();
            v.objects = base
                .objects
                .iter()
                .flat_map(|o| [o.clone(), o.clone()])
                .collect::<Vec<LiteralObject>>();
            v
        }
        other => bail!(
            "no relation {other:?} (relations: {})",
            RELATIONS.join(", ")
        ),
    };
    v.description = format!("rendiff fuzz --from: {relation} of the base scene");
    Ok(v)
}

/// What [`write`] produced.
#[derive(Debug, Default)]
pub struct Written {
    /// Every scene file (bases and variants).
    pub files: Vec<PathBuf>,
    /// Variant name -> its relation (the "family" findings count by).
    pub relation: BTreeMap<String, String>,
    /// Variant name -> its base's name.
    pub base: BTreeMap<String, String>,
    /// Variants not written, with the reason (e.g. a triangle that rounds
    /// to zero area once translated).
    pub skipped: Vec<String>,
}

/// Writes each source's standalone base and its variants into `dir`.
pub fn write(sources: &[PathBuf], dir: &Path) -> Result<Written> {
    std::fs::create_dir_all(dir)
        .map_err(|e| anyhow::anyhow!("{}: cannot create: {e}", dir.display()))?;
    let mut out = Written::default();
    for (i, src) in sources.iter().enumerate() {
        let base = super::standalone(src)?;
        let name = base_name(i, src);
        let mut base = base;
        base.description = format!("rendiff fuzz --from: the base scene {name}");
        let file = dir.join(format!("{name}.toml"));
        std::fs::write(&file, base.to_toml())
            .map_err(|e| anyhow::anyhow!("{}: cannot write: {e}", file.display()))?;
        out.files.push(file);
        for rel in RELATIONS {
            let v = variant(&base, rel)?;
            let vname = variant_name(&name, rel);
            let text = v.to_toml();
            let vfile = dir.join(format!("{vname}.toml"));
            // A variant must itself be a valid scene: resolve it before it is checked.
            let valid = crate::scene::Scene::parse(&vfile, &text)
                .map_err(anyhow::Error::from)
                .and_then(|s| {
                    crate::scene::resolve::ResolvedScene::resolve(&s).map_err(anyhow::Error::from)
                });
            if let Err(e) = valid {
                out.skipped.push(format!(
                    "{vname}: {}",
                    crate::scene::printable(&format!("{e:#}"), 300)
                ));
                continue;
            }
            std::fs::write(&vfile, text)
                .map_err(|e| anyhow::anyhow!("{}: cannot write: {e}", vfile.display()))?;
            out.files.push(vfile);
            out.relation.insert(vname.clone(), rel.to_string());
            out.base.insert(vname, name.clone());
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fuzz::literal::LiteralCamera;
    use crate::scene::resolve::ResolvedScene;
    use crate::scene::Scene;

    fn base() -> LiteralScene {
        LiteralScene {
            description: "base".into(),
            requires: vec!["depth".into(), "ids".into()],
            camera: LiteralCamera {
                eye: [0.5, 0.25, 4.0],
                look_at: [0.0, 0.0, 0.0],
                up: [0.0, 1.0, 0.0],
                vfov: 45.0,
                width: 24,
                height: 16,
                near: 1e-3,
                far: None,
            },
            objects: vec![
                LiteralObject::new(vec![
                    [[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]],
                    [[1.0, -1.0, 0.0], [2.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
                ]),
                LiteralObject::new(vec![[
                    [-1.0, 0.0, -1.0],
                    [1.0, 0.0, -1.0],
                    [0.0, 2.0, -1.0],
                ]]),
            ],
            materials: Vec::new(),
            lights: Vec::new(),
            integrator: None,
        }
    }

    fn resolve(s: &LiteralScene) -> ResolvedScene {
        let scene = Scene::parse(Path::new("v.toml"), &s.to_toml()).unwrap();
        ResolvedScene::resolve(&scene).unwrap()
    }

    /// The core's id buffer of a scene (the reference every variant is judged by).
    fn ids(s: &LiteralScene) -> Vec<u32> {
        let r = resolve(s);
        crate::raster::render(&r, Default::default(), &|_| {}).prim
    }

    #[test]
    fn exact_relations_give_the_same_picture_up_to_the_transform() {
        let b = base();
        let (w, h) = (b.camera.width as usize, b.camera.height as usize);
        let base_ids = ids(&b);
        let covered = base_ids
            .iter()
            .filter(|&&p| p != crate::frame::BACKGROUND_ID)
            .count();
        assert!(covered > 50, "the base shows its triangles ({covered} px)");
        // A quarter turn of scene and camera together: the same ids, pixel for pixel.
        assert_eq!(ids(&variant(&b, "rotate").unwrap()), base_ids);
        // Winding: the same ids (no culling in the contract).
        assert_eq!(ids(&variant(&b, "flip_winding").unwrap()), base_ids);
        // Mirror: the picture mirrors left to right.
        let m = ids(&variant(&b, "mirror").unwrap());
        for y in 0..h {
            for x in 0..w {
                assert_eq!(m[y * w + x], base_ids[y * w + (w - 1 - x)], "({x},{y})");
            }
        }
        // Permute and duplicate change prim ids but not what is covered.
        for rel in ["permute", "duplicate"] {
            let v = ids(&variant(&b, rel).unwrap());
            let hit: Vec<bool> = v
                .iter()
                .map(|&p| p != crate::frame::BACKGROUND_ID)
                .collect();
            let base_hit: Vec<bool> = base_ids
                .iter()
                .map(|&p| p != crate::frame::BACKGROUND_ID)
                .collect();
            assert_eq!(hit, base_hit, "{rel}");
        }
        let d = variant(&b, "duplicate").unwrap();
        assert_eq!(d.triangle_count(), 2 * b.triangle_count());
        // Translate: far from the origin (2^k >= 256 x the largest coordinate, 4 here: 1024).
        let t = variant(&b, "translate").unwrap();
        assert_eq!(t.camera.eye, [1024.5, -1023.75, 1028.0]);
        assert!(variant(&b, "stretch").is_err());
    }

    #[test]
    fn lights_move_with_the_geometry() {
        let mut b = base();
        b.lights = vec![
            LightSpec::Point {
                position: [1.0, 2.0, 3.0],
                intensity: [1.0; 3],
            },
            LightSpec::Directional {
                direction: [0.25, -1.0, -0.5],
                irradiance: [1.0; 3],
            },
        ];
        let lights = |rel: &str| variant(&b, rel).unwrap().lights;
        let both = |p: [f64; 3], d: [f64; 3]| {
            vec![
                LightSpec::Point {
                    position: p,
                    intensity: [1.0; 3],
                },
                LightSpec::Directional {
                    direction: d,
                    irradiance: [1.0; 3],
                },
            ]
        };
        // (x, y, z) -> (z, y, -x), as the vertices.
        assert_eq!(
            lights("rotate"),
            both([3.0, 2.0, -1.0], [-0.5, -1.0, -0.25])
        );
        assert_eq!(
            lights("mirror"),
            both([-1.0, 2.0, 3.0], [-0.25, -1.0, -0.5])
        );
        // A translation moves positions, never directions (exactly as written).
        let o = 1024.0;
        assert_eq!(
            lights("translate"),
            both([1.0 + o, 2.0 - o, 3.0 + o], [0.25, -1.0, -0.5])
        );
        assert_eq!(lights("permute"), b.lights);
    }

    #[test]
    fn sources_become_a_base_and_one_variant_per_relation() {
        let dir = tempfile::tempdir().unwrap();
        let src = dir.path().join("my scene.toml");
        std::fs::write(&src, base().to_toml()).unwrap();
        let out = dir.path().join("scenes");
        let w = write(std::slice::from_ref(&src), &out).unwrap();
        assert!(w.skipped.is_empty(), "{:?}", w.skipped);
        assert_eq!(w.files.len(), 1 + RELATIONS.len());
        assert_eq!(w.relation["m0_my_scene__mirror"], "mirror");
        assert_eq!(w.base["m0_my_scene__translate"], "m0_my_scene");
        for f in &w.files {
            let s = Scene::load(f).unwrap();
            ResolvedScene::resolve(&s).unwrap();
        }
    }
}
