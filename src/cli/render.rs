//! `rendiff render`: one scene through one of the core's loops or Embree,
//! to an EXR and its PNG previews.

use super::load_scene;
use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use rendiff::backends::embree::EmbreeMode;
use rendiff::exr_io::{frame_attrs, write_frame_with};
use rendiff::frame::Frame;
use rendiff::progress::LazyProgress;
use rendiff::render::{Backend, NotRendered, RenderOptions, Rendered};
use rendiff::scene::resolve::ResolvedScene;
use rendiff::trace::BvhQuality;
use rendiff::{preview, trace};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// The loops `render --renderer` offers.
#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Renderer {
    /// Outer loop over triangles, z-buffer, tiles in parallel.
    Raster,
    /// Outer loop over pixels, BVH (see --bvh), rows in parallel.
    Trace,
    /// Raster or trace, whichever the cost model expects to finish sooner
    /// (the same buffers either way; docs/benchmarks.md, "Which loop").
    Core,
    /// Embree's rtcIntersect1 per pixel center, default scene flags (visibility only).
    Embree,
    /// Embree with RTC_SCENE_FLAG_ROBUST (visibility only).
    EmbreeRobust,
}

// `rendiff render`'s options. (No doc comment: clap would take it for the
// subcommand's help, which is the variant's in main.rs.)
#[derive(Args)]
pub struct RenderArgs {
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
    /// BVH build quality for the tracer (default: the least build + trace
    /// for one frame, measured in docs/benchmarks.md).
    #[arg(long, value_parser = rendiff::args::named::<BvhQuality>(), default_value = "linear")]
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
}

/// `rendiff render`.
pub fn run(a: RenderArgs) -> Result<ExitCode> {
    let deadline = a
        .timeout
        .map(|t| std::time::Instant::now() + std::time::Duration::from_secs(t));
    // Refused before the render too, not only at the write.
    if let Some(out) = &a.output {
        rendiff::exr_io::check_output(out)?;
        preview::check_preview_paths(out)?;
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()
        .context("cannot start worker threads")?;
    let resolved = load_scene(&a.scene)?;
    let backend = backend(a.renderer, &resolved, pool.current_num_threads());
    let name = backend.name();
    let opts = RenderOptions {
        bvh: a.bvh,
        kernel: a.kernel,
        spp: a.spp,
        seed: a.seed,
        bias: a.inject_bias,
        deadline,
    };
    let what = match backend {
        Backend::Raster => "raster tiles",
        _ => "trace rows",
    };
    let bar = LazyProgress::new(backend.progress_total(&resolved), what, !a.quiet);
    let result =
        pool.install(|| rendiff::render::render(&resolved, backend, opts, &|n| bar.inc(n)));
    bar.finish();
    let rendered = match result {
        Ok(r) => r,
        Err(NotRendered::Skipped(why)) => {
            // The harness's convention: `check` runs this as a child.
            rendiff::errln!("{name}: skipped: {why}");
            return Ok(ExitCode::from(rendiff::check::isolated::EXIT_SKIPPED as u8));
        }
        Err(NotRendered::Failed(why)) => anyhow::bail!("{name}: {why}"),
    };
    if let (Some(t), true) = (a.timeout, rendiff::deadline::past(deadline)) {
        anyhow::bail!("{name}: timed out: stopped at --timeout {t} s; nothing written");
    }
    let out = a.output.clone().unwrap_or_else(|| {
        let stem = a
            .scene
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scene".into());
        Path::new("out").join(format!("{stem}.{name}.exr"))
    });
    write(&a, &rendered, &out, pool.current_num_threads())?;
    summary(backend, &rendered.frame, &resolved, &out);
    Ok(ExitCode::SUCCESS)
}

/// The backend `--renderer` names; for `core`, the cost model's pick, said
/// with its estimates.
fn backend(renderer: Renderer, resolved: &ResolvedScene, threads: usize) -> Backend {
    match renderer {
        Renderer::Raster => Backend::Raster,
        Renderer::Trace => Backend::Trace,
        Renderer::Core => {
            let (b, c) = rendiff::render::core_loop(resolved, threads);
            let build = if rendiff::shade::needs_shading(resolved) {
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
    }
}

/// Writes the EXR (with its attributes) and, unless `--no-preview`, its PNG
/// previews: never a result beside another render's previews, nor one whose
/// previews failed, since the EXR and its previews are one output. One
/// render's EXR and previews at a time in this folder: two renders to one
/// output at once mixed their files.
fn write(a: &RenderArgs, rendered: &Rendered, out: &Path, threads: usize) -> Result<()> {
    let Rendered { frame, radiance } = rendered;
    let mut attrs = frame_attrs(frame, &a.scene.display().to_string());
    attrs.insert("threads".to_string(), threads.to_string());
    if let Some(r) = radiance {
        attrs.insert("seed".to_string(), a.seed.to_string());
        if let Some(b) = a.inject_bias {
            attrs.insert("injected_bias".to_string(), format!("{b:?}"));
        }
        rendiff::outln!(
            "  radiance: {} ({} spp) in {:.3} s",
            r.integrator,
            r.spp,
            r.seconds
        );
    }
    let folder = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(folder)
        .with_context(|| format!("{}: cannot create output folder", folder.display()))?;
    let _lock = rendiff::exr_io::lock_folder(folder)?;
    preview::remove_previews(out)?;
    write_frame_with(out, frame, radiance.as_ref(), &attrs)?;
    if !a.no_preview {
        let written = preview::write_previews(out, frame).and_then(|()| match radiance {
            Some(r) => preview::write_radiance_preview(out, frame.width, frame.height, &r.rgb),
            None => Ok(()),
        });
        if let Err(e) = written {
            let _ = std::fs::remove_file(out);
            let _ = preview::remove_previews(out);
            return Err(e);
        }
    }
    Ok(())
}

/// The closing lines: size, time and output; the core loops' counters.
fn summary(backend: Backend, frame: &Frame, resolved: &ResolvedScene, out: &Path) {
    let c = &frame.counters;
    rendiff::outln!(
        "{}: {}x{} px, {} triangles, {:.3} s -> {}",
        backend.name(),
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
}
