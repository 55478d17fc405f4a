//! `rendiff-bench` (also run as `rendiff bench ...`): every benchmark writes
//! JSON (plus HTML and SVG for the subcommands) under `reports/bench/`.

use anyhow::Result;
use clap::Parser;
use rendiff::trace::BvhQuality;
use rendiff_bench::cli::BenchCommand;
use std::path::PathBuf;
use std::process::ExitCode;

/// Benchmarks: speed against accuracy (knobs), against other renderers (peers),
/// raster vs trace by triangle size (crossover), the main job's wall time
/// (scale), numerical extremes (stability), the path tracer's variance.
///
/// Without a subcommand: raster and trace on one scene (median of runs after a
/// warm-up), as JSON. Each subcommand writes JSON, HTML and SVG to reports/bench/.
#[derive(Debug, Parser)]
#[command(
    name = "rendiff bench",
    version,
    args_conflicts_with_subcommands = true
)]
struct Cli {
    /// What to benchmark (default: raster and trace on SCENE).
    #[command(subcommand)]
    what: Option<BenchCommand>,
    /// Scene file (TOML) (default: scenes/million.toml in rendiff's checkout, found like
    /// `rendiff check` finds it: RENDIFF_HOME, the current folder, the checkout built from).
    scene: Option<PathBuf>,
    /// Resolution override, e.g. 1920x1080.
    #[arg(long, value_parser = rendiff_bench::knobs::parse_size)]
    size: Option<(u32, u32)>,
    /// Thread counts, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1,2", value_parser = rendiff::args::parse_threads)]
    threads: Vec<usize>,
    /// Timed runs per configuration.
    #[arg(long, default_value_t = 3, value_parser = rendiff::args::parse_runs)]
    runs: usize,
    /// BVH build quality.
    #[arg(long, value_parser = rendiff::args::named::<BvhQuality>(), default_value = "medium")]
    bvh: BvhQuality,
    /// Output JSON file.
    #[arg(short, long, default_value = "reports/bench/core.json")]
    output: PathBuf,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Err(e) = rendiff::shutdown::install() {
        rendiff::errln!("warning: SIGINT/SIGTERM not hooked ({e}); an interrupted run may leave renderers running");
    }
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            rendiff::errln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    if let Some(what) = cli.what {
        return rendiff_bench::cli::run(what);
    }
    // Refused before minutes of work, not after.
    rendiff::exr_io::check_output(&cli.output)?;
    let scene_path = match cli.scene {
        Some(p) => p,
        None => rendiff_bench::cli::default_core_scene()?,
    };
    let scene = rendiff::scene::Scene::load(&scene_path)?;
    let resolved = rendiff::scene::resolve::ResolvedScene::resolve(&scene)?;
    let opts = rendiff_bench::BenchOptions {
        size: cli.size,
        threads: cli.threads,
        runs: cli.runs,
        bvh: cli.bvh,
    };
    let record = rendiff_bench::run(&resolved, &scene_path.display().to_string(), &opts)?;
    let text = serde_json::to_string_pretty(&record)?;
    rendiff::exr_io::write_atomically(&cli.output, |tmp| {
        std::fs::write(tmp, &text)?;
        Ok(())
    })?;
    rendiff::outln!("{text}");
    Ok(())
}
