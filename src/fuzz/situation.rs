//! The geometric situation of a finding's scene (its reduced scene when the
//! reduction succeeded): a few cheap tags saying what kind of geometry a
//! renderer got wrong, so that findings.json and the findings page say more
//! than "povray fails id", and a declared known finding (`known.rs`) can
//! name the situation its cause needs (POV-Ray's 1e7 limit needs `distant`
//! geometry, Mitsuba's zero normal a `huge` triangle).
//!
//! Every tag is a property of the resolved scene (f32 vertices, the camera),
//! computed in f64; thresholds are powers of two, stated with each tag and in
//! docs/fuzzing.md. A tag is a description, never a verdict: the verifier has
//! already judged the pixels.

use crate::scene::resolve::ResolvedScene;
use glam::DVec3;
use std::collections::{BTreeSet, HashMap};

/// Two triangles share an edge: two vertices equal bit for bit.
pub const SHARED_EDGE: &str = "shared_edge";
/// Two triangles lie in one plane, or nearly: every vertex of each within
/// [`COPLANAR_REL`] of its distance from the eye of the other's plane (the
/// situation of ties and near-ties).
pub const COPLANAR: &str = "coplanar";
/// A triangle crosses the near plane, or lies partly behind it.
pub const NEAR_PLANE: &str = "near_plane";
/// The eye is at least [`FAR_ORIGIN`] from the world origin (f32 steps of its
/// coordinates reach 2^-8).
pub const FAR_FROM_ORIGIN: &str = "far_from_origin";
/// A vertex is more than [`DISTANT`] units from the eye (absolute limits:
/// POV-Ray drops hits beyond 1e7).
pub const DISTANT_TAG: &str = "distant";
/// A triangle's longest edge exceeds [`HUGE_VIEWS`] view widths at its
/// centroid's planar depth (it reaches far off-screen).
pub const HUGE: &str = "huge";
/// A triangle whose height is under [`SLIVER`] of its longest edge.
pub const SLIVER_TAG: &str = "sliver";

/// Relative plane distance under which two triangles count as coplanar:
/// 2^-10 of the depth, wider than every near-coplanar gap the grammar draws
/// (2^-20 to 2^-6, the upper ones counted only when they are under it).
pub const COPLANAR_REL: f64 = 1.0 / 1024.0;
/// |eye| from which a scene is far from the origin: 2^16.
pub const FAR_ORIGIN: f64 = 65536.0;
/// Distance from the eye beyond which a vertex is distant: 2^20 (about 1e6).
pub const DISTANT: f64 = 1_048_576.0;
/// View widths beyond which a triangle is huge: 2^4.
pub const HUGE_VIEWS: f64 = 16.0;
/// Height over longest edge under which a triangle is a sliver: 2^-8.
pub const SLIVER: f64 = 1.0 / 256.0;
/// Pairwise tests (coplanar) are skipped above this many triangles: the
/// situation describes small (reduced) scenes; a large one is O(n^2).
pub const PAIRWISE_MAX: usize = 2000;

/// The tags of `scene`, sorted.
pub fn situations(scene: &ResolvedScene) -> Vec<String> {
    let cam = &scene.camera;
    let tris: Vec<[DVec3; 3]> = scene
        .triangles
        .iter()
        .zip(&scene.degenerate)
        .filter(|(_, d)| !**d)
        .map(|(t, _)| t.map(|v| v.as_dvec3()))
        .collect();
    let mut tags = BTreeSet::new();
    if cam.eye.length() >= FAR_ORIGIN {
        tags.insert(FAR_FROM_ORIGIN);
    }
    let aspect = f64::from(cam.width) / f64::from(cam.height.max(1));
    let depth = |v: DVec3| (v - cam.eye).dot(cam.forward);
    for t in &tris {
        let z = t.map(depth);
        let (lo, hi) = (z[0].min(z[1]).min(z[2]), z[0].max(z[1]).max(z[2]));
        if lo < cam.near && hi > cam.near || hi <= cam.near {
            tags.insert(NEAR_PLANE);
        }
        if t.iter().any(|v| (*v - cam.eye).length() > DISTANT) {
            tags.insert(DISTANT_TAG);
        }
        let edges = [t[1] - t[0], t[2] - t[1], t[0] - t[2]];
        let longest = edges.iter().map(|e| e.length()).fold(0.0, f64::max);
        let centroid = (z[0] + z[1] + z[2]) / 3.0;
        let view = 2.0 * centroid * cam.tan_half_vfov * aspect;
        if centroid > 0.0 && longest > HUGE_VIEWS * view {
            tags.insert(HUGE);
        }
        let doubled_area = edges[0].cross(-edges[2]).length();
        if longest > 0.0 && doubled_area / (longest * longest) < SLIVER {
            tags.insert(SLIVER_TAG);
        }
    }
    if shares_an_edge(scene) {
        tags.insert(SHARED_EDGE);
    }
    if tris.len() <= PAIRWISE_MAX && any_coplanar(&tris, cam.eye) {
        tags.insert(COPLANAR);
    }
    tags.into_iter().map(String::from).collect()
}

/// Two non-degenerate triangles with two vertices in common (bit for bit).
fn shares_an_edge(scene: &ResolvedScene) -> bool {
    let key = |v: glam::Vec3| v.to_array().map(f32::to_bits);
    let mut seen: HashMap<([u32; 3], [u32; 3]), usize> = HashMap::new();
    for (i, t) in scene.triangles.iter().enumerate() {
        if scene.degenerate[i] {
            continue;
        }
        for (a, b) in [(0, 1), (1, 2), (2, 0)] {
            let (ka, kb) = (key(t[a]), key(t[b]));
            let edge = if ka <= kb { (ka, kb) } else { (kb, ka) };
            match seen.get(&edge) {
                Some(&j) if j != i => return true,
                Some(_) => {}
                None => {
                    seen.insert(edge, i);
                }
            }
        }
    }
    false
}

/// Two triangles whose vertices all lie within [`COPLANAR_REL`] of their
/// distance from the eye of the other's plane.
fn any_coplanar(tris: &[[DVec3; 3]], eye: DVec3) -> bool {
    let near_plane_of = |p: &[DVec3; 3], q: &[DVec3; 3]| {
        let n = (p[1] - p[0]).cross(p[2] - p[0]);
        let len = n.length();
        len > 0.0
            && q.iter()
                .all(|v| ((*v - p[0]).dot(n) / len).abs() <= COPLANAR_REL * (*v - eye).length())
    };
    (0..tris.len()).any(|i| {
        (i + 1..tris.len())
            .any(|j| near_plane_of(&tris[i], &tris[j]) && near_plane_of(&tris[j], &tris[i]))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fuzz::literal::{LiteralCamera, LiteralObject, LiteralScene, Tri};

    fn scene(eye: [f64; 3], near: f64, tris: Vec<Tri>) -> ResolvedScene {
        let s = LiteralScene {
            description: "situation test".into(),
            requires: vec!["depth".into(), "ids".into()],
            camera: LiteralCamera {
                eye,
                look_at: [eye[0], eye[1], eye[2] - 1.0],
                up: [0.0, 1.0, 0.0],
                vfov: 60.0,
                width: 32,
                height: 32,
                near,
                far: None,
            },
            objects: vec![LiteralObject::new(tris)],
            materials: Vec::new(),
            lights: Vec::new(),
            integrator: None,
        };
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("s.toml");
        std::fs::write(&file, s.to_toml()).unwrap();
        let loaded = crate::scene::Scene::load(&file).unwrap();
        ResolvedScene::resolve(&loaded).unwrap()
    }

    fn tags(s: &ResolvedScene) -> Vec<String> {
        situations(s)
    }

    #[test]
    fn a_plain_triangle_has_no_tag() {
        let s = scene(
            [0.0, 0.0, 0.0],
            0.01,
            vec![[[-1.0, -1.0, -4.0], [1.0, -1.0, -4.0], [0.0, 1.0, -4.0]]],
        );
        assert!(tags(&s).is_empty(), "{:?}", tags(&s));
    }

    #[test]
    fn each_tag_fires_on_its_situation_and_not_beside_it() {
        // Two triangles sharing the edge (1,-1)-(0,1), in one plane.
        let pair = vec![
            [[-1.0, -1.0, -4.0], [1.0, -1.0, -4.0], [0.0, 1.0, -4.0]],
            [[1.0, -1.0, -4.0], [2.0, 1.0, -4.0], [0.0, 1.0, -4.0]],
        ];
        let t = tags(&scene([0.0, 0.0, 0.0], 0.01, pair));
        assert_eq!(t, vec![COPLANAR.to_string(), SHARED_EDGE.to_string()]);
        // Near-coplanar: 2^-12 of the depth apart is coplanar; 2^-8 is not.
        let gap = |g: f64| {
            let z = -4.0 * (1.0 + g);
            vec![
                [[-1.0, -1.0, -4.0], [1.0, -1.0, -4.0], [0.0, 1.0, -4.0]],
                [[-1.0, -1.0, z], [1.0, -1.0, z], [0.0, 1.0, z]],
            ]
        };
        assert!(tags(&scene([0.0; 3], 0.01, gap(1.0 / 4096.0))).contains(&COPLANAR.into()));
        assert!(!tags(&scene([0.0; 3], 0.01, gap(1.0 / 256.0))).contains(&COPLANAR.into()));
        // Crossing the near plane (near 3: depths 2 to 5).
        let crossing = vec![[[-1.0, -1.0, -2.0], [1.0, -1.0, -5.0], [0.0, 1.0, -5.0]]];
        assert_eq!(
            tags(&scene([0.0; 3], 3.0, crossing.clone())),
            vec![NEAR_PLANE]
        );
        assert!(tags(&scene([0.0; 3], 1.0, crossing)).is_empty());
        // Far from the origin: eye at 2^16, not at 2^15 (the triangle moves with it).
        let at = |x: f64| {
            let tri = [[x - 1.0, -1.0, -4.0], [x + 1.0, -1.0, -4.0], [x, 1.0, -4.0]];
            tags(&scene([x, 0.0, 0.0], 0.01, vec![tri]))
        };
        assert_eq!(at(65536.0), vec![FAR_FROM_ORIGIN]);
        assert!(at(32768.0).is_empty());
        // Distant: beyond 2^20 from the eye.
        let far = |z: f64| {
            let tri = [[-z, -z, -z], [z, -z, -z], [0.0, z, -z]];
            tags(&scene([0.0; 3], 1.0, vec![tri]))
        };
        assert_eq!(far(1.1e6), vec![DISTANT_TAG]);
        assert!(far(5e5).is_empty());
        // Huge: longest edge over 16 view widths (view at depth 4: 4.62).
        let wide = |w: f64| {
            let tri = [[-w, -1.0, -4.0], [w, -1.0, -4.0], [0.0, 1.0, -4.0]];
            tags(&scene([0.0; 3], 0.01, vec![tri]))
        };
        assert!(wide(40.0).contains(&HUGE.into()));
        assert!(!wide(30.0).contains(&HUGE.into()));
        // Sliver: height under 2^-8 of the longest edge.
        let thin = |h: f64| {
            let tri = [[-1.0, 0.0, -4.0], [1.0, 0.0, -4.0], [0.0, h, -4.0]];
            tags(&scene([0.0; 3], 0.01, vec![tri]))
        };
        assert_eq!(thin(0.005), vec![SLIVER_TAG]);
        assert!(thin(0.01).is_empty());
    }
}
