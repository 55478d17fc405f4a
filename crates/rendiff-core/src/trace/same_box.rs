//! Triangles whose boxes are bit-identical, built as one BVH primitive.
//!
//! obvhs's PLOC builder merges mutually nearest clusters, with the merged box's
//! surface area as the distance. Among `n` clusters with the same box every
//! distance ties, only a pair or so merges per pass, and the build is
//! quadratic: 20k copies of one triangle took 24 s, where 20k distinct ones
//! take milliseconds. No box can separate such triangles anyway (a node's box
//! would be the same for any split of them), so nothing is lost by handing the
//! builder one primitive per distinct box and expanding each leaf's range
//! afterwards into the triangles that share it (only where enough share one
//! box for it to matter: [`MIN_GROUP`]). Leaves come out in the builder's
//! order, each group's triangles in ascending ID order, so a scene without
//! shared boxes gets exactly the tree it got before.

use obvhs::triangle::Triangle;
use rayon::prelude::*;

/// A triangle's box as the bits of its f32 corners: equal keys, equal boxes.
type BoxKey = [u32; 6];

fn box_key(t: &Triangle) -> BoxKey {
    let lo = t.v0.min(t.v1).min(t.v2);
    let hi = t.v0.max(t.v1).max(t.v2);
    // -0.0 and 0.0 bound the same box; the builder cannot tell them apart either.
    let bits = |x: f32| (x + 0.0).to_bits();
    [
        bits(lo.x),
        bits(lo.y),
        bits(lo.z),
        bits(hi.x),
        bits(hi.y),
        bits(hi.z),
    ]
}

/// The fewest triangles sharing a box that are grouped. PLOC's ties cost
/// about the square of a group's size; below this the cost per triangle is a
/// small constant (a quad's two halves share a box, so pairs are everywhere,
/// and grouping them would cost a second pass over the scene for nothing).
pub(super) const MIN_GROUP: usize = 16;

/// True when some [`MIN_GROUP`] adjacent items of sorted `v` are all `eq`.
fn has_run<T>(v: &[T], eq: impl Fn(&T, &T) -> bool) -> bool {
    let mut run = 1;
    for w in v.windows(2) {
        run = if eq(&w[0], &w[1]) { run + 1 } else { 1 };
        if run >= MIN_GROUP {
            return true;
        }
    }
    false
}

/// A 64-bit mix of a box key, for finding equal boxes by sorting eight bytes
/// per triangle rather than twenty-eight (equal hashes are then checked on
/// the whole key).
fn box_hash(k: &BoxKey) -> u64 {
    let mut h = 0u64;
    for &w in k {
        h = (h ^ u64::from(w)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        h ^= h >> 29;
    }
    h
}

/// False when no [`MIN_GROUP`] triangles can share a box, in one pass and
/// no sort: each box hash is counted in a bucket named by its top bits, and
/// equal boxes have equal hashes, so a shared box fills one bucket. With
/// about half a triangle per bucket a bucket reaches [`MIN_GROUP`] by chance
/// almost never; when one does, [`SameBoxGroups::find`] sorts as before.
/// (On `million` the sort was 0.05 s of a 0.9 s first image.)
fn may_share(tris: &[Triangle]) -> bool {
    let buckets = (tris.len().next_power_of_two() * 2).clamp(1 << 10, 1 << 21);
    let shift = 64 - buckets.trailing_zeros();
    let mut counts = vec![0u8; buckets];
    for t in tris {
        // `box_hash` is weak in its top bits on grid-like meshes: mix it
        // again (MurmurHash3's 64-bit finalizer) before taking them.
        let mut h = box_hash(&box_key(t));
        h = (h ^ (h >> 33)).wrapping_mul(0xff51_afd7_ed55_8ccd);
        h = (h ^ (h >> 33)).wrapping_mul(0xc4ce_b9fe_1a85_ec53);
        h ^= h >> 33;
        let c = &mut counts[(h >> shift) as usize];
        *c = c.saturating_add(1);
        if usize::from(*c) >= MIN_GROUP {
            return true;
        }
    }
    false
}

/// The input triangles grouped by box: `reps` are the triangles handed to the
/// builder (the first of each group) and `members` the input indices of each.
pub(super) struct SameBoxGroups {
    /// One triangle per distinct box, in order of each box's first appearance.
    pub reps: Vec<Triangle>,
    /// `members[starts[g]..starts[g + 1]]`: the input indices sharing group `g`'s box.
    members: Vec<u32>,
    starts: Vec<u32>,
}

impl SameBoxGroups {
    /// Groups `tris` where at least [`MIN_GROUP`] of them share a box;
    /// `None` when none do (the common case), so the caller builds over `tris`
    /// as they are. That case costs a hash per triangle and a sort of the
    /// hashes.
    pub fn find(tris: &[Triangle]) -> Option<SameBoxGroups> {
        if !may_share(tris) {
            return None;
        }
        let mut hashes: Vec<u64> = tris.par_iter().map(|t| box_hash(&box_key(t))).collect();
        hashes.par_sort_unstable();
        if !has_run(&hashes, |a, b| a == b) {
            return None;
        }
        drop(hashes);
        // Some hashes repeat: sort (hash, index) pairs, then split each run of
        // one hash by its whole key.
        let mut keyed: Vec<(u64, u32)> = tris
            .par_iter()
            .enumerate()
            .map(|(i, t)| (box_hash(&box_key(t)), i as u32))
            .collect();
        keyed.par_sort_unstable();
        // rep_of[i]: the lowest index with triangle i's box.
        let mut rep_of: Vec<u32> = (0..tris.len() as u32).collect();
        let mut run = 0usize;
        for i in 1..=keyed.len() {
            if i < keyed.len() && keyed[i].0 == keyed[run].0 {
                continue;
            }
            if i - run >= MIN_GROUP {
                let mut members: Vec<(BoxKey, u32)> = keyed[run..i]
                    .iter()
                    .map(|&(_, j)| (box_key(&tris[j as usize]), j))
                    .collect();
                members.sort_unstable();
                let mut s = 0usize;
                for k in 1..=members.len() {
                    if k == members.len() || members[k].0 != members[s].0 {
                        for m in &members[s..k] {
                            rep_of[m.1 as usize] = members[s].1;
                        }
                        s = k;
                    }
                }
            }
            run = i;
        }
        // Groups in order of their lowest index; members in ascending order.
        let mut group_of_rep = vec![u32::MAX; tris.len()];
        let mut reps = Vec::new();
        for (i, &r) in rep_of.iter().enumerate() {
            if r == i as u32 {
                group_of_rep[i] = reps.len() as u32;
                reps.push(tris[i]);
            }
        }
        let mut starts = vec![0u32; reps.len() + 1];
        for &r in &rep_of {
            starts[group_of_rep[r as usize] as usize + 1] += 1;
        }
        for g in 0..reps.len() {
            starts[g + 1] += starts[g];
        }
        let mut cursor = starts.clone();
        let mut members = vec![0u32; tris.len()];
        for (i, &r) in rep_of.iter().enumerate() {
            let g = group_of_rep[r as usize] as usize;
            members[cursor[g] as usize] = i as u32;
            cursor[g] += 1;
        }
        if reps.len() == tris.len() {
            return None; // every long run of one hash was collisions
        }
        Some(SameBoxGroups {
            reps,
            members,
            starts,
        })
    }

    /// The input indices in group `g`.
    fn group(&self, g: u32) -> &[u32] {
        &self.members[self.starts[g as usize] as usize..self.starts[g as usize + 1] as usize]
    }

    /// Rewrites a tree built over [`Self::reps`] into one over the input
    /// triangles: `primitive_indices` lists every member of each group in
    /// place of the group, and each leaf's `(first, count)` covers its groups'
    /// members. Leaves keep their relative order in `primitive_indices`, so
    /// subtrees that were contiguous stay contiguous.
    pub fn expand(&self, first_count: &mut [(u32, u32)], primitive_indices: &mut Vec<u32>) {
        let mut leaves: Vec<usize> = (0..first_count.len())
            .filter(|&i| first_count[i].1 > 0)
            .collect();
        leaves.sort_unstable_by_key(|&i| first_count[i].0);
        let mut out = Vec::with_capacity(self.members.len());
        for i in leaves {
            let (first, count) = first_count[i];
            let new_first = out.len() as u32;
            for &g in &primitive_indices[first as usize..(first + count) as usize] {
                out.extend_from_slice(self.group(g));
            }
            first_count[i] = (new_first, out.len() as u32 - new_first);
        }
        *primitive_indices = out;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3A;

    fn tri(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> Triangle {
        Triangle {
            v0: Vec3A::from(a),
            v1: Vec3A::from(b),
            v2: Vec3A::from(c),
        }
    }

    /// The one-pass check says "maybe" once MIN_GROUP boxes are equal and
    /// "no" on many distinct boxes (a large grid-like mesh); the groups
    /// found are exact either way (a bucket that fills by chance only costs
    /// the sort).
    #[test]
    fn the_bucket_check_sees_exactly_the_groups_that_matter() {
        let grid: Vec<Triangle> = (0..200_000)
            .map(|i| {
                let (x, y) = ((i % 500) as f32, (i / 500) as f32);
                tri([x, y, 0.0], [x + 0.5, y, 0.0], [x, y + 0.5, 0.0])
            })
            .collect();
        assert!(!may_share(&grid));
        for copies in [MIN_GROUP - 1, MIN_GROUP] {
            let mut tris = grid.clone();
            tris.extend(std::iter::repeat_n(grid[7], copies - 1));
            if copies >= MIN_GROUP {
                assert!(may_share(&tris));
            }
            assert_eq!(SameBoxGroups::find(&tris).is_some(), copies >= MIN_GROUP);
        }
    }

    #[test]
    fn distinct_boxes_give_no_groups() {
        let tris = [
            tri([0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
            tri([0.0; 3], [2.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
        ];
        assert!(SameBoxGroups::find(&tris).is_none());
    }

    #[test]
    fn same_box_different_triangles_share_a_group_in_index_order() {
        let a = tri([0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        // Same box, other diagonal.
        let b = tri([1.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        let c = tri([0.0; 3], [3.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        // -0.0 bounds the same box as 0.0.
        let d = tri([-0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        let mut tris = vec![c, a, b, d];
        tris.extend(std::iter::repeat_n(a, MIN_GROUP - 3));
        let g = SameBoxGroups::find(&tris).expect("a group");
        assert_eq!(g.reps.len(), 2);
        assert_eq!(g.group(0), &[0]);
        let expected: Vec<u32> = (1..tris.len() as u32).collect();
        assert_eq!(g.group(1), &expected[..]);
        // One fewer sharing the box: no group.
        assert!(SameBoxGroups::find(&tris[..tris.len() - 1]).is_none());
    }

    #[test]
    fn expand_keeps_leaf_order_and_covers_every_member_once() {
        let a = tri([0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        let c = tri([0.0; 3], [3.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        // c, then a and c alternating: a's group is the odd indices.
        let n = 2 * MIN_GROUP as u32 + 1;
        let tris: Vec<Triangle> = (0..n).map(|i| if i % 2 == 1 { a } else { c }).collect();
        let g = SameBoxGroups::find(&tris).expect("groups");
        assert_eq!(g.reps.len(), 2);
        // Two leaves laid out in reverse node order: node 2 owns group 1, node 1 group 0.
        let mut fc = vec![(0, 0), (1, 1), (0, 1)];
        let mut prims = vec![1, 0];
        g.expand(&mut fc, &mut prims);
        let odd: Vec<u32> = (0..n).filter(|i| i % 2 == 1).collect();
        let even: Vec<u32> = (0..n).filter(|i| i % 2 == 0).collect();
        assert_eq!(prims, [odd.clone(), even.clone()].concat());
        assert_eq!(
            fc,
            vec![
                (0, 0),
                (odd.len() as u32, even.len() as u32),
                (0, odd.len() as u32)
            ]
        );
    }
}
