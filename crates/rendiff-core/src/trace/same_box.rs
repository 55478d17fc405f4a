//! Triangles whose boxes are bit-identical, built as one BVH primitive.
//!
//! obvhs's PLOC builder merges mutually nearest clusters, with the merged box's
//! surface area as the distance. Among `n` clusters with the same box every
//! distance ties, only a pair or so merges per pass, and the build is
//! quadratic: 20k copies of one triangle took 24 s, where 20k distinct ones
//! take milliseconds. No box can separate such triangles anyway (a node's box
//! would be the same for any split of them), so nothing is lost by handing the
//! builder one primitive per distinct box and expanding each leaf's range
//! afterwards into the triangles that share it. Leaves come out in the builder's
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
    /// Groups `tris`; `None` when every box is distinct (the common case), so
    /// the caller builds over `tris` as they are.
    pub fn find(tris: &[Triangle]) -> Option<SameBoxGroups> {
        let mut keyed: Vec<(BoxKey, u32)> = tris
            .par_iter()
            .enumerate()
            .map(|(i, t)| (box_key(t), i as u32))
            .collect();
        // Ties broken by index, so each group lists its triangles in ascending order
        // and the first is its lowest index.
        keyed.par_sort_unstable();
        if keyed.windows(2).all(|w| w[0].0 != w[1].0) {
            return None;
        }
        let mut runs: Vec<(u32, u32, u32)> = Vec::new(); // (lowest index, start, len)
        let mut start = 0usize;
        for i in 1..=keyed.len() {
            if i == keyed.len() || keyed[i].0 != keyed[start].0 {
                runs.push((keyed[start].1, start as u32, (i - start) as u32));
                start = i;
            }
        }
        runs.sort_unstable_by_key(|r| r.0);
        let mut reps = Vec::with_capacity(runs.len());
        let mut members = Vec::with_capacity(keyed.len());
        let mut starts = Vec::with_capacity(runs.len() + 1);
        for &(lowest, s, n) in &runs {
            reps.push(tris[lowest as usize]);
            starts.push(members.len() as u32);
            members.extend(keyed[s as usize..(s + n) as usize].iter().map(|k| k.1));
        }
        starts.push(members.len() as u32);
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
        let g = SameBoxGroups::find(&[c, a, b, d]).expect("a group");
        assert_eq!(g.reps.len(), 2);
        assert_eq!(g.group(0), &[0]);
        assert_eq!(g.group(1), &[1, 2, 3]);
    }

    #[test]
    fn expand_keeps_leaf_order_and_covers_every_member_once() {
        let a = tri([0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        let c = tri([0.0; 3], [3.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        let g = SameBoxGroups::find(&[a, c, a, a, c]).expect("groups");
        // Two leaves laid out in reverse node order: node 2 owns group 1, node 1 group 0.
        let mut fc = vec![(0, 0), (1, 1), (0, 1)];
        let mut prims = vec![1, 0];
        g.expand(&mut fc, &mut prims);
        assert_eq!(prims, vec![1, 4, 0, 2, 3]);
        assert_eq!(fc, vec![(0, 0), (2, 3), (0, 2)]);
    }
}
