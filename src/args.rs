//! Value parsers for command-line arguments that both binaries take
//! (`rendiff` and `rendiff-bench`): one home for what a thread count or a
//! named setting may be.

use rendiff_core::names::Named;

/// More worker threads than this per core only adds switching (and `--threads
/// 100000` once started 2661 threads and stalled the machine).
pub const MAX_THREADS_PER_CORE: usize = 4;

/// `--threads N`: 1 to 4 per core of this machine, checked before any thread starts.
pub fn parse_threads(s: &str) -> std::result::Result<usize, String> {
    let n: usize = s
        .parse()
        .map_err(|_| format!("{s:?} is not a thread count"))?;
    let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
    let max = MAX_THREADS_PER_CORE * cores;
    if n == 0 || n > max {
        return Err(format!(
            "{n} threads: give 1 to {max} ({MAX_THREADS_PER_CORE} per core on {cores} cores)"
        ));
    }
    Ok(n)
}

/// A clap parser for a core enum: its names are the core's ([`Named`]), so the
/// core needs no command-line library and each name is written once.
pub fn named<T: Named + Clone>() -> impl clap::builder::TypedValueParser<Value = T> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(T::ALL.iter().map(|v| v.name()))
        .map(|s| T::from_name(&s).expect("clap accepted only listed names"))
}
