//! Ray tracing: the outer loop runs over pixels, the inner over the triangles a
//! BVH (our linear one by default, `linear.rs`, or obvhs's) says the pixel ray
//! may hit.
//!
//! The BVH only prunes; every candidate is decided by [`crate::visibility`],
//! exactly as in the rasterizer. Node boxes are recomputed here from the f32
//! triangles and grown by [`grow_box`], so pruning is conservative: a box is
//! skipped only when its nearest possible key is worse than the best hit.

mod build;
pub(crate) mod frustum;
mod general;
mod lazy;
mod linear;
mod nodes;
mod packet;
pub(crate) mod primary;
mod rect;
pub(crate) mod rows;
mod same_box;
#[cfg(test)]
pub(crate) mod test_tris;
mod timing;

use crate::camera::{Camera, PixelRay};
use crate::frame::{Frame, PixelKeys};
use crate::predicate::EdgePlane;
use crate::scene::resolve::{ResolvedScene, Tri};
use crate::visibility::{covers_by, edge_sign, fill_no_hit, hit_key, Counters, TriDepth, NO_HIT};
use glam::Vec3;
use nodes::Nodes32;
use obvhs::{triangle::Triangle, BvhBuildParams};
use primary::Ray32;
use rayon::prelude::*;
use std::time::Instant;

/// BVH build quality: our linear BVH ([`linear`]) and obvhs presets
/// (without spatial splits, which would give a triangle several partial
/// boxes and break conservative pruning).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BvhQuality {
    /// A linear BVH (Morton codes of the box centroids, radix sorted, split
    /// at the highest differing bit; `trace/linear.rs`): the cheapest build.
    /// The default: a render traces one frame per tree, and on `million` at
    /// 1080p its build + trace is about a third of `very_fast`'s (tree 0.10 s
    /// against 0.53 s on 1 thread) for the same trace (0.15 s: the traversal
    /// layout merges every subtree of up to 16 adjacent prims either way),
    /// the least of the six (the `first_image` example, Nov 30).
    #[default]
    Linear,
    /// obvhs fastest_build.
    Fastest,
    /// obvhs very_fast_build: fastest's PLOC search (the nearest neighbour
    /// only), one light reinsertion pass sequence and leaves of up to 8.
    /// The least build + trace of obvhs's five presets on `million` at
    /// 1080p, 1 and 2 threads (docs/benchmarks.md, "time to first image"),
    /// and the default until [`Self::Linear`].
    VeryFast,
    /// obvhs fast_build.
    Fast,
    /// obvhs medium_build.
    Medium,
    /// obvhs slow_build.
    Slow,
}

impl crate::names::Named for BvhQuality {
    const ALL: &'static [Self] = &[
        Self::Linear,
        Self::Fastest,
        Self::VeryFast,
        Self::Fast,
        Self::Medium,
        Self::Slow,
    ];
    fn name(self) -> &'static str {
        match self {
            Self::Linear => "linear",
            Self::Fastest => "fastest",
            Self::VeryFast => "very_fast",
            Self::Fast => "fast",
            Self::Medium => "medium",
            Self::Slow => "slow",
        }
    }
}

impl BvhQuality {
    /// The obvhs preset's parameters, pre-splits off; None for [`Self::Linear`]
    /// (not obvhs's builder).
    fn params(self) -> Option<BvhBuildParams> {
        let mut p = match self {
            BvhQuality::Linear => return None,
            BvhQuality::Fastest => BvhBuildParams::fastest_build(),
            BvhQuality::VeryFast => BvhBuildParams::very_fast_build(),
            BvhQuality::Fast => BvhBuildParams::fast_build(),
            BvhQuality::Medium => BvhBuildParams::medium_build(),
            BvhQuality::Slow => BvhBuildParams::slow_build(),
        };
        p.pre_split = false;
        Some(p)
    }
}

#[derive(Debug, Clone, Copy)]
struct Node {
    /// Leaf: index of the first prim in `prims`; inner: index of the first child.
    first: u32,
    /// Leaf: number of prims; inner: 0.
    count: u32,
}

/// A BVH over the scene's non-degenerate triangles, with boxes grown for robust tests.
pub struct TraceBvh {
    /// The tree's shape, for shading's general rays.
    nodes: Vec<Node>,
    /// This tree as shading rays walk it (world-space f64 boxes grown for
    /// the current eye, f64 triangles), made the first time a general ray
    /// needs it (a frame of pixel rays never does): [`Self::rays`].
    general: std::sync::OnceLock<general::GeneralTree>,
    /// The shading rays' SAH tree for path tracing, made on first use:
    /// [`Self::path_rays`].
    sah: std::sync::OnceLock<general::GeneralTree>,
    /// The eye the tree is aimed at.
    eye: glam::DVec3,
    prims: Vec<u32>,
    /// The same tree as eye-relative f32 boxes, for pixel rays ([`primary`]),
    /// laid out for traversal ([`nodes`]).
    nodes32: Nodes32,
    /// Where each of `nodes32`'s slots comes from (camera-independent).
    layout: nodes::Layout,
    /// `refit` in `layout`'s slot order, so a new camera reads it in order.
    refit_slots: Vec<[Vec3; 2]>,
    /// Per-prim edge data and pixel rectangles ([`rect`]) in `prims`
    /// order, for pixel rays, each leaf set up when a ray first reaches it
    /// ([`lazy`]).
    aimed: lazy::AimedLeaves,
    /// Every packet's frustum planes ([`frustum`]).
    planes: frustum::PacketPlanes,
    /// Each node's f32 box refit from its triangles, before growth: the
    /// camera-independent tree [`Self::aim`] grows again for a new eye.
    refit: Vec<[Vec3; 2]>,
    /// Seconds of the whole build: [`Self::tree_seconds`] plus
    /// [`Self::camera_seconds`].
    pub build_seconds: f64,
    /// Seconds of the camera-independent part (the builder, the refit).
    pub tree_seconds: f64,
    /// Seconds of the last camera set-up (eye-relative node boxes, packet
    /// frustum planes): what a new camera costs with the tree kept before
    /// its first frame ([`Self::aim`]); each leaf's edge data and pixel
    /// rectangles are made by the frame's first ray to reach it (`trace/lazy.rs`),
    /// so that part is in the frame's time.
    pub camera_seconds: f64,
}

/// The obvhs tree for `params` over the scene's triangles `ids`, its prims
/// indices into `ids`; None once `deadline` has passed ([`build`]).
fn obvhs_tree(
    scene: &ResolvedScene,
    ids: &[u32],
    params: BvhBuildParams,
    deadline: Option<Instant>,
) -> Option<obvhs::bvh2::Bvh2> {
    let tris: Vec<Triangle> = ids
        .iter()
        .map(|&i| {
            let t = &scene.triangles[i as usize];
            Triangle {
                v0: t[0].into(),
                v1: t[1].into(),
                v2: t[2].into(),
            }
        })
        .collect();
    // Triangles sharing a box go to the builder as one primitive
    // (`same_box`: its merging is quadratic in them otherwise).
    let groups = same_box::SameBoxGroups::find(&tris);
    let build_input = groups.as_ref().map_or(&tris[..], |g| &g.reps[..]);
    if crate::deadline::past(deadline) {
        return None;
    }
    let mut bvh = build::build_bvh2(build_input, params, deadline)?;
    if let Some(g) = &groups {
        let mut first_count: Vec<(u32, u32)> = bvh
            .nodes
            .iter()
            .map(|nd| (nd.first_index, nd.prim_count))
            .collect();
        g.expand(&mut first_count, &mut bvh.primitive_indices);
        for (nd, &(first, count)) in bvh.nodes.iter_mut().zip(&first_count) {
            if count > 0 {
                (nd.first_index, nd.prim_count) = (first, count);
            }
        }
    }
    Some(bvh)
}

/// A box with nothing in it: the start of [`grow_bounds`]' fold.
pub(super) const NO_BOUNDS: [Vec3; 2] = [Vec3::INFINITY, Vec3::NEG_INFINITY];

/// Box `b` grown by triangle `t`: the one expression every leaf box is
/// made with (the refit's and the linear builder's), so they agree bit for
/// bit (even in the sign of a zero, which `min` may pick either way).
#[inline]
pub(super) fn grow_bounds([lo, hi]: [Vec3; 2], t: &Tri) -> [Vec3; 2] {
    [
        lo.min(t[0]).min(t[1]).min(t[2]),
        hi.max(t[0]).max(t[1]).max(t[2]),
    ]
}

/// The box of two children's boxes: the one expression every inner box
/// is made with ([`grow_bounds`]).
#[inline]
pub(super) fn union_bounds(a: [Vec3; 2], b: [Vec3; 2]) -> [Vec3; 2] {
    [a[0].min(b[0]), a[1].max(b[1])]
}

/// Every node's box refit from its triangles (post-order), before growth.
/// The leaves' copies hold the triangles in prim order, so a leaf's are
/// read together, not gathered from the scene again.
fn refit_boxes(nodes: &[Node], aimed: &mut lazy::AimedLeaves) -> Vec<[Vec3; 2]> {
    let n = nodes.len();
    let mut refit = vec![NO_BOUNDS; n];
    let mut order = Vec::with_capacity(n);
    let mut stack = vec![0usize];
    while let Some(i) = stack.pop() {
        order.push(i);
        let nd = &nodes[i];
        if nd.count == 0 {
            stack.push(nd.first as usize);
            stack.push(nd.first as usize + 1);
        }
    }
    for &i in order.iter().rev() {
        let nd = &nodes[i];
        refit[i] = if nd.count > 0 {
            (nd.first..nd.first + nd.count)
                .fold(NO_BOUNDS, |b, k| grow_bounds(b, aimed.tri(k as usize)))
        } else {
            let c = nd.first as usize;
            union_bounds(refit[c], refit[c + 1])
        };
    }
    refit
}

impl TraceBvh {
    /// A tree over no triangles: every ray misses.
    fn empty() -> TraceBvh {
        TraceBvh {
            nodes: Vec::new(),
            general: std::sync::OnceLock::new(),
            sah: std::sync::OnceLock::new(),
            eye: glam::DVec3::ZERO,
            prims: Vec::new(),
            nodes32: Nodes32::empty(),
            layout: nodes::Layout::default(),
            refit_slots: Vec::new(),
            aimed: lazy::AimedLeaves::empty(),
            planes: frustum::PacketPlanes::empty(),
            refit: Vec::new(),
            build_seconds: 0.0,
            tree_seconds: 0.0,
            camera_seconds: 0.0,
        }
    }

    /// Builds the BVH for this scene and camera (boxes are grown relative to the eye).
    pub fn build(scene: &ResolvedScene, quality: BvhQuality) -> TraceBvh {
        Self::build_until(scene, quality, None).expect("a build without a deadline finishes")
    }

    /// [`Self::build`], or None once `deadline` has passed: it is checked
    /// between the build's phases ([`build`]), so `--timeout` stops a slow
    /// build too.
    pub fn build_until(
        scene: &ResolvedScene,
        quality: BvhQuality,
        deadline: Option<Instant>,
    ) -> Option<TraceBvh> {
        let start = Instant::now();
        let ids: Vec<u32> = (0..scene.triangles.len() as u32)
            .filter(|&i| !scene.degenerate[i as usize])
            .collect();
        if ids.is_empty() {
            return Some(TraceBvh::empty());
        }
        // The linear BVH reads the scene's triangles itself, and its
        // boxes are the refit's, bit for bit (`linear::build`).
        let (bvh, boxes_exact) = match quality.params() {
            None => (linear::build(&scene.triangles, &ids, deadline)?, true),
            Some(params) => (obvhs_tree(scene, &ids, params, deadline)?, false),
        };
        let prims: Vec<u32> = bvh
            .primitive_indices
            .iter()
            .map(|&k| ids[k as usize])
            .collect();
        let nodes: Vec<Node> = bvh
            .nodes
            .iter()
            .map(|nd| Node {
                first: nd.first_index,
                count: nd.prim_count,
            })
            .collect();
        let shape: Vec<(u32, u32)> = nodes.iter().map(|n| (n.first, n.count)).collect();
        let layout = nodes::Layout::new(&shape);
        let mut aimed = lazy::AimedLeaves::new(
            &scene.triangles,
            &prims,
            layout.slots()[1..]
                .iter()
                .filter(|s| s.count > 0)
                .map(|s| (s.first, s.count)),
        );
        // Every box from the f32 triangles, before growth.
        let refit = if boxes_exact {
            let b = |v: glam::Vec3A| Vec3::from(v);
            bvh.nodes
                .iter()
                .map(|n| [b(n.aabb.min), b(n.aabb.max)])
                .collect()
        } else {
            refit_boxes(&nodes, &mut aimed)
        };
        let refit_slots = layout
            .slots()
            .iter()
            .map(|s| refit[s.src as usize])
            .collect();
        let tree_seconds = start.elapsed().as_secs_f64();
        let mut out = TraceBvh {
            nodes,
            general: std::sync::OnceLock::new(),
            sah: std::sync::OnceLock::new(),
            eye: glam::DVec3::ZERO,
            prims,
            nodes32: Nodes32::empty(),
            layout,
            refit_slots,
            aimed,
            planes: frustum::PacketPlanes::empty(),
            refit,
            build_seconds: 0.0,
            tree_seconds,
            camera_seconds: 0.0,
        };
        out.aim_until(scene, deadline)?;
        out.build_seconds = start.elapsed().as_secs_f64();
        Some(out)
    }

    /// Re-aims the tree at `scene.camera`, keeping the camera-independent
    /// tree: recomputes the eye-relative f32 node boxes and the packet
    /// frustum planes, and marks every leaf's edge data and pixel rectangles
    /// (made when a ray first reaches the leaf, `trace/lazy.rs`) and the shading
    /// rays' trees (made for the first general ray) stale, exactly as
    /// [`Self::build`] leaves them, so a render through the re-aimed tree is
    /// bit for bit the render through a fresh build. Returns the seconds it
    /// took (also [`Self::camera_seconds`]): the per-camera cost `bench
    /// peers` counts in its per-frame table besides the frame. `scene` must
    /// hold the triangles the tree was built from (only the camera may
    /// differ): the leaves keep their own copies.
    pub fn aim(&mut self, scene: &ResolvedScene) -> f64 {
        self.aim_until(scene, None)
            .expect("a set-up without a deadline finishes");
        self.camera_seconds
    }

    /// [`Self::aim`], or None once `deadline` has passed (checked between
    /// its phases, as in [`Self::build_until`]).
    fn aim_until(&mut self, scene: &ResolvedScene, deadline: Option<Instant>) -> Option<()> {
        let start = Instant::now();
        if self.prims.is_empty() {
            self.camera_seconds = 0.0;
            return Some(());
        }
        let cam = &scene.camera;
        let eye = cam.eye;
        debug_assert_eq!(self.refit.len(), self.nodes.len());
        // The shading rays' trees wait for the first general ray.
        self.eye = eye;
        self.general = std::sync::OnceLock::new();
        self.sah = std::sync::OnceLock::new();
        // Each slot's box grown from its refit box in slot order: the same
        // bits as its node's world box ([`general`]), read
        // without a gather.
        self.nodes32
            .fill_grown(&self.layout, &self.refit_slots, eye);
        if crate::deadline::past(deadline) {
            return None;
        }
        debug_assert!((0..self.aimed.len())
            .step_by(997)
            .all(|k| *self.aimed.tri(k) == scene.triangles[self.prims[k] as usize]));
        // The leaves: each set up when a ray first reaches it ([`lazy`]).
        self.aimed.aim(cam);
        self.planes = frustum::PacketPlanes::new(cam);
        self.camera_seconds = start.elapsed().as_secs_f64();
        Some(())
    }

    /// Nearest hit key for one pixel ray (and optionally every covering triangle's
    /// facing), with a caller-owned traversal stack reused across pixels.
    ///
    /// Traversal and the first try at each edge sign run in f32 ([`primary`]);
    /// every sign the f32 filter cannot vouch for, and every depth, is decided by
    /// [`crate::visibility`] exactly as the rasterizer decides it.
    pub fn trace_with(
        &self,
        scene: &ResolvedScene,
        ray: &PixelRay,
        c: &mut Counters,
        mut coverage: Option<&mut [u16; 2]>,
        stack: &mut Vec<(u32, f32)>,
    ) -> u64 {
        let cam: &Camera = &scene.camera;
        let mut best = NO_HIT;
        if self.nodes32.is_empty() {
            return best;
        }
        let r = Ray32::new(ray);
        let count_all = coverage.is_some();
        stack.clear();
        c.bvh_nodes_visited += 1;
        let (t0, _, miss) = self.nodes32.get(Nodes32::ROOT).slab(&r.inv);
        if miss {
            return best;
        }
        stack.push((Nodes32::ROOT, t0));
        while let Some((ni, tmin)) = stack.pop() {
            if !count_all && lower_key(tmin, ray) > best {
                continue;
            }
            let node = self.nodes32.get(ni);
            if node.count > 0 {
                let (leaves, _) = self.aimed.get(node.first, node.count);
                for leaf in leaves {
                    let t = &leaf.tri;
                    let signs = [0, 1, 2].map(|k| leaf.edge_sign32(k, r.dir, r.dir_norm));
                    let facing = covers(cam, t, signs, ray, c);
                    if facing == 0 {
                        continue;
                    }
                    if let Some(z) = TriDepth::new(cam, t).depth(cam, ray) {
                        best = best.min(hit_key(z, leaf.prim));
                        if let Some(cov) = coverage.as_deref_mut() {
                            let slot = usize::from(facing > 0);
                            cov[slot] = cov[slot].saturating_add(1);
                        }
                    }
                }
                continue;
            }
            let mut kids = [(node.first, 0.0f32, true); 2];
            for (j, kid) in kids.iter_mut().enumerate() {
                let id = node.first + j as u32;
                c.bvh_nodes_visited += 1;
                let (a, _, miss) = self.nodes32.get(id).slab(&r.inv);
                *kid = (id, a, miss);
            }
            // Push the farther child first so the nearer one is popped first.
            if kids[0].1 < kids[1].1 {
                kids.swap(0, 1);
            }
            for (id, a, miss) in kids {
                if !miss && (count_all || lower_key(a, ray) <= best) {
                    stack.push((id, a));
                }
            }
        }
        best
    }
}

/// Coverage of one candidate by [`covers_by`]: each edge's sign from the f32
/// filter when it is sure, else from [`edge_sign`] (f64 filter, exact
/// arithmetic, tie rule). `signs32` are the filter's answers (0: unsure).
#[inline(always)]
fn covers(
    cam: &Camera,
    t: &crate::scene::resolve::Tri,
    signs32: [i8; 3],
    ray: &PixelRay,
    c: &mut Counters,
) -> i8 {
    covers_by(c, |k, c| {
        if signs32[k] != 0 {
            return signs32[k];
        }
        let (p, q) = (t[k].as_dvec3(), t[(k + 1) % 3].as_dvec3());
        edge_sign(cam, &EdgePlane::new(cam.eye, p, q), ray, c)
    })
}

/// Smallest hit key any triangle inside a box entered at ray parameter `tmin`
/// (from the f32 slab test) can have. The f32 entry may exceed the exact f64
/// entry by a few f32 roundings, so it is lowered by 2^-20 first.
#[inline]
fn lower_key(tmin: f32, ray: &PixelRay) -> u64 {
    let t = f64::from(tmin) * (1.0 - 1.0 / (1u64 << 20) as f64);
    let z = (t * ray.planar).max(0.0) as f32;
    hit_key(z, 0)
}

/// A ray packet's width and height in pixels (for reports that name the kernel).
pub const PACKET_PIXELS: [usize; 2] = [packet::PW, packet::PH];

/// How pixel rays walk the BVH. Both give the same buffers; they differ in speed
/// (and in the traversal counters), which the benchmarks compare.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TraceKernel {
    /// Packets of [`PACKET_PIXELS`] walk the tree together (the default).
    #[default]
    Packets,
    /// One ray at a time.
    SingleRays,
}

impl crate::names::Named for TraceKernel {
    const ALL: &'static [Self] = &[Self::Packets, Self::SingleRays];
    fn name(self) -> &'static str {
        match self {
            Self::Packets => "packets",
            Self::SingleRays => "single-rays",
        }
    }
}

/// Options for one trace render.
#[derive(Debug, Clone, Copy, Default)]
pub struct TraceOptions {
    /// BVH build quality (ignored by [`render_with_bvh`], which is handed a tree).
    pub bvh: BvhQuality,
    /// Count every covering triangle per pixel (front/back); disables pruning
    /// and uses single rays.
    pub count_coverage: bool,
    /// Packets or single rays.
    pub kernel: TraceKernel,
    /// Stop tracing when this passes (`check --timeout`); the frame is then partial.
    pub deadline: Option<Instant>,
}

/// Renders depth and IDs by ray tracing. `progress` is called with rows finished.
pub fn render(scene: &ResolvedScene, opts: TraceOptions, progress: &(dyn Fn(u64) + Sync)) -> Frame {
    render_keeping_bvh(scene, opts, progress).0
}

/// [`render`], handing back the BVH it built, for callers that shade the
/// frame next (shading traces through the same tree: one build, not two).
/// The frame's time includes the build.
pub fn render_keeping_bvh(
    scene: &ResolvedScene,
    opts: TraceOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> (Frame, TraceBvh) {
    let start = Instant::now();
    // Past the deadline the build stops; the empty tree then traces no
    // triangle and the caller discards the frame ([`crate::deadline::past`]).
    let bvh = TraceBvh::build_until(scene, opts.bvh, opts.deadline).unwrap_or_else(TraceBvh::empty);
    let mut frame = render_with_bvh(scene, &bvh, opts, progress);
    frame.seconds = start.elapsed().as_secs_f64();
    (frame, bvh)
}

/// Traces every pixel through an already built BVH (benchmarks time the two phases apart).
pub fn render_with_bvh(
    scene: &ResolvedScene,
    bvh: &TraceBvh,
    opts: TraceOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> Frame {
    let start = Instant::now();
    let t = trace_keys(scene, bvh, opts, progress);
    t.into_frame(scene, start.elapsed().as_secs_f64())
}

/// Traces every pixel and stops at the per-pixel hit keys: the part of a
/// render that answers ray queries, which the throughput benchmark compares
/// with Embree's `rtcIntersect*` loop (that also stops at keys).
pub fn trace_keys(
    scene: &ResolvedScene,
    bvh: &TraceBvh,
    opts: TraceOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> PixelKeys {
    let cam = &scene.camera;
    let w = cam.width as usize;
    if !opts.count_coverage && opts.kernel == TraceKernel::Packets {
        let (keys, counters) = packet_keys(scene, bvh, opts, progress);
        return PixelKeys {
            keys,
            coverage: None,
            counters,
            renderer: "trace",
        };
    }
    let mut keys = vec![NO_HIT; cam.pixel_count()];
    let mut cov = vec![[0u16; 2]; if opts.count_coverage { keys.len() } else { 0 }];
    let counters: Counters = if opts.count_coverage {
        keys.par_chunks_mut(w)
            .zip(cov.par_chunks_mut(w))
            .enumerate()
            .map(|(y, (row, crow))| {
                let mut c = Counters::default();
                if crate::deadline::past(opts.deadline) {
                    return c;
                }
                let mut stack = Vec::with_capacity(64);
                for (x, (k, cv)) in row.iter_mut().zip(crow.iter_mut()).enumerate() {
                    let ray = cam.pixel_ray(x as u32, y as u32);
                    *k = bvh.trace_with(scene, &ray, &mut c, Some(cv), &mut stack);
                }
                progress(1);
                c
            })
            .reduce(Counters::default, sum)
    } else {
        // Single rays (packets returned above).
        keys.par_chunks_mut(w)
            .enumerate()
            .map(|(y, row)| {
                let mut c = Counters::default();
                if crate::deadline::past(opts.deadline) {
                    return c;
                }
                let mut stack = Vec::with_capacity(64);
                for (x, k) in row.iter_mut().enumerate() {
                    let ray = cam.pixel_ray(x as u32, y as u32);
                    *k = bvh.trace_with(scene, &ray, &mut c, None, &mut stack);
                }
                progress(1);
                c
            })
            .reduce(Counters::default, sum)
    };
    PixelKeys {
        keys,
        coverage: opts.count_coverage.then_some(cov),
        counters,
        renderer: "trace",
    }
}

/// The packet kernel over every pixel: bands of `PH` rows, packets of
/// `PW` x `PH` pixels. The key buffer is never filled before the parallel
/// loop (neither by a serial fill nor by `calloc`'s, which reused memory
/// needs): each band writes every key of its rows, a band cut off by the
/// deadline `NO_HIT`, so the whole buffer is written before it is read.
fn packet_keys(
    scene: &ResolvedScene,
    bvh: &TraceBvh,
    opts: TraceOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> (Vec<u64>, Counters) {
    use std::mem::MaybeUninit;
    let cam = &scene.camera;
    let (w, n) = (cam.width as usize, cam.pixel_count());
    let mut keys: Vec<u64> = Vec::with_capacity(n);
    let counters = keys.spare_capacity_mut()[..n]
        .par_chunks_mut(w * packet::PH)
        .enumerate()
        .map(|(band, rows): (usize, &mut [MaybeUninit<u64>])| {
            let mut c = Counters::default();
            if crate::deadline::past(opts.deadline) {
                fill_no_hit(rows);
                return c;
            }
            let mut stack = Vec::with_capacity(64);
            let y0 = band * packet::PH;
            // Every pixel of the band lies in exactly one packet's lanes.
            for x0 in (0..w).step_by(packet::PW) {
                let pk = bvh.trace_packet(scene, x0, y0, &mut c, &mut stack);
                for (i, &k) in pk.iter().enumerate() {
                    let (x, dy) = (x0 + i % packet::PW, i / packet::PW);
                    if x < w && dy * w < rows.len() {
                        rows[dy * w + x] = MaybeUninit::new(k);
                    }
                }
            }
            progress((rows.len() / w) as u64);
            c
        })
        .reduce(Counters::default, sum);
    // SAFETY: the `n` keys were all written above (each band writes every
    // pixel of its rows: columns `0..w` in steps of `PW` lanes, rows `0..PH`
    // clipped to the band, or `NO_HIT` throughout), and `n <= capacity`.
    unsafe { keys.set_len(n) };
    (keys, counters)
}

fn sum(mut a: Counters, b: Counters) -> Counters {
    a += b;
    a
}

/// A closest hit of a general ray (shading queries, not the visibility predicate).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayHit {
    /// Triangle id.
    pub prim: u32,
    /// Ray parameter of the hit.
    pub t: f64,
}

/// The part `o + t d`, `t` in `(tmin, tmax)`, of a general ray: what
/// shading asks the tracer about (path and shadow rays), as one value so
/// every query and its walk take the same four numbers together.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// Origin.
    pub o: glam::DVec3,
    /// Direction (not necessarily unit).
    pub d: glam::DVec3,
    /// Lower end of the open parameter interval.
    pub tmin: f64,
    /// Upper end of the open parameter interval.
    pub tmax: f64,
}

impl TraceBvh {
    /// Closest hit on the segment `s` ([`Self::rays`]).
    pub fn closest(&self, scene: &ResolvedScene, s: Segment) -> Option<RayHit> {
        self.rays(scene).closest(s)
    }

    /// True when anything lies on the segment `s` ([`Self::rays`]).
    pub fn occluded(&self, scene: &ResolvedScene, s: Segment) -> bool {
        self.rays(scene).occluded(s)
    }

    /// Shading rays through this tree's own shape, laid out for them
    /// ([`general::GeneralTree::from_tree`]; made in one pass on first use
    /// after each [`Self::aim`]): for renders that trace a few rays per
    /// pixel (direct lighting's shadow rays).
    pub fn rays(&self, scene: &ResolvedScene) -> Rays<'_> {
        if self.nodes.is_empty() {
            return Rays { tree: None };
        }
        // Serially: a parallel loop here could steal a task that asks for
        // the same tree while it is being made, which `OnceLock` forbids.
        let tree = self.general.get_or_init(|| {
            general::GeneralTree::from_tree(
                &self.nodes,
                &self.refit,
                &self.prims,
                &scene.triangles,
                self.eye,
            )
        });
        Rays { tree: Some(tree) }
    }

    /// Shading rays through a tree of their own, built by SAH on first use
    /// after each [`Self::aim`] ([`general`]): for renders that trace many
    /// rays per pixel (path tracing), whose rays it serves several times
    /// faster on closed rooms than the visibility tree's shape, while its
    /// build costs more than a few rays per pixel save on large meshes.
    /// Same answers as [`Self::rays`].
    pub fn path_rays(&self, scene: &ResolvedScene) -> Rays<'_> {
        if self.nodes.is_empty() {
            return Rays { tree: None };
        }
        let tree = self
            .sah
            .get_or_init(|| general::GeneralTree::sah(&self.prims, &scene.triangles, self.eye));
        Rays { tree: Some(tree) }
    }
}

/// Shading rays' queries through one of a [`TraceBvh`]'s shading trees
/// ([`TraceBvh::rays`], [`TraceBvh::path_rays`]).
#[derive(Debug, Clone, Copy)]
pub struct Rays<'a> {
    /// None for a tree over no triangles.
    tree: Option<&'a general::GeneralTree>,
}

impl Rays<'_> {
    /// Closest hit on the segment `s`; used by shading (shadow and path rays).
    pub fn closest(self, s: Segment) -> Option<RayHit> {
        self.tree?.query(s, false)
    }

    /// True when anything lies on the segment `s`.
    pub fn occluded(self, s: Segment) -> bool {
        self.tree.is_some_and(|t| t.query(s, true).is_some())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tree built for one camera and re-aimed at another traces exactly
    /// what a fresh build for the second camera traces (keys and every
    /// counter, in both kernels), so `bench peers` can time a new camera
    /// apart from the tree without changing a bit of the output; and the
    /// build's seconds split into the tree's and the camera's.
    #[test]
    fn aim_at_a_new_camera_equals_a_fresh_build() {
        let file =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/icosphere.toml");
        let mut s = crate::scene::Scene::load(&file).unwrap();
        let first = ResolvedScene::resolve(&s).unwrap();
        // Another eye (closer, from the other side), the same triangles.
        s.file.camera.eye = Some([-1.9, 0.8, 2.2]);
        let second = ResolvedScene::resolve(&s).unwrap();
        assert_eq!(first.triangles, second.triangles);
        assert_ne!(first.camera.eye, second.camera.eye);
        for quality in [BvhQuality::Linear, BvhQuality::Fastest, BvhQuality::Medium] {
            let mut aimed = TraceBvh::build(&first, quality);
            assert!(aimed.tree_seconds > 0.0 && aimed.camera_seconds > 0.0);
            assert!(aimed.tree_seconds + aimed.camera_seconds <= aimed.build_seconds);
            let secs = aimed.aim(&second);
            assert_eq!(secs, aimed.camera_seconds);
            let fresh = TraceBvh::build(&second, quality);
            for kernel in [TraceKernel::Packets, TraceKernel::SingleRays] {
                let opts = TraceOptions {
                    kernel,
                    ..TraceOptions::default()
                };
                let a = trace_keys(&second, &aimed, opts, &|_| {});
                let f = trace_keys(&second, &fresh, opts, &|_| {});
                assert!(f.keys.iter().any(|&k| k != NO_HIT));
                assert_eq!(a.keys, f.keys, "{quality:?} {kernel:?}");
                assert_eq!(a.counters, f.counters, "{quality:?} {kernel:?}");
            }
            // Back at the first camera: the leaves and nodes rewritten in
            // place a second time are a fresh build's again.
            aimed.aim(&first);
            let fresh = TraceBvh::build(&first, quality);
            let opts = TraceOptions::default();
            let a = trace_keys(&first, &aimed, opts, &|_| {});
            let f = trace_keys(&first, &fresh, opts, &|_| {});
            assert_eq!(a.keys, f.keys, "{quality:?} back");
            assert_eq!(a.counters, f.counters, "{quality:?} back");
        }
    }

    /// The linear builder's boxes, which the build takes in place of a
    /// refit, are the refit's bit for bit (signs of zeros included: the
    /// scene straddles 0 on every axis), and the tracer through the linear
    /// tree gives the raster's keys, in both kernels.
    #[test]
    fn the_linear_tree_keeps_the_refit_and_the_raster_keys() {
        let file =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/icosphere.toml");
        let s = crate::scene::Scene::load(&file).unwrap();
        let base = ResolvedScene::resolve(&s).unwrap();
        // The icosphere, and copies of it at -0.0 / 0.0 corners, and 300
        // exact duplicates of one triangle.
        let mut tris = base.triangles.clone();
        let z = [
            Vec3::new(-0.0, 0.0, -0.0),
            Vec3::ZERO,
            Vec3::new(0.0, -0.0, 0.0),
        ];
        for k in 0..40 {
            let d = 0.01 * k as f32;
            tris.push([
                z[k % 3],
                Vec3::new(0.5 + d, 0.1, 0.0),
                Vec3::new(0.0, 0.6, -0.3 - d),
            ]);
        }
        tris.extend(std::iter::repeat_n(tris[5], 300));
        for (w, h) in [(64, 48), (37, 23)] {
            let scene = ResolvedScene::from_triangles(base.camera.clone(), tris.clone())
                .resized(w, h)
                .unwrap();
            let mut bvh = TraceBvh::build(&scene, BvhQuality::Linear);
            let canon = refit_boxes(&bvh.nodes, &mut bvh.aimed);
            let bits = |b: &[[Vec3; 2]]| -> Vec<[u32; 6]> {
                b.iter()
                    .map(|[l, h]| [l.x, l.y, l.z, h.x, h.y, h.z].map(f32::to_bits))
                    .collect()
            };
            let (ours, refit) = (bits(&bvh.refit), bits(&canon));
            assert_eq!(ours.len(), refit.len());
            for (i, (a, b)) in ours.iter().zip(&refit).enumerate() {
                assert_eq!(a, b, "node {i}'s box bits");
            }
            let raster = crate::raster::render_keys(&scene, Default::default(), &|_| {});
            assert!(raster.keys.iter().any(|&k| k != NO_HIT));
            for kernel in [TraceKernel::Packets, TraceKernel::SingleRays] {
                let opts = TraceOptions {
                    kernel,
                    bvh: BvhQuality::Linear,
                    ..TraceOptions::default()
                };
                let t = trace_keys(&scene, &bvh, opts, &|_| {});
                assert_eq!(t.keys, raster.keys, "{w}x{h} {kernel:?}");
                let r = render(&scene, opts, &|_| {});
                let f = crate::raster::render(&scene, Default::default(), &|_| {});
                assert_eq!(r.prim, f.prim, "{w}x{h} {kernel:?}");
                assert_eq!(
                    r.z.iter().map(|d| d.to_bits()).collect::<Vec<_>>(),
                    f.z.iter().map(|d| d.to_bits()).collect::<Vec<_>>()
                );
            }
        }
    }

    /// The packet loop writes every key of its never-filled buffer: at
    /// sizes where packets overhang the right and bottom edges its keys are
    /// the single-ray loop's, and past the deadline every key is `NO_HIT`.
    #[test]
    fn packet_keys_cover_every_pixel() {
        let file =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/icosphere.toml");
        let s = crate::scene::Scene::load(&file).unwrap();
        let base = ResolvedScene::resolve(&s).unwrap();
        for (w, h) in [(37, 23), (8, 4), (9, 5), (1, 1), (64, 3)] {
            let scene = base.resized(w, h).unwrap();
            let bvh = TraceBvh::build(&scene, BvhQuality::Medium);
            let packets = trace_keys(&scene, &bvh, TraceOptions::default(), &|_| {});
            let single = TraceOptions {
                kernel: TraceKernel::SingleRays,
                ..TraceOptions::default()
            };
            let single = trace_keys(&scene, &bvh, single, &|_| {});
            assert_eq!(packets.keys, single.keys, "{w}x{h}");
            assert!(packets.keys.iter().any(|&k| k != NO_HIT), "{w}x{h}");
            let past = TraceOptions {
                deadline: Some(Instant::now()),
                ..TraceOptions::default()
            };
            let cut = trace_keys(&scene, &bvh, past, &|_| {});
            assert_eq!(cut.keys.len(), (w * h) as usize);
            assert!(cut.keys.iter().all(|&k| k == NO_HIT), "{w}x{h}");
        }
    }
}
