//! obvhs's BVH build (`build_bvh2_from_tris` without pre-splits) taken apart
//! into its phases, so that `check --timeout` and `render --timeout` can stop
//! it: the deadline is checked after the PLOC build, after each of the
//! reinsertion optimizer's passes (16 before the leaf collapse, 16 after) and
//! after the collapse. The phases, their order and their parameters are
//! obvhs's own, so the tree is the one `build_bvh2_from_tris` makes (a test
//! compares them node for node).
//!
//! A phase already running cannot be stopped, and the PLOC build is
//! quadratic in near-duplicate triangles (boxes a few f32 steps apart, which
//! `same_box` does not merge: 20,000 took 5 s, 40,000 21 s in a release
//! build). So with a deadline the phases run on a thread of their own and the
//! caller waits for them only until the deadline: past it the render goes on
//! without a tree (and is discarded as timed out), while the thread finishes
//! the phase it is in, stops at its next check and drops its work. Its
//! parallel loops then run on rayon's global pool. Without a deadline the
//! phases run on the caller's thread and pool, as before.

use obvhs::bvh2::leaf_collapser::collapse;
use obvhs::bvh2::reinsertion::ReinsertionOptimizer;
use obvhs::bvh2::Bvh2;
use obvhs::ploc::PlocBuilder;
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;
use std::time::Instant;

/// The reinsertion optimizer's default sequence of batch ratios (obvhs's
/// `optimize_impl` with no sequence given: 1/1, 1/3, ..., 1/31), one pass each.
fn ratio_sequence() -> impl Iterator<Item = f32> {
    (1..32).step_by(2).map(|n| 1.0 / n as f32)
}

/// Runs the reinsertion optimizer one ratio at a time (the same passes as
/// one call with the whole sequence: each pass starts from cleared state),
/// stopping early past `deadline`. False when stopped.
fn reinsert(bvh: &mut Bvh2, batch_ratio: f32, deadline: Option<Instant>) -> bool {
    let mut opt = ReinsertionOptimizer::default();
    for r in ratio_sequence() {
        if crate::deadline::past(deadline) {
            return false;
        }
        opt.run(bvh, batch_ratio, Some(vec![r]));
    }
    true
}

/// obvhs's `build_bvh2_from_tris` for `params` with `pre_split` off, or
/// None once `deadline` has passed (by then, whatever phase is running).
pub fn build_bvh2(
    tris: &[Triangle],
    params: BvhBuildParams,
    deadline: Option<Instant>,
) -> Option<Bvh2> {
    let Some(d) = deadline else {
        return phases(tris, params, None);
    };
    let owned = tris.to_vec();
    let (tx, rx) = std::sync::mpsc::channel();
    let spawned = std::thread::Builder::new()
        .name("rendiff-bvh-build".into())
        .spawn(move || {
            // The receiver may be gone (the deadline passed): nothing to tell.
            let _ = tx.send(phases(&owned, params, Some(d)));
        });
    if spawned.is_err() {
        // No thread to be had: build here, stopping between phases only.
        return phases(tris, params, deadline);
    }
    rx.recv_timeout(d.saturating_duration_since(Instant::now()))
        .ok()
        .flatten()
}

/// The phases, the deadline checked between them.
fn phases(tris: &[Triangle], params: BvhBuildParams, deadline: Option<Instant>) -> Option<Bvh2> {
    debug_assert!(
        !params.pre_split,
        "pre-splits would give a triangle several boxes"
    );
    let indices: Vec<u32> = (0..tris.len() as u32).collect();
    let mut bvh = PlocBuilder::with_capacity(tris.len()).build(
        params.ploc_search_distance,
        tris,
        indices,
        params.sort_precision,
        params.search_depth_threshold,
    );
    bvh.uses_spatial_splits = false;
    if !reinsert(&mut bvh, params.reinsertion_batch_ratio, deadline) {
        return None;
    }
    collapse(
        &mut bvh,
        params.max_prims_per_leaf.clamp(1, 255),
        params.collapse_traversal_cost,
    );
    let post =
        params.reinsertion_batch_ratio * params.post_collapse_reinsertion_batch_ratio_multiplier;
    if !reinsert(&mut bvh, post, deadline) || crate::deadline::past(deadline) {
        return None;
    }
    #[cfg(debug_assertions)]
    {
        bvh.validate(tris, false, false);
    }
    Some(bvh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::BvhQuality;
    use obvhs::bvh2::builder::build_bvh2_from_tris;
    use std::time::Duration;

    /// The shared test scatter as obvhs's triangles.
    fn scattered(n: usize) -> Vec<Triangle> {
        crate::trace::test_tris::scattered(n, 0x9E37_79B9_7F4A_7C15)
            .iter()
            .map(|t| Triangle {
                v0: t[0].into(),
                v1: t[1].into(),
                v2: t[2].into(),
            })
            .collect()
    }

    /// Phase by phase, the tree obvhs's own builder makes, node for node.
    #[test]
    fn the_phased_build_is_obvhs_build() {
        use crate::names::Named;
        for &q in BvhQuality::ALL {
            let Some(params) = q.params() else {
                continue; // the linear BVH, not obvhs's builder
            };
            let tris = scattered(5000);
            let ours = build_bvh2(&tris, params, None).unwrap();
            let theirs = build_bvh2_from_tris(&tris, params, &mut Duration::default());
            assert_eq!(ours.primitive_indices, theirs.primitive_indices, "{q:?}");
            assert_eq!(ours.nodes.len(), theirs.nodes.len(), "{q:?}");
            for (a, b) in ours.nodes.iter().zip(&theirs.nodes) {
                assert_eq!(
                    (a.aabb.min, a.aabb.max, a.first_index, a.prim_count),
                    (b.aabb.min, b.aabb.max, b.first_index, b.prim_count),
                    "{q:?}"
                );
            }
        }
    }

    /// A deadline already past stops it (on the thread and between phases);
    /// a distant one changes nothing in the tree.
    #[test]
    fn a_past_deadline_stops_the_build() {
        let tris = scattered(2000);
        let p = BvhQuality::Medium.params().unwrap();
        assert!(build_bvh2(&tris, p, Some(Instant::now())).is_none());
        assert!(phases(&tris, p, Some(Instant::now())).is_none());
        let later = build_bvh2(&tris, p, Some(Instant::now() + Duration::from_secs(3600))).unwrap();
        let free = build_bvh2(&tris, p, None).unwrap();
        assert_eq!(later.primitive_indices, free.primitive_indices);
        assert_eq!(later.nodes.len(), free.nodes.len());
    }
}
