//! One external render through the harness (`python -m rendiff_harness
//! render`), split by job: whether it can run at all, its arguments, the
//! command the report records to reproduce it, running it (on a worker, in a
//! process of its own, or measured), reading its outcome into the record, and
//! refusing a render that changed its input.

use super::home::{self, python};
use super::manifest::{RenderRecord, SceneRuns};
use super::process::{self, run_with_timeout, shell_line, Outcome};
use super::{
    harness_command, inputs, isolated, repro_out, visibility_only, worker, Capability,
    CheckOptions, HarnessBackend, RENDERERS_ENV,
};
use crate::vocab::RenderStatus;
use anyhow::Result;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// What a loaded scene's external renders need.
pub(super) struct ExternalScene {
    /// `RUN/scenes/<stem>`: holds `resolved/` and receives the EXRs.
    pub(super) dir: PathBuf,
    /// The same, relative to the run folder.
    pub(super) rel_dir: String,
    /// Triangles of the resolved scene, for the pool's estimates.
    pub(super) triangles: u64,
    /// What `dir/resolved` held when exported: each render's copy is
    /// checked against it (inputs.rs).
    pub(super) seal: inputs::Seal,
}

/// One external render through the harness: on `slot`'s long-lived worker
/// when there is one, else in a process of its own (measured under
/// `measure`, the rendiff binary, in a measuring run).
pub(super) fn external(
    opts: &CheckOptions,
    b: &HarnessBackend,
    runs: &SceneRuns,
    scene: &ExternalScene,
    scratch: &Path,
    measure: Option<&Path>,
    slot: Option<&mut worker::Slot>,
) -> RenderRecord {
    let mut rec = RenderRecord {
        backend: b.name.clone(),
        version: b.version.clone().unwrap_or_default(),
        buffers: b.buffers.clone(),
        ..RenderRecord::default()
    };
    let features: Vec<&str> = b.features.iter().map(String::as_str).collect();
    let capability = Capability::of(&runs.requires, &features);
    if let Some(refused) = refusal(b, &capability) {
        refused.apply(&mut rec);
        return rec;
    }
    let rel_exr = format!("{}/{}.exr", scene.rel_dir, b.name);
    let exr = opts.run_dir.join(&rel_exr);
    let resolved = scene.dir.join("resolved");
    let mut args = render_args(opts, b, &resolved, &exr, &capability);
    rec.command = recorded_command(opts, &args, &rel_exr);
    // The render reads a copy of its own (inputs.rs); the record names the
    // run's resolved scene, which the copy equals.
    let input = scratch
        .join("inputs")
        .join(format!("{}-{}", runs.scene, b.name));
    if let Err(e) = inputs::private_copy(&resolved, &input) {
        rec.status = RenderStatus::Error;
        rec.message = format!("cannot copy the resolved scene for the render: {e:#}");
        let _ = std::fs::remove_dir_all(&input);
        return rec;
    }
    let scene_arg = args
        .iter()
        .position(|a| a == "--scene")
        .expect("the arguments name the scene")
        + 1;
    args[scene_arg] = input.display().to_string();
    // The harness enforces the timeout on its own subprocesses; this one also
    // covers in-process renderers (pyrender, Mitsuba) that hang.
    let limit = opts.timeout + opts.timeout.min(Duration::from_secs(30));
    let work = scratch.join(format!("{}-{}", runs.scene, b.name));
    let outcome = run_render(opts, b, &args, limit, &work, measure, slot);
    read_outcome(&mut rec, outcome, b, opts.timeout, limit, &exr, rel_exr);
    // A render that changed its input is judged on nothing it wrote.
    let tampered = match inputs::Seal::of(&input) {
        Ok(now) => scene.seal.changes(&now),
        Err(e) => Some(format!("{e:#}")),
    };
    let _ = std::fs::remove_dir_all(&input);
    if let Some(what) = tampered {
        rec.status = RenderStatus::Error;
        rec.reason.clear();
        rec.message = format!(
            "{} changed its input, the resolved scene {{scene}}, during the render ({what}); a renderer may only read it: its buffers are not judged (every render reads a copy of its own: no other verdict is affected)",
            b.name
        );
    }
    if let Capability::VisibilityOnly(m) = &capability {
        visibility_only(&mut rec, m);
    }
    // Never take a partial output for a result.
    if rec.status != RenderStatus::Ok {
        let _ = std::fs::remove_file(&exr);
    }
    rec
}

/// Why a render is not attempted: the scene needs features the backend
/// lacks, or the backend is unavailable on this machine.
enum Refusal {
    /// Skipped, with the reason.
    Skipped(String),
    /// An error, with the message.
    Unavailable(String),
}

impl Refusal {
    /// Writes the refusal into the record.
    fn apply(self, rec: &mut RenderRecord) {
        match self {
            Refusal::Skipped(reason) => {
                rec.status = RenderStatus::Skipped;
                rec.reason = reason;
            }
            Refusal::Unavailable(message) => {
                rec.status = RenderStatus::Error;
                rec.message = message;
            }
        }
    }
}

/// The refusal, if the render cannot be attempted.
fn refusal(b: &HarnessBackend, capability: &Capability) -> Option<Refusal> {
    if let Capability::Skip(miss) = capability {
        return Some(Refusal::Skipped(format!(
            "missing features: {}",
            miss.join(", ")
        )));
    }
    (!b.available).then(|| {
        Refusal::Unavailable(format!(
            "{} unavailable: {}",
            b.name,
            b.reason.clone().unwrap_or_default()
        ))
    })
}

/// The harness's `render` arguments for this backend, scene and output.
fn render_args(
    opts: &CheckOptions,
    b: &HarnessBackend,
    resolved: &Path,
    exr: &Path,
    capability: &Capability,
) -> Vec<String> {
    let secs = opts.timeout.as_secs_f64();
    let mut args: Vec<String> = vec![
        "render".into(),
        "--backend".into(),
        b.name.clone(),
        "--scene".into(),
        resolved.display().to_string(),
        "--out".into(),
        exr.display().to_string(),
        "--timeout".into(),
        format!("{secs}"),
    ];
    if let Capability::VisibilityOnly(_) = capability {
        // Z and IDs without RGB; a backend that cannot do that answers "skipped".
        args.push("--visibility-only".into());
    }
    if let Some(v) = &b.version {
        // The harness asked the renderer once (`info --json`): each render
        // takes that answer, so a version command runs once per run, and a
        // hanging one costs its timeout once. One token, so a version that
        // starts with '-' is not read as an option.
        args.push(format!("--known-version={v}"));
    }
    args
}

/// The shell command the report records to reproduce the render: every word
/// quoted, writing beside the run, not over it (the harness writes only into
/// a folder that exists, so it makes that folder first).
fn recorded_command(opts: &CheckOptions, args: &[String], rel_exr: &str) -> String {
    let mut words = vec![
        python(&opts.root).display().to_string(),
        "-m".into(),
        "rendiff_harness".into(),
    ];
    words.extend(args.iter().cloned());
    let repro = repro_out(&opts.run_dir, rel_exr);
    if let Some(i) = words.iter().position(|w| w == "--out") {
        if let Some(out) = words.get_mut(i + 1) {
            *out = repro.display().to_string();
        }
    }
    let mkdir = repro.parent().map_or(String::new(), |d| {
        format!(
            "{} && ",
            shell_line(["mkdir", "-p", &d.display().to_string()])
        )
    });
    let declared = opts.renderers.as_ref().map_or(String::new(), |f| {
        format!(
            "{RENDERERS_ENV}={} ",
            process::shell_quote(&f.display().to_string())
        )
    });
    format!(
        "{mkdir}{declared}{}{}",
        home::harness_path_words(&opts.root),
        shell_line(&words)
    )
}

/// Runs the render within `limit`: measured under `measure` in a measuring
/// run, else on `slot`'s long-lived worker, else in a process of its own.
fn run_render(
    opts: &CheckOptions,
    b: &HarnessBackend,
    args: &[String],
    limit: Duration,
    work: &Path,
    measure: Option<&Path>,
    slot: Option<&mut worker::Slot>,
) -> Result<Outcome> {
    let mut cmd = harness_command(opts);
    cmd.args(args);
    match (measure, slot) {
        (Some(helper), _) => process::run_measured(cmd, limit, work, helper),
        (None, Some(slot)) => {
            let serve = || {
                let mut c = harness_command(opts);
                c.arg("serve");
                c
            };
            slot.request(&b.name, serve, args, limit)
        }
        (None, None) => run_with_timeout(cmd, limit, work),
    }
}

/// Reads the render's outcome into the record: ok only with its buffer
/// file written, skipped with the harness's reason, else an error saying
/// how it ended (`timeout` is the render's own limit, `limit` that plus the
/// harness's start-up).
fn read_outcome(
    rec: &mut RenderRecord,
    outcome: Result<Outcome>,
    b: &HarnessBackend,
    timeout: Duration,
    limit: Duration,
    exr: &Path,
    rel_exr: String,
) {
    let o = match outcome {
        Err(e) => {
            rec.status = RenderStatus::Error;
            rec.message = format!("{e:#}");
            return;
        }
        Ok(o) => o,
    };
    rec.time_s = o.seconds;
    rec.max_rss_bytes = o.max_rss_bytes;
    if o.timed_out {
        rec.status = RenderStatus::Error;
        rec.message = format!(
            "timed out and was killed after {:.0} s (--timeout {} s for the render, plus {:.0} s for the harness's own start-up)",
            limit.as_secs_f64(),
            timeout.as_secs_f64(),
            (limit - timeout).as_secs_f64()
        );
    } else if o.code == Some(0) {
        if exr.exists() {
            rec.status = RenderStatus::Ok;
            rec.exr = rel_exr;
            let last = o
                .stdout
                .lines()
                .rev()
                .find(|l| l.trim_start().starts_with('{'));
            if let Some(v) = last.and_then(|l| serde_json::from_str::<serde_json::Value>(l).ok()) {
                if let Some(ver) = v.get("version").and_then(|x| x.as_str()) {
                    rec.version = ver.to_string();
                }
                rec.info = v.get("info").cloned().unwrap_or_default();
            }
        } else {
            rec.status = RenderStatus::Error;
            rec.message = "reported success but wrote no buffer file".into();
        }
    } else if o.code == Some(isolated::EXIT_SKIPPED) {
        rec.status = RenderStatus::Skipped;
        rec.reason = o.stderr_tail(3);
        if rec.reason.is_empty() {
            // The harness's skip line: {"status": "skipped", "reason": ...}.
            rec.reason = o
                .stdout
                .lines()
                .rev()
                .find_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
                .and_then(|v| v.get("reason")?.as_str().map(String::from))
                .unwrap_or_else(|| o.stdout.trim().to_string());
        }
    } else {
        rec.status = RenderStatus::Error;
        rec.message = format!("{} failed ({}): {}", b.name, o.how(), o.stderr_tail(6));
    }
}
