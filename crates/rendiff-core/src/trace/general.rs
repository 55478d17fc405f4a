//! The shading rays' copy of the tree (path and shadow rays:
//! [`super::TraceBvh::closest`] and [`super::TraceBvh::occluded`]), laid
//! out for their walk: each inner node holds both children's grown world
//! boxes side by side, so one slab test does the pair, and each leaf's
//! triangles are in f64 with their edges already taken, in the tree's prim
//! order.
//!
//! It is the same tree, the same boxes (`grow_box` of the refit f32 boxes
//! for the current eye), the same pruning rule, the same visiting order and
//! the same Möller–Trumbore arithmetic as the walk over the node array it
//! replaced, so every query returns the same hit bit for bit; only the
//! memory it reads and the work per node changed. Before it, the walk read
//! a node, then each child's box from another array, then each triangle's
//! f32 corners through the prim index, and converted and subtracted them
//! again for every ray: the shading rays' walk was four fifths of the path
//! tracer's time (docs/radiance.md, "Equal time against Mitsuba").

use super::{Node, RayHit, Segment};
use crate::scene::resolve::Tri;
use crate::visibility::{grow_box, slab_misses, slab_od, RayBox};
use glam::{DVec3, Vec3};

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

    /// The entry and exit distances of both boxes of `p`.
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

/// Deep enough for any tree obvhs builds here; a deeper one spills into a `Vec`.
const STACK: usize = 64;

impl GeneralTree {
    /// Lays out the tree `nodes` (children of an inner node at `first` and
    /// `first + 1`, leaves over `prims[first..first + count]`) with each
    /// node's box `grow_box(eye, refit[i])` and each prim's triangle from
    /// `triangles`.
    pub(super) fn new(
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
        // Pairs in depth-first order (a node's nearer-built child next to
        // it); `todo` holds (node, the pair slot its reference goes into).
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
            Some(r) => self.walk(s, any, |b| r.slab(b), |p| r.slab2(p)),
            None => self.walk(
                s,
                any,
                |b| slab_od(o, d, inv, b),
                |p| {
                    let one = |c: usize| {
                        let lo = DVec3::new(p.b[0][0][c], p.b[0][1][c], p.b[0][2][c]);
                        let hi = DVec3::new(p.b[1][0][c], p.b[1][1][c], p.b[1][2][c]);
                        slab_od(o, d, inv, &RayBox { lo, hi })
                    };
                    let ((a0, z0), (a1, z1)) = (one(0), one(1));
                    ([a0, a1], [z0, z1])
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
        slab2: impl Fn(&Pair) -> ([f64; 2], [f64; 2]),
    ) -> Option<RayHit> {
        let Segment {
            o,
            d,
            tmin,
            mut tmax,
        } = s;
        // True when the ray meets the box [a, z] within (tmin, tmax).
        let meets = |a: f64, z: f64, tmax: f64| !(slab_misses(a, z) || a > tmax || z < tmin);
        let (a, z) = slab(&self.root_box);
        if !meets(a, z, tmax) {
            return None;
        }
        let mut best: Option<RayHit> = None;
        let mut stack = [(Child::default(), 0f64); STACK];
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
                let (a, z) = slab2(p);
                let h0 = meets(a[0], z[0], tmax);
                let h1 = meets(a[1], z[1], tmax);
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
                        stack[depth] = f;
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
                        stack[depth]
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
