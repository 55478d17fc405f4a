//! The eye-relative node array in the order traversal reads it.
//!
//! obvhs stores a node's two children side by side, but the pair may straddle
//! two cache lines and subtrees are spread over the array. Traversal tests
//! both children of a node together (it orders them by their centers), so
//! here the tree is laid out again depth first with every sibling pair in one
//! 64-byte line ([`NodePair`]), and the traversal can prefetch a pushed
//! node's children (or a leaf's triangles) long before it pops it: on the
//! million-triangle scene most of the kernel's stalls were those loads.
//!
//! The layout also merges small subtrees (up to [`MERGE_MAX`] prims, when
//! their prims are adjacent) into one leaf under the subtree root's box. That
//! is conservative: the root's box contains every box below it, so a lane
//! that reached a triangle before still reaches it, and coverage and depth
//! decide the rest exactly as before. Packets cull a leaf's triangles by
//! their pixel rectangles ([`super::rect`]), which costs less than the box
//! tests and stack traffic of the merged levels (3% on the million scene).

use super::primary::Node32;
use crate::simd::prefetch;
use crate::visibility::grow_box;
use glam::{DVec3, Vec3};

/// Largest leaf made by merging a subtree: testing a few more triangles'
/// pixel rectangles costs less than the box tests and stack traffic of the
/// levels it replaces.
const MERGE_MAX: u32 = 16;

/// Two sibling nodes in one cache line.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(64))]
struct NodePair([Node32; 2]);

/// The eye-relative tree, siblings paired. Node indices are as in
/// [`Node32::first`]; the root is [`Nodes32::ROOT`] (slot 1 of pair 0, whose
/// slot 0 is unused), so every sibling pair starts at an even index.
pub(crate) struct Nodes32 {
    pairs: Vec<NodePair>,
}

/// Where each slot of [`Nodes32`] comes from: the layout depends on the
/// tree's shape alone, not on the camera, so it is made once per tree and
/// every camera's boxes are written into it in place ([`Nodes32::fill`]).
#[derive(Debug, Clone, Default)]
pub(crate) struct Layout {
    /// Per slot: the index of its node in the input tree, and the slot's own
    /// `first` and `count` (children's slot, or a possibly merged leaf's
    /// prims). Slot 0 is unused and repeats the input's root as given.
    slots: Vec<Slot>,
}

/// One slot of a [`Layout`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct Slot {
    /// Index of the node in the input tree whose box the slot takes.
    pub src: u32,
    /// The slot's [`Node32::first`].
    pub first: u32,
    /// The slot's [`Node32::count`].
    pub count: u32,
}

impl Layout {
    /// Lays a tree out depth first, siblings paired: `shape[i]` is node
    /// `i`'s `(first, count)` (children of inner node `i` at `first` and the
    /// next index, root at 0).
    pub fn new(shape: &[(u32, u32)]) -> Layout {
        let Some(&(root_first, root_count)) = shape.first() else {
            return Layout::default();
        };
        let unset = Slot {
            src: 0,
            first: root_first,
            count: root_count,
        };
        let mut slots = vec![unset; (shape.len().div_ceil(2) + 1) * 2];
        let mut next = 2u32;
        // (old index, new index)
        let mut stack = vec![(0u32, Nodes32::ROOT)];
        let span = prim_spans(shape);
        while let Some((old, new)) = stack.pop() {
            let (mut first, mut count) = shape[old as usize];
            // A small subtree whose prims are adjacent becomes one leaf under
            // its root's box (which contains every box below it).
            if let Some((f, c)) = span[old as usize] {
                if c <= MERGE_MAX {
                    (first, count) = (f, c);
                }
            }
            if count == 0 {
                let c = first;
                first = next;
                stack.push((c + 1, next + 1));
                stack.push((c, next));
                next += 2;
            }
            slots[new as usize] = Slot {
                src: old,
                first,
                count,
            };
        }
        slots.truncate(next as usize);
        Layout { slots }
    }

    /// The slots, in [`Nodes32`]'s order (slot 0 unused).
    pub fn slots(&self) -> &[Slot] {
        &self.slots
    }
}

impl Nodes32 {
    /// Index of the root node.
    pub const ROOT: u32 = 1;

    /// A tree with no nodes.
    pub fn empty() -> Nodes32 {
        Nodes32 { pairs: Vec::new() }
    }

    /// Lays `nodes` (children of inner node `i` at `nodes[i].first` and the
    /// next index, root at 0) out depth first, siblings paired.
    #[cfg(test)]
    pub fn new(nodes: &[Node32]) -> Nodes32 {
        let shape: Vec<(u32, u32)> = nodes.iter().map(|n| (n.first, n.count)).collect();
        let mut out = Nodes32::empty();
        out.fill(&Layout::new(&shape), |_, s| {
            let mut n = nodes[s.src as usize];
            (n.first, n.count) = (s.first, s.count);
            n
        });
        out
    }

    /// Writes every slot of `layout` as `node(k, slot)` (slot `k`: the
    /// input tree's node `slot.src`'s box with the slot's `first` and
    /// `count`), in parallel on rayon's current pool (the tests' trees; a
    /// camera's nodes are [`Self::fill_grown`]'s).
    #[cfg(test)]
    pub fn fill(&mut self, layout: &Layout, node: impl Fn(usize, &Slot) -> Node32 + Sync) {
        use rayon::prelude::*;
        self.size_for(layout);
        self.pairs
            .par_iter_mut()
            .zip(layout.slots.par_chunks_exact(2))
            .enumerate()
            .with_min_len(1024)
            .for_each(|(i, (pair, slots))| {
                pair.0[0] = node(2 * i, &slots[0]);
                pair.0[1] = node(2 * i + 1, &slots[1]);
            });
    }

    /// Writes every slot of `layout` with its node made from its world box
    /// (`boxes`, one per slot: its f32 corners) for the eye `eye`:
    /// `Node32::new(eye, &grow_box(eye, lo, hi), ..)`, eight slots at a
    /// time in AVX-512 f64 lanes or four in AVX2's where the CPU has them
    /// ([`Node32::grown_lanes`], the same bits), the rest one at a time. On
    /// `million`'s `slow` tree one slot at a time took about 6 ms of a new
    /// camera on one thread (docs/benchmarks.md). In parallel on rayon's
    /// current pool, reusing the pairs' memory when the tree already has
    /// this layout's size (a new camera on the same tree).
    pub fn fill_grown(&mut self, layout: &Layout, boxes: &[[Vec3; 2]], eye: DVec3) {
        use rayon::prelude::*;
        assert_eq!(boxes.len(), layout.slots.len(), "one box per slot");
        self.size_for(layout);
        let pairs: &mut [NodePair] = &mut self.pairs;
        // A whole number of eight-slot groups per task.
        const TASK: usize = 512;
        pairs
            .par_chunks_mut(TASK)
            .zip(layout.slots.par_chunks(2 * TASK))
            .zip(boxes.par_chunks(2 * TASK))
            .for_each(|((pairs, slots), boxes)| {
                fill_grown_range(pairs, slots, boxes, eye);
            });
    }

    /// Sizes the pairs for `layout` (contents to be written by the caller).
    fn size_for(&mut self, layout: &Layout) {
        let n = layout.slots.len() / 2;
        if self.pairs.len() != n {
            // On huge pages where the OS has them (`crate::huge_pages`):
            // pops land all over the tree. Every pair is written below.
            let filler = NodePair(
                [Node32::new(
                    glam::DVec3::ZERO,
                    &crate::visibility::RayBox {
                        lo: glam::DVec3::ZERO,
                        hi: glam::DVec3::ZERO,
                    },
                    0,
                    0,
                ); 2],
            );
            self.pairs = crate::huge_pages::with_capacity(n);
            self.pairs.resize(n, filler);
        }
    }

    /// True when the tree has no nodes.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.pairs.is_empty()
    }

    /// Node `i`.
    #[inline(always)]
    pub fn get(&self, i: u32) -> &Node32 {
        &self.pairs[i as usize / 2].0[i as usize % 2]
    }

    /// Asks the CPU to start loading node `i`'s children (one line).
    #[inline(always)]
    pub fn prefetch_children(&self, n: &Node32) {
        if let Some(p) = self.pairs.get(n.first as usize / 2) {
            prefetch(p);
        }
    }
}

/// Per node, the prims under it as one range `(first, count)`, when they
/// are adjacent in prim order.
fn prim_spans(shape: &[(u32, u32)]) -> Vec<Option<(u32, u32)>> {
    let mut order = Vec::with_capacity(shape.len());
    let mut stack = vec![0u32];
    while let Some(i) = stack.pop() {
        order.push(i);
        let (first, count) = shape[i as usize];
        if count == 0 {
            stack.push(first);
            stack.push(first + 1);
        }
    }
    let mut span = vec![None; shape.len()];
    for &i in order.iter().rev() {
        let (first, count) = shape[i as usize];
        span[i as usize] = if count > 0 {
            Some((first, count))
        } else {
            match (span[first as usize], span[first as usize + 1]) {
                (Some((fa, ca)), Some((fb, cb))) if fb == fa + ca => Some((fa, ca + cb)),
                (Some((fa, ca)), Some((fb, cb))) if fa == fb + cb => Some((fb, ca + cb)),
                _ => None,
            }
        };
    }
    span
}

/// [`Nodes32::fill_grown`] over one task's pairs, their slots and boxes, in
/// the widest lanes the CPU has.
fn fill_grown_range(pairs: &mut [NodePair], slots: &[Slot], boxes: &[[Vec3; 2]], eye: DVec3) {
    #[cfg(target_arch = "x86_64")]
    if let Some(wide) = crate::simd::Avx512::detect() {
        // SAFETY: the CPU has AVX-512F (just detected).
        unsafe { fill_grown_avx512(wide, pairs, slots, boxes, eye) };
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if let Some(avx2) = crate::simd::Avx2::detect() {
        // SAFETY: the CPU has AVX2 (just detected).
        unsafe { fill_grown_avx2(avx2, pairs, slots, boxes, eye) };
        return;
    }
    fill_grown_lanes(crate::simd::Portable, pairs, slots, boxes, eye);
}

/// [`fill_grown_lanes`] compiled for AVX-512F.
///
/// # Safety
/// The CPU must have AVX-512F (`l` proves it).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f")]
unsafe fn fill_grown_avx512(
    l: crate::simd::Avx512,
    pairs: &mut [NodePair],
    slots: &[Slot],
    boxes: &[[Vec3; 2]],
    eye: DVec3,
) {
    fill_grown_lanes(l, pairs, slots, boxes, eye);
}

/// [`fill_grown_lanes`] compiled for AVX2.
///
/// # Safety
/// The CPU must have AVX2 (`l` proves it).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn fill_grown_avx2(
    l: crate::simd::Avx2,
    pairs: &mut [NodePair],
    slots: &[Slot],
    boxes: &[[Vec3; 2]],
    eye: DVec3,
) {
    fill_grown_lanes(l, pairs, slots, boxes, eye);
}

/// Each slot's node from its box, `N` slots at a time in the lanes `l`, the
/// last few (fewer than `N`) one at a time.
#[inline(always)]
fn fill_grown_lanes<L: crate::simd::Lanes<N>, const N: usize>(
    l: L,
    pairs: &mut [NodePair],
    slots: &[Slot],
    boxes: &[[Vec3; 2]],
    eye: DVec3,
) {
    let len = 2 * pairs.len();
    let whole = len / N * N;
    for g in (0..whole).step_by(N) {
        let (mut lo, mut hi) = ([[0f32; N]; 3], [[0f32; N]; 3]);
        for j in 0..N {
            let [a, b] = boxes[g + j];
            for k in 0..3 {
                lo[k][j] = a[k];
                hi[k][j] = b[k];
            }
        }
        let (glo, ghi) = Node32::grown_lanes(l, eye, &lo, &hi);
        for j in 0..N {
            let s = &slots[g + j];
            pairs[(g + j) / 2].0[(g + j) % 2] = Node32::from_corners(
                [glo[0][j], glo[1][j], glo[2][j]],
                [ghi[0][j], ghi[1][j], ghi[2][j]],
                s.first,
                s.count,
            );
        }
    }
    for i in whole..len {
        let [a, b] = boxes[i];
        let s = &slots[i];
        pairs[i / 2].0[i % 2] = Node32::new(eye, &grow_box(eye, a, b), s.first, s.count);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::predicate::tests::lcg;

    /// The nodes made in lanes are the scalar `Node32::new(eye,
    /// &grow_box(..))` bit for bit, on every lane type this CPU runs, for
    /// boxes near and far from eyes near and far from the origin: boxes
    /// with a face through the eye (the growth's floor, corners of about
    /// 1e-35), tiny, huge, flat and single points, and a count that leaves
    /// a scalar rest. Compared are the corners' bits and the slot's numbers
    /// (a wrong rounding direction or margin fails; both tried).
    #[test]
    fn nodes_in_lanes_are_the_scalar_nodes() {
        let mut s = 11u64;
        let mut floor_corners = 0;
        for (i, off) in [0.0, 1e3, -3e7].into_iter().enumerate() {
            // An eye on f32 values, so a box's face can pass through it.
            let eye = (DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 3.0 + off)
                .as_vec3()
                .as_dvec3();
            // Even (whole pairs), and not all whole groups of lanes (the
            // scalar rest is taken too).
            let count = [4000, 4002, 4006][i];
            let boxes: Vec<[Vec3; 2]> = (0..count)
                .map(|k| {
                    let size = [1.0, 1e-3, 1e-30, 1e6, 0.0][k % 5];
                    let c = eye + DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 10.0;
                    let mut lo = (c - DVec3::splat(lcg(&mut s).abs() * size)).as_vec3();
                    let mut hi = (c + DVec3::splat(lcg(&mut s).abs() * size)).as_vec3();
                    if k % 7 == 3 {
                        // A face through the eye: that corner's distance is
                        // 0 and only the growth's floor moves it.
                        lo.x = eye.x as f32;
                        hi.x = lo.x;
                    }
                    [lo.min(hi), lo.max(hi)]
                })
                .collect();
            let slots: Vec<Slot> = (0..count as u32)
                .map(|k| Slot {
                    src: k,
                    first: 3 * k,
                    count: k % 9,
                })
                .collect();
            let want: Vec<Node32> = boxes
                .iter()
                .zip(&slots)
                .map(|(&[a, b], sl)| Node32::new(eye, &grow_box(eye, a, b), sl.first, sl.count))
                .collect();
            floor_corners += want
                .iter()
                .filter(|n| {
                    n.corner_bits()
                        .iter()
                        .any(|&b| f32::from_bits(b).abs() < 1e-30)
                })
                .count();
            // A node no slot makes, so a slot the lanes skip fails.
            let blank = NodePair([Node32::from_corners([7.0; 3], [7.0; 3], u32::MAX, u32::MAX); 2]);
            let check = |kernel: &str, got: &[NodePair]| {
                for (k, w) in want.iter().enumerate() {
                    let g = &got[k / 2].0[k % 2];
                    assert_eq!(
                        g.corner_bits(),
                        w.corner_bits(),
                        "{kernel}: box {k} {:?}",
                        boxes[k]
                    );
                    assert_eq!((g.first, g.count), (w.first, w.count), "{kernel}: box {k}");
                }
            };
            let (b, sl) = (&boxes[..], &slots[..]);
            let mut pairs = vec![blank; count / 2];
            fill_grown_lanes(crate::simd::Portable, &mut pairs, sl, b, eye);
            check("portable", &pairs);
            #[cfg(target_arch = "x86_64")]
            if let Some(avx2) = crate::simd::Avx2::detect() {
                let mut p = vec![blank; count / 2];
                // SAFETY: the CPU has AVX2 (just detected).
                unsafe { fill_grown_avx2(avx2, &mut p, sl, b, eye) };
                check("avx2", &p);
            }
            #[cfg(target_arch = "x86_64")]
            if let Some(wide) = crate::simd::Avx512::detect() {
                let mut p = vec![blank; count / 2];
                // SAFETY: the CPU has AVX-512F (just detected).
                unsafe { fill_grown_avx512(wide, &mut p, sl, b, eye) };
                check("avx512", &p);
            }
        }
        assert!(
            floor_corners > 10,
            "the cases reach the growth's floor: {floor_corners}"
        );
    }

    /// Every node keeps its box, and every node reaches the same prims (a
    /// merged leaf holds exactly its old subtree's), with siblings in one
    /// 64-byte pair.
    #[test]
    fn relayout_keeps_the_tree() {
        const _: () = assert!(8 <= MERGE_MAX && MERGE_MAX < 25);
        use crate::visibility::RayBox;
        use glam::DVec3;
        // 0 -> (1, 2), 2 -> (3, 4), 4 -> (5, 6), 6 -> (7, 8); prims:
        // 1: 0..17, 3: 17..18, 5: 18..20, 7: 20..23, 8: 30..32 (not adjacent).
        let kids = [
            (1, 0),
            (0, 17),
            (3, 0),
            (17, 1),
            (5, 0),
            (18, 2),
            (7, 0),
            (20, 3),
            (30, 2),
        ];
        let old: Vec<Node32> = kids
            .iter()
            .enumerate()
            .map(|(i, &(first, count))| {
                let b = RayBox {
                    lo: DVec3::splat(i as f64),
                    hi: DVec3::splat(i as f64 + 1.0),
                };
                Node32::new(DVec3::ZERO, &b, first, count)
            })
            .collect();
        fn prims_old(old: &[Node32], o: u32) -> Vec<u32> {
            let n = old[o as usize];
            if n.count > 0 {
                (n.first..n.first + n.count).collect()
            } else {
                let mut v = prims_old(old, n.first);
                v.extend(prims_old(old, n.first + 1));
                v.sort();
                v
            }
        }
        let new = Nodes32::new(&old);
        fn walk(old: &[Node32], new: &Nodes32, o: u32, n: u32, leaves: &mut usize) {
            let (a, b) = (old[o as usize], *new.get(n));
            assert_eq!(a.bounds(0), b.bounds(0));
            if b.count > 0 {
                *leaves += 1;
                let got: Vec<u32> = (b.first..b.first + b.count).collect();
                assert_eq!(got, prims_old(old, o));
                assert!(a.count > 0 || b.count <= MERGE_MAX);
            } else {
                assert_eq!(a.count, 0);
                assert_eq!(b.first % 2, 0);
                walk(old, new, a.first, b.first, leaves);
                walk(old, new, a.first + 1, b.first + 1, leaves);
            }
        }
        let mut leaves = 0;
        walk(&old, &new, 0, Nodes32::ROOT, &mut leaves);
        // No subtree's prims are adjacent (30..32 breaks every range that
        // reaches 8), so the tree keeps its five leaves.
        assert_eq!(leaves, 5);
        assert_eq!(std::mem::size_of::<NodePair>(), 64);
        assert_eq!(std::mem::align_of::<NodePair>(), 64);
        // With the far leaf adjacent, the whole right subtree (17..25, 8
        // prims) merges; the root (25 prims) does not.
        let mut adj = old.clone();
        adj[8].first = 23;
        let new = Nodes32::new(&adj);
        let mut leaves = 0;
        walk(&adj, &new, 0, Nodes32::ROOT, &mut leaves);
        assert_eq!(leaves, 2);
    }
}
