//! Packet traversal: 8x8 neighbouring pixel rays walk the tree together.
//!
//! Pixel rays are coherent, so a packet pays for one node fetch and one
//! 64-lane slab test where single rays pay for 64. On the million-triangle
//! scene at 1080p, packets ran 1.3x (4x2), 2.2-2.5x (4x4), 2.5-2.6x (8x4) and
//! 2.1x (8x8) faster than single rays before the frustum culling below; with
//! it, 8x8 beat 8x4 by 4-8% on 1 and 2 threads (minimums of 5 runs,
//! alternated, Intel Xeon) and tied on the scanned mesh, so 8x8 it is. Each lane keeps its own
//! mask bit, nearest key and pruning bound, and a lane is tested against a
//! triangle only where the single-ray traversal could have reached it, so every
//! lane's answer is the single-ray answer: the nearest key over all covering
//! candidates, with the same exact coverage and depth functions.
//!
//! Before a leaf triangle's edge tests, the lanes outside its conservative
//! pixel rectangle ([`super::rect`]) are dropped: they cannot be covered, so
//! no key changes. (Sizes were measured again with that culling, before the
//! frustum: 8x8 and 16x4 lost to 8x4 by 3-6%; an AVX-512 build of this kernel and an interval-arithmetic
//! whole-packet box test were no faster on the AMD EPYC test machine.)
//!
//! Where the CPU has AVX-512F, the box test and the edge signs take two rows
//! of lanes in one 512-bit vector ([`Rows::PAIRS`]; a triangle meeting one
//! row of the packet still takes one 256-bit row): on `million` at 1080p the
//! kernel ran 6-11% faster than with 256-bit rows alone (alternated in one
//! process, 2-vCPU Intel Xeon, same keys). An AVX-512 *build* of the AVX2
//! code had run 20% slower; these are intrinsics for the 16-lane steps only.
//!
//! Before a child is pushed, the packet's frustum ([`super::frustum`]) tests
//! it and its sibling in one 8-lane step; a child wholly outside is never
//! pushed, slab-tested or prefetched below. On `million` at 1080p that drops
//! a third of the boxes popped (the kernel ran 5-10% faster, alternated in
//! one process on the 2-vCPU Intel Xeon), with the same keys.
//!
//! Counters: `bvh_nodes_visited` counts the live lanes at each (per-lane)
//! box test, so not the children the frustum culls; `coverage_tests` counts the (triangle, lane) pairs that reach the
//! edge tests, i.e. after the rectangle culling, so it is lower than the
//! single-ray kernel's (which tests every candidate the tree hands it).

use super::frustum::Frustum;
use super::nodes::Nodes32;
use super::primary::{dir_norm_bound, LeafTri, Node32};
use super::rows::{box_out, BoxAxes, Rows, ROW};
use super::{covers, TraceBvh};
use crate::camera::{Camera, PixelRay};
use crate::raster::edges::{ChunkOps, ChunkRays};
use crate::scene::resolve::ResolvedScene;
#[cfg(target_arch = "x86_64")]
use crate::simd::{Avx2, Avx512};
use crate::simd::{Portable, RowLanes};
use crate::visibility::{hit_key, key_depth, Counters, NO_HIT};
use glam::DVec3;

/// Packet width in pixels.
pub(crate) const PW: usize = 8;
/// Packet height in pixels.
pub(crate) const PH: usize = 8;
/// Rays per packet.
pub(crate) const LANES: usize = PW * PH;
/// Rows of comparisons (vectors of [`ROW`] lanes) per packet.
const NROWS: usize = LANES / ROW;
/// The mask bits of one row of comparisons.
const ROW_BITS: Mask = (1 << ROW) - 1;

// A packet row is a whole number of rows of comparisons, and every lane has a mask bit.
const _: () = assert!(PW.is_multiple_of(ROW) && LANES <= Mask::BITS as usize);

/// Lanes `r * ROW ..` of a per-lane array, `W` of them: one row ([`ROW`]) or
/// two ([`super::rows::ROW2`]), as the row operation taking them wants.
#[inline(always)]
fn row<T, const W: usize>(a: &[T; LANES], r: usize) -> &[T; W] {
    a[r * ROW..][..W].try_into().unwrap()
}

/// [`row`] of each axis of a per-lane vector (`dir`, `inv`, `d64`). (Spelled
/// out per axis, not an array `map`: see `rows::edge_signs`.)
#[inline(always)]
fn axis_rows<T, const W: usize>(a: &[[T; LANES]; 3], r: usize) -> [&[T; W]; 3] {
    [row(&a[0], r), row(&a[1], r), row(&a[2], r)]
}

/// The first and last rows with a lane in `m` (not 0): loops over the rows
/// between them, rather than over all rows with a branch on each, ran 4%
/// faster twice over in the leaf (edge signs, then depths; `million`,
/// alternated in one process).
#[inline(always)]
fn live_rows(m: Mask) -> (usize, usize) {
    debug_assert!(m != 0);
    (
        m.trailing_zeros() as usize / ROW,
        (Mask::BITS - 1 - m.leading_zeros()) as usize / ROW,
    )
}

/// Ors the edge signs of the rows from row `r` (one or two rows' bits per
/// edge, certainly positive and certainly negative) into the packet's masks.
#[inline(always)]
fn or_signs((pos, neg): (&mut [Mask; 3], &mut [Mask; 3]), signs: &[(u32, u32); 3], r: usize) {
    for (k, &(p, n)) in signs.iter().enumerate() {
        pos[k] |= Mask::from(p) << (r * ROW);
        neg[k] |= Mask::from(n) << (r * ROW);
    }
}

/// One bit per lane.
pub(crate) type Mask = u64;

/// A packet of pixel rays and their per-lane traversal state (structure of arrays
/// where the slab and edge tests run across lanes).
///
/// Aligned to a cache line, its lane arrays first and each a multiple of 64
/// bytes long (`repr(C)` keeps that order), so every row of 8 lanes is one
/// aligned vector load: with Rust's 8-byte alignment the packet's offset in
/// its stack frame, and so which row loads split cache lines, changed with
/// the frame layout of each build.
#[repr(C, align(64))]
pub(crate) struct Packet {
    /// The exact directions `D` per axis, per lane (depth, and the exact
    /// fallback's rays: [`Packet::ray`]).
    d64: [[f64; LANES]; 3],
    /// `D . forward` per lane.
    planar: [f64; LANES],
    /// `D` per axis, per lane.
    dir: [[f32; LANES]; 3],
    /// `1 / D` per axis, per lane.
    inv: [[f32; LANES]; 3],
    /// `|D|` rounded up, per lane.
    dir_norm: [f32; LANES],
    /// Lower bound on planar depth per unit of f32 slab parameter, per lane.
    zscale: [f32; LANES],
    /// Nearest key so far, per lane.
    pub best: [u64; LANES],
    /// Depth of `best` (+inf when none), for pruning.
    best_z: [f32; LANES],
    /// `sx` per column and `sy` per row, from which [`Packet::ray`] rebuilds
    /// a lane's point on the image plane.
    sx: [f64; PW],
    sy: [f64; PH],
    /// The planes every lane's ray lies inside (whole-packet culling; none
    /// until the tree's [`super::frustum::PacketPlanes`] give them).
    frustum: Frustum,
    /// Lanes inside the image.
    active: Mask,
    /// Per axis, the sign every lane's direction shares (+1 or -1, by the sign
    /// of `1 / D`), or 0 when lanes differ: a shared sign fixes which slab
    /// plane is entered first, saving a min and a max per lane.
    axis_sign: [i8; 3],
    /// Some lane has a subnormal direction component (no depth shortcut:
    /// [`ChunkDepth`]).
    subnormal: bool,
}

// Every lane array is a whole number of cache lines, so each starts on one.
const _: () = assert!(
    (LANES * 4).is_multiple_of(64) && (LANES * 8).is_multiple_of(64) && (PW * 8).is_multiple_of(64)
);

impl Packet {
    /// The packet whose top-left pixel is `(x0, y0)`; lanes outside the image are
    /// inactive. Built lane-parallel (inlined into the AVX2 kernel): `sx` once per
    /// column and `sy` once per row, then [`Camera::screen_ray`]'s arithmetic
    /// axis by axis, so every lane's exact ray is bit for bit
    /// [`Camera::pixel_ray`] (a test checks it). Calling `screen_ray` lane by
    /// lane measured about 6% slower on the million-triangle scene.
    #[inline(always)]
    pub fn new(cam: &Camera, x0: usize, y0: usize) -> Packet {
        let (w, h) = (cam.width as usize, cam.height as usize);
        // Columns or rows past the image give finite rays on inactive lanes.
        // (Plain loops, not `std::array::from_fn`: its closures compiled to
        // out-of-line calls in this kernel, several per packet.)
        let (mut sx, mut sy) = ([0f64; PW], [0f64; PH]);
        for (i, sx) in sx.iter_mut().enumerate() {
            *sx = cam.screen_x((x0 + i) as u32);
        }
        for (j, sy) in sy.iter_mut().enumerate() {
            *sy = cam.screen_y((y0 + j) as u32);
        }
        // `Camera::screen_ray` lane-parallel, one axis at a time (structure of
        // arrays, so the f64 loops vectorize): the same operations in the same
        // order as glam's, hence the same bits.
        let (mut sxl, mut syl) = ([0f64; LANES], [0f64; LANES]);
        for i in 0..LANES {
            (sxl[i], syl[i]) = (sx[i % PW], sy[i / PW]);
        }
        // (The point P and 1 / D are rebuilt by `ray` for the few lanes
        // whose exact fallback needs them.)
        let mut d64 = [[0f64; LANES]; 3];
        for (k, dk) in d64.iter_mut().enumerate() {
            let (e, f, r, u) = (cam.eye[k], cam.forward[k], cam.right[k], cam.up_ortho[k]);
            for (i, d) in dk.iter_mut().enumerate() {
                *d = (e + (f + r * sxl[i] + u * syl[i])) - e;
            }
        }
        let (f0, f1, f2) = (cam.forward.x, cam.forward.y, cam.forward.z);
        let mut planar = [0f64; LANES];
        for (i, p) in planar.iter_mut().enumerate() {
            *p = d64[0][i] * f0 + d64[1][i] * f1 + d64[2][i] * f2;
        }
        let mut subnormal = false;
        for dk in &d64 {
            for v in dk {
                subnormal |= v.is_subnormal();
            }
        }
        let mut active: Mask = 0;
        for i in 0..LANES {
            active |= Mask::from(x0 + i % PW < w && y0 + i / PW < h) << i;
        }
        let mut dir = [[0f32; LANES]; 3];
        let mut inv = [[0f32; LANES]; 3];
        for k in 0..3 {
            for i in 0..LANES {
                dir[k][i] = d64[k][i] as f32;
                inv[k][i] = 1.0 / dir[k][i];
            }
        }
        let mut dir_norm = [0f32; LANES];
        for (i, n) in dir_norm.iter_mut().enumerate() {
            *n = dir_norm_bound([dir[0][i], dir[1][i], dir[2][i]]);
        }
        // Pixel rays have planar > 0 (D = forward + sideways terms), so rounding
        // planar (1 - 2^-18) to nearest stays below planar (1 - 2^-19), and then
        // fl(tmin * zscale) <= tmin * planar * (1 - 2^-20): the single-ray lower key.
        let mut zscale = [0f32; LANES];
        for (z, &p) in zscale.iter_mut().zip(&planar) {
            *z = (p * (1.0 - 1.0 / (1u64 << 18) as f64)) as f32;
        }
        let mut axis_sign = [0i8; 3];
        for (sign, v) in axis_sign.iter_mut().zip(&inv) {
            let (mut pos, mut neg) = (true, true);
            for &x in v {
                (pos, neg) = (pos & (x > 0.0), neg & (x < 0.0));
            }
            *sign = i8::from(pos) - i8::from(neg);
        }
        Packet {
            frustum: Frustum::NONE,
            axis_sign,
            d64,
            planar,
            sx,
            sy,
            subnormal,
            dir,
            inv,
            dir_norm,
            zscale,
            best: [NO_HIT; LANES],
            best_z: [f32::INFINITY; LANES],
            active,
        }
    }

    /// Lane `i`'s exact ray, bit for bit [`Camera::pixel_ray`]'s (the same
    /// arithmetic as `new`, a test checks it).
    #[inline(always)]
    fn ray(&self, cam: &Camera, i: usize) -> PixelRay {
        let (sx, sy) = (self.sx[i % PW], self.sy[i / PW]);
        let p = |k: usize| cam.eye[k] + (cam.forward[k] + cam.right[k] * sx + cam.up_ortho[k] * sy);
        let dir = DVec3::new(self.d64[0][i], self.d64[1][i], self.d64[2][i]);
        PixelRay {
            p: DVec3::new(p(0), p(1), p(2)),
            dir,
            inv_dir: DVec3::new(1.0 / dir.x, 1.0 / dir.y, 1.0 / dir.z),
            planar: self.planar[i],
        }
    }

    /// Lanes of `mask` whose ray may reach something in the box that beats
    /// their best. All lanes take the slab test (skipping rows without a bit
    /// in `mask` measured slower: the branches cost more than the vectors).
    ///
    /// `tmin` starts at 0 rather than -inf, i.e. it is `max(0, tmin)`, which
    /// folds [`Node32::misses`]'s `tmax < 0` into its first comparison and
    /// saves a comparison, a mask move and an or per row, with the same mask:
    /// * `max(0, tmin) > tmax (1 + s)` is `tmin > tmax (1 + s)` or
    ///   `0 > tmax (1 + s)`, and multiplying by `1 + s > 1` keeps the sign of
    ///   `tmax` (and -0 stays -0), so the second is `tmax < 0`;
    /// * the pruning test `fl(tmin zscale) > best_z` is unchanged where
    ///   `tmin >= 0`; where `tmin < 0` both forms are false, since `zscale > 0`
    ///   makes `fl(tmin zscale) <= 0`, and `best_z > 0` always (+inf, or a
    ///   depth that passed `z >= near > 0`; `Camera::new` rejects `near <= 0`).
    #[inline(always)]
    fn node_mask<S: Rows>(&self, s: S, node: &Node32, mask: Mask) -> Mask {
        // Per axis, the bounds in the order `rows::box_out` takes them: with
        // one sign on every lane (lo <= hi and rounding is monotone), min(t0,
        // t1) is always the same one of the two, saving a min and a max per lane.
        let mut axes = [(0f32, 0f32, false); 3];
        for (k, a) in axes.iter_mut().enumerate() {
            let (lo, hi) = node.bounds(k);
            *a = match self.axis_sign[k] {
                0 => (lo, hi, true),
                s if s > 0 => (lo, hi, false),
                _ => (hi, lo, false),
            };
        }
        // A lane misses as in `Node32::misses` (see above for its `tmax < 0`),
        // or is pruned when even the box's entry is beyond its best hit. Row
        // by row, so each row's interval stays in registers (a whole-packet
        // `tmin`/`tmax` array went through the stack, and its cost moved with
        // the compiler's inlining: 2.5x slower kernel in an LTO build).
        let m = if S::PAIRS {
            self.box_rows(s.two(), &axes)
        } else {
            self.box_rows(s.one(), &axes)
        };
        m & mask
    }

    /// The box test's bits over the whole packet, set where a lane may
    /// enter, `W` lanes (a row or a pair of rows) at a time.
    #[inline(always)]
    fn box_rows<const W: usize, L: RowLanes<W>>(&self, l: L, axes: &BoxAxes) -> Mask {
        let mut m: Mask = 0;
        for r in (0..NROWS).step_by(W / ROW) {
            let (inv, zscale) = (axis_rows(&self.inv, r), row(&self.zscale, r));
            let out = box_out(l, axes, inv, zscale, row(&self.best_z, r));
            m |= (Mask::from(!out) & ((1 << W) - 1)) << (r * ROW);
        }
        m
    }

    /// Tests one triangle against the lanes in `m`, updating their nearest keys.
    ///
    /// The f32 edge signs of all lanes come first, as masks. Lanes that
    /// [`covers_by`](crate::visibility::covers_by) would reject from f32 signs
    /// alone (the first two certain and opposite, or the first two agreeing and
    /// the third certain and opposite) and lanes all three of whose signs agree
    /// are settled from the masks, with the counts `covers_by` would make; only
    /// lanes with an unsure sign take the per-lane path. The caller has already
    /// removed the lanes outside the triangle's pixel rectangle from `m`.
    #[inline(always)]
    fn leaf<S: Rows, L: ChunkOps>(
        &mut self,
        (s, l): (S, L),
        cam: &Camera,
        leaf: &LeafTri,
        m: Mask,
        c: &mut Counters,
    ) {
        let mut pos = [0 as Mask; 3];
        let mut neg = [0 as Mask; 3];
        let (first, last) = live_rows(m);
        if S::PAIRS {
            // Pairs of rows from the first live row to the last (a pair
            // that would pass the packet's end starts a row earlier). A
            // rectangle's rows are contiguous, so a pair rarely takes a row
            // without a live lane. Lanes outside `m` get signs nothing reads.
            let mut r = first;
            while r <= last {
                let at = r.min(NROWS - 2);
                let dir = axis_rows(&self.dir, at);
                let signs = leaf.edge_rows(s.two(), dir, row(&self.dir_norm, at));
                or_signs((&mut pos, &mut neg), &signs, at);
                r += 2;
            }
        } else {
            for r in first..=last {
                // A row of lanes is one 256-bit vector: skip rows the box let no lane into.
                if (m >> (r * ROW)) & ROW_BITS == 0 {
                    continue;
                }
                let dir = axis_rows(&self.dir, r);
                let signs = leaf.edge_rows(s.one(), dir, row(&self.dir_norm, r));
                or_signs((&mut pos, &mut neg), &signs, r);
            }
        }
        let [p0, p1, p2] = pos;
        let [n0, n1, n2] = neg;
        let rejected = m & ((p0 & n1) | (n0 & p1) | (p0 & p1 & n2) | (n0 & n1 & p2));
        let inside = m & ((p0 & p1 & p2) | (n0 & n1 & n2));
        let unsure = m & !rejected & !inside;
        c.coverage_tests += u64::from(rejected.count_ones() + inside.count_ones());
        c.covered += u64::from(inside.count_ones());
        let mut hit = inside;
        let mut lanes = unsure;
        while lanes != 0 {
            let i = lanes.trailing_zeros() as usize;
            lanes &= lanes - 1;
            let signs = [0, 1, 2].map(|k| ((pos[k] >> i) & 1) as i8 - ((neg[k] >> i) & 1) as i8);
            if covers(cam, &leaf.tri, signs, &self.ray(cam, i), c) != 0 {
                hit |= 1 << i;
            }
        }
        if hit == 0 {
            return;
        }
        // Depths a row of 8 lanes at a time, as the rasterizer's chunks take
        // them (`ChunkDepth`: `TriDepth::depth` bit for bit, mostly without
        // the slab clamp).
        let d = l.chunk_depth(cam, &leaf.tri);
        let (first, last) = live_rows(hit);
        for r in first..=last {
            let need = ((hit >> (r * ROW)) & ROW_BITS) as u32;
            if need == 0 {
                continue;
            }
            let rays = ChunkRays {
                d: axis_rows(&self.d64, r),
                planar: row(&self.planar, r),
                subnormal: self.subnormal,
            };
            let (z, ok) = d.depths(l, cam, rays, need);
            let mut m = need & ok;
            while m != 0 {
                let j = m.trailing_zeros() as usize;
                m &= m - 1;
                let i = r * ROW + j;
                let k = hit_key(z[j], leaf.prim);
                if k < self.best[i] {
                    self.best[i] = k;
                    self.best_z[i] = key_depth(k);
                }
            }
        }
    }
}

impl TraceBvh {
    /// Traces the packet whose top-left pixel is `(x0, y0)` to completion and
    /// returns its lanes' nearest keys (only those: handing back the whole
    /// 8 KB packet cost a tenth of the kernel's time in copies, at 4 KB).
    /// On x86-64 CPUs with AVX2 the same code runs compiled for 256-bit
    /// vectors (the packet set-up's lane loops auto-vectorized; the box
    /// test and edge signs as intrinsics, rows of comparisons read off with
    /// `vmovmskps`, see [`super::rows`]); the arithmetic is unchanged, as
    /// neither Rust nor the intrinsics contract a*b+c into an FMA.
    pub(crate) fn trace_packet(
        &self,
        scene: &ResolvedScene,
        x0: usize,
        y0: usize,
        c: &mut Counters,
        stack: &mut Vec<(u32, Mask)>,
    ) -> [u64; LANES] {
        #[cfg(target_arch = "x86_64")]
        if let Some(avx512) = Avx512::detect() {
            // SAFETY: the token proves the CPU supports AVX-512F, AVX2 and POPCNT.
            return unsafe { self.trace_packet_avx512(avx512, scene, x0, y0, c, stack) };
        }
        #[cfg(target_arch = "x86_64")]
        if let Some(avx2) = Avx2::detect() {
            // SAFETY: the token proves the CPU supports AVX2 and POPCNT.
            return unsafe { self.trace_packet_avx2(avx2, scene, x0, y0, c, stack) };
        }
        self.trace_packet_body(((Portable, Portable), Portable), scene, x0, y0, c, stack)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,popcnt")]
    fn trace_packet_avx2(
        &self,
        avx2: Avx2,
        scene: &ResolvedScene,
        x0: usize,
        y0: usize,
        c: &mut Counters,
        stack: &mut Vec<(u32, Mask)>,
    ) -> [u64; LANES] {
        // Rows in AVX2; no pairs (in plain Rust, never taken).
        self.trace_packet_body(((avx2, Portable), avx2), scene, x0, y0, c, stack)
    }

    /// [`TraceBvh::trace_packet_avx2`] with pairs of rows in 512-bit vectors.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,avx512f,popcnt")]
    fn trace_packet_avx512(
        &self,
        avx512: Avx512,
        scene: &ResolvedScene,
        x0: usize,
        y0: usize,
        c: &mut Counters,
        stack: &mut Vec<(u32, Mask)>,
    ) -> [u64; LANES] {
        // Pairs of rows in AVX-512; single rows (the frustum test, a
        // triangle meeting one row) and the depths' f64 chunks stay AVX2's.
        let avx2 = avx512.avx2();
        self.trace_packet_body(((avx2, avx512), avx2), scene, x0, y0, c, stack)
    }

    /// Prefetches what popping `n` will read next: its children, or its
    /// triangles' first lines.
    #[inline(always)]
    fn prefetch_below(&self, n: &Node32) {
        if n.count == 0 {
            self.nodes32.prefetch_children(n);
        } else {
            self.aimed.prefetch(n.first, n.count);
        }
    }

    #[inline(always)]
    fn trace_packet_body<S: Rows, L: ChunkOps>(
        &self,
        (s, l): (S, L),
        scene: &ResolvedScene,
        x0: usize,
        y0: usize,
        c: &mut Counters,
        stack: &mut Vec<(u32, Mask)>,
    ) -> [u64; LANES] {
        let cam = &scene.camera;
        let mut pk = Packet::new(cam, x0, y0);
        if self.nodes32.is_empty() || pk.active == 0 {
            return pk.best;
        }
        pk.frustum = self.planes.packet(x0, y0);
        // Near-to-far child order along the packet's mean direction.
        let mut mean = [0f32; 3];
        for (m, d) in mean.iter_mut().zip(&pk.dir) {
            *m = d.iter().sum();
        }
        stack.clear();
        stack.push((Nodes32::ROOT, pk.active));
        while let Some((ni, mask)) = stack.pop() {
            let node = self.nodes32.get(ni);
            c.bvh_nodes_visited += u64::from(mask.count_ones());
            let m = pk.node_mask(s, node, mask);
            if m == 0 {
                continue;
            }
            if node.count > 0 {
                let (leaves, rects) = self.aimed.get(node.first, node.count);
                for (leaf, rect) in leaves.iter().zip(rects) {
                    let m = m & rect.lanes(x0 as i32, y0 as i32);
                    if m != 0 {
                        pk.leaf((s, l), cam, leaf, m, c);
                    }
                }
                continue;
            }
            let (a, b) = (node.first, node.first + 1);
            let (na, nb) = (self.nodes32.get(a), self.nodes32.get(b));
            // A child wholly outside the packet's frustum is never pushed
            // (nor what lies below it prefetched).
            match pk.frustum.excludes(s.one(), na, nb) {
                [true, true] => {}
                [false, true] => {
                    self.prefetch_below(na);
                    stack.push((a, m));
                }
                [true, false] => {
                    self.prefetch_below(nb);
                    stack.push((b, m));
                }
                [false, false] => {
                    self.prefetch_below(na);
                    self.prefetch_below(nb);
                    let da = na.center_along(&mean);
                    let db = nb.center_along(&mean);
                    let (near, far) = if da <= db { (a, b) } else { (b, a) };
                    stack.push((far, m));
                    stack.push((near, m));
                }
            }
        }
        pk.best
    }
}

/// Cameras that stress the packet set-up and the frustum: an image that
/// is not a whole number of packets, an eye far from the origin with a wide
/// field of view, and a narrow field of view at 1080p with a tiny near plane.
#[cfg(test)]
pub(super) fn awkward_cameras() -> Vec<Camera> {
    [
        Camera::new(
            DVec3::new(0.3, -2.0, 5.0),
            DVec3::ZERO,
            DVec3::Y,
            60.0,
            37,
            23,
            1e-3,
            100.0,
        ),
        Camera::new(
            DVec3::splat(1e6),
            DVec3::new(1e6, 1e6 + 1.0, 1e6 - 3.0),
            DVec3::Z,
            130.0,
            9,
            5,
            0.5,
            f64::INFINITY,
        ),
        Camera::new(
            DVec3::new(-1.0, 0.0, 0.0),
            DVec3::new(1.0, 1e-3, 0.0),
            DVec3::Y,
            1.0,
            1920,
            1080,
            1e-7,
            1.0,
        ),
    ]
    .map(Result::unwrap)
    .into()
}

#[cfg(test)]
mod tests {
    use super::super::primary::Ray32;
    use super::*;

    /// The AVX2 and AVX-512 kernels (where the CPU has them) and the
    /// portable one give the same keys and the same counts on every packet, and every key is the
    /// single-ray kernel's.
    #[test]
    fn avx2_and_portable_kernels_agree() {
        for (path, size) in [
            ("scenes/icosphere.toml", (61, 35)),
            ("scenes/million.toml", (160, 90)),
        ] {
            let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../..")
                .join(path);
            let s = crate::scene::Scene::load(&file).unwrap();
            let scene = ResolvedScene::resolve(&s)
                .unwrap()
                .resized(size.0, size.1)
                .unwrap();
            let bvh = TraceBvh::build(&scene, crate::trace::BvhQuality::Medium);
            let cam = &scene.camera;
            let mut stack = Vec::new();
            let mut single_stack = Vec::new();
            for y0 in (0..size.1 as usize).step_by(PH) {
                for x0 in (0..size.0 as usize).step_by(PW) {
                    let mut c = Counters::default();
                    let portable = bvh.trace_packet_body(
                        ((Portable, Portable), Portable),
                        &scene,
                        x0,
                        y0,
                        &mut c,
                        &mut stack,
                    );
                    // Each wide kernel the CPU has, against the portable one.
                    #[cfg(target_arch = "x86_64")]
                    {
                        let mut wide = Vec::new();
                        if let Some(avx2) = Avx2::detect() {
                            let mut c2 = Counters::default();
                            // SAFETY: the token proves the CPU supports AVX2 and POPCNT.
                            let k = unsafe {
                                bvh.trace_packet_avx2(avx2, &scene, x0, y0, &mut c2, &mut stack)
                            };
                            wide.push(("avx2", k, c2));
                        }
                        if let Some(avx512) = Avx512::detect() {
                            let mut c2 = Counters::default();
                            // SAFETY: the token proves the CPU supports AVX-512F, AVX2 and POPCNT.
                            let k = unsafe {
                                bvh.trace_packet_avx512(avx512, &scene, x0, y0, &mut c2, &mut stack)
                            };
                            wide.push(("avx512", k, c2));
                        }
                        for (kernel, k, c2) in wide {
                            assert_eq!(k, portable, "{kernel}: {path} packet ({x0}, {y0})");
                            assert_eq!(c2, c, "{kernel}: {path} packet ({x0}, {y0})");
                        }
                    }
                    let active = Packet::new(cam, x0, y0).active;
                    for i in (0..LANES).filter(|i| active >> i & 1 == 1) {
                        let (x, y) = ((x0 + i % PW) as u32, (y0 + i / PW) as u32);
                        let ray = cam.pixel_ray(x, y);
                        let mut cs = Counters::default();
                        let want = bvh.trace_with(&scene, &ray, &mut cs, None, &mut single_stack);
                        assert_eq!(portable[i], want, "{path} pixel ({x}, {y})");
                    }
                }
            }
        }
    }

    /// Every lane's exact ray is bit for bit the camera's pixel ray, its f32
    /// data is that ray's, and exactly the lanes inside the image are active.
    #[test]
    fn packet_rays_are_the_pixel_rays() {
        for cam in awkward_cameras() {
            let (w, h) = (cam.width as usize, cam.height as usize);
            for (x0, y0) in [(0, 0), (w / PW * PW, h / PH * PH), (PW, PH)] {
                let pk = Packet::new(&cam, x0, y0);
                for i in 0..LANES {
                    let (x, y) = (x0 + i % PW, y0 + i / PW);
                    let inside = x < w && y < h;
                    assert_eq!(pk.active >> i & 1 == 1, inside, "lane {i} at ({x}, {y})");
                    let exact = cam.pixel_ray(x as u32, y as u32);
                    assert_eq!(pk.ray(&cam, i), exact, "lane {i} at ({x}, {y})");
                    let r32 = Ray32::new(&exact);
                    assert_eq!([0, 1, 2].map(|k| pk.dir[k][i]), r32.dir);
                    assert_eq!([0, 1, 2].map(|k| pk.inv[k][i]), r32.inv);
                    assert_eq!(pk.dir_norm[i], r32.dir_norm);
                    assert!(f64::from(pk.dir_norm[i]) >= exact.dir.length());
                    // The pruning scale stays below the ray's planar factor by 2^-20.
                    let bound = exact.planar * (1.0 - 1.0 / (1u64 << 20) as f64);
                    assert!(f64::from(pk.zscale[i]) <= bound);
                    assert!(f64::from(pk.zscale[i]) > exact.planar * 0.999);
                }
            }
        }
    }
}
