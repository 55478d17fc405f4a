//! A linear BVH (LBVH): the cheapest tree to build, for renders that trace
//! one frame per tree.
//!
//! Why it exists: a first image is build + trace, and on `million` obvhs's
//! cheapest preset (PLOC, reinsertion, leaf collapse) took 0.5 s of a 0.7 s
//! first image on one thread where Embree's Morton build takes 0.17 s
//! (issue 39). Here each triangle's box centroid is quantized in the
//! centroids' box to 10 bits per axis, the 30-bit Morton codes are radix
//! sorted (three stable passes, ties in index order, so the tree is a pure
//! function of the input), and the sorted range is split top-down at the
//! highest bit in which its first and last codes differ (Karras' split; a
//! range of equal codes is split in the middle, so duplicates cost depth
//! `log2 n`, not `n`), down to leaves of at most [`MAX_LEAF`]. Boxes are
//! computed bottom-up, with the refit's own expressions
//! ([`super::grow_bounds`], [`super::union_bounds`]) over the leaves'
//! triangles in prim order, so they are the refit's boxes bit for bit and
//! the caller skips its refit. No `same_box` grouping is needed: equal
//! boxes have equal codes, which split in the middle. The output is an
//! [`obvhs::bvh2::Bvh2`] in obvhs's conventions (root at 0, an inner
//! node's children at `first_index` and the next index, a leaf's prims at
//! `primitive_indices[first_index..]`, parents before children), so
//! everything downstream of the builder (`nodes::Layout`, the lazy leaves,
//! the shading trees) takes it unchanged.
//!
//! The top of the tree is split serially until ranges are small enough to
//! be subtrees built in parallel ([`GRAIN`]), each into a node list of its
//! own; the lists are then copied into place. A deadline is checked between
//! the phases and at the start of every subtree.

use super::{grow_bounds, union_bounds, NO_BOUNDS};
use crate::scene::resolve::Tri;
use glam::{Vec3, Vec3A};
use obvhs::aabb::Aabb;
use obvhs::bvh2::node::Bvh2Node;
use obvhs::bvh2::{Bvh2, DEFAULT_MAX_STACK_DEPTH};
use rayon::prelude::*;
use std::time::Instant;

/// The most triangles in a leaf. Every subtree of at most
/// `nodes::MERGE_MAX` (16) triangles whose triangles are adjacent becomes
/// one leaf in the traversal layout anyway, and every subtree here is a
/// range of the sorted order, so smaller leaves would give the same pixel
/// traversal tree with more nodes to build and lay out: on `million`, 1
/// thread, leaves of up to 8 took 0.107 s of tree against 0.095 s here,
/// for the same trace (Nov 30). Shading's shadow rays walk this tree's own
/// shape (`general::GeneralTree::from_tree`), so they see the larger leaves.
pub(super) const MAX_LEAF: usize = 16;

/// Ranges of at most this many triangles are built as one serial subtree
/// (a parallel task); the larger ones above them are split serially first.
const GRAIN: usize = 1 << 13;

/// Bits of the quantized centroid per axis: three make a 30-bit code,
/// which fits above a 32-bit index in one `u64` key.
const BITS: u32 = 10;

/// Spreads the low 10 bits of `v` to every third bit (bit `i` to `3 i`).
fn spread(v: u32) -> u32 {
    let mut x = v & 0x3ff;
    x = (x | (x << 16)) & 0x0300_00ff;
    x = (x | (x << 8)) & 0x0300_f00f;
    x = (x | (x << 4)) & 0x030c_30c3;
    x = (x | (x << 2)) & 0x0924_9249;
    x
}

/// A triangle's box centroid (for its code only).
#[inline]
fn centroid(t: &Tri) -> Vec3A {
    let (a, b, c) = (Vec3A::from(t[0]), Vec3A::from(t[1]), Vec3A::from(t[2]));
    (a.min(b).min(c) + a.max(b).max(c)) * 0.5
}

/// A box as obvhs stores it.
fn aabb([lo, hi]: [Vec3; 2]) -> Aabb {
    Aabb {
        min: lo.into(),
        max: hi.into(),
    }
}

/// A box as the refit stores it.
fn bounds(b: &Aabb) -> [Vec3; 2] {
    [b.min.into(), b.max.into()]
}

/// Each of triangles `ids`' key: its 30-bit Morton code above its index
/// in `ids`.
fn keys(tris: &[Tri], ids: &[u32]) -> Vec<u64> {
    let (lo, hi) = ids
        .par_iter()
        .with_min_len(1 << 14)
        .fold(
            || (Vec3A::INFINITY, Vec3A::NEG_INFINITY),
            |(lo, hi), &i| {
                let c = centroid(&tris[i as usize]);
                (lo.min(c), hi.max(c))
            },
        )
        .reduce(
            || (Vec3A::INFINITY, Vec3A::NEG_INFINITY),
            |a, b| (a.0.min(b.0), a.1.max(b.1)),
        );
    let cells = (1u32 << BITS) as f32;
    let ext = hi - lo;
    // A flat axis (or a non-finite extent) quantizes to cell 0.
    let scale = Vec3A::select(
        ext.cmpgt(Vec3A::ZERO) & ext.is_finite_mask(),
        cells / ext,
        Vec3A::ZERO,
    );
    let top = (1u32 << BITS) - 1;
    let mut out = Vec::with_capacity(ids.len());
    ids.par_iter()
        .with_min_len(1 << 14)
        .enumerate()
        .map(|(i, &t)| {
            let q = (centroid(&tris[t as usize]) - lo) * scale;
            // `as` saturates (NaN to 0); the top cell takes the maximum.
            let [x, y, z] = q.to_array().map(|v| (v as u32).min(top));
            let code = (spread(x) << 2) | (spread(y) << 1) | spread(z);
            (u64::from(code) << 32) | i as u64
        })
        .collect_into_vec(&mut out);
    out
}

/// Sorts `keys` by their top 32 bits (the code; the index below it is
/// already ascending): a stable least-significant-digit radix sort in three
/// passes of 10 bits, so equal codes keep their index order.
fn radix_sort(keys: &mut Vec<u64>) {
    const DIGIT: u32 = 10;
    const BUCKETS: usize = 1 << DIGIT;
    let mut tmp = vec![0u64; keys.len()];
    for pass in 0..3 {
        let shift = 32 + DIGIT * pass;
        let digit = |k: u64| ((k >> shift) as usize) & (BUCKETS - 1);
        let mut start = [0usize; BUCKETS];
        for &k in keys.iter() {
            start[digit(k)] += 1;
        }
        let mut sum = 0;
        for s in start.iter_mut() {
            (*s, sum) = (sum, sum + *s);
        }
        for &k in keys.iter() {
            let d = digit(k);
            tmp[start[d]] = k;
            start[d] += 1;
        }
        std::mem::swap(keys, &mut tmp);
    }
}

/// Where to split the sorted range `lo..hi` (at least two keys): at the
/// first key with the highest bit in which the range's first and last
/// codes differ set, or in the middle when they are equal.
fn split(keys: &[u64], lo: usize, hi: usize) -> usize {
    let code = |i: usize| (keys[i] >> 32) as u32;
    let diff = code(lo) ^ code(hi - 1);
    if diff == 0 {
        return lo + (hi - lo) / 2;
    }
    // Every code in the range shares the bits above `bit`; those with it
    // clear come first. The first key has it clear and the last set, so
    // the split is strictly inside the range.
    let bit = 1u32 << (31 - diff.leading_zeros());
    lo + keys[lo..hi].partition_point(|&k| (k >> 32) as u32 & bit == 0)
}

/// The sorted keys and the triangles, shared by every subtree's build.
struct Ctx<'a> {
    tris: &'a [Tri],
    ids: &'a [u32],
    keys: &'a [u64],
}

impl Ctx<'_> {
    /// Builds the subtree over sorted positions `lo..hi` with its root at
    /// `out[at]`, pushing each inner node's child pair at the end of `out`.
    /// Returns the depth of its deepest node (the root at `depth`).
    fn grow(&self, lo: usize, hi: usize, at: usize, out: &mut Vec<Bvh2Node>, depth: u32) -> u32 {
        if hi - lo <= MAX_LEAF {
            let b = self.keys[lo..hi].iter().fold(NO_BOUNDS, |b, &k| {
                grow_bounds(b, &self.tris[self.ids[k as u32 as usize] as usize])
            });
            out[at] = Bvh2Node::new(aabb(b), (hi - lo) as u32, lo as u32);
            return depth;
        }
        let mid = split(self.keys, lo, hi);
        let c = out.len();
        out.extend([Bvh2Node::default(); 2]);
        let d0 = self.grow(lo, mid, c, out, depth + 1);
        let d1 = self.grow(mid, hi, c + 1, out, depth + 1);
        let b = union_bounds(bounds(&out[c].aabb), bounds(&out[c + 1].aabb));
        out[at] = Bvh2Node::new(aabb(b), 0, c as u32);
        d0.max(d1)
    }
}

/// A range of the sorted keys on the way down the top of the tree, and
/// at its end a serially built subtree: its range, the top node it roots
/// at, and its depth there.
struct Task {
    lo: usize,
    hi: usize,
    slot: usize,
    depth: u32,
}

/// The linear BVH over the triangles `tris[ids[..]]` (its prims are
/// indices into `ids`), or None once `deadline` has passed (checked
/// between the phases and at the start of each subtree: no phase is worse
/// than `n log n`, so no thread of its own is needed to stop it).
pub(super) fn build(tris: &[Tri], ids: &[u32], deadline: Option<Instant>) -> Option<Bvh2> {
    if ids.is_empty() {
        return Some(Bvh2::default());
    }
    let mut keys = keys(tris, ids);
    if crate::deadline::past(deadline) {
        return None;
    }
    radix_sort(&mut keys);
    if crate::deadline::past(deadline) {
        return None;
    }
    let ctx = Ctx {
        tris,
        ids,
        keys: &keys,
    };
    // The top: ranges split breadth first until each is a task.
    let mut top = vec![Bvh2Node::default()];
    let mut tasks = Vec::new();
    let mut queue = std::collections::VecDeque::from([Task {
        lo: 0,
        hi: keys.len(),
        slot: 0,
        depth: 0,
    }]);
    while let Some(t) = queue.pop_front() {
        if t.hi - t.lo <= GRAIN {
            tasks.push(t);
            continue;
        }
        let mid = split(&keys, t.lo, t.hi);
        let c = top.len();
        top.extend([Bvh2Node::default(); 2]);
        top[t.slot] = Bvh2Node::new(Aabb::empty(), 0, c as u32);
        for (i, (lo, hi)) in [(t.lo, mid), (mid, t.hi)].into_iter().enumerate() {
            queue.push_back(Task {
                lo,
                hi,
                slot: c + i,
                depth: t.depth + 1,
            });
        }
    }
    let built: Option<Vec<(Vec<Bvh2Node>, u32)>> = tasks
        .par_iter()
        .map(|t| {
            if crate::deadline::past(deadline) {
                return None;
            }
            // About two nodes per leaf of eight (it grows if need be).
            let mut out = Vec::with_capacity((t.hi - t.lo) / 4 + 1);
            out.push(Bvh2Node::default());
            let d = ctx.grow(t.lo, t.hi, 0, &mut out, t.depth);
            Some((out, d))
        })
        .collect();
    let built = built?;
    // Each subtree's nodes below its root go after the top, in task order.
    let top_len = top.len();
    let mut bases = Vec::with_capacity(tasks.len());
    let mut total = top_len;
    for (sub, _) in &built {
        bases.push(total);
        total += sub.len() - 1;
    }
    let mut nodes = top;
    nodes.resize(total, Bvh2Node::default());
    // A subtree's local node `j >= 1` lands at `base + j - 1`.
    let place = |n: &Bvh2Node, base: usize| {
        let mut n = *n;
        if n.prim_count == 0 {
            n.first_index += base as u32 - 1;
        }
        n
    };
    {
        let (head, mut rest) = nodes.split_at_mut(top_len);
        let mut chunks = Vec::with_capacity(built.len());
        for (sub, _) in &built {
            let (c, r) = rest.split_at_mut(sub.len() - 1);
            chunks.push(c);
            rest = r;
        }
        chunks
            .into_par_iter()
            .zip(built.par_iter().zip(&bases))
            .for_each(|(dst, ((sub, _), &base))| {
                for (d, s) in dst.iter_mut().zip(&sub[1..]) {
                    *d = place(s, base);
                }
            });
        for ((t, (sub, _)), &base) in tasks.iter().zip(&built).zip(&bases) {
            head[t.slot] = place(&sub[0], base);
        }
        // The boxes of the nodes the top split made, children (at higher
        // indices) first. Their children are top slots; a subtree's root,
        // whose box is already set, has its children past the top.
        for i in (0..top_len).rev() {
            let n = head[i];
            let c = n.first_index as usize;
            if n.prim_count == 0 && c < top_len {
                let b = union_bounds(bounds(&head[c].aabb), bounds(&head[c + 1].aabb));
                head[i].aabb = aabb(b);
            }
        }
    }
    let depth = built.iter().map(|(_, d)| *d).max().unwrap_or(0);
    let primitive_indices: Vec<u32> = keys
        .par_iter()
        .with_min_len(1 << 14)
        .map(|&k| k as u32)
        .collect();
    if crate::deadline::past(deadline) {
        return None;
    }
    Some(Bvh2 {
        nodes,
        primitive_indices,
        max_depth: DEFAULT_MAX_STACK_DEPTH.max(depth as usize + 1),
        children_are_ordered_after_parents: true,
        ..Bvh2::default()
    })
}

#[cfg(test)]
mod tests {
    use super::super::test_tris::scattered;
    use super::*;
    use obvhs::triangle::Triangle;

    fn all(tris: &[Tri]) -> Vec<u32> {
        (0..tris.len() as u32).collect()
    }

    /// Walks the tree from the root: every node is reached exactly once,
    /// after its parent; each box contains its children's (or its
    /// triangles') boxes; leaves hold 1 to [`MAX_LEAF`] prims; every
    /// triangle is in exactly one leaf; and obvhs's own validation passes
    /// (tight boxes included). Returns (node count, depth).
    fn check(bvh: &Bvh2, tris: &[Tri], ids: &[u32]) -> (usize, usize) {
        let contains = |o: &Aabb, [lo, hi]: [Vec3; 2]| {
            Vec3::from(o.min).cmple(lo).all() && Vec3::from(o.max).cmpge(hi).all()
        };
        let mut seen_node = vec![false; bvh.nodes.len()];
        let mut seen_prim = vec![false; ids.len()];
        let mut stack = vec![(0usize, 0usize)];
        let mut depth = 0;
        while let Some((i, d)) = stack.pop() {
            assert!(!seen_node[i], "node {i} reached twice");
            seen_node[i] = true;
            depth = depth.max(d);
            let n = &bvh.nodes[i];
            if n.prim_count == 0 {
                let c = n.first_index as usize;
                assert!(c > i, "children after their parent");
                for k in [c, c + 1] {
                    assert!(contains(&n.aabb, bounds(&bvh.nodes[k].aabb)), "{i} {k}");
                    stack.push((k, d + 1));
                }
            } else {
                assert!(n.prim_count as usize <= MAX_LEAF);
                for p in n.first_index..n.first_index + n.prim_count {
                    let k = bvh.primitive_indices[p as usize] as usize;
                    assert!(!seen_prim[k], "prim {k} twice");
                    seen_prim[k] = true;
                    let t = &tris[ids[k] as usize];
                    assert!(contains(&n.aabb, grow_bounds(NO_BOUNDS, t)));
                }
            }
        }
        assert!(seen_node.iter().all(|&s| s), "unreachable nodes");
        assert!(seen_prim.iter().all(|&s| s), "a prim in no leaf");
        assert!(depth < bvh.max_depth);
        let obvhs_tris: Vec<Triangle> = ids
            .iter()
            .map(|&i| {
                let t = &tris[i as usize];
                Triangle {
                    v0: t[0].into(),
                    v1: t[1].into(),
                    v2: t[2].into(),
                }
            })
            .collect();
        bvh.validate(&obvhs_tris, false, true);
        (bvh.nodes.len(), depth)
    }

    #[test]
    fn every_triangle_once_boxes_nested_leaves_small() {
        for n in [1, 2, MAX_LEAF, MAX_LEAF + 1, 1000, 3 * GRAIN + 17, 60_000] {
            let tris = scattered(n, n as u64);
            let bvh = build(&tris, &all(&tris), None).unwrap();
            let (nodes, _) = check(&bvh, &tris, &all(&tris));
            // Leaves of at least one prim: at most 2 n - 1 nodes.
            assert!(nodes < 2 * n, "{n}");
        }
        // A subset: prims index `ids`, not the triangles.
        let tris = scattered(5000, 11);
        let odd: Vec<u32> = (1..5000).step_by(2).collect();
        let bvh = build(&tris, &odd, None).unwrap();
        check(&bvh, &tris, &odd);
        assert!(build(&tris, &[], None).unwrap().nodes.is_empty());
    }

    /// The tree is a pure function of the input (the parallel parts
    /// included): two builds agree node for node.
    #[test]
    fn the_build_is_deterministic() {
        let tris = scattered(50_000, 5);
        let a = build(&tris, &all(&tris), None).unwrap();
        let b = build(&tris, &all(&tris), None).unwrap();
        assert_eq!(a.primitive_indices, b.primitive_indices);
        assert_eq!(a.nodes.len(), b.nodes.len());
        for (x, y) in a.nodes.iter().zip(&b.nodes) {
            assert_eq!(
                (x.aabb.min, x.aabb.max, x.first_index, x.prim_count),
                (y.aabb.min, y.aabb.max, y.first_index, y.prim_count)
            );
        }
    }

    /// 40,000 copies of one triangle (every code equal) split in the
    /// middle: a balanced tree, `log2` deep, not a chain; likewise many
    /// copies among distinct triangles.
    #[test]
    fn duplicates_give_a_balanced_tree() {
        let one = scattered(1, 9)[0];
        let n = 40_000;
        let tris = vec![one; n];
        let bvh = build(&tris, &all(&tris), None).unwrap();
        let (nodes, depth) = check(&bvh, &tris, &all(&tris));
        let leaves = n.div_ceil(MAX_LEAF);
        assert!(nodes < 4 * leaves, "{nodes} nodes");
        let balanced = (2 * leaves).next_power_of_two().trailing_zeros() as usize;
        assert!(depth <= balanced, "depth {depth} over {balanced}");
        let mut mixed = scattered(20_000, 3);
        mixed.extend(std::iter::repeat_n(one, 30_000));
        let bvh = build(&mixed, &all(&mixed), None).unwrap();
        let (_, depth) = check(&bvh, &mixed, &all(&mixed));
        // At most the 30 code bits above the duplicates' balanced split.
        assert!(depth <= 3 * BITS as usize + balanced, "depth {depth}");
    }

    /// The split is at the highest differing code bit, strictly inside.
    #[test]
    fn split_at_the_highest_differing_bit() {
        let k = |c: u64, i: u64| (c << 32) | i;
        let keys = [k(0b0001, 0), k(0b0011, 1), k(0b0100, 2), k(0b0111, 3)];
        assert_eq!(split(&keys, 0, 4), 2);
        assert_eq!(split(&keys, 0, 2), 1);
        let same = [k(5, 0), k(5, 1), k(5, 2), k(5, 3), k(5, 4)];
        assert_eq!(split(&same, 0, 5), 2);
        assert_eq!(spread(0x3ff), 0x0924_9249);
        assert_eq!(spread(0b11), 0b1001);
    }

    /// The radix sort orders by code, ties in index order; a flat scene
    /// (one axis of no extent) quantizes without NaN.
    #[test]
    fn radix_sort_is_a_stable_sort_by_code() {
        let tris = scattered(30_000, 77);
        let mut keys = keys(&tris, &all(&tris));
        let mut expected = keys.clone();
        expected.sort_by_key(|&k| k >> 32);
        assert_ne!(keys, expected);
        radix_sort(&mut keys);
        assert_eq!(keys, expected);
        let flat: Vec<Tri> = tris
            .iter()
            .map(|t| t.map(|v| v * Vec3::new(1.0, 1.0, 0.0)))
            .collect();
        let bvh = build(&flat, &all(&flat), None).unwrap();
        check(&bvh, &flat, &all(&flat));
    }

    /// A deadline already past stops it.
    #[test]
    fn a_past_deadline_stops_it() {
        let tris = scattered(5000, 1);
        assert!(build(&tris, &all(&tris), Some(Instant::now())).is_none());
        let later = Instant::now() + std::time::Duration::from_secs(3600);
        assert!(build(&tris, &all(&tris), Some(later)).is_some());
    }
}
