//! "Near the same triangles": the second half of the reducer's
//! interestingness test (docs/fuzzing.md). A candidate that fails the same
//! buffer with the same class is the same failure only when its failing
//! pixels are on, or within a pixel of, a triangle the original failure's
//! pixels were on; otherwise removing triangles has uncovered another
//! failure (one the removed triangles hid, say) and the reduction would
//! shrink that one instead.
//!
//! Triangles are followed across reductions by identity: the reducer keeps
//! prim order, so each candidate carries, for every triangle it kept, that
//! triangle's index in the scene the reduction started from
//! (`reduce.rs`). Where the failing pixels are comes from the verifier's
//! `explanations` (docs/run-format.md): its mismatching pixels grouped by
//! (class, reference prim, test prim), each group with an example pixel
//! (on `id` and `N`, and on `Z` and `RGB` their interior pixels).
//! A group names the triangle each side saw (a mismatch always has one on
//! at least one side); "within a pixel" adds the triangles the core's
//! raster (the reference) sees in the 3x3 pixels around the example.

use crate::check::manifest::ResultEntry;
use crate::scene::resolve::ResolvedScene;
use serde_json::Value;
use std::collections::BTreeSet;

/// The verifier's classes that explanation groups carry (judge/verify.py).
const GROUP_CLASSES: [&str; 4] = ["edge", "tie", "crack", "interior"];

/// One group of failing pixels: the prims each side saw (None: the
/// background) and an example pixel `(x, y)`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Group {
    /// The reference's prim there.
    pub ref_prim: Option<usize>,
    /// The test renderer's prim there.
    pub test_prim: Option<usize>,
    /// An example pixel of the group.
    pub example: (u32, u32),
}

/// The groups of `entry`'s explanations that make up its failure of class
/// `class`: the groups of that class when the verifier groups by it
/// (`interior`, `crack`), else its failing groups (`interior`, `crack`:
/// the `mask`, `depth` and `normal` classes are counted apart from the
/// groups, whose pixels are the same). None when the entry records no such
/// group (no explanations: a side without `id.prim`, an error), so nothing
/// is known of where the failure is.
pub fn failing_groups(entry: &ResultEntry, class: &str) -> Option<Vec<Group>> {
    let groups = entry.details.get("explanations")?.as_array()?;
    let wanted = |c: &str| {
        if GROUP_CLASSES.contains(&class) {
            c == class
        } else {
            c == "interior" || c == "crack"
        }
    };
    let prim = |v: &Value| v.as_u64().and_then(|p| usize::try_from(p).ok());
    let out: Vec<Group> = groups
        .iter()
        .filter(|g| g["class"].as_str().is_some_and(wanted))
        .filter_map(|g| {
            let ex = g["example"].as_array()?;
            Some(Group {
                ref_prim: prim(&g["ref_prim"]),
                test_prim: prim(&g["test_prim"]),
                example: (
                    u32::try_from(ex.first()?.as_u64()?).ok()?,
                    u32::try_from(ex.get(1)?.as_u64()?).ok()?,
                ),
            })
        })
        .collect();
    (!out.is_empty()).then_some(out)
}

/// The triangles the groups' pixels are on: the prims either side saw,
/// as indices of the scene the reduction started from (`origin[p]` for the
/// candidate's prim `p`; a prim beyond it names no triangle and is left out).
pub fn on_triangles(groups: &[Group], origin: &[usize]) -> BTreeSet<usize> {
    groups
        .iter()
        .flat_map(|g| [g.ref_prim, g.test_prim])
        .flatten()
        .filter_map(|p| origin.get(p).copied())
        .collect()
}

/// [`on_triangles`] and the triangles within a pixel of the groups'
/// example pixels: those the reference (`scene` rendered by the core's
/// raster) sees in the 3x3 pixels around each example.
pub fn near_triangles(
    groups: &[Group],
    origin: &[usize],
    scene: &ResolvedScene,
) -> BTreeSet<usize> {
    let mut out = on_triangles(groups, origin);
    let frame = crate::raster::render(scene, crate::raster::RasterOptions::default(), &|_| {});
    let (w, h) = (i64::from(frame.width), i64::from(frame.height));
    for g in groups {
        let (x0, y0) = (i64::from(g.example.0), i64::from(g.example.1));
        for y in (y0 - 1).max(0)..=(y0 + 1).min(h - 1) {
            for x in (x0 - 1).max(0)..=(x0 + 1).min(w - 1) {
                let p = frame.prim[(y * w + x) as usize];
                if let Some(&o) = usize::try_from(p).ok().and_then(|p| origin.get(p)) {
                    out.insert(o);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fuzz::literal::test_scene;
    use serde_json::json;
    use std::path::Path;

    fn entry(explanations: Value) -> ResultEntry {
        let mut details = serde_json::Map::new();
        details.insert("explanations".into(), explanations);
        ResultEntry {
            scene: "s".into(),
            backend: "b".into(),
            buffer: "id".into(),
            status: "fail".into(),
            reason: String::new(),
            details,
        }
    }

    fn group(class: &str, r: Value, t: Value, x: u32, y: u32) -> Value {
        json!({"class": class, "ref_prim": r, "test_prim": t, "pixels": 3,
               "example": [x, y], "why": "..."})
    }

    #[test]
    fn failing_groups_are_those_of_the_class() {
        let e = entry(json!([
            group("interior", json!(4), json!(3), 10, 5),
            group("crack", json!(1), Value::Null, 2, 2),
            group("edge", json!(0), json!(1), 7, 7),
        ]));
        let g = failing_groups(&e, "interior").unwrap();
        assert_eq!(g.len(), 1);
        assert_eq!((g[0].ref_prim, g[0].test_prim), (Some(4), Some(3)));
        let g = failing_groups(&e, "crack").unwrap();
        assert_eq!((g.len(), g[0].test_prim, g[0].example), (1, None, (2, 2)));
        // A class the groups do not carry: every failing group.
        assert_eq!(failing_groups(&e, "mask").unwrap().len(), 2);
        // No explanations (Z), or none of the class: nothing known.
        assert!(failing_groups(&entry(json!([])), "interior").is_none());
        let mut z = entry(json!([]));
        z.details.clear();
        assert!(failing_groups(&z, "depth").is_none());
        let only_edges = entry(json!([group("edge", json!(0), json!(1), 7, 7)]));
        assert!(failing_groups(&only_edges, "interior").is_none());
    }

    #[test]
    fn triangles_are_mapped_to_their_origin_and_widened_by_a_pixel() {
        // Kept triangles 0, 1 of the candidate were 3 and 4 of the start.
        let origin = [3, 4];
        let g = [Group {
            ref_prim: Some(1),
            test_prim: None,
            example: (0, 0),
        }];
        assert_eq!(on_triangles(&g, &origin), BTreeSet::from([4]));
        // A prim beyond the candidate's triangles names none.
        let stray = [Group {
            ref_prim: Some(7),
            test_prim: None,
            example: (0, 0),
        }];
        assert!(on_triangles(&stray, &origin).is_empty());
        // Two triangles side by side (x < 0 and x > 0, a 16x16 view): a
        // pixel on the left one, next to the seam, is within a pixel of the
        // right one; a pixel at the far left is not.
        let s = test_scene(
            90.0,
            16,
            16,
            vec![vec![
                [[-9.0, -9.0, 0.0], [0.0, -9.0, 0.0], [0.0, 9.0, 0.0]],
                [[0.0, -9.0, 0.0], [9.0, -9.0, 0.0], [0.0, 9.0, 0.0]],
            ]],
        );
        let scene = crate::scene::Scene::parse(Path::new("t.toml"), &s.to_toml()).unwrap();
        let r = ResolvedScene::resolve(&scene).unwrap();
        let at = |x: u32| {
            [Group {
                ref_prim: Some(0),
                test_prim: None,
                example: (x, 4),
            }]
        };
        assert_eq!(near_triangles(&at(7), &origin, &r), BTreeSet::from([3, 4]));
        assert_eq!(near_triangles(&at(1), &origin, &r), BTreeSet::from([3]));
    }
}
