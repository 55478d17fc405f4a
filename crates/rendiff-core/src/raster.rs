//! Rasterization: the outer loop runs over triangles, the inner over the pixels
//! of each triangle's bounding box, keeping the nearest hit in a z-buffer.
//!
//! Triangles are clipped against the near plane only to find a conservative
//! screen bounding box and binned into tiles; tiles render in parallel. The
//! decision per pixel is [`crate::visibility`]'s, exactly as in the tracer.

use crate::camera::{Camera, PixelRay};
use crate::frame::Frame;
use crate::scene::resolve::{ResolvedScene, Tri};
use crate::visibility::{hit_key, Counters, TriDepth, TriEdges, NO_HIT};
use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;

/// Tile side in pixels: small enough for load balance, big enough to amortize setup.
pub const TILE: u32 = 32;

/// Inclusive pixel rectangle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PixelRect {
    /// First column.
    pub x0: u32,
    /// First row.
    pub y0: u32,
    /// Last column (inclusive).
    pub x1: u32,
    /// Last row (inclusive).
    pub y1: u32,
}

/// Conservative pixel bounding box of the part of a triangle at planar depth
/// at least `near` (Sutherland-Hodgman clip against the near plane, then
/// projection), grown by one pixel against rounding. `None` when nothing can be visible.
pub fn screen_bounds(cam: &Camera, t: &Tri) -> Option<PixelRect> {
    let zmin = cam.near * (1.0 - 1e-6);
    let pts: Vec<DVec3> = t.iter().map(|v| cam.to_camera(v.as_dvec3())).collect();
    let mut poly: Vec<DVec3> = Vec::with_capacity(4);
    for i in 0..3 {
        let (p, q) = (pts[i], pts[(i + 1) % 3]);
        let (pin, qin) = (p.z >= zmin, q.z >= zmin);
        if pin {
            poly.push(p);
        }
        if pin != qin {
            let s = (zmin - p.z) / (q.z - p.z);
            let mut m = p + (q - p) * s;
            m.z = m.z.max(zmin);
            poly.push(m);
        }
    }
    if poly.is_empty() {
        return None;
    }
    if cam.far.is_finite() && poly.iter().all(|p| p.z > cam.far * (1.0 + 1e-6)) {
        return None;
    }
    let (mut xmin, mut ymin) = (f64::INFINITY, f64::INFINITY);
    let (mut xmax, mut ymax) = (f64::NEG_INFINITY, f64::NEG_INFINITY);
    for p in &poly {
        let (px, py) = cam.camera_to_pixel(*p);
        if !px.is_finite() || !py.is_finite() {
            // Projection overflowed: fall back to the whole screen.
            return Some(PixelRect {
                x0: 0,
                y0: 0,
                x1: cam.width - 1,
                y1: cam.height - 1,
            });
        }
        xmin = xmin.min(px);
        xmax = xmax.max(px);
        ymin = ymin.min(py);
        ymax = ymax.max(py);
    }
    // Pixel k's center is k + 0.5; keep a one-pixel margin for rounding.
    let lo = |v: f64, n: u32| (v - 1.5).floor().max(0.0).min(f64::from(n)) as u32;
    let hi = |v: f64, n: u32| (v + 0.5).ceil().min(f64::from(n) - 1.0);
    let (x1, y1) = (hi(xmax, cam.width), hi(ymax, cam.height));
    if x1 < 0.0 || y1 < 0.0 {
        return None;
    }
    let (x0, y0) = (lo(xmin, cam.width), lo(ymin, cam.height));
    let (x1, y1) = (x1 as u32, y1 as u32);
    if x0 > x1 || y0 > y1 {
        return None;
    }
    Some(PixelRect { x0, y0, x1, y1 })
}

/// Options for one raster render.
#[derive(Debug, Clone, Copy, Default)]
pub struct RasterOptions {
    /// Also count every covering triangle per pixel (front/back), for watertightness tests.
    pub count_coverage: bool,
    /// Stop rasterizing when this passes (`check --timeout`); the frame is then partial.
    pub deadline: Option<Instant>,
}

/// Renders depth and IDs by rasterization. `progress` is called with the number
/// of tiles finished since the last call (from worker threads).
pub fn render(
    scene: &ResolvedScene,
    opts: RasterOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> Frame {
    let start = Instant::now();
    let cam = &scene.camera;
    let (w, h) = (cam.width, cam.height);
    let tiles_x = w.div_ceil(TILE);
    let tiles_y = h.div_ceil(TILE);
    let rects: Vec<Option<PixelRect>> = scene
        .triangles
        .par_iter()
        .zip(scene.degenerate.par_iter())
        .map(|(t, &deg)| if deg { None } else { screen_bounds(cam, t) })
        .collect();
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); (tiles_x * tiles_y) as usize];
    for (prim, r) in rects.iter().enumerate() {
        if let Some(r) = r {
            for ty in r.y0 / TILE..=r.y1 / TILE {
                for tx in r.x0 / TILE..=r.x1 / TILE {
                    bins[(ty * tiles_x + tx) as usize].push(prim as u32);
                }
            }
        }
    }
    let tiles: Vec<(Vec<u64>, Vec<[u16; 2]>, Counters)> = bins
        .par_iter()
        .enumerate()
        .map(|(ti, bin)| {
            let tx = ti as u32 % tiles_x;
            let ty = ti as u32 / tiles_x;
            // Past the deadline a tile renders nothing (background, right size).
            let bin = if crate::deadline::past(opts.deadline) {
                &[][..]
            } else {
                &bin[..]
            };
            let out = render_tile(scene, &rects, bin, tx * TILE, ty * TILE, opts);
            progress(1);
            out
        })
        .collect();
    let mut keys = vec![NO_HIT; cam.pixel_count()];
    let mut coverage = opts
        .count_coverage
        .then(|| vec![[0u16; 2]; cam.pixel_count()]);
    let mut counters = Counters::default();
    for (ti, (tkeys, tcov, tc)) in tiles.into_iter().enumerate() {
        counters += tc;
        let x0 = (ti as u32 % tiles_x) * TILE;
        let y0 = (ti as u32 / tiles_x) * TILE;
        let tw = TILE.min(w - x0);
        let th = TILE.min(h - y0);
        for ly in 0..th {
            for lx in 0..tw {
                let dst = ((y0 + ly) * w + x0 + lx) as usize;
                let src = (ly * tw + lx) as usize;
                keys[dst] = tkeys[src];
                if let Some(cov) = coverage.as_mut() {
                    cov[dst] = tcov[src];
                }
            }
        }
    }
    Frame::from_keys(
        scene,
        &keys,
        coverage,
        counters,
        "raster",
        start.elapsed().as_secs_f64(),
    )
}

fn render_tile(
    scene: &ResolvedScene,
    rects: &[Option<PixelRect>],
    bin: &[u32],
    x0: u32,
    y0: u32,
    opts: RasterOptions,
) -> (Vec<u64>, Vec<[u16; 2]>, Counters) {
    let cam = &scene.camera;
    let tw = TILE.min(cam.width - x0);
    let th = TILE.min(cam.height - y0);
    let n = (tw * th) as usize;
    let mut keys = vec![NO_HIT; n];
    let mut cov = if opts.count_coverage {
        vec![[0u16; 2]; n]
    } else {
        Vec::new()
    };
    let mut c = Counters::default();
    if bin.is_empty() {
        return (keys, cov, c);
    }
    let rays: Vec<PixelRay> = (0..th)
        .flat_map(|ly| (0..tw).map(move |lx| (lx, ly)))
        .map(|(lx, ly)| cam.pixel_ray(x0 + lx, y0 + ly))
        .collect();
    for &prim in bin {
        let r = rects[prim as usize].expect("binned triangles have bounds");
        let t = &scene.triangles[prim as usize];
        c.triangle_setups += 1;
        let edges = TriEdges::new(cam, t);
        let mut depth: Option<TriDepth> = None;
        let (ax, bx) = (r.x0.max(x0), r.x1.min(x0 + tw - 1));
        let (ay, by) = (r.y0.max(y0), r.y1.min(y0 + th - 1));
        for y in ay..=by {
            for x in ax..=bx {
                let li = ((y - y0) * tw + (x - x0)) as usize;
                let ray = &rays[li];
                let facing = edges.covers(cam, ray, &mut c);
                if facing == 0 {
                    continue;
                }
                let d = depth.get_or_insert_with(|| TriDepth::new(cam, t));
                if let Some(z) = d.depth(cam, ray) {
                    let k = hit_key(z, prim);
                    if k < keys[li] {
                        keys[li] = k;
                    }
                    if opts.count_coverage {
                        let slot = usize::from(facing > 0);
                        cov[li][slot] = cov[li][slot].saturating_add(1);
                    }
                }
            }
        }
    }
    (keys, cov, c)
}
