//! Numbers the report computes itself from the buffers, beyond results.json:
//! the distribution of depth errors (a maximum hides whether one pixel or all of
//! them are off) and where ID mismatches fall, per object.

use crate::frame::BACKGROUND_ID;

/// Smallest decade of the depth-error histogram (errors below it go to `under`).
pub const LO_EXP: i32 = -12;
/// Largest decade (errors at or above 10^HI_EXP go to `over`).
pub const HI_EXP: i32 = 4;
/// Bins per decade.
pub const PER_DECADE: i32 = 2;
/// Number of log bins between 10^LO_EXP and 10^HI_EXP.
pub const BINS: usize = ((HI_EXP - LO_EXP) * PER_DECADE) as usize;

/// |Z_test − Z_ref| over pixels both sides hit, in fixed log bins, so that
/// histograms of different scenes and backends can be added and drawn on one axis.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Histogram {
    /// Errors exactly 0 (bit-identical depth).
    pub zero: u64,
    /// Nonzero errors below 10^LO_EXP.
    pub under: u64,
    /// Bin k holds errors in [10^(LO_EXP + k/PER_DECADE), 10^(LO_EXP + (k+1)/PER_DECADE)).
    pub bins: [u64; BINS],
    /// Errors at or above 10^HI_EXP.
    pub over: u64,
    /// Pixels one side hits and the other does not (not an error value, but counted).
    pub mask_mismatches: u64,
    /// Pixels both hit on different triangles: their |Z_test − Z_ref| compares two
    /// surfaces, not a depth error, so it is not binned (the verdict judges
    /// them against the test's own triangle's plane).
    pub other_prim: u64,
}

impl Default for Histogram {
    fn default() -> Self {
        Histogram {
            zero: 0,
            under: 0,
            bins: [0; BINS],
            over: 0,
            mask_mismatches: 0,
            other_prim: 0,
        }
    }
}

impl Histogram {
    /// Histogram of |test − reference| over common hits on the same triangle
    /// (`prims`: the reference's and the test's id.prim, when both wrote one;
    /// hits on different triangles are counted in `other_prim`).
    pub fn of_depth_same_prims(
        reference: &[f32],
        test: &[f32],
        prims: Option<(&[u32], &[u32])>,
    ) -> Histogram {
        let Some((rp, tp)) =
            prims.filter(|(a, b)| a.len() == reference.len() && b.len() == test.len())
        else {
            return Histogram::of_depth(reference, test);
        };
        let mut h = Histogram::default();
        for (((&r, &t), &a), &b) in reference.iter().zip(test).zip(rp).zip(tp) {
            match (r.is_finite(), t.is_finite()) {
                (true, true) if a != b => h.other_prim += 1,
                (true, true) => h.add((f64::from(t) - f64::from(r)).abs()),
                (false, false) => {}
                _ => h.mask_mismatches += 1,
            }
        }
        h
    }

    /// Histogram of |test − reference| over common hits.
    pub fn of_depth(reference: &[f32], test: &[f32]) -> Histogram {
        let mut h = Histogram::default();
        for (&r, &t) in reference.iter().zip(test) {
            match (r.is_finite(), t.is_finite()) {
                (true, true) => h.add((f64::from(t) - f64::from(r)).abs()),
                (false, false) => {}
                _ => h.mask_mismatches += 1,
            }
        }
        h
    }

    /// Adds one error value.
    pub fn add(&mut self, err: f64) {
        if err == 0.0 {
            self.zero += 1;
            return;
        }
        let k = ((err.log10() - f64::from(LO_EXP)) * f64::from(PER_DECADE)).floor();
        if k < 0.0 {
            self.under += 1;
        } else if k >= BINS as f64 {
            self.over += 1;
        } else {
            self.bins[k as usize] += 1;
        }
    }

    /// Adds another histogram (same fixed bins).
    pub fn merge(&mut self, other: &Histogram) {
        self.zero += other.zero;
        self.under += other.under;
        self.over += other.over;
        self.mask_mismatches += other.mask_mismatches;
        self.other_prim += other.other_prim;
        for (a, b) in self.bins.iter_mut().zip(other.bins.iter()) {
            *a += b;
        }
    }

    /// Number of common hits counted.
    pub fn total(&self) -> u64 {
        self.zero + self.under + self.over + self.bins.iter().sum::<u64>()
    }

    /// Lower edge of bin `k`.
    pub fn bin_lo(k: usize) -> f64 {
        10f64.powf(f64::from(LO_EXP) + k as f64 / f64::from(PER_DECADE))
    }

    /// Range of bins (inclusive) holding nonzero counts, None when every error is 0.
    pub fn used_bins(&self) -> Option<(usize, usize)> {
        let first = self.bins.iter().position(|&c| c > 0)?;
        let last = self.bins.iter().rposition(|&c| c > 0)?;
        Some((first, last))
    }
}

/// ID mismatches of one backend, attributed to objects: where a reviewer should look.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ObjectMismatches {
    /// Pixels whose id.prim differs, by the reference's object there (or the
    /// test's where the reference sees background).
    pub by_object: Vec<u64>,
    /// Mismatches where neither side names a known object (should not happen).
    pub unattributed: u64,
    /// All pixels whose id.prim differs.
    pub total: u64,
}

/// Counts id.prim mismatches per object.
pub fn object_mismatches(
    ref_prim: &[u32],
    ref_object: Option<&[u32]>,
    test_prim: &[u32],
    test_object: Option<&[u32]>,
    objects: usize,
) -> ObjectMismatches {
    let mut m = ObjectMismatches {
        by_object: vec![0; objects],
        ..ObjectMismatches::default()
    };
    for (i, (&r, &t)) in ref_prim.iter().zip(test_prim).enumerate() {
        if r == t {
            continue;
        }
        m.total += 1;
        let pick = |o: Option<&[u32]>| o.and_then(|o| o.get(i).copied());
        let obj = if r != BACKGROUND_ID {
            pick(ref_object)
        } else {
            pick(test_object)
        };
        match obj.filter(|&o| (o as usize) < objects) {
            Some(o) => m.by_object[o as usize] += 1,
            None => m.unattributed += 1,
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_land_in_log_bins_and_zeros_apart() {
        let inf = f32::INFINITY;
        let h = Histogram::of_depth(&[1.0, 1.0, 2.0, inf, inf], &[1.0, 1.001, 2.5, inf, 3.0]);
        assert_eq!(h.zero, 1);
        assert_eq!(h.mask_mismatches, 1);
        assert_eq!(h.total(), 3);
        let (a, b) = h.used_bins().unwrap();
        assert!(Histogram::bin_lo(a) <= 0.001 && 0.001 < Histogram::bin_lo(a + 1));
        assert!(Histogram::bin_lo(b) <= 0.5 && 0.5 < Histogram::bin_lo(b + 1));
        let mut m = h.clone();
        m.merge(&h);
        assert_eq!(m.total(), 6);
    }

    #[test]
    fn hits_on_different_triangles_are_counted_apart_not_binned() {
        let inf = f32::INFINITY;
        let (z_ref, z_test) = ([1.0, 1.0, 2.0, inf], [1.0, 1.1, 2.5, 3.0]);
        // Pixel 1 sees triangle 7 in the test, 4 in the reference: its 0.1 is two surfaces.
        let h =
            Histogram::of_depth_same_prims(&z_ref, &z_test, Some((&[4, 4, 5, 0], &[4, 7, 5, 9])));
        assert_eq!(
            (h.zero, h.other_prim, h.mask_mismatches, h.total()),
            (1, 1, 1, 2)
        );
        let (a, b) = h.used_bins().unwrap();
        assert!(a == b && Histogram::bin_lo(a) <= 0.5 && 0.5 < Histogram::bin_lo(a + 1));
        // Without prims every common hit is binned, as before.
        assert_eq!(
            Histogram::of_depth_same_prims(&z_ref, &z_test, None).total(),
            3
        );
    }

    #[test]
    fn mismatches_go_to_the_reference_object_or_the_test_one_on_background() {
        let bg = BACKGROUND_ID;
        let m = object_mismatches(
            &[0, 1, bg, 2],
            Some(&[0, 0, bg, 1]),
            &[0, 2, 3, 2],
            Some(&[0, 1, 1, 1]),
            2,
        );
        assert_eq!(m.by_object, vec![1, 1]);
        assert_eq!(m.total, 2);
    }
}
