//! `rendiff fuzz` and `rendiff reduce`: generated scenes checked and their
//! failures grouped and shrunk; one failing scene shrunk.

use super::check::template;
use super::exit;
use anyhow::Result;
use clap::Args;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

// `rendiff fuzz`'s options. (No doc comment: clap would take it for the
// subcommand's help, which is the variant's in main.rs.)
#[derive(Args)]
pub struct FuzzArgs {
    /// Seed: the same seed and count give the same scene files, byte for byte.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// How many scenes to generate (give this or --minutes).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=rendiff::fuzz::MAX_COUNT))]
    count: Option<u64>,
    /// Generate and check batches of 50 scenes until this many minutes
    /// have passed (give this or --count); the first N scenes are the
    /// same as --count N's.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=rendiff::fuzz::MAX_MINUTES))]
    minutes: Option<u64>,
    /// The fuzz folder (a new folder, or one an earlier fuzz wrote).
    #[arg(short, long, default_value = "reports/fuzz/latest")]
    output: PathBuf,
    /// Only these backends, comma-separated (the raster reference always runs).
    #[arg(long, value_delimiter = ',')]
    only: Option<Vec<String>>,
    /// Your own renderers, declared by command in a TOML file (docs/your-renderer.md).
    #[arg(long)]
    renderers: Option<PathBuf>,
    /// External renders run this many at a time (default: the cores).
    #[arg(long, value_parser = rendiff::args::parse_threads)]
    jobs: Option<usize>,
    /// Seconds before an external renderer is killed (1 to a week).
    #[arg(long, default_value_t = 600, value_parser = rendiff::args::parse_timeout)]
    timeout: u64,
    /// Known divergences with their bounds (default: rendiff's tests/expectations.toml).
    #[arg(long)]
    expectations: Option<PathBuf>,
    /// Render no calibration probes (the comparison then measures no camera).
    #[arg(long)]
    no_calibration: bool,
    /// Seconds of reduction per finding (0: reduce nothing).
    #[arg(long, default_value_t = 180)]
    reduce_budget: u64,
    /// Instead of generated scenes: metamorphic variants of these scene
    /// files (translate, rotate, mirror, permute, flip winding,
    /// duplicate), each held to its base's verdict class.
    #[arg(long, num_args = 1..)]
    from: Vec<PathBuf>,
    /// Known-finding declarations that classify the findings
    /// (default: rendiff's scenes/found/known/; docs/fuzzing.md).
    #[arg(long)]
    known: Option<PathBuf>,
    /// Print only the summary.
    #[arg(long)]
    quiet: bool,
}

// `rendiff reduce`'s options (no doc comment, as for `FuzzArgs`).
#[derive(Args)]
pub struct ReduceArgs {
    /// The check run (holds manifest.json and results.json).
    run: PathBuf,
    /// The scene's name in the run (its file stem).
    scene: String,
    /// The backend whose failure to keep.
    #[arg(long)]
    backend: String,
    /// The buffer whose failure to keep (default: the first failing one).
    #[arg(long)]
    buffer: Option<String>,
    /// The reduced scene file (default: reduced/SCENE.BACKEND.toml).
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// The renderers file the run used, when BACKEND is declared there.
    #[arg(long)]
    renderers: Option<PathBuf>,
    /// Known divergences with their bounds (default: rendiff's tests/expectations.toml).
    #[arg(long)]
    expectations: Option<PathBuf>,
    /// External renders run this many at a time (default: the cores).
    #[arg(long, value_parser = rendiff::args::parse_threads)]
    jobs: Option<usize>,
    /// Seconds before an external renderer is killed (1 to a week).
    #[arg(long, default_value_t = 600, value_parser = rendiff::args::parse_timeout)]
    timeout: u64,
    /// Stop reducing after this many seconds and keep what was reached.
    #[arg(long, value_parser = rendiff::args::parse_timeout)]
    budget: Option<u64>,
}

/// `rendiff fuzz`.
pub fn run(a: FuzzArgs) -> Result<ExitCode> {
    // Checked here rather than by clap, whose refusal spans several
    // lines: the one-line error every bad input gets.
    let amount = match (a.count, a.minutes) {
        _ if !a.from.is_empty() && (a.count.is_some() || a.minutes.is_some()) => {
            anyhow::bail!("fuzz: --from makes its own scenes; give no --count or --minutes")
        }
        _ if !a.from.is_empty() => rendiff::fuzz::Amount::Variants(a.from),
        (Some(n), None) => rendiff::fuzz::Amount::Count(n),
        (None, Some(m)) => rendiff::fuzz::Amount::Minutes(m),
        (Some(_), Some(_)) => {
            anyhow::bail!("fuzz: give --count N or --minutes M, not both")
        }
        (None, None) => {
            anyhow::bail!("fuzz: give --count N or --minutes M (or --from SCENE...)")
        }
    };
    let mut check = template(a.only, a.renderers, a.jobs, a.timeout, a.expectations)?;
    check.quiet = a.quiet;
    if a.no_calibration {
        check.calibration = None;
    }
    let folder = std::path::absolute(&a.output)?;
    let opts = rendiff::fuzz::FuzzOptions {
        seed: a.seed,
        amount,
        folder: folder.clone(),
        check,
        reduce_budget: (a.reduce_budget > 0)
            .then(|| std::time::Duration::from_secs(a.reduce_budget)),
        known: a.known,
    };
    let outcome = rendiff::fuzz::run(&opts)?;
    let l = &outcome.ledger;
    print_findings(l, &folder);
    rendiff::outln!(
        "fuzz: seed {}, {} scenes, {} failing verdicts, {} findings{} -> {}",
        a.seed,
        l.scenes,
        l.failures.len(),
        l.findings.len(),
        if l.camera_failures.is_empty() {
            String::new()
        } else {
            format!(", {} camera calibration failures", l.camera_failures.len())
        },
        folder.join("findings.json").display()
    );
    let failed = !l.failures.is_empty() || !l.camera_failures.is_empty();
    Ok(exit(!failed, 1))
}

/// One paragraph per finding: what fails where, and its reduction.
fn print_findings(l: &rendiff::fuzz::findings::Ledger, folder: &Path) {
    for f in &l.findings {
        let s = &f.signature;
        let families: Vec<String> = f.families.iter().map(|(k, n)| format!("{k} {n}")).collect();
        rendiff::outln!(
            "{}: {} fails {} ({}) on {} scene(s) ({})",
            f.id,
            s.backend,
            s.buffer,
            s.class,
            f.hits,
            families.join(", ")
        );
        match &f.reduced {
            Some(r) if r.error.is_empty() => rendiff::outln!(
                "  reduced {}{}: {} -> {} triangles, {} -> {} bytes, {}x{} -> {}x{} pixels: {}\n  reproduce: {}",
                r.from,
                if r.complete { "" } else { " (budget ran out)" },
                r.triangles_before,
                r.triangles_after,
                r.bytes_before,
                r.bytes_after,
                r.image_before[0],
                r.image_before[1],
                r.image_after[0],
                r.image_after[1],
                folder.join(&r.scene).display(),
                r.command
            ),
            Some(r) => rendiff::outln!("  not reduced {}: {}", r.from, r.error),
            None => {}
        }
    }
}

/// `rendiff reduce`.
pub fn reduce(a: ReduceArgs) -> Result<ExitCode> {
    let mut check = template(None, a.renderers, a.jobs, a.timeout, a.expectations)?;
    check.quiet = true;
    let (target, scene_file) =
        rendiff::fuzz::target_in_run(&a.run, &a.scene, &a.backend, a.buffer.as_deref())?;
    let out = a.output.unwrap_or_else(|| {
        // The scene name is one plain folder name in a run (docs/run-format.md).
        PathBuf::from("reduced").join(format!("{}.{}.toml", a.scene, a.backend))
    });
    let out = std::path::absolute(&out)?;
    let work = out.with_extension("work");
    let r = rendiff::fuzz::reduce_file(
        &scene_file,
        &target,
        &check,
        &work,
        a.budget.map(std::time::Duration::from_secs),
        &out,
    )?;
    rendiff::outln!(
        "{} fails {} with class {}: {}",
        target.backend,
        target.buffer,
        target.class,
        r.sizes("->")
    );
    if !r.image_note.is_empty() {
        rendiff::outln!("{}", r.image_note);
    }
    rendiff::outln!("reduced: {}", out.display());
    rendiff::outln!("reproduce: {}", r.command);
    Ok(ExitCode::SUCCESS)
}
