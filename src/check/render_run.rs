//! One check run's jobs, in their order: each scene loaded, exported and
//! sealed, then rendered by the core's loops and Embree in process
//! ([`render_scene`]); every external render of every scene in the job pool
//! ([`render_externals`]); the seals checked and manifest.json written
//! ([`write_manifest`]); then the comparison ([`super::compare`]), which
//! has judged each scene whose renders were in already (streamed.rs).

use super::external::{external, ExternalScene};
use super::manifest::{Manifest, RenderRecord, SceneRuns, ShardRecord, MANIFEST_FORMAT};
use super::process::Fed;
use super::{
    compare, core_features, describe, embree_features, in_process, inputs, isolated, missing,
    note_loop_choice, pool, reference_loop, repro_out, rerun_inputs, run_options, say, shell_line,
    skipped_for_features, stem, streamed, unstage, visibility_only, wanted, worker, Capability,
    CheckOptions, CheckOutcome, HarnessBackend, CORE_LOOPS, EMBREE_MODES, REFERENCE,
};
use crate::backends::embree;
use crate::render::{Backend, RenderOptions};
use crate::scene::export::export;
use crate::scene::resolve::ResolvedScene;
use crate::scene::Scene;
use crate::vocab::RenderStatus;
use anyhow::{bail, Result};
use std::path::{Path, PathBuf};

/// The command name recorded in reproduction commands.
const EXE: &str = "rendiff";

/// What every render of one run shares.
struct Run<'a> {
    opts: &'a CheckOptions,
    /// A rendiff binary when every render runs in a child process of its own.
    isolate: Option<&'a Path>,
    /// `RUN/scratch`: the harness's listing, workers' folders, renders' copies.
    scratch: PathBuf,
    /// rendiff's version as recorded for the core's renders.
    version: String,
    /// Where the run will be once published (messages name it).
    shown_dir: &'a Path,
}

impl Run<'_> {
    /// Messages name the published run folder, never the staging folder.
    fn unstage(&self, rec: &mut RenderRecord) {
        for text in [&mut rec.command, &mut rec.message, &mut rec.reason] {
            *text = unstage(text, &self.opts.run_dir, self.shown_dir);
        }
    }
}

/// The run itself, written to `opts.run_dir` (the staging folder); commands in
/// the manifest name `shown_dir`, where the run will be once published.
pub(super) fn render_and_compare(
    opts: &CheckOptions,
    jobs: &[(PathBuf, &'static str)],
    isolate: Option<&Path>,
    shown_dir: &Path,
    shard: Option<ShardRecord>,
) -> Result<CheckOutcome> {
    let run = Run {
        opts,
        isolate,
        scratch: opts.run_dir.join("scratch"),
        version: format!("rendiff {}", env!("CARGO_PKG_VERSION")),
        shown_dir,
    };
    // The comparison starts first, so that its start-up overlaps the renders,
    // and judges each scene once its renders are in (streamed.rs); a
    // measuring run (`isolate`) keeps the machine to one render at a time.
    let fed = isolate
        .is_none()
        .then(|| streamed::start(opts, &run.scratch))
        .flatten();
    let mut scenes = Vec::new();
    // Per scene, what its external renders need (folder, size); None when it did not load.
    let mut pending: Vec<Option<ExternalScene>> = Vec::new();
    // The harness lists its backends (a Python start-up that mostly waits)
    // while the core renders every scene.
    let externals = std::thread::scope(|s| {
        let listing = s.spawn(|| super::harness_backends(opts, &run.scratch.join("info")));
        for (si, (scene_path, role)) in jobs.iter().enumerate() {
            let (runs, p) = render_scene(&run, scene_path, role, (si + 1, jobs.len()));
            scenes.push(runs);
            pending.push(p);
        }
        listing
            .join()
            .unwrap_or_else(|_| Err("the harness's listing of its backends panicked".into()))
    });
    if let Err(e) = &externals {
        say(opts, format!("warning: {e}"));
    }
    // Then every external render of every scene, side by side in the job pool
    // (pool.rs); the core's renders above had the cores to themselves (but for
    // the listing's start-up).
    match &externals {
        Err(e) => {
            for (runs, _) in scenes.iter_mut().zip(&pending).filter(|(_, p)| p.is_some()) {
                runs.renders.push(RenderRecord {
                    backend: "harness".into(),
                    status: RenderStatus::Error,
                    message: e.clone(),
                    ..RenderRecord::default()
                });
            }
        }
        Ok(list) => render_externals(&run, list, &mut scenes, &pending, fed.as_ref()),
    }
    let manifest = write_manifest(opts, scenes, &pending, shard)?;
    let (results, table) = match fed {
        Some(fed) => streamed::finish(opts, fed, shown_dir)?,
        None => compare(opts, &run.scratch, shown_dir)?,
    };
    Ok(CheckOutcome {
        manifest,
        results,
        table,
    })
}

/// One scene's record with its in-process renders (the core's loops and
/// Embree), and what its external renders need (`None` when it did not load).
fn render_scene(
    run: &Run,
    scene_path: &Path,
    role: &str,
    (k, total): (usize, usize),
) -> (SceneRuns, Option<ExternalScene>) {
    let name = stem(scene_path);
    let rel_dir = format!("scenes/{name}");
    let dir = run.opts.run_dir.join(&rel_dir);
    let mut runs = SceneRuns {
        scene: name,
        scene_file: scene_path.display().to_string(),
        resolved: format!("{rel_dir}/resolved"),
        resolved_sha256: String::new(),
        requires: Vec::new(),
        role: role.to_string(),
        renders: Vec::new(),
    };
    let what = if role.is_empty() {
        String::new()
    } else {
        format!(" ({role} probe)")
    };
    say(
        run.opts,
        format!("[{k}/{total}] {}{what}", scene_path.display()),
    );
    let (scene, seal) = match load_sealed(scene_path, &dir) {
        Ok(s) => s,
        Err(e) => {
            let mut rec = RenderRecord {
                backend: REFERENCE.into(),
                status: RenderStatus::Error,
                message: format!("cannot load scene: {e:#}"),
                ..RenderRecord::default()
            };
            run.unstage(&mut rec);
            say(run.opts, format!("  scene ERROR: {}", rec.message));
            runs.renders.push(rec);
            return (runs, None);
        }
    };
    // What the import left out (a glTF POINTS or LINES primitive) is
    // said even with --quiet: the scene is not all of the user's file.
    for w in &scene.warnings {
        crate::errln!("  warning: {w}");
    }
    runs.requires = scene.requires.iter().cloned().collect();
    runs.resolved_sha256 = seal.digest.clone();
    let job = SceneJob {
        path: scene_path,
        scene: &scene,
        rel_dir: &rel_dir,
    };
    core_renders(run, &job, &mut runs);
    embree_renders(run, &job, &mut runs);
    let external = ExternalScene {
        dir,
        rel_dir,
        triangles: scene.triangles.len() as u64,
        seal,
    };
    (runs, Some(external))
}

/// The scene at `scene_path` loaded, resolved and exported to `dir/resolved`.
/// The export is sealed (inputs.rs): its hash is recorded, its files are
/// read-only, and every external render reads a copy of it.
fn load_sealed(scene_path: &Path, dir: &Path) -> Result<(ResolvedScene, inputs::Seal)> {
    let scene = Scene::load(scene_path)?;
    let resolved = ResolvedScene::resolve(&scene)?;
    let folder = dir.join("resolved");
    export(&resolved, &folder)?;
    inputs::make_read_only(&folder)?;
    Ok((resolved, inputs::Seal::of(&folder)?))
}

/// One loaded scene, as its in-process renders see it.
struct SceneJob<'a> {
    path: &'a Path,
    scene: &'a ResolvedScene,
    /// `scenes/<stem>`, relative to the run folder.
    rel_dir: &'a str,
}

impl SceneJob<'_> {
    /// The buffer file of backend `name`: relative to the run, and in it.
    fn exr(&self, run: &Run, name: &str) -> (String, PathBuf) {
        let rel_exr = format!("{}/{name}.exr", self.rel_dir);
        let exr = run.opts.run_dir.join(&rel_exr);
        (rel_exr, exr)
    }

    /// The job for a child `rendiff render` of backend `name` (`check` measuring memory).
    fn isolated<'a>(
        &'a self,
        run: &'a Run,
        bin: &'a Path,
        name: &'a str,
        exr: &'a (String, PathBuf),
    ) -> isolated::Job<'a> {
        isolated::Job {
            bin,
            backend: name,
            scene: self.path,
            exr: &exr.1,
            rel_exr: &exr.0,
            scratch: &run.scratch,
        }
    }
}

/// Records one in-process render: messages unstaged, its line said.
fn record(run: &Run, runs: &mut SceneRuns, name: &str, mut rec: RenderRecord) {
    run.unstage(&mut rec);
    say(run.opts, format!("  {:<14} {}", name, describe(&rec)));
    runs.renders.push(rec);
}

/// The core's loops (`CORE_LOOPS`) on one scene, each unless `--only` leaves it out.
fn core_renders(run: &Run, job: &SceneJob, runs: &mut SceneRuns) {
    let opts = run.opts;
    let core_missing = missing(&runs.requires, &core_features());
    for name in CORE_LOOPS {
        if !wanted(opts, name) {
            continue;
        }
        let exr = job.exr(run, name);
        let rec = if !core_missing.is_empty() {
            skipped_for_features(name, &core_missing)
        } else if let Some(bin) = run.isolate {
            isolated::render(
                opts,
                &job.isolated(run, bin, name, &exr),
                run.version.clone(),
            )
        } else {
            let command = shell_line([
                EXE,
                "render",
                &job.path.display().to_string(),
                "--renderer",
                name,
                "-o",
                &repro_out(&opts.run_dir, &exr.0).display().to_string(),
            ]);
            let (backend, choice) = if name != REFERENCE {
                (Backend::Trace, None)
            } else {
                reference_loop(opts, job.scene)
            };
            let render_opts = RenderOptions {
                spp: opts.core.spp,
                seed: opts.core.seed,
                bias: opts.core.bias,
                ..RenderOptions::default()
            };
            let mut rec = in_process(
                backend,
                job.scene,
                &exr.1,
                &exr.0,
                command,
                run.version.clone(),
                render_opts,
                opts.timeout,
            );
            note_loop_choice(&mut rec, choice);
            // The reference keeps its name whichever loop rendered it (the
            // loops' buffers are bit-identical); `info.loop_choice` says which.
            rec.backend = name.to_string();
            rec
        };
        record(run, runs, name, rec);
    }
}

/// Embree's modes (`EMBREE_MODES`) on one scene: visibility only, so on a
/// shaded scene they still give Z and IDs.
fn embree_renders(run: &Run, job: &SceneJob, runs: &mut SceneRuns) {
    let opts = run.opts;
    for mode in EMBREE_MODES {
        let name = mode.name();
        if !wanted(opts, name) {
            continue;
        }
        let exr = job.exr(run, name);
        let capability = Capability::of(&runs.requires, &embree_features());
        let version = || embree::version().unwrap_or_else(|e| e.to_string());
        let mut rec = if let Capability::Skip(emissing) = &capability {
            skipped_for_features(name, emissing)
        } else if let Some(bin) = run.isolate {
            isolated::render(opts, &job.isolated(run, bin, name, &exr), version())
        } else {
            let scene_arg = job.path.display().to_string();
            let command = shell_line([EXE, "check", "--only", name, &scene_arg]);
            in_process(
                Backend::Embree(mode),
                job.scene,
                &exr.1,
                &exr.0,
                command,
                version(),
                RenderOptions::default(),
                opts.timeout,
            )
        };
        if let Capability::VisibilityOnly(m) = &capability {
            visibility_only(&mut rec, m);
        }
        record(run, runs, name, rec);
    }
}

/// Every external render of every loaded scene, side by side in the job
/// pool (pool.rs), each record added to its scene.
fn render_externals(
    run: &Run,
    list: &[HarnessBackend],
    scenes: &mut [SceneRuns],
    pending: &[Option<ExternalScene>],
    fed: Option<&Fed>,
) {
    let opts = run.opts;
    let tasks: Vec<(usize, &HarnessBackend)> = pending
        .iter()
        .enumerate()
        .filter(|(_, p)| p.is_some())
        .flat_map(|(si, _)| {
            list.iter()
                .filter(|b| wanted(opts, &b.name))
                .map(move |b| (si, b))
        })
        .collect();
    let size = |&(si, b): &(usize, &HarnessBackend)| {
        let triangles = pending[si].as_ref().map_or(0, |p| p.triangles);
        pool::render_memory(b.peak_memory, triangles)
    };
    // Biggest first (the estimate grows with the scene's triangles),
    // so that a large scene does not finish alone at the end.
    let cost = |t: &(usize, &HarnessBackend)| size(t) as f64;
    let waits = |&(si, b): &(usize, &HarnessBackend)| {
        pending[si]
            .as_ref()
            .is_some_and(|p| p.triangles < b.waits_below)
    };
    let pool_opts = pool::PoolOptions {
        // A measuring run (`isolate`) renders one at a time, so that
        // each peak is the render's own.
        jobs: if run.isolate.is_some() { 1 } else { opts.jobs },
        wait_slots: if run.isolate.is_some() {
            0
        } else {
            opts.wait_slots
        },
        memory_budget: opts.memory_budget,
    };
    let done = std::sync::atomic::AtomicUsize::new(0);
    let total = tasks.len();
    let shared: &[SceneRuns] = scenes;
    let mut counts = vec![0; shared.len()];
    for (si, _) in &tasks {
        counts[*si] += 1;
    }
    let streamed = fed.map(|fed| streamed::Scenes::new(fed, shared, &counts));
    // A render's place in its scene's record: its backend's place in `list`.
    let position = |b: &HarnessBackend| list.iter().position(|x| std::ptr::eq(x, b)).unwrap_or(0);
    let recs = pool::run(
        pool_opts,
        &tasks,
        cost,
        waits,
        size,
        |i| {
            (opts.workers && run.isolate.is_none())
                .then(|| worker::Slot::new(run.scratch.join(format!("workers/slot{i}"))))
        },
        |slot, &(si, b)| {
            let p = pending[si].as_ref().expect("tasks are loaded scenes");
            let runs = &shared[si];
            let mut rec = external(opts, b, runs, p, &run.scratch, run.isolate, slot.as_mut());
            run.unstage(&mut rec);
            let k = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            let line = format!("  [{k}/{total}] {} {:<10}", runs.scene, b.name);
            say(opts, format!("{line} {}", describe(&rec)));
            if let Some(s) = &streamed {
                s.arrived(si, position(b), &rec);
            }
            rec
        },
    );
    for ((si, _), rec) in tasks.iter().zip(recs) {
        scenes[*si].renders.push(rec);
    }
}

/// Checks that every loaded scene's export is still as sealed (the
/// comparison reads the run's own copy), then writes manifest.json.
fn write_manifest(
    opts: &CheckOptions,
    scenes: Vec<SceneRuns>,
    pending: &[Option<ExternalScene>],
    shard: Option<ShardRecord>,
) -> Result<Manifest> {
    for (runs, p) in scenes.iter().zip(pending) {
        let Some(p) = p else { continue };
        let folder = p.dir.join("resolved");
        let now = inputs::Seal::of(&folder)?;
        if let Some(what) = p.seal.changes(&now) {
            bail!(
                "{}: the resolved scene of {:?} changed during the run ({what}), though every render read a copy of its own: its verdicts cannot be trusted; run rendiff check again",
                folder.display(),
                crate::scene::printable(&runs.scene, 100)
            );
        }
    }
    let manifest = Manifest {
        format: MANIFEST_FORMAT.into(),
        reference: REFERENCE.into(),
        created_unix: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_secs())
            .unwrap_or(0),
        rendiff_version: env!("CARGO_PKG_VERSION").into(),
        scenes,
        options: Some(run_options(opts)?),
        rerun: Some(rerun_inputs(opts)),
        shard,
    };
    crate::exr_io::write_atomically(&opts.run_dir.join("manifest.json"), |tmp| {
        std::fs::write(tmp, serde_json::to_vec_pretty(&manifest)?)?;
        Ok(())
    })?;
    Ok(manifest)
}
