//! `rendiff-wgpu --scene DIR --out OUT.exr`: renders a resolved scene's depth
//! and IDs with wgpu, for rendiff's command-renderer protocol
//! (renderers/wgpu.toml).
//!
//! Exit status: 0 written; 3 skipped (no Vulkan adapter: one line
//! "no Vulkan adapter: <reason>" on stderr); 1 any other failure (one line
//! naming the file and the problem; bad input, including special files such
//! as FIFOs and devices, is refused before any adapter is looked for). Never
//! a panic, never a hang on an input. Interrupted (SIGINT, SIGTERM, SIGHUP),
//! it removes its temporary files and folders and dies by that signal.

use clap::Parser;
use rendiff_wgpu::gpu::{self, RenderError};
use rendiff_wgpu::{camera, output, pending, precision, scene};
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;

/// Command line.
#[derive(Parser, Debug)]
#[command(
    name = "rendiff-wgpu",
    version = concat!(env!("CARGO_PKG_VERSION"), " (wgpu 30, Vulkan)"),
    about = "Render a rendiff resolved scene's depth and IDs with wgpu (Vulkan)"
)]
struct Args {
    /// Resolved scene folder (scene.json, triangles.f32, object_ids.u32), from `rendiff export`.
    #[arg(long)]
    scene: PathBuf,
    /// Output OpenEXR (Z, id.prim, id.object).
    #[arg(long)]
    out: PathBuf,
    /// Draw at most this many triangles per draw call (testing the split draws).
    #[arg(long, hide = true)]
    chunk_triangles: Option<usize>,
    /// Wait this many milliseconds (at most 60,000) before reading the scene (testing the clean-up on signals).
    #[arg(long, hide = true)]
    pause_ms: Option<u64>,
}

/// Exit status for "skipped" in rendiff's command protocol.
const EXIT_SKIPPED: u8 = 3;

fn run(args: &Args) -> Result<(), RenderError> {
    let t0 = std::time::Instant::now();
    // Bad input is refused before the (slow) adapter selection.
    output::check_output(&args.out)?;
    let scene = scene::load(&args.scene)?;
    // GPU failures name the scene folder they were rendering.
    let buffers = gpu::render(&scene, args.chunk_triangles).map_err(|e| match e {
        RenderError::Failed(e) => RenderError::Failed(e.context(args.scene.display().to_string())),
        other => other,
    })?;
    let view = camera::View::from_json(&scene.camera);
    let edge = precision::edge_px(&view, buffers.adapter.subpixel_bits);
    if edge > precision::EDGE_PX {
        eprintln!(
            "rendiff-wgpu: warning: this camera/adapter's edge distance {edge:.3e} px exceeds the declared {} px",
            precision::EDGE_PX
        );
    }
    let mut attrs = BTreeMap::new();
    attrs.insert("renderer".to_string(), "wgpu".to_string());
    attrs.insert("scene".to_string(), scene.name.clone());
    attrs.insert("adapter".to_string(), buffers.adapter.description.clone());
    attrs.insert(
        "sub_pixel_bits".to_string(),
        format!(
            "{}{}",
            buffers.adapter.subpixel_bits,
            if buffers.adapter.subpixel_bits_queried {
                ""
            } else {
                " (assumed)"
            }
        ),
    );
    attrs.insert("edge_px".to_string(), format!("{edge:e}"));
    attrs.insert(
        "depth_relative".to_string(),
        format!("{:e}", precision::DEPTH_RELATIVE),
    );
    attrs.insert("gpu_seconds".to_string(), format!("{:.6}", buffers.seconds));
    attrs.insert(
        "seconds".to_string(),
        format!("{:.6}", t0.elapsed().as_secs_f64()),
    );
    output::write_exr(&args.out, &buffers, &attrs)?;
    Ok(())
}

/// Mesa's Vulkan WSI prints "error: XDG_RUNTIME_DIR is invalid or not set"
/// for every instance when that variable is unset (as under CI and rendiff's
/// runner), which would break the one-line stderr protocol. Point it at a
/// fresh private folder for this process only; removed on drop, or by the
/// signal handler ([`pending`]) if the process is interrupted.
struct QuietWsi(Option<(PathBuf, pending::PathGuard)>);

impl QuietWsi {
    fn new() -> QuietWsi {
        let valid = std::env::var_os("XDG_RUNTIME_DIR")
            .map(PathBuf::from)
            .is_some_and(|d| d.is_absolute() && d.is_dir());
        if valid {
            return QuietWsi(None);
        }
        let dir = std::env::temp_dir().join(format!("rendiff-wgpu-xdg-{}", std::process::id()));
        #[cfg(unix)]
        let made = {
            use std::os::unix::fs::DirBuilderExt;
            std::fs::DirBuilder::new().mode(0o700).create(&dir).is_ok()
        };
        #[cfg(not(unix))]
        let made = std::fs::create_dir(&dir).is_ok();
        if !made {
            return QuietWsi(None);
        }
        // Registered once made (never someone else's folder of this name); a
        // signal arriving in between waits for the watcher, started later.
        let guard = pending::track_path(&dir);
        // Edition 2021: safe; nothing else runs yet (no threads started).
        std::env::set_var("XDG_RUNTIME_DIR", &dir);
        QuietWsi(Some((dir, guard)))
    }
}

impl Drop for QuietWsi {
    fn drop(&mut self) {
        if let Some((dir, _guard)) = &self.0 {
            let _ = std::fs::remove_dir_all(dir);
        }
    }
}

fn main() -> ExitCode {
    let args = Args::parse();
    // Hooked before the folder exists, watched once the environment is set
    // (set_var must come before any thread starts). A failure to hook leaves
    // the default behaviour, which is no reason to refuse the render.
    let signals = pending::Signals::hook();
    let _wsi = QuietWsi::new();
    if let Ok(signals) = signals {
        let _ = signals.watch();
    }
    if let Some(ms) = args.pause_ms {
        std::thread::sleep(std::time::Duration::from_millis(ms.min(60_000)));
    }
    // wgpu and the driver may panic on conditions they consider bugs; report
    // them as one line and exit 1, never with a backtrace.
    std::panic::set_hook(Box::new(|_| {}));
    let outcome = std::panic::catch_unwind(|| run(&args));
    match outcome {
        Ok(Ok(())) => ExitCode::SUCCESS,
        Ok(Err(RenderError::NoAdapter(reason))) => {
            eprintln!("no Vulkan adapter: {reason}");
            ExitCode::from(EXIT_SKIPPED)
        }
        Ok(Err(RenderError::Failed(e))) => {
            eprintln!("rendiff-wgpu: {}", gpu::one_line(&format!("{e:#}")));
            ExitCode::FAILURE
        }
        Err(panic) => {
            let msg = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "unknown panic".into());
            eprintln!(
                "rendiff-wgpu: {}: internal error: {}",
                args.scene.display(),
                gpu::one_line(&msg)
            );
            ExitCode::FAILURE
        }
    }
}
