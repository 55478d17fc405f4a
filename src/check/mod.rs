//! `rendiff check`: every scene on every backend, then the comparison.
//!
//! Core loops and Embree render in process; Python and CLI renderers run as
//! subprocesses of the harness (`python -m rendiff_harness render`), each with
//! a timeout, so one crashing or hanging renderer is reported as an error and
//! the others still run. The Python side then compares every buffer with the
//! reference (OpenImageIO + numpy) and writes results.json.
//!
//! Capabilities are judged per buffer ([`Capability`]): a backend lacking only
//! shading features renders its depth and ID buffers without RGB. The camera
//! calibration probes (`CheckOptions::calibration`) run first, as scenes with
//! `role: "calibration"`.

pub mod home;
pub mod inputs;
pub mod isolated;
use crate::vocab::{Feature, RenderStatus, Status};
mod external;
pub mod manifest;
pub mod pool;
pub mod process;
mod render_run;
pub mod run_folder;
pub mod shard;
mod streamed;
pub mod table;
pub mod worker;

use crate::backends::embree::EmbreeMode;
use crate::exr_io::{frame_attrs, write_frame_with};
use crate::render::{Backend, NotRendered, RenderOptions, Rendered};
use crate::scene::resolve::ResolvedScene;
use anyhow::{bail, Context, Result};
use manifest::{Manifest, RenderRecord, Results};
use process::{run_with_timeout, shell_line, Outcome};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// The backend every other one is compared against.
pub const REFERENCE: &str = "raster";

/// Scene features the core models ([`Backend::features`]: every one).
pub fn core_features() -> Vec<&'static str> {
    Backend::Trace
        .features()
        .iter()
        .map(|f| f.as_str())
        .collect()
}

/// Scene features Embree's visibility queries model ([`Backend::features`]).
pub fn embree_features() -> Vec<&'static str> {
    Backend::Embree(EmbreeMode::Default)
        .features()
        .iter()
        .map(|f| f.as_str())
        .collect()
}

/// The scene features the visibility buffers (Z, id, N) need
/// (`vocab::Feature::VISIBILITY`).
pub fn visibility_features() -> Vec<&'static str> {
    Feature::VISIBILITY.iter().map(|f| f.as_str()).collect()
}

/// `role` of a calibration probe in manifest.json (docs/run-format.md).
pub const CALIBRATION_ROLE: &str = "calibration";

/// Seed of the core's path tracer in check runs (recorded in the buffers).
pub const CHECK_SEED: u64 = 1;

/// Options of one check run.
#[derive(Debug, Clone)]
pub struct CheckOptions {
    /// Scene files to run.
    pub scenes: Vec<PathBuf>,
    /// Output folder (manifest, buffers, results).
    pub run_dir: PathBuf,
    /// Where rendiff's own files are: a checkout, or an installed harness's
    /// data folder ([`home`]).
    pub root: PathBuf,
    /// Only these backends (the reference always runs).
    pub only: Option<Vec<String>>,
    /// Time limit per external render.
    pub timeout: Duration,
    /// Expectations file (known divergences with bounds).
    pub expectations: PathBuf,
    /// Print nothing but errors.
    pub quiet: bool,
    /// Cached Monte Carlo references (Mitsuba), compared with the core's path tracer.
    pub references: Option<PathBuf>,
    /// The core's path-tracing settings.
    pub core: CoreShading,
    /// Folder of calibration probe scenes (`*.toml`), rendered first on every
    /// backend and recorded with `role: "calibration"`; `None` renders none.
    pub calibration: Option<PathBuf>,
    /// External renders run this many at a time, across scenes (pool.rs);
    /// 1 (and no wait slots) runs them one after another.
    pub jobs: usize,
    /// Extra pool slots for renders that mostly wait (pool.rs); 0: none.
    pub wait_slots: usize,
    /// External renders go to long-lived harness workers (worker.rs), one
    /// per backend and job slot; false starts a process per render.
    pub workers: bool,
    /// The user's renderers file (`--renderers`, docs/your-renderer.md),
    /// absolute: its renderers join the harness's built-in ones.
    pub renderers: Option<PathBuf>,
    /// The run's copy of that file ([`RENDERERS_SNAPSHOT`]), set by the run
    /// itself once its staging folder exists; `None` everywhere else.
    pub renderers_snapshot: Option<PathBuf>,
    /// Estimated peak bytes of external renders in flight at most
    /// ([`pool::render_memory`]); [`pool::default_memory_budget`] by default.
    pub memory_budget: u64,
}

impl CheckOptions {
    /// A quiet run of `scenes` into `run_dir` with the checkout or data
    /// folder `root`: every backend, the repository's expectations
    /// (`tests/expectations.toml`), 600 s per external render, no cached
    /// references, no calibration probes, the default jobs, wait slots (as
    /// many as jobs, like `check`), workers and memory budget, no renderers
    /// file. Callers change what they need with struct update syntax.
    pub fn new(scenes: Vec<PathBuf>, run_dir: PathBuf, root: PathBuf) -> Self {
        CheckOptions {
            scenes,
            run_dir,
            expectations: root.join("tests/expectations.toml"),
            root,
            only: None,
            timeout: Duration::from_secs(600),
            quiet: true,
            references: None,
            core: CoreShading::default(),
            calibration: None,
            jobs: default_jobs(),
            wait_slots: default_jobs(),
            workers: true,
            renderers: None,
            renderers_snapshot: None,
            memory_budget: pool::default_memory_budget(),
        }
    }
}

/// The default of `--jobs`: the cores this process may use.
pub fn default_jobs() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// How the core shades in a check run (the reference for radiance).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoreShading {
    /// Seed of the path tracer.
    pub seed: u64,
    /// Samples per pixel; default: the scene's `integrator.spp`.
    pub spp: Option<u32>,
    /// A deliberate error, for testing the statistical gate's power.
    pub bias: Option<crate::shade::Bias>,
}

impl Default for CoreShading {
    fn default() -> Self {
        Self {
            seed: CHECK_SEED,
            spp: None,
            bias: None,
        }
    }
}

/// What a run produced.
#[derive(Debug, Clone)]
pub struct CheckOutcome {
    /// What was rendered.
    pub manifest: Manifest,
    /// How it compared.
    pub results: Results,
    /// The verdict table, as the comparison printed it.
    pub table: String,
}

pub use home::{find_root, in_root, python};

/// The environment variable that names the user's renderers file for the
/// harness (harness `command_renderers.py`, docs/your-renderer.md).
pub const RENDERERS_ENV: &str = "RENDIFF_RENDERERS";

/// The environment variable that names the run's copy of the renderers file
/// (`RUN/renderers.toml`), whose declarations the harness reads in place of
/// the file's (`command_renderers.SNAPSHOT_ENV_VAR`).
pub const RENDERERS_SNAPSHOT_ENV: &str = "RENDIFF_RENDERERS_SNAPSHOT";

/// The run's copy of the user's renderers file, taken as the run begins: the
/// declarations (their precision above all) every render and the comparison
/// of the run use, whatever happens to the file meanwhile, and the record of
/// what the run was judged with. An edit to the file during a run used to
/// change the precision of the comparisons after it.
pub const RENDERERS_SNAPSHOT: &str = "renderers.toml";

/// Most bytes of a renderers file (the harness's `MAX_FILE_BYTES`).
const MAX_RENDERERS_BYTES: u64 = 1 << 20;

fn harness_command(opts: &CheckOptions) -> Command {
    let root = &opts.root;
    let mut cmd = Command::new(python(root));
    cmd.current_dir(root).args(["-m", "rendiff_harness"]);
    home::harness_path(&mut cmd, root);
    match &opts.renderers {
        Some(file) => cmd.env(RENDERERS_ENV, file),
        None => cmd.env_remove(RENDERERS_ENV),
    };
    match &opts.renderers_snapshot {
        Some(copy) if opts.renderers.is_some() => cmd.env(RENDERERS_SNAPSHOT_ENV, copy),
        _ => cmd.env_remove(RENDERERS_SNAPSHOT_ENV),
    };
    cmd
}

/// Copies the user's renderers file into the staging run folder
/// ([`RENDERERS_SNAPSHOT`]) and returns the copy's path.
fn snapshot_renderers(file: &Path, run_dir: &Path) -> Result<PathBuf> {
    let bytes = crate::scene::read_regular_file(file, MAX_RENDERERS_BYTES)
        .map_err(|p| anyhow::anyhow!("{}: the renderers file {p}", file.display()))?;
    let copy = run_dir.join(RENDERERS_SNAPSHOT);
    crate::exr_io::write_atomically(&copy, |tmp| Ok(std::fs::write(tmp, &bytes)?))?;
    Ok(copy)
}

/// One external backend as the harness describes it (`info --json`).
#[derive(Debug, Clone, serde::Deserialize)]
struct HarnessBackend {
    name: String,
    version: Option<String>,
    features: Vec<String>,
    buffers: Vec<String>,
    available: bool,
    /// (fixed bytes, bytes per triangle) at a render's peak, as the backend
    /// declares it (`PEAK_MEMORY` beside it in the harness, else the
    /// harness's `UNMEASURED_MEMORY`); the pool's budget.
    peak_memory: (u64, u64),
    /// Scenes below this many triangles render mostly waiting (the backend's
    /// measured `waits_below`; 0: never): the pool's wait slots may take them.
    #[serde(default)]
    waits_below: u64,
    reason: Option<String>,
}

/// How the harness begins the one line of an expected failure: its commands
/// (`rendiff_harness/__main__.py`, `_fail`) and its comparison (`compare.py`).
const HARNESS_REFUSALS: [&str; 2] = ["rendiff_harness: ", "rendiff_harness compare: "];

/// The harness's own one-line refusal (a malformed renderers or expectations
/// file, which it names), when that is all its stderr says; None for a
/// harness that could not run at all (a traceback, a missing module).
fn harness_refusal(stderr: &str) -> Option<String> {
    let text = stderr.trim();
    if text.contains('\n') {
        return None;
    }
    HARNESS_REFUSALS
        .iter()
        .find_map(|p| text.strip_prefix(p))
        .map(|m| crate::scene::printable(m, 2000))
}

/// Asks the Python harness which backends it has. An error here means the harness
/// itself is not installed; the message says how to fix it.
fn harness_backends(opts: &CheckOptions, scratch: &Path) -> Result<Vec<HarnessBackend>, String> {
    if let Some(missing) = home::missing_python(&opts.root) {
        return Err(missing);
    }
    let mut cmd = harness_command(opts);
    cmd.args(["info", "--json"]);
    let o = run_with_timeout(cmd, Duration::from_secs(120), scratch)
        .map_err(|e| format!("cannot run the Python harness: {e:#}"))?;
    if o.code != Some(0) {
        if let Some(refusal) = harness_refusal(&o.stderr) {
            return Err(refusal);
        }
        let tail = o.stderr_tail(5);
        return Err(format!(
            "the Python harness failed to start ({}): {tail}; run scripts/setup.sh",
            o.how(),
        ));
    }
    #[derive(serde::Deserialize)]
    struct Info {
        backends: Vec<HarnessBackend>,
    }
    let info: Info = serde_json::from_str(o.stdout.trim())
        .map_err(|e| format!("unreadable `info --json` output from the harness: {e}"))?;
    Ok(info.backends)
}

fn missing(requires: &[String], features: &[&str]) -> Vec<String> {
    requires
        .iter()
        .filter(|r| !features.contains(&r.as_str()))
        .cloned()
        .collect()
}

/// What a backend renders of a scene, judged per buffer from its features.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Capability {
    /// Every buffer it produces.
    Full,
    /// The visibility buffers only: these shading features are missing.
    VisibilityOnly(Vec<String>),
    /// Nothing: a visibility feature is missing (all missing features listed).
    Skip(Vec<String>),
}

impl Capability {
    /// Decides from the scene's requirements and the backend's features.
    pub fn of(requires: &[String], features: &[&str]) -> Self {
        let miss = missing(requires, features);
        if miss.is_empty() {
            Capability::Full
        } else if miss
            .iter()
            .any(|m| Feature::VISIBILITY.iter().any(|f| f.as_str() == m))
        {
            Capability::Skip(miss)
        } else {
            Capability::VisibilityOnly(miss)
        }
    }
}

/// The manifest reason of a render without RGB (the Python side words it the same).
pub fn rgb_not_rendered(missing: &[String]) -> String {
    format!("RGB not rendered: missing features: {}", missing.join(", "))
}

/// Marks an ok record as visibility only: no RGB listed, the reason recorded.
fn visibility_only(rec: &mut RenderRecord, missing: &[String]) {
    if rec.status == RenderStatus::Ok {
        rec.buffers.retain(|b| b != "RGB");
        rec.reason = rgb_not_rendered(missing);
    }
}

/// A scene's name in a run: its file's stem, which names its folder
/// `RUN/scenes/<name>/` (checked by [`scene_name`] before anything runs).
pub(crate) fn stem(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene".into())
}

/// A scene name that can be its run folder `scenes/<name>/`: one plain path
/// component (checked for names from files too: `merge` reads them from
/// shards' manifests, where `../../x` would name a folder outside the run).
pub(crate) fn is_folder_name(name: &str) -> bool {
    let mut parts = Path::new(name).components();
    matches!(
        (parts.next(), parts.next()),
        (Some(std::path::Component::Normal(n)), None) if n == std::ffi::OsStr::new(name)
    )
}

/// [`stem`], refused where it cannot name a folder of its own: a file
/// `...toml` has the stem `..`, and its outputs landed in the run's root,
/// beside (and over) the run's own files; `..toml` wrote into `RUN/scenes/`.
fn scene_name(path: &Path) -> Result<String> {
    let name = stem(path);
    if !is_folder_name(&name) {
        bail!(
            "{}: a scene file's name without .toml names its run folder RUN/scenes/<name>/, and {name:?} cannot (rename the file)",
            path.display()
        );
    }
    Ok(name)
}

/// The core's loops, rendered in process (the first is [`REFERENCE`]).
const CORE_LOOPS: [&str; 2] = [REFERENCE, "trace"];

/// Embree's scene modes, rendered in process.
const EMBREE_MODES: [EmbreeMode; 2] = [EmbreeMode::Default, EmbreeMode::Robust];

/// Every name in `--only` is a backend this run could render: the core's
/// loops, Embree's modes, or one the harness lists (`listed`, asked only
/// when a name is none of the first two). A typo used to leave its backend
/// out silently: `--only bogus` ran the reference alone and passed.
fn check_only(only: &[String], listed: impl FnOnce() -> Result<Vec<String>, String>) -> Result<()> {
    let in_process: Vec<&str> = CORE_LOOPS
        .into_iter()
        .chain(EMBREE_MODES.map(EmbreeMode::name))
        .collect();
    let others: Vec<&String> = only
        .iter()
        .filter(|n| !in_process.contains(&n.as_str()))
        .collect();
    if others.is_empty() {
        return Ok(());
    }
    let listed = listed().map_err(|e| {
        anyhow::anyhow!(
            "--only {}: not a core or Embree backend, and the harness cannot list its own: {e}",
            crate::scene::printable(others[0], 100)
        )
    })?;
    if let Some(bad) = others.iter().find(|n| !listed.contains(n)) {
        let known: Vec<&str> = in_process
            .iter()
            .copied()
            .chain(listed.iter().map(String::as_str))
            .collect();
        bail!(
            "--only {}: no such backend (known: {})",
            crate::scene::printable(bad, 100),
            known.join(", ")
        );
    }
    Ok(())
}

/// [`check_only`] for callers that run many checks with one `--only`
/// (`bench stability`): refuses a name no backend has before the first.
pub fn check_only_option(opts: &CheckOptions) -> Result<()> {
    match &opts.only {
        Some(only) => check_only(only, || harness_names(opts)),
        None => Ok(()),
    }
}

/// The expectations file's content, checked by the reader the comparison
/// uses (`python -m rendiff_harness expectations FILE`) before anything
/// runs: a bad bound or a typo in a key was found only after every render,
/// leaving the run incomplete.
fn check_expectations(opts: &CheckOptions) -> Result<()> {
    if let Some(missing) = home::missing_python(&opts.root) {
        bail!("{missing}");
    }
    let mut cmd = harness_command(opts);
    cmd.arg("expectations").arg("--").arg(&opts.expectations);
    let o = in_probe_folder("expectations", |probe| {
        run_with_timeout(cmd, Duration::from_secs(120), probe)
    })
    .context("cannot run the Python harness to read the expectations file")?;
    if o.code == Some(0) {
        return Ok(());
    }
    match harness_refusal(&o.stderr) {
        Some(refusal) => bail!("{refusal}"),
        None => bail!(
            "{}: the Python harness could not check it ({}): {}; run scripts/setup.sh",
            opts.expectations.display(),
            o.how(),
            o.stderr_tail(5)
        ),
    }
}

/// Runs `f` with a scratch folder of its own for a harness call made before
/// the run folder exists (`rendiff-<what>-<pid>` in the temp folder), removed
/// afterwards, and by the signal handler if rendiff is interrupted meanwhile.
fn in_probe_folder<T>(what: &str, f: impl FnOnce(&Path) -> T) -> T {
    let probe = std::env::temp_dir().join(format!("rendiff-{what}-{}", std::process::id()));
    let _pending = crate::shutdown::track_path(&probe);
    let out = f(&probe);
    let _ = std::fs::remove_dir_all(&probe);
    out
}

/// The names the harness lists, asked in a scratch folder of its own.
fn harness_names(opts: &CheckOptions) -> Result<Vec<String>, String> {
    in_probe_folder("renderers", |probe| harness_backends(opts, probe))
        .map(|b| b.into_iter().map(|b| b.name).collect())
}

/// The loop that renders the reference: the raster when the tracer renders
/// too (so the run compares the two loops), else whichever the cost model
/// expects to finish sooner (bit-identical buffers, so no verdict changes).
fn reference_loop(
    opts: &CheckOptions,
    scene: &ResolvedScene,
) -> (Backend, Option<rendiff_core::loop_cost::Choice>) {
    if wanted(opts, "trace") {
        return (Backend::Raster, None);
    }
    let (b, c) = crate::render::core_loop(scene, rayon::current_num_threads());
    (b, Some(c))
}

/// Records in the reference's `info` which loop rendered it and why.
fn note_loop_choice(rec: &mut RenderRecord, choice: Option<rendiff_core::loop_cost::Choice>) {
    if let (Some(c), Some(info)) = (choice, rec.info.as_object_mut()) {
        info.insert("loop_choice".into(), serde_json::json!(c));
    }
}

fn wanted(opts: &CheckOptions, name: &str) -> bool {
    name == REFERENCE
        || opts
            .only
            .as_ref()
            .is_none_or(|o| o.iter().any(|x| x == name))
}

/// Renders a core loop or Embree in process (`render::render`, the entry
/// point `rendiff render` uses too); a panic becomes an error record. The
/// render's deadline is `check --timeout` from now: the core's loops stop
/// there, and a render that ends past it is a timeout, its partial buffers
/// discarded, exactly as for an external renderer that is killed. (Embree
/// cannot be stopped mid-render; one that ends late still counts as timed out.)
#[allow(clippy::too_many_arguments)] // one call site per backend kind; a struct would only rename them
fn in_process(
    backend: Backend,
    scene: &ResolvedScene,
    exr: &Path,
    rel_exr: &str,
    command: String,
    version: String,
    render_opts: RenderOptions,
    timeout: Duration,
) -> RenderRecord {
    let name = backend.name();
    let mut rec = RenderRecord {
        backend: name.into(),
        command,
        version,
        ..RenderRecord::default()
    };
    let start = Instant::now();
    let deadline = start + timeout;
    let render_opts = RenderOptions {
        deadline: Some(deadline),
        ..render_opts
    };
    let seed = render_opts.seed;
    match std::panic::catch_unwind(move || {
        crate::render::render(scene, backend, render_opts, &|_| {})
    }) {
        Ok(Ok(_)) if rendiff_core::deadline::past(Some(deadline)) => {
            rec.status = RenderStatus::Error;
            rec.time_s = start.elapsed().as_secs_f64();
            rec.message = format!(
                "timed out: stopped after {:.0} s (--timeout {} s); its partial buffers were discarded",
                rec.time_s,
                timeout.as_secs_f64()
            );
        }
        Ok(Ok(Rendered { frame, radiance })) => {
            rec.time_s = start.elapsed().as_secs_f64();
            let mut attrs = frame_attrs(&frame, &scene.name);
            if radiance.is_some() {
                attrs.insert("seed".into(), seed.to_string());
            }
            match write_frame_with(exr, &frame, radiance.as_ref(), &attrs) {
                Ok(()) => {
                    rec.status = RenderStatus::Ok;
                    rec.exr = rel_exr.into();
                    rec.buffers = vec!["Z".into(), "id".into(), "N".into()];
                    if radiance.is_some() {
                        rec.buffers.push("RGB".into());
                    }
                    rec.info = serde_json::json!({
                        "counters": frame.counters,
                        "render_seconds": frame.seconds,
                        "shade_seconds": radiance.as_ref().map(|r| r.seconds),
                        "spp": radiance.as_ref().map(|r| r.spp),
                        "integrator": radiance.as_ref().map(|r| r.integrator),
                    });
                }
                Err(e) => {
                    rec.status = RenderStatus::Error;
                    rec.message = format!("{e:#}");
                }
            }
        }
        Ok(Err(NotRendered::Skipped(why))) => {
            rec.status = RenderStatus::Skipped;
            rec.reason = why;
        }
        Ok(Err(NotRendered::Failed(e))) => {
            rec.status = RenderStatus::Error;
            rec.message = e;
            rec.time_s = start.elapsed().as_secs_f64();
        }
        Err(_) => {
            rec.status = RenderStatus::Error;
            rec.message = format!("{name} panicked (a bug in rendiff)");
            rec.time_s = start.elapsed().as_secs_f64();
        }
    }
    rec
}

/// One progress line on stderr. It names scene files and quotes renderers'
/// messages, which may hold any text: control characters (a terminal escape
/// in a file name, a newline that split the line) are written as escapes.
fn say(opts: &CheckOptions, line: String) {
    if !opts.quiet {
        crate::errln!("{}", crate::scene::printable(&line, SAY_MAX_CHARS));
    }
}

/// Most characters of one progress line (a renderer's message is six lines
/// of its stderr at most: this keeps them whole and a runaway one short).
const SAY_MAX_CHARS: usize = 4000;

fn describe(rec: &RenderRecord) -> String {
    match rec.status {
        RenderStatus::Ok if !rec.reason.is_empty() => {
            format!("ok ({:.2} s; {})", rec.time_s, rec.reason)
        }
        RenderStatus::Ok => format!("ok ({:.2} s)", rec.time_s),
        RenderStatus::Skipped => format!("skipped: {}", rec.reason),
        RenderStatus::Error => format!("ERROR: {}", rec.message),
    }
}

/// Runs every scene on every backend, then the comparison; writes manifest.json and results.json.
pub fn run(opts: &CheckOptions) -> Result<CheckOutcome> {
    run_isolating(opts, None)
}

/// Like [`run`], but with `isolate` (a rendiff binary) set, every render runs
/// in a child process of its own whose peak memory is measured
/// (`max_rss_bytes`, see [`process::run_measured`]): the core loops and Embree
/// through `rendiff render`, the external renderers as always. A separate
/// entry point, so that `CheckOptions` stays as it was.
pub fn run_isolating(opts: &CheckOptions, isolate: Option<&Path>) -> Result<CheckOutcome> {
    run_recorded(opts, isolate, None)
}

/// [`run`] of one shard of a split (`check --shard K/N`): `shard` (from
/// [`shard::deal`]) is recorded in manifest.json, where `merge` checks it.
pub fn run_shard(opts: &CheckOptions, shard: manifest::ShardRecord) -> Result<CheckOutcome> {
    run_recorded(opts, None, Some(shard))
}

fn run_recorded(
    opts: &CheckOptions,
    isolate: Option<&Path>,
    shard: Option<manifest::ShardRecord>,
) -> Result<CheckOutcome> {
    if opts.scenes.is_empty() {
        bail!("no scenes to check");
    }
    let jobs = scene_jobs(opts)?;
    // The harness's backends, asked at most once before anything runs.
    let mut listed: Option<Result<Vec<String>, String>> = None;
    let mut list = || listed.get_or_insert_with(|| harness_names(opts)).clone();
    if let Some(file) = &opts.renderers {
        // A user's renderers file is checked before anything runs: a typo in
        // it is one line naming it, not an error on every scene.
        if let Err(e) = list() {
            // The harness's refusal names the file already.
            let file = file.display().to_string();
            if e.starts_with(&file) {
                bail!("{e}");
            }
            bail!("{file}: {e}");
        }
    }
    if let Some(only) = &opts.only {
        check_only(only, list)?;
    }
    check_expectations(opts)?;
    // Everything is written to a staging folder that replaces the run folder
    // once results.json exists (run_folder.rs): never a half-old run.
    let staging = run_folder::Staging::begin(&opts.run_dir)?;
    let renderers_snapshot = match &opts.renderers {
        Some(file) => Some(snapshot_renderers(file, &staging.dir)?),
        None => None,
    };
    let staged = CheckOptions {
        run_dir: staging.dir.clone(),
        renderers_snapshot,
        ..opts.clone()
    };
    let outcome = render_run::render_and_compare(&staged, &jobs, isolate, &opts.run_dir, shard)
        .map_err(|e| anyhow::anyhow!(unstage(&format!("{e:#}"), &staging.dir, &opts.run_dir)))?;
    staging.publish()?;
    Ok(outcome)
}

/// `text` with the staging folder's path replaced by the run folder's: the
/// staging folder (`.NAME.partial-PID`) is gone once the run is published
/// or abandoned, so no message, record or verdict may send a user there.
pub(crate) fn unstage(text: &str, staged: &Path, shown: &Path) -> String {
    text.replace(&staged.display().to_string(), &shown.display().to_string())
}

/// What the run's verdicts depend on besides scenes and renderers
/// ([`manifest::RunOptions`]).
fn run_options(opts: &CheckOptions) -> Result<manifest::RunOptions> {
    use rendiff_core::names::Named;
    let renderers_sha256 = match &opts.renderers_snapshot {
        Some(copy) => inputs::file_digest(copy)?,
        None => String::new(),
    };
    Ok(manifest::RunOptions {
        only: opts.only.clone(),
        renderers_sha256,
        calibration: opts.calibration.is_some(),
        seed: opts.core.seed,
        spp: opts.core.spp,
        bias: opts.core.bias.map(|b| b.name().to_string()),
    })
}

/// Where a recorded render command writes its buffer: `RUN.repro/render/<rel>`,
/// beside the run, so that running it never overwrites the run it came
/// from (report/rerun.rs writes check reruns to `RUN.repro/` too). Given the
/// staging folder, it names the run's once the command is unstaged.
fn repro_out(run_dir: &Path, rel_exr: &str) -> PathBuf {
    let mut dir = run_dir.as_os_str().to_owned();
    dir.push(".repro");
    PathBuf::from(dir).join("render").join(rel_exr)
}

/// What the report's reproduction commands need besides the run's options.
fn rerun_inputs(opts: &CheckOptions) -> manifest::Rerun {
    // rendiff's own files are check's defaults: a command without them finds them again.
    let own = |rel: &str| std::path::absolute(in_root(&opts.root, rel)).ok();
    let given = |file: &Path, rel: &str| {
        let abs = std::path::absolute(file).ok();
        (abs != own(rel)).then(|| file.display().to_string())
    };
    manifest::Rerun {
        cwd: std::env::current_dir()
            .ok()
            .map(|d| d.display().to_string()),
        renderers_file: opts.renderers.as_ref().map(|f| f.display().to_string()),
        calibration_dir: opts
            .calibration
            .as_ref()
            .and_then(|c| given(c, "scenes/calibration")),
        expectations_file: given(&opts.expectations, "tests/expectations.toml"),
    }
}

/// Runs the harness's comparison: results.json, and the verdict table it
/// prints on stdout (its one formatter, `results.format_table`).
///
/// The comparison runs in the staging folder and may name it (a buffer's
/// path in an error); results.json and the table are rewritten to name
/// `shown`, the run folder, instead ([`unstage`]).
fn compare(opts: &CheckOptions, scratch: &Path, shown: &Path) -> Result<(Results, String)> {
    let cmd = compare_command(opts, false);
    let o = run_with_timeout(cmd, COMPARE_TIMEOUT, &scratch.join("compare"));
    compared(opts, o, shown)
}

/// How long the comparison may take once every render is in.
const COMPARE_TIMEOUT: Duration = Duration::from_secs(1800);

/// The comparison's command; with `stream`, it judges the scenes written to
/// its stdin before it reads manifest.json (`compare.py`'s `--stream`).
fn compare_command(opts: &CheckOptions, stream: bool) -> Command {
    let _ = std::fs::remove_file(opts.run_dir.join("results.json"));
    let mut cmd = harness_command(opts);
    cmd.arg("compare")
        .arg("--run")
        .arg(&opts.run_dir)
        .arg("--expectations")
        .arg(&opts.expectations)
        .args(["--jobs", &opts.jobs.to_string()]);
    if stream {
        cmd.arg("--stream");
    }
    if let Some(r) = &opts.references {
        cmd.arg("--references").arg(r);
    }
    cmd
}

/// results.json and the verdict table from the comparison's outcome `o`.
fn compared(opts: &CheckOptions, o: Result<Outcome>, shown: &Path) -> Result<(Results, String)> {
    let results_path = opts.run_dir.join("results.json");
    let o = o.context("cannot run the comparison (python -m rendiff_harness compare)")?;
    if o.timed_out || o.code != Some(0) {
        if let Some(refusal) = harness_refusal(&o.stderr).filter(|_| !o.timed_out) {
            bail!("the comparison refused the run: {refusal}");
        }
        bail!(
            "the comparison failed ({}): {} (run scripts/setup.sh if the Python harness is missing)",
            o.how(),
            o.stderr_line(12)
        );
    }
    let text = std::fs::read_to_string(&results_path)
        .with_context(|| format!("{}: comparison wrote no results", results_path.display()))?;
    let in_json = |p: &Path| {
        let quoted = serde_json::to_string(&p.display().to_string()).unwrap_or_default();
        quoted.trim_matches('"').to_string()
    };
    let (staged, final_dir) = (in_json(&opts.run_dir), in_json(shown));
    let text = if text.contains(&staged) {
        let text = text.replace(&staged, &final_dir);
        crate::exr_io::write_atomically(&results_path, |tmp| Ok(std::fs::write(tmp, &text)?))?;
        text
    } else {
        text
    };
    let results = serde_json::from_str(&text)
        .with_context(|| format!("{}: unreadable", results_path.display()))?;
    let table = unstage(&o.stdout, &opts.run_dir, shown);
    // The comparison's notes (expectations that matched no verdict: a typo
    // in a backend's name passed silently), in its own words.
    for line in o.stderr.lines().filter(|l| l.starts_with(COMPARE_NOTE)) {
        say(opts, crate::scene::printable(line, 2000));
    }
    Ok((results, table))
}

/// How the comparison begins a line meant for the user (`compare.py`).
const COMPARE_NOTE: &str = "note: ";

/// The run's scenes in order, each with its manifest `role`: the calibration
/// probes first (`CALIBRATION_ROLE`), then `opts.scenes`. A file named twice
/// runs once; two files with one stem are refused (they would share
/// `RUN/scenes/<stem>/`). A missing probe folder fails here, before anything runs.
fn scene_jobs(opts: &CheckOptions) -> Result<Vec<(PathBuf, &'static str)>> {
    let mut list: Vec<(PathBuf, &'static str)> = Vec::new();
    if let Some(dir) = &opts.calibration {
        if !dir.is_dir() {
            bail!(
                "calibration probe folder {} not found: add the probe scenes there, or pass --no-calibration to check without camera calibration",
                dir.display()
            );
        }
        let probes = collect_scenes(std::slice::from_ref(dir))?;
        if probes.is_empty() {
            bail!(
                "calibration probe folder {} has no *.toml probe scenes: add them, or pass --no-calibration",
                dir.display()
            );
        }
        list.extend(probes.into_iter().map(|p| (p, CALIBRATION_ROLE)));
    }
    list.extend(opts.scenes.iter().map(|p| (p.clone(), "")));
    let mut seen: std::collections::HashMap<String, PathBuf> = std::collections::HashMap::new();
    let mut out = Vec::new();
    for (path, role) in list {
        let name = scene_name(&path)?;
        match seen.get(&name) {
            Some(prev) if same_file(prev, &path) => continue,
            Some(prev) => bail!(
                "two scene files named {name:?}: {} and {}; their outputs would share RUN/scenes/{name}/ (rename one)",
                prev.display(),
                path.display()
            ),
            None => {
                seen.insert(name, path.clone());
                out.push((path, role));
            }
        }
    }
    Ok(out)
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => a == b,
    }
}

/// Scene files named on the command line: files as they are, folders expanded
/// to their `*.toml` (not recursively: `scenes/calibration/` stays out of
/// `scenes`). A path that does not exist is an error naming it.
pub fn collect_scenes(args: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for a in args {
        if !a.exists() {
            bail!("{}: no such scene file or folder", a.display());
        }
        if a.is_dir() {
            let mut v: Vec<PathBuf> = std::fs::read_dir(a)
                .with_context(|| format!("{}: cannot list", a.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "toml"))
                .collect();
            v.sort();
            out.extend(v);
        } else {
            out.push(a.clone());
        }
    }
    Ok(out)
}

/// Counts of verdicts, for the closing line and exit code.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Tally {
    /// Verdicts that passed (pass and expected_fail).
    pub ok: usize,
    /// fail, error and unexpected_pass.
    pub failed: usize,
    /// skipped.
    pub skipped: usize,
}

/// The tally of a run's verdicts. The verdict table itself has one
/// formatter, the harness's (`results.format_table`), printed by `compare`.
pub fn tally(results: &Results) -> Tally {
    let mut t = Tally::default();
    for r in &results.results {
        if r.is_failure() {
            t.failed += 1;
        } else if r.status == Status::Skipped.as_str() {
            t.skipped += 1;
        } else {
            t.ok += 1;
        }
    }
    t
}

/// The record of a backend skipped because it cannot model what the scene requires.
fn skipped_for_features(backend: &str, missing: &[String]) -> RenderRecord {
    RenderRecord {
        backend: backend.into(),
        status: RenderStatus::Skipped,
        reason: format!("missing features: {}", missing.join(", ")),
        ..RenderRecord::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn req(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn capabilities_are_judged_per_buffer() {
        let shaded = req(&["depth", "ids", "lambert", "shadows", "two_sided"]);
        assert_eq!(Capability::of(&shaded, &core_features()), Capability::Full);
        assert_eq!(
            Capability::of(&shaded, &embree_features()),
            Capability::VisibilityOnly(req(&["lambert", "shadows", "two_sided"]))
        );
        // A missing visibility feature skips, and every missing feature is named.
        let normals = req(&["depth", "ids", "normals", "lambert"]);
        assert_eq!(
            Capability::of(&normals, &["depth", "ids", "lambert"]),
            Capability::Skip(req(&["normals"]))
        );
        assert_eq!(
            Capability::of(&normals, &["depth", "ids"]),
            Capability::Skip(req(&["normals", "lambert"]))
        );
        assert_eq!(
            rgb_not_rendered(&req(&["one_sided", "shadows"])),
            "RGB not rendered: missing features: one_sided, shadows"
        );
    }

    #[test]
    fn visibility_features_are_known_and_embree_has_them() {
        for f in visibility_features() {
            assert!(Feature::parse(f).is_some(), "{f}");
            assert!(embree_features().contains(&f), "{f}");
        }
    }

    #[test]
    fn visibility_only_records_drop_rgb_and_say_why() {
        let mut rec = RenderRecord {
            status: RenderStatus::Ok,
            buffers: req(&["Z", "id", "RGB"]),
            ..RenderRecord::default()
        };
        visibility_only(&mut rec, &req(&["shadows"]));
        assert_eq!(rec.buffers, req(&["Z", "id"]));
        assert_eq!(rec.reason, "RGB not rendered: missing features: shadows");
        let mut skipped = skipped_for_features("x", &req(&["ids"]));
        visibility_only(&mut skipped, &req(&["shadows"]));
        assert_eq!(skipped.reason, "missing features: ids");
    }

    #[test]
    fn scene_jobs_put_probes_first_and_refuse_stem_clashes() {
        let dir = tempfile::tempdir().unwrap();
        let probes = dir.path().join("calibration");
        let other = dir.path().join("other");
        std::fs::create_dir_all(&probes).unwrap();
        std::fs::create_dir_all(&other).unwrap();
        for p in [
            probes.join("p.toml"),
            dir.path().join("a.toml"),
            other.join("a.toml"),
        ] {
            std::fs::write(p, "").unwrap();
        }
        let mut opts = CheckOptions {
            scenes: vec![dir.path().join("a.toml"), dir.path().join("a.toml")],
            run_dir: dir.path().join("run"),
            root: dir.path().into(),
            only: None,
            timeout: Duration::from_secs(1),
            expectations: dir.path().join("e.toml"),
            quiet: true,
            references: None,
            core: CoreShading::default(),
            calibration: Some(probes.clone()),
            jobs: 1,
            wait_slots: 0,
            workers: true,
            renderers: None,
            renderers_snapshot: None,
            memory_budget: pool::default_memory_budget(),
        };
        let jobs = scene_jobs(&opts).unwrap();
        let got: Vec<(String, &str)> = jobs.iter().map(|(p, r)| (stem(p), *r)).collect();
        assert_eq!(
            got,
            [("p".into(), CALIBRATION_ROLE), ("a".into(), "")],
            "probes first, a file named twice runs once"
        );
        opts.scenes.push(other.join("a.toml"));
        let e = scene_jobs(&opts).unwrap_err().to_string();
        assert!(e.contains("two scene files named \"a\""), "{e}");
        opts.calibration = Some(dir.path().join("none"));
        let e = scene_jobs(&opts).unwrap_err().to_string();
        assert!(e.contains("--no-calibration") && e.contains("none"), "{e}");
        opts.calibration = Some(other.clone());
        opts.scenes.clear();
        assert_eq!(scene_jobs(&opts).unwrap().len(), 1);
        let e = collect_scenes(&[dir.path().join("missing")]).unwrap_err();
        assert!(
            e.to_string().contains("no such scene file or folder"),
            "{e}"
        );
    }
}
