//! The commands on a run's records and buffers: `report`, `gate`, `bless`,
//! `diff`, and `bench`, which runs the benchmarks' own binary.

use super::exit;
use anyhow::{Context, Result};
use std::path::Path;
use std::process::ExitCode;

/// `rendiff report RUN`.
pub fn report(run: &Path) -> Result<ExitCode> {
    let index = rendiff::report::write(run)?;
    rendiff::outln!("report: {}", index.display());
    Ok(ExitCode::SUCCESS)
}

/// `rendiff gate RUN`: the summary; exit 1 on any regression.
pub fn gate(run: &Path, baseline: &Path) -> Result<ExitCode> {
    let (summary, passed) = rendiff::gate::gate(baseline, run)?;
    rendiff::out!("{summary}");
    Ok(exit(passed, 1))
}

/// `rendiff bless RUN`: the run's verdicts become the baseline.
pub fn bless(run: &Path, baseline: &Path, opts: rendiff::gate::BlessOptions) -> Result<ExitCode> {
    let b = rendiff::gate::bless(run, baseline, &opts)?;
    rendiff::outln!(
        "blessed {} entries from {} into {}",
        b.entries.len(),
        rendiff::scene::printable(&run.display().to_string(), 500),
        rendiff::scene::printable(&baseline.display().to_string(), 500)
    );
    Ok(ExitCode::SUCCESS)
}

/// `rendiff diff`: one line per buffer present in either file (src/diff.rs);
/// exit 1 on any difference, 0 when identical, 2 (an error) when the files
/// share no buffer.
pub fn diff(a: &Path, b: &Path) -> Result<ExitCode> {
    let d = rendiff::diff::diff_files(a, b)?;
    for line in d.lines(&a.display().to_string(), &b.display().to_string()) {
        rendiff::outln!("{line}");
    }
    Ok(exit(!d.differs(), 1))
}

/// `rendiff bench ...`: the benchmarks are a workspace member of their own
/// (crates/rendiff-bench), run as the `rendiff-bench` binary found beside
/// this one; its exit status is passed on.
pub fn bench(args: &[std::ffi::OsString]) -> Result<ExitCode> {
    let exe = std::env::current_exe().context("cannot find the rendiff binary")?;
    let bench = exe.with_file_name("rendiff-bench");
    if !bench.is_file() {
        anyhow::bail!(
            "{}: not built; the benchmarks are their own binary: cargo build --release -p rendiff-bench",
            bench.display()
        );
    }
    let status = std::process::Command::new(&bench)
        .args(args)
        .status()
        .with_context(|| format!("cannot run {}", bench.display()))?;
    Ok(ExitCode::from(
        status.code().map_or(2, |c| c.clamp(0, 255) as u8),
    ))
}
