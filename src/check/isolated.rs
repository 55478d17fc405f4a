//! The core loops and Embree rendered in a child process (`rendiff render`),
//! for runs that measure memory: a render in process shares its peak with the
//! whole check, a child's peak (`wait4`'s `ru_maxrss`) is that renderer's own.

use super::manifest::RenderRecord;
use super::process::{run_measured, shell_line};
use super::CheckOptions;
use crate::exr_io::read_buffers;
use crate::vocab::RenderStatus;
use std::path::Path;
use std::process::Command;

/// Exit code of `rendiff render` when the renderer is unavailable or cannot
/// model the scene: the render is skipped, not failed (one home: `vocab`).
pub use crate::vocab::EXIT_SKIPPED;

/// One render to run in a child.
pub struct Job<'a> {
    /// The rendiff binary.
    pub bin: &'a Path,
    /// Backend name as check names it (raster, trace, embree, embree_robust).
    pub backend: &'a str,
    /// Scene file.
    pub scene: &'a Path,
    /// Output EXR.
    pub exr: &'a Path,
    /// Output EXR relative to the run folder (for the manifest).
    pub rel_exr: &'a str,
    /// Scratch folder for captured output.
    pub scratch: &'a Path,
}

/// The `--renderer` value of `rendiff render` for a check backend name.
pub fn renderer_arg(backend: &str) -> String {
    backend.replace('_', "-")
}

/// Runs `rendiff render SCENE --renderer NAME -o EXR` with the check's timeout
/// and turns its outcome into the manifest record, peak memory included.
pub fn render(opts: &CheckOptions, job: &Job, version: String) -> RenderRecord {
    let scene = job.scene.display().to_string();
    let exr = job.exr.display().to_string();
    let renderer = renderer_arg(job.backend);
    let args = [
        "render",
        scene.as_str(),
        "--renderer",
        renderer.as_str(),
        "-o",
        exr.as_str(),
        "--no-preview",
        "--quiet",
    ];
    let mut rec = RenderRecord {
        backend: job.backend.into(),
        version,
        command: shell_line(
            std::iter::once(job.bin.display().to_string()).chain(args.map(String::from)),
        ),
        ..RenderRecord::default()
    };
    let mut cmd = Command::new(job.bin);
    cmd.args(args);
    let work = job
        .scratch
        .join(format!("{}-{}", super::stem(job.scene), job.backend));
    match run_measured(cmd, opts.timeout, &work, job.bin) {
        Err(e) => {
            rec.status = RenderStatus::Error;
            rec.message = format!("{e:#}");
        }
        Ok(o) if o.timed_out => {
            rec.status = RenderStatus::Error;
            rec.message = format!(
                "timed out after {:.0} s and was killed",
                opts.timeout.as_secs_f64()
            );
            rec.time_s = o.seconds;
        }
        Ok(o) => {
            rec.time_s = o.seconds;
            rec.max_rss_bytes = o.max_rss_bytes;
            match o.code {
                Some(0) => match read_buffers(job.exr) {
                    Ok(b) => {
                        rec.status = RenderStatus::Ok;
                        rec.exr = job.rel_exr.into();
                        rec.buffers = vec!["Z".into(), "id".into(), "N".into()];
                        let secs = b.attrs.get("seconds").and_then(|s| s.parse::<f64>().ok());
                        rec.info = serde_json::json!({
                            "render_seconds": secs,
                            "counters": b.attrs.get("counters")
                                .and_then(|c| serde_json::from_str::<serde_json::Value>(c).ok()),
                            "isolated": true,
                        });
                    }
                    Err(e) => {
                        rec.status = RenderStatus::Error;
                        rec.message =
                            format!("reported success but its buffers are unreadable: {e:#}");
                    }
                },
                Some(EXIT_SKIPPED) => {
                    rec.status = RenderStatus::Skipped;
                    rec.reason = o.stderr_tail(2);
                }
                _ => {
                    rec.status = RenderStatus::Error;
                    rec.message =
                        format!("{} failed ({}): {}", job.backend, o.how(), o.stderr_tail(6));
                }
            }
        }
    }
    if rec.status != RenderStatus::Ok {
        let _ = std::fs::remove_file(job.exr);
    }
    rec
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_names_map_to_render_flags() {
        assert_eq!(renderer_arg("embree_robust"), "embree-robust");
        assert_eq!(renderer_arg("raster"), "raster");
    }
}
