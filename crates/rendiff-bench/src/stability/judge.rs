//! Judging renders of the families whose truth is known, pixel by pixel, from
//! their buffers: the fill rule (every center on an edge) and a per-pixel truth
//! computed from the resolved scene itself (nearest surface, exact ties to the
//! lower id) for coplanar overlaps, z-fighting and geometry next to the eye.

use super::families::Layout;
use rendiff::exr_io::Buffers;
use rendiff::frame::{Frame, BACKGROUND_ID};
use rendiff::predicate::exact_sign;
use rendiff::scene::resolve::ResolvedScene;
use rendiff::visibility::{Counters, TriEdges};
use serde_json::{json, Value};
use std::collections::HashMap;

/// A render's buffers as the judges read them.
pub struct Ids<'a> {
    /// Width in pixels.
    pub width: usize,
    /// `id.prim`, row-major.
    pub prim: &'a [u32],
}

impl<'a> Ids<'a> {
    /// The ID view of an EXR's buffers, if it has `id.prim` of the right size.
    pub fn of(b: &'a Buffers, width: usize, height: usize) -> Option<Ids<'a>> {
        let prim = b.prim.as_deref()?;
        (b.width == width && b.height == height && prim.len() == width * height)
            .then_some(Ids { width, prim })
    }
}

fn sentence(parts: Vec<String>) -> Option<String> {
    (!parts.is_empty()).then(|| parts.join("; "))
}

/// Fill rule against the raster (the top-left rule): cracks strictly inside a
/// mesh, hits outside every mesh, and pixels (all on edges or vertices here)
/// whose winner, or hit/miss on a mesh boundary, differs from the rule's.
pub fn fill_rule(layout: &Layout, reference: &Ids, test: &Ids) -> (Option<String>, Value) {
    let (mut cracks, mut spills, mut winners, mut boundary) = (0u64, 0u64, 0u64, 0u64);
    for (i, (&r, &t)) in reference.prim.iter().zip(test.prim).enumerate() {
        let (x, y) = ((i % reference.width) as u32, (i / reference.width) as u32);
        let (rh, th) = (r != BACKGROUND_ID, t != BACKGROUND_ID);
        if layout.inside(x, y) && !th {
            cracks += 1;
        } else if layout.outside(x, y) && th {
            spills += 1;
        } else if rh && th && r != t {
            winners += 1;
        } else if rh != th {
            boundary += 1;
        }
    }
    let mut why = Vec::new();
    if cracks > 0 {
        why.push(format!(
            "{cracks} cracks (background strictly inside a watertight mesh)"
        ));
    }
    if winners > 0 {
        why.push(format!(
            "{winners} pixels on shared edges won by another triangle than the top-left rule's"
        ));
    }
    if boundary > 0 {
        why.push(format!(
            "{boundary} pixels on a mesh boundary covered otherwise than by the top-left rule"
        ));
    }
    if spills > 0 {
        why.push(format!("{spills} hits outside every mesh"));
    }
    let stats =
        json!({"cracks": cracks, "other_winner": winners, "boundary": boundary, "spills": spills});
    (sentence(why), stats)
}

/// The core's own fill-rule check from per-pixel coverage counts (which the
/// buffers cannot show): no pixel covered twice, every pixel strictly inside
/// covered once, none outside.
pub fn fill_rule_coverage(layout: &Layout, frame: &Frame) -> (Option<String>, Value) {
    let Some(cov) = &frame.coverage else {
        return (Some("no coverage counts".into()), Value::Null);
    };
    let w = frame.width as usize;
    let (mut double, mut holes, mut spills) = (0u64, 0u64, 0u64);
    for (i, c) in cov.iter().enumerate() {
        let (x, y) = ((i % w) as u32, (i / w) as u32);
        let n = u32::from(c[0]) + u32::from(c[1]);
        if n >= 2 {
            double += 1;
        }
        if n == 0 && layout.inside(x, y) {
            holes += 1;
        }
        if n > 0 && layout.outside(x, y) {
            spills += 1;
        }
    }
    let mut why = Vec::new();
    if double > 0 {
        why.push(format!("{double} pixels covered twice or more"));
    }
    if holes > 0 {
        why.push(format!(
            "{holes} pixels strictly inside covered by no triangle"
        ));
    }
    if spills > 0 {
        why.push(format!("{spills} pixels outside every mesh covered"));
    }
    (
        sentence(why),
        json!({"double_coverage": double, "holes": holes, "spills": spills}),
    )
}

/// A covering triangle and its planar depth at one pixel.
type Hit = (u32, f64);

/// What one pixel must show.
#[derive(Debug, Clone)]
pub struct PixelTruth {
    /// The winner: the nearest covering triangle, exact ties to the lowest id;
    /// [`BACKGROUND_ID`] when nothing covers the center within [near, far].
    pub id: u32,
    /// Its planar depth (f64, from the f32 vertices every renderer reads).
    pub z: f64,
    /// Triangles exactly coplanar with the winner that also cover (higher ids).
    pub ties: Vec<u32>,
    /// Covering triangles behind the winner, with their depth gap to it.
    pub behind: Vec<(u32, f64)>,
}

/// The truth of every pixel far enough from every edge (its 3x3 neighbourhood
/// is covered by the same triangles) that rounding cannot move it; `None` elsewhere.
pub struct Truth {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Per pixel, row-major.
    pub pixels: Vec<Option<PixelTruth>>,
}

fn plane_depth(scene: &ResolvedScene, i: usize, x: u32, y: u32) -> Option<f64> {
    let cam = &scene.camera;
    let ray = cam.pixel_ray(x, y);
    let [a, b, c] = scene.triangles[i].map(|v| v.as_dvec3());
    let n = (b - a).cross(c - a);
    let denom = n.dot(ray.dir);
    if denom == 0.0 {
        return None;
    }
    let z = n.dot(a - cam.eye) / denom * ray.planar;
    (z >= cam.near && z <= cam.far).then_some(z)
}

/// Computes the truth of a small scene by brute force (every triangle at every pixel).
pub fn truth(scene: &ResolvedScene) -> Truth {
    let cam = &scene.camera;
    let (w, h) = (cam.width as usize, cam.height as usize);
    let edges: Vec<Option<TriEdges>> = scene
        .triangles
        .iter()
        .zip(&scene.degenerate)
        .map(|(t, &d)| (!d).then(|| TriEdges::new(cam, t)))
        .collect();
    let mut c = Counters::default();
    let covers: Vec<Vec<(u32, f64)>> = (0..w * h)
        .map(|p| {
            let (x, y) = ((p % w) as u32, (p / w) as u32);
            let ray = cam.pixel_ray(x, y);
            edges
                .iter()
                .enumerate()
                .filter_map(|(i, e)| {
                    let e = e.as_ref()?;
                    if e.covers(cam, &ray, &mut c) == 0 {
                        return None;
                    }
                    plane_depth(scene, i, x, y).map(|z| (i as u32, z))
                })
                .collect()
        })
        .collect();
    let mut coplanar: HashMap<(u32, u32), bool> = HashMap::new();
    let mut same_plane = |a: u32, b: u32| -> bool {
        *coplanar.entry((a, b)).or_insert_with(|| {
            let [p, q, r] = scene.triangles[a as usize].map(|v| v.as_dvec3());
            scene.triangles[b as usize]
                .iter()
                .all(|v| exact_sign(p, q, r, v.as_dvec3()) == 0)
        })
    };
    let ids = |p: usize| covers[p].iter().map(|c| c.0).collect::<Vec<_>>();
    let pixels = (0..w * h)
        .map(|p| {
            let (x, y) = (p % w, p / w);
            let mine = ids(p);
            for ny in y.saturating_sub(1)..=(y + 1).min(h - 1) {
                for nx in x.saturating_sub(1)..=(x + 1).min(w - 1) {
                    if ids(ny * w + nx) != mine {
                        return None;
                    }
                }
            }
            let cov = &covers[p];
            let Some(&(m, zm)) = cov.iter().min_by(|a, b| a.1.total_cmp(&b.1)) else {
                return Some(PixelTruth {
                    id: BACKGROUND_ID,
                    z: f64::INFINITY,
                    ties: vec![],
                    behind: vec![],
                });
            };
            let (tied, behind): (Vec<&Hit>, Vec<&Hit>) =
                cov.iter().partition(|&&(i, _)| i == m || same_plane(m, i));
            let mut tied: Vec<u32> = tied.into_iter().map(|t| t.0).collect();
            tied.sort_unstable();
            Some(PixelTruth {
                id: tied[0],
                z: zm,
                ties: tied[1..].to_vec(),
                behind: behind.into_iter().map(|&(i, z)| (i, z - zm)).collect(),
            })
        })
        .collect();
    Truth {
        width: w,
        height: h,
        pixels,
    }
}

/// The smallest depth difference a renderer can resolve at planar depth `z`,
/// and where the figure comes from. Every renderer reads f32 vertices and
/// (except POV-Ray inside) computes or stores depth in f32: one f32 spacing at
/// `z`. pyrender's 24-bit GL depth buffer at its own planes n, f (from the
/// render's info) resolves z^2 (f - n) / (f n) 2^-24, when that is coarser.
pub fn depth_resolution(backend: &str, z: f64, info: &Value) -> (f64, &'static str) {
    let z32 = z.abs() as f32;
    let ulp = f64::from(f32::from_bits(z32.to_bits() + 1) - z32);
    if backend != "pyrender" {
        return (ulp, "f32 spacing at the depth");
    }
    let num = |k: &str| info.get(k).and_then(Value::as_f64);
    match (num("znear"), num("zfar")) {
        (Some(n), Some(f)) if n > 0.0 && f > n => {
            let step = z * z * (f - n) / (f * n) * 2f64.powi(-24);
            (
                step.max(ulp),
                "24-bit GL depth step at the render's znear/zfar",
            )
        }
        _ => (ulp, "f32 spacing (the render gave no GL planes)"),
    }
}

/// Judges one render against the truth. A pixel breaks when it shows
/// background where a surface is, a surface where none is, a higher id than
/// its exact coplanar tie (when `ties_break`), a triangle that does not cover
/// it, or a farther surface whose gap to the nearest exceeds the renderer's
/// depth resolution. Farther surfaces within the resolution are counted, not broken.
pub fn judge_truth(
    truth: &Truth,
    test: &Ids,
    backend: &str,
    info: &Value,
    ties_break: bool,
) -> (Option<String>, Value) {
    let (mut missing, mut phantom, mut tie_lost, mut wrong) = (0u64, 0u64, 0u64, 0u64);
    let (mut lost, mut lost_below) = (0u64, 0u64);
    let mut worst: Option<(f64, f64, f64)> = None; // (gap, z, resolution) of the largest lost gap
    let mut judged = 0u64;
    for (p, t) in truth.pixels.iter().enumerate() {
        let Some(t) = t else { continue };
        judged += 1;
        let got = test.prim[p];
        if got == t.id {
            continue;
        }
        if got == BACKGROUND_ID {
            missing += 1;
        } else if t.id == BACKGROUND_ID {
            phantom += 1;
        } else if t.ties.contains(&got) {
            tie_lost += 1;
        } else if let Some(&(_, gap)) = t.behind.iter().find(|b| b.0 == got) {
            let (res, _) = depth_resolution(backend, t.z, info);
            if gap > res {
                lost += 1;
            } else {
                lost_below += 1;
            }
            if worst.is_none_or(|w| gap > w.0) {
                worst = Some((gap, t.z, res));
            }
        } else {
            wrong += 1;
        }
    }
    let mut why = Vec::new();
    if missing > 0 {
        why.push(format!(
            "{missing} pixels show background where a surface is"
        ));
    }
    if phantom > 0 {
        why.push(format!("{phantom} hits where no surface is"));
    }
    if tie_lost > 0 && ties_break {
        why.push(format!(
            "{tie_lost} exact coplanar ties won by the higher id"
        ));
    }
    if lost > 0 {
        let (gap, z, res) = worst.unwrap_or_default();
        why.push(format!(
            "nearer surface lost in {lost} pixels, gap up to {gap:.3e} at depth {z:.4} (resolution {res:.3e})"
        ));
    }
    if wrong > 0 {
        why.push(format!(
            "{wrong} pixels show a triangle that does not cover them"
        ));
    }
    let stats = json!({
        "judged_pixels": judged, "missing": missing, "phantom": phantom, "tie_lost": tie_lost,
        "nearer_lost": lost, "nearer_lost_below_resolution": lost_below, "wrong_triangle": wrong,
        "largest_lost_gap": worst.map(|w| w.0), "largest_lost_gap_depth": worst.map(|w| w.1),
        "resolution_there": worst.map(|w| w.2),
    });
    (sentence(why), stats)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f32_resolution_is_one_spacing() {
        let (r, _) = depth_resolution("embree", 1.0, &Value::Null);
        assert_eq!(r, f64::from(f32::EPSILON));
        let info = json!({"znear": 0.01, "zfar": 100.0});
        let (r, _) = depth_resolution("pyrender", 10.0, &info);
        let step = 100.0 * (100.0 - 0.01) / (100.0 * 0.01) * 2f64.powi(-24);
        assert!((r - step).abs() < 1e-18, "{r} vs {step}");
    }
}
