//! Value parsers for command-line arguments that both binaries take
//! (`rendiff` and `rendiff-bench`): one home for what a thread count or a
//! named setting may be.

use rendiff_core::names::Named;

/// The shape of every count option: `s` parsed as a whole number (`what`
/// names it when it is none), then 1 to `max`; the error reads `{n}{unit}:
/// give 1 to {max}{why}`.
fn count(s: &str, what: &str, max: u64, unit: &str, why: &str) -> Result<u64, String> {
    let n: u64 = s.parse().map_err(|_| format!("{s:?} is not {what}"))?;
    if n == 0 || n > max {
        return Err(format!("{n}{unit}: give 1 to {max}{why}"));
    }
    Ok(n)
}

/// More worker threads than this per core only adds switching (and `--threads
/// 100000` once started 2661 threads and stalled the machine).
pub const MAX_THREADS_PER_CORE: usize = 4;

/// `--threads N`: 1 to 4 per core of this machine, checked before any thread starts.
pub fn parse_threads(s: &str) -> std::result::Result<usize, String> {
    let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
    let max = (MAX_THREADS_PER_CORE * cores) as u64;
    let why = format!(" ({MAX_THREADS_PER_CORE} per core on {cores} cores)");
    count(s, "a thread count", max, " threads", &why).map(|n| n as usize)
}

/// Most timed runs a benchmark takes per configuration: each is a whole
/// pass (seconds on the big scenes, minutes for `bench scale`), a median of
/// a thousand is already exact to the machine's noise, and the run times are
/// kept in a list allocated up front (`--runs 10^14` aborted on that
/// allocation).
pub const MAX_RUNS: usize = 1000;

/// `--runs N`: 1 to [`MAX_RUNS`] (0 used to be raised to 1 silently, so the
/// report said one thing and the command another).
pub fn parse_runs(s: &str) -> std::result::Result<usize, String> {
    count(s, "a number of runs", MAX_RUNS as u64, " runs", "").map(|n| n as usize)
}

/// Longest `--timeout` for one external render: a week. Longer is a typo
/// (and `--timeout 18446744073709551615` overflowed the deadline's clock
/// arithmetic: a panic, not an error).
pub const MAX_TIMEOUT_S: u64 = 7 * 24 * 3600;

/// `--timeout SECONDS`: 1 to [`MAX_TIMEOUT_S`] (0 failed every external
/// render as timed out).
pub fn parse_timeout(s: &str) -> std::result::Result<u64, String> {
    count(s, "a number of seconds", MAX_TIMEOUT_S, " s", " (a week)")
}

/// `--spp N`: the scene file's own limit ([`crate::scene::check_spp`]), before any rendering.
pub fn parse_spp(s: &str) -> std::result::Result<u32, String> {
    let n: u32 = s
        .parse()
        .map_err(|_| format!("{s:?} is not a sample count"))?;
    crate::scene::check_spp(n).map(|()| n)
}

/// A clap parser for a core enum: its names are the core's ([`Named`]), so the
/// core needs no command-line library and each name is written once.
pub fn named<T: Named + Clone>() -> impl clap::builder::TypedValueParser<Value = T> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(T::ALL.iter().map(|v| v.name()))
        .map(|s| T::from_name(&s).expect("clap accepted only listed names"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_timeouts_and_threads_are_bounded() {
        assert_eq!(parse_runs("1"), Ok(1));
        assert_eq!(parse_runs("1000"), Ok(MAX_RUNS));
        for bad in ["0", "1001", "100000000000000", "-1", "x", ""] {
            assert!(parse_runs(bad).is_err(), "{bad:?}");
        }
        assert_eq!(parse_timeout("1"), Ok(1));
        assert_eq!(parse_timeout("604800"), Ok(MAX_TIMEOUT_S));
        for bad in ["0", "604801", "18446744073709551615", "1.5", "-1"] {
            assert!(parse_timeout(bad).is_err(), "{bad:?}");
        }
        assert_eq!(parse_threads("1"), Ok(1));
        for bad in ["0", "100000", "-2", "two"] {
            assert!(parse_threads(bad).is_err(), "{bad:?}");
        }
    }
}
