//! The rasterizer's fast path: edge functions evaluated for eight pixels at a
//! time, deciding coverage where a proven error bound vouches for every sign
//! needed, and leaving every other pixel to [`crate::visibility`]'s exact
//! predicate.
//!
//! # What is evaluated
//!
//! For edge `k` (a->b, b->c, c->a) the value is the predicate filter's own
//! determinant, `det = Dx nx + Dy ny + Dz nz` (left to right, no FMA), with
//! `n = (a - e) x (b - e)` the f64 [`EdgePlane`] normal and `D = P - e` the
//! pixel ray's rounded direction. It is evaluated directly per pixel from the
//! tile's f64 directions (no incremental stepping, so no accumulation error),
//! one 8-pixel chunk of a tile row at a time, in a loop the compiler
//! vectorizes (256-bit when the CPU has AVX2).
//!
//! # The bound ([`FAST_EDGE_BOUND`])
//!
//! Let `u = 2^-53` and `E = N . (P - e)` the exact value (N from exact
//! differences), whose sign is the orientation. Expanded, `E` is a sum of six
//! terms `+-(P_i - e_i)(a_j - e_j)(b_k - e_k)`. The computed `det` carries
//! each term through at most 8 roundings: three differences (`D_i`, `ad_j`,
//! `bd_k`), the product `ad_j bd_k`, the subtraction forming `n_i`, the
//! product `D_i n_i`, and two additions (the last term only one). So
//! `det = sum t (1 + th_t)` with `|th_t| <= g8 = 8u / (1 - 8u)`, and
//! `|det - E| <= g8 S*`, `S* = sum |t|`. Replacing exact values by computed
//! ones, `|x| <= |fl(x)| / (1 - u)` per rounding: three differences, then
//! `perm_i = fl(|fl(ad_j bd_k)| + |fl(ad_k bd_j)|)` (two roundings), then the
//! tile's `S = fl(fl(fl(Mx permx) + fl(My permy)) + fl(Mz permz))` with
//! `M_i >= |D_i|` the tile's largest direction component (three roundings), so
//! `S* <= S / (1 - u)^8`. The bound `B = fl(9u S) >= 9u S (1 - u)`, hence
//! `|det - E| <= B (8/9) / ((1 - 8u)(1 - u)^9) < B`: when `det > B` the
//! orientation is positive, when `-det > B` negative; otherwise the pixel
//! goes to the exact predicate. (As for Shewchuk's filter, the rounding model
//! assumes no underflow or overflow; a non-finite `B` decides nothing, and
//! the next paragraph makes the fast path never less safe than that filter.)
//!
//! # Why the raster's output cannot change
//!
//! The filter in [`EdgePlane::sign_with`] computes the same `det` from the
//! same operands and compares it with `b = fl(o3derrboundA fl(sum |D_i|
//! perm_i))`, `o3derrboundA = 7u + 56u^2 < 9u`. Round-to-nearest is monotone,
//! all operands are non-negative and `M_i >= |D_i|`, so `B >= b` for every
//! pixel of the tile (a NaN `B` decides nothing; a finite `B` implies a finite
//! `b`). So a sign the fast path gives is one the filter would have returned
//! at once, without exact arithmetic or the tie rule: coverage, depth, IDs and
//! every operation count are those of the pure predicate path
//! ([`crate::raster::render_exact`]); tests compare the two bit for bit.

//!
//! # Whole 8x8 blocks ([`FastEdges::block`])
//!
//! Let `E(p) = N . δ_p` be the exact orientation at pixel `p`, `δ_p = P_p - e`
//! exactly. The ideal direction `g_p = f + r sx_p + u sy_p` (exact screen
//! coordinates of the center, the camera's f64 basis) is affine in the
//! pixel's column and row, so `G(p) = N . g_p` is too, and over an 8x8 block
//! `G(p) >= min G(corners)` (the block is the convex hull of its corner
//! centers). The pixel ray's rounding moves `δ` off `g` by `|δ_j - g_j| <=
//! η_j = 16U H_j`, `H_j = |e_j| + |f_j| + |r_j| A + |u_j| T` (A = aspect
//! tan, T = tan(vfov / 2)): the screen coordinates carry at most `4U A`,
//! `4U T`, the sum `f + r sx + u sy` three roundings, `P = e + d` one, in all
//! `9U H_j + O(U²)`. With `ρ = Σ_j |N_j| η_j`, `|E(p) - G(p)| <= ρ`. The
//! corners' `G` is read off the screen-space form `G'` of the next section,
//! within `δ`: so when every corner's `G'` exceeds `B_block = 3B + 4 Σ_j
//! perm_j η_j`, `G(p) >= min_c G(c) > B_block - δ` at every pixel of the
//! block, and (next section) `det_p > B`: the sign is the one the chunk test
//! above gives at `p`, and (as `B >= b`) the one the predicate's filter
//! gives, without exact arithmetic or the tie rule. Likewise for `-G'`. No
//! pixel ray is needed. A block whose certain signs reject or cover all its
//! pixels by [`ChunkSigns`]' rules is thereby decided exactly as its 64
//! pixels would be one by one, with the same counts.
//! `tests::block_signs_hold_at_every_pixel` checks the claim pixel by pixel
//! on edges through block corners, and that a block bound of 0 breaks it.
//!
//! # Screen-space signs ([`FastEdges::screen_chunk`], block corners)
//!
//! A chunk whose rays were never written (a block on a big triangle's edge),
//! and a block's corners, take their signs from screen coordinates alone.
//! Per edge, `a = fl(n . r)`,
//! `b = fl(n . v)`, `c = fl(n . f)` (the f64 normal `n`, the camera's f64
//! right, up and forward), and per lane `G' = fl(fl(a sx) + fl(fl(b sy) + c))`
//! with the tile's computed `sx`, `sy`. `G'` is off the exact `G(p) = N . g_p`
//! of the block argument by at most `δ`, the sum of:
//! - the evaluation, against `n . g'` with `g' = f + r sx + v sy` at the
//!   computed coordinates taken as exact: `6u Σ_j |n_j| H_j` (three
//!   roundings in each coefficient, three in the evaluation: the bound
//!   [`crate::raster::screen_depth`] derives for its `den`, with `|sx| <= A`,
//!   `|sy| <= T`);
//! - the coordinates' own rounding, `|g' - g| <= 4u (|r_j| A + |v_j| T)` per
//!   component: `4u Σ_j |n_j| H_j`;
//! - the normal's rounding: `n_i = fl(fl(ad_j bd_k) - fl(ad_k bd_j))` from
//!   rounded differences is within `γ4 (|x1| + |x2|) <= 4.0001u perm_i` of
//!   `N_i` (`x1, x2` the exact products), so `|n . g - N . g| <= 4.0001u
//!   Σ_j perm_j H_j`.
//!
//! With `|n_j| <= 1.0001 perm_j`, `δ <= 14.01u Σ_j perm_j H_j <= 0.876 Σ_j
//! perm_j η_j` (`η_j = 16u H_j`), and `|E(p) - G(p)| <= ρ <= 1.0001 Σ_j perm_j
//! η_j` (`|N_i| <= |x1| + |x2|`). So `G > B_block - δ` at a pixel (from its
//! own `G'`, or from a block's corners) gives `E(p) > 3B + 2.1 Σ_j perm_j
//! η_j` and `det_p > E(p) - B > B`: the sign [`FastEdges::chunk`] gives at
//! `p`, hence the predicate filter's. Likewise for `-G'`; NaN decides
//! nothing. A lane this leaves open sends its row to the rays'
//! chunk (writing the tile's rays first), so counts and buffers are the
//! predicate path's. `tests::screen_signs_are_chunk_signs` checks every sign
//! against the rays' chunk on edges through pixel centers, with eyes up to
//! 1e7 from the origin, and that a bound of 0 breaks it.

use crate::camera::{Camera, PixelRay};
use crate::predicate::EdgePlane;
use crate::raster::screen_depth::ScreenRow;
use crate::scene::resolve::Tri;
#[cfg(doc)]
use crate::simd::Avx2;
use crate::simd::Portable;
use crate::visibility::{hit_key, TriDepth, TriEdges, NO_HIT};
use glam::DVec3;

/// Unit roundoff of f64.
const U: f64 = f64::EPSILON / 2.0;

/// The fast path's coefficient on the tile permanent `S` (see the module
/// documentation for the derivation): 9u, above the 8u (plus second-order
/// terms) the evaluation can err by, and above the predicate filter's
/// `7u + 56u^2`, so every sign it gives is one the filter gives too.
pub const FAST_EDGE_BOUND: f64 = 9.0 * U;

// Every sign the fast path gives must be one the predicate's filter gives (module documentation).
const _: () = assert!(FAST_EDGE_BOUND >= crate::predicate::O3D_ERRBOUND_A);

/// Pixels per chunk: one evaluation step (two 256-bit vectors of f64).
pub const CHUNK: usize = 8;

/// The 8 rows of 8 keys of one block of a tile, to write.
pub type BlockRows<'a> = [&'a mut [u64; CHUNK]; CHUNK];

/// The raster's operations on a chunk of 8 pixels (and the tracer's depths):
/// plain Rust everywhere ([`Portable`]: the default methods, which are the
/// definitions), AVX2 intrinsics where the CPU has it ([`Avx2`], in
/// [`crate::simd`]); e.g. 8 comparisons become 8 mask bits by one `vcmppd` +
/// `vmovmskpd` per half. Both give the same bits (tests check it).
pub trait ChunkOps: Copy {
    /// Bit `j` set where `a[j] > b` (false for NaN).
    fn gt(self, a: &[f64; CHUNK], b: f64) -> u32;

    /// The predicate's own f64 filter ([`EdgePlane::sign_with`]: the same
    /// operands in the same order) for the three edge planes `e` at four
    /// rays whose directions `d` hold one ray per lane: per edge, the lanes
    /// whose sign it settles as positive and as negative (NaN: neither).
    /// (Boxes of a few pixels, [`crate::raster`]'s `small_box`: all signs
    /// at once, without a branch per sign.)
    #[inline(always)]
    fn filter4(self, e: &[EdgePlane; 3], d: &[[f64; 4]; 3]) -> ([u32; 3], [u32; 3]) {
        let (mut pos, mut neg) = ([0u32; 3], [0u32; 3]);
        for (k, e) in e.iter().enumerate() {
            let [dx, dy, dz] = d;
            for (j, ((&x, &y), &z)) in dx.iter().zip(dy).zip(dz).enumerate() {
                let (det, bound) = e.filter(x, y, z);
                pos[k] |= u32::from(det > bound) << j;
                neg[k] |= u32::from(-det > bound) << j;
            }
        }
        (pos, neg)
    }

    /// [`ChunkOps::filter4`] for the edge planes of triangle `t` seen from
    /// `eye` ([`EdgePlane::new`]'s operations, edge by edge) at the first
    /// `n` rays of `d`, folded into what a small box needs, bit `j` for ray
    /// `j`: the rays whose three signs it settles as positive (`front`), as
    /// negative (`back`), and those with a sign left open (`open`). This is
    /// the definition; the AVX2 form puts one plane per lane instead of one
    /// ray, so that a box of a pixel or two pays for its own rays only.
    #[inline(always)]
    fn small_signs(self, eye: DVec3, t: &Tri, d: &[[f64; 4]; 3], n: usize) -> (u32, u32, u32) {
        let (a, b, c) = (t[0].as_dvec3(), t[1].as_dvec3(), t[2].as_dvec3());
        let planes = [
            EdgePlane::new(eye, a, b),
            EdgePlane::new(eye, b, c),
            EdgePlane::new(eye, c, a),
        ];
        let (pos, neg) = Portable.filter4(&planes, d);
        let lanes = (1u32 << n) - 1;
        let front = pos[0] & pos[1] & pos[2] & lanes;
        let back = neg[0] & neg[1] & neg[2] & lanes;
        let open = (!(pos[0] | neg[0]) | !(pos[1] | neg[1]) | !(pos[2] | neg[2])) & lanes;
        (front, back, open)
    }

    /// [`ChunkDepth::new`] of [`TriDepth::new`] for triangle `t`: the
    /// definition. The AVX2 form does the three axes' f64 arithmetic in one
    /// vector each (the tracer sets this up once per triangle a packet
    /// hits, for a pixel or four, and the raster once per covered small box).
    #[inline(always)]
    fn chunk_depth(self, cam: &Camera, t: &Tri) -> ChunkDepth {
        ChunkDepth::new_inlined(cam, &TriDepth::new(cam, t))
    }

    /// One row of one component of a tile's directions, `d[i] = (e +
    /// (across[i] + up)) - e` ([`Camera::screen_ray`]'s roundings, see
    /// [`TileRays::fill`]), its values taken into `ext` as they are written
    /// (none where the tile's corners already gave the span).
    #[inline(always)]
    fn dir_row(self, e: f64, up: f64, across: &[f64], d: &mut [f64], ext: Option<&mut Extremes>) {
        for (d, &a) in d.iter_mut().zip(across) {
            *d = dir_lane(e, up, a);
        }
        if let Some(ext) = ext {
            ext.add(d);
        }
    }

    /// One row of a tile's planar factors, `p[i] = D_i . f` (`DVec3::dot`:
    /// left to right).
    #[inline(always)]
    fn planar_row(self, f: [f64; 3], [x, y, z]: [&[f64]; 3], p: &mut [f64]) {
        for (((p, &x), &y), &z) in p.iter_mut().zip(x).zip(y).zip(z) {
            *p = x * f[0] + y * f[1] + z * f[2];
        }
    }

    /// [`ChunkDepth`]'s shortcut over 8 lanes in wide registers: the
    /// depths, the mask of lanes with a depth, and the mask of lanes the
    /// clamp-free test settles (whose depths alone are meaningful); `None`
    /// where there is no such code (the lane loop then does it all). Only
    /// the lanes in `want` are asked for: a vector of lanes with none of
    /// them may be skipped, its lanes then neither with a depth nor settled
    /// (the packet tracer's hits often lie in one half of a row).
    #[inline(always)]
    fn clamp_free_depths(
        self,
        _cd: &ChunkDepth,
        _cam: &Camera,
        _d: [&[f64; CHUNK]; 3],
        _planar: &[f64; CHUNK],
        _want: u32,
    ) -> Option<([f32; CHUNK], u32, u32)> {
        None
    }

    /// [`ScreenRow::lanes`] (its definition) for the 8 lanes of columns
    /// `sx`, in wide registers where the CPU has them.
    #[inline(always)]
    fn screen_row(self, p: &ScreenRow, sx: &[f64; CHUNK]) -> ([f32; CHUNK], u32, u32) {
        p.lanes(sx)
    }

    /// [`ChunkOps::screen_row`] and [`ChunkOps::min_keys`] in one pass over the 8
    /// rows of a block whose lanes all hit: row `i` has `R = r[i]` (the
    /// rest of `p` is the block's) and its keys `rows[i]`.
    /// A row whose every lane is certified has its keys lowered, and its
    /// bit set in the returned mask; other rows are left as they were.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn screen_keys(
        self,
        p: &ScreenRow,
        r: &[f64; CHUNK],
        sx: &[f64; CHUNK],
        rows: &mut BlockRows,
        prim: u32,
    ) -> u32 {
        let mut done = 0;
        for (i, &r) in r.iter().enumerate() {
            let (z, _, sure) = ScreenRow { r, ..*p }.lanes(sx);
            if sure == 0xff {
                self.min_keys(rows[i], &z, 0xff, prim);
                done |= 1 << i;
            }
        }
        done
    }

    /// Each of a block's 8 rows of keys lowered to its row's `key` where
    /// that is smaller (`NO_HIT`: unchanged).
    #[inline(always)]
    fn min_key_rows(self, rows: &mut BlockRows, key: &[u64; CHUNK]) {
        for (row, &k) in rows.iter_mut().zip(key) {
            for t in row.iter_mut() {
                *t = (*t).min(k);
            }
        }
    }

    /// Each key of `keys` lowered to `hit_key(z[j], prim)` where lane `j`
    /// of `hits` is set and that key is smaller (the z-buffer test, 8 at a time).
    #[inline(always)]
    fn min_keys(self, keys: &mut [u64; CHUNK], z: &[f32; CHUNK], hits: u32, prim: u32) {
        for (j, key) in keys.iter_mut().enumerate() {
            let k = if (hits >> j) & 1 == 1 {
                hit_key(z[j], prim)
            } else {
                NO_HIT
            };
            *key = (*key).min(k);
        }
    }
}

/// What a scan of a tile's direction components finds ([`row_stats_scalar`],
/// the definition [`Span::stats`] must equal).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RowStats {
    /// The largest magnitude that is not NaN.
    pub max: f64,
    /// Some value is NaN or infinite.
    pub non_finite: bool,
    /// Some value is subnormal.
    pub subnormal: bool,
}

/// [`RowStats`] one value at a time: the definition, and the rare tiles'
/// fallback ([`Span::stats`]).
#[inline(always)]
fn row_stats_scalar(v: &[f64]) -> RowStats {
    let mut out = RowStats {
        max: 0.0,
        non_finite: false,
        subnormal: false,
    };
    for &x in v {
        let a = x.abs();
        out.max = if a > out.max { a } else { out.max };
        out.non_finite |= !a.is_finite();
        out.subnormal |= a != 0.0 && a < f64::MIN_POSITIVE;
    }
    out
}

/// Running extremes of values, four lanes wide (min, max and a sum that
/// turns NaN at the first NaN or infinity): two compares and a
/// multiply-add per four values, in plain Rust that vectorizes
/// (`if x < lo { x } else { lo }` is exactly `minpd`'s rule). The tile's
/// rays gather them as they are written, so that neither the fast path's
/// bounds ([`RowStats`]) nor the early depth test
/// ([`crate::raster::hiz::TileDepthBound`]) reads the tile again.
#[derive(Debug, Clone, Copy)]
pub struct Extremes {
    /// Smallest value per lane (NaN never enters).
    pub(crate) lo: [f64; 4],
    /// Largest value per lane.
    pub(crate) hi: [f64; 4],
    /// `Σ 0 x` per lane: 0 while every value is finite.
    pub(crate) bad: [f64; 4],
}

impl Default for Extremes {
    fn default() -> Self {
        Extremes {
            lo: [f64::INFINITY; 4],
            hi: [f64::NEG_INFINITY; 4],
            bad: [0.0; 4],
        }
    }
}

impl Extremes {
    /// Takes in the values of `v`.
    #[inline(always)]
    pub fn add(&mut self, v: &[f64]) {
        // Locals and fixed-size quads: what LLVM turns into 4-lane vectors.
        let Extremes {
            mut lo,
            mut hi,
            mut bad,
        } = *self;
        let mut lane = |j: usize, x: f64| {
            lo[j] = if x < lo[j] { x } else { lo[j] };
            hi[j] = if x > hi[j] { x } else { hi[j] };
            bad[j] += x * 0.0;
        };
        let mut quads = v.chunks_exact(4);
        for q in &mut quads {
            let q: &[f64; 4] = q.try_into().unwrap();
            for (j, &x) in q.iter().enumerate() {
                lane(j, x);
            }
        }
        for (j, &x) in quads.remainder().iter().enumerate() {
            lane(j, x);
        }
        *self = Extremes { lo, hi, bad };
    }

    /// The extremes over all lanes.
    #[inline(always)]
    pub fn span(&self) -> Span {
        let mut out = Span {
            lo: f64::INFINITY,
            hi: f64::NEG_INFINITY,
            finite: true,
        };
        for j in 0..4 {
            out.lo = if self.lo[j] < out.lo {
                self.lo[j]
            } else {
                out.lo
            };
            out.hi = if self.hi[j] > out.hi {
                self.hi[j]
            } else {
                out.hi
            };
            out.finite &= self.bad[j] == 0.0;
        }
        out
    }
}

/// The smallest and largest of some values, and whether all are finite
/// (then `lo` and `hi` are the true extremes; empty: `+inf`, `-inf`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Span {
    /// Smallest value (meaningful when `finite`).
    pub lo: f64,
    /// Largest value.
    pub hi: f64,
    /// No value is NaN or infinite.
    pub finite: bool,
}

impl Default for Span {
    /// The span of no values.
    fn default() -> Self {
        Extremes::default().span()
    }
}

impl Span {
    /// The span of `v` (tests, and tiles not built by [`TileRays::fill`]).
    pub fn of(v: &[f64]) -> Span {
        let mut e = Extremes::default();
        e.add(v);
        e.span()
    }

    /// Every value is nonzero and of one sign.
    #[inline(always)]
    pub fn one_strict_sign(&self) -> bool {
        self.lo > 0.0 || self.hi < 0.0
    }

    /// What [`TileRays`] keeps per direction component, from the span of
    /// `v`: the largest magnitude (NaN when some value is not finite) and
    /// whether some value is subnormal, as [`row_stats_scalar`] defines
    /// them. The magnitudes are the extremes'; with one strict sign the
    /// smallest magnitude is an extreme's too, else (values crossing or
    /// touching zero, or non-finite: a few tiles of a frame) `v` is scanned.
    #[inline(always)]
    pub fn stats(&self, v: &[f64]) -> (f64, bool) {
        if self.finite && self.one_strict_sign() {
            let smallest = if self.lo > 0.0 { self.lo } else { -self.hi };
            (
                (-self.lo).max(self.hi).max(0.0),
                smallest < f64::MIN_POSITIVE,
            )
        } else {
            let r = row_stats_scalar(v);
            let max = if r.non_finite {
                f64::NAN
            } else {
                // Mixed signs: the extremes' magnitudes (finite here).
                (-self.lo).max(self.hi).max(0.0)
            };
            (max, r.subnormal)
        }
    }
}

/// Plain Rust, for any CPU: the trait's default methods are the definitions.
impl ChunkOps for Portable {
    #[inline(always)]
    fn gt(self, a: &[f64; CHUNK], b: f64) -> u32 {
        (0..CHUNK).fold(0, |m, j| m | (u32::from(a[j] > b) << j))
    }
}

/// One direction component of a pixel ray, `(e + (across + up)) - e`:
/// [`Camera::screen_ray`]'s `P = eye + ((forward + right sx) + up sy)` and
/// `D = P - eye`, with `across = forward + right sx` taken once per column
/// and `up = up_k sy` once per row.
#[inline(always)]
fn dir_lane(e: f64, up: f64, across: f64) -> f64 {
    (e + (across + up)) - e
}

/// Eight rays side by side, the unit [`ChunkDepth`] takes (a chunk of a
/// tile row, [`TileRays::rays_at`], or a row of the packet tracer's lanes):
/// their directions and planar factors, and whether a direction component
/// among them may be subnormal (then no clamp-free shortcut).
#[derive(Debug, Clone, Copy)]
pub struct ChunkRays<'a> {
    /// The directions `D`, per axis.
    pub d: [&'a [f64; CHUNK]; 3],
    /// The planar factors `D . f`.
    pub planar: &'a [f64; CHUNK],
    /// Some direction component may be subnormal.
    pub subnormal: bool,
}

/// The pixel rays of one tile, by component (structure of arrays with a fixed
/// row stride, so 8 lanes from any column of a row are one slice), and the largest magnitude of
/// each direction component over the tile (for the bound). Every value is
/// [`Camera::pixel_ray`]'s, bit for bit: it is computed by the same
/// [`Camera::screen_ray`] from the same `sx` and `sy`.
#[derive(Debug, Clone, Default)]
pub struct TileRays {
    /// Columns in the tile.
    width: usize,
    /// Row stride in pixels: the width plus at least `CHUNK - 1` padding lanes
    /// (rounded up to whole 4-lane vectors), so a
    /// chunk may start at any column (a small triangle's box then needs one chunk per row).
    stride: usize,
    /// `sx` per column (padding lanes repeat the last column).
    sx: Vec<f64>,
    /// `sy` per row.
    sy: Vec<f64>,
    /// The first row and the row count `sy` was written for (a band's
    /// tiles share them: written once per band).
    rows: Option<(u32, u32)>,
    /// The camera's eye, forward, right and up: `P` is recomputed from them
    /// for the few pixels that need it (the exact predicate).
    basis: [DVec3; 4],
    /// `D = P - eye` per component. (`1 / D` is computed where needed, by
    /// the same `1.0 / D`: most depths never need it, see [`ChunkDepth`].)
    d: [Vec<f64>; 3],
    /// `D . forward`.
    planar: Vec<f64>,
    /// `forward_k + right_k sx` per column and component (the part of `D`
    /// that does not change down a column).
    across: [Vec<f64>; 3],
    /// The span of each component of `D` over the tile's pixels.
    d_span: [Span; 3],
    /// `d_span` came from the tile's four corner pixels
    /// ([`TileRays::corner_spans`]), not from every value as it was written.
    spans_from_corners: bool,
    /// A lower bound on `planar` over the tile's pixels, from its corners
    /// alone ([`TileRays::planar_low`]; NaN when a corner is not finite).
    planar_low: f64,
    /// `max |D_i|` over the tile's pixels, per component.
    max_abs: [f64; 3],
    /// `d` and `planar` are written for this tile
    /// ([`TileRays::ensure_dirs`]).
    dirs_filled: bool,
    /// Some direction component is subnormal: its reciprocal may overflow,
    /// so [`ChunkDepth`] takes no shortcut in this tile.
    subnormal: bool,
    /// `η_j`: how far a pixel's `P - e` may lie from its ideal direction
    /// (module documentation, whole blocks).
    eta: [f64; 3],
}

/// The half of a tile's rays that depends on its columns alone: `sx` per
/// column and `forward_k + right_k sx` per column and component, padded as
/// [`TileRays`] pads its rows. Every tile of a tile column has the same, so a
/// pass makes them once per column ([`TileColumns`]) and each tile copies
/// them, rather than recomputing them (a division per column) per tile:
/// alternated in one process, 3% off the raster's pass on two
/// screen-filling triangles at 512x512 (1 thread), `million` unchanged
/// within noise. (Filling every tile's rays twice had cost a tenth of
/// that pass; the rest of the fill is the corners' per-tile statistics.)
#[derive(Debug, Clone)]
pub struct TileColumn {
    /// Columns in the tile.
    width: usize,
    /// Lanes per row: the width and its padding.
    stride: usize,
    /// `sx` per column (padding lanes repeat the last column), then
    /// `forward_k + right_k sx` per column for each component `k`: one
    /// allocation, `stride` values each.
    values: Vec<f64>,
}

impl TileColumn {
    /// The columns `x0 .. x0 + tw` ([`Camera::screen_x`], then the same
    /// products and sums [`TileRays`] used to take per tile).
    pub fn new(cam: &Camera, x0: u32, tw: u32) -> TileColumn {
        // At least CHUNK - 1 padding lanes, rounded up to whole 4-lane vectors.
        let stride = (tw as usize + CHUNK - 1).next_multiple_of(4);
        let mut values = vec![0.0; 4 * stride];
        let (sx, across) = values.split_at_mut(stride);
        for (lx, v) in sx.iter_mut().enumerate() {
            *v = cam.screen_x(x0 + (lx as u32).min(tw - 1));
        }
        let (f, r) = (cam.forward.to_array(), cam.right.to_array());
        for (k, across) in across.chunks_exact_mut(stride).enumerate() {
            for (a, &sx) in across.iter_mut().zip(&*sx) {
                *a = f[k] + r[k] * sx;
            }
        }
        TileColumn {
            width: tw as usize,
            stride,
            values,
        }
    }

    /// `sx` per column.
    #[inline(always)]
    fn sx(&self) -> &[f64] {
        &self.values[..self.stride]
    }

    /// `forward_k + right_k sx` per column.
    #[inline(always)]
    fn across(&self, k: usize) -> &[f64] {
        &self.values[(k + 1) * self.stride..(k + 2) * self.stride]
    }
}

/// Every tile column's [`TileColumn`] for one image: made once per pass.
#[derive(Debug, Clone)]
pub struct TileColumns {
    /// Pixels per tile side.
    tile: u32,
    /// Column `tx` of tiles.
    columns: Vec<TileColumn>,
}

impl TileColumns {
    /// The columns of `cam`'s image in tiles of `tile` pixels.
    pub fn new(cam: &Camera, tile: u32) -> TileColumns {
        let columns = (0..cam.width.div_ceil(tile))
            .map(|tx| {
                let x0 = tx * tile;
                TileColumn::new(cam, x0, tile.min(cam.width - x0))
            })
            .collect();
        TileColumns { tile, columns }
    }

    /// The column of the tile whose first column is `x0`.
    #[inline(always)]
    pub fn at(&self, x0: u32) -> &TileColumn {
        debug_assert_eq!(x0 % self.tile, 0);
        &self.columns[(x0 / self.tile) as usize]
    }
}

impl TileRays {
    /// The rays of the `tw` x `th` tile whose top-left pixel is `(x0, y0)`:
    /// [`Camera::screen_ray`]'s arithmetic written per component over a row,
    /// so that it vectorizes (padding lanes repeat the last column).
    #[inline(always)]
    pub fn new(cam: &Camera, x0: u32, y0: u32, tw: u32, th: u32) -> TileRays {
        let mut t = TileRays::default();
        t.fill(Portable, cam, &TileColumn::new(cam, x0, tw), y0, th);
        t.ensure_dirs(Portable);
        t
    }

    /// [`TileRays::new`] into this one's buffers, for the tile of column
    /// `col` ([`TileColumn::new`] of its `x0` and width) whose rows are
    /// `y0 .. y0 + th` (a band of tiles reuses the buffers: no allocation or
    /// zeroing per tile; start from `default()`, and keep to one camera).
    #[inline(always)]
    pub fn fill<L: ChunkOps>(&mut self, l: L, cam: &Camera, col: &TileColumn, y0: u32, th: u32) {
        let t = self;
        t.width = col.width;
        t.stride = col.stride;
        t.sx.clear();
        t.sx.extend_from_slice(col.sx());
        for (k, across) in t.across.iter_mut().enumerate() {
            across.clear();
            across.extend_from_slice(col.across(k));
        }
        // The rows are the band's: the same for each of its tiles.
        if t.rows != Some((y0, th)) {
            t.sy.clear();
            t.sy.extend((0..th).map(|ly| cam.screen_y(y0 + ly)));
            t.rows = Some((y0, th));
        }
        t.basis = [cam.eye, cam.forward, cam.right, cam.up_ortho];
        let (e, f, r, u) = (cam.eye, cam.forward, cam.right, cam.up_ortho);
        // The camera's private aspect tan, by the same expression.
        let a = cam.tan_half_vfov * (f64::from(cam.width) / f64::from(cam.height));
        let eta_k = |k: usize| {
            16.0 * U * (e[k].abs() + f[k].abs() + r[k].abs() * a + u[k].abs() * cam.tan_half_vfov)
        };
        t.eta = [eta_k(0), eta_k(1), eta_k(2)];
        let (e, f, u) = (e.to_array(), f.to_array(), u.to_array());
        let corners = t.corner_spans(e, u);
        t.spans_from_corners = corners.is_some();
        t.dirs_filled = false;
        match corners {
            Some(spans) => {
                // One strict sign and finite per component: the spans alone
                // give the statistics (`Span::stats` never scans then), and
                // the directions wait until something reads them.
                t.d_span = spans;
                // (Plain arrays: array `map` compiled to out-of-line calls here.)
                let stats = [
                    spans[0].stats(&[]),
                    spans[1].stats(&[]),
                    spans[2].stats(&[]),
                ];
                t.max_abs = [stats[0].0, stats[1].0, stats[2].0];
                t.subnormal = stats.iter().any(|&(_, subnormal)| subnormal);
            }
            None => {
                t.fill_dirs(l);
                // A NaN or infinite direction leaves a NaN bound, which decides
                // nothing (as an infinite one would).
                // (Plain arrays: array `map` compiled to out-of-line calls here.)
                let stats = [
                    t.d_span[0].stats(&t.d[0]),
                    t.d_span[1].stats(&t.d[1]),
                    t.d_span[2].stats(&t.d[2]),
                ];
                t.max_abs = [stats[0].0, stats[1].0, stats[2].0];
                t.subnormal = stats.iter().any(|&(_, subnormal)| subnormal);
            }
        }
        t.planar_low = t.planar_low(f, a, cam.tan_half_vfov);
    }

    /// The directions and planar factors of every pixel, written now if
    /// [`TileRays::fill`] left them for later (tiles whose corners gave the
    /// spans): a tile whose triangles all settle whole blocks by corners
    /// and screen-space depth ([`crate::raster::screen_depth`]) never needs
    /// them.
    #[inline(always)]
    pub fn ensure_dirs<L: ChunkOps>(&mut self, l: L) {
        if !self.dirs_filled {
            self.fill_dirs(l);
        }
    }

    /// Writes the directions and planar factors (and the spans the corners
    /// did not give).
    #[inline(always)]
    fn fill_dirs<L: ChunkOps>(&mut self, l: L) {
        let t = self;
        let (stride, rows) = (t.stride, t.sy.len());
        let n = stride * rows;
        for v in t.d.iter_mut().chain([&mut t.planar]) {
            // Every lane is written below; old values only avoid zeroing.
            v.resize(n, 0.0);
        }
        let [e, f, _, u] = t.basis;
        let (e, f, u) = (e.to_array(), f.to_array(), u.to_array());
        let from_corners = t.spans_from_corners;
        let mut d_ext = [Extremes::default(); 3];
        for ly in 0..rows {
            let sy = t.sy[ly];
            let row = ly * stride..(ly + 1) * stride;
            for (k, ext) in d_ext.iter_mut().enumerate() {
                // Camera::screen_ray: P = eye + ((forward + right sx) + up sy),
                // D = P - eye, component by component (the same roundings,
                // with `forward + right sx` taken once per column).
                let d = &mut t.d[k][row.clone()];
                let ext = (!from_corners).then_some(ext);
                l.dir_row(e[k], u[k] * sy, &t.across[k], d, ext);
            }
            let [dx, dy, dz] = &t.d;
            let d = [&dx[row.clone()], &dy[row.clone()], &dz[row.clone()]];
            // DVec3::dot(D, forward).
            l.planar_row(f, d, &mut t.planar[row.clone()]);
        }
        // Padding lanes repeat real pixels: the spans are the tile's.
        if !from_corners {
            t.d_span = [d_ext[0].span(), d_ext[1].span(), d_ext[2].span()];
        }
        t.dirs_filled = true;
    }

    /// A lower bound on every pixel's `planar = fl(D · f)` in the tile, from
    /// its four corners: `min planar(corner) - 2ε`, NaN when a corner's is
    /// not finite. (`a`: the aspect tan, `tan`: `tan(vfov / 2)`.)
    ///
    /// Why: `g = f + r sx + v sy` with the computed screen coordinates taken
    /// as exact reals makes `g · f` affine in `(sx, sy)`, and every pixel
    /// center's `(sx, sy)` lies in the rectangle of the corners' (monotone
    /// in the column and row), so its least value over the tile is a
    /// corner's. Each computed `planar` lies within `ε = 4u Σ|f_j|(H_j +
    /// η_j) + 1.01 Σ|f_j| η_j` of `g · f`: `|D_j - g_j| <= η_j`
    /// ([`crate::raster::screen_depth`] derives it from the module's `η_j`),
    /// `|g_j| <= H_j = |f_j| + |r_j| a + |v_j| tan`, and the dot product
    /// rounds by at most `3.01u Σ|f_j||D_j|`. So `planar(p) >= g·f(p) - ε
    /// >= min_c g·f(c) - ε >= min_c planar(c) - 2ε`. Costs four directions
    /// instead of the tile's, which a tile settled by whole blocks never
    /// computes ([`TileRays::ensure_dirs`]).
    #[inline(always)]
    fn planar_low(&self, f: [f64; 3], a: f64, tan: f64) -> f64 {
        let [_, _, r, v] = self.basis;
        let (last_col, last_row) = (self.width - 1, self.sy.len() - 1);
        let mut low = f64::INFINITY;
        let mut finite = true;
        for (lx, ly) in [(0, 0), (last_col, 0), (0, last_row), (last_col, last_row)] {
            let (x, y, z) = (
                self.dir_component(0, lx, ly),
                self.dir_component(1, lx, ly),
                self.dir_component(2, lx, ly),
            );
            let p = x * f[0] + y * f[1] + z * f[2];
            finite &= p.is_finite();
            low = low.min(p);
        }
        let mut eps = 0.0;
        for k in 0..3 {
            let h = f[k].abs() + r[k].abs() * a + v[k].abs() * tan;
            eps += f[k].abs() * (4.0 * U * (h + self.eta[k]) + 1.01 * self.eta[k]);
        }
        if finite {
            low - 2.0 * eps
        } else {
            f64::NAN
        }
    }

    /// Component `k` of the direction of tile pixel `(lx, ly)`, from the
    /// written directions or, before they are written, by the same
    /// arithmetic ([`dir_lane`]: equal bits).
    #[inline(always)]
    fn dir_component(&self, k: usize, lx: usize, ly: usize) -> f64 {
        if self.dirs_filled {
            self.d[k][ly * self.stride + lx]
        } else {
            let [e, _, _, u] = self.basis;
            dir_lane(e[k], u[k] * self.sy[ly], self.across[k][lx])
        }
    }

    /// The span of each direction component over the tile, from its four
    /// corner pixels alone, when those are finite and, per component, of one
    /// strict sign (`None` otherwise: the rows then gather the spans as
    /// they are written). Needs `sx`, `sy` and `across` filled.
    ///
    /// Why the corners suffice: `D_k = fl(fl(e_k + fl(A_k(x) + B_k(y))) -
    /// e_k)` with `A_k(x) = fl(f_k + fl(r_k sx(x)))` and `B_k(y) = fl(u_k
    /// sy(y))`, and `sx`, `sy` are monotone in the column and row
    /// ([`Camera::screen_x`]: `+ 0.5`, `* 2`, `/ width`, `- 1`, `* A`, each
    /// rounded; padding lanes repeat the last column). Rounding to nearest is
    /// monotone, so every step is monotone in its variable argument (a
    /// product by a negative constant reverses the order), and `D_k` is
    /// monotone in the column along each row and in the row down each
    /// column, the same way everywhere in the tile. So each value lies
    /// between the two ends of its row, and each end between the corners of
    /// its column: the least and greatest corner values are the tile's.
    /// Overflow is monotone too (to `±inf`), and with finite corners every
    /// intermediate lies between finite corner intermediates, so no value
    /// is infinite or NaN. One strict sign per component leaves no zero
    /// whose sign would depend on the order of `min`/`max` (the rescan of
    /// [`Span::stats`] is never needed). `tests::filled_tiles_keep_the_scans_statistics`
    /// compares the spans with scans, on tiles that take either way.
    #[inline(always)]
    fn corner_spans(&self, e: [f64; 3], u: [f64; 3]) -> Option<[Span; 3]> {
        let (last_col, last_row) = (self.width - 1, self.sy.len() - 1);
        let mut out = [Span::default(); 3];
        for (k, span) in out.iter_mut().enumerate() {
            for (lx, ly) in [(0, 0), (last_col, 0), (0, last_row), (last_col, last_row)] {
                let v = dir_lane(e[k], u[k] * self.sy[ly], self.across[k][lx]);
                span.lo = if v < span.lo { v } else { span.lo };
                span.hi = if v > span.hi { v } else { span.hi };
                span.finite &= v.is_finite();
            }
            if !(span.finite && span.one_strict_sign()) {
                return None;
            }
        }
        Some(out)
    }

    /// Builds the tile from given directions (tests of the edge functions).
    #[cfg(test)]
    fn from_dirs(dirs: &[[f64; 3]], tw: usize, th: usize) -> TileRays {
        let stride = tw + CHUNK - 1;
        let mut d = [(); 3].map(|_| vec![0.0; stride * th]);
        let mut max_abs = [0f64; 3];
        for (i, v) in dirs.iter().enumerate() {
            for k in 0..3 {
                d[k][(i / tw) * stride + i % tw] = v[k];
                max_abs[k] = max_abs[k].max(v[k].abs());
            }
        }
        TileRays {
            width: tw,
            stride,
            sx: vec![0.0; stride],
            sy: vec![0.0; th],
            rows: None,
            basis: [DVec3::ZERO; 4],
            planar: d[0].clone(),
            across: Default::default(),
            d_span: [0, 1, 2].map(|k| Span::of(&d[k])),
            spans_from_corners: false,
            planar_low: Span::of(&d[0]).lo,
            d,
            max_abs,
            subnormal: false,
            dirs_filled: true,
            // Unknown rays: no block is ever decided whole.
            eta: [f64::NAN; 3],
        }
    }

    /// The ray of pixel `(lx, ly)` of the tile, as [`Camera::pixel_ray`] gives it.
    #[inline(always)]
    pub fn ray(&self, lx: usize, ly: usize) -> PixelRay {
        debug_assert!(self.dirs_filled, "tile directions read before ensure_dirs");
        let at = ly * self.stride + lx;
        let v = |a: &[Vec<f64>; 3]| DVec3::new(a[0][at], a[1][at], a[2][at]);
        let [e, f, r, u] = self.basis;
        // As in `new`: Camera::screen_ray's P, component by component.
        let (sx, sy) = (self.sx[lx], self.sy[ly]);
        let p = |k: usize| e[k] + ((f[k] + r[k] * sx) + u[k] * sy);
        PixelRay {
            p: DVec3::new(p(0), p(1), p(2)),
            dir: v(&self.d),
            inv_dir: v(&self.d).recip(),
            planar: self.planar[at],
        }
    }

    /// The tile's early depth bound ([`crate::raster::hiz`]), from its frame:
    /// the corners' lower bound on `planar` and the span of `D_axis` (from
    /// the corners, or gathered when the directions were written).
    #[inline(always)]
    pub fn depth_bound(&self, cam: &Camera) -> Option<crate::raster::hiz::TileDepthBound> {
        let faces = crate::raster::hiz::NearFaces::new(cam);
        let dk = self.d_span[faces.axis()];
        crate::raster::hiz::TileDepthBound::from_low(faces.negative(), self.planar_low, dk)
    }

    /// The direction `D` of pixel `(lx, ly)`, as [`Camera::pixel_ray`] gives it.
    #[inline(always)]
    pub fn dir(&self, lx: usize, ly: usize) -> DVec3 {
        debug_assert!(self.dirs_filled, "tile directions read before ensure_dirs");
        let at = ly * self.stride + lx;
        DVec3::new(self.d[0][at], self.d[1][at], self.d[2][at])
    }

    /// The 8 rays from column `col` of tile row `row`, written out per
    /// component (`[0, 1, 2].map` of a fallible conversion compiled to an
    /// out-of-line call per chunk, with a `vzeroupper`, in the raster's
    /// hottest loop).
    #[inline(always)]
    pub(crate) fn rays_at(&self, row: usize, col: usize) -> ChunkRays<'_> {
        debug_assert!(self.dirs_filled, "tile directions read before ensure_dirs");
        fn lane(a: &[f64], at: usize) -> &[f64; CHUNK] {
            a[at..at + CHUNK].try_into().unwrap()
        }
        let at = row * self.stride + col;
        let [x, y, z] = &self.d;
        ChunkRays {
            d: [lane(x, at), lane(y, at), lane(z, at)],
            planar: lane(&self.planar, at),
            subnormal: self.subnormal,
        }
    }

    /// Columns in the tile.
    pub fn width(&self) -> usize {
        self.width
    }

    /// `sx` of the tile's columns, as [`Camera::screen_x`] computes them
    /// (padding lanes repeat the last column).
    pub(crate) fn sx(&self) -> &[f64] {
        &self.sx
    }

    /// `sy` of the tile's rows.
    pub(crate) fn sy(&self) -> &[f64] {
        &self.sy
    }

    /// `η_j` (module documentation, whole blocks): how far a pixel's `P - e`
    /// may lie from its ideal direction, per component.
    pub(crate) fn eta(&self) -> [f64; 3] {
        self.eta
    }

    /// Some direction component of the tile is subnormal (its reciprocal
    /// may overflow: no proof that skips the slab holds there).
    pub(crate) fn subnormal(&self) -> bool {
        self.subnormal
    }
}

/// [`TriDepth::depth`] for the 8 lanes of a chunk, bit for bit, written
/// lane-parallel so that it vectorizes.
///
/// # Skipping the slab clamp where it cannot bite
///
/// The depth function clamps `t = num / denom` into the triangle's slab
/// interval `[lo, hi]`; where `lo <= t <= hi` the clamp returns `t` itself,
/// and the slab (three reciprocals `1 / D_k`, six products) changes nothing.
/// That is proven per lane with products alone: with `L_k = fl(b.lo_k - e_k)`,
/// `H_k = fl(b.hi_k - e_k)`, `M_k = max(|L_k|, |H_k|)` and `q = fl(t D_k)`,
/// the lane is settled when, on every axis, `fl(L_k + 8u M_k) <= q <=
/// fl(H_k - 8u M_k)` (`u = 2^-53`; NaN and infinities fail). Guards keep
/// every rounding relative: `|t| <= 1e300` (no overflow in `L_k / D_k`),
/// `8u M_k >= 1e-280` (else the axis never passes) and no subnormal
/// direction component in the tile (whose reciprocal could overflow).
///
/// Why: take `D_k > 0` (the slab's `t0 = fl(L_k fl(1 / D_k))` is then its
/// lower bound, `t1` its upper). `t0 = (L_k / D_k)(1 + θ)`, `|θ| <= 2u + u²`,
/// so `t0 <= t` follows from `t D_k >= L_k + 2.0001u |L_k|`. Now `q` lies
/// within `[L_k, H_k]`, so `|q| <= M_k` and `t D_k >= q - 1.0001u M_k`; the
/// threshold is at least `L_k + 8u M_k - 1.0001u M_k` (its own rounding,
/// `|L_k + 8u M_k| <= 1.0001 M_k`), hence `t D_k >= L_k + 5.99u M_k`, enough.
/// `t <= t1` and the case `D_k < 0` (bounds swapped, inequalities through
/// `H_k`) are the same argument mirrored. On an axis with `D_k = 0` the slab
/// skips the axis unless the eye lies outside it, and `q = 0` inside the
/// thresholds puts it strictly inside (`L_k < 0 < H_k`). So `lo <= t <= hi`
/// and the clamp is the identity (`f64::max`/`min` of equal-or-ordered
/// values). The box is grown by `2^-48 = 32u` of the same magnitudes
/// ([`crate::visibility::grow_box`]), so a hit inside the triangle's f32
/// box passes unless `t` itself is off by more than about `20u` (grazing
/// planes); a lane that fails takes the slab as written.
/// `tests::chunk_depths_are_the_scalar_ones` checks lanes that take either
/// path, and that thresholds `1e-6 M_k` outside the box break it. (A clamp
/// that moves `t` by less than the f32 rounding of the depth changes no
/// output, so thresholds within about `1e-9 M_k` of the box, the `8u M_k`
/// margin among them, cannot be told apart by outputs: the proof above is
/// what carries the margin.)
#[derive(Debug, Clone, Copy)]
pub struct ChunkDepth {
    /// The plane normal.
    pub(crate) normal: [f64; 3],
    /// `normal . (a - eye)`.
    pub(crate) num: f64,
    /// `bounds.lo - eye`, per axis (the slab test's `b.lo[k] - origin[k]`).
    pub(crate) lo: [f64; 3],
    /// `bounds.hi - eye`, per axis.
    pub(crate) hi: [f64; 3],
    /// Per axis: a ray with `D_k = 0` misses the box (the eye is outside its slab).
    pub(crate) zero_misses: [bool; 3],
    /// Per axis, `fl(L_k + 8u M_k)`: `t D_k` above it cannot be clamped from below.
    pub(crate) clamp_free_lo: [f64; 3],
    /// Per axis, `fl(H_k - 8u M_k)`: `t D_k` below it cannot be clamped from above.
    pub(crate) clamp_free_hi: [f64; 3],
}

/// The margin of [`ChunkDepth`]'s clamp-free test, in units of `M_k`.
pub(crate) const CLAMP_FREE_MARGIN: f64 = 8.0 * U;

/// Largest `|t|` the clamp-free test accepts: far from overflow in `L_k / D_k`.
pub(crate) const CLAMP_FREE_MAX_T: f64 = 1e300;

/// Smallest margin `8u M_k` the clamp-free test uses: far above the
/// subnormal range, so the roundings it absorbs are relative ones.
pub(crate) const CLAMP_FREE_MIN_MARGIN: f64 = 1e-280;

impl ChunkDepth {
    /// Takes the scalar depth function's per-triangle data.
    pub fn new(cam: &Camera, d: &TriDepth) -> ChunkDepth {
        Self::with_margin(cam, d, CLAMP_FREE_MARGIN)
    }

    /// [`ChunkDepth::new`] inlined into the caller (the packet tracer's
    /// leaf, once per triangle a packet hits, and the raster's small boxes,
    /// once per covered one: out of line, its time moved by several percent
    /// with where the linker happened to put it).
    #[inline(always)]
    pub fn new_inlined(cam: &Camera, d: &TriDepth) -> ChunkDepth {
        Self::with_margin(cam, d, CLAMP_FREE_MARGIN)
    }

    /// [`ChunkDepth::new`] with another clamp-free margin (tests: 0 must break).
    #[inline(always)]
    fn with_margin(cam: &Camera, d: &TriDepth, margin: f64) -> ChunkDepth {
        // Arrays, not glam's run-time component index (a match per access);
        // plain loops, not array `map` (its closures compiled to out-of-line
        // calls in the packet tracer's leaf, once per hit triangle).
        let (eye, blo, bhi) = (
            cam.eye.to_array(),
            d.bounds.lo.to_array(),
            d.bounds.hi.to_array(),
        );
        let mut c = ChunkDepth {
            normal: d.normal.to_array(),
            num: d.num,
            lo: [0.0; 3],
            hi: [0.0; 3],
            zero_misses: [false; 3],
            clamp_free_lo: [f64::INFINITY; 3],
            clamp_free_hi: [f64::NEG_INFINITY; 3],
        };
        for k in 0..3 {
            let (lo, hi) = (blo[k] - eye[k], bhi[k] - eye[k]);
            let m = margin * lo.abs().max(hi.abs());
            (c.lo[k], c.hi[k]) = (lo, hi);
            c.zero_misses[k] = eye[k] < blo[k] || eye[k] > bhi[k];
            // A margin near underflow (or NaN) settles nothing: empty thresholds.
            if m.abs() >= CLAMP_FREE_MIN_MARGIN || margin == 0.0 {
                (c.clamp_free_lo[k], c.clamp_free_hi[k]) = (lo + m, hi - m);
            }
        }
        c
    }

    /// The triangle's f64 plane: `normal` and `num = normal . (a - eye)`.
    pub(crate) fn plane(&self) -> ([f64; 3], f64) {
        (self.normal, self.num)
    }

    /// The slab's planes relative to the eye, `(L_k, H_k) = (fl(b.lo_k -
    /// e_k), fl(b.hi_k - e_k))`: what the slab divides by `D_k`.
    pub(crate) fn slab_planes(&self) -> ([f64; 3], [f64; 3]) {
        (self.lo, self.hi)
    }

    /// Depths of the 8 rays `rays`, and the mask of lanes where
    /// [`TriDepth::depth`] is `Some`; exact for the lanes in `need` (the
    /// others may take the shortcut unproven).
    #[inline(always)]
    pub fn depths<L: ChunkOps>(
        &self,
        l: L,
        cam: &Camera,
        rays: ChunkRays,
        need: u32,
    ) -> ([f32; CHUNK], u32) {
        let ChunkRays {
            d,
            planar,
            subnormal,
        } = rays;
        if !subnormal {
            if let Some((z, ok, free)) = l.clamp_free_depths(self, cam, d, planar, need) {
                if need & !free == 0 {
                    return (z, ok);
                }
            }
        }
        self.lanes(cam, d.map(|v| *v), *planar, need, subnormal)
    }

    /// The wide shortcut alone ([`ChunkOps::clamp_free_depths`]) over the 8
    /// rays `rays`: depths, lanes with a depth, lanes it settles; `None`
    /// where it cannot run.
    #[inline(always)]
    pub fn clamp_free<L: ChunkOps>(
        &self,
        l: L,
        cam: &Camera,
        rays: ChunkRays,
    ) -> Option<([f32; CHUNK], u32, u32)> {
        if rays.subnormal {
            return None;
        }
        l.clamp_free_depths(self, cam, rays.d, rays.planar, 0xff)
    }

    /// [`TriDepth::depth`] of tile pixel `(lx, ly)` (boxes of a few pixels).
    #[inline(always)]
    pub fn depth_at(&self, cam: &Camera, rays: &TileRays, lx: usize, ly: usize) -> Option<f32> {
        let at = ly * rays.stride + lx;
        // (Not `[0, 1, 2].map`: array `map` compiled to an out-of-line call.)
        debug_assert!(rays.dirs_filled, "tile directions read before ensure_dirs");
        let d = [[rays.d[0][at]], [rays.d[1][at]], [rays.d[2][at]]];
        let (z, ok) = self.lanes(cam, d, [rays.planar[at]], 1, rays.subnormal);
        (ok == 1).then_some(z[0])
    }

    /// The depth function over `N` lanes of directions `d` and planar
    /// factors `planar`, exact for the lanes in `need`; `subnormal`: some
    /// direction of the tile is subnormal (no shortcut).
    #[inline(always)]
    fn lanes<const N: usize>(
        &self,
        cam: &Camera,
        d: [[f64; N]; 3],
        planar: [f64; N],
        need: u32,
        subnormal: bool,
    ) -> ([f32; N], u32) {
        // DVec3::dot: x*x' + y*y' + z*z', left to right.
        let denom: [f64; N] = std::array::from_fn(|j| {
            self.normal[0] * d[0][j] + self.normal[1] * d[1][j] + self.normal[2] * d[2][j]
        });
        let t_raw = denom.map(|v| self.num / v);
        let mut free = [true; N];
        for (k, dk) in d.iter().enumerate() {
            for j in 0..N {
                let q = t_raw[j] * dk[j];
                free[j] &= (q >= self.clamp_free_lo[k]) & (q <= self.clamp_free_hi[k]);
            }
        }
        for j in 0..N {
            // No overflow in the slab's products (see above).
            free[j] &= t_raw[j].abs() <= CLAMP_FREE_MAX_T;
        }
        let free = (0..N).fold(0u32, |m, j| m | (u32::from(free[j]) << j));
        let t = if need & !free == 0 && !subnormal {
            t_raw
        } else {
            self.clamped(d, denom)
        };
        let mut z = [0f32; N];
        let mut ok = 0u32;
        for j in 0..N {
            let valid = denom[j] != 0.0 && denom[j].is_finite();
            let zj = (t[j] * planar[j]) as f32;
            let zf = f64::from(zj);
            z[j] = zj;
            ok |= u32::from(valid & (zf >= cam.near) & (zf <= cam.far)) << j;
        }
        (z, ok)
    }

    /// `t` clamped into the slab interval as [`TriDepth::depth`] does it
    /// (`visibility::slab_od` with origin = eye), for lanes the shortcut
    /// does not settle.
    #[inline(always)]
    fn clamped<const N: usize>(&self, d: [[f64; N]; 3], denom: [f64; N]) -> [f64; N] {
        std::array::from_fn(|j| {
            let mut tmin = f64::NEG_INFINITY;
            let mut tmax = f64::INFINITY;
            let mut empty = false;
            for (k, dk) in d.iter().enumerate() {
                let dk = dk[j];
                let inv = 1.0 / dk;
                let zero = dk == 0.0;
                empty |= zero & self.zero_misses[k];
                let t0 = self.lo[k] * inv;
                let t1 = self.hi[k] * inv;
                let (a, bb) = if dk > 0.0 { (t0, t1) } else { (t1, t0) };
                let (nmin, nmax) = (tmin.max(a), tmax.min(bb));
                tmin = if zero { tmin } else { nmin };
                tmax = if zero { tmax } else { nmax };
            }
            let (lo, hi) = if empty {
                (f64::INFINITY, f64::NEG_INFINITY)
            } else {
                (tmin, tmax)
            };
            (self.num / denom[j]).max(lo).min(hi.max(lo))
        })
    }
}

/// One triangle's edge functions over one tile: the f64 normals of its
/// [`TriEdges`] and each edge's bound `B` (module documentation).
#[derive(Debug, Clone, Copy)]
pub struct FastEdges {
    /// Edge normals, as the predicate's filter uses them.
    n: [[f64; 3]; 3],
    /// `B` per edge: a sign is taken only where `|det| > B`.
    bound: [f64; 3],
    /// `B_block` per edge: a block's sign is taken only where every corner's
    /// `|det|` exceeds it, with one sign.
    block: [f64; 3],
    /// Per edge, the screen-space form `(a, b, c) = (n . r, n . v, n . f)`
    /// (f64 dot products with the camera's right, up and forward): `G' =
    /// fl(fl(a sx) + fl(fl(b sy) + c))` decides a lane's sign where `|G'|`
    /// exceeds `B_block` ([`FastEdges::screen_chunk`]).
    screen: [[f64; 3]; 3],
}

/// Sign masks of one chunk: bit `j` of `pos[k]` (`neg[k]`) set when edge `k`
/// is certainly positive (negative) at lane `j`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ChunkSigns {
    /// Certainly positive, per edge.
    pub pos: [u32; 3],
    /// Certainly negative, per edge.
    pub neg: [u32; 3],
}

impl ChunkSigns {
    /// Lanes [`crate::visibility::covers_by`] would reject from certain signs
    /// alone (the first two opposite, or the first two agreeing and the third
    /// opposite): exactly the signs it would ask for are certain.
    #[inline(always)]
    pub fn rejected(&self) -> u32 {
        let [p0, p1, p2] = self.pos;
        let [n0, n1, n2] = self.neg;
        (p0 & n1) | (n0 & p1) | (p0 & p1 & n2) | (n0 & n1 & p2)
    }

    /// Lanes covered back-facing (all three signs certainly positive).
    #[inline(always)]
    pub fn inside_pos(&self) -> u32 {
        self.pos[0] & self.pos[1] & self.pos[2]
    }

    /// Lanes covered front-facing (all three signs certainly negative).
    #[inline(always)]
    pub fn inside_neg(&self) -> u32 {
        self.neg[0] & self.neg[1] & self.neg[2]
    }

    /// Edge `k`'s certain sign at lane `j`, 0 when it must go to the predicate.
    #[inline(always)]
    pub fn sign(&self, k: usize, j: usize) -> i8 {
        ((self.pos[k] >> j) & 1) as i8 - ((self.neg[k] >> j) & 1) as i8
    }
}

impl FastEdges {
    /// Sets up a triangle's edges over a tile.
    #[inline]
    pub fn new(edges: &TriEdges, dirs: &TileRays) -> FastEdges {
        let m = dirs.max_abs;
        let f = |e: &EdgePlane| {
            let s = m[0] * e.perm.x + m[1] * e.perm.y + m[2] * e.perm.z;
            FAST_EDGE_BOUND * s
        };
        let bound = [f(&edges.0[0]), f(&edges.0[1]), f(&edges.0[2])];
        let eta = dirs.eta;
        let block_k = |k: usize| {
            let p = edges.0[k].perm;
            3.0 * bound[k] + 4.0 * (p.x * eta[0] + p.y * eta[1] + p.z * eta[2])
        };
        // Plain arrays, not array `map`: its closures compiled to
        // out-of-line calls here, once per triangle and tile.
        let block = [block_k(0), block_k(1), block_k(2)];
        let n = [
            edges.0[0].n.to_array(),
            edges.0[1].n.to_array(),
            edges.0[2].n.to_array(),
        ];
        let [_, f, r, v] = dirs.basis;
        let mut screen = [[0.0; 3]; 3];
        for (g, n) in screen.iter_mut().zip(&n) {
            let dot = |w: DVec3| n[0] * w.x + n[1] * w.y + n[2] * w.z;
            *g = [dot(r), dot(v), dot(f)];
        }
        FastEdges {
            n,
            bound,
            block,
            screen,
        }
    }

    /// The same edges with the block bound multiplied by `factor` (tests: 0 must break).
    #[cfg(test)]
    fn block_scaled(mut self, factor: f64) -> FastEdges {
        self.block = self.block.map(|b| b * factor);
        self
    }

    /// Certain signs of the three edges over the whole 8x8 block whose
    /// top-left pixel is `(col, row)` of the tile (module documentation):
    /// each mask is all 8 lanes or none, and holds in every row of the
    /// block; the caller needs the block inside the tile.
    #[inline(always)]
    pub fn block(&self, dirs: &TileRays, row: usize, col: usize) -> ChunkSigns {
        self.rect(dirs, [col, col + CHUNK - 1, row, row + CHUNK - 1])
    }

    /// [`FastEdges::block`] over the tile rectangle `[lx0, lx1, ly0, ly1]`
    /// (the argument holds for any rectangle of pixel centers: it is their
    /// convex hull): a triangle's box in a tile, decided at once, from the
    /// screen-space form at its four corners (module documentation).
    #[inline(always)]
    pub fn rect(&self, dirs: &TileRays, [lx0, lx1, ly0, ly1]: [usize; 4]) -> ChunkSigns {
        let (x0, x1) = (dirs.sx[lx0], dirs.sx[lx1]);
        let (y0, y1) = (dirs.sy[ly0], dirs.sy[ly1]);
        let mut out = ChunkSigns::default();
        for k in 0..3 {
            let [a, b, c] = self.screen[k];
            let (r0, r1) = (b * y0 + c, b * y1 + c);
            let det = [a * x0 + r0, a * x1 + r0, a * x0 + r1, a * x1 + r1];
            let bk = self.block[k];
            // NaN fails both.
            let pos = det.iter().all(|&d| d > bk);
            let neg = det.iter().all(|&d| -d > bk);
            out.pos[k] = if pos { 0xff } else { 0 };
            out.neg[k] = if neg { 0xff } else { 0 };
        }
        out
    }

    /// Certain signs of the three edges at the 8 pixels from column `col` of
    /// tile row `row`, from their screen coordinates alone (module
    /// documentation, screen-space chunks): no pixel ray is needed, and
    /// every sign given is one [`FastEdges::chunk`] gives too (lanes past
    /// the tile's width are padding, to be masked off).
    #[inline(always)]
    pub fn screen_chunk<L: ChunkOps>(
        &self,
        l: L,
        rays: &TileRays,
        row: usize,
        col: usize,
    ) -> ChunkSigns {
        let sx: &[f64; CHUNK] = rays.sx[col..col + CHUNK].try_into().unwrap();
        let sy = rays.sy[row];
        let mut out = ChunkSigns::default();
        for k in 0..3 {
            let [a, b, c] = self.screen[k];
            let r = b * sy + c;
            let mut det = [0.0; CHUNK];
            let mut neg = [0.0; CHUNK];
            for j in 0..CHUNK {
                det[j] = a * sx[j] + r;
                neg[j] = -det[j];
            }
            out.pos[k] = l.gt(&det, self.block[k]);
            out.neg[k] = l.gt(&neg, self.block[k]);
        }
        out
    }

    /// Certain signs of the three edges at the 8 pixels from column `col` of
    /// tile row `row` (lane `j` is the pixel at column `col + j`; lanes past
    /// the tile's width are padding, to be masked off).
    #[inline(always)]
    pub fn chunk<L: ChunkOps>(&self, l: L, dirs: &TileRays, row: usize, col: usize) -> ChunkSigns {
        let at = row * dirs.stride + col;
        debug_assert!(dirs.dirs_filled, "tile directions read before ensure_dirs");
        let dx: &[f64; CHUNK] = dirs.d[0][at..at + CHUNK].try_into().unwrap();
        let dy: &[f64; CHUNK] = dirs.d[1][at..at + CHUNK].try_into().unwrap();
        let dz: &[f64; CHUNK] = dirs.d[2][at..at + CHUNK].try_into().unwrap();
        let mut out = ChunkSigns::default();
        for k in 0..3 {
            let [nx, ny, nz] = self.n[k];
            // The filter's expression, operand for operand (EdgePlane::sign_with).
            let det: [f64; CHUNK] = std::array::from_fn(|j| dx[j] * nx + dy[j] * ny + dz[j] * nz);
            let neg: [f64; CHUNK] = det.map(|d| -d);
            out.pos[k] = l.gt(&det, self.bound[k]);
            out.neg[k] = l.gt(&neg, self.bound[k]);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::predicate::exact_sign;
    use crate::predicate::tests::lcg;
    #[cfg(target_arch = "x86_64")]
    use crate::simd::Avx2;
    use glam::DVec3;

    /// An exact 90° 32x32 camera looking down -z from `o + z`, and a tilted
    /// non-dyadic `w` x `h` one, both around `o`.
    fn offset_cameras(o: DVec3, w: u32, h: u32) -> [Result<Camera, String>; 2] {
        [
            Camera::new(o + DVec3::Z, o, DVec3::Y, 90.0, 32, 32, 1e-3, f64::INFINITY),
            Camera::new(
                o + DVec3::new(0.3, 0.7, 2.1),
                o + DVec3::new(0.1, -0.2, 0.0),
                DVec3::Y,
                50.0,
                w,
                h,
                1e-3,
                f64::INFINITY,
            ),
        ]
    }

    /// Both [`ChunkOps`] give the same bits, for equal values, infinities, NaN and signed zeros.
    #[test]
    fn lane_masks_agree() {
        let vals = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            1e-300,
        ];
        let mut s = 5u64;
        for _ in 0..2000 {
            let a: [f64; CHUNK] =
                std::array::from_fn(|_| vals[((lcg(&mut s) + 1.0) * 4.0) as usize % 8]);
            let b = vals[((lcg(&mut s) + 1.0) * 4.0) as usize % 8];
            let want: u32 = (0..CHUNK).map(|j| u32::from(a[j] > b) << j).sum();
            assert_eq!(Portable.gt(&a, b), want);
            #[cfg(target_arch = "x86_64")]
            if let Some(avx) = Avx2::detect() {
                assert_eq!(avx.gt(&a, b), want, "{a:?} > {b}");
            }
        }
    }

    /// Four rays from `eye` for the filter tests, one per lane: through a
    /// point of an edge of `v` (on its plane up to rounding), near its
    /// centroid, or anywhere within `scale`; sometimes a zero or NaN
    /// component, or all zero (det = bound = 0: the filter settles nothing).
    fn probe_rays(
        s: &mut u64,
        case: usize,
        eye: DVec3,
        v: [DVec3; 3],
        scale: f64,
    ) -> [[f64; 4]; 3] {
        let [a, b, c] = v;
        let mut d = [[0f64; 4]; 3];
        for j in 0..4 {
            let t = lcg(s);
            let r = DVec3::new(lcg(s), lcg(s), lcg(s)) * scale;
            let p = match (case + j) % 5 {
                0 => a + (b - a) * t,
                1 => b + (c - b) * t,
                2 => c + (a - c) * t,
                3 => (a + b + c) / 3.0 + r * 0.1,
                _ => r,
            };
            let mut q = (p - eye).to_array();
            match (case / 5 + j) % 7 {
                0 => q[j % 3] = 0.0,
                1 if case % 4 == 1 => q[j % 3] = f64::NAN,
                2 if case.is_multiple_of(11) => q = [0.0; 3],
                _ => {}
            }
            for k in 0..3 {
                d[k][j] = q[k];
            }
        }
        d
    }

    /// Every field of a [`ChunkDepth`] as bits (NaN and signed zeros included).
    fn depth_bits(d: &ChunkDepth) -> Vec<u64> {
        let mut v: Vec<u64> = [d.normal, d.lo, d.hi, d.clamp_free_lo, d.clamp_free_hi]
            .iter()
            .flatten()
            .map(|x| x.to_bits())
            .collect();
        v.push(d.num.to_bits());
        v.extend(d.zero_misses.map(u64::from));
        v
    }

    /// [`ChunkOps::chunk_depth`] in AVX2 is its definition bit for bit: on
    /// vertices with signed-zero and equal coordinates (the min/max ties),
    /// f32's extremes, tiny ones, and eyes from the origin out to 1e308
    /// (bounds minus the eye overflowing to infinity, the clamp-free
    /// thresholds NaN); the eye inside and outside the triangle's slabs.
    #[test]
    fn chunk_depth_forms_agree() {
        let vals = [
            0.0f32,
            -0.0,
            1.0,
            -1.0,
            0.5,
            3.25,
            1e-30,
            -1e-38,
            f32::MAX,
            f32::MIN,
            1e20,
        ];
        let mut s = 41u64;
        let pick = |s: &mut u64| vals[((lcg(s) + 1.0) * 5.5) as usize % vals.len()];
        let (mut misses, mut nan) = (0, 0);
        for case in 0..4000 {
            let eye = match case % 5 {
                0 => DVec3::ZERO,
                1 => DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)),
                2 => DVec3::splat(1e7),
                3 => DVec3::new(f64::MAX, -f64::MAX, 0.25),
                _ => DVec3::new(0.0, -0.0, 1e-300),
            };
            let cam = Camera::new(
                eye,
                eye + DVec3::new(0.3, 0.2, -1.0),
                DVec3::Y,
                60.0,
                8,
                8,
                1e-3,
                f64::INFINITY,
            )
            .unwrap();
            let tri: Tri =
                std::array::from_fn(|_| glam::Vec3::new(pick(&mut s), pick(&mut s), pick(&mut s)));
            let want = Portable.chunk_depth(&cam, &tri);
            misses += want.zero_misses.iter().filter(|&&m| m).count();
            nan += usize::from(want.clamp_free_lo.iter().any(|x| x.is_nan()));
            #[cfg(target_arch = "x86_64")]
            if let Some(avx) = Avx2::detect() {
                let got = avx.chunk_depth(&cam, &tri);
                assert_eq!(depth_bits(&got), depth_bits(&want), "{tri:?} from {eye}");
            }
        }
        assert!(misses > 1000 && nan > 10, "{misses} {nan}");
    }

    /// [`ChunkOps::small_signs`] in AVX2 (one plane per lane) gives the bits
    /// of its definition (one ray per lane, from [`ChunkOps::filter4`]) for
    /// every ray count of a small box: rays through the edges, anywhere,
    /// with zero and NaN components; all three outcomes occur.
    #[test]
    fn small_signs_forms_agree() {
        let mut s = 29u64;
        let mut seen = [0u32; 3];
        for case in 0..3000 {
            let scale = [1.0, 1e-3, 1e5][case % 3];
            let p = |s: &mut u64| DVec3::new(lcg(s), lcg(s), lcg(s)) * scale;
            let eye = p(&mut s);
            let tri: Tri = [p(&mut s), p(&mut s), p(&mut s)].map(|v| v.as_vec3());
            let v = [tri[0].as_dvec3(), tri[1].as_dvec3(), tri[2].as_dvec3()];
            let d = probe_rays(&mut s, case, eye, v, scale);
            for n in 1..=4 {
                let want = Portable.small_signs(eye, &tri, &d, n);
                seen[0] += want.0.count_ones();
                seen[1] += want.1.count_ones();
                seen[2] += want.2.count_ones();
                #[cfg(target_arch = "x86_64")]
                if let Some(avx) = Avx2::detect() {
                    assert_eq!(avx.small_signs(eye, &tri, &d, n), want, "{tri:?} {d:?} {n}");
                }
            }
        }
        assert!(seen.iter().all(|&k| k > 500), "{seen:?}");
    }

    /// [`ChunkOps::filter4`] settles exactly the signs the predicate's filter
    /// settles ([`EdgePlane::sign`] without an exact fallback), with its
    /// sign, on both lane kinds: rays on, near and off the edge planes,
    /// zero and NaN components.
    #[test]
    fn filter4_is_the_predicates_filter() {
        let mut s = 17u64;
        let (mut settled, mut deferred) = (0, 0);
        for case in 0..3000 {
            let scale = [1.0, 1e-3, 1e5][case % 3];
            let p = |s: &mut u64| DVec3::new(lcg(s), lcg(s), lcg(s)) * scale;
            let (eye, a, b, c) = (p(&mut s), p(&mut s), p(&mut s), p(&mut s));
            let planes = [
                EdgePlane::new(eye, a, b),
                EdgePlane::new(eye, b, c),
                EdgePlane::new(eye, c, a),
            ];
            let d = probe_rays(&mut s, case, eye, [a, b, c], scale);
            let (pos, neg) = Portable.filter4(&planes, &d);
            let dirs: [DVec3; 4] = std::array::from_fn(|j| DVec3::new(d[0][j], d[1][j], d[2][j]));
            for (k, e) in planes.iter().enumerate() {
                for (j, &qd) in dirs.iter().enumerate() {
                    let mut fallbacks = 0;
                    let sign = e.sign(eye, eye + qd, qd, &mut fallbacks);
                    let (p, n) = ((pos[k] >> j) & 1 == 1, (neg[k] >> j) & 1 == 1);
                    assert_eq!(
                        (p, n),
                        (fallbacks == 0 && sign > 0, fallbacks == 0 && sign < 0)
                    );
                    if fallbacks == 0 {
                        settled += 1;
                    } else {
                        deferred += 1;
                    }
                }
            }
            #[cfg(target_arch = "x86_64")]
            if let Some(avx) = Avx2::detect() {
                assert_eq!(avx.filter4(&planes, &d), (pos, neg), "{d:?}");
            }
        }
        assert!(settled > 1000 && deferred > 1000, "{settled} {deferred}");
    }

    /// The statistics taken from a span ([`Span::stats`]) are the scan's
    /// ([`row_stats_scalar`]), whatever the length (whole and partial
    /// vectors), with zeros, subnormals, infinities and NaN, of one sign or
    /// mixed; and the span's extremes are the values' own.
    #[test]
    fn span_stats_are_the_scans() {
        let vals = [
            0.0,
            -0.0,
            1.5,
            -3.0,
            f64::MIN_POSITIVE,
            f64::MIN_POSITIVE / 4.0,
            -f64::MIN_POSITIVE / 2.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            7e300,
        ];
        let mut s = 9u64;
        let mut seen = [false; 3];
        for len in 0..40 {
            for _ in 0..200 {
                // Mostly ordinary values, so each flag is sometimes unset.
                let v: Vec<f64> = (0..len)
                    .map(|_| {
                        let r = lcg(&mut s);
                        if r > -0.9 {
                            r * 2.0
                        } else {
                            vals[((lcg(&mut s) + 1.0) * 5.5) as usize % vals.len()]
                        }
                    })
                    .collect();
                // Half the vectors of one sign, so the extremes decide.
                let v: Vec<f64> = if lcg(&mut s) > 0.0 {
                    v.iter().map(|x| x.abs()).collect()
                } else {
                    v
                };
                let want = row_stats_scalar(&v);
                let span = Span::of(&v);
                let (max, subnormal) = span.stats(&v);
                let want_max = if want.non_finite { f64::NAN } else { want.max };
                assert_eq!(max.to_bits(), want_max.to_bits(), "{v:?}");
                assert_eq!(subnormal, want.subnormal, "{v:?}");
                assert_eq!(span.finite, !want.non_finite, "{v:?}");
                if span.finite {
                    let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
                    let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                    assert_eq!((span.lo, span.hi), (lo, hi), "{v:?}");
                }
                let finite_max = v
                    .iter()
                    .map(|x| x.abs())
                    .filter(|a| !a.is_nan())
                    .fold(0.0, f64::max);
                assert_eq!(want.max, finite_max);
                seen[0] |= want.non_finite;
                seen[1] |= want.subnormal;
                seen[2] |= !want.non_finite && !want.subnormal;
            }
        }
        assert_eq!(seen, [true; 3]);
    }

    /// Cameras for the tile tests: tilted and non-dyadic, far from the
    /// origin with an odd image (a column of rays with a zero component),
    /// looking along +x at a wide, short image.
    fn tile_cameras() -> Vec<Camera> {
        let cams = [
            Camera::new(
                DVec3::new(0.3, 0.7, 2.1),
                DVec3::new(0.1, -0.2, 0.0),
                DVec3::Y,
                50.0,
                45,
                37,
                1e-3,
                1.0,
            ),
            Camera::new(
                DVec3::Z * 1e7,
                DVec3::ZERO,
                DVec3::X,
                90.0,
                33,
                33,
                1e-3,
                1.0,
            ),
            Camera::new(
                DVec3::new(-4.0, 0.5, 0.25),
                DVec3::new(3.0, 0.0, 0.0),
                DVec3::Z,
                20.0,
                70,
                9,
                1e-3,
                10.0,
            ),
        ];
        cams.into_iter().map(Result::unwrap).collect()
    }

    /// Every ray of a tile is [`Camera::pixel_ray`]'s, bit for bit, borders included.
    #[test]
    fn tile_rays_are_the_cameras() {
        for cam in tile_cameras() {
            for (x0, y0) in [(0, 0), (32, 32), (32, 0)] {
                if x0 >= cam.width || y0 >= cam.height {
                    continue;
                }
                let (tw, th) = ((cam.width - x0).min(32), (cam.height - y0).min(32));
                let t = TileRays::new(&cam, x0, y0, tw, th);
                for ly in 0..th {
                    for lx in 0..tw {
                        let (a, b) = (
                            t.ray(lx as usize, ly as usize),
                            cam.pixel_ray(x0 + lx, y0 + ly),
                        );
                        let bits = |r: PixelRay| {
                            [r.p, r.dir, r.inv_dir].map(|v| v.to_array().map(f64::to_bits))
                        };
                        assert_eq!(bits(a), bits(b), "pixel ({}, {})", x0 + lx, y0 + ly);
                        assert_eq!(a.planar.to_bits(), b.planar.to_bits());
                    }
                }
            }
        }
    }

    /// A filled tile's statistics, gathered as its rays are written, are the
    /// scans' of its arrays (largest magnitudes, subnormals, the early depth
    /// bound), on either lane kind, whose arrays agree bit for bit; tiles
    /// where a direction component crosses or touches zero (the odd-sized
    /// image's middle column) take the rescan, the others the extremes.
    #[test]
    fn filled_tiles_keep_the_scans_statistics() {
        let (mut rescans, mut extremes_only, mut from_corners, mut tiles) = (0, 0, 0, 0);
        for cam in tile_cameras() {
            #[cfg(target_arch = "x86_64")]
            let mut reused = TileRays::default();
            for (x0, y0) in [(0, 0), (32, 0), (0, 32), (32, 32), (64, 0), (5, 3)] {
                if x0 >= cam.width || y0 >= cam.height {
                    continue;
                }
                let (tw, th) = ((cam.width - x0).min(32), (cam.height - y0).min(32));
                let t = TileRays::new(&cam, x0, y0, tw, th);
                from_corners += usize::from(t.spans_from_corners);
                tiles += 1;
                for k in 0..3 {
                    let want = row_stats_scalar(&t.d[k]);
                    let want_max = if want.non_finite { f64::NAN } else { want.max };
                    assert_eq!(t.max_abs[k].to_bits(), want_max.to_bits());
                    assert_eq!(t.d_span[k], Span::of(&t.d[k]));
                    if t.d_span[k].one_strict_sign() {
                        extremes_only += 1;
                    } else {
                        rescans += 1;
                    }
                }
                let any_subnormal = (0..3).any(|k| row_stats_scalar(&t.d[k]).subnormal);
                assert_eq!(t.subnormal, any_subnormal);
                // The corners' lower bound on `planar` holds at every pixel,
                // and lies at most `2ε` below the least value (`planar_low`'s
                // proof: least >= the least corner). With `Σ|f_j| <= √3`,
                // `H_j <= 3` (these cameras' screen tangents are below 1.4) and
                // `η_j <= η' = 16u(|e| + 4)`, `2ε < 8η'` relative to
                // `planar` (about 1): a looser `ε` fails here.
                let least = Span::of(&t.planar).lo;
                let within = 8.0 * 16.0 * U * (cam.eye.length() + 4.0);
                assert!(t.planar_low <= least, "{} above {least}", t.planar_low);
                assert!(
                    t.planar_low >= least * (1.0 - within),
                    "{} far below {least}",
                    t.planar_low
                );
                let faces = crate::raster::hiz::NearFaces::new(&cam);
                let (k, neg) = (faces.axis(), faces.negative());
                let scanned = crate::raster::hiz::TileDepthBound::new(neg, &t.planar, &t.d[k]);
                let (got, scanned) = (t.depth_bound(&cam).unwrap(), scanned.unwrap());
                assert!(got.kappa() <= scanned.kappa());
                assert!(got.kappa() >= scanned.kappa() * (1.0 - within));
                #[cfg(target_arch = "x86_64")]
                if let Some(avx) = Avx2::detect() {
                    // One buffer for the camera's tiles in turn, as a band
                    // reuses it: rows kept where a tile shares the last
                    // one's, rewritten where it does not.
                    let w = &mut reused;
                    w.fill(avx, &cam, &TileColumn::new(&cam, x0, tw), y0, th);
                    assert_eq!(w.sy, t.sy);
                    assert_eq!(w.sx, t.sx);
                    assert_eq!(w.across, t.across);
                    // Before its directions are written, a tile gives the
                    // same statistics, and the same direction per pixel.
                    assert_eq!(w.max_abs.map(f64::to_bits), t.max_abs.map(f64::to_bits));
                    assert_eq!(w.subnormal, t.subnormal);
                    for (k, ly, lx) in (0..3).flat_map(|k| {
                        (0..th as usize)
                            .flat_map(move |ly| (0..tw as usize).map(move |lx| (k, ly, lx)))
                    }) {
                        let want = t.d[k][ly * t.stride + lx];
                        assert_eq!(w.dir_component(k, lx, ly).to_bits(), want.to_bits());
                    }
                    w.ensure_dirs(avx);
                    let bits = |a: &[f64]| a.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                    for k in 0..3 {
                        assert_eq!(bits(&w.d[k]), bits(&t.d[k]));
                        assert_eq!(w.d_span[k], t.d_span[k]);
                    }
                    assert_eq!(bits(&w.planar), bits(&t.planar));
                    assert_eq!(w.planar_low.to_bits(), t.planar_low.to_bits());
                    assert_eq!(bits(&w.max_abs), bits(&t.max_abs));
                    assert_eq!(w.subnormal, t.subnormal);
                    assert_eq!(w.spans_from_corners, t.spans_from_corners);
                }
            }
        }
        // Both ways to the spans are taken: from the corners, and gathered
        // per row (then with and without the rescan).
        assert!(
            rescans > 0 && extremes_only > 0 && from_corners > 0 && from_corners < tiles,
            "{rescans} {extremes_only} {from_corners} of {tiles}"
        );
    }

    /// Where a tile's direction spans come from its corners
    /// ([`TileRays::corner_spans`]), they are the scans' of its arrays, on
    /// random cameras: eyes from 1e-3 to 1e9 from the origin, any view
    /// direction and roll, narrow to wide fields of view, tiles anywhere
    /// in odd-sized images (edge tiles narrower than a chunk included).
    #[test]
    fn corner_spans_are_the_scans() {
        let mut s = 41u64;
        let (mut from_corners, mut tiles) = (0, 0);
        for i in 0..400 {
            let scale = 10f64.powi(i % 13 - 3);
            let v = |s: &mut u64| DVec3::new(lcg(s), lcg(s), lcg(s));
            let eye = v(&mut s) * scale;
            let at = eye + v(&mut s);
            let up = v(&mut s);
            let vfov = 1.0 + 178.0 * (lcg(&mut s) + 1.0) / 2.0;
            let (w, h) = (1 + (i * 37 % 97) as u32, 1 + (i * 53 % 89) as u32);
            let Ok(cam) = Camera::new(eye, at, up, vfov, w, h, 1e-3, 1.0) else {
                continue;
            };
            let x0 = (((lcg(&mut s) + 1.0) / 2.0 * f64::from(w)) as u32).min(w - 1);
            let y0 = (((lcg(&mut s) + 1.0) / 2.0 * f64::from(h)) as u32).min(h - 1);
            let (tw, th) = ((w - x0).min(32), (h - y0).min(32));
            let t = TileRays::new(&cam, x0, y0, tw, th);
            tiles += 1;
            if t.spans_from_corners {
                from_corners += 1;
                for k in 0..3 {
                    assert_eq!(t.d_span[k], Span::of(&t.d[k]), "camera {i}, axis {k}");
                }
            }
        }
        assert!(
            from_corners > 100 && tiles > 300,
            "{from_corners} of {tiles}"
        );
    }

    #[test]
    fn bound_covers_the_derived_evaluation_error() {
        assert!(FAST_EDGE_BOUND * (1.0 - 8.0 * U) * (1.0 - U).powi(9) > 8.0 * U);
    }

    /// Directions of a tile whose rays point (nearly) into edge planes: a
    /// third of the lanes exactly on the plane through the eye and both
    /// endpoints (up to the rounding of `D`), a third within a few ulps, the
    /// rest generic. Every certain sign is the exact one and agrees with the
    /// predicate's filter, near-plane lanes are left undecided, and clear
    /// lanes are decided.
    #[test]
    fn certain_signs_are_exact_and_near_plane_lanes_are_deferred() {
        let mut s = 3u64;
        let (mut deferred, mut near, mut decided, mut clear) = (0, 0, 0, 0);
        for case in 0..3000 {
            let scale = [1.0, 1e-3, 1e4, 3e7][case % 4];
            let eye = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * scale;
            let v = |s: &mut u64| {
                eye + DVec3::new(lcg(s), lcg(s), lcg(s) - 2.0) * scale.max(1.0) + DVec3::splat(0.1)
            };
            let [a, b, c] = [v(&mut s), v(&mut s), v(&mut s)].map(|p| p.as_vec3().as_dvec3());
            let tri = [a, b, c].map(|p| p.as_vec3());
            let cam = crate::camera::Camera::new(
                eye,
                eye - DVec3::Z,
                DVec3::Y,
                60.0,
                8,
                8,
                1e-3,
                f64::INFINITY,
            )
            .unwrap();
            let edges = TriEdges::new(&cam, &tri);
            let mut points = Vec::new();
            for j in 0..CHUNK {
                let (p, q) = [(a, b), (b, c), (c, a)][j % 3];
                let (sa, sb) = (lcg(&mut s).abs() + 0.1, lcg(&mut s).abs() + 0.1);
                let on = eye + ((p - eye) * sa + (q - eye) * sb) / (sa + sb);
                let pt = match j % 3 {
                    0 => on,
                    1 => {
                        let ulps = (lcg(&mut s) * 4.0).round();
                        DVec3::new(on.x + ulps * on.x.abs() * f64::EPSILON, on.y, on.z)
                    }
                    _ => eye + DVec3::new(lcg(&mut s), lcg(&mut s), -1.0),
                };
                points.push(pt);
            }
            let pts: Vec<[f64; 3]> = points.iter().map(|p| (*p - eye).to_array()).collect();
            let dirs = TileRays::from_dirs(&pts, CHUNK, 1);
            let fast = FastEdges::new(&edges, &dirs);
            let signs = fast.chunk(Portable, &dirs, 0, 0);
            for (j, p) in points.iter().enumerate() {
                for k in 0..3 {
                    let e = &edges.0[k];
                    let got = signs.sign(k, j);
                    let mut fb = 0;
                    let filter = e.sign(eye, *p, *p - eye, &mut fb);
                    if got != 0 {
                        assert_eq!(got, exact_sign(e.a, e.b, *p, eye), "case {case} lane {j}");
                        assert_eq!((got, fb), (filter, 0), "case {case} lane {j}");
                    }
                    if j % 3 != 2 && k == j % 3 {
                        near += 1;
                        deferred += usize::from(got == 0);
                    }
                    if j % 3 == 2 && fb == 0 {
                        clear += 1;
                        decided += usize::from(got != 0);
                    }
                }
            }
        }
        assert!(
            deferred * 10 >= near * 9,
            "only {deferred} of {near} near-plane signs deferred"
        );
        assert!(
            decided * 100 >= clear * 95,
            "decided {decided} of {clear} clear signs"
        );
    }

    #[test]
    fn chunk_masks_read_the_right_lanes() {
        // A 10-wide tile: stride 17, so row 1 starts at 17 and columns 10..17 are padding.
        let dirs: Vec<[f64; 3]> = (0..20)
            .map(|i| [if i % 2 == 0 { 1.0 } else { -1.0 }, 0.0, -1.0])
            .collect();
        let t = TileRays::from_dirs(&dirs, 10, 2);
        let eye = glam::DVec3::ZERO;
        let e = EdgePlane::new(eye, DVec3::new(0.0, -1.0, -1.0), DVec3::new(0.0, 1.0, -1.0));
        let edges = TriEdges([e; 3]);
        let f = FastEdges::new(&edges, &t);
        let c0 = f.chunk(Portable, &t, 1, 0);
        let c1 = f.chunk(Portable, &t, 1, 8);
        // Row 1 holds rays 10..20: lane j has x = +1 when 10 + j is even.
        assert_eq!(c0.pos[0] | c0.neg[0], 0xff);
        assert_eq!(c0.pos[0], 0b0101_0101 ^ if e.n.x > 0.0 { 0 } else { 0xff });
        assert_eq!(c1.pos[0] | c1.neg[0], 0b11, "padding lanes decide nothing");
    }

    /// Edges through block corners (vertices on the corner pixels' rays, so
    /// corner values are within rounding of 0), at offsets up to 1e7 under
    /// exact and tilted cameras: wherever a block's sign is certain, every
    /// pixel's chunk sign is that sign; some blocks are decided; and with a
    /// block bound of 0 some block claims a sign a pixel does not have.
    #[test]
    fn block_signs_hold_at_every_pixel() {
        let mut s = 21u64;
        let (mut decided, mut broken) = (0, 0);
        for (k, off) in [0.0, 1e3, 12345.678, 1e7].into_iter().enumerate() {
            let o = DVec3::new(off, -off, off);
            let cams = offset_cameras(o, 32, 32);
            for cam in cams.map(Result::unwrap) {
                let rays = TileRays::new(&cam, 0, 0, 32, 32);
                let on = |x: u32, y: u32, t: f64| (cam.eye + cam.pixel_ray(x, y).dir * t).as_vec3();
                for case in 0..150 {
                    // Two corners of one block (or of two), a third vertex anywhere.
                    let (bx, by) = ((case % 4) * 8, ((case / 4) % 4) * 8);
                    let corner = |i: u32| (bx + (i % 2) * 7, by + (i / 2) * 7);
                    let (p, q) = (corner(case % 4), corner((case / 4 + 1 + case % 4) % 4));
                    let q = if p == q { (q.0 ^ 7, q.1) } else { q };
                    let t = |s: &mut u64| 1.0 + 0.5 * (lcg(s) + 1.0) + k as f64 * 0.0;
                    let r = (
                        ((lcg(&mut s) + 1.0) * 16.0) as u32 % 32,
                        ((lcg(&mut s) + 1.0) * 16.0) as u32 % 32,
                    );
                    let tri = [
                        on(p.0, p.1, t(&mut s)),
                        on(q.0, q.1, t(&mut s)),
                        on(r.0, r.1, t(&mut s)),
                    ];
                    let edges = TriEdges::new(&cam, &tri);
                    let fast = FastEdges::new(&edges, &rays);
                    for (f, factor) in [(fast, 1.0), (fast.block_scaled(0.0), 0.0)] {
                        for (row, col) in (0..16).map(|b| ((b / 4) * 8, (b % 4) * 8)) {
                            let blk = f.block(&rays, row, col);
                            let mut holds = true;
                            for ly in row..row + 8 {
                                let sg = fast.chunk(Portable, &rays, ly, col);
                                for e in 0..3 {
                                    holds &= sg.pos[e] & blk.pos[e] == blk.pos[e];
                                    holds &= sg.neg[e] & blk.neg[e] == blk.neg[e];
                                }
                            }
                            if factor == 1.0 {
                                assert!(holds, "offset {off} case {case} block ({col}, {row})");
                                decided +=
                                    usize::from(blk.pos.iter().chain(&blk.neg).any(|&m| m != 0));
                            } else {
                                broken += usize::from(!holds);
                            }
                        }
                    }
                }
            }
        }
        assert!(decided > 1000, "only {decided} blocks decided");
        assert!(broken > 0, "a block bound of 0 broke nothing");
    }

    /// Screen-space chunk signs against the rays' own ([`FastEdges::chunk`],
    /// the predicate filter's): on the triangles of
    /// `block_signs_hold_at_every_pixel` (edges through pixel centers, eyes
    /// up to 1e7 from the origin), every sign `screen_chunk` gives at a
    /// pixel is one `chunk` gives there; most lanes get a sign; and with a
    /// bound of 0 some lane gets a sign the filter does not vouch for.
    #[test]
    fn screen_signs_are_chunk_signs() {
        let mut s = 21u64;
        let (mut lanes, mut signed, mut broken) = (0, 0, 0);
        for off in [0.0, 1e3, 12345.678, 1e7] {
            let o = DVec3::new(off, -off, off);
            for cam in offset_cameras(o, 32, 32).map(Result::unwrap) {
                let rays = TileRays::new(&cam, 0, 0, 32, 32);
                let on = |x: u32, y: u32, t: f64| (cam.eye + cam.pixel_ray(x, y).dir * t).as_vec3();
                for case in 0..150u32 {
                    let mut px = || {
                        (
                            ((lcg(&mut s) + 1.0) * 16.0) as u32 % 32,
                            ((lcg(&mut s) + 1.0) * 16.0) as u32 % 32,
                            1.0 + 0.5 * (lcg(&mut s) + 1.0),
                        )
                    };
                    let (p, q, r) = (px(), px(), px());
                    // Two vertices on pixel rays: an edge through pixel centers.
                    let tri = [on(p.0, p.1, p.2), on(q.0, q.1, q.2), on(r.0, r.1, r.2)];
                    let edges = TriEdges::new(&cam, &tri);
                    let fast = FastEdges::new(&edges, &rays);
                    for (f, zero) in [(fast, false), (fast.block_scaled(0.0), true)] {
                        for ly in 0..32 {
                            for col in (0..32).step_by(CHUNK) {
                                let sc = f.screen_chunk(Portable, &rays, ly, col);
                                #[cfg(target_arch = "x86_64")]
                                if let Some(avx) = Avx2::detect() {
                                    assert_eq!(f.screen_chunk(avx, &rays, ly, col), sc);
                                }
                                let sg = fast.chunk(Portable, &rays, ly, col);
                                let mut holds = true;
                                for e in 0..3 {
                                    holds &= sg.pos[e] & sc.pos[e] == sc.pos[e];
                                    holds &= sg.neg[e] & sc.neg[e] == sc.neg[e];
                                }
                                if zero {
                                    broken += usize::from(!holds);
                                } else {
                                    assert!(holds, "offset {off} case {case} row {ly} col {col}");
                                    lanes += 3 * CHUNK;
                                    signed += (0..3)
                                        .map(|e| (sc.pos[e] | sc.neg[e]).count_ones() as usize)
                                        .sum::<usize>();
                                }
                            }
                        }
                    }
                }
            }
        }
        assert!(
            signed * 100 > lanes * 95,
            "{signed} of {lanes} edge lanes signed"
        );
        assert!(broken > 0, "a bound of 0 broke nothing");
    }

    /// Runs [`ChunkDepth::depths`] (clamp-free margin `margin`) over every
    /// lane of a tile for each triangle and compares it with
    /// [`TriDepth::depth`]; returns (lanes that took the shortcut, lanes that
    /// took the slab, lanes that differ).
    fn chunk_depth_trial(cam: &Camera, tris: &[[glam::Vec3; 3]], margin: f64) -> [usize; 3] {
        let (tw, th) = (cam.width.min(32), cam.height.min(32));
        let rays = TileRays::new(cam, 0, 0, tw, th);
        let mut out = [0; 3];
        for t in tris {
            let scalar = TriDepth::new(cam, t);
            let d = ChunkDepth::with_margin(cam, &scalar, margin);
            for row in 0..th as usize {
                for col in (0..tw as usize).step_by(CHUNK) {
                    // One lane at a time, so each lane's path is known.
                    for j in 0..CHUNK.min(tw as usize - col) {
                        let (z, ok) = d.depths(Portable, cam, rays.rays_at(row, col), 1 << j);
                        #[cfg(target_arch = "x86_64")]
                        if let Some(avx) = Avx2::detect() {
                            let wide = d.depths(avx, cam, rays.rays_at(row, col), 1 << j);
                            // (Only lane `j` was asked for: a half without it may be skipped.)
                            assert_eq!(wide.0[j].to_bits(), z[j].to_bits());
                            assert_eq!(wide.1 & (1 << j), ok & (1 << j));
                        }
                        let want = scalar.depth(cam, &cam.pixel_ray((col + j) as u32, row as u32));
                        let got = ((ok >> j) & 1 == 1).then_some(z[j]);
                        let at = row * rays.stride + col + j;
                        let dir = [0, 1, 2].map(|k| rays.d[k][at]);
                        let denom =
                            d.normal[0] * dir[0] + d.normal[1] * dir[1] + d.normal[2] * dir[2];
                        let t_raw = d.num / denom;
                        let free = (0..3).all(|k| {
                            let q = t_raw * dir[k];
                            q >= d.clamp_free_lo[k] && q <= d.clamp_free_hi[k]
                        }) && t_raw.abs() <= CLAMP_FREE_MAX_T;
                        out[usize::from(!free)] += 1;
                        out[2] += usize::from(got.map(f32::to_bits) != want.map(f32::to_bits));
                    }
                }
            }
        }
        out
    }

    /// Triangles for the clamp-free test: random ones, axis-aligned ones
    /// (a box of zero extent on one axis, grown by rounding only) and
    /// grazing ones (nearly edge-on to the eye, where `t` is ill-conditioned
    /// and the clamp bites).
    fn clamp_trial_triangles(cam: &Camera, seed: u64, n: usize) -> Vec<[glam::Vec3; 3]> {
        let mut s = seed;
        let mut tris = Vec::new();
        for i in 0..n {
            let r = |s: &mut u64| lcg(s);
            let p = |s: &mut u64, depth: f64| {
                let x = (r(s) * 0.5 + 0.5) * f64::from(cam.width.min(32));
                let y = (r(s) * 0.5 + 0.5) * f64::from(cam.height.min(32));
                let ray = cam.pixel_ray(x as u32, y as u32);
                cam.eye + ray.dir * depth * (1.0 + 0.01 * r(s))
            };
            let (a, b) = (p(&mut s, 2.0), p(&mut s, 3.0));
            let c = match i % 3 {
                0 => p(&mut s, 2.5),
                1 => {
                    // Same z as a and b: flat in z (after rounding to f32).
                    let mut c = p(&mut s, 2.5);
                    c.z = a.z;
                    let b = DVec3::new(b.x, b.y, a.z);
                    tris.push([a, b, c].map(|v| v.as_vec3()));
                    continue;
                }
                // Nearly edge-on: c continues a along its own ray.
                _ => cam.eye + (a - cam.eye) * (1.5 + r(&mut s)) + DVec3::splat(1e-9 * r(&mut s)),
            };
            tris.push([a, b, c].map(|v| v.as_vec3()));
        }
        tris
    }

    /// Lanes that take the clamp-free shortcut and lanes that take the slab
    /// both give [`TriDepth::depth`] bit for bit, on plain, axis-aligned and
    /// grazing triangles, under exact and tilted cameras, near the origin
    /// and far from it; and thresholds placed outside the box by a relative
    /// `1e-6` (an unsound shortcut) are caught.
    #[test]
    fn chunk_depths_are_the_scalar_ones() {
        let (mut free, mut slab) = (0, 0);
        for (k, off) in [0.0, 1e3, 12345.678].into_iter().enumerate() {
            let o = DVec3::new(off, -off, off);
            let cams = offset_cameras(o, 40, 24);
            for (c, cam) in cams.into_iter().map(Result::unwrap).enumerate() {
                let tris = clamp_trial_triangles(&cam, 11 + (k * 2 + c) as u64, 60);
                let [f, sl, differ] = chunk_depth_trial(&cam, &tris, CLAMP_FREE_MARGIN);
                assert_eq!(differ, 0, "offset {off}, camera {c}: {differ} lanes differ");
                free += f;
                slab += sl;
            }
        }
        assert!(
            free > 10_000 && slab > 1_000,
            "{free} shortcut lanes, {slab} slab lanes"
        );
        let cam = Camera::new(
            DVec3::Z,
            DVec3::ZERO,
            DVec3::Y,
            90.0,
            32,
            32,
            1e-3,
            f64::INFINITY,
        )
        .unwrap();
        let tris = clamp_trial_triangles(&cam, 5, 60);
        let [_, _, differ] = chunk_depth_trial(&cam, &tris, -1e-6);
        assert!(differ > 0, "thresholds outside the box broke nothing");
    }
}
