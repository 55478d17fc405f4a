//! A packet's frustum: four planes through the eye that every lane's exact
//! ray lies inside, so a box wholly outside one of them is skipped for the
//! whole packet with one small test instead of 64 lanes' slab tests.
//!
//! On the million-triangle scene at 1080p (8x4 packets), 37% of the boxes a packet popped
//! were missed by every lane, and the frustum test catches 93% of those (the
//! rest slip between the lanes' rays: boxes smaller than a pixel). Tested
//! on a child before it is pushed, a culled box costs no stack traffic, no
//! slab tests and no prefetch of what lies below it: on this workload the
//! node and triangle lines fetched for boxes no lane enters were a good part
//! of the kernel's memory traffic.
//!
//! Why skipping is safe. A plane is a normal `n` (f32 components, read as
//! exact reals) with `n . D > 0` for every lane's exact direction `D` (the
//! f64 `d64` the exact predicate uses). A lane covers a triangle only where
//! its ray `eye + t D`, `t > 0`, meets it (the slab test already keeps only
//! `t >= 0`), and the meeting point minus the eye lies in the node's
//! eye-relative box ([`super::primary::Node32`] contains every point of every
//! triangle below it). If `n . y < 0` for every `y` in the box, then
//! `n . (t D) > 0` puts the point outside the box, so no lane can be covered
//! by anything below the node, and no key changes.
//!
//! *The lanes are inside.* Each lane's `D` is `P = f + r sx + u sy` (camera
//! basis, the lane's screen coordinates) up to rounding: [`Packet::new`]
//! computes `(e + ((f + r sx) + u sy)) - e`, six roundings of at most
//! `u |operand|` each (`u = 2^-53`), so per axis `|D - P| <= E` with
//! `E = 8 u (|e| + |f| + |r| S + |u| T)` (`S`, `T`: largest `|sx|`, `|sy|`
//! considered; 8 covers the six roundings and their second-order terms).
//! `n . P` is affine in `(sx, sy)`, so over a rectangle of screen
//! coordinates its minimum is at a corner. A packet's left and right planes
//! are built a margin outside its columns (`sx >= sx_lo - M`, before `n` is
//! rounded to f32) and checked over its columns by every row of the image,
//! the top and bottom ones likewise; a plane is kept only if every corner's
//! `n . P`, evaluated in f64, exceeds `2 sum |n_k| E_k`: one `sum |n_k| E_k`
//! for `|n . (D - P)|` and one for the evaluation's own rounding (at most
//! `5 u` times the same terms). A plane that fails the check is disabled
//! (all zero: it never culls), so the proof never depends on the margin
//! being large enough.
//!
//! *The box is outside.* For each plane the box corner farthest along `n`
//! is `y_k = hi_k` where `n_k > 0`, else `lo_k`; the box is outside when
//! `n . y < 0`. In f32, `s = fl(n . y)` is within `3.0001 u32 a` of the exact
//! value, where `a = fl(sum |fl(n_k y_k)|)` (standard dot-product bounds, with
//! `a` at most `2 u32` below the exact sum of magnitudes), plus under
//! `3 * 2^-150` from products that underflow. So `s < -(4 u32 a + 2^-126)`
//! proves `n . y < 0`. Infinite bounds give an infinite `a` or a NaN, and
//! neither culls.
//!
//! [`Packet::new`]: super::packet::Packet::new

use super::packet::{PH, PW};
use super::primary::Node32;
use super::rows::{planes_out, ROW};
use crate::camera::Camera;
use crate::simd::RowLanes;
use glam::DVec3;

/// f64's unit roundoff.
const U64: f64 = 1.0 / (1u64 << 53) as f64;

/// The f32 box test's relative allowance: 4 times f32's unit roundoff.
pub(crate) const BOX_REL: f32 = 4.0 / (1u32 << 24) as f32;

/// The f32 box test's absolute allowance, far above the products' underflow.
pub(crate) const BOX_ABS: f32 = f32::MIN_POSITIVE;

/// A packet's four side planes, components by axis then lane: lanes 0-3
/// hold the four planes for one box and lanes 4-7 the same planes for a
/// second box, so a node's two children take one 8-lane vector per step.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Frustum {
    n: [[f32; ROW]; 3],
}

impl Frustum {
    /// A frustum that culls nothing.
    pub const NONE: Frustum = Frustum { n: [[0.0; ROW]; 3] };

    /// Whether each of two boxes is wholly outside one of the planes, so no
    /// lane's ray enters it (see the module docs for why this is exact).
    ///
    /// Per plane and axis, the far corner's term `fl(n_k y_k)` is taken as
    /// `max(fl(n_k lo_k), fl(n_k hi_k))`: rounding is monotone, so that is
    /// the product with `hi_k` where `n_k > 0` and with `lo_k` where
    /// `n_k < 0` (both 0 where `n_k = 0`), with no per-plane selection. An
    /// infinite bound makes an infinite `mag` or a NaN, and neither culls.
    #[inline(always)]
    pub fn excludes<L: RowLanes<ROW>>(&self, l: L, a: &Node32, b: &Node32) -> [bool; 2] {
        let bounds = |n: &Node32| [n.bounds(0), n.bounds(1), n.bounds(2)];
        let m = planes_out(l, &self.n, &bounds(a), &bounds(b));
        [m & 0xf != 0, m & 0xf0 != 0]
    }
}

/// Every packet's planes for one camera: a packet's left and right planes
/// depend only on its column of packets, its top and bottom ones only on its
/// row, so they are built and checked once per render (building them per
/// packet cost a third of what the culling saved).
pub(crate) struct PacketPlanes {
    /// Per column of packets: the planes `sx >= lo` and `sx <= hi`.
    columns: Vec<[[f32; 3]; 2]>,
    /// Per row of packets: the planes `sy >= lo` and `sy <= hi`.
    rows: Vec<[[f32; 3]; 2]>,
}

impl PacketPlanes {
    /// No planes (an empty scene's tree).
    pub fn empty() -> PacketPlanes {
        PacketPlanes {
            columns: Vec::new(),
            rows: Vec::new(),
        }
    }

    /// The planes of every packet of the camera's image (packets that run
    /// past its right or bottom edge included, inactive lanes and all).
    pub fn new(cam: &Camera) -> PacketPlanes {
        let (cols, rows) = (
            (cam.width as usize).div_ceil(PW),
            (cam.height as usize).div_ceil(PH),
        );
        let span = |a: f64, b: f64| [a.min(b), a.max(b)];
        let col = |c: usize| {
            span(
                cam.screen_x((c * PW) as u32),
                cam.screen_x((c * PW + PW - 1) as u32),
            )
        };
        let row = |r: usize| {
            span(
                cam.screen_y((r * PH) as u32),
                cam.screen_y((r * PH + PH - 1) as u32),
            )
        };
        // Every lane's screen coordinates lie in `all_x` x `all_y`.
        let all_x = span(
            col(0)[0].min(col(cols - 1)[0]),
            col(0)[1].max(col(cols - 1)[1]),
        );
        let all_y = span(
            row(0)[0].min(row(rows - 1)[0]),
            row(0)[1].max(row(rows - 1)[1]),
        );
        let err = direction_error(cam, all_x, all_y);
        let (f, r, u) = (cam.forward, cam.right, cam.up_ortho);
        // The margin outside each packet: well above the f32 rounding of the
        // normals (2^-24 of each component, times |P| <= 1 + S + T).
        let scale = 1.0 + all_x[0].abs().max(all_x[1].abs()) + all_y[0].abs().max(all_y[1].abs());
        let margin = scale * scale / (1u64 << 20) as f64 + 4.0 * scale * err.element_sum();
        // Per packet column (`side = r`) or row (`side = u`): the planes
        // `s >= lo - M` and `s <= hi + M`, checked over the packet's own
        // range of `s` by every value of the other coordinate.
        let pair = |side: DVec3, s: [f64; 2], sx: [f64; 2], sy: [f64; 2]| {
            let (lo, hi) = (s[0] - margin, s[1] + margin);
            [
                checked_plane(cam, side - f * lo, sx, sy),
                checked_plane(cam, f * hi - side, sx, sy),
            ]
        };
        let columns = (0..cols).map(|c| pair(r, col(c), col(c), all_y)).collect();
        let rows = (0..rows).map(|k| pair(u, row(k), all_x, row(k))).collect();
        PacketPlanes { columns, rows }
    }

    /// The frustum of the packet whose top-left pixel is `(x0, y0)`.
    #[inline(always)]
    pub fn packet(&self, x0: usize, y0: usize) -> Frustum {
        let (Some(c), Some(r)) = (self.columns.get(x0 / PW), self.rows.get(y0 / PH)) else {
            return Frustum::NONE;
        };
        let mut n = [[0f32; ROW]; 3];
        for (j, p) in [c[0], c[1], r[0], r[1]].iter().enumerate() {
            for k in 0..3 {
                (n[k][j], n[k][j + 4]) = (p[k], p[k]);
            }
        }
        Frustum { n }
    }
}

/// `E`: per axis, a bound on how far a direction computed from screen
/// coordinates in `sx` x `sy` lies from `f + r sx + u sy` (module docs).
fn direction_error(cam: &Camera, sx: [f64; 2], sy: [f64; 2]) -> DVec3 {
    let big_s = sx[0].abs().max(sx[1].abs());
    let big_t = sy[0].abs().max(sy[1].abs());
    let (e, f, r, u) = (cam.eye, cam.forward, cam.right, cam.up_ortho);
    (e.abs() + f.abs() + r.abs() * big_s + u.abs() * big_t) * (8.0 * U64)
}

/// `n` in f32 when `n . D > 0` is proven for every direction computed from
/// screen coordinates in `sx` x `sy` (the check in the module docs), else
/// zero (a plane that culls nothing).
fn checked_plane(cam: &Camera, n: DVec3, sx: [f64; 2], sy: [f64; 2]) -> [f32; 3] {
    let err = direction_error(cam, sx, sy);
    let n32 = n.as_vec3();
    let n64 = n32.as_dvec3();
    let need = 2.0 * n64.abs().dot(err);
    let (nf, nr, nu) = (
        n64.dot(cam.forward),
        n64.dot(cam.right),
        n64.dot(cam.up_ortho),
    );
    let inside = sx
        .iter()
        .flat_map(|&x| sy.iter().map(move |&y| nf + nr * x + nu * y))
        .all(|v| v > need);
    if inside && n32.is_finite() {
        n32.to_array()
    } else {
        [0.0; 3]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simd::Portable;
    use crate::visibility::RayBox;
    use glam::DVec3;

    /// The packet tests' cameras, and `million`'s.
    fn cameras() -> Vec<Camera> {
        let mut cams = super::super::packet::awkward_cameras();
        cams.extend(
            [Camera::new(
                DVec3::new(0.0, 1.2, 3.2),
                DVec3::new(0.0, 0.1, 0.0),
                DVec3::Y,
                45.0,
                1920,
                1080,
                1e-3,
                f64::INFINITY,
            )]
            .map(Result::unwrap),
        );
        cams
    }

    /// Whether the frustum excludes `b`, tested as either box of a pair
    /// (beside a box it does not exclude, in both orders).
    fn excl(fr: &Frustum, b: &Node32) -> bool {
        let wide = RayBox {
            lo: DVec3::splat(-1e3),
            hi: DVec3::splat(1e3),
        };
        let wide = Node32::new(DVec3::ZERO, &wide, 0, 1);
        let [x, y] = fr.excludes(Portable, b, &wide);
        let [z, w] = fr.excludes(Portable, &wide, b);
        assert!(!y && !z);
        assert_eq!(x, w);
        x
    }

    /// A small eye-relative node box around the exact point `eye + t D`
    /// (grown by a bound on the rounding of the computed point).
    fn point_box(cam: &Camera, d: DVec3, t: f64) -> Node32 {
        let p = cam.eye + d * t;
        let tol = (cam.eye.abs() + (d * t).abs()) * (4.0 * U64);
        let b = RayBox {
            lo: p - tol,
            hi: p + tol,
        };
        Node32::new(cam.eye, &b, 0, 1)
    }

    /// A box around any point of any lane's exact ray (the corner lanes' rays
    /// included, which lie nearest the planes) is never excluded, near the
    /// eye or far from it; every plane survives its check on these cameras,
    /// and the frustum does cull: a point one packet beside, above or below
    /// is excluded.
    #[test]
    fn lanes_are_inside_and_neighbours_outside() {
        for cam in cameras() {
            let planes = PacketPlanes::new(&cam);
            let (w, h) = (cam.width as usize, cam.height as usize);
            let last = (w.div_ceil(PW) * PW - PW, h.div_ceil(PH) * PH - PH);
            for (x0, y0) in [(0, 0), last, (w / 2 / PW * PW, h / 2 / PH * PH)] {
                let fr = planes.packet(x0, y0);
                for j in 0..4 {
                    assert!((0..3).any(|k| fr.n[k][j] != 0.0), "plane {j} disabled");
                }
                for y in y0..y0 + PH {
                    for x in x0..x0 + PW {
                        let (sx, sy) = (cam.screen_x(x as u32), cam.screen_y(y as u32));
                        let d = cam.screen_ray(sx, sy).dir;
                        for t in [1e-9, 1e-3, 0.5, 1.0, 7.0, 1e4] {
                            let b = point_box(&cam, d, t);
                            assert!(!excl(&fr, &b), "lane ({x}, {y}) at t = {t}");
                        }
                    }
                }
                let px = |x: i64| cam.screen_x(0) + x as f64 * (cam.screen_x(1) - cam.screen_x(0));
                let py = |y: i64| cam.screen_y(0) + y as f64 * (cam.screen_y(1) - cam.screen_y(0));
                let (x0, y0) = (x0 as i64, y0 as i64);
                let (pw, ph) = (PW as i64, PH as i64);
                for (x, y) in [
                    (x0 - pw, y0),
                    (x0 + 2 * pw, y0),
                    (x0, y0 - ph),
                    (x0, y0 + 2 * ph),
                ] {
                    let d = cam.screen_ray(px(x), py(y)).dir;
                    assert!(
                        excl(&fr, &point_box(&cam, d, 1.0)),
                        "({x}, {y}) beside ({x0}, {y0})"
                    );
                }
            }
        }
    }

    /// A plane the lanes are not proven inside is disabled, a packet past
    /// the image has no planes, and infinite bounds never cull.
    #[test]
    fn unproven_planes_and_huge_boxes_never_cull() {
        let cam = &cameras()[0];
        let (sx, sy) = ([-0.1, 0.1], [-0.1, 0.1]);
        // sx >= -0.1 - 1e-5 holds on the rectangle, sx >= -0.1 + 1e-5 not
        // (the f32 rounding of the normal moves a plane by about 1e-8).
        let left = |lo: f64| cam.right - cam.forward * lo;
        assert_ne!(checked_plane(cam, left(-0.1 - 1e-5), sx, sy), [0.0; 3]);
        assert_eq!(checked_plane(cam, left(-0.1 + 1e-5), sx, sy), [0.0; 3]);
        assert_eq!(checked_plane(cam, -cam.forward, sx, sy), [0.0; 3]);
        let planes = PacketPlanes::new(cam);
        let fr = planes.packet(0, 0);
        let beside = point_box(cam, cam.screen_ray(10.0, 0.0).dir, 1.0);
        assert!(excl(&fr, &beside));
        assert!(!excl(&planes.packet(1 << 20, 0), &beside));
        assert!(!excl(&Frustum::NONE, &beside));
        let huge = RayBox {
            lo: DVec3::splat(-1e300),
            hi: DVec3::splat(1e300),
        };
        assert!(!excl(&fr, &Node32::new(cam.eye, &huge, 0, 1)));
    }
}
