//! Option values that the command line and the JSON records spell: one
//! spelling per value, written once beside the enum, so the core needs no
//! command-line library (the tool turns [`Named`] into its parsers).

/// An enum whose values have one name each.
pub trait Named: Copy + Send + Sync + 'static {
    /// Every value, in the order help lists them.
    const ALL: &'static [Self];
    /// The value's name on the command line (kebab-case).
    fn name(self) -> &'static str;
    /// The value with that name.
    fn from_name(s: &str) -> Option<Self> {
        Self::ALL.iter().copied().find(|v| v.name() == s)
    }
}

#[cfg(test)]
mod tests {
    use super::Named;
    use crate::shade::Bias;
    use crate::trace::{BvhQuality, TraceKernel};

    fn round_trips<T: Named + PartialEq + std::fmt::Debug>() {
        for &v in T::ALL {
            assert_eq!(T::from_name(v.name()), Some(v));
        }
        let mut names: Vec<_> = T::ALL.iter().map(|v| v.name()).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), T::ALL.len(), "two values share a name");
    }

    #[test]
    fn names_round_trip_and_are_unique() {
        round_trips::<BvhQuality>();
        round_trips::<TraceKernel>();
        round_trips::<Bias>();
    }
}
