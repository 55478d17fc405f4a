//! The `rendiff` command line: render scenes with either visibility loop, list
//! scenes, export resolved scenes for external renderers, and diff buffers.

use anyhow::{Context, Result};
use clap::{Parser, Subcommand, ValueEnum};
use rendiff::backends::embree::EmbreeMode;
use rendiff::exr_io::{frame_attrs, write_frame_with};
use rendiff::progress::LazyProgress;
use rendiff::render::{Backend, NotRendered, RenderOptions, Rendered};
use rendiff::scene::resolve::ResolvedScene;
use rendiff::scene::Scene;
use rendiff::trace::BvhQuality;
use rendiff::{preview, trace};
use std::path::{Path, PathBuf};
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

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Renderer {
    /// Outer loop over triangles, z-buffer, tiles in parallel.
    Raster,
    /// Outer loop over pixels, BVH (obvhs), rows in parallel.
    Trace,
    /// Raster or trace, whichever the cost model expects to finish sooner
    /// (the same buffers either way; docs/benchmarks.md, "Which loop").
    Core,
    /// Embree's rtcIntersect1 per pixel center, default scene flags (visibility only).
    Embree,
    /// Embree with RTC_SCENE_FLAG_ROBUST (visibility only).
    EmbreeRobust,
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
    Render {
        /// Scene file (TOML), e.g. scenes/three_triangles.toml, or a model (.obj, .gltf, .glb).
        scene: PathBuf,
        /// Which visibility loop to use.
        #[arg(long, value_enum)]
        renderer: Renderer,
        /// Output EXR; default out/<scene>.<renderer>.exr.
        #[arg(short, long)]
        output: Option<PathBuf>,
        /// Worker threads (default: all cores; at most 4 per core).
        #[arg(long, value_parser = rendiff::args::parse_threads)]
        threads: Option<usize>,
        /// BVH build quality for the tracer.
        #[arg(long, value_parser = rendiff::args::named::<BvhQuality>(), default_value = "medium")]
        bvh: BvhQuality,
        /// How the tracer's pixel rays walk the BVH (same buffers either way).
        #[arg(long, value_parser = rendiff::args::named::<trace::TraceKernel>(), default_value = "packets")]
        kernel: trace::TraceKernel,
        /// Skip the PNG previews.
        #[arg(long)]
        no_preview: bool,
        /// Never show a progress bar.
        #[arg(long)]
        quiet: bool,
        /// Samples per pixel for path tracing (default: the scene's integrator.spp).
        #[arg(long, value_parser = rendiff::args::parse_spp)]
        spp: Option<u32>,
        /// Random seed for path tracing.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Deliberately wrong shading, for testing the statistical gate's power.
        #[arg(long, value_parser = rendiff::args::named::<rendiff::shade::Bias>(), hide = true)]
        inject_bias: Option<rendiff::shade::Bias>,
        /// Seconds before the render stops, BVH build included (1 to a week);
        /// a render stopped by it writes nothing and exits with an error.
        #[arg(long, value_parser = rendiff::args::parse_timeout)]
        timeout: Option<u64>,
    },
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
        /// Output folder (scene.json, triangles.f32, object_ids.u32).
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Run every scene on every backend and compare against the core's raster output.
    ///
    /// Backends: the core's raster (reference) and trace loops, Embree (default
    /// and robust), and the Python harness's POV-Ray, pyrender and Mitsuba 3.
    /// Writes RUN/manifest.json, the buffers, diff images and RUN/results.json.
    /// Exit 1 if any comparison fails or errors.
    Check {
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
        /// the cores; 1 runs them one after another).
        #[arg(long, value_parser = rendiff::args::parse_threads)]
        jobs: Option<usize>,
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
    },
    /// Joins shard runs (`check --shard K/N`) into one run folder, compares it
    /// once and writes its report: the verdicts one machine would give.
    Merge {
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
    },
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
    Fuzz {
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
    },
    /// Shrink a failing scene of a check run to a small standalone repro
    /// (docs/fuzzing.md): ddmin over objects, then triangles, then snapping
    /// coordinates to coarser grids, while the backend still fails the same
    /// buffer with the same class.
    Reduce {
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
    },
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

fn run(cli: Cli) -> Result<ExitCode> {
    match cli.command {
        Command::Render {
            scene,
            renderer,
            output,
            threads,
            bvh,
            kernel,
            no_preview,
            quiet,
            spp,
            seed,
            inject_bias,
            timeout,
        } => {
            let deadline =
                timeout.map(|t| std::time::Instant::now() + std::time::Duration::from_secs(t));
            // Refused before the render too, not only at the write.
            if let Some(out) = &output {
                rendiff::exr_io::check_output(out)?;
                preview::check_preview_paths(out)?;
            }
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads.unwrap_or(0))
                .build()
                .context("cannot start worker threads")?;
            let resolved = load_scene(&scene)?;
            let backend = match renderer {
                Renderer::Raster => Backend::Raster,
                Renderer::Trace => Backend::Trace,
                Renderer::Core => {
                    let (b, c) = rendiff::render::core_loop(&resolved, pool.current_num_threads());
                    let build = if rendiff::shade::needs_shading(&resolved) {
                        "not counted: shading builds it either way"
                    } else {
                        "counted in trace"
                    };
                    rendiff::outln!(
                        "core: {} (estimated raster {:.4} s, trace {:.4} s; BVH build {:.4} s, {build})",
                        b.name(),
                        c.raster_s,
                        c.trace_s,
                        c.build_s,
                    );
                    b
                }
                Renderer::Embree => Backend::Embree(EmbreeMode::Default),
                Renderer::EmbreeRobust => Backend::Embree(EmbreeMode::Robust),
            };
            let name = backend.name();
            let opts = RenderOptions {
                bvh,
                kernel,
                spp,
                seed,
                bias: inject_bias,
                deadline,
            };
            let what = match backend {
                Backend::Raster => "raster tiles",
                _ => "trace rows",
            };
            let bar = LazyProgress::new(backend.progress_total(&resolved), what, !quiet);
            let result =
                pool.install(|| rendiff::render::render(&resolved, backend, opts, &|n| bar.inc(n)));
            bar.finish();
            let Rendered { frame, radiance } = match result {
                Ok(r) => r,
                Err(NotRendered::Skipped(why)) => {
                    // The harness's convention: `check` runs this as a child.
                    rendiff::errln!("{name}: skipped: {why}");
                    return Ok(ExitCode::from(rendiff::check::isolated::EXIT_SKIPPED as u8));
                }
                Err(NotRendered::Failed(why)) => anyhow::bail!("{name}: {why}"),
            };
            if let (Some(t), true) = (timeout, rendiff::deadline::past(deadline)) {
                anyhow::bail!("{name}: timed out: stopped at --timeout {t} s; nothing written");
            }
            let out = output.unwrap_or_else(|| {
                let stem = scene
                    .file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_else(|| "scene".into());
                Path::new("out").join(format!("{stem}.{name}.exr"))
            });
            let mut attrs = frame_attrs(&frame, &scene.display().to_string());
            attrs.insert(
                "threads".to_string(),
                pool.current_num_threads().to_string(),
            );
            if let Some(r) = &radiance {
                attrs.insert("seed".to_string(), seed.to_string());
                if let Some(b) = inject_bias {
                    attrs.insert("injected_bias".to_string(), format!("{b:?}"));
                }
                rendiff::outln!(
                    "  radiance: {} ({} spp) in {:.3} s",
                    r.integrator,
                    r.spp,
                    r.seconds
                );
            }
            // Never a result beside another render's previews, nor one whose
            // previews failed: the EXR and its previews are one output.
            // One render's EXR and previews at a time in this folder: two
            // renders to one output at once mixed their files.
            let folder = out
                .parent()
                .filter(|p| !p.as_os_str().is_empty())
                .unwrap_or(Path::new("."));
            std::fs::create_dir_all(folder)
                .with_context(|| format!("{}: cannot create output folder", folder.display()))?;
            let _lock = rendiff::exr_io::lock_folder(folder)?;
            preview::remove_previews(&out)?;
            write_frame_with(&out, &frame, radiance.as_ref(), &attrs)?;
            if !no_preview {
                let written =
                    preview::write_previews(&out, &frame).and_then(|()| match &radiance {
                        Some(r) => {
                            preview::write_radiance_preview(&out, frame.width, frame.height, &r.rgb)
                        }
                        None => Ok(()),
                    });
                if let Err(e) = written {
                    let _ = std::fs::remove_file(&out);
                    let _ = preview::remove_previews(&out);
                    return Err(e);
                }
            }
            let c = &frame.counters;
            rendiff::outln!(
                "{name}: {}x{} px, {} triangles, {:.3} s -> {}",
                frame.width,
                frame.height,
                resolved.triangles.len(),
                frame.seconds,
                out.display()
            );
            if !matches!(backend, Backend::Embree(_)) {
                rendiff::outln!(
                    "  coverage tests {}, covered {}, exact fallbacks {}, ties {}, triangle setups {}, BVH nodes visited {}",
                    c.coverage_tests, c.covered, c.exact_fallbacks, c.ties, c.triangle_setups, c.bvh_nodes_visited
                );
                if c.fast_decided + c.hidden_skipped > 0 {
                    rendiff::outln!(
                        "  decided by edge functions {}, triangle-tile pairs skipped as hidden {}",
                        c.fast_decided,
                        c.hidden_skipped
                    );
                }
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Scene {
            action: SceneAction::New { model, output },
        } => {
            let mesh = rendiff::scene::model::write_model_scene(&model, &output)?;
            rendiff::outln!(
                "wrote {} (mesh = {:?})",
                rendiff::scene::printable(&output.display().to_string(), 500),
                rendiff::scene::printable(&mesh, 500)
            );
            Ok(ExitCode::SUCCESS)
        }
        Command::Scenes { dir } => {
            let mut entries: Vec<PathBuf> = std::fs::read_dir(&dir)
                .with_context(|| format!("{}: cannot list scenes", dir.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "toml"))
                .collect();
            entries.sort();
            let mut failed = false;
            for p in entries {
                match Scene::load(&p) {
                    Ok(s) => {
                        // A file's name and its description are the user's text:
                        // shown escaped, so that neither can forge a listing line
                        // or send the terminal control sequences.
                        let req: Vec<&str> = s.requires.iter().map(String::as_str).collect();
                        let name = rendiff::scene::printable(&p.display().to_string(), 200);
                        rendiff::outln!("{name:<28} requires: {}", req.join(", "));
                        if !s.file.description.is_empty() {
                            let text = rendiff::scene::printable(&s.file.description, 500);
                            rendiff::outln!("{:<28}   {text}", "");
                        }
                    }
                    Err(e) => {
                        failed = true;
                        rendiff::errln!("error: {e}");
                    }
                }
            }
            Ok(if failed {
                ExitCode::from(2)
            } else {
                ExitCode::SUCCESS
            })
        }
        Command::Export { scene, output } => {
            let resolved = load_scene(&scene)?;
            rendiff::scene::export::export(&resolved, &output)?;
            rendiff::outln!(
                "exported {} triangles to {}",
                resolved.triangles.len(),
                output.display()
            );
            Ok(ExitCode::SUCCESS)
        }
        Command::Diff { a, b } => diff(&a, &b),
        Command::Report { run } => {
            let index = rendiff::report::write(&run)?;
            rendiff::outln!("report: {}", index.display());
            Ok(ExitCode::SUCCESS)
        }
        Command::Gate { run, baseline } => {
            let (summary, passed) = rendiff::gate::gate(&baseline, &run)?;
            rendiff::out!("{summary}");
            Ok(if passed {
                ExitCode::SUCCESS
            } else {
                ExitCode::from(1)
            })
        }
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
            let b = rendiff::gate::bless(&run, &baseline, &opts)?;
            rendiff::outln!(
                "blessed {} entries from {} into {}",
                b.entries.len(),
                rendiff::scene::printable(&run.display().to_string(), 500),
                rendiff::scene::printable(&baseline.display().to_string(), 500)
            );
            Ok(ExitCode::SUCCESS)
        }
        Command::Merge {
            runs,
            output,
            expectations,
            references,
            quiet,
            verbose,
            renderers,
        } => {
            let root = rendiff::check::find_root()?;
            let expectations = match expectations {
                Some(f) => user_file(&f, "expectations")?,
                None => own_file(&root, None, "tests/expectations.toml")?,
            };
            let references = own_file(&root, references, "tests/references")?;
            let output = std::path::absolute(&output)?;
            let runs = runs
                .iter()
                .map(std::path::absolute)
                .collect::<std::io::Result<Vec<_>>>()?;
            let opts = rendiff::check::CheckOptions {
                scenes: Vec::new(),
                run_dir: output.clone(),
                root,
                only: None,
                timeout: std::time::Duration::from_secs(600),
                expectations,
                quiet,
                references: Some(references),
                core: rendiff::check::CoreShading::default(),
                calibration: None,
                jobs: rendiff::check::default_jobs(),
                workers: true,
                renderers: renderers_file(renderers)?,
                renderers_snapshot: None,
                memory_budget: rendiff::check::pool::default_memory_budget(),
            };
            let outcome = rendiff::check::shard::merge(&runs, &opts)?;
            let what = format!("merge of {} shard runs", runs.len());
            Ok(finish_run(&what, &outcome, &output, verbose))
        }
        Command::Vocab { json } => {
            let v = rendiff::vocab::json();
            if json {
                rendiff::outln!("{v}");
            } else if let Some(map) = v.as_object() {
                for (k, words) in map {
                    let list: Vec<&str> = words
                        .as_array()
                        .map(|a| a.iter().filter_map(|w| w.as_str()).collect())
                        .unwrap_or_default();
                    rendiff::outln!("{k:<20} {}", list.join(", "));
                }
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Doctor { renderers } => {
            let renderers = renderers_file(renderers)?;
            Ok(if rendiff::doctor::run(renderers.as_deref()) {
                ExitCode::SUCCESS
            } else {
                ExitCode::from(2)
            })
        }
        Command::PeakRss { report, command } => {
            let code = rendiff::check::process::peak_rss_main(&report, &command)?;
            Ok(ExitCode::from(u8::try_from(code).unwrap_or(255)))
        }
        Command::Bench { args } => bench(&args),
        Command::Fuzz {
            seed,
            count,
            minutes,
            output,
            only,
            renderers,
            jobs,
            timeout,
            expectations,
            no_calibration,
            reduce_budget,
            from,
            known,
            quiet,
        } => {
            // Checked here rather than by clap, whose refusal spans several
            // lines: the one-line error every bad input gets.
            let amount = match (count, minutes) {
                _ if !from.is_empty() && (count.is_some() || minutes.is_some()) => {
                    anyhow::bail!("fuzz: --from makes its own scenes; give no --count or --minutes")
                }
                _ if !from.is_empty() => rendiff::fuzz::Amount::Variants(from),
                (Some(n), None) => rendiff::fuzz::Amount::Count(n),
                (None, Some(m)) => rendiff::fuzz::Amount::Minutes(m),
                (Some(_), Some(_)) => {
                    anyhow::bail!("fuzz: give --count N or --minutes M, not both")
                }
                (None, None) => {
                    anyhow::bail!("fuzz: give --count N or --minutes M (or --from SCENE...)")
                }
            };
            let mut check = check_template(only, renderers, jobs, timeout, expectations)?;
            check.quiet = quiet;
            if no_calibration {
                check.calibration = None;
            }
            let folder = std::path::absolute(&output)?;
            let opts = rendiff::fuzz::FuzzOptions {
                seed,
                amount,
                folder: folder.clone(),
                check,
                reduce_budget: (reduce_budget > 0)
                    .then(|| std::time::Duration::from_secs(reduce_budget)),
                known,
            };
            let outcome = rendiff::fuzz::run(&opts)?;
            let l = &outcome.ledger;
            for f in &l.findings {
                let s = &f.signature;
                let families: Vec<String> =
                    f.families.iter().map(|(k, n)| format!("{k} {n}")).collect();
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
                        "  reduced {}{}: {} -> {} triangles, {} -> {} bytes: {}\n  reproduce: {}",
                        r.from,
                        if r.complete { "" } else { " (budget ran out)" },
                        r.triangles_before,
                        r.triangles_after,
                        r.bytes_before,
                        r.bytes_after,
                        folder.join(&r.scene).display(),
                        r.command
                    ),
                    Some(r) => rendiff::outln!("  not reduced {}: {}", r.from, r.error),
                    None => {}
                }
            }
            rendiff::outln!(
                "fuzz: seed {seed}, {} scenes, {} failing verdicts, {} findings{} -> {}",
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
            Ok(if failed {
                ExitCode::from(1)
            } else {
                ExitCode::SUCCESS
            })
        }
        Command::Reduce {
            run,
            scene,
            backend,
            buffer,
            output,
            renderers,
            expectations,
            jobs,
            timeout,
            budget,
        } => {
            let mut check = check_template(None, renderers, jobs, timeout, expectations)?;
            check.quiet = true;
            let (target, scene_file) =
                rendiff::fuzz::target_in_run(&run, &scene, &backend, buffer.as_deref())?;
            let out = output.unwrap_or_else(|| {
                // The scene name is one plain folder name in a run (docs/run-format.md).
                PathBuf::from("reduced").join(format!("{scene}.{backend}.toml"))
            });
            let out = std::path::absolute(&out)?;
            let work = out.with_extension("work");
            let r = rendiff::fuzz::reduce_file(
                &scene_file,
                &target,
                &check,
                &work,
                budget.map(std::time::Duration::from_secs),
                &out,
            )?;
            rendiff::outln!(
                "{} fails {} with class {}: {} -> {} triangles, {} -> {} objects, {} -> {} bytes ({} check runs, {} candidates{})",
                target.backend,
                target.buffer,
                target.class,
                r.triangles_before,
                r.triangles_after,
                r.objects_before,
                r.objects_after,
                r.bytes_before,
                r.bytes_after,
                r.check_runs,
                r.candidates,
                if r.complete { "" } else { "; budget ran out" }
            );
            rendiff::outln!("reduced: {}", out.display());
            rendiff::outln!("reproduce: {}", r.command);
            Ok(ExitCode::SUCCESS)
        }
        Command::Check {
            scenes,
            output,
            only,
            timeout,
            expectations,
            quiet,
            verbose,
            references,
            seed,
            spp,
            inject_bias,
            calibration,
            no_calibration,
            shard,
            shard_costs,
            jobs,
            renderers,
            no_workers,
            memory_budget,
        } => {
            let jobs = jobs.unwrap_or_else(rendiff::check::default_jobs);
            // rendiff's own files come from its checkout, wherever this runs;
            // the harness runs there, so every path it gets is absolute.
            let root = rendiff::check::find_root()?;
            let expectations = match expectations {
                Some(f) => user_file(&f, "expectations")?,
                None => own_file(&root, None, "tests/expectations.toml")?,
            };
            let references = own_file(&root, references, "tests/references")?;
            let calibration = own_file(&root, calibration, "scenes/calibration")?;
            let output = std::path::absolute(&output)?;
            let scenes = if scenes.is_empty() {
                vec![
                    rendiff::check::in_root(&root, "scenes"),
                    rendiff::check::in_root(&root, "scenes/corpus"),
                ]
            } else {
                scenes
            };
            let mut scenes = rendiff::check::collect_scenes(&scenes)?;
            let mut split = None;
            if let Some(shard) = shard {
                use rendiff::check::shard;
                let costs = match &shard_costs {
                    Some(run) => shard::recorded_costs(run, true)?,
                    None => shard::recorded_costs(&output, false)?,
                };
                let all = scenes.len();
                split = Some(shard::deal(&scenes, shard, &costs)?);
                scenes = shard::select(&scenes, shard, &costs);
                rendiff::errln!(
                    "shard {}/{}: {} of {all} scenes",
                    shard.index,
                    shard.total,
                    scenes.len()
                );
                if scenes.is_empty() {
                    anyhow::bail!(
                        "shard {}/{} has no scenes ({all} scenes for {} shards): use fewer shards",
                        shard.index,
                        shard.total,
                        shard.total
                    );
                }
            }
            let opts = rendiff::check::CheckOptions {
                scenes,
                run_dir: output.clone(),
                root,
                only,
                timeout: std::time::Duration::from_secs(timeout),
                expectations,
                quiet,
                references: Some(references),
                core: rendiff::check::CoreShading {
                    seed,
                    spp,
                    bias: inject_bias,
                },
                calibration: (!no_calibration).then_some(calibration),
                jobs,
                workers: !no_workers,
                renderers: renderers_file(renderers)?,
                renderers_snapshot: None,
                memory_budget: memory_budget
                    .map_or_else(rendiff::check::pool::default_memory_budget, |mib| mib << 20),
            };
            // On failure the run folder keeps its INCOMPLETE marker: no report.
            let outcome = match split {
                Some(record) => rendiff::check::run_shard(&opts, record)?,
                None => rendiff::check::run(&opts)?,
            };
            Ok(finish_run("check", &outcome, &output, verbose))
        }
    }
}

/// The check settings `fuzz` and `reduce` run with: `check`'s defaults
/// (rendiff's expectations, references and calibration probes, all cores)
/// and the options they share with it; scenes and run folder are theirs to set.
fn check_template(
    only: Option<Vec<String>>,
    renderers: Option<PathBuf>,
    jobs: Option<usize>,
    timeout: u64,
    expectations: Option<PathBuf>,
) -> Result<rendiff::check::CheckOptions> {
    let root = rendiff::check::find_root()?;
    let expectations = match expectations {
        Some(f) => user_file(&f, "expectations")?,
        None => own_file(&root, None, "tests/expectations.toml")?,
    };
    let references = own_file(&root, None, "tests/references")?;
    let calibration = own_file(&root, None, "scenes/calibration")?;
    Ok(rendiff::check::CheckOptions {
        scenes: Vec::new(),
        run_dir: PathBuf::new(),
        root,
        only,
        timeout: std::time::Duration::from_secs(timeout),
        expectations,
        quiet: false,
        references: Some(references),
        core: rendiff::check::CoreShading::default(),
        calibration: Some(calibration),
        jobs: jobs.unwrap_or_else(rendiff::check::default_jobs),
        workers: true,
        renderers: renderers_file(renderers)?,
        renderers_snapshot: None,
        memory_budget: rendiff::check::pool::default_memory_budget(),
    })
}

/// `rendiff bench ...`: the benchmarks are a workspace member of their own
/// (crates/rendiff-bench), run as the `rendiff-bench` binary found beside
/// this one; its exit status is passed on.
fn bench(args: &[std::ffi::OsString]) -> Result<ExitCode> {
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

/// The `--renderers` file, made absolute and checked to exist here, so that
/// a typo is one clear line and the harness (which runs in rendiff's
/// checkout) finds it.
fn renderers_file(file: Option<PathBuf>) -> Result<Option<PathBuf>> {
    file.map(|f| user_file(&f, "renderers")).transpose()
}

/// A file the user names for the harness to read (`--renderers`,
/// `--expectations`), absolute, checked here to exist and to be a regular
/// file (the harness reads it later, after the renders: a typo or a device
/// is one line before anything runs).
fn user_file(file: &Path, what: &str) -> Result<PathBuf> {
    let abs = std::path::absolute(file)?;
    if !abs.exists() {
        anyhow::bail!("{}: {what} file not found", file.display());
    }
    if !abs.is_file() {
        anyhow::bail!("{}: the {what} file is not a regular file", file.display());
    }
    Ok(abs)
}

/// One of rendiff's own files: as the user gave it, else `rel` in its
/// checkout ([`rendiff::check::in_root`]); absolute, because the harness runs
/// in the checkout, not in the user's folder.
fn own_file(root: &Path, given: Option<PathBuf>, rel: &str) -> Result<PathBuf> {
    Ok(std::path::absolute(
        given.unwrap_or_else(|| rendiff::check::in_root(root, rel)),
    )?)
}

/// The end of `check` and `merge`: the verdict table, the tally, the report;
/// exit 1 when any verdict fails.
fn finish_run(
    what: &str,
    outcome: &rendiff::check::CheckOutcome,
    output: &Path,
    verbose: bool,
) -> ExitCode {
    let tally = rendiff::check::tally(&outcome.results);
    let verdicts = &outcome.results.results;
    let failing = verdicts.iter().filter(|e| e.is_failure()).count();
    let table = rendiff::check::table::shown(&outcome.table, verdicts.len(), failing, verbose);
    // The table quotes scene names: control characters escaped.
    rendiff::out!("{}", rendiff::check::process::printable_lines(&table));
    rendiff::outln!(
        "{what}: {} ok, {} failing, {} skipped -> {}",
        tally.ok,
        tally.failed,
        tally.skipped,
        rendiff::scene::printable(&output.join("results.json").display().to_string(), 500)
    );
    write_report(output);
    if tally.failed > 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    }
}

/// Every check run gets its report; a report problem is a warning, never a changed verdict.
fn write_report(run: &Path) {
    match rendiff::report::write(run) {
        Ok(index) => rendiff::outln!("report: {}", index.display()),
        Err(e) => rendiff::errln!("warning: report not written: {e:#}"),
    }
}

fn load_scene(path: &Path) -> Result<ResolvedScene> {
    let scene = Scene::load(path)?;
    let resolved = ResolvedScene::resolve(&scene)?;
    for w in &resolved.warnings {
        rendiff::errln!("warning: {w}");
    }
    Ok(resolved)
}

/// `rendiff diff`: one line per buffer present in either file (src/diff.rs);
/// exit 1 on any difference, 0 when identical, 2 (an error) when the files
/// share no buffer.
fn diff(a: &Path, b: &Path) -> Result<ExitCode> {
    let d = rendiff::diff::diff_files(a, b)?;
    for line in d.lines(&a.display().to_string(), &b.display().to_string()) {
        rendiff::outln!("{line}");
    }
    Ok(if d.differs() {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    })
}
