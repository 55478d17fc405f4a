//! The scene's corners numbered by vertex identity, once, for every reader of
//! the resolved scene (`vertex_ids.u32`, docs/resolved-scene.md).
//!
//! Why here: the verifier finds the edges two triangles share by vertex
//! identity (harness `judge/verify.py`, `topology`), and numbering the 3.9M
//! corners of `million` in numpy (two argsorts of a 64-bit key, each in a
//! fresh process) took 2-3 s of the comparison's CPU on every check. Here it
//! is one parallel sort of one 128-bit word per corner, during the export the
//! check does anyway. The harness checks a numbering in one linear pass before
//! it uses it, and numbers the corners itself where the file is absent
//! (`contract/vertex_ids.py`, `checked` and `group`): two implementations of
//! one convention, each the other's test.

use super::resolve::Tri;
use anyhow::{bail, Result};
use rayon::slice::ParallelSliceMut;

/// A corner's coordinates as one key that orders as their 12 little-endian
/// bytes compare (memcmp order), `-0.0` made `+0.0` first.
fn key(v: glam::Vec3) -> u128 {
    // -0.0 + 0.0 is +0.0 in round-to-nearest; every other value is unchanged.
    let b = |c: f32| u128::from((c + 0.0).to_bits().swap_bytes());
    (b(v.x) << 64) | (b(v.y) << 32) | b(v.z)
}

/// Per corner (three per triangle, in `triangles` order): the number of its
/// vertex among the scene's distinct vertices. Two corners share a number
/// exactly when their f32 coordinates are equal bit for bit once `-0.0` is
/// made `+0.0`; numbers run from 0 in the order of the vertices' 12
/// little-endian bytes, the numbering `np.unique` gives 12-byte rows (so the
/// harness's own numbering and this one are the same numbers).
///
/// Fails only for a scene of 2^32 corners or more (the numbers are u32).
pub fn vertex_ids(triangles: &[Tri]) -> Result<Vec<u32>> {
    let corners = triangles.len() * 3;
    if corners > u32::MAX as usize {
        bail!("{corners} triangle corners: vertex numbers are u32, at most 2^32 - 1 corners");
    }
    // The key in the high 96 bits, the corner's index in the low 32: one
    // sort orders the corners by vertex, equal vertices side by side.
    let mut keyed: Vec<u128> = triangles
        .iter()
        .flatten()
        .enumerate()
        .map(|(i, &v)| (key(v) << 32) | i as u128)
        .collect();
    keyed.par_sort_unstable();
    let mut ids = vec![0u32; corners];
    let mut number = 0u32;
    for (k, w) in keyed.iter().enumerate() {
        if k > 0 && w >> 32 != keyed[k - 1] >> 32 {
            number += 1;
        }
        ids[(*w as u32) as usize] = number;
    }
    Ok(ids)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn tri(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> Tri {
        [Vec3::from(a), Vec3::from(b), Vec3::from(c)]
    }

    #[test]
    fn equal_corners_share_a_number_and_signed_zeros_are_one_vertex() {
        let tris = [
            tri([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
            tri([1.0, 0.0, 0.0], [-0.0, 1.0, 0.0], [1.0, 1.0, -0.0]),
        ];
        let ids = vertex_ids(&tris).unwrap();
        assert_eq!(ids[1], ids[3], "the same vertex twice");
        assert_eq!(ids[2], ids[4], "-0.0 and +0.0 are one vertex");
        assert_eq!(ids.iter().max(), Some(&3), "four distinct vertices");
        // A vertex one f32 step away is another vertex.
        let next = f32::from_bits(1.0f32.to_bits() + 1);
        let ids = vertex_ids(&[tri([1.0, 0.0, 0.0], [next, 0.0, 0.0], [1.0, 0.0, 0.0])]).unwrap();
        assert_eq!((ids[0] == ids[2], ids[0] == ids[1]), (true, false));
    }

    /// The numbers follow the coordinates' little-endian bytes, not their
    /// values: 2.0 (bytes 00 00 00 40) comes before 1.0 (00 00 80 3f), and
    /// x decides before y, y before z.
    #[test]
    fn numbers_run_in_the_vertices_byte_order() {
        let tris = [
            tri([1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 0.0, 1.0]),
            tri([2.0, 1.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]),
        ];
        let ids = vertex_ids(&tris).unwrap();
        // Byte order: (0,0,0) < (2,0,0) < (2,0,1) < (2,1,0) < (1,0,0).
        assert_eq!(ids, vec![4, 1, 2, 3, 0, 4]);
    }

    /// Against a plain reference: distinct byte strings sorted, each corner
    /// looked up, on a scatter with many repeats.
    #[test]
    fn agrees_with_sorting_the_byte_strings() {
        let pts: Vec<Tri> = crate::trace::test_tris::scattered(500, 7)
            .into_iter()
            .map(|t| t.map(|v| (v * 4.0).round() / 4.0))
            .collect();
        let bytes = |v: Vec3| -> Vec<u8> {
            [v.x, v.y, v.z]
                .iter()
                .flat_map(|c| (c + 0.0).to_le_bytes())
                .collect()
        };
        let mut distinct: Vec<Vec<u8>> = pts.iter().flatten().map(|&v| bytes(v)).collect();
        distinct.sort();
        distinct.dedup();
        let want: Vec<u32> = pts
            .iter()
            .flatten()
            .map(|&v| distinct.binary_search(&bytes(v)).unwrap() as u32)
            .collect();
        assert!(
            distinct.len() < pts.len() * 3,
            "the scatter repeats vertices"
        );
        assert_eq!(vertex_ids(&pts).unwrap(), want);
        assert!(vertex_ids(&[]).unwrap().is_empty());
    }
}
