//! The `rendiff` command line: render scenes with either visibility loop, list
//! scenes, export resolved scenes for external renderers, and diff buffers.
//! This file holds the commands and their options; each one's body is in
//! `cli/` (one module per family).

mod cli;

use anyhow::Result;
use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

/// rendiff: differential testing for renderers.
///
/// Renders a scene's visibility (depth, triangle and object IDs, normals) two
/// ways, by rasterization (for each triangle, which pixels?) and by ray tracing
/// (for each pixel, which triangle?), which must agree bit for bit, and
/// compares buffers. Scenes are TOML files; see scenes/ and the README.
#[derive(Parser)]
#[command(name = "rendiff", version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// `rendiff scene ...`.
#[derive(Subcommand)]
enum SceneAction {
    /// Write the scene rendiff makes for a model file (the camera framing its
    /// bounding sphere, docs/resolved-scene.md) to a new TOML file for editing.
    New {
        /// The model: .obj, .gltf or .glb.
        model: PathBuf,
        /// The scene file to write (never overwritten); its folder must hold the model.
        #[arg(short, long)]
        output: PathBuf,
    },
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene's depth/ID/normal buffers to an EXR (plus PNG previews).
    Render(cli::render::RenderArgs),
    /// Make scene files (`scene new MODEL -o SCENE.toml`).
    Scene {
        #[command(subcommand)]
        action: SceneAction,
    },
    /// List scenes in a folder with the features they require.
    Scenes {
        /// Folder to list.
        #[arg(default_value = "scenes")]
        dir: PathBuf,
    },
    /// Write the resolved scene (triangles, IDs, camera) for external renderers.
    Export {
        /// Scene file (TOML), or a model (.obj, .gltf, .glb).
        scene: PathBuf,
        /// Output folder (scene.json, triangles.f32, object_ids.u32, vertex_ids.u32).
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Run every scene on every backend and compare against the core's raster output.
    ///
    /// Backends: the core's raster (reference) and trace loops, Embree (default
    /// and robust), and the Python harness's POV-Ray, pyrender and Mitsuba 3.
    /// Writes RUN/manifest.json, the buffers, diff images and RUN/results.json.
    /// Exit 1 if any comparison fails or errors.
    Check(cli::check::CheckArgs),
    /// Joins shard runs (`check --shard K/N`) into one run folder, compares it
    /// once and writes its report: the verdicts one machine would give.
    Merge(cli::check::MergeArgs),
    /// Benchmarks (knobs, peers, crossover, scale, stability, variance, or raster
    /// and trace on one scene): runs `rendiff-bench` from beside this binary
    /// (`cargo build --release -p rendiff-bench`) with the same arguments;
    /// `rendiff bench --help` lists them.
    #[command(disable_help_flag = true)]
    Bench {
        /// Arguments of `rendiff-bench`.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<std::ffi::OsString>,
    },
    /// Compare two buffer EXRs, every buffer bit for bit (IDs, depth, normals,
    /// radiance). Exit 1 on any difference, 2 when they share no buffer.
    Diff {
        /// Reference EXR.
        a: PathBuf,
        /// Test EXR.
        b: PathBuf,
    },
    /// Write a check run's static HTML report to RUN/report/ (check does this too).
    Report {
        /// Run folder (holds manifest.json and results.json).
        #[arg(default_value = "reports/runs/latest")]
        run: PathBuf,
    },
    /// Compare a run's verdicts with a blessed baseline; exit 1 on any regression.
    ///
    /// Writes a markdown summary (for a PR comment) to stdout and RUN/gate.md.
    Gate {
        /// Run folder (holds results.json).
        #[arg(default_value = "reports/runs/latest")]
        run: PathBuf,
        /// Baseline file written by `rendiff bless`.
        #[arg(long, default_value = "reports/baseline.json")]
        baseline: PathBuf,
    },
    /// The words of scene files and run records (features, statuses, buffers,
    /// mismatch classes), from their one definition; the Python harness checks
    /// its copy against `--json`.
    Vocab {
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// What this installation found: the binary, the harness and how it was
    /// found (RENDIFF_HOME, the current checkout, the checkout built from, or
    /// an installed harness through RENDIFF_PYTHON), its Python, and every
    /// renderer's version and status. Exit 2 when the harness is missing,
    /// with the command that fixes it.
    Doctor {
        /// Also list the renderers this file declares (docs/your-renderer.md).
        #[arg(long)]
        renderers: Option<PathBuf>,
    },
    /// Internal: run a command and write its peak memory (max RSS, bytes) to a
    /// file; `check` measures renders through it, from a small process.
    #[command(hide = true, name = "peak-rss")]
    PeakRss {
        /// File to write the peak to.
        #[arg(long)]
        report: PathBuf,
        /// The command and its arguments.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, required = true)]
        command: Vec<std::ffi::OsString>,
    },
    /// Generate scenes nobody wrote (docs/fuzzing.md), check them all in one
    /// run (or batches until --minutes are up), group the failures into
    /// findings and reduce each to a small repro.
    ///
    /// Writes FOLDER/scenes/ (the generated scenes), FOLDER/run/ (the check
    /// run; FOLDER/runs/b<k>/ per batch under --minutes), FOLDER/reduced/
    /// (one standalone scene per finding) and
    /// FOLDER/findings.json. Exit 1 when anything failed.
    Fuzz(cli::fuzz::FuzzArgs),
    /// Shrink a failing scene of a check run to a small standalone repro
    /// (docs/fuzzing.md): ddmin over objects, then triangles, then snapping
    /// coordinates to coarser grids, while the backend still fails the same
    /// buffer with the same class.
    Reduce(cli::fuzz::ReduceArgs),
    /// Make a run's verdicts and numbers the new baseline (the only way thresholds change).
    Bless {
        /// Run folder (holds manifest.json and results.json).
        #[arg(default_value = "reports/runs/latest")]
        run: PathBuf,
        /// Baseline file to (re)write, atomically.
        #[arg(long, default_value = "reports/baseline.json")]
        baseline: PathBuf,
        /// Accept failing or erroring verdicts (scenes that could not be
        /// loaded included) into the baseline instead of refusing.
        #[arg(long)]
        allow_failures: bool,
        /// Accept a run whose set of scenes differs from the current
        /// baseline's (scenes added or removed) instead of refusing.
        #[arg(long)]
        allow_scene_changes: bool,
        /// Accept a run that lacks entries (scene, backend, buffer) of the
        /// baseline's scenes, and record WHY in the baseline; without it such
        /// a run is refused, naming the entries it would drop.
        #[arg(long, value_name = "WHY")]
        drop_reason: Option<String>,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Err(e) = rendiff::shutdown::install() {
        rendiff::errln!("warning: SIGINT/SIGTERM not hooked ({e}); an interrupted run may leave renderers running");
    }
    match run(cli) {
        Ok(code) => code,
        Err(e) => {
            // Errors quote file names and renderers' output: control
            // characters are escaped (lines stay lines).
            let text = rendiff::check::process::printable_lines(&format!("{e:#}"));
            rendiff::errln!("error: {text}");
            ExitCode::from(2)
        }
    }
}

/// One subcommand, by its module in `cli/`.
fn run(cli: Cli) -> Result<ExitCode> {
    match cli.command {
        Command::Render(args) => cli::render::run(args),
        Command::Scene {
            action: SceneAction::New { model, output },
        } => cli::scenes::new(&model, &output),
        Command::Scenes { dir } => cli::scenes::list(&dir),
        Command::Export { scene, output } => cli::scenes::export(&scene, &output),
        Command::Vocab { json } => cli::scenes::vocab(json),
        Command::Check(args) => cli::check::run(args),
        Command::Merge(args) => cli::check::merge(args),
        Command::Fuzz(args) => cli::fuzz::run(args),
        Command::Reduce(args) => cli::fuzz::reduce(args),
        Command::Diff { a, b } => cli::records::diff(&a, &b),
        Command::Report { run } => cli::records::report(&run),
        Command::Gate { run, baseline } => cli::records::gate(&run, &baseline),
        Command::Bless {
            run,
            baseline,
            allow_failures,
            allow_scene_changes,
            drop_reason,
        } => {
            let opts = rendiff::gate::BlessOptions {
                command: rendiff::check::process::shell_line(std::env::args()),
                allow_failures,
                allow_scene_changes,
                drop_reason,
            };
            cli::records::bless(&run, &baseline, opts)
        }
        Command::Doctor { renderers } => {
            let renderers = cli::renderers_file(renderers)?;
            Ok(cli::exit(rendiff::doctor::run(renderers.as_deref()), 2))
        }
        Command::PeakRss { report, command } => {
            let code = rendiff::check::process::peak_rss_main(&report, &command)?;
            Ok(ExitCode::from(u8::try_from(code).unwrap_or(255)))
        }
        Command::Bench { args } => cli::records::bench(&args),
    }
}
