//! The shading rays' trees (path and shadow rays: [`super::Rays`]), laid
//! out for their walk, in one of two shapes:
//!
//! * [`GeneralTree::from_tree`]: the visibility tree's own shape (obvhs,
//!   built for pixel rays from one eye), made in one pass, for renders
//!   with a few rays per pixel (direct lighting's shadow rays).
//! * [`GeneralTree::sah`]: a binned SAH build with leaves of up to
//!   [`MAX_LEAF`], for path tracing. The obvhs shape served shading rays
//!   badly on closed rooms: on `cornell_gi` it was a chain of room-sized
//!   boxes peeling off one wall at a time, ending in a room-sized leaf of
//!   eight wall triangles, so a path ray tested 12 triangles and a shadow
//!   ray 10; here 3.3 and 0.6 (docs/radiance.md, "Equal time against
//!   Mitsuba"). Its build (about 1.5 µs a triangle) is paid back only by
//!   many rays per pixel.
//!
//! Boxes are the f32 boxes of their triangles grown for the current eye by
//! `grow_box`, as the visibility tree's are, so pruning stays conservative
//! and a query's answer does not depend on the tree (only which of two
//! triangles hit at exactly the same distance is found first may).
//!
//! Each inner node holds both children's boxes side by side, so one slab
//! test (SSE2 on x86-64) does the pair, and each leaf's triangles are in
//! f64 with their edges taken once, in leaf order, so a walk reads neither
//! the prim index nor the scene's f32 corners.

use super::{Node, RayHit, Segment};
use crate::scene::resolve::Tri;
use crate::visibility::{grow_box, slab_od, RayBox};
use glam::{DVec3, Vec3};
use std::mem::MaybeUninit;

/// A child: an inner node (`count == 0`, `first` indexes [`GeneralTree::pairs`])
/// or a leaf (`count` triangles from `first` in [`GeneralTree::tris`]).
#[derive(Debug, Clone, Copy, Default)]
struct Child {
    first: u32,
    count: u32,
}

/// An inner node's two children: their boxes as `b[side][axis][child]`
/// (side 0 the lower corner, 1 the upper).
#[derive(Debug, Clone, Copy)]
struct Pair {
    b: [[[f64; 2]; 3]; 2],
    child: [Child; 2],
}

/// A triangle as Möller–Trumbore reads it: corner `a` and edges `b - a`,
/// `c - a`, each from the f32 corners widened to f64 (the bits the walk
/// over the node array computed per ray).
#[derive(Debug, Clone, Copy)]
struct Tri64 {
    a: DVec3,
    e1: DVec3,
    e2: DVec3,
    prim: u32,
}

impl Tri64 {
    fn new(t: &Tri, prim: u32) -> Tri64 {
        let [a, b, c] = t.map(|v| v.as_dvec3());
        Tri64 {
            a,
            e1: b - a,
            e2: c - a,
            prim,
        }
    }

    /// Möller–Trumbore in f64, both sides, `t` in `(tmin, tmax)`. The
    /// barycentric tests compare against `|det|` instead of dividing first,
    /// so the division is paid only by rays that pass inside the triangle
    /// (most tests are misses).
    #[inline(always)]
    fn intersect(&self, o: DVec3, d: DVec3, tmin: f64, tmax: f64) -> Option<f64> {
        let (e1, e2) = (self.e1, self.e2);
        let p = d.cross(e2);
        let det = e1.dot(p);
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let (sign, adet) = if det > 0.0 { (1.0, det) } else { (-1.0, -det) };
        let s = o - self.a;
        let u = s.dot(p) * sign;
        if !(0.0..=adet).contains(&u) {
            return None;
        }
        let q = s.cross(e1);
        let v = d.dot(q) * sign;
        if v < 0.0 || u + v > adet {
            return None;
        }
        let tt = e2.dot(q) * sign / adet;
        (tt > tmin && tt < tmax).then_some(tt)
    }
}

/// The tree for shading rays, made from a [`super::TraceBvh`] for its current eye.
#[derive(Debug, Clone)]
pub(super) struct GeneralTree {
    root_box: RayBox,
    root: Child,
    pairs: Vec<Pair>,
    tris: Vec<Tri64>,
}

/// A shading ray's slab test with its per-axis choice of near and far
/// plane made once per ray, for rays whose every `1/d` is finite and
/// non-zero. Then no NaN can arise, and plain comparisons give the same
/// interval as [`crate::visibility::slab_od`] (same products, same
/// maximum and minimum) without its per-node branches on `d` and its
/// NaN-aware `max`/`min`.
struct SlabRay {
    o: [f64; 3],
    inv: [f64; 3],
    /// Per axis, the side whose plane the ray enters by: 1 (the upper)
    /// when `d` is negative.
    near: [usize; 3],
}

impl SlabRay {
    /// None when some `1/d` is infinite or zero (the general test handles those).
    fn new(o: DVec3, d: DVec3, inv: DVec3) -> Option<SlabRay> {
        let ok = (0..3).all(|k| d[k] != 0.0 && inv[k].is_finite() && inv[k] != 0.0);
        ok.then(|| SlabRay {
            o: o.to_array(),
            inv: inv.to_array(),
            near: [0, 1, 2].map(|k| usize::from(d[k] < 0.0)),
        })
    }

    /// The entry and exit distances of one box.
    #[inline(always)]
    fn slab(&self, b: &RayBox) -> (f64, f64) {
        let bb = [b.lo.to_array(), b.hi.to_array()];
        let mut a = f64::NEG_INFINITY;
        let mut z = f64::INFINITY;
        for k in 0..3 {
            let n = (bb[self.near[k]][k] - self.o[k]) * self.inv[k];
            let f = (bb[1 - self.near[k]][k] - self.o[k]) * self.inv[k];
            a = max(a, n);
            z = min(z, f);
        }
        (a, z)
    }

    /// The entry distances of both boxes of `p`, and whether the ray
    /// meets each within `(tmin, tmax)` ([`meets`]): [`Self::slab2`]
    /// and [`met2`] two lanes at a time in SSE2 (`simd::enter_pair`, the
    /// same bits: a test compares them).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn enter2(&self, p: &Pair, tmin: f64, tmax: f64) -> ([f64; 2], [bool; 2]) {
        // Written out: an array `map` here was left out of line.
        let [n0, n1, n2] = self.near;
        let near = [&p.b[n0][0], &p.b[n1][1], &p.b[n2][2]];
        let far = [&p.b[1 - n0][0], &p.b[1 - n1][1], &p.b[1 - n2][2]];
        crate::simd::enter_pair(near, far, self.o, self.inv, tmin, tmax)
    }

    /// [`Self::enter2`] on other targets.
    #[cfg(not(target_arch = "x86_64"))]
    #[inline(always)]
    fn enter2(&self, p: &Pair, tmin: f64, tmax: f64) -> ([f64; 2], [bool; 2]) {
        let (a, z) = self.slab2(p);
        met2(a, z, tmin, tmax)
    }

    /// The entry and exit distances of both boxes of `p`.
    #[cfg_attr(all(target_arch = "x86_64", not(test)), allow(dead_code))]
    #[inline(always)]
    fn slab2(&self, p: &Pair) -> ([f64; 2], [f64; 2]) {
        let mut a = [f64::NEG_INFINITY; 2];
        let mut z = [f64::INFINITY; 2];
        for k in 0..3 {
            let (near, far) = (&p.b[self.near[k]][k], &p.b[1 - self.near[k]][k]);
            for c in 0..2 {
                a[c] = max(a[c], (near[c] - self.o[k]) * self.inv[k]);
                z[c] = min(z[c], (far[c] - self.o[k]) * self.inv[k]);
            }
        }
        (a, z)
    }
}

/// `x > y ? x : y`: the fold `SlabRay` uses (a -0.0 is kept as is).
#[inline(always)]
fn max(x: f64, y: f64) -> f64 {
    if x > y {
        x
    } else {
        y
    }
}

/// `x < y ? x : y`.
#[inline(always)]
fn min(x: f64, y: f64) -> f64 {
    if x < y {
        x
    } else {
        y
    }
}

/// True when a ray meets the box whose slab interval is `[a, z]` within
/// `(tmin, tmax)`: not [`crate::visibility::slab_misses`]`(a, z)`, `a <= tmax` and `z >=
/// tmin`, with the same comparisons, evaluated without short circuits so
/// that a node's two tests need no branches.
#[inline(always)]
fn meets(a: f64, z: f64, tmin: f64, tmax: f64) -> bool {
    let tol = (a.abs().min(f64::MAX) + z.abs().min(f64::MAX)) * 4e-16;
    !((a > z + tol) | (z < -tol) | (a > tmax) | (z < tmin))
}

/// The entry distances `a` and [`meets`] for both lanes.
#[inline(always)]
fn met2(a: [f64; 2], z: [f64; 2], tmin: f64, tmax: f64) -> ([f64; 2], [bool; 2]) {
    let m = |c: usize| meets(a[c], z[c], tmin, tmax);
    (a, [m(0), m(1)])
}

/// Deep enough for any tree obvhs builds here; a deeper one spills into a `Vec`.
const STACK: usize = 64;

/// Most triangles a leaf may hold.
const MAX_LEAF: usize = 4;

/// Bins per axis of the SAH build.
const BINS: usize = 32;

/// The SAH cost of testing one pair of boxes, in triangle tests.
const PAIR_COST: f64 = 1.0;

/// One triangle during the build: its f32 box (exact in f64) and centroid.
#[derive(Debug, Clone, Copy)]
struct Item {
    lo: Vec3,
    hi: Vec3,
    c: DVec3,
    prim: u32,
}

/// Half the surface area of the box `[lo, hi]`.
fn half_area(lo: Vec3, hi: Vec3) -> f64 {
    let e = (hi - lo).as_dvec3().max(DVec3::ZERO);
    e.x * e.y + e.y * e.z + e.z * e.x
}

/// The f32 box of `items`.
fn bounds(items: &[Item]) -> (Vec3, Vec3) {
    items.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), it| (lo.min(it.lo), hi.max(it.hi)),
    )
}

/// A split plane of the binned SAH build: centroids in bins below `bin`
/// along `axis` go left.
#[derive(Debug, Clone, Copy)]
struct Split {
    axis: usize,
    cmin: f64,
    scale: f64,
    bin: usize,
}

impl Split {
    /// The bin of centroid coordinate `c` on `axis`.
    fn bin_of(&self, c: f64) -> usize {
        bin(c, self.cmin, self.scale)
    }
}

/// The bin of `c` for bins starting at `cmin`, `scale` bins per unit.
fn bin(c: f64, cmin: f64, scale: f64) -> usize {
    // `as` saturates (and maps NaN to 0), so every value lands in a bin.
    (((c - cmin) * scale) as usize).min(BINS - 1)
}

/// Where to split `items` (box `lo..hi`): the axis and bin with the least
/// binned SAH cost, or None when a leaf costs no more and may hold them,
/// or when no plane separates their centroids.
fn split_plane(items: &[Item], lo: Vec3, hi: Vec3) -> Option<Split> {
    let (cmin, cmax) = items.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(a, b), it| (a.min(it.c), b.max(it.c)),
    );
    let parent = half_area(lo, hi);
    let mut best: Option<(f64, Split)> = None;
    for axis in 0..3 {
        let extent = cmax[axis] - cmin[axis];
        if !(extent > 0.0 && extent.is_finite()) {
            continue;
        }
        let scale = BINS as f64 / extent;
        let mut count = [0usize; BINS];
        let mut blo = [Vec3::splat(f32::INFINITY); BINS];
        let mut bhi = [Vec3::splat(f32::NEG_INFINITY); BINS];
        for it in items {
            let b = bin(it.c[axis], cmin[axis], scale);
            count[b] += 1;
            blo[b] = blo[b].min(it.lo);
            bhi[b] = bhi[b].max(it.hi);
        }
        // The right side's area and count for a split below bin i.
        let mut right = [(0.0, 0usize); BINS];
        let (mut rlo, mut rhi, mut rn) = (blo[BINS - 1], bhi[BINS - 1], 0);
        for i in (1..BINS).rev() {
            rlo = rlo.min(blo[i]);
            rhi = rhi.max(bhi[i]);
            rn += count[i];
            right[i] = (half_area(rlo, rhi), rn);
        }
        let (mut llo, mut lhi, mut ln) = (blo[0], bhi[0], 0);
        for i in 1..BINS {
            llo = llo.min(blo[i - 1]);
            lhi = lhi.max(bhi[i - 1]);
            ln += count[i - 1];
            let (ra, rn) = right[i];
            if ln == 0 || rn == 0 {
                continue;
            }
            let cost = PAIR_COST + (half_area(llo, lhi) * ln as f64 + ra * rn as f64) / parent;
            if best.is_none_or(|(b, _)| cost < b) {
                let cmin = cmin[axis];
                best = Some((
                    cost,
                    Split {
                        axis,
                        cmin,
                        scale,
                        bin: i,
                    },
                ));
            }
        }
    }
    let (cost, split) = best?;
    (items.len() > MAX_LEAF || cost < items.len() as f64).then_some(split)
}

/// Moves the items of `split`'s left side to the front; returns how many.
fn partition(items: &mut [Item], split: &Split) -> usize {
    let mut left = 0;
    for i in 0..items.len() {
        if split.bin_of(items[i].c[split.axis]) < split.bin {
            items.swap(i, left);
            left += 1;
        }
    }
    left
}

impl GeneralTree {
    /// A binned SAH tree over `prims` (their triangles from `triangles`),
    /// each node's box the f32 box of its triangles grown for `eye`: for
    /// renders that trace many rays per pixel (its build takes about 1.5 µs
    /// per triangle, 2 s for `million`'s 1.3M).
    pub(super) fn sah(prims: &[u32], triangles: &[Tri], eye: DVec3) -> GeneralTree {
        let mut items: Vec<Item> = prims
            .iter()
            .map(|&prim| {
                let t = &triangles[prim as usize];
                let (lo, hi) = (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
                let c = (lo.as_dvec3() + hi.as_dvec3()) * 0.5;
                Item { lo, hi, c, prim }
            })
            .collect();
        debug_assert!(!items.is_empty(), "an empty tree has no general walk");
        let (lo, hi) = bounds(&items);
        let mut pairs: Vec<Pair> = Vec::with_capacity(items.len() / MAX_LEAF * 2);
        let mut root = Child::default();
        // Ranges of `items` to make a node of, and the pair slot (pair,
        // side) its reference goes into (None: the root); left before
        // right, so pairs are in depth-first order.
        type Slot = Option<(usize, usize)>;
        let mut todo: Vec<(usize, usize, Slot)> = vec![(0, items.len(), None)];
        while let Some((start, end, slot)) = todo.pop() {
            let range = &mut items[start..end];
            let (lo, hi) = bounds(range);
            let split = split_plane(range, lo, hi);
            // No plane separates too many centroids: halve them as they lie.
            let left = match split {
                Some(sp) => partition(range, &sp),
                None if range.len() > MAX_LEAF => range.len() / 2,
                None => 0,
            };
            let me = if left == 0 {
                Child {
                    first: start as u32,
                    count: range.len() as u32,
                }
            } else {
                pairs.push(Pair {
                    b: [[[0.0; 2]; 3]; 2],
                    child: [Child::default(); 2],
                });
                let at = pairs.len() - 1;
                todo.push((start + left, end, Some((at, 1))));
                todo.push((start, start + left, Some((at, 0))));
                Child {
                    first: at as u32,
                    count: 0,
                }
            };
            match slot {
                Some((at, side)) => {
                    let w = grow_box(eye, lo, hi);
                    let p = &mut pairs[at];
                    p.child[side] = me;
                    for (k, (l, h)) in w.lo.to_array().into_iter().zip(w.hi.to_array()).enumerate()
                    {
                        p.b[0][k][side] = l;
                        p.b[1][k][side] = h;
                    }
                }
                None => root = me,
            }
        }
        let tris = items
            .iter()
            .map(|it| Tri64::new(&triangles[it.prim as usize], it.prim))
            .collect();
        GeneralTree {
            root_box: grow_box(eye, lo, hi),
            root,
            pairs,
            tris,
        }
    }

    /// The tree `nodes` as it is (children of an inner node at `first`
    /// and `first + 1`, leaves over `prims[first..first + count]`), each
    /// node's box `grow_box(eye, refit[i])`: made in one pass, for renders
    /// that trace few rays per pixel.
    pub(super) fn from_tree(
        nodes: &[Node],
        refit: &[[Vec3; 2]],
        prims: &[u32],
        triangles: &[Tri],
        eye: DVec3,
    ) -> GeneralTree {
        let world = |i: usize| grow_box(eye, refit[i][0], refit[i][1]);
        let tris = prims
            .iter()
            .map(|&p| Tri64::new(&triangles[p as usize], p))
            .collect();
        let mut pairs: Vec<Pair> = Vec::with_capacity(nodes.len() / 2);
        // Pairs in depth-first order; `todo` holds (node, the pair slot its
        // reference goes into).
        let mut todo: Vec<(usize, Option<(usize, usize)>)> = vec![(0, None)];
        let mut root = Child::default();
        while let Some((i, slot)) = todo.pop() {
            let nd = nodes[i];
            let me = if nd.count > 0 {
                Child {
                    first: nd.first,
                    count: nd.count,
                }
            } else {
                let c = nd.first as usize;
                let (w0, w1) = (world(c), world(c + 1));
                let b = [
                    [0, 1, 2].map(|k| [w0.lo[k], w1.lo[k]]),
                    [0, 1, 2].map(|k| [w0.hi[k], w1.hi[k]]),
                ];
                pairs.push(Pair {
                    b,
                    child: [Child::default(); 2],
                });
                let at = pairs.len() - 1;
                todo.push((c + 1, Some((at, 1))));
                todo.push((c, Some((at, 0))));
                Child {
                    first: at as u32,
                    count: 0,
                }
            };
            match slot {
                Some((at, k)) => pairs[at].child[k] = me,
                None => root = me,
            }
        }
        GeneralTree {
            root_box: world(0),
            root,
            pairs,
            tris,
        }
    }

    /// Closest hit on `s` (any hit when `any`), with the slab test picked per ray.
    pub(super) fn query(&self, s: Segment, any: bool) -> Option<RayHit> {
        let (o, d) = (s.o, s.d);
        let inv = DVec3::ONE / d;
        match SlabRay::new(o, d, inv) {
            Some(r) => self.walk(s, any, |b| r.slab(b), |p, t0, t1| r.enter2(p, t0, t1)),
            None => self.walk(
                s,
                any,
                |b| slab_od(o, d, inv, b),
                |p, tmin, tmax| {
                    let one = |c: usize| {
                        let lo = DVec3::new(p.b[0][0][c], p.b[0][1][c], p.b[0][2][c]);
                        let hi = DVec3::new(p.b[1][0][c], p.b[1][1][c], p.b[1][2][c]);
                        slab_od(o, d, inv, &RayBox { lo, hi })
                    };
                    let ((a0, z0), (a1, z1)) = (one(0), one(1));
                    met2([a0, a1], [z0, z1], tmin, tmax)
                },
            ),
        }
    }

    /// Front-to-back walk: of an inner node's two children the nearer
    /// entry is visited first (the first on a tie) and the farther waits
    /// on the stack with its entry distance, skipped once a closer hit lies
    /// before it. The stack lives on the call's frame (shading traces
    /// several rays per path, and an allocation per ray was a tenth of the
    /// path tracer's time); a tree deeper than it spills into a `Vec`, so
    /// no tree is too deep.
    #[inline(always)]
    fn walk(
        &self,
        s: Segment,
        any: bool,
        slab: impl Fn(&RayBox) -> (f64, f64),
        enter2: impl Fn(&Pair, f64, f64) -> ([f64; 2], [bool; 2]),
    ) -> Option<RayHit> {
        let Segment {
            o,
            d,
            tmin,
            mut tmax,
        } = s;
        let (a, z) = slab(&self.root_box);
        if !meets(a, z, tmin, tmax) {
            return None;
        }
        let mut best: Option<RayHit> = None;
        // Not zeroed (a kibibyte per ray was a fiftieth of the path
        // tracer's time): only entries below `depth` are ever read.
        let mut stack = [const { MaybeUninit::<(Child, f64)>::uninit() }; STACK];
        let mut depth = 0;
        let mut spill: Vec<(Child, f64)> = Vec::new();
        let mut cur = self.root;
        loop {
            let mut next = None;
            if cur.count > 0 {
                let (lo, hi) = (cur.first as usize, (cur.first + cur.count) as usize);
                for t in &self.tris[lo..hi] {
                    if let Some(tt) = t.intersect(o, d, tmin, tmax) {
                        best = Some(RayHit {
                            prim: t.prim,
                            t: tt,
                        });
                        if any {
                            return best;
                        }
                        tmax = tt;
                    }
                }
            } else {
                let p = &self.pairs[cur.first as usize];
                let (a, [h0, h1]) = enter2(p, tmin, tmax);
                let [c0, c1] = p.child;
                let (near, far) = match (h0, h1) {
                    (true, true) if a[1] < a[0] => (Some(c1), Some((c0, a[0]))),
                    (true, true) => (Some(c0), Some((c1, a[1]))),
                    (true, false) => (Some(c0), None),
                    (false, true) => (Some(c1), None),
                    (false, false) => (None, None),
                };
                if let Some(f) = far {
                    if depth < STACK {
                        stack[depth] = MaybeUninit::new(f);
                        depth += 1;
                    } else {
                        spill.push(f);
                    }
                }
                next = near;
            }
            while next.is_none() {
                let (n, a) = match spill.pop() {
                    Some(f) => f,
                    None if depth > 0 => {
                        depth -= 1;
                        // SAFETY: entries `0..depth` were written by the
                        // pushes above (each push writes `stack[depth]`
                        // before raising `depth`), and `depth` is below
                        // the old depth, so `stack[depth]` was written.
                        unsafe { stack[depth].assume_init() }
                    }
                    None => return best,
                };
                // A hit found since it was pushed may lie before its box.
                if a <= tmax {
                    next = Some(n);
                }
            }
            cur = next.unwrap_or_default();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{BvhQuality, TraceBvh};
    use super::*;
    use crate::scene::resolve::ResolvedScene;
    use crate::visibility::slab_misses;
    use rand::{Rng, SeedableRng};

    /// Brute force over every triangle: the nearest hit's distance on `s`.
    fn nearest(scene: &ResolvedScene, s: Segment) -> Option<f64> {
        (0..scene.triangles.len())
            .filter(|&i| !scene.degenerate[i])
            .filter_map(|i| {
                Tri64::new(&scene.triangles[i], i as u32).intersect(s.o, s.d, s.tmin, s.tmax)
            })
            .min_by(f64::total_cmp)
    }

    /// `meets` is `slab_misses` and the segment's ends, over the values a
    /// slab test gives (infinities, signed zeros, ties, near ties).
    #[test]
    fn meets_is_slab_misses_and_the_ends() {
        let v = [
            f64::NEG_INFINITY,
            -1.0,
            -1e-300,
            -0.0,
            0.0,
            1e-300,
            1.0 - 1e-16,
            1.0,
            1.0 + 2e-16,
            2.0,
            f64::MAX,
            f64::INFINITY,
        ];
        for &a in &v {
            for &z in &v {
                for (tmin, tmax) in [(0.0, f64::INFINITY), (0.0, 1.0), (1.0, 2.0)] {
                    let want = !(slab_misses(a, z) || a > tmax || z < tmin);
                    assert_eq!(meets(a, z, tmin, tmax), want, "{a} {z} {tmin} {tmax}");
                }
            }
        }
    }

    /// On x86-64 the SSE2 pair test gives the scalar test's bits: the same
    /// entry distances and the same verdicts, for random rays against
    /// every pair of `cornell_gi`'s tree and segments that end inside,
    /// before and after the boxes.
    #[test]
    fn pair_test_is_the_scalar_test() {
        let file =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell_gi.toml");
        let scene = ResolvedScene::resolve(&crate::scene::Scene::load(&file).unwrap()).unwrap();
        let prims: Vec<u32> = (0..scene.triangles.len() as u32).collect();
        let tree = GeneralTree::sah(&prims, &scene.triangles, scene.camera.eye);
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(3);
        let mut met = 0;
        for _ in 0..2_000 {
            let o = DVec3::new(
                rng.random_range(-1.5..1.5),
                rng.random_range(-0.5..2.5),
                rng.random_range(-1.5..3.0),
            );
            let d = DVec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            );
            let Some(r) = SlabRay::new(o, d, DVec3::ONE / d) else {
                continue;
            };
            for p in &tree.pairs {
                for (tmin, tmax) in [(0.0, f64::INFINITY), (0.0, 0.5), (1.0, 2.0)] {
                    let (a, z) = r.slab2(p);
                    let (want_a, want) = met2(a, z, tmin, tmax);
                    let (got_a, got) = r.enter2(p, tmin, tmax);
                    assert_eq!(got, want);
                    assert_eq!(got_a.map(f64::to_bits), want_a.map(f64::to_bits));
                    met += want.iter().filter(|&&m| m).count();
                }
            }
        }
        assert!(met > 10_000, "{met}");
    }

    /// Random path and shadow rays (from inside the room and from outside,
    /// some along axes, for the slab test's general case), through either
    /// shading tree, find what a test of every triangle finds: the same nearest distance, a triangle hit
    /// there, and an occlusion answer that agrees.
    #[test]
    fn queries_agree_with_every_triangle() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
        for name in ["cornell_gi.toml", "icosphere.toml"] {
            let s = crate::scene::Scene::load(&root.join(name)).unwrap();
            let scene = ResolvedScene::resolve(&s).unwrap();
            let bvh = TraceBvh::build(&scene, BvhQuality::Medium);
            let (mut hits, mut blocked) = (0, 0);
            for i in 0..20_000 {
                let o = DVec3::new(
                    rng.random_range(-1.5..1.5),
                    rng.random_range(-0.5..2.5),
                    rng.random_range(-1.5..3.0),
                );
                let mut d = DVec3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                );
                if i % 10 == 0 {
                    d[i % 3] = 0.0;
                }
                if i % 50 == 0 {
                    d = DVec3::ZERO;
                    d[(i / 50) % 3] = 1.0;
                }
                let far = Segment {
                    o,
                    d,
                    tmin: 0.0,
                    tmax: f64::INFINITY,
                };
                let short = Segment {
                    tmax: rng.random_range(0.0..3.0),
                    ..far
                };
                let (want, want_short) = (nearest(&scene, far), nearest(&scene, short));
                for (tree, rays) in [("own", bvh.rays(&scene)), ("sah", bvh.path_rays(&scene))] {
                    let got = rays.closest(far);
                    assert_eq!(got.map(|h| h.t), want, "{name} {tree} ray {i}: {far:?}");
                    if let Some(h) = got {
                        hits += 1;
                        let t = &scene.triangles[h.prim as usize];
                        let again = Tri64::new(t, h.prim).intersect(o, d, 0.0, f64::INFINITY);
                        assert_eq!(again, Some(h.t), "{name} {tree} ray {i}");
                    }
                    let occluded = rays.occluded(short);
                    assert_eq!(occluded, want_short.is_some(), "{name} {tree} ray {i}");
                    blocked += usize::from(occluded);
                }
                assert_eq!(bvh.closest(&scene, far), bvh.rays(&scene).closest(far));
            }
            assert!(hits > 2_000 && blocked > 1_000, "{name}: {hits} {blocked}");
        }
    }
}
