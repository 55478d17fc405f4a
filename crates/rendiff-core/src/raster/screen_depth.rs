//! Depth for whole 8x8 blocks without their pixel rays: the depth
//! function's f32 result read off a screen-space interpolant, and taken only
//! where a rounding certificate proves it is [`TriDepth::depth`](crate::visibility::TriDepth::depth)'s, bit for bit.
//!
//! # Why
//!
//! [`TriDepth::depth`](crate::visibility::TriDepth::depth) per pixel costs a ray (`D = (e + d) - e`), two dot
//! products, a division, the product `t · planar` and a proof that the slab
//! clamp is the identity ([`ChunkDepth`]). The f32 it returns is all that
//! is kept, and an f32 has 29 fewer bits than the f64 arithmetic behind it.
//! So one division per pixel of an affine interpolant, off by at most a
//! bounded relative error `e` (about `1e-15`), gives the same f32 unless the
//! true value lies within `e` of an f32 rounding boundary: a test on the
//! interpolant's own bits finds those pixels, and only those pay the exact
//! path. Raster and trace stay one depth function: this is a proof about
//! that function's output, never a second definition (docs/DESIGN.md).
//!
//! # The interpolant and its error ([`ScreenDepth::block`])
//!
//! `u = 2^-53`. Let `n`, `num` be the triangle's f64 plane ([`TriDepth`](crate::visibility::TriDepth),
//! as [`ChunkDepth::plane`] keeps it),
//! `f, r, v` the camera's f64 basis, and `(sx, sy)` a pixel's computed
//! screen coordinates ([`TileRays::sx`], the camera's own), taken as exact
//! reals. The ideal direction `g = f + r sx + v sy` makes `G = n · g =
//! A sx + B sy + C` affine, with `A = n · r`, `B = n · v`, `C = n · f`
//! (exact reals). Per pixel the interpolant is `den = fl(fl(a sx) + R)`,
//! `R = fl(fl(b sy) + c)` (once per row), `a, b, c` the f64 dot products,
//! and `w = fl(num / den)`.
//!
//! - `|den - G| <= Δf = 6u S`, `S = Σ|n_j||r_j| |sx| + Σ|n_j||v_j| |sy| +
//!   Σ|n_j||f_j|`: each of `a, b, c` is off by `γ3` of its absolute dot
//!   product, the evaluation by `γ2` of `|a sx| + |b sy| + |c|`, in all
//!   `5.001u S`, and `S` as computed (five roundings of non-negative terms)
//!   is within `6u` of the real one.
//! - The pixel's ray `D` lies within `ε_j` = [`TileRays::eta`] of `g` per
//!   component: `η_j = 16u(|e_j| + H_j)` bounds `|δ_j - g_j|` for exact
//!   screen coordinates ([`crate::raster::edges`], whole blocks), and with
//!   the computed ones the sum `f + r sx + v sy` (`3.01u H_j`), `P = e + s`
//!   and `D = fl(P - e)` (`u(|e_j| + 1.01 H_j)` each) come to `5.03u H_j +
//!   1.01u|e_j| < η_j`. The eye's distance from the origin enters here.
//! - The depth function's `denom = fl(n · D)` lies within `Δden = 3.01u(S +
//!   Nε) + Nε`, `Nε = Σ|n_j| ε_j`, of `G` (`Σ|n_j||g_j| <= S`).
//! - Its `planar = fl(D · f)` lies within `Δpl` of 1: `|g · f - 1| <= |f·f
//!   - 1| + |sx||r·f| + |sy||v·f|` (exact dot products, bounded through the
//!   computed ones plus `3.01u` of their absolute sums), plus `Σ|f_j| ε_j`
//!   for `D - g` and `3.01u Σ|f_j|(|g_j| + ε_j)` for the rounding.
//!
//! Over a block, `G` is affine and its pixel centers' `(sx, sy)` lie in the
//! rectangle of its corners' (the coordinates are monotone in the column
//! and row), so when all four corner `den` share a sign and exceed `Δf` in
//! magnitude, `|G| >= g_min = min|den| - Δf > 0` at every pixel. The depth
//! function's unrounded depth is `z = fl(fl(num / denom) · planar) = num
//! planar / denom (1 + θ)`, `|θ| <= γ2`, and `w = num / den (1 + θ')`,
//! `|θ'| <= u`, so with `ρ = (Δf + Δden) / (g_min - Δden)`:
//!
//! `|z / w - 1| <= (1 + Δpl)(1 + ρ)(1 + γ2)/(1 - u) - 1 <= e =
//! 1.01(Δpl + ρ) + 4u`
//!
//! while `Δpl, ρ <= 2^-32` (the cross terms, below `2^-61.9`, fit in the
//! `0.99u` left of `4u - 3.01u`). A block past that, with a sign change, or
//! with depths outside `[2^-100, 2^100]` (f32-normal with room to spare) is
//! left to [`ChunkDepth`].
//!
//! # The certificate ([`rounds_alone`])
//!
//! For `w` in binade `[2^k, 2^(k+1))` (f64 ulp `2^(k-52)`), `e|w| < e 2^53`
//! ulps. The f32 rounding boundaries in the binade (midpoints between
//! neighbouring f32 values) are exactly the f64 values whose low 29 bits are
//! `2^28`. So when the low bits of `w` differ from `2^28` by more than `E >=
//! e 2^53`, no boundary of the binade lies within `e|w|` of `w`; the
//! nearest boundaries of the neighbouring binades are `2^-25`-relative away
//! from the binade's ends, beyond reach while `e <= 2^-30`. Round-to-nearest
//! is constant between boundaries, so `z as f32 == w as f32`: the depth
//! function's bits, and with them its `near <= z <= far` decision and its
//! hit (`denom` is finite and non-zero, as `|denom| >= g_min - Δden > 0`).
//! A lane that fails the test takes [`ChunkDepth`] with its row.
//!
//! # The slab clamp
//!
//! The depth function clamps `t = fl(num / denom)` into the triangle's slab
//! interval; [`ChunkDepth`]'s documentation proves it returns `t` when, on
//! every axis, the real product `t D_k >= L_k + 2.0001u|L_k|` and `t D_k <=
//! H_k - 2.0001u|H_k|` (`L_k, H_k` the slab's planes, [`ChunkDepth::slab_planes`]),
//! under its guards: no subnormal direction in the tile, `|t| <= 1e300`
//! (here `|t| <= 2|num| / g_min (1 + u) < 2^102`, as `g_min > 2Δden` is
//! required), and `8u M_k >= 1e-280`. Without the ray, `t D_k` is bounded
//! per block: write `h_k = num g_k / G`, the exact hit of the ideal ray on
//! the f64 plane. Then `num D_k / denom - h_k = num (D_k G - g_k denom) /
//! (denom G)`, with `D_k G - g_k (n · D) = Σ_{j≠k} n_j ((D_k - g_k) g_j -
//! g_k (D_j - g_j))` and `|denom - n · D| <= 3.01u(S + Nε)`. The axis's own
//! term cancels: that is what keeps an axis-aligned plane inside the proof
//! (its box has no extent on `k`, and every hit lies on the box's boundary
//! but for the growth of [`crate::visibility::grow_box`], `32u M_k`). So,
//! with `X_k = Σ_{j≠k}|n_j|(ε_k H_j^b + H_k^b ε_j)`,
//!
//! `|t D_k - h_k| <= |num|(X_k + H_k^b 3.01u(S + Nε)) / ((g_min - Δden)
//! g_min) (1 + u) + u|h_k|` (the last two for `t`'s own rounding),
//!
//! with `H_j^b = |f_j| + |r_j| max|sx| + |v_j| max|sy| >= |g_j|` over the
//! block. `h_k` is linear-fractional in `(sx, sy)` with `G` of one sign, so
//! over the block it lies between its corner values; those are computed as
//! `fl(fl(num g̃_k) fl(1 / den))`, `g̃_k` the rounded sum, off by at most
//! `|num| (3.01u H_k^b + H_k^b Δf / g_min) / g_min + 3.01u|h|`. The block passes an
//! axis when the corner range widened by both errors (and 1% plus `4u
//! max|h|` for the comparison's own rounding) lies within `[fl(L_k + 3.2u
//! M_k), fl(H_k - 3.2u M_k)]`, which is at least `L_k + 2.19u M_k` (resp.
//! mirrored) however it rounds.
//!
//! Tests: `certified_depths_are_the_depth_functions` compares every
//! certified lane with [`TriDepth::depth`](crate::visibility::TriDepth::depth) and checks that the clamp was the
//! identity there, on adversarial cameras and planes;
//! `observed_error_stays_within_the_bound` checks `|z - w| <= e|w|` lane by
//! lane; `rounds_alone_at_the_bound` checks the certificate at its edge
//! against every f64 around a rounding boundary.

use crate::camera::Camera;
use crate::raster::edges::{
    BlockRows, ChunkDepth, ChunkOps, TileRays, CHUNK, CLAMP_FREE_MIN_MARGIN,
};
use crate::visibility::{hit_key, NO_HIT};

/// Unit roundoff of f64.
const U: f64 = f64::EPSILON / 2.0;

/// Largest `Δpl` and `ρ` a block may carry (module documentation): far
/// below the f32 spacing (`2^-24`), so almost every lane certifies, and
/// small enough that the bound's second-order terms fit in its slack.
const MAX_TERM: f64 = 1.0 / (1u64 << 32) as f64;

/// Depths the certificate handles: f32-normal, far from overflow, so that
/// the rounding to f32 is the one the bit test reads.
const MIN_DEPTH: f64 = 1.0 / (1u128 << 100) as f64;
/// See [`MIN_DEPTH`].
const MAX_DEPTH: f64 = (1u128 << 100) as f64;

/// The f64 bits an f32 rounding drops (52 - 23).
pub(crate) const DROPPED_MASK: u64 = (1 << 29) - 1;
/// The dropped bits of an f32 rounding boundary (a midpoint).
pub(crate) const MIDPOINT: i64 = 1 << 28;

/// True when every real within `eu` f64 ulps of `w` (a positive normal f64
/// of the f32-normal range) rounds to the f32 `w` rounds to: the low 29
/// bits of `w` lie more than `eu` from a midpoint's (module documentation).
#[inline(always)]
pub fn rounds_alone(w: f64, eu: i64) -> bool {
    ((w.to_bits() & DROPPED_MASK) as i64 - MIDPOINT).abs() > eu
}

/// The most rows [`ScreenDepth::box_keys`] takes (a tile's).
pub const MAX_BOX_ROWS: usize = crate::raster::TILE as usize;

/// One row of a block, as [`ChunkOps::screen_row`] evaluates it.
#[derive(Debug, Clone, Copy)]
pub struct ScreenRow {
    /// The plane's `num`.
    pub num: f64,
    /// The interpolant's `a`.
    pub a: f64,
    /// The row's `R = fl(fl(b sy) + c)`.
    pub r: f64,
    /// The camera's near depth.
    pub near: f64,
    /// The camera's far depth.
    pub far: f64,
    /// The block's bound in ulps ([`BlockBound::eu`]).
    pub eu: i64,
}

impl ScreenRow {
    /// The definition the wide code must equal: per lane `w = fl(num /
    /// fl(fl(a sx) + R))`, its f32, whether that is within `[near, far]`,
    /// and whether [`rounds_alone`] certifies it.
    #[inline(always)]
    pub fn lanes(&self, sx: &[f64; CHUNK]) -> ([f32; CHUNK], u32, u32) {
        let mut z = [0f32; CHUNK];
        let (mut ok, mut sure) = (0u32, 0u32);
        for j in 0..CHUNK {
            let w = self.num / (self.a * sx[j] + self.r);
            let zj = w as f32;
            let zf = f64::from(zj);
            z[j] = zj;
            ok |= u32::from((zf >= self.near) & (zf <= self.far)) << j;
            sure |= u32::from(rounds_alone(w, self.eu)) << j;
        }
        (z, ok, sure)
    }
}

/// One triangle's screen-space depth over one tile: the interpolant's
/// coefficients and what its error bounds need (module documentation).
/// Built once per triangle and tile whose box has a covered block.
#[derive(Debug, Clone, Copy)]
pub struct ScreenDepth {
    /// `normal . (a - eye)`.
    num: f64,
    /// `a, b, c`: `den = fl(fl(a sx) + fl(fl(b sy) + c))`.
    coef: [f64; 3],
    /// `Σ|n_j||r_j|`, `Σ|n_j||v_j|`, `Σ|n_j||f_j|`.
    abs_coef: [f64; 3],
    /// `|n_j|`.
    n_abs: [f64; 3],
    /// `ε_j`: the tile's ray error bound per component.
    eps: [f64; 3],
    /// `Nε = Σ|n_j| ε_j`.
    n_eps: f64,
    /// The camera basis per axis: `|f_k|, |r_k|, |v_k|` and `f_k, r_k, v_k`.
    basis: [[f64; 3]; 3],
    /// `Δpl = pl[0] + max|sx| pl[1] + max|sy| pl[2]`.
    pl: [f64; 3],
    /// Per axis, `fl(L_k + 3.2u M_k)`: `t D_k` above it is not clamped from below.
    lo_req: [f64; 3],
    /// Per axis, `fl(H_k - 3.2u M_k)`.
    hi_req: [f64; 3],
    /// The camera's depth range.
    near: f64,
    /// See `near`.
    far: f64,
}

/// What a block's certificate needs per lane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BlockBound {
    /// The relative error bound `e` of the block's interpolant.
    pub e: f64,
    /// `e` in f64 ulps of the lane's value ([`rounds_alone`]).
    pub eu: i64,
    /// Every lane's f32 depth lies within `[near, far]`: each lane with a
    /// certified depth is a hit, without testing it.
    pub all_hit: bool,
}

impl ScreenDepth {
    /// Sets up a triangle over a tile; `None` when the clamp proof's guards
    /// fail for it (a subnormal direction in the tile, a slab too close to
    /// underflow).
    pub fn new(cam: &Camera, cd: &ChunkDepth, rays: &TileRays) -> Option<Self> {
        if rays.subnormal() {
            return None;
        }
        Self::for_plane(cam, cd, rays.eta())
    }

    /// [`ScreenDepth::new`] without the tile's subnormal check: all that
    /// depends on the camera, the triangle and `eps` (the tiles' `η`,
    /// the camera's alone), so one triangle's serves every tile.
    pub fn for_plane(cam: &Camera, cd: &ChunkDepth, eps: [f64; 3]) -> Option<Self> {
        let (n, num) = cd.plane();
        let (f, r, v) = (
            cam.forward.to_array(),
            cam.right.to_array(),
            cam.up_ortho.to_array(),
        );
        let dot = |x: [f64; 3], y: [f64; 3]| x[0] * y[0] + x[1] * y[1] + x[2] * y[2];
        let abs_dot = |x: [f64; 3], y: [f64; 3]| {
            x[0].abs() * y[0].abs() + x[1].abs() * y[1].abs() + x[2].abs() * y[2].abs()
        };
        let n_abs = n.map(f64::abs);
        let n_eps = abs_dot(n, eps);
        let f_eps = abs_dot(f, eps);
        let (ff, rf, vf) = (dot(f, f), dot(r, f), dot(v, f));
        let pl = [
            (ff - 1.0).abs() + 4.0 * U + 4.0 * U * (abs_dot(f, f) + f_eps) + 1.01 * f_eps,
            rf.abs() + 8.0 * U * abs_dot(r, f),
            vf.abs() + 8.0 * U * abs_dot(v, f),
        ];
        let (lo, hi) = cd.slab_planes();
        let (mut lo_req, mut hi_req) = ([0.0; 3], [0.0; 3]);
        for k in 0..3 {
            let m = lo[k].abs().max(hi[k].abs());
            // (Written so that NaN fails, here and below.)
            let relative = 8.0 * U * m >= CLAMP_FREE_MIN_MARGIN;
            if !relative {
                return None;
            }
            lo_req[k] = lo[k] + 3.2 * U * m;
            hi_req[k] = hi[k] - 3.2 * U * m;
        }
        Some(ScreenDepth {
            num,
            coef: [dot(n, r), dot(n, v), dot(n, f)],
            abs_coef: [abs_dot(n, r), abs_dot(n, v), abs_dot(n, f)],
            n_abs,
            eps,
            n_eps,
            basis: [0, 1, 2].map(|k| [f[k], r[k], v[k]]),
            pl,
            lo_req,
            hi_req,
            near: cam.near,
            far: cam.far,
        })
    }

    /// The error bound of the 8x8 block whose top-left tile pixel is
    /// `(base, r0)`, when the module's conditions hold there: one sign of
    /// `G`, terms below [`MAX_TERM`], depths in range, the slab clamp the
    /// identity at every pixel. `None` sends the block to [`ChunkDepth`].
    #[inline(always)]
    pub fn block(&self, rays: &TileRays, r0: usize, base: usize) -> Option<BlockBound> {
        self.rect(rays, [base, base + CHUNK - 1, r0, r0 + CHUNK - 1])
    }

    /// [`ScreenDepth::block`] for every block inside the tile rectangle
    /// `[lx0, lx1, ly0, ly1]` at once (the module's argument holds for any
    /// rectangle of pixel centers): one bound for all of them, a little
    /// looser than each block's own.
    #[inline(always)]
    pub fn rect(&self, rays: &TileRays, [lx0, lx1, ly0, ly1]: [usize; 4]) -> Option<BlockBound> {
        let (sx, sy) = (rays.sx(), rays.sy());
        self.between((sx[lx0], sx[lx1]), (sy[ly0], sy[ly1]))
    }

    /// The bound over the rows of `rays`' tile (its band's) across every
    /// column of the image: it holds in each of the band's tiles. (The first
    /// and last columns' `sx` are the image's extremes:
    /// [`Camera::screen_x`] is monotone in the column.)
    #[inline(always)]
    pub fn band(&self, cam: &Camera, rays: &TileRays) -> Option<BlockBound> {
        let sy = rays.sy();
        let columns = (cam.screen_x(0), cam.screen_x(cam.width - 1));
        self.between(columns, (sy[0], sy[sy.len() - 1]))
    }

    /// [`ScreenDepth::rect`] for the rectangle of pixel centers whose first
    /// and last columns have screen coordinates `sx0`, `sx1` and whose first
    /// and last rows `sy0`, `sy1` ([`crate::camera::Camera::screen_x`] and
    /// `screen_y`), in or beyond one tile: a bound over a band's rows across
    /// the whole image holds in each of its tiles.
    #[inline(always)]
    pub fn between(&self, (sx0, sx1): (f64, f64), (sy0, sy1): (f64, f64)) -> Option<BlockBound> {
        let [a, b, c] = self.coef;
        let (row0, row1) = (b * sy0 + c, b * sy1 + c);
        let corners = [
            (sx0, sy0, row0),
            (sx1, sy0, row0),
            (sx0, sy1, row1),
            (sx1, sy1, row1),
        ];
        // Plain loops, not array `map`: its closures compiled to out-of-line
        // calls, once per block.
        let mut den = [0.0; 4];
        for (d, &(x, _, row)) in den.iter_mut().zip(&corners) {
            *d = a * x + row;
        }
        let (sxm, sym) = (sx0.abs().max(sx1.abs()), sy0.abs().max(sy1.abs()));
        let s = self.abs_coef[0] * sxm + self.abs_coef[1] * sym + self.abs_coef[2];
        let delta_f = 6.0 * U * s;
        let positive = den.iter().all(|&d| d > 0.0);
        if !positive && !den.iter().all(|&d| d < 0.0) {
            return None;
        }
        let (dmin, dmax) = den.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &d| {
            (lo.min(d.abs()), hi.max(d.abs()))
        });
        let g_min = dmin - delta_f;
        let delta_den = 4.0 * U * (s + self.n_eps) + 1.01 * self.n_eps;
        let conditioned = g_min > 2.0 * delta_den;
        if !conditioned {
            return None;
        }
        let rho = (delta_f + delta_den) / (g_min - delta_den);
        let delta_pl = self.pl[0] + sxm * self.pl[1] + sym * self.pl[2];
        let small = rho <= MAX_TERM && delta_pl <= MAX_TERM;
        if !small {
            return None;
        }
        // Depths positive and in range at every lane: `|den| <= dmax + 2Δf`
        // and `>= g_min - Δf` per pixel, `Δf <= 2^-32 g_min`, so 1% covers
        // both and the f32 rounding (as it does for `near` and `far` below).
        let num = self.num;
        let (z_lo, z_hi) = (
            num.abs() / (dmax + delta_f) * 0.99,
            num.abs() / g_min * 1.01,
        );
        let in_range = (num > 0.0) == positive && z_lo >= MIN_DEPTH && z_hi <= MAX_DEPTH;
        if !in_range {
            return None;
        }
        // The slab clamp, axis by axis.
        let mut inv = [0.0; 4];
        for (q, &d) in inv.iter_mut().zip(&den) {
            *q = 1.0 / d;
        }
        let mut hb = [0.0; 3];
        for (h, &[f, r, v]) in hb.iter_mut().zip(&self.basis) {
            *h = f.abs() + r.abs() * sxm + v.abs() * sym;
        }
        for k in 0..3 {
            let [fk, rk, vk] = self.basis[k];
            let (mut h_lo, mut h_hi, mut h_abs) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
            for (&(x, y, _), &q) in corners.iter().zip(&inv) {
                let h = num * ((fk + rk * x) + vk * y) * q;
                (h_lo, h_hi, h_abs) = (h_lo.min(h), h_hi.max(h), h_abs.max(h.abs()));
            }
            let mut x_k = 0.0;
            for j in 0..3 {
                if j != k {
                    x_k += self.n_abs[j] * (self.eps[k] * hb[j] + hb[k] * self.eps[j]);
                }
            }
            let ray = num.abs() * (x_k + hb[k] * 4.0 * U * (s + self.n_eps))
                / ((g_min - delta_den) * g_min)
                * 1.02
                + 3.0 * U * h_abs;
            let corner = num.abs() * (4.0 * U * hb[k] + hb[k] * delta_f / g_min) / g_min * 1.02
                + 4.0 * U * h_abs;
            let tot = (ray + corner) * 1.01 + 4.0 * U * h_abs;
            let inside = h_lo - tot >= self.lo_req[k] && h_hi + tot <= self.hi_req[k];
            if !inside {
                return None;
            }
        }
        let e = 1.01 * (delta_pl + rho) + 4.0 * U;
        Some(BlockBound {
            e,
            eu: (e * (1u64 << 53) as f64).ceil() as i64 + 1,
            all_hit: z_lo >= self.near && z_hi <= self.far,
        })
    }

    /// The 8 lanes of tile row `row` from column `base` in a block
    /// [`ScreenDepth::block`] passed with `eu`: `w as f32` per lane, the
    /// lanes with a hit (`near <= z <= far`), and the lanes [`rounds_alone`]
    /// certifies (only those are the depth function's).
    #[inline(always)]
    pub fn row<L: ChunkOps>(
        &self,
        l: L,
        rays: &TileRays,
        row: usize,
        base: usize,
        eu: i64,
    ) -> ([f32; CHUNK], u32, u32) {
        let p = self.row_params(rays, row, eu);
        if p.a == 0.0 && p.r != 0.0 && p.r.is_finite() {
            // Every lane's `den` is `R` (`ScreenDepth::row_constant_keys`):
            // `ScreenRow::lanes`' arithmetic once serves all 8.
            let w = p.num / p.r;
            let z = w as f32;
            let zf = f64::from(z);
            let all = |b: bool| if b { 0xff } else { 0 };
            let ok = (zf >= p.near) & (zf <= p.far);
            return ([z; CHUNK], all(ok), all(rounds_alone(w, p.eu)));
        }
        let sx: &[f64; CHUNK] = rays.sx()[base..base + CHUNK].try_into().unwrap();
        l.screen_row(&p, sx)
    }

    /// The keys of the 8x8 block at tile pixel `(base, r0)` (its rows
    /// `rows`), in a block whose bound has
    /// `all_hit`: each row whose lanes [`rounds_alone`] all certifies gets
    /// its keys lowered to the certified depths and its bit in the returned
    /// mask; the other rows are left for the caller. [`ScreenDepth::row`]
    /// and the z-test in one pass.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    pub fn block_keys<L: ChunkOps>(
        &self,
        l: L,
        rays: &TileRays,
        (r0, base): (usize, usize),
        eu: i64,
        rows: &mut BlockRows,
        prim: u32,
    ) -> u32 {
        let [a, b, c] = self.coef;
        if a == 0.0 {
            return self.row_constant_keys(l, rays, r0, eu, rows, prim);
        }
        let sx: &[f64; CHUNK] = rays.sx()[base..base + CHUNK].try_into().unwrap();
        let p = self.row_params(rays, r0, eu);
        let mut r = [0.0; CHUNK];
        for (i, r) in r.iter_mut().enumerate() {
            *r = b * rays.sy()[r0 + i] + c;
        }
        l.screen_keys(&p, &r, sx, rows, prim)
    }

    /// [`ScreenDepth::block_keys`] where `a` is a zero (the plane's
    /// interpolant is constant along rows: `n . r = 0`, a wall parallel to
    /// the camera's right axis, or a plane facing the camera): every lane's
    /// `den = fl(fl(a sx) + R)` is `R` itself, since `fl(a sx)` is a zero
    /// (`sx` is finite) and a zero plus a nonzero `R` is `R` exactly. So a
    /// row's lanes share one `w = fl(num / R)`, one certificate and one key,
    /// the lane path's bits for one division a row; where `b` is a zero as
    /// well (a plane facing the camera), `R = fl(fl(b sy) + c)` is `c` in
    /// every row, and the block takes one division. Rows whose `R` is zero
    /// or not finite are left to the caller.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn row_constant_keys<L: ChunkOps>(
        &self,
        l: L,
        rays: &TileRays,
        r0: usize,
        eu: i64,
        rows: &mut BlockRows,
        prim: u32,
    ) -> u32 {
        let [_, b, c] = self.coef;
        let mut key = [NO_HIT; CHUNK];
        let mut done = 0;
        if b == 0.0 {
            if let Some(k) = self.row_key(c, eu, prim) {
                (key, done) = ([k; CHUNK], 0xff);
            }
        } else {
            for (i, key) in key.iter_mut().enumerate() {
                if let Some(k) = self.row_key(b * rays.sy()[r0 + i] + c, eu, prim) {
                    (*key, done) = (k, done | 1 << i);
                }
            }
        }
        if done != 0 {
            l.min_key_rows(rows, &key);
        }
        done
    }

    /// The key of each row of the tile rectangle `[lx0, lx1, ly0, ly1]`
    /// (from row `ly0`), under a bound over the whole rectangle with
    /// `all_hit`, when `a` is a zero and every row's key is certified
    /// ([`ScreenDepth::row_constant_keys`]' argument: every pixel of a row
    /// has its key; the rectangle one key where `b` is a zero too); `None`
    /// otherwise.
    #[inline(always)]
    pub fn box_keys(
        &self,
        rays: &TileRays,
        [_, _, ly0, ly1]: [usize; 4],
        eu: i64,
        prim: u32,
    ) -> Option<[u64; MAX_BOX_ROWS]> {
        let [a, b, c] = self.coef;
        if a != 0.0 || ly1 - ly0 >= MAX_BOX_ROWS {
            return None;
        }
        let mut key = [NO_HIT; MAX_BOX_ROWS];
        if b == 0.0 {
            key = [self.row_key(c, eu, prim)?; MAX_BOX_ROWS];
        } else {
            for (i, k) in key[..=ly1 - ly0].iter_mut().enumerate() {
                *k = self.row_key(b * rays.sy()[ly0 + i] + c, eu, prim)?;
            }
        }
        Some(key)
    }

    /// The key every lane of a row with `den = r` takes, when its `w` is
    /// certified (`None`: `r` zero or not finite, or `w` not certified).
    #[inline(always)]
    fn row_key(&self, r: f64, eu: i64, prim: u32) -> Option<u64> {
        if r == 0.0 || !r.is_finite() {
            return None;
        }
        let w = self.num / r;
        rounds_alone(w, eu).then(|| hit_key(w as f32, prim))
    }

    /// The constants of one row of the interpolant.
    #[inline(always)]
    fn row_params(&self, rays: &TileRays, row: usize, eu: i64) -> ScreenRow {
        let [a, b, c] = self.coef;
        ScreenRow {
            num: self.num,
            a,
            r: b * rays.sy()[row] + c,
            near: self.near,
            far: self.far,
            eu,
        }
    }

    /// The interpolant `w` itself at tile pixel `(col, row)` (tests: its
    /// distance from the depth function's unrounded depth).
    #[cfg(test)]
    fn value(&self, rays: &TileRays, row: usize, col: usize) -> f64 {
        let [a, b, c] = self.coef;
        self.num / (a * rays.sx()[col] + (b * rays.sy()[row] + c))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::predicate::tests::lcg;
    use crate::raster::TILE;
    use crate::simd::Portable;
    use crate::visibility::{slab, TriDepth};
    use glam::{DVec3, Vec3};

    /// Cameras the bounds must survive: facing an axis (every depth of a
    /// facing plane equal) and oblique, near the origin and far from it
    /// (the eye's offset enters the ray error).
    fn cameras() -> Vec<Camera> {
        // Up is +y; near and far are the defaults unless given.
        let cam = |eye, at, vfov, (w, h), (near, far)| {
            Camera::new(eye, at, DVec3::Y, vfov, w, h, near, far).unwrap()
        };
        let open = (1e-3, f64::INFINITY);
        let mut out = Vec::new();
        for off in [0.0, 1e3, 12345.678, 3.1e6] {
            let o = DVec3::new(off, -off, off);
            out.push(cam(o + DVec3::Z, o, 90.0, (64, 64), open));
            let (eye, at) = (DVec3::new(0.3, 0.7, 2.1), DVec3::new(0.1, -0.2, 0.0));
            out.push(cam(o + eye, o + at, 50.0, (72, 40), open));
        }
        // Pitched down, its right axis exactly the world's x: the
        // horizontal and z-facing planes have interpolants constant along
        // rows (`a = n . r = 0`, `b` not).
        for off in [0.0, 1e3] {
            let o = DVec3::new(off, -off, off);
            out.push(cam(o + DVec3::new(0.0, 2.0, 3.0), o, 60.0, (64, 48), open));
        }
        // Near and far planes through the trial planes: blocks whose depths
        // straddle them (not `all_hit`) test each lane's hit.
        let (eye, at) = (DVec3::new(0.3, 0.7, 2.1), DVec3::new(0.1, -0.2, 0.0));
        out.push(cam(eye, at, 50.0, (72, 40), (2.4, 5.5)));
        out
    }

    /// Triangles for one camera: planes filling the view (facing it,
    /// axis-aligned walls seen at an angle, random tilts up to grazing) and
    /// triangles whose corners fall inside it (blocks near the box's edges,
    /// where the slab clamp's margin is thinnest).
    fn triangles(cam: &Camera, seed: u64) -> Vec<[Vec3; 3]> {
        let mut s = seed;
        let (f, r, v, e) = (cam.forward, cam.right, cam.up_ortho, cam.eye);
        let mut tris = Vec::new();
        let mut plane = |c: DVec3, a: DVec3, b: DVec3, big: f64| {
            let quad = [
                c - a * big - b * big,
                c + a * big - b * big,
                c + a * big + b * big,
            ];
            tris.push(quad.map(|p| p.as_vec3()));
            let other = [
                c - a * big - b * big,
                c + a * big + b * big,
                c - a * big + b * big,
            ];
            tris.push(other.map(|p| p.as_vec3()));
        };
        for depth in [1.0, 2.5, 7.0] {
            // Facing, and world-axis-aligned through the same point.
            plane(e + f * depth, r, v, 10.0);
            plane(e + f * depth, DVec3::X, DVec3::Y, 10.0);
            plane(e + f * depth, DVec3::Y, DVec3::Z, 10.0);
            plane(e + f * depth, DVec3::Z, DVec3::X, 10.0);
        }
        for _ in 0..12 {
            // Random tilts; the smallest scales make grazing planes.
            let tilt = lcg(&mut s).abs().powi(3) * 0.999;
            let a = (r + f * tilt * 30.0 * lcg(&mut s)).normalize();
            let b = (v + f * tilt * 30.0 * lcg(&mut s)).normalize();
            plane(e + f * (2.0 + 3.0 * lcg(&mut s).abs()), a, b, 50.0);
        }
        for _ in 0..20 {
            // Corners in view.
            let p = |s: &mut u64| {
                let d = cam.screen_direction(lcg(s) * 1.2, lcg(s) * 1.2);
                e + d * (2.0 + lcg(s))
            };
            let t = [p(&mut s), p(&mut s), p(&mut s)];
            tris.push(t.map(|p| p.as_vec3()));
        }
        tris
    }

    /// One row of a block [`ScreenDepth::block`] passed: the camera, the
    /// triangle's depth data and interpolant, the tile, the block's bound,
    /// the tile's origin and the row's tile coordinates `(row, base)`.
    struct Row<'a> {
        cam: &'a Camera,
        td: &'a TriDepth,
        s: &'a ScreenDepth,
        rays: &'a TileRays,
        bound: BlockBound,
        origin: (u32, u32),
        at: (usize, usize),
    }

    /// Every row of every block [`ScreenDepth::block`] passes, over every
    /// tile of every trial.
    fn each_row(mut visit: impl FnMut(&Row)) {
        for (c, cam) in cameras().iter().enumerate() {
            for t in triangles(cam, 7 + c as u64) {
                let td = TriDepth::new(cam, &t);
                let cd = ChunkDepth::new(cam, &td);
                for y0 in (0..cam.height).step_by(TILE as usize) {
                    for x0 in (0..cam.width).step_by(TILE as usize) {
                        let (tw, th) = (TILE.min(cam.width - x0), TILE.min(cam.height - y0));
                        let rays = TileRays::new(cam, x0, y0, tw, th);
                        let Some(s) = ScreenDepth::new(cam, &cd, &rays) else {
                            continue;
                        };
                        for r0 in (0..th as usize + 1 - CHUNK).step_by(CHUNK) {
                            for base in (0..tw as usize + 1 - CHUNK).step_by(CHUNK) {
                                let Some(bound) = s.block(&rays, r0, base) else {
                                    continue;
                                };
                                for i in 0..CHUNK {
                                    visit(&Row {
                                        cam,
                                        td: &td,
                                        s: &s,
                                        rays: &rays,
                                        bound,
                                        origin: (x0, y0),
                                        at: (r0 + i, base),
                                    });
                                }
                            }
                        }
                    }
                }
            }
        }
    }

    /// Every certified lane of every row [`each_row`] visits (both
    /// [`ChunkOps`] giving the same row): `check(row, pixel, tile column, z,
    /// hit)`. Returns (certified lanes, lanes of passed blocks).
    fn each_certified_lane(
        mut check: impl FnMut(&Row, (u32, u32), usize, f32, bool),
    ) -> (usize, usize) {
        let (mut sure_lanes, mut lanes) = (0, 0);
        each_row(|r| {
            let (row, base) = r.at;
            let (z, ok, sure) = r.s.row(Portable, r.rays, row, base, r.bound.eu);
            // The definition, lane by lane (`row` takes one lane's where
            // `a` is a zero).
            let sx: &[f64; CHUNK] = r.rays.sx()[base..base + CHUNK].try_into().unwrap();
            let def = r.s.row_params(r.rays, row, r.bound.eu).lanes(sx);
            assert_eq!(def.0.map(f32::to_bits), z.map(f32::to_bits));
            assert_eq!((def.1, def.2), (ok, sure));
            #[cfg(target_arch = "x86_64")]
            if let Some(avx) = crate::simd::Avx2::detect() {
                let wide = r.s.row(avx, r.rays, row, base, r.bound.eu);
                assert_eq!(wide.0.map(f32::to_bits), z.map(f32::to_bits));
                assert_eq!((wide.1, wide.2), (ok, sure));
            }
            lanes += CHUNK;
            for j in (0..CHUNK).filter(|j| (sure >> j) & 1 == 1) {
                sure_lanes += 1;
                let px = (r.origin.0 + (base + j) as u32, r.origin.1 + row as u32);
                check(r, px, base + j, z[j], (ok >> j) & 1 == 1);
            }
        });
        (sure_lanes, lanes)
    }

    /// The depth function's own `t = num / denom` at a pixel, its slab
    /// interval, and its unrounded depth `t · planar`.
    fn contract(cam: &Camera, td: &TriDepth, x: u32, y: u32) -> (f64, (f64, f64), f64) {
        let ray = cam.pixel_ray(x, y);
        let t = td.num / td.normal.dot(ray.dir);
        (t, slab(cam.eye, &ray, &td.bounds), t * ray.planar)
    }

    /// Every lane the certificate settles is [`TriDepth::depth`]'s, bit for
    /// bit, and the slab clamp the module's proof skips is the identity
    /// there; most lanes of the trials are settled (the test is not vacuous).
    #[test]
    fn certified_depths_are_the_depth_functions() {
        let (mut straddling, mut missed) = (0, 0);
        let (sure, lanes) = each_certified_lane(|r, (x, y), _, z, ok| {
            straddling += usize::from(!r.bound.all_hit);
            missed += usize::from(!ok);
            let want = r.td.depth(r.cam, &r.cam.pixel_ray(x, y));
            let got = ok.then_some(z);
            assert_eq!(
                got.map(f32::to_bits),
                want.map(f32::to_bits),
                "pixel ({x}, {y})"
            );
            let (t, (lo, hi), _) = contract(r.cam, r.td, x, y);
            assert!(
                lo <= t && t <= hi,
                "pixel ({x}, {y}): t {t} outside [{lo}, {hi}]"
            );
            assert!(
                !r.bound.all_hit || ok,
                "pixel ({x}, {y}): all_hit, yet no hit"
            );
        });
        assert!(
            lanes > 100_000 && sure * 100 > lanes * 95,
            "{sure} of {lanes} lanes certified"
        );
        assert!(
            straddling > 1000 && missed > 100,
            "{straddling} straddling lanes, {missed} missed"
        );
    }

    /// The bound holds lane by lane: the depth function's unrounded depth
    /// lies within `e|w|` of the interpolant `w`, and not absurdly far
    /// inside it (a bound 10^4 times too loose would still certify most
    /// lanes, so the test says how tight it is).
    #[test]
    fn observed_error_stays_within_the_bound() {
        let mut worst = 0.0f64;
        each_certified_lane(|r, (x, y), col, _, _| {
            let (_, _, z) = contract(r.cam, r.td, x, y);
            let w = r.s.value(r.rays, r.at.0, col);
            let used = (z - w).abs() / (r.bound.e * w.abs());
            assert!(
                used <= 1.0,
                "pixel ({x}, {y}): |z - w| = {} > e|w|",
                (z - w).abs()
            );
            worst = worst.max(used);
        });
        assert!(worst > 1e-4, "the largest error used {worst} of the bound");
    }

    /// [`ScreenDepth::block_keys`] is [`ScreenDepth::row`] followed by the
    /// z-test, row by row, for both [`ChunkOps`], over keys below, above and
    /// equal to the block's: it writes exactly the rows whose lanes are all
    /// certified.
    #[test]
    fn block_keys_is_row_then_min_keys() {
        let (mut seed, mut written) = (3u64, 0);
        // Blocks of planes whose interpolant is constant along rows (`a`
        // a zero), and of those, constant over the block (`b` too).
        let (mut row_constant, mut flat, mut boxed_blocks) = (0, 0, 0);
        each_row(|r| {
            let (row, base) = r.at;
            // Once per block, from its first row.
            if !r.bound.all_hit || row % CHUNK != 0 {
                return;
            }
            if r.s.coef[0] == 0.0 {
                row_constant += 1;
                flat += usize::from(r.s.coef[1] == 0.0);
            }
            let stride = 11;
            let mut keys = vec![0u64; CHUNK * stride];
            let mut want = keys.clone();
            let mut rows = 0u32;
            for i in 0..CHUNK {
                let (z, _, sure) = r.s.row(Portable, r.rays, row + i, base, r.bound.eu);
                let at = i * stride;
                for (j, k) in keys[at..at + CHUNK].iter_mut().enumerate() {
                    let own = crate::visibility::hit_key(z[j], 5);
                    *k = match (lcg(&mut seed) * 2.0) as i64 {
                        -1 => own - 1,
                        0 => own,
                        _ => crate::visibility::NO_HIT,
                    };
                }
                want[at..at + CHUNK].copy_from_slice(&keys[at..at + CHUNK]);
                if sure == 0xff {
                    let w: &mut [u64; CHUNK] = (&mut want[at..at + CHUNK]).try_into().unwrap();
                    Portable.min_keys(w, &z, 0xff, 5);
                    rows |= 1 << i;
                    written += 1;
                }
            }
            // Over the keys as they were, and over a block still all
            // `NO_HIT` (a tile's first triangle), whose z-test leaves the
            // new keys.
            let empty = vec![crate::visibility::NO_HIT; keys.len()];
            let mut fresh_want = empty.clone();
            for i in (0..CHUNK).filter(|i| (rows >> i) & 1 == 1) {
                let (z, _, _) = r.s.row(Portable, r.rays, row + i, base, r.bound.eu);
                let w: &mut [u64; CHUNK] = (&mut fresh_want[i * stride..i * stride + CHUNK])
                    .try_into()
                    .unwrap();
                Portable.min_keys(w, &z, 0xff, 5);
            }
            // The block's rows in a key buffer of `stride` per row.
            fn rows_of(v: &mut [u64], stride: usize) -> BlockRows<'_> {
                let mut it = v.chunks_mut(stride);
                std::array::from_fn(|_| (&mut it.next().unwrap()[..CHUNK]).try_into().unwrap())
            }
            for (start, want) in [(&keys, &want), (&empty, &fresh_want)] {
                // The block as a box: each row one key, the row-then-z-test
                // keys, or (None) not taken.
                let rect = [base, base + CHUNK - 1, row, row + CHUNK - 1];
                let boxed = r.s.box_keys(r.rays, rect, r.bound.eu, 5);
                let can = r.s.coef[0] == 0.0 && rows == 0xff;
                assert_eq!(boxed.is_some(), can);
                if let Some(k) = boxed {
                    let mut by_box = start.clone();
                    for (i, &k) in k[..CHUNK].iter().enumerate() {
                        for key in &mut by_box[i * stride..i * stride + CHUNK] {
                            *key = (*key).min(k);
                        }
                    }
                    assert_eq!(&by_box, want);
                    boxed_blocks += 1;
                }
                // `block_keys` on a copy of `start`, with lanes `l`.
                fn keys_by<L: ChunkOps>(l: L, r: &Row, start: &[u64]) -> (u32, Vec<u64>) {
                    let (mut got, (row, base)) = (start.to_vec(), r.at);
                    let rows = &mut rows_of(&mut got, start.len() / CHUNK);
                    let done = r.s.block_keys(l, r.rays, (row, base), r.bound.eu, rows, 5);
                    (done, got)
                }
                assert_eq!(keys_by(Portable, r, start), (rows, want.clone()));
                #[cfg(target_arch = "x86_64")]
                if let Some(avx) = crate::simd::Avx2::detect() {
                    assert_eq!(keys_by(avx, r, start), (rows, want.clone()));
                }
            }
        });
        assert!(written > 1000, "{written} rows written");
        assert!(boxed_blocks > 400, "{boxed_blocks} blocks taken as boxes");
        assert!(
            row_constant - flat > 100 && flat > 100,
            "{row_constant} blocks with a = 0, {flat} of them with b = 0"
        );
    }

    /// A band's bound ([`ScreenDepth::band`]) holds in every tile of the
    /// band: each lane it certifies is [`TriDepth::depth`]'s, bit for bit,
    /// and it is never tighter than a block's own bound (`e`), nor says
    /// `all_hit` where a block's does not. Many of the trials' bands have one
    /// and many do not (the test is not vacuous).
    #[test]
    fn band_bounds_hold_in_every_tile_of_the_band() {
        let (mut bands, mut with_bound, mut certified) = (0, 0, 0usize);
        for (c, cam) in cameras().iter().enumerate() {
            for t in triangles(cam, 7 + c as u64) {
                let td = TriDepth::new(cam, &t);
                let cd = ChunkDepth::new(cam, &td);
                for y0 in (0..cam.height).step_by(TILE as usize) {
                    let th = TILE.min(cam.height - y0);
                    bands += 1;
                    let first = TileRays::new(cam, 0, y0, TILE.min(cam.width), th);
                    let Some(b) =
                        ScreenDepth::new(cam, &cd, &first).and_then(|s| s.band(cam, &first))
                    else {
                        continue;
                    };
                    with_bound += 1;
                    for x0 in (0..cam.width).step_by(TILE as usize) {
                        let tw = TILE.min(cam.width - x0);
                        let rays = TileRays::new(cam, x0, y0, tw, th);
                        let Some(s) = ScreenDepth::new(cam, &cd, &rays) else {
                            continue;
                        };
                        assert_eq!(s.band(cam, &rays), Some(b), "tile ({x0}, {y0})");
                        for r0 in (0..th as usize + 1 - CHUNK).step_by(CHUNK) {
                            for base in (0..tw as usize + 1 - CHUNK).step_by(CHUNK) {
                                if let Some(own) = s.block(&rays, r0, base) {
                                    assert!(b.e >= own.e, "band e {} < block e {}", b.e, own.e);
                                    assert!(!b.all_hit || own.all_hit);
                                }
                                for row in r0..r0 + CHUNK {
                                    let (z, ok, sure) = s.row(Portable, &rays, row, base, b.eu);
                                    for j in (0..CHUNK).filter(|j| (sure >> j) & 1 == 1) {
                                        let (x, y) = (x0 + (base + j) as u32, y0 + row as u32);
                                        let want = td.depth(cam, &cam.pixel_ray(x, y));
                                        let got = ((ok >> j) & 1 == 1).then_some(z[j]);
                                        assert_eq!(
                                            got.map(f32::to_bits),
                                            want.map(f32::to_bits),
                                            "pixel ({x}, {y})"
                                        );
                                        assert!(!b.all_hit || got.is_some());
                                        certified += 1;
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        // (The trials' planes span the image; their small triangles do not,
        // and their bands take each tile's own bound.)
        assert!(
            with_bound > 100 && bands - with_bound > 100 && certified > 100_000,
            "{with_bound} of {bands} bands with a bound, {certified} lanes certified"
        );
    }

    /// The certificate at its edge: around f32 rounding boundaries (in a
    /// binade and at its ends), `w` is certified for `eu` exactly when
    /// every f64 within `eu` ulps rounds as it does, once `eu` ulps reach
    /// the boundary.
    #[test]
    fn rounds_alone_at_the_bound() {
        let up = |x: f64, k: i64| f64::from_bits((x.to_bits() as i64 + k) as u64);
        for base in [1.0f32, 1.5, 3.999_999_8, 1e-20, 7.5e19] {
            let next = f32::from_bits(base.to_bits() + 1);
            // The f64 midpoint between `base` and the next f32.
            let mid = (f64::from(base) + f64::from(next)) / 2.0;
            assert_eq!(mid.to_bits() & DROPPED_MASK, MIDPOINT as u64);
            for eu in [0i64, 3, 40] {
                for k in -60i64..=60 {
                    let w = up(mid, k);
                    let alone = (-eu..=eu).all(|i| up(w, i) as f32 == w as f32);
                    assert_eq!(
                        rounds_alone(w, eu),
                        k.abs() > eu,
                        "base {base}, eu {eu}, k {k}"
                    );
                    if rounds_alone(w, eu) {
                        assert!(
                            alone,
                            "base {base}, eu {eu}, k {k}: certified but not alone"
                        );
                    }
                }
            }
        }
        // A power of two: the boundary below it lies in the lower binade.
        let two = 2.0f64;
        for k in -50i64..=50 {
            let w = up(two, k);
            assert!(rounds_alone(w, 40), "next to 2, offset {k}");
            assert!((-40..=40).all(|i| up(w, i) as f32 == 2.0f32));
        }
    }
}
