//! `rendiff reduce`: shrinks a failing scene to a small standalone repro by
//! delta debugging (Zeller and Hildebrandt's ddmin), first over objects,
//! then over a shaded scene's lights (none at all tried first), then over
//! triangles (each keeps its object's material), then over vertex precision (every coordinate
//! snapped to a coarser power-of-two grid, the coarsest that still fails),
//! then over the image (the smallest centered crop that still fails,
//! [`super::window`]), repeated until a round changes nothing
//! (docs/fuzzing.md).
//!
//! The interestingness test is "the same backend still fails the same
//! buffer with the same class" ([`super::findings::failure_class`]) "near
//! the same triangles" ([`super::near`]: its failing pixels on, or within a
//! pixel of, a triangle the first failure's pixels were on, triangles
//! followed by their index in the starting scene) "at a comparable size"
//! (an RGB failure's largest interior error at least [`SIZE_FRACTION`] of
//! the first one's, [`holds_size`]), asked of `check`
//! itself: candidates are written as scene files and checked together, a
//! batch per `check` run, so the harness's workers, the pool and the
//! comparison start once per batch, not per candidate. Candidates
//! are tried in ddmin's order and the first interesting one wins, so the
//! result is the one sequential ddmin would give. Calibration is not rerun
//! (the run being reduced judged the camera already): a reduction asks
//! only whether the failure persists.

use super::findings::failure_class;
use super::literal::{LiteralScene, Tri};
use super::near::{self, Group};
use super::rng::pow2;
use super::window;
use crate::check::manifest::ResultEntry;
use crate::check::CheckOptions;
use crate::scene::resolve::ResolvedScene;
use crate::scene::Scene;
use anyhow::{bail, Context, Result};
use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What must keep failing.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Target {
    /// Backend.
    pub backend: String,
    /// Buffer (`id`, `Z`, `N`, ...).
    pub buffer: String,
    /// Class ([`failure_class`]).
    pub class: String,
}

/// Candidates per `check` run. A run costs a fixed start (the harness's
/// `info`, a worker, the comparison's start) plus each candidate's render
/// and comparison; 12 keeps that start under half of a batch of small
/// scenes while a round that finds its candidate early wastes few renders.
pub const BATCH: usize = 12;

/// Most rounds of (objects, triangles, snapping) before giving up on a
/// fixed point; each round after the first usually changes only the snap.
pub const MAX_ROUNDS: usize = 6;

/// Crops tried per axis in each `check` run of the image step. Each run
/// costs its start (about 8 candidates' renders, measured: 13 runs of 118
/// candidates took 160 s, about 6 s a start and 0.7 s a candidate, on 2
/// shared cores) plus a render per candidate, and `n` crops cut the
/// interval searched `n + 1`-fold, so the cost per halving,
/// `(start + 2n) / log2(n + 1)` candidates' worth, is least near `n = 4`;
/// the last run, which only confirms that nothing more holds, then asks 8
/// crops, not 24. (seed 1's s1_00007, 128x96 to 10x36: 13 runs of 118
/// candidates with 12 crops per axis, 15 runs of 89 with 4, 2m21 for the
/// whole 8-scene fuzz.)
pub const CROPS_PER_AXIS: u32 = 4;

/// How small a candidate's failure may be, as a fraction of the first
/// failure's size ([`failure_size`]), and still count as the same failure.
///
/// What it must keep out: a reduction that drifts to another failure of the
/// same class on the same triangle. Reducing the POV-Ray RGB failure of
/// `two_lights_shadowless`'s `translate` variant (an error of 8e-6 at its
/// worst pixel) ended on a light in the triangle's plane, the reference
/// 4e-15 and POV-Ray 0: nine orders of magnitude smaller, and an unrelated
/// rounding. What it must let through: the steps that keep a failure while
/// changing its size. Objects and triangles that do not shade the failing
/// pixel leave its error alone; snapping and cropping move a point's
/// shading by a fraction; removing a light keeps the share of the error it
/// did not carry: a fault in the shading of each light (an albedo or
/// cosine bug) is a sum over the lights at the pixel, so keeping the one
/// that carries the most keeps at least 1/k of it with k lights, 1/8 with up
/// to 8 lit equally (more lights, and ddmin keeps more of them). The
/// quantization of an 8- or 16-bit output changes the error by at most the
/// tolerance's absolute part, below the error of a failure that is beyond
/// it. So 1/8: an order of magnitude for what a reduction may legitimately
/// do, far above the drift it stops.
pub const SIZE_FRACTION: f64 = 0.125;

/// The size of an entry's failure: an `RGB` entry's `interior_max_abs_error`
/// (the largest |test - reference| at an interior failing pixel,
/// docs/run-format.md); None when the entry records none (other buffers,
/// whose classes and triangles already pin a failure down).
pub fn failure_size(entry: &ResultEntry) -> Option<f64> {
    entry
        .details
        .get("interior_max_abs_error")?
        .as_f64()
        .filter(|x| x.is_finite())
}

/// Whether a candidate's failure (size `cand`) is comparable to the first
/// failure (size `first`): at least [`SIZE_FRACTION`] of it. Always when the
/// first has no size; never when it has one and the candidate has none (a
/// failure of non-finite values only, not the finite one being reduced).
pub fn holds_size(first: Option<f64>, cand: Option<f64>) -> bool {
    match first {
        None => true,
        Some(f) => cand.is_some_and(|c| c >= SIZE_FRACTION * f),
    }
}

/// The result of a reduction.
#[derive(Debug, Clone)]
pub struct Reduction {
    /// The reduced scene.
    pub scene: LiteralScene,
    /// `check` runs and candidate scenes rendered.
    pub check_runs: usize,
    /// (see above)
    pub candidates: usize,
    /// False when the time budget ran out before a fixed point.
    pub complete: bool,
    /// The triangles (indices in the starting scene) the first failure's
    /// pixels were on, which every accepted candidate's failure stayed near;
    /// None when the verifier names none (no explanations: a side without
    /// `id.prim`, an error), and the test was the class alone.
    pub failure_triangles: Option<Vec<usize>>,
    /// The first failure's size ([`failure_size`]), which every accepted
    /// candidate's stayed comparable to ([`holds_size`]); None when the
    /// entry records none.
    pub failure_size: Option<f64>,
    /// Set when the image step tried crops and kept the image as it was:
    /// why, for the log.
    pub image_note: Option<String>,
}

/// A candidate: a scene, and for each of its triangles (in prim order) its
/// index in the scene the reduction started from.
#[derive(Debug, Clone)]
struct Cand {
    scene: LiteralScene,
    origin: Vec<usize>,
}

impl Cand {
    /// What the cache knows it by: its text and its triangles' origins
    /// (the same text with other origins may be near other triangles).
    fn key(&self) -> String {
        let ids: Vec<String> = self.origin.iter().map(usize::to_string).collect();
        format!("{}\n# origin {}", self.scene.to_toml(), ids.join(" "))
    }
}

/// A candidate's failure as the target says, as its `check` run recorded it.
#[derive(Debug, Clone)]
struct Failure {
    /// Its failing pixel groups ([`near::failing_groups`]; None when the
    /// verifier names none).
    groups: Option<Vec<Group>>,
    /// Its size ([`failure_size`]).
    size: Option<f64>,
}

/// What a `check` run says of one candidate: None when it does not fail as
/// the target says.
type Answer = Option<Failure>;

/// Ran out of the time budget (the reduction keeps what it has).
struct OutOfTime;

/// The interestingness test, with its cache and counters.
struct Oracle<'a> {
    template: &'a CheckOptions,
    work: PathBuf,
    target: Target,
    cache: HashMap<String, bool>,
    /// The first failure's triangles ([`Reduction::failure_triangles`]);
    /// None until it is known, or when the verifier names none.
    footprint: Option<BTreeSet<usize>>,
    /// The first failure's size ([`Reduction::failure_size`]).
    size: Option<f64>,
    check_runs: usize,
    candidates: usize,
    /// Crops the image step asked about (cached or not).
    crops_tried: usize,
    deadline: Option<Instant>,
}

/// Whether the core accepts a scene (parsed, validated, resolved): a
/// candidate it refuses (a triangle snapped to zero area, no objects) is
/// not interesting and is never rendered.
pub fn valid(scene: &LiteralScene) -> bool {
    if scene.objects.is_empty() {
        return false;
    }
    Scene::parse(Path::new("candidate.toml"), &scene.to_toml())
        .ok()
        .is_some_and(|s| ResolvedScene::resolve(&s).is_ok())
}

impl Oracle<'_> {
    /// The index of the first interesting candidate, testing in batches of
    /// [`BATCH`] and stopping after the batch that holds one.
    fn first(&mut self, cands: &[Cand]) -> Result<Result<Option<usize>, OutOfTime>> {
        let texts: Vec<String> = cands.iter().map(Cand::key).collect();
        let mut i = 0;
        while i < cands.len() {
            match self.cache.get(&texts[i]) {
                Some(true) => return Ok(Ok(Some(i))),
                Some(false) => i += 1,
                // Candidate i is in the next batch (or refused): then cached.
                None => {
                    if let Err(e) = self.batch(i, BATCH, cands, &texts)? {
                        return Ok(Err(e));
                    }
                }
            }
        }
        Ok(Ok(None))
    }

    /// Whether each candidate is interesting: every one not yet known is
    /// asked, all in one `check` run (the image step wants every answer, so
    /// a larger batch wastes nothing).
    fn all(&mut self, cands: &[Cand]) -> Result<Result<Vec<bool>, OutOfTime>> {
        let texts: Vec<String> = cands.iter().map(Cand::key).collect();
        if let Err(e) = self.batch(0, cands.len(), cands, &texts)? {
            return Ok(Err(e));
        }
        Ok(Ok(texts
            .iter()
            .map(|t| self.cache.get(t) == Some(&true))
            .collect()))
    }

    /// Asks one `check` run about the next `size` distinct candidates from
    /// `from` on that the cache does not know, and caches the answers; those
    /// the core refuses ([`valid`]) are cached as not interesting, unrendered.
    fn batch(
        &mut self,
        from: usize,
        size: usize,
        cands: &[Cand],
        texts: &[String],
    ) -> Result<Result<(), OutOfTime>> {
        let mut batch: Vec<usize> = Vec::new();
        let mut j = from;
        while j < cands.len() && batch.len() < size {
            let new =
                !self.cache.contains_key(&texts[j]) && !batch.iter().any(|&b| texts[b] == texts[j]);
            if new {
                if valid(&cands[j].scene) {
                    batch.push(j);
                } else {
                    self.cache.insert(texts[j].clone(), false);
                }
            }
            j += 1;
        }
        if !batch.is_empty() && self.deadline.is_some_and(|d| Instant::now() >= d) {
            return Ok(Err(OutOfTime));
        }
        let answers = self.test(&batch, cands)?;
        for (k, answer) in batch.iter().zip(answers) {
            let interesting = same_failure(
                self.footprint.as_ref(),
                self.size,
                &cands[*k],
                answer.as_ref(),
            );
            self.cache.insert(texts[*k].clone(), interesting);
        }
        Ok(Ok(()))
    }

    /// Checks the starting scene alone: whether it fails as the target
    /// says, and the triangles its failing pixels are on (the footprint
    /// every later candidate is held to).
    fn establish(&mut self, start: &Cand) -> Result<bool> {
        let mut answers = self.test(&[0], std::slice::from_ref(start))?;
        let Some(first) = answers.pop().flatten() else {
            return Ok(false);
        };
        self.footprint = first.groups.map(|g| near::on_triangles(&g, &start.origin));
        self.size = first.size;
        self.cache.insert(start.key(), true);
        Ok(true)
    }

    /// One `check` run over the candidates `which`: for each, None when it
    /// does not fail as the target says, else its [`Failure`].
    fn test(&mut self, which: &[usize], cands: &[Cand]) -> Result<Vec<Answer>> {
        if which.is_empty() {
            return Ok(Vec::new());
        }
        let dir = self.work.join("candidates");
        if dir.exists() {
            std::fs::remove_dir_all(&dir)
                .with_context(|| format!("{}: cannot clear", dir.display()))?;
        }
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("{}: cannot create", dir.display()))?;
        let mut files = Vec::new();
        for (n, &k) in which.iter().enumerate() {
            let f = dir.join(format!("c{n:03}.toml"));
            std::fs::write(&f, cands[k].scene.to_toml())
                .with_context(|| format!("{}: cannot write", f.display()))?;
            files.push(f);
        }
        let opts = CheckOptions {
            scenes: files,
            run_dir: self.work.join("run"),
            only: Some(vec![self.target.backend.clone()]),
            calibration: None,
            quiet: true,
            ..self.template.clone()
        };
        let outcome = crate::check::run(&opts)?;
        let verdicts = crate::gate::verdicts(&outcome.results)?;
        self.check_runs += 1;
        self.candidates += which.len();
        let t = &self.target;
        Ok((0..which.len())
            .map(|n| {
                let name = format!("c{n:03}");
                let fails = verdicts.iter().any(|v| {
                    v.scene == name
                        && v.backend == t.backend
                        && v.buffer == t.buffer
                        && failure_class(v).as_deref() == Some(t.class.as_str())
                });
                fails.then(|| {
                    let entry = outcome.results.results.iter().find(|e| {
                        e.scene == name && e.backend == t.backend && e.buffer == t.buffer
                    });
                    Failure {
                        groups: entry.and_then(|e| near::failing_groups(e, &t.class)),
                        size: entry.and_then(failure_size),
                    }
                })
            })
            .collect())
    }
}

/// Whether a candidate's `check` answer is the first failure again: it
/// failed as the target says, at a comparable size ([`holds_size`] against
/// `size`, the first failure's), and near the first failure's triangles
/// (`footprint`; any triangles when the verifier named none the first time,
/// none when it names none now).
fn same_failure(
    footprint: Option<&BTreeSet<usize>>,
    size: Option<f64>,
    cand: &Cand,
    answer: Option<&Failure>,
) -> bool {
    let Some(failure) = answer else {
        return false;
    };
    if !holds_size(size, failure.size) {
        return false;
    }
    let Some(footprint) = footprint else {
        return true;
    };
    let Some(groups) = &failure.groups else {
        return false;
    };
    let resolved = Scene::parse(Path::new("candidate.toml"), &cand.scene.to_toml())
        .ok()
        .and_then(|s| ResolvedScene::resolve(&s).ok());
    resolved.is_some_and(|r| !near::near_triangles(groups, &cand.origin, &r).is_disjoint(footprint))
}

/// Delta debugging over `n_units` units: `build(keep)` makes the scene
/// holding the units whose indices are in `keep` (in order). Returns the
/// 1-minimal subset ddmin reaches (or what it had when time ran out).
/// ddmin never tries the empty set (a scene needs an object); with
/// `empty_too` (lights: a scene may have none) the empty set is tried
/// first, in the first round's batch, and wins if it holds.
fn ddmin(
    n_units: usize,
    build: &dyn Fn(&[usize]) -> Cand,
    oracle: &mut Oracle,
    empty_too: bool,
) -> Result<Result<Vec<usize>, Vec<usize>>> {
    let mut units: Vec<usize> = (0..n_units).collect();
    let mut n = 2usize;
    let mut try_empty = empty_too && n_units > 0;
    while units.len() >= 2 || try_empty {
        let chunks: Vec<Vec<usize>> = if units.len() >= 2 {
            split(&units, n)
        } else {
            Vec::new()
        };
        let mut cands: Vec<Vec<usize>> = chunks.clone();
        if n > 2 {
            for c in &chunks {
                cands.push(units.iter().copied().filter(|u| !c.contains(u)).collect());
            }
        }
        // The empty set first, so that it wins when it holds.
        let skip = usize::from(try_empty);
        if try_empty {
            cands.insert(0, Vec::new());
            try_empty = false;
        }
        let scenes: Vec<Cand> = cands.iter().map(|k| build(k)).collect();
        match oracle.first(&scenes)? {
            Err(OutOfTime) => return Ok(Err(units)),
            Ok(Some(0)) if skip == 1 => return Ok(Ok(Vec::new())),
            Ok(Some(i)) if i - skip < chunks.len() => {
                units = cands[i].clone();
                n = 2;
            }
            Ok(Some(i)) => {
                units = cands[i].clone();
                n = (n - 1).max(2);
            }
            Ok(None) => {
                if units.len() < 2 || n >= units.len() {
                    break;
                }
                n = (2 * n).min(units.len());
            }
        }
    }
    Ok(Ok(units))
}

/// `units` in `n` nearly equal consecutive chunks.
fn split(units: &[usize], n: usize) -> Vec<Vec<usize>> {
    let mut out = Vec::with_capacity(n);
    let mut start = 0;
    for k in 0..n {
        let end = units.len() * (k + 1) / n;
        out.push(units[start..end].to_vec());
        start = end;
    }
    out.retain(|c| !c.is_empty());
    out
}

/// The scene with only the objects `keep`.
fn keep_objects(s: &LiteralScene, keep: &[usize]) -> LiteralScene {
    let mut out = s.clone();
    out.objects = keep.iter().map(|&i| s.objects[i].clone()).collect();
    out
}

/// [`keep_objects`] of a candidate, its kept triangles' origins with it.
fn cand_objects(c: &Cand, keep: &[usize]) -> Cand {
    let mut starts = Vec::with_capacity(c.scene.objects.len());
    let mut k = 0;
    for o in &c.scene.objects {
        starts.push(k);
        k += o.triangles.len();
    }
    let origin = keep
        .iter()
        .flat_map(|&i| {
            let n = c.scene.objects[i].triangles.len();
            c.origin[starts[i]..starts[i] + n].iter().copied()
        })
        .collect();
    Cand {
        scene: keep_objects(&c.scene, keep),
        origin,
    }
}

/// The candidate with only the lights `keep` (its triangles unchanged).
fn cand_lights(c: &Cand, keep: &[usize]) -> Cand {
    let mut out = c.clone();
    out.scene.lights = keep.iter().map(|&i| c.scene.lights[i].clone()).collect();
    out
}

/// [`keep_triangles`] of a candidate, its kept triangles' origins with it.
fn cand_triangles(c: &Cand, keep: &[usize]) -> Cand {
    Cand {
        scene: keep_triangles(&c.scene, keep),
        origin: keep.iter().map(|&i| c.origin[i]).collect(),
    }
}

/// The scene with only the triangles `keep` (indices over all objects in
/// order); objects left empty are dropped.
fn keep_triangles(s: &LiteralScene, keep: &[usize]) -> LiteralScene {
    let mut out = s.clone();
    let mut k = 0;
    let mut next = keep.iter().peekable();
    for o in &mut out.objects {
        let mut tris = Vec::new();
        for t in &o.triangles {
            if next.peek() == Some(&&k) {
                tris.push(*t);
                next.next();
            }
            k += 1;
        }
        o.triangles = tris;
    }
    out.objects.retain(|o| !o.triangles.is_empty());
    out
}

/// Every vertex coordinate rounded to the nearest multiple of `2^e`
/// (exact: a division and a product by a power of two, and a round).
fn snapped(s: &LiteralScene, e: i32) -> LiteralScene {
    let g = pow2(e);
    let mut out = s.clone();
    for o in &mut out.objects {
        for t in &mut o.triangles {
            for v in t.iter_mut() {
                for x in v.iter_mut() {
                    *x = (*x / g).round() * g;
                }
            }
        }
    }
    out
}

/// The binary exponent of the largest vertex coordinate's magnitude.
fn top_exponent(s: &LiteralScene) -> i32 {
    let m = s
        .objects
        .iter()
        .flat_map(|o| o.triangles.iter())
        .flat_map(|t: &Tri| t.iter())
        .flat_map(|v| v.iter())
        .fold(0.0f64, |m, x| m.max(x.abs()));
    if m == 0.0 {
        return 0;
    }
    ((m.to_bits() >> 52) & 0x7ff) as i32 - 1023
}

/// Grids tried, coarsest first: from twice the largest coordinate down to
/// 2^-24 of it (f32's precision: finer snaps change nothing of the largest
/// coordinates, and the reduced scene is written from f32 values anyway).
fn snap_candidates(s: &LiteralScene) -> Vec<LiteralScene> {
    let top = top_exponent(s);
    let current = s.to_toml();
    let mut out: Vec<LiteralScene> = Vec::new();
    for e in (top - 24..=top + 1).rev() {
        let c = snapped(s, e);
        let text = c.to_toml();
        if text == current {
            // Finer grids keep it as it is too.
            break;
        }
        if out.last().is_some_and(|p| p.to_toml() == text) {
            continue;
        }
        out.push(c);
    }
    out
}

/// The image step: the smallest centered crop ([`window::crop`]) that
/// still fails. Per axis a search for the largest crop per side that
/// holds, both axes in each `check` run: [`window::probes`] spaces up to
/// [`CROPS_PER_AXIS`] crops of an axis between the largest known to hold (none at
/// first) and the smallest known not to (past the largest possible at
/// first), the other axis at its current crop; the largest that holds is
/// taken, and the next run looks between it and the next larger one tried,
/// until no crop is left between on either axis. When both axes gained in
/// one run, only the columns' gain is taken (the two together were not
/// tried) and the rows are searched again from where they were. That finds
/// the largest crops when holding is monotone in them (one failing region);
/// where it is not, it finds crops that hold, and every crop kept is one the
/// interestingness test passed. The verifier's example pixels do not bound
/// it: each is only the first pixel of its group, not the group's extent.
/// Triangles stay (the origins are unchanged). `Err` with what it had when
/// the time ran out.
fn crop_image(oracle: &mut Oracle, start: Cand) -> Result<Result<Cand, Cand>> {
    let base = start.clone();
    let cam = &base.scene.camera;
    let mut lo = [0u32; 2];
    let mut hi = [cam.width, cam.height].map(|side| window::max_crop(side) + 1);
    let mut cur = start;
    loop {
        let mut tries: Vec<(usize, u32, Cand)> = Vec::new();
        for axis in 0..2 {
            for k in window::probes(lo[axis], hi[axis], CROPS_PER_AXIS) {
                let mut at = lo;
                at[axis] = k;
                if let Some(camera) = window::crop(cam, at[0], at[1]) {
                    let mut c = base.clone();
                    c.scene.camera = camera;
                    tries.push((axis, k, c));
                }
            }
        }
        if tries.is_empty() {
            return Ok(Ok(cur));
        }
        let cands: Vec<Cand> = tries.iter().map(|t| t.2.clone()).collect();
        oracle.crops_tried += cands.len();
        let held = match oracle.all(&cands)? {
            Ok(h) => h,
            Err(OutOfTime) => return Ok(Err(cur)),
        };
        let mut gained = None;
        for axis in 0..2 {
            // This axis' crops, largest first, and whether each held.
            let mine: Vec<(u32, bool, usize)> = (0..tries.len())
                .filter(|&i| tries[i].0 == axis)
                .map(|i| (tries[i].1, held[i], i))
                .collect();
            match mine.iter().position(|m| m.1) {
                Some(p) => {
                    if p > 0 {
                        hi[axis] = mine[p - 1].0;
                    }
                    if gained.is_none() {
                        lo[axis] = mine[p].0;
                        cur = cands[mine[p].2].clone();
                        gained = Some(axis);
                    }
                }
                None => {
                    if let Some(m) = mine.last() {
                        hi[axis] = m.0;
                    }
                }
            }
        }
    }
}

/// Reduces `start`, which must fail as `target` says. `work` holds the
/// candidates and the check runs (removed at the end); `template` gives
/// the check's settings (renderers, expectations, jobs, timeout); its scenes
/// and run folder are replaced. `budget` bounds the time (the reduction
/// then keeps what it reached).
pub fn reduce(
    start: &LiteralScene,
    target: &Target,
    template: &CheckOptions,
    work: &Path,
    budget: Option<std::time::Duration>,
    description: &str,
) -> Result<Reduction> {
    std::fs::create_dir_all(work).with_context(|| format!("{}: cannot create", work.display()))?;
    let mut oracle = Oracle {
        template,
        work: work.to_path_buf(),
        target: target.clone(),
        cache: HashMap::new(),
        footprint: None,
        size: None,
        check_runs: 0,
        candidates: 0,
        crops_tried: 0,
        deadline: budget.map(|b| Instant::now() + b),
    };
    let mut cur = start.clone();
    cur.description = description.to_string();
    let result = reduce_with(&mut oracle, cur);
    let _ = std::fs::remove_dir_all(work);
    let (scene, complete) = result?;
    let (w, h) = (start.camera.width, start.camera.height);
    let kept = (scene.camera.width, scene.camera.height) == (w, h);
    let image_note = (kept && oracle.crops_tried > 0).then(|| {
        format!(
            "image kept at {w}x{h}: no centered crop (the field of view narrowed to keep \
             the pixel pitch, which rounds every ray anew) still failed the same way"
        )
    });
    Ok(Reduction {
        scene,
        check_runs: oracle.check_runs,
        candidates: oracle.candidates,
        complete,
        failure_triangles: oracle.footprint.map(|f| f.into_iter().collect()),
        failure_size: oracle.size,
        image_note,
    })
}

fn reduce_with(oracle: &mut Oracle, start: LiteralScene) -> Result<(LiteralScene, bool)> {
    if !valid(&start) {
        bail!("the standalone rewrite of the scene is not a valid scene");
    }
    let mut cur = Cand {
        origin: (0..start.triangle_count()).collect(),
        scene: start,
    };
    // Before any deadline: this test always runs.
    if !oracle.establish(&cur)? {
        bail!(
            "the failure ({} fails {} with class {}) does not reproduce from the scene rewritten standalone \
             (literal triangles, checked with --only {} and no calibration)",
            oracle.target.backend,
            oracle.target.buffer,
            oracle.target.class,
            oracle.target.backend
        );
    }
    for _ in 0..MAX_ROUNDS {
        let before = cur.key();
        let s = cur.clone();
        match ddmin(
            s.scene.objects.len(),
            &|k| cand_objects(&s, k),
            oracle,
            false,
        )? {
            Ok(k) => cur = cand_objects(&s, &k),
            Err(k) => return Ok((cand_objects(&s, &k).scene, false)),
        }
        // A light is a unit like an object (a visibility scene has none).
        let s = cur.clone();
        match ddmin(s.scene.lights.len(), &|k| cand_lights(&s, k), oracle, true)? {
            Ok(k) => cur = cand_lights(&s, &k),
            Err(k) => return Ok((cand_lights(&s, &k).scene, false)),
        }
        let s = cur.clone();
        match ddmin(
            s.scene.triangle_count(),
            &|k| cand_triangles(&s, k),
            oracle,
            false,
        )? {
            Ok(k) => cur = cand_triangles(&s, &k),
            Err(k) => return Ok((cand_triangles(&s, &k).scene, false)),
        }
        // Snapping moves vertices, never triangles: the origins stay.
        let snaps: Vec<Cand> = snap_candidates(&cur.scene)
            .into_iter()
            .map(|scene| Cand {
                scene,
                origin: cur.origin.clone(),
            })
            .collect();
        match oracle.first(&snaps)? {
            Ok(Some(i)) => cur = snaps[i].clone(),
            Ok(None) => {}
            Err(OutOfTime) => return Ok((cur.scene, false)),
        }
        match crop_image(oracle, cur)? {
            Ok(c) => cur = c,
            Err(c) => return Ok((c.scene, false)),
        }
        if cur.key() == before {
            return Ok((cur.scene, true));
        }
    }
    Ok((cur.scene, false))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fuzz::literal::test_scene;

    fn scene(objects: Vec<Vec<Tri>>) -> LiteralScene {
        test_scene(45.0, 32, 32, objects)
    }

    fn tri(x: f64) -> Tri {
        [[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x, 1.0, 0.0]]
    }

    #[test]
    fn chunks_and_keeps_preserve_order() {
        assert_eq!(split(&[1, 2, 3, 4, 5], 2), vec![vec![1, 2], vec![3, 4, 5]]);
        assert_eq!(split(&[1, 2], 4), vec![vec![1], vec![2]]);
        let s = scene(vec![
            vec![tri(0.0), tri(1.0)],
            vec![tri(2.0)],
            vec![tri(3.0)],
        ]);
        let k = keep_triangles(&s, &[1, 3]);
        assert_eq!(k.objects.len(), 2);
        assert_eq!(k.objects[0].triangles, vec![tri(1.0)]);
        assert_eq!(k.objects[1].triangles, vec![tri(3.0)]);
        assert_eq!(keep_objects(&s, &[2]).objects[0].triangles, vec![tri(3.0)]);
    }

    #[test]
    fn a_candidate_must_fail_at_a_size_comparable_to_the_first() {
        let cand = Cand {
            scene: scene(vec![vec![tri(0.0)]]),
            origin: vec![0],
        };
        let failing = |size: Option<f64>| Failure { groups: None, size };
        // The POV-Ray reduction's drift: 8e-6 at first, then 4e-15 on a
        // light in the triangle's plane. Same class, same triangle: refused.
        let first = Some(8e-6);
        assert!(!same_failure(
            None,
            first,
            &cand,
            Some(&failing(Some(4e-15)))
        ));
        // Just below and at 1/8 of the first.
        assert!(!same_failure(
            None,
            first,
            &cand,
            Some(&failing(Some(0.99e-6)))
        ));
        assert!(same_failure(None, first, &cand, Some(&failing(Some(1e-6)))));
        // Larger is the same failure too (a crop may drop its smaller pixels).
        assert!(same_failure(None, first, &cand, Some(&failing(Some(1.0)))));
        // A failure without a finite size is not the finite one.
        assert!(!same_failure(None, first, &cand, Some(&failing(None))));
        // No size the first time (a buffer that records none): the class alone.
        assert!(same_failure(None, None, &cand, Some(&failing(None))));
        assert!(same_failure(None, None, &cand, Some(&failing(Some(1e-30)))));
        // Not failing at all.
        assert!(!same_failure(None, first, &cand, None));
    }

    #[test]
    fn the_size_is_rgb_s_largest_interior_error() {
        let mut details = serde_json::Map::new();
        details.insert("interior_max_abs_error".into(), serde_json::json!(8.04e-6));
        let mut e = ResultEntry {
            scene: "s".into(),
            backend: "povray".into(),
            buffer: "RGB".into(),
            status: "fail".into(),
            reason: String::new(),
            details,
        };
        assert_eq!(failure_size(&e), Some(8.04e-6));
        e.details
            .insert("interior_max_abs_error".into(), serde_json::Value::Null);
        assert_eq!(failure_size(&e), None);
        e.details.clear();
        assert_eq!(failure_size(&e), None);
    }

    #[test]
    fn snapping_goes_coarse_to_fine_and_stops_at_no_change() {
        let s = scene(vec![vec![[
            [0.3, 0.0, 0.0],
            [1.7, 0.1, 0.0],
            [0.0, 1.25, 0.0],
        ]]]);
        let c = snap_candidates(&s);
        assert!(!c.is_empty());
        // The coarsest grid is 2^(top + 1) = 2 (top exponent of 1.7 is 0).
        assert_eq!(c[0].objects[0].triangles[0][1], [2.0, 0.0, 0.0]);
        // Each candidate differs from the scene, and they are distinct.
        for w in c.windows(2) {
            assert_ne!(w[0].to_toml(), w[1].to_toml());
        }
        assert!(c.iter().all(|x| x.to_toml() != s.to_toml()));
        // An already coarse scene has fewer candidates than a fine one.
        let coarse = scene(vec![vec![[
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
        ]]]);
        assert!(snap_candidates(&coarse).len() < c.len());
    }
}
