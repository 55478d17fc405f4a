//! Rasterization: the outer loop runs over triangles, the inner over the pixels
//! of each triangle's bounding box, keeping the nearest hit in a z-buffer.
//!
//! Triangles are clipped against the near plane only to find a conservative
//! screen bounding box and binned into tiles; tiles render in parallel. The
//! decision per pixel is [`crate::visibility`]'s, exactly as in the tracer:
//! the edge-function fast path ([`crate::raster_edges`]) settles only the
//! signs the predicate's own filter would settle at once (8 pixels at a time),
//! and [`render_exact`] keeps the pure predicate loop to test it against.

use crate::camera::{Camera, PixelRay};
use crate::frame::Frame;
#[cfg(target_arch = "x86_64")]
use crate::raster_edges::Avx2;
use crate::raster_edges::{ChunkDepth, FastEdges, Lanes, Portable, TileRays, CHUNK};
use crate::scene::resolve::{ResolvedScene, Tri};
use crate::visibility::{covers_by, edge_sign, hit_key, Counters, TriDepth, TriEdges, NO_HIT};
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
    let pts: [DVec3; 3] = t.map(|v| cam.to_camera(v.as_dvec3()));
    // Clipping a triangle by one plane leaves at most 4 vertices (no allocation).
    let mut poly = [DVec3::ZERO; 4];
    let mut len = 0;
    for i in 0..3 {
        let (p, q) = (pts[i], pts[(i + 1) % 3]);
        let (pin, qin) = (p.z >= zmin, q.z >= zmin);
        if pin {
            poly[len] = p;
            len += 1;
        }
        if pin != qin {
            let s = (zmin - p.z) / (q.z - p.z);
            let mut m = p + (q - p) * s;
            m.z = m.z.max(zmin);
            poly[len] = m;
            len += 1;
        }
    }
    let poly = &poly[..len];
    if poly.is_empty() {
        return None;
    }
    if cam.far.is_finite() && poly.iter().all(|p| p.z > cam.far * (1.0 + 1e-6)) {
        return None;
    }
    let (mut xmin, mut ymin) = (f64::INFINITY, f64::INFINITY);
    let (mut xmax, mut ymax) = (f64::NEG_INFINITY, f64::NEG_INFINITY);
    for p in poly {
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
/// of tiles finished since the last call (from worker threads). Coverage goes
/// through the edge-function fast path ([`crate::raster_edges`]) first.
pub fn render(
    scene: &ResolvedScene,
    opts: RasterOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> Frame {
    render_impl(scene, opts, true, progress)
}

/// [`render`] without the edge-function fast path: every bounding-box pixel
/// calls the orientation predicate. Kept as the reference the fast path must
/// equal bit for bit (buffers and counts, `fast_decided` aside), in tests and
/// benchmarks.
pub fn render_exact(
    scene: &ResolvedScene,
    opts: RasterOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> Frame {
    render_impl(scene, opts, false, progress)
}

fn render_impl(
    scene: &ResolvedScene,
    opts: RasterOptions,
    fast: bool,
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
    let tiles: Vec<TileOut> = bins
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
            let out = render_tile(scene, &rects, bin, tx * TILE, ty * TILE, opts, fast);
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

/// One tile's keys, coverage counts and operation counts.
type TileOut = (Vec<u64>, Vec<[u16; 2]>, Counters);

/// Renders one tile; on x86-64 CPUs with AVX2 the same code runs compiled for
/// 256-bit vectors (the fast path's 8-lane loops vectorize; the arithmetic is
/// unchanged, as Rust never contracts a*b+c into an FMA by itself).
fn render_tile(
    scene: &ResolvedScene,
    rects: &[Option<PixelRect>],
    bin: &[u32],
    x0: u32,
    y0: u32,
    opts: RasterOptions,
    fast: bool,
) -> TileOut {
    #[cfg(target_arch = "x86_64")]
    if let Some(avx2) = Avx2::detect().filter(|_| fast) {
        // SAFETY: the token proves the CPU has AVX2 and POPCNT.
        return unsafe { render_tile_avx2(avx2, scene, rects, bin, x0, y0, opts) };
    }
    render_tile_body(Portable, scene, rects, bin, x0, y0, opts, fast)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,popcnt")]
fn render_tile_avx2(
    avx2: Avx2,
    scene: &ResolvedScene,
    rects: &[Option<PixelRect>],
    bin: &[u32],
    x0: u32,
    y0: u32,
    opts: RasterOptions,
) -> TileOut {
    render_tile_body(avx2, scene, rects, bin, x0, y0, opts, true)
}

/// Depth test and key update for a pixel the triangle covers with `facing`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn record_hit(
    cam: &Camera,
    t: &Tri,
    prim: u32,
    ray: &PixelRay,
    facing: i8,
    depth: &mut Option<TriDepth>,
    key: &mut u64,
    cov: Option<&mut [u16; 2]>,
) {
    let d = depth.get_or_insert_with(|| TriDepth::new(cam, t));
    if let Some(z) = d.depth(cam, ray) {
        let k = hit_key(z, prim);
        if k < *key {
            *key = k;
        }
        if let Some(cov) = cov {
            let slot = usize::from(facing > 0);
            cov[slot] = cov[slot].saturating_add(1);
        }
    }
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn render_tile_body<L: Lanes>(
    l: L,
    scene: &ResolvedScene,
    rects: &[Option<PixelRect>],
    bin: &[u32],
    x0: u32,
    y0: u32,
    opts: RasterOptions,
    fast: bool,
) -> TileOut {
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
    if fast {
        fast_tile(
            l,
            scene,
            rects,
            bin,
            (x0, y0, tw, th),
            &mut keys,
            &mut cov,
            &mut c,
        );
        return (keys, cov, c);
    }
    // The pure predicate path: every bounding-box pixel asks `visibility`.
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
                if facing != 0 {
                    let cv = cov.get_mut(li);
                    record_hit(cam, t, prim, ray, facing, &mut depth, &mut keys[li], cv);
                }
            }
        }
    }
    (keys, cov, c)
}

/// The fast path over one tile (`(x0, y0, tw, th)`): per triangle, its edge
/// functions decide 8 pixels of a row at a time where their bound allows
/// ([`crate::raster_edges`]); undecided pixels go to the predicate exactly as
/// [`TriEdges::covers`] would ask it; covered pixels get their depth 8 at a
/// time from the same arithmetic as [`TriDepth::depth`].
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn fast_tile<L: Lanes>(
    l: L,
    scene: &ResolvedScene,
    rects: &[Option<PixelRect>],
    bin: &[u32],
    (x0, y0, tw, th): (u32, u32, u32, u32),
    keys: &mut [u64],
    cov: &mut [[u16; 2]],
    c: &mut Counters,
) {
    let cam = &scene.camera;
    let rays = TileRays::new(cam, x0, y0, tw, th);
    let width = rays.width();
    for &prim in bin {
        let r = rects[prim as usize].expect("binned triangles have bounds");
        let t = &scene.triangles[prim as usize];
        c.triangle_setups += 1;
        let edges = TriEdges::new(cam, t);
        let f = FastEdges::new(&edges, &rays);
        let mut depth: Option<ChunkDepth> = None;
        let (lx0, lx1) = (
            (r.x0.max(x0) - x0) as usize,
            (r.x1.min(x0 + tw - 1) - x0) as usize,
        );
        let (ly0, ly1) = (
            (r.y0.max(y0) - y0) as usize,
            (r.y1.min(y0 + th - 1) - y0) as usize,
        );
        for ly in ly0..=ly1 {
            // Chunks of 8 lanes start at the box's first column (any column:
            // `TileRays` pads its rows), so a box 8 pixels wide takes one per row.
            for base in (lx0..=lx1).step_by(CHUNK) {
                let span: u32 = (1u32 << ((lx1 - base).min(CHUNK - 1) + 1)) - 1;
                let sg = f.chunk(l, &rays, ly, base);
                let rejected = sg.rejected() & span;
                let (mut back, mut front) = (sg.inside_pos() & span, sg.inside_neg() & span);
                let inside = back | front;
                // What `covers_by` would count for the lanes settled here.
                let decided = u64::from((rejected | inside).count_ones());
                c.coverage_tests += decided;
                c.fast_decided += decided;
                c.covered += u64::from(inside.count_ones());
                let mut unsure = span & !rejected & !inside;
                while unsure != 0 {
                    let j = unsure.trailing_zeros() as usize;
                    unsure &= unsure - 1;
                    let ray = rays.ray(base + j, ly);
                    // Certain signs stand (they are the predicate's own);
                    // the rest go to the predicate, in `covers_by`'s order.
                    let facing = covers_by(c, |k, c| match sg.sign(k, j) {
                        0 => edge_sign(cam, &edges.0[k], &ray, c),
                        s => s,
                    });
                    back |= u32::from(facing > 0) << j;
                    front |= u32::from(facing < 0) << j;
                }
                if back | front == 0 {
                    continue;
                }
                let d = depth.get_or_insert_with(|| ChunkDepth::new(cam, &TriDepth::new(cam, t)));
                let (z, ok) = d.depths(cam, &rays, ly, base);
                let mut m = (back | front) & ok;
                while m != 0 {
                    let j = m.trailing_zeros() as usize;
                    m &= m - 1;
                    let li = ly * width + base + j;
                    let k = hit_key(z[j], prim);
                    if k < keys[li] {
                        keys[li] = k;
                    }
                    if let Some(cv) = cov.get_mut(li) {
                        let slot = usize::from((back >> j) & 1 == 1);
                        cv[slot] = cv[slot].saturating_add(1);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::predicate::tests::lcg;
    use glam::{DVec3, Vec3};

    /// Renders with and without the fast path, with and without coverage
    /// counts, and checks every buffer and count is the same bit for bit
    /// (`fast_decided` aside). Returns the fast render's counts.
    fn fast_equals_exact(what: &str, scene: &ResolvedScene) -> Counters {
        let mut out = Counters::default();
        for count_coverage in [false, true] {
            let opts = RasterOptions {
                count_coverage,
                deadline: None,
            };
            let f = render(scene, opts, &|_| {});
            let e = render_exact(scene, opts, &|_| {});
            for i in 0..f.prim.len() {
                let at = (i % f.width as usize, i / f.width as usize);
                assert_eq!(f.prim[i], e.prim[i], "{what}: id.prim at {at:?}");
                assert_eq!(f.z[i].to_bits(), e.z[i].to_bits(), "{what}: Z at {at:?}");
                assert_eq!(f.object[i], e.object[i], "{what}: id.object at {at:?}");
                let bits = |n: [f32; 3]| n.map(f32::to_bits);
                assert_eq!(bits(f.normal[i]), bits(e.normal[i]), "{what}: N at {at:?}");
            }
            assert_eq!(f.coverage, e.coverage, "{what}: coverage counts");
            assert_eq!(
                e.counters.fast_decided, 0,
                "{what}: the exact path took shortcuts"
            );
            let mut fc = f.counters;
            fc.fast_decided = 0;
            assert_eq!(fc, e.counters, "{what}: operation counts");
            out = f.counters;
        }
        out
    }

    fn camera(eye: DVec3, at: DVec3, vfov: f64, w: u32, h: u32) -> Camera {
        Camera::new(eye, at, DVec3::Y, vfov, w, h, 1e-3, f64::INFINITY).unwrap()
    }

    /// The point at ray parameter `t` along pixel `(x, y)`'s ray, rounded to f32:
    /// for the exact cameras below, exactly on the ray through the pixel center.
    fn on_ray(cam: &Camera, x: u32, y: u32, t: f64) -> Vec3 {
        (cam.eye + cam.pixel_ray(x, y).dir * t).as_vec3()
    }

    /// Triangles whose vertices lie on pixel-center rays (so edges pass through
    /// or within f32 rounding of pixel centers), pairs sharing such edges with
    /// both windings, slivers, huge triangles and triangles behind the eye.
    fn adversarial(cam: &Camera, seed: u64, n: usize) -> Vec<Tri> {
        let mut s = seed;
        let (w, h) = (cam.width, cam.height);
        let px = |s: &mut u64| {
            let x = ((lcg(s) * 0.5 + 0.5) * f64::from(w)) as u32;
            let y = ((lcg(s) * 0.5 + 0.5) * f64::from(h)) as u32;
            (x.min(w - 1), y.min(h - 1))
        };
        let depths = [1.0, 2.0, 1.5, 3.0, 1.25];
        let mut tris = Vec::new();
        for i in 0..n {
            let t = |s: &mut u64| depths[((lcg(s) * 0.5 + 0.5) * 5.0) as usize % 5];
            let (p, q, r) = (px(&mut s), px(&mut s), px(&mut s));
            let a = on_ray(cam, p.0, p.1, t(&mut s));
            let b = on_ray(cam, q.0, q.1, t(&mut s));
            let c = on_ray(cam, r.0, r.1, t(&mut s));
            match i % 5 {
                0 => tris.push([a, b, c]),
                1 => {
                    // A shared edge, the second triangle in either winding.
                    let d = on_ray(cam, px(&mut s).0, px(&mut s).1, t(&mut s));
                    tris.push([a, b, c]);
                    tris.push(if lcg(&mut s) > 0.0 {
                        [b, a, d]
                    } else {
                        [a, b, d]
                    });
                }
                2 => {
                    // A sliver: the third vertex within a few f32 ulps of the edge's middle.
                    let m = (a + b) * 0.5;
                    let e = Vec3::new(m.x.next_up(), m.y, m.z.next_down());
                    tris.push([a, b, if lcg(&mut s) > 0.0 { m } else { e }]);
                }
                3 => {
                    // Huge: far beyond the image, edges still through pixel centers.
                    let far = on_ray(cam, p.0, p.1, 1e6);
                    tris.push([far, b, c]);
                }
                _ => {
                    // One vertex behind the eye (clipped for the bounds only).
                    let behind = (cam.eye - cam.pixel_ray(q.0, q.1).dir * 0.5).as_vec3();
                    tris.push([a, behind, c]);
                }
            }
        }
        tris
    }

    /// Edges through and within a few ulps of pixel centers, at offsets from 0
    /// to 1e7, exact and tilted cameras, an odd image (a column of rays with
    /// `D.x = 0`), slivers, huge triangles: the fast path defers the undecidable
    /// pixels to the predicate (ties and exact fallbacks happen, with the same
    /// counts as the pure predicate path) and every buffer is the pure path's.
    #[test]
    fn fast_path_equals_the_predicate_path_at_pixel_centers() {
        let mut deferred = 0;
        let mut ties = 0;
        for (k, off) in [0.0, 1e3, 1e5, 12345.678, 1e7].into_iter().enumerate() {
            let o = DVec3::new(off, -off, off);
            for (w, h) in [(32, 32), (33, 33), (40, 24)] {
                let cams = [
                    // Exact: pixel centers are dyadic on the plane at depth 1.
                    camera(o + DVec3::Z, o, 90.0, w, h),
                    // Tilted, non-dyadic.
                    camera(
                        o + DVec3::new(0.3, 0.7, 2.1),
                        o + DVec3::new(0.1, -0.2, 0.0),
                        50.0,
                        w,
                        h,
                    ),
                ];
                for (ci, cam) in cams.into_iter().enumerate() {
                    let what = format!("offset {off}, {w}x{h}, camera {ci}");
                    let tris = adversarial(&cam, 17 + k as u64 * 31 + u64::from(w), 25);
                    let c = fast_equals_exact(&what, &ResolvedScene::from_triangles(cam, tris));
                    assert!(c.fast_decided > 0, "{what}: nothing decided fast");
                    deferred += c.coverage_tests - c.fast_decided;
                    ties += c.ties;
                }
            }
        }
        assert!(
            ties > 100 && deferred > 100,
            "ties {ties}, deferred {deferred}"
        );
    }

    /// The grid of `bench crossover`, exactly over the image: grid lines and
    /// diagonals through pixel centers, so every such center is a tie.
    #[test]
    fn aligned_grid_ties_are_deferred_and_decided_by_the_rule() {
        for nx in [1, 3, 8] {
            let cam = camera(DVec3::Z, DVec3::ZERO, 90.0, 64, 64);
            let tris = crate::scene::generators::grid([-1.0, -1.0], [1.0, 1.0], nx, nx)
                .iter()
                .map(|t| t.map(|v| v.as_vec3()))
                .collect();
            let scene = ResolvedScene::from_triangles(cam, tris);
            let c = fast_equals_exact(&format!("grid {nx}"), &scene);
            assert!(c.ties > 0 && c.fast_decided < c.coverage_tests);
            let f = render(&scene, RasterOptions::default(), &|_| {});
            assert!(f.prim.iter().all(|&p| p != u32::MAX), "grid {nx}: a crack");
        }
    }

    /// Random triangles at scales from 1e-6 to 1e6 seen from far away and
    /// close by: the depth of every lane and the coverage of every pixel match.
    #[test]
    fn fast_path_equals_the_predicate_path_at_extreme_scales() {
        let mut s = 99u64;
        for i in 0..24 {
            let scale = 10f64.powi((i % 13) - 6);
            let eye = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s) + 3.0) * scale;
            let cam = camera(
                eye,
                DVec3::ZERO,
                [30.0, 90.0, 120.0][i as usize % 3],
                37,
                29,
            );
            let tris = (0..30)
                .map(|_| {
                    let c = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * scale;
                    let r = scale * [1.0, 0.01, 1e-4][(i as usize / 3) % 3];
                    [0; 3].map(|_| {
                        (c + DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * r).as_vec3()
                    })
                })
                .collect();
            fast_equals_exact(
                &format!("scale {scale}"),
                &ResolvedScene::from_triangles(cam, tris),
            );
        }
    }
}
