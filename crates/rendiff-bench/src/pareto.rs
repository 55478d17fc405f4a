//! The Pareto front of (time, error) points: the settings worth choosing,
//! because no other setting is both at least as fast and at least as accurate.
//! Kept apart so the smoke test and the plots use one definition.

/// True when `a` dominates `b`: no worse in both coordinates and better in one (both minimised).
pub fn dominates(a: (f64, f64), b: (f64, f64)) -> bool {
    a.0 <= b.0 && a.1 <= b.1 && (a.0 < b.0 || a.1 < b.1)
}

/// Indices of the non-dominated points, in input order. Points with a
/// non-finite coordinate are never on the front and never dominate (they were
/// not measured). Equal points are all on the front: none dominates another.
pub fn front(points: &[(f64, f64)]) -> Vec<usize> {
    let ok = |p: &(f64, f64)| p.0.is_finite() && p.1.is_finite();
    (0..points.len())
        .filter(|&i| ok(&points[i]) && !points.iter().any(|q| ok(q) && dominates(*q, points[i])))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn front_keeps_only_non_dominated_points() {
        let pts = [
            (1.0, 10.0),
            (2.0, 5.0),
            (3.0, 6.0), // dominated by (2, 5)
            (4.0, 0.0),
            (4.0, 0.0), // a tie: both stay
            (0.5, f64::NAN),
        ];
        assert_eq!(front(&pts), vec![0, 1, 3, 4]);
        assert!(dominates((1.0, 1.0), (1.0, 2.0)));
        assert!(!dominates((1.0, 1.0), (1.0, 1.0)));
    }
}
