//! The per-triangle half of a camera's set-up, done the first time a frame
//! needs it.
//!
//! A new camera needs, per leaf triangle, its edge normals relative to the
//! eye ([`LeafTri::aim`]) and its pixel rectangle ([`PixelRect::new`]). Done
//! for every triangle up front this was most of a new camera's cost on the
//! million-triangle scene, yet a frame reads only the triangles of the leaves
//! its rays reach: the triangles facing away behind the visible ones, and
//! those outside the view, are never read. So [`TraceBvh::aim`] only starts a
//! new epoch here, and each BVH leaf is set up when a traversal first reaches
//! it ([`AimedLeaves::get`]).
//!
//! The values do not depend on who computes them or when: each is a pure
//! function of the leaf's triangle and the camera, the same function the
//! eager pass called. So the keys and every counter of a frame are those of
//! the eager set-up, whatever the threads' timing.
//!
//! Thread safety. Each leaf (a range of prims, disjoint from every other
//! leaf's, checked once per tree in [`AimedLeaves::new`]) has one state word
//! keyed by its first prim: `2 e` once set up for epoch `e`, `2 e + 1` while
//! one thread sets it up, anything else when stale. A thread that finds it
//! stale claims it with a compare-and-swap, writes the range, then publishes
//! `2 e` with release ordering; every other reader waits for `2 e` with
//! acquire ordering before it forms a reference to the range. A new epoch
//! starts only through `&mut self`, when no reference to any range is alive.
//!
//! [`TraceBvh::aim`]: super::TraceBvh::aim

use super::primary::LeafTri;
use super::rect::{PixelRect, RectSlack};
use crate::camera::Camera;
use crate::scene::resolve::Tri;
use crate::simd::prefetch;
use std::cell::UnsafeCell;
use std::sync::atomic::{AtomicU32, Ordering};

/// How many prims ahead [`AimedLeaves::new`] starts loading a triangle:
/// enough loads in flight to cover a miss to memory (about 100 ns) at a few
/// ns per copied triangle.
const GATHER_AHEAD: usize = 16;

/// The leaves' per-camera data in prim (BVH) order, set up lazily.
pub(crate) struct AimedLeaves {
    /// Per prim: the triangle, its id, and its edges for the current eye
    /// once its leaf is set up.
    leaves: Vec<UnsafeCell<LeafTri>>,
    /// Per prim: its pixel rectangle for the current camera, likewise.
    rects: Vec<UnsafeCell<PixelRect>>,
    /// Per prim, used at each leaf's first prim: the leaf's state (see the
    /// module comment).
    state: Vec<AtomicU32>,
    /// The current epoch (at least 1, below `u32::MAX / 2`).
    epoch: u32,
    /// The camera the current epoch sets up for.
    cam: Option<Camera>,
    /// Its rectangle allowances.
    slack: Option<RectSlack>,
}

// SAFETY: the cells are written only by the one thread that holds their
// leaf's claim (a successful compare-and-swap of its state to "busy"), and
// read only after the state was seen "ready" with acquire ordering, which
// the writer published with release ordering after its last write; leaves'
// prim ranges are disjoint (checked in `new`), and an epoch changes only
// through `&mut self`. So no cell is ever read and written concurrently.
unsafe impl Sync for AimedLeaves {}

impl AimedLeaves {
    /// No leaves (a tree over no triangles).
    pub fn empty() -> AimedLeaves {
        AimedLeaves {
            leaves: Vec::new(),
            rects: Vec::new(),
            state: Vec::new(),
            epoch: 1,
            cam: None,
            slack: None,
        }
    }

    /// The leaves of prims `prims` (scene ids in BVH order), no camera yet.
    /// `leaf_ranges` are the tree's leaves as `(first, count)`: they must be
    /// disjoint ranges of prim indices (the soundness of the lazy set-up
    /// rests on it, so this panics otherwise).
    pub fn new(
        triangles: &[Tri],
        prims: &[u32],
        leaf_ranges: impl Iterator<Item = (u32, u32)>,
    ) -> AimedLeaves {
        let mut ranges: Vec<(u32, u32)> = leaf_ranges.collect();
        ranges.sort_unstable();
        let mut end = 0u64;
        for &(f, c) in &ranges {
            assert!(
                u64::from(f) >= end && u64::from(f) + u64::from(c) <= prims.len() as u64,
                "BVH leaves overlap or leave the prim array at {f}+{c}"
            );
            end = u64::from(f) + u64::from(c);
        }
        // The triangles are read from the scene in BVH order, scattered over
        // tens of megabytes: each read a cache miss, one after the other,
        // unless the loads of those a few places ahead are started early.
        let mut leaves = crate::huge_pages::with_capacity(prims.len());
        leaves.extend(prims.iter().enumerate().map(|(k, &p)| {
            if let Some(&q) = prims.get(k + GATHER_AHEAD) {
                let t = &triangles[q as usize];
                prefetch(&t[0]);
                prefetch(&t[2]);
            }
            UnsafeCell::new(LeafTri::unaimed(&triangles[p as usize], p))
        }));
        let mut rects = crate::huge_pages::with_capacity(prims.len());
        rects.extend((0..prims.len()).map(|_| UnsafeCell::new(PixelRect::ALL)));
        AimedLeaves {
            leaves,
            rects,
            state: (0..prims.len()).map(|_| AtomicU32::new(0)).collect(),
            epoch: 1,
            cam: None,
            slack: None,
        }
    }

    /// Starts a new camera: every leaf is stale until a traversal reaches it.
    pub fn aim(&mut self, cam: &Camera) {
        self.epoch += 1;
        if self.epoch >= u32::MAX / 2 {
            // States from old epochs could read "ready" again: clear them.
            for s in &mut self.state {
                *s.get_mut() = 0;
            }
            self.epoch = 1;
        }
        self.slack = Some(RectSlack::new(cam));
        self.cam = Some(cam.clone());
    }

    /// Leaf `(first, count)`'s triangles and pixel rectangles for the
    /// current camera, set up now if no traversal has yet. `(first, count)`
    /// must be one of the tree's leaves (as [`Self::new`] was given).
    #[inline(always)]
    pub fn get(&self, first: u32, count: u32) -> (&[LeafTri], &[PixelRect]) {
        let (f, n) = (first as usize, count as usize);
        if self.state[f].load(Ordering::Acquire) != 2 * self.epoch {
            self.set_up(f, n);
        }
        let (leaves, rects) = (&self.leaves[f..f + n], &self.rects[f..f + n]);
        // SAFETY: the leaf's state read "ready" for this epoch with acquire
        // ordering (above or in `set_up`), so its writer's writes happened
        // before, and no cell of the range is written again before the next
        // epoch, which needs `&mut self` (see the impl of `Sync`).
        // `UnsafeCell<T>` has `T`'s layout, so the slices cast.
        unsafe {
            (
                std::slice::from_raw_parts(leaves.as_ptr().cast::<LeafTri>(), n),
                std::slice::from_raw_parts(rects.as_ptr().cast::<PixelRect>(), n),
            )
        }
    }

    /// Sets leaf `f..f + n` up for the current camera, or waits until the
    /// thread that claimed it has.
    #[cold]
    #[inline(never)]
    fn set_up(&self, f: usize, n: usize) {
        let (ready, busy) = (2 * self.epoch, 2 * self.epoch + 1);
        let state = &self.state[f];
        let (Some(cam), Some(slack)) = (&self.cam, &self.slack) else {
            unreachable!("a tree is aimed before it is traced")
        };
        loop {
            let s = state.load(Ordering::Acquire);
            if s == ready {
                return;
            }
            if s != busy
                && state
                    .compare_exchange(s, busy, Ordering::Acquire, Ordering::Relaxed)
                    .is_ok()
            {
                // SAFETY: this thread holds the leaf's claim: no other thread
                // reads or writes these cells until it publishes "ready"
                // below (see the impl of `Sync`).
                unsafe { self.aim_leaf(f, n, cam, slack) };
                state.store(ready, Ordering::Release);
                return;
            }
            std::hint::spin_loop();
        }
    }

    /// Sets up prims `f..f + n` for `cam`: eight at a time in AVX-512 f64
    /// lanes where the CPU has AVX-512F, four in AVX2's where it has AVX2
    /// (the scalar set-up's bits, `LeafTri::aim_lanes` and
    /// `PixelRect::new_lanes`), else one at a time. On `million` a new
    /// camera's leaves were 45% of a frame's CPU one triangle at a time (six
    /// divisions and six square roots after one another); the lanes, their
    /// bounds' rounding and the rectangles' integer ends included, set up
    /// all 1.31M triangles in 0.038 s (AMD EPYC, eight lanes) where four
    /// lanes with a scalar tail took 0.090 s (docs/benchmarks.md).
    ///
    /// # Safety
    /// The calling thread must hold the claim of every leaf in the range (no
    /// other thread reads or writes its cells meanwhile).
    #[inline(always)]
    unsafe fn aim_leaf(&self, f: usize, n: usize, cam: &Camera, slack: &RectSlack) {
        #[cfg(target_arch = "x86_64")]
        if let Some(wide) = crate::simd::Avx512::detect() {
            // SAFETY: the CPU has AVX-512F (just detected); the claim is the
            // caller's.
            unsafe { self.aim_leaf_avx512(wide, f, n, cam, slack) };
            return;
        }
        #[cfg(target_arch = "x86_64")]
        if let Some(avx2) = crate::simd::Avx2::detect() {
            // SAFETY: the CPU has AVX2 (just detected); the claim is the
            // caller's.
            unsafe { self.aim_leaf_avx2(avx2, f, n, cam, slack) };
            return;
        }
        for (leaf, rect) in self.leaves[f..f + n].iter().zip(&self.rects[f..f + n]) {
            // SAFETY: the caller holds the leaf's claim.
            let (leaf, rect) = unsafe { (&mut *leaf.get(), &mut *rect.get()) };
            leaf.aim(cam.eye);
            *rect = PixelRect::new(cam, slack, &leaf.tri);
        }
    }

    /// [`Self::aim_leaf_lanes`] compiled for AVX2, four prims at a time.
    ///
    /// # Safety
    /// As [`Self::aim_leaf`], on a CPU with AVX2 (`l` proves it).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn aim_leaf_avx2(
        &self,
        l: crate::simd::Avx2,
        f: usize,
        n: usize,
        cam: &Camera,
        slack: &RectSlack,
    ) {
        // SAFETY: the caller holds the claim.
        unsafe { self.aim_leaf_lanes(l, f, n, cam, slack) }
    }

    /// [`Self::aim_leaf_lanes`] compiled for AVX-512F, eight prims at a time
    /// (a `slow` or `linear` tree's leaves hold up to eight).
    ///
    /// # Safety
    /// As [`Self::aim_leaf`], on a CPU with AVX-512F (`l` proves it).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,avx512f")]
    unsafe fn aim_leaf_avx512(
        &self,
        l: crate::simd::Avx512,
        f: usize,
        n: usize,
        cam: &Camera,
        slack: &RectSlack,
    ) {
        // SAFETY: the caller holds the claim.
        unsafe { self.aim_leaf_lanes(l, f, n, cam, slack) }
    }

    /// [`Self::aim_leaf`] in `N` f64 lanes, `N` prims at a time (the last
    /// group padded with copies of the range's last triangle, whose lanes
    /// are not kept). Each vertex coordinate is widened into its lanes once
    /// ([`crate::simd::load_tris`]) for both halves of the set-up.
    ///
    /// # Safety
    /// As [`Self::aim_leaf`].
    #[inline(always)]
    unsafe fn aim_leaf_lanes<L: crate::simd::Lanes<N>, const N: usize>(
        &self,
        l: L,
        f: usize,
        n: usize,
        cam: &Camera,
        slack: &RectSlack,
    ) {
        let end = f + n;
        let mut k = f;
        while k < end {
            let m = (end - k).min(N);
            let mut tris = [[glam::Vec3::ZERO; 3]; N];
            for (j, t) in tris.iter_mut().enumerate() {
                // SAFETY: the caller holds the leaf's claim.
                *t = unsafe { (*self.leaves[k + j.min(m - 1)].get()).tri };
            }
            let v = crate::simd::load_tris(l, &tris);
            let (normals, bounds) = LeafTri::aim_lanes(l, &v, cam.eye);
            let rects = PixelRect::new_lanes(l, cam, slack, &v);
            for j in 0..m {
                // SAFETY: the caller holds the leaf's claim.
                let (leaf, rect) = unsafe {
                    (
                        &mut *self.leaves[k + j].get(),
                        &mut *self.rects[k + j].get(),
                    )
                };
                leaf.set_aimed(normals[j], bounds[j]);
                *rect = rects[j];
            }
            k += N;
        }
    }

    /// Prefetches what [`Self::get`] will read for leaf `(first, count)`:
    /// its state, all its rectangles' lines and its triangles.
    #[inline(always)]
    pub fn prefetch(&self, first: u32, count: u32) {
        let (f, n) = (first as usize, count as usize);
        if n == 0 {
            return;
        }
        let (Some(r), Some(t)) = (self.rects.get(f..f + n), self.leaves.get(f..f + n)) else {
            return;
        };
        prefetch(&self.state[f]);
        for r in r.iter().step_by(64 / std::mem::size_of::<PixelRect>()) {
            prefetch(r);
        }
        if let Some(last) = r.last() {
            prefetch(last);
        }
        for t in t {
            prefetch(t);
        }
    }

    /// Prim `k`'s triangle: for checks, and for the tree's refit, which
    /// reads the leaves' copies in prim order instead of the scene's
    /// triangles scattered in BVH order.
    pub fn tri(&mut self, k: usize) -> &Tri {
        &self.leaves[k].get_mut().tri
    }

    /// The number of prims.
    pub fn len(&self) -> usize {
        self.leaves.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::predicate::tests::lcg;
    use crate::simd::{Lanes, Portable};
    use glam::{DVec3, Vec3};

    /// Random triangles for `cam` in every regime the set-up distinguishes:
    /// in front of the eye, with a vertex behind it or on its plane, tiny
    /// (normals below f32's normal range: an infinite bound), huge, far off
    /// the view, and degenerate.
    fn cases(cam: &Camera, s: &mut u64, count: usize) -> Vec<Tri> {
        (0..count)
            .map(|i| {
                let base = cam.eye + cam.forward * (0.5 + 4.0 * lcg(s).abs());
                let size = [1.0, 1e-3, 1e-12, 1e6, 1e-30][i % 5];
                let mut t: Tri = [Vec3::ZERO; 3];
                for (k, v) in t.iter_mut().enumerate() {
                    let off = DVec3::new(lcg(s), lcg(s), lcg(s)) * size;
                    *v = (base + off).as_vec3();
                    if i % 7 == 3 && k == 0 {
                        *v = (cam.eye - cam.forward * lcg(s).abs()).as_vec3();
                    }
                    if i % 11 == 5 && k == 1 {
                        *v = (cam.eye + cam.right * lcg(s)).as_vec3();
                    }
                }
                if i % 13 == 6 {
                    t[2] = t[1];
                }
                t
            })
            .collect()
    }

    /// Both halves of a leaf's set-up in lanes give the scalar set-up's
    /// bits, on every lane type this CPU runs, for cameras near and far
    /// from the origin. Compared are the outputs (f32 normals and bounds,
    /// integer pixel ends): a change one f64 rounding deep that leaves them
    /// equal here (a reassociated sum) passes, a wrong operand, sign or
    /// threshold fails (both tried).
    #[test]
    fn the_lanes_set_up_is_the_scalar_set_up_bit_for_bit() {
        fn check<L: Lanes<N>, const N: usize>(l: L, cam: &Camera, tris: &[Tri]) -> usize {
            let slack = RectSlack::new(cam);
            let mut all = 0;
            for chunk in tris.chunks_exact(N) {
                let t: &[Tri; N] = chunk.try_into().unwrap();
                let v = crate::simd::load_tris(l, t);
                let (normals, bounds) = LeafTri::aim_lanes(l, &v, cam.eye);
                let rects = PixelRect::new_lanes(l, cam, &slack, &v);
                for j in 0..N {
                    let mut want = LeafTri::unaimed(&t[j], 0);
                    want.aim(cam.eye);
                    let mut got = LeafTri::unaimed(&t[j], 0);
                    got.set_aimed(normals[j], bounds[j]);
                    assert_eq!(got.edge_bits(), want.edge_bits(), "{:?}", t[j]);
                    let rect = PixelRect::new(cam, &slack, &t[j]);
                    assert_eq!(rects[j], rect, "{:?}", t[j]);
                    all += usize::from(rect == PixelRect::ALL);
                }
            }
            all
        }
        let mut s = 5u64;
        let mut whole_image = 0;
        for (i, off) in [0.0, 1e3, -3e7].into_iter().enumerate() {
            let eye = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 3.0 + off;
            let look = eye + DVec3::new(lcg(&mut s), lcg(&mut s), 1.0);
            let cam = Camera::new(
                eye,
                look,
                DVec3::Y,
                [30.0, 90.0, 150.0][i],
                64,
                48,
                1e-6,
                f64::INFINITY,
            )
            .unwrap();
            let tris = cases(&cam, &mut s, 4000);
            whole_image += check(Portable, &cam, &tris);
            #[cfg(target_arch = "x86_64")]
            if let Some(avx2) = crate::simd::Avx2::detect() {
                check(avx2, &cam, &tris);
            }
            #[cfg(target_arch = "x86_64")]
            if let Some(wide) = crate::simd::Avx512::detect() {
                check(wide, &cam, &tris);
            }
        }
        assert!(
            whole_image > 100,
            "the cases reach the whole-image rectangle: {whole_image}"
        );
    }
}
