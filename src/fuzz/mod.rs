//! `rendiff fuzz` and `rendiff reduce` (docs/fuzzing.md): scenes nobody
//! wrote, run through `check`, every failure shrunk to a small repro and
//! grouped with the others of its kind.
//!
//! * [`grammar`]: the seeded generator of valid scenes (same seed, same
//!   files, byte for byte), over [`rng`]'s stable stream;
//! * [`literal`]: standalone scenes of literal triangles, the one format
//!   both the generator and the reducer write;
//! * [`reduce`]: ddmin over objects and triangles, then coordinate snapping,
//!   then a centered crop of the image ([`window`]), with `check` as the
//!   interestingness test;
//! * [`near`]: that test's "near the same triangles";
//! * [`findings`]: failure classes, signatures, findings.json;
//! * [`situation`]: the geometric situation of a finding's scene;
//! * [`known`]: declared findings that classify a run's findings;
//! * [`page`]: the findings page beside the ledger;
//! * [`variants`]: `--from`'s metamorphic variants of real scenes.
//!
//! All generated scenes go through one `check` run (one pool, one set of
//! workers, calibration once), and every reduction batches its candidates
//! into `check` runs too: no process starts per scene that `check` does
//! not already amortise.

pub mod findings;
pub mod grammar;
pub mod known;
pub mod literal;
pub mod near;
pub mod page;
pub mod reduce;
pub mod rng;
pub mod situation;
pub mod variants;
pub mod window;

use crate::check::CheckOptions;
use crate::scene::resolve::ResolvedScene;
use crate::scene::Scene;
use anyhow::{bail, Context, Result};
use findings::{Finding, Ledger, ReducedRecord, FINDINGS_FORMAT};
use literal::LiteralScene;
use reduce::Target;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Most scenes one `fuzz` run generates: a million small scenes is days of
/// rendering; more is a typo.
pub const MAX_COUNT: u64 = 1_000_000;

/// Longest `--minutes`: a week of fuzzing in one run; more is a typo.
pub const MAX_MINUTES: u64 = 7 * 24 * 60;

/// Scenes per batch under `--minutes`: batch `k` is scenes `k * BATCH` to
/// `(k + 1) * BATCH - 1`, one check run each. 50 small scenes are about 10 s
/// through one renderer and 25 s through every built-in one on 2 cores, so
/// the run ends at most that long after the time is up, while the check's
/// start-up (about 3 s) stays a small share of each batch.
pub const BATCH: u64 = 50;

/// How many scenes a fuzz run generates: a fixed count, or batches until
/// a time is up.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Amount {
    /// `--count N`: scenes 0 to N-1, one check run.
    Count(u64),
    /// `--minutes M`: batches of [`BATCH`] scenes, a new one started while
    /// less than M minutes have passed since the run began.
    Minutes(u64),
    /// `--from SCENE...`: no generated scenes; the variants of these scene
    /// files (`variants.rs`), one check run.
    Variants(Vec<PathBuf>),
}

/// What `rendiff fuzz` was asked.
#[derive(Debug, Clone)]
pub struct FuzzOptions {
    /// `--seed`.
    pub seed: u64,
    /// `--count` or `--minutes`.
    pub amount: Amount,
    /// `-o`: the fuzz folder.
    pub folder: PathBuf,
    /// The check's settings (its scenes and run folder are set here).
    pub check: CheckOptions,
    /// Time for each finding's reduction; None reduces nothing.
    pub reduce_budget: Option<Duration>,
    /// `--known`: the folder of known-finding declarations; None is
    /// rendiff's own, `scenes/found/known/` under the check's root.
    pub known: Option<PathBuf>,
}

/// rendiff's own known findings, relative to its root.
pub const KNOWN_DIR: &str = "scenes/found/known";

/// What a fuzz run found.
#[derive(Debug, Clone)]
pub struct FuzzOutcome {
    /// The ledger, as written to FOLDER/findings.json.
    pub ledger: Ledger,
    /// The check's verdict table.
    pub table: String,
}

/// Name of generated scene `index` of run `seed` (its file stem: one folder
/// name, unique in the run).
pub fn scene_name(seed: u64, index: u64) -> String {
    format!("s{seed}_{index:05}")
}

/// The ledger's file name in a fuzz folder.
const MARKER: &str = "findings.json";

/// Writes the `count` scenes of `seed` into `dir` (created); returns their
/// files and each one's primary family, by name.
pub fn write_scenes(
    seed: u64,
    count: u64,
    dir: &Path,
) -> Result<(Vec<PathBuf>, BTreeMap<String, String>)> {
    write_range(seed, 0..count, dir)
}

/// Writes scenes `indices` of `seed` into `dir` (created): a batch of a
/// `--minutes` run, the same files `--count` writes for those indices.
fn write_range(
    seed: u64,
    indices: std::ops::Range<u64>,
    dir: &Path,
) -> Result<(Vec<PathBuf>, BTreeMap<String, String>)> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let mut files = Vec::new();
    let mut families = BTreeMap::new();
    for i in indices {
        let g = grammar::generate(seed, i);
        let name = scene_name(seed, i);
        let file = dir.join(format!("{name}.toml"));
        std::fs::write(&file, g.scene.to_toml())
            .with_context(|| format!("{}: cannot write", file.display()))?;
        families.insert(name, g.families[0].name().to_string());
        files.push(file);
    }
    Ok((files, families))
}

/// What a fuzz folder holds: its own entries, and the check's staging
/// folders (hidden, beside `run`). A folder holding anything else is not one.
fn fuzz_entry(name: &std::ffi::OsStr) -> bool {
    let name = name.to_string_lossy();
    [
        "scenes",
        "run",
        "runs",
        "reduced",
        MARKER,
        page::PAGE,
        page::IMAGES,
    ]
    .contains(&name.as_ref())
        || name.starts_with('.')
}

/// Makes `folder` ready for a fuzz run: created when absent; a folder that
/// holds only what a fuzz writes (a finished one, or one whose check was
/// refused or interrupted) has its scenes and reductions cleared; any other
/// non-empty folder is refused, untouched.
fn prepare(folder: &Path) -> Result<()> {
    if folder.exists() {
        let mut entries = std::fs::read_dir(folder)
            .with_context(|| format!("{}: cannot list", folder.display()))?;
        if let Some(other) =
            entries.find_map(|e| e.ok().map(|e| e.file_name()).filter(|n| !fuzz_entry(n)))
        {
            bail!(
                "{}: not a fuzz folder (it holds {}): give a new folder with -o",
                folder.display(),
                crate::scene::printable(&other.to_string_lossy(), 100)
            );
        }
        for sub in ["scenes", "runs", "reduced", page::IMAGES] {
            let p = folder.join(sub);
            if p.exists() {
                std::fs::remove_dir_all(&p)
                    .with_context(|| format!("{}: cannot clear", p.display()))?;
            }
        }
    }
    std::fs::create_dir_all(folder).with_context(|| format!("{}: cannot create", folder.display()))
}

/// Folder (in the fuzz folder) of batch `k`'s check run under `--minutes`.
pub fn batch_run(k: u64) -> String {
    format!("runs/b{k:04}")
}

/// The `rendiff fuzz` run: generate, check (once, or once per batch under
/// `--minutes`, calibrating in the first only), group, reduce, write the
/// ledger.
pub fn run(opts: &FuzzOptions) -> Result<FuzzOutcome> {
    match opts.amount {
        Amount::Count(n) if n == 0 || n > MAX_COUNT => {
            bail!("--count {n}: give 1 to {MAX_COUNT}")
        }
        Amount::Minutes(m) if m == 0 || m > MAX_MINUTES => {
            bail!("--minutes {m}: give 1 to {MAX_MINUTES}")
        }
        _ => {}
    }
    let known_dir = opts
        .known
        .clone()
        .unwrap_or_else(|| opts.check.root.join(KNOWN_DIR));
    // Before any rendering: a bad declaration is bad input, refused at once.
    let known = known::load(&known_dir)?;
    let folder = &opts.folder;
    prepare(folder)?;
    let scenes_dir = folder.join("scenes");
    let started = Instant::now();
    let mut families = BTreeMap::new();
    let mut verdicts = Vec::new();
    let mut tables = Vec::new();
    let (mut count, mut k) = (0, 0);
    let mut from: Option<variants::Written> = None;
    let run_name = loop {
        let (files, fams, run_name) = match &opts.amount {
            Amount::Count(n) => {
                let (f, fam) = write_range(opts.seed, 0..*n, &scenes_dir)?;
                (f, fam, "run".to_string())
            }
            Amount::Minutes(_) => {
                let (f, fam) = write_range(opts.seed, k * BATCH..(k + 1) * BATCH, &scenes_dir)?;
                (f, fam, batch_run(k))
            }
            Amount::Variants(sources) => {
                let w = variants::write(sources, &scenes_dir)?;
                for why in &w.skipped {
                    crate::errln!("fuzz --from: variant not written: {why}");
                }
                let (f, fam) = (w.files.clone(), w.relation.clone());
                from = Some(w);
                (f, fam, "run".to_string())
            }
        };
        // Bases are checked too (their verdicts are what the variants are held to).
        let generated = files.len() - from.as_ref().map_or(0, |w| w.files.len() - w.base.len());
        count += generated as u64;
        families.extend(fams);
        let check = CheckOptions {
            scenes: files,
            run_dir: folder.join(&run_name),
            // Calibration judges the camera, not the scenes: once per run.
            calibration: if k == 0 {
                opts.check.calibration.clone()
            } else {
                None
            },
            ..opts.check.clone()
        };
        let outcome = crate::check::run(&check)?;
        verdicts.extend(crate::gate::verdicts(&outcome.results)?);
        tables.push(outcome.table);
        k += 1;
        match opts.amount {
            Amount::Minutes(m)
                if started.elapsed() < Duration::from_secs(m * 60) && count < MAX_COUNT => {}
            Amount::Minutes(_) => break "runs".to_string(),
            Amount::Count(_) | Amount::Variants(_) => break run_name,
        }
    };
    let table = tables.join("\n");
    let mut base_failures = Vec::new();
    if let Some(w) = &from {
        let (held, of_bases) = hold_to_bases(verdicts, w);
        verdicts = held;
        base_failures = of_bases;
    }
    let (failures, camera_failures, grouped) = findings::group(&verdicts, &families);
    let mut found = split_findings(opts, grouped, &failures, &families)?;
    for f in &mut found {
        let s = &f.signature;
        f.classification = Some(known::classify(
            &known,
            &s.backend,
            &s.buffer,
            &s.class,
            &s.situation,
        ));
    }
    let ledger = Ledger {
        format: FINDINGS_FORMAT.into(),
        seed: opts.seed,
        scenes: count,
        run: run_name,
        from: match &opts.amount {
            Amount::Variants(sources) => sources.iter().map(|p| p.display().to_string()).collect(),
            _ => Vec::new(),
        },
        base_failures,
        failures,
        camera_failures,
        findings: found,
    };
    let json = serde_json::to_string_pretty(&ledger)? + "\n";
    crate::exr_io::write_atomically(&folder.join(MARKER), |tmp| Ok(std::fs::write(tmp, &json)?))?;
    page::write(folder, &ledger)?;
    Ok(FuzzOutcome { ledger, table })
}

/// `--from`: the variants' verdicts whose class differs from their base's on
/// the same backend and buffer (the reason then names the base's class), and
/// the bases' own failing verdicts (reported, not reduced: the variants are
/// the fuzz's scenes). Calibration probes pass through.
fn hold_to_bases(
    verdicts: Vec<crate::gate::Verdict>,
    w: &variants::Written,
) -> (Vec<crate::gate::Verdict>, Vec<findings::Failure>) {
    let bases: std::collections::BTreeSet<&String> = w.base.values().collect();
    let base_class: BTreeMap<(String, String, String), Option<String>> = verdicts
        .iter()
        .filter(|v| bases.contains(&v.scene))
        .map(|v| {
            (
                (v.scene.clone(), v.backend.clone(), v.buffer.clone()),
                findings::failure_class(v),
            )
        })
        .collect();
    let mut of_bases = Vec::new();
    let mut held = Vec::new();
    for mut v in verdicts {
        if bases.contains(&v.scene) {
            if let Some(class) = findings::failure_class(&v) {
                of_bases.push(findings::Failure {
                    scene: v.scene.clone(),
                    backend: v.backend.clone(),
                    buffer: v.buffer.clone(),
                    class,
                    reason: crate::scene::printable(&v.reason, 300),
                });
            }
            continue;
        }
        let Some(base) = w.base.get(&v.scene) else {
            held.push(v); // a calibration probe
            continue;
        };
        let Some(class) = findings::failure_class(&v) else {
            continue;
        };
        let was = base_class
            .get(&(base.clone(), v.backend.clone(), v.buffer.clone()))
            .cloned()
            .flatten();
        if was.as_deref() == Some(class.as_str()) {
            continue;
        }
        v.reason = format!(
            "base {base}: {}; this variant: {}",
            was.as_deref().unwrap_or("pass"),
            v.reason
        );
        held.push(v);
    }
    (held, of_bases)
}

/// The situation of a scene file (`situation.rs`); empty when it does not resolve.
fn situation_of(file: &Path) -> Vec<String> {
    Scene::load(file)
        .ok()
        .and_then(|s| ResolvedScene::resolve(&s).ok())
        .map_or_else(Vec::new, |r| situation::situations(&r))
}

/// Splits each (backend, buffer, class) group by the situation of its
/// reduced scenes ([`findings::split`]), reducing within `--reduce-budget`;
/// the findings in signature order, numbered `F1`, `F2`, ..., each reduced
/// scene at `reduced/F<n>.toml`.
fn split_findings(
    opts: &FuzzOptions,
    grouped: Vec<Finding>,
    failures: &[findings::Failure],
    families: &BTreeMap<String, String>,
) -> Result<Vec<Finding>> {
    let folder = &opts.folder;
    let scene_file = |s: &str| folder.join("scenes").join(format!("{s}.toml"));
    let cache = std::cell::RefCell::new(BTreeMap::<String, Vec<String>>::new());
    let own = |s: &str| -> Vec<String> {
        if let Some(t) = cache.borrow().get(s) {
            return t.clone();
        }
        let t = situation_of(&scene_file(s));
        cache.borrow_mut().insert(s.to_string(), t.clone());
        t
    };
    let size = |s: &str| std::fs::metadata(scene_file(s)).map_or(u64::MAX, |m| m.len());
    let mut pending = 0;
    let mut found = Vec::new();
    for g in grouped {
        let sig = g.signature;
        let mut reduce = |s: &str| -> Option<(ReducedRecord, Vec<String>)> {
            let budget = opts.reduce_budget?;
            pending += 1;
            let r = reduce_scene(opts, &sig, s, &format!(".pending{pending}"), budget);
            let situation = if r.error.is_empty() {
                situation_of(&folder.join(&r.scene))
            } else {
                own(s)
            };
            Some((r, situation))
        };
        for part in findings::split(&g.scenes, &own, &size, &mut reduce) {
            let mut fams = BTreeMap::new();
            for s in &part.scenes {
                if let Some(f) = families.get(s) {
                    *fams.entry(f.clone()).or_insert(0) += 1;
                }
            }
            let reason = failures
                .iter()
                .find(|f| {
                    f.scene == part.scenes[0]
                        && f.backend == sig.backend
                        && f.buffer == sig.buffer
                        && f.class == sig.class
                })
                .map_or_else(|| g.reason.clone(), |f| f.reason.clone());
            found.push(Finding {
                id: String::new(),
                signature: findings::Signature {
                    situation: part.situation,
                    ..sig.clone()
                },
                hits: part.scenes.len(),
                scenes: part.scenes,
                families: fams,
                reason,
                reduced: part.reduced,
                classification: None,
            });
        }
    }
    found.sort_by(|a, b| a.signature.cmp(&b.signature));
    for (i, f) in found.iter_mut().enumerate() {
        f.id = format!("F{}", i + 1);
        if let Some(r) = f.reduced.as_mut().filter(|r| r.error.is_empty()) {
            let to = format!("reduced/{}.toml", f.id);
            std::fs::rename(folder.join(&r.scene), folder.join(&to))
                .with_context(|| format!("{}: cannot rename", folder.join(&r.scene).display()))?;
            r.command = reproduce_command(
                &folder.join(&to),
                &f.signature.backend,
                opts.check.renderers.as_deref(),
            );
            r.scene = to;
        }
    }
    Ok(found)
}

/// Reduces `scene` (a generated scene's name) for `sig` into
/// `reduced/NAME.toml`; a reduction that fails is recorded with its reason.
fn reduce_scene(
    opts: &FuzzOptions,
    sig: &findings::Signature,
    scene: &str,
    name: &str,
    budget: Duration,
) -> ReducedRecord {
    let scene_file = opts.folder.join("scenes").join(format!("{scene}.toml"));
    let out = opts.folder.join("reduced").join(format!("{name}.toml"));
    let target = Target {
        backend: sig.backend.clone(),
        buffer: sig.buffer.clone(),
        class: sig.class.clone(),
    };
    let work = opts.folder.join("reduced").join(format!("{name}.work"));
    match reduce_file(&scene_file, &target, &opts.check, &work, Some(budget), &out) {
        Ok(mut r) => {
            r.scene = format!("reduced/{name}.toml");
            r.from = scene.to_string();
            r
        }
        Err(e) => ReducedRecord {
            from: scene.to_string(),
            error: format!("{e:#}"),
            ..ReducedRecord::default()
        },
    }
}

/// The standalone rewrite of a scene file (literal triangles, explicit near).
pub fn standalone(scene_file: &Path) -> Result<LiteralScene> {
    let scene = Scene::load(scene_file)?;
    let resolved = ResolvedScene::resolve(&scene)?;
    LiteralScene::from_resolved(&resolved, "")
        .map_err(|e| anyhow::anyhow!("{}: {e}", scene_file.display()))
}

/// Reduces `scene_file` for `target` and writes the result to `out`
/// (atomically); the record has its sizes and the command that reproduces it.
pub fn reduce_file(
    scene_file: &Path,
    target: &Target,
    template: &CheckOptions,
    work: &Path,
    budget: Option<Duration>,
    out: &Path,
) -> Result<ReducedRecord> {
    let start = standalone(scene_file)?;
    let description = format!(
        "reduced by rendiff reduce: {} fails {} with class {}",
        target.backend, target.buffer, target.class
    );
    let before_text = std::fs::read_to_string(scene_file)
        .with_context(|| format!("{}: cannot read", scene_file.display()))?;
    let r = reduce::reduce(&start, target, template, work, budget, &description)?;
    let text = r.scene.to_toml();
    if let Some(dir) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create", dir.display()))?;
    }
    crate::exr_io::write_atomically(out, |tmp| Ok(std::fs::write(tmp, &text)?))?;
    Ok(ReducedRecord {
        from: scene_file.display().to_string(),
        scene: out.display().to_string(),
        command: reproduce_command(out, &target.backend, template.renderers.as_deref()),
        triangles_before: start.triangle_count(),
        triangles_after: r.scene.triangle_count(),
        objects_before: start.objects.len(),
        objects_after: r.scene.objects.len(),
        lights_before: start.lights.len(),
        lights_after: r.scene.lights.len(),
        bytes_before: before_text.len(),
        bytes_after: text.len(),
        image_before: [start.camera.width, start.camera.height],
        image_after: [r.scene.camera.width, r.scene.camera.height],
        image_note: r.image_note.unwrap_or_default(),
        check_runs: r.check_runs,
        candidates: r.candidates,
        complete: r.complete,
        failure_triangles: r.failure_triangles,
        failure_size: r.failure_size,
        error: String::new(),
    })
}

/// `rendiff check SCENE --only B [--renderers FILE] -o RUN`, shell-quoted.
pub fn reproduce_command(scene: &Path, backend: &str, renderers: Option<&Path>) -> String {
    let mut words = vec![
        "rendiff".to_string(),
        "check".into(),
        scene.display().to_string(),
        "--only".into(),
        backend.to_string(),
    ];
    if let Some(r) = renderers {
        words.push("--renderers".into());
        words.push(r.display().to_string());
    }
    let run = scene.with_extension("run");
    words.push("-o".into());
    words.push(run.display().to_string());
    crate::check::process::shell_line(words)
}

/// The failing verdict of `scene` on `backend` in a finished run (the first
/// failing buffer, or `buffer`), as a reduction target, and the scene's file.
pub fn target_in_run(
    run: &Path,
    scene: &str,
    backend: &str,
    buffer: Option<&str>,
) -> Result<(Target, PathBuf)> {
    crate::check::run_folder::ensure_complete(run)?;
    let verdicts = crate::gate::load_verdicts(&run.join("results.json"))?;
    let v = verdicts
        .iter()
        .filter(|v| v.scene == scene && v.backend == backend)
        .filter(|v| buffer.is_none_or(|b| v.buffer == b))
        .find_map(|v| findings::failure_class(v).map(|c| (v, c)));
    let Some((v, class)) = v else {
        bail!(
            "{}: no failing verdict for scene {} on backend {}{}",
            run.display(),
            crate::scene::printable(scene, 100),
            crate::scene::printable(backend, 100),
            buffer.map_or(String::new(), |b| format!(
                ", buffer {}",
                crate::scene::printable(b, 20)
            ))
        );
    };
    let manifest_path = run.join("manifest.json");
    let text = crate::check::manifest::read_record(&manifest_path)
        .map_err(|e| anyhow::anyhow!("{}: {e}", manifest_path.display()))?;
    let manifest: crate::check::manifest::Manifest = serde_json::from_str(&text)
        .with_context(|| format!("{}: not a valid manifest", manifest_path.display()))?;
    let Some(entry) = manifest.scenes.iter().find(|s| s.scene == scene) else {
        bail!(
            "{}: no scene {} in the run",
            manifest_path.display(),
            crate::scene::printable(scene, 100)
        );
    };
    Ok((
        Target {
            backend: backend.to_string(),
            buffer: v.buffer.clone(),
            class,
        },
        PathBuf::from(&entry.scene_file),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gate::{Status, Verdict};

    fn v(scene: &str, backend: &str, status: Status, interior: u64) -> Verdict {
        Verdict {
            scene: scene.into(),
            backend: backend.into(),
            buffer: "id".into(),
            status,
            reason: "why".into(),
            counts: [("interior_mismatches".to_string(), interior)].into(),
            errors: BTreeMap::new(),
        }
    }

    #[test]
    fn variants_are_held_to_their_base_verdict_class() {
        let mut w = variants::Written::default();
        for rel in ["translate", "mirror"] {
            let name = variants::variant_name("m0_a", rel);
            w.base.insert(name.clone(), "m0_a".into());
            w.relation.insert(name, rel.into());
        }
        let verdicts = vec![
            // The base passes on povray and fails (interior) on mitsuba.
            v("m0_a", "povray", Status::Pass, 0),
            v("m0_a", "mitsuba", Status::Fail, 3),
            // translate: povray now fails (a finding); mitsuba fails as its base does (none).
            v("m0_a__translate", "povray", Status::Fail, 5),
            v("m0_a__translate", "mitsuba", Status::Fail, 7),
            // mirror: both as the base (none), and a calibration probe passes through.
            v("m0_a__mirror", "povray", Status::Pass, 0),
            v("m0_a__mirror", "mitsuba", Status::Fail, 1),
            v("camera_far", "povray", Status::Fail, 0),
        ];
        let (held, bases) = hold_to_bases(verdicts, &w);
        let keys: Vec<(&str, &str)> = held
            .iter()
            .map(|v| (v.scene.as_str(), v.backend.as_str()))
            .collect();
        assert_eq!(
            keys,
            vec![("m0_a__translate", "povray"), ("camera_far", "povray")]
        );
        assert!(held[0]
            .reason
            .starts_with("base m0_a: pass; this variant: "));
        assert_eq!(bases.len(), 1);
        assert_eq!(
            (bases[0].backend.as_str(), bases[0].class.as_str()),
            ("mitsuba", "interior")
        );
    }
}
