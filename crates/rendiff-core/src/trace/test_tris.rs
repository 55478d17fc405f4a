//! Test triangles shared by unit tests (the builders' `build.rs`, `linear.rs`;
//! `scene/vertex_ids.rs`).

use crate::scene::resolve::Tri;
use glam::Vec3;

/// `n` triangles scattered in a 10-unit cube by an xorshift from `seed`:
/// every seventh large (3 units), the rest small (0.05), so the builders
/// meet overlapping boxes of two sizes. Deterministic for a seed.
pub(crate) fn scattered(n: usize, seed: u64) -> Vec<Tri> {
    let mut s = seed | 1;
    let mut f = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32
    };
    (0..n)
        .map(|i| {
            let c = Vec3::new(f(), f(), f()) * 10.0;
            let size = if i % 7 == 0 { 3.0 } else { 0.05 };
            [
                c,
                c + Vec3::new(f(), f(), 0.0) * size,
                c + Vec3::new(0.0, f(), f()) * size,
            ]
        })
        .collect()
}
