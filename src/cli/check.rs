//! `rendiff check` and `rendiff merge`: the run's options from the command
//! line and rendiff's own files, the run, and its closing table and report.

use super::{exit, expectations_file, own_file, renderers_file};
use anyhow::Result;
use clap::Args;
use rendiff::check::{self, CheckOptions, CheckOutcome};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

// `rendiff check`'s options. (No doc comment: clap would take it for the
// subcommand's help, which is the variant's in main.rs.)
#[derive(Args)]
pub struct CheckArgs {
    /// Scene files or folders (default: rendiff's scenes and the real-asset corpus scenes/corpus);
    /// a model file (.obj, .gltf, .glb) is checked as the scene `scene new` would write for it.
    scenes: Vec<PathBuf>,
    /// Run folder.
    #[arg(short, long, default_value = "reports/runs/latest")]
    output: PathBuf,
    /// Only these backends, comma-separated (the raster reference always runs).
    #[arg(long, value_delimiter = ',')]
    only: Option<Vec<String>>,
    /// Seconds before an external renderer is killed (1 to a week).
    #[arg(long, default_value_t = 600, value_parser = rendiff::args::parse_timeout)]
    timeout: u64,
    /// Known divergences with their bounds (default: rendiff's tests/expectations.toml).
    #[arg(long)]
    expectations: Option<PathBuf>,
    /// Print only the summary.
    #[arg(long)]
    quiet: bool,
    /// Print every verdict, not only the failing ones (results.json and
    /// the report always have every one).
    #[arg(long)]
    verbose: bool,
    /// Cached Monte Carlo references (Mitsuba) for global-illumination scenes
    /// (default: rendiff's tests/references).
    #[arg(long)]
    references: Option<PathBuf>,
    /// Seed of the core's path tracer.
    #[arg(long, default_value_t = rendiff::check::CHECK_SEED)]
    seed: u64,
    /// Samples per pixel of the core's path tracer (default: each scene's integrator.spp).
    #[arg(long, value_parser = rendiff::args::parse_spp)]
    spp: Option<u32>,
    /// Deliberately wrong core shading, for testing the statistical gate's power.
    #[arg(long, value_parser = rendiff::args::named::<rendiff::shade::Bias>(), hide = true)]
    inject_bias: Option<rendiff::shade::Bias>,
    /// Folder of camera calibration probe scenes, rendered first on every
    /// backend (default: rendiff's scenes/calibration).
    #[arg(long)]
    calibration: Option<PathBuf>,
    /// Render no calibration probes (the comparison then measures no camera).
    #[arg(long, conflicts_with = "calibration")]
    no_calibration: bool,
    /// Run shard K of N (1-based, e.g. 2/4): a deterministic, cost-balanced
    /// share of the scenes (probes run in every shard); `rendiff merge`
    /// joins the shard runs.
    #[arg(long)]
    shard: Option<rendiff::check::shard::Shard>,
    /// A previous run whose render times balance the shards (default: the
    /// run folder's previous run, if any).
    #[arg(long, requires = "shard")]
    shard_costs: Option<PathBuf>,
    /// External renders run this many at a time, across scenes (default:
    /// the cores; 1 with `--wait-slots 0` runs them one after another).
    #[arg(long, value_parser = rendiff::args::parse_threads)]
    jobs: Option<usize>,
    /// Extra slots for renders that mostly wait (POV-Ray's small scenes),
    /// beside the `--jobs` ones (default: as many as `--jobs`; 0: none).
    #[arg(long)]
    wait_slots: Option<usize>,
    /// Your own renderers, declared by command in a TOML file
    /// (docs/your-renderer.md); they run beside the built-in ones.
    #[arg(long)]
    renderers: Option<PathBuf>,
    /// Start a fresh harness process for every external render instead of
    /// long-lived workers (slower; for comparison and debugging).
    #[arg(long)]
    no_workers: bool,
    /// Estimated peak memory of the external renders in flight, in MiB
    /// (default: half of the memory available; a render bigger than it runs alone).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=1 << 30))]
    memory_budget: Option<u64>,
}

// `rendiff merge`'s options (no doc comment, as for `CheckArgs`).
#[derive(Args)]
pub struct MergeArgs {
    /// The shard runs.
    #[arg(required = true)]
    runs: Vec<PathBuf>,
    /// The merged run folder.
    #[arg(short, long, default_value = "reports/runs/latest")]
    output: PathBuf,
    /// Known divergences with their bounds (default: rendiff's tests/expectations.toml).
    #[arg(long)]
    expectations: Option<PathBuf>,
    /// Cached Monte Carlo references (Mitsuba) for global-illumination scenes
    /// (default: rendiff's tests/references).
    #[arg(long)]
    references: Option<PathBuf>,
    /// Print only the summary.
    #[arg(long)]
    quiet: bool,
    /// Print every verdict, not only the failing ones.
    #[arg(long)]
    verbose: bool,
    /// The renderers file the shard runs used (docs/your-renderer.md):
    /// their declared precision judges their renders.
    #[arg(long)]
    renderers: Option<PathBuf>,
}

/// `rendiff check`.
pub fn run(a: CheckArgs) -> Result<ExitCode> {
    let jobs = a.jobs.unwrap_or_else(check::default_jobs);
    // rendiff's own files come from its checkout, wherever this runs;
    // the harness runs there, so every path it gets is absolute.
    let root = check::find_root()?;
    let expectations = expectations_file(&root, a.expectations)?;
    let references = own_file(&root, a.references, "tests/references")?;
    let calibration = own_file(&root, a.calibration, "scenes/calibration")?;
    let output = std::path::absolute(&a.output)?;
    let scenes = if a.scenes.is_empty() {
        vec![
            check::in_root(&root, "scenes"),
            check::in_root(&root, "scenes/corpus"),
        ]
    } else {
        a.scenes
    };
    let mut scenes = check::collect_scenes(&scenes)?;
    let mut split = None;
    if let Some(shard) = a.shard {
        let (record, mine) = deal_shard(shard, &scenes, a.shard_costs.as_deref(), &output)?;
        split = Some(record);
        scenes = mine;
    }
    let opts = CheckOptions {
        scenes,
        run_dir: output.clone(),
        root,
        only: a.only,
        timeout: std::time::Duration::from_secs(a.timeout),
        expectations,
        quiet: a.quiet,
        references: Some(references),
        core: check::CoreShading {
            seed: a.seed,
            spp: a.spp,
            bias: a.inject_bias,
        },
        calibration: (!a.no_calibration).then_some(calibration),
        jobs,
        wait_slots: a.wait_slots.unwrap_or(jobs),
        workers: !a.no_workers,
        renderers: renderers_file(a.renderers)?,
        renderers_snapshot: None,
        memory_budget: a
            .memory_budget
            .map_or_else(check::pool::default_memory_budget, |mib| mib << 20),
    };
    // On failure the run folder keeps its INCOMPLETE marker: no report.
    let outcome = match split {
        Some(record) => check::run_shard(&opts, record)?,
        None => check::run(&opts)?,
    };
    Ok(finish_run("check", &outcome, &output, a.verbose))
}

/// `check --shard K/N`: the split's record and this shard's scenes, balanced
/// by the render times of `costs_run` (else the run folder's previous run).
fn deal_shard(
    shard: check::shard::Shard,
    scenes: &[PathBuf],
    costs_run: Option<&Path>,
    output: &Path,
) -> Result<(check::manifest::ShardRecord, Vec<PathBuf>)> {
    use rendiff::check::shard as sh;
    let costs = match costs_run {
        Some(run) => sh::recorded_costs(run, true)?,
        None => sh::recorded_costs(output, false)?,
    };
    let all = scenes.len();
    let record = sh::deal(scenes, shard, &costs)?;
    let mine = sh::select(scenes, shard, &costs);
    rendiff::errln!(
        "shard {}/{}: {} of {all} scenes",
        shard.index,
        shard.total,
        mine.len()
    );
    if mine.is_empty() {
        anyhow::bail!(
            "shard {}/{} has no scenes ({all} scenes for {} shards): use fewer shards",
            shard.index,
            shard.total,
            shard.total
        );
    }
    Ok((record, mine))
}

/// `rendiff merge`.
pub fn merge(a: MergeArgs) -> Result<ExitCode> {
    let root = check::find_root()?;
    let expectations = expectations_file(&root, a.expectations)?;
    let references = own_file(&root, a.references, "tests/references")?;
    let output = std::path::absolute(&a.output)?;
    let runs = a
        .runs
        .iter()
        .map(std::path::absolute)
        .collect::<std::io::Result<Vec<_>>>()?;
    let opts = CheckOptions {
        scenes: Vec::new(),
        run_dir: output.clone(),
        root,
        only: None,
        timeout: std::time::Duration::from_secs(600),
        expectations,
        quiet: a.quiet,
        references: Some(references),
        core: check::CoreShading::default(),
        calibration: None,
        jobs: check::default_jobs(),
        wait_slots: check::default_jobs(),
        workers: true,
        renderers: renderers_file(a.renderers)?,
        renderers_snapshot: None,
        memory_budget: check::pool::default_memory_budget(),
    };
    let outcome = check::shard::merge(&runs, &opts)?;
    let what = format!("merge of {} shard runs", runs.len());
    Ok(finish_run(&what, &outcome, &output, a.verbose))
}

/// The check settings `fuzz` and `reduce` run with: `check`'s defaults
/// (rendiff's expectations, references and calibration probes, all cores)
/// and the options they share with it; scenes and run folder are theirs to set.
pub fn template(
    only: Option<Vec<String>>,
    renderers: Option<PathBuf>,
    jobs: Option<usize>,
    timeout: u64,
    expectations: Option<PathBuf>,
) -> Result<CheckOptions> {
    let root = check::find_root()?;
    let expectations = expectations_file(&root, expectations)?;
    let references = own_file(&root, None, "tests/references")?;
    let calibration = own_file(&root, None, "scenes/calibration")?;
    Ok(CheckOptions {
        scenes: Vec::new(),
        run_dir: PathBuf::new(),
        root,
        only,
        timeout: std::time::Duration::from_secs(timeout),
        expectations,
        quiet: false,
        references: Some(references),
        core: check::CoreShading::default(),
        calibration: Some(calibration),
        jobs: jobs.unwrap_or_else(check::default_jobs),
        wait_slots: jobs.unwrap_or_else(check::default_jobs),
        workers: true,
        renderers: renderers_file(renderers)?,
        renderers_snapshot: None,
        memory_budget: check::pool::default_memory_budget(),
    })
}

/// The end of `check` and `merge`: the verdict table, the tally, the report;
/// exit 1 when any verdict fails.
fn finish_run(what: &str, outcome: &CheckOutcome, output: &Path, verbose: bool) -> ExitCode {
    let tally = check::tally(&outcome.results);
    let verdicts = &outcome.results.results;
    let failing = verdicts.iter().filter(|e| e.is_failure()).count();
    let table = check::table::shown(&outcome.table, verdicts.len(), failing, verbose);
    // The table quotes scene names: control characters escaped.
    rendiff::out!("{}", check::process::printable_lines(&table));
    rendiff::outln!(
        "{what}: {} ok, {} failing, {} skipped -> {}",
        tally.ok,
        tally.failed,
        tally.skipped,
        rendiff::scene::printable(&output.join("results.json").display().to_string(), 500)
    );
    write_report(output);
    exit(tally.failed == 0, 1)
}

/// Every check run gets its report; a report problem is a warning, never a changed verdict.
fn write_report(run: &Path) {
    match rendiff::report::write(run) {
        Ok(index) => rendiff::outln!("report: {}", index.display()),
        Err(e) => rendiff::errln!("warning: report not written: {e:#}"),
    }
}
