//! Shards and merge: a check run split across CI machines (`check --shard
//! K/N`, as deqp-runner's `--fraction` and nextest's `--partition`) and put
//! back together (`rendiff merge`) into one run folder whose verdicts are a
//! single machine's.
//!
//! Sharding is deterministic: scenes are dealt to shards greedily, largest
//! recorded cost first (the scene's render times in a previous run, when one
//! is given; otherwise one unit per scene), ties broken by path, so every
//! machine computes the same split without talking to the others. Every shard
//! renders the calibration probes: they are cheap, and each shard's verdicts
//! need its own backends' calibration.
//!
//! Merging copies each shard's scene folders into a fresh run, keeps one copy
//! of the probes, writes the combined manifest and runs the comparison once
//! over the whole: results.json, the report and the gate are then exactly
//! what one machine's run would give (the comparison is deterministic given
//! the buffers).

use super::manifest::{DealtScene, Manifest, SceneRuns, ShardRecord, MANIFEST_FORMAT};
use super::run_folder::{ensure_complete, Staging};
use super::{stem, CheckOptions, CheckOutcome, CALIBRATION_ROLE};
use crate::vocab::RenderStatus;
use anyhow::{bail, Context, Result};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Most shards a run may be split into: 1024. Each shard renders the
/// calibration probes again and a machine of its own is the point, so no CI
/// fans out wider; the deal keeps a load per shard (`--shard 1/99999999999`
/// aborted on that allocation).
pub const MAX_SHARDS: usize = 1024;

/// `K/N`: this machine runs shard K (1-based) of N.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// 1-based index.
    pub index: usize,
    /// How many shards.
    pub total: usize,
}

impl std::str::FromStr for Shard {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let (k, n) = s
            .split_once('/')
            .ok_or_else(|| format!("{s:?}: give the shard as K/N, e.g. 2/4"))?;
        let parse = |t: &str| t.trim().parse::<usize>().ok();
        match (parse(k), parse(n)) {
            (Some(_), Some(total)) if total > MAX_SHARDS => Err(format!(
                "{s:?}: at most {MAX_SHARDS} shards (each renders the probes again)"
            )),
            (Some(index), Some(total)) if total >= 1 && (1..=total).contains(&index) => {
                Ok(Shard { index, total })
            }
            _ => Err(format!(
                "{s:?}: K/N needs 1 <= K <= N (shard K of N machines)"
            )),
        }
    }
}

/// Recorded cost of each scene (seconds of rendering, summed over its
/// renders) in a previous run's manifest.json. A run named by `--shard-costs`
/// (`given`) must have a readable manifest (a wrong path used to deal the
/// shards without costs, silently); the run folder's own previous run is
/// optional (empty when there is none, or when it cannot be read).
pub fn recorded_costs(previous_run: &Path, given: bool) -> Result<BTreeMap<String, f64>> {
    let path = previous_run.join("manifest.json");
    let manifest = super::manifest::read_record(&path).and_then(|text| {
        serde_json::from_str::<Manifest>(&text).map_err(|e| format!("not a rendiff manifest: {e}"))
    });
    let m = match manifest {
        Ok(m) => m,
        Err(e) if given => bail!("--shard-costs {}: {e}", path.display()),
        Err(_) => return Ok(BTreeMap::new()),
    };
    Ok(m.scenes
        .iter()
        .map(|s| {
            let t: f64 = s.renders.iter().map(|r| r.time_s.max(0.0)).sum();
            (s.scene.clone(), t)
        })
        .collect())
}

/// The scenes shard `shard` runs, in their original order. Greedy
/// longest-processing-time assignment: scenes by cost (unknown cost: the mean
/// of the known ones, or 1), largest first, each to the least loaded shard.
pub fn select(scenes: &[PathBuf], shard: Shard, costs: &BTreeMap<String, f64>) -> Vec<PathBuf> {
    scenes
        .iter()
        .zip(assign(scenes, shard.total, costs))
        .filter(|(_, k)| *k == shard.index - 1)
        .map(|(p, _)| p.clone())
        .collect()
}

/// The whole split as shard `shard` records it in its manifest (every
/// scene, its file's hash and its shard): what `merge` checks the shards
/// against. A scene file that cannot be read is refused here, naming it.
pub fn deal(
    scenes: &[PathBuf],
    shard: Shard,
    costs: &BTreeMap<String, f64>,
) -> Result<ShardRecord> {
    let owners = assign(scenes, shard.total, costs);
    let deal = scenes
        .iter()
        .zip(owners)
        .map(|(p, k)| {
            Ok(DealtScene {
                scene: stem(p),
                file: p.display().to_string(),
                sha256: super::inputs::file_digest(p)?,
                shard: k + 1,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(ShardRecord {
        index: shard.index,
        total: shard.total,
        deal,
    })
}

/// The 0-based shard of each scene (see [`select`]).
fn assign(scenes: &[PathBuf], total: usize, costs: &BTreeMap<String, f64>) -> Vec<usize> {
    let known: Vec<f64> = costs.values().copied().filter(|c| *c > 0.0).collect();
    let default = if known.is_empty() {
        1.0
    } else {
        known.iter().sum::<f64>() / known.len() as f64
    };
    let cost = |p: &PathBuf| {
        costs
            .get(&stem(p))
            .copied()
            .filter(|c| *c > 0.0)
            .unwrap_or(default)
    };
    let mut order: Vec<usize> = (0..scenes.len()).collect();
    order.sort_by(|&a, &b| {
        cost(&scenes[b])
            .total_cmp(&cost(&scenes[a]))
            .then_with(|| scenes[a].cmp(&scenes[b]))
    });
    let mut load = vec![0.0f64; total];
    let mut owner = vec![0usize; scenes.len()];
    for i in order {
        let (k, _) = load
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1).then(a.0.cmp(&b.0)))
            .expect("at least one shard");
        load[k] += cost(&scenes[i]);
        owner[i] = k;
    }
    owner
}

fn copy_tree(from: &Path, to: &Path) -> Result<()> {
    std::fs::create_dir_all(to).with_context(|| format!("{}: cannot create", to.display()))?;
    for e in std::fs::read_dir(from).with_context(|| format!("{}: cannot list", from.display()))? {
        let e = e?;
        let (src, dst) = (e.path(), to.join(e.file_name()));
        let kind = e.file_type()?;
        if kind.is_dir() {
            copy_tree(&src, &dst)?;
        } else if kind.is_file() {
            std::fs::copy(&src, &dst).with_context(|| format!("{}: cannot copy", src.display()))?;
        }
        // Links and special files are never part of a run: skipped.
    }
    Ok(())
}

/// `rendiff merge SHARD_RUN... -o RUN`: one run folder from shard runs, then
/// the comparison over all of it. `opts` gives the output folder, the
/// repository root, expectations and references (its scenes are unused).
/// Refuses incomplete shards, a scene present in two shards, and shards of
/// different rendiff versions or references.
pub fn merge(shards: &[PathBuf], opts: &CheckOptions) -> Result<CheckOutcome> {
    if shards.is_empty() {
        bail!("no shard runs to merge");
    }
    let mut manifests = Vec::new();
    for run in shards {
        ensure_complete(run)?;
        let path = run.join("manifest.json");
        let text = super::manifest::read_record(&path).map_err(|e| {
            anyhow::anyhow!(
                "{}: cannot read (not a finished check run): {e}",
                path.display()
            )
        })?;
        let m: Manifest = serde_json::from_str(&text)
            .with_context(|| format!("{}: not a rendiff manifest", path.display()))?;
        if m.format != MANIFEST_FORMAT {
            bail!(
                "{}: format {:?}, expected {MANIFEST_FORMAT:?}",
                path.display(),
                m.format
            );
        }
        manifests.push((run.clone(), m));
    }
    let first = &manifests[0].1;
    // Every scene name is checked before the set (a name that leaves the
    // run is the worst problem a shard can have).
    for (run, m) in &manifests {
        for s in &m.scenes {
            if !super::is_folder_name(&s.scene) {
                bail!(
                    "{}: scene name {:?} cannot name a folder of the run (scenes/<name>/)",
                    run.join("manifest.json").display(),
                    crate::scene::printable(&s.scene, 100)
                );
            }
        }
    }
    for (run, m) in &manifests[1..] {
        if m.rendiff_version != first.rendiff_version || m.reference != first.reference {
            bail!(
                "{}: made by rendiff {} with reference {}, but {} by rendiff {} with reference {}: shards must come from one build",
                run.display(), m.rendiff_version, m.reference,
                manifests[0].0.display(), first.rendiff_version, first.reference
            );
        }
    }
    check_shard_set(&manifests)?;
    check_resolved_seals(&manifests)?;
    // The merge judges with the renderers file it is given: the shards' own.
    let recorded = first
        .options
        .as_ref()
        .map_or("", |o| o.renderers_sha256.as_str());
    let given = match &opts.renderers {
        Some(f) => super::inputs::file_digest(f)?,
        None => String::new(),
    };
    if given != recorded {
        bail!(
            "the shards were run {}, but this merge {}: pass the renderers file the shards used, so their declared precision judges their renders",
            if recorded.is_empty() { "without --renderers" } else { "with a --renderers file" },
            if given.is_empty() { "has no --renderers" } else { "has a different one" }
        );
    }
    // Every scene is checked before the output is touched: a refused merge
    // left the marker in a good run given as -o.
    let mut seen: BTreeMap<String, PathBuf> = BTreeMap::new();
    let mut taken: Vec<(&PathBuf, &SceneRuns)> = Vec::new();
    for (run, m) in &manifests {
        for s in &m.scenes {
            if let Some(prev) = seen.get(&s.scene) {
                if s.role == CALIBRATION_ROLE {
                    continue; // every shard renders the probes; one copy is kept
                }
                bail!(
                    "scene {:?} is in two shards ({} and {}): merge shards of one split",
                    s.scene,
                    prev.display(),
                    run.display()
                );
            }
            seen.insert(s.scene.clone(), run.clone());
            taken.push((run, s));
        }
    }
    let staging = Staging::begin(&opts.run_dir)?;
    let mut scenes: Vec<SceneRuns> = Vec::new();
    for (run, s) in taken {
        {
            let rel = format!("scenes/{}", s.scene);
            let from = run.join(&rel);
            // Never through a link: a linked scene folder copied files from
            // outside the shard into the merged run.
            if std::fs::symlink_metadata(&from).is_ok_and(|m| m.is_dir()) {
                copy_tree(&from, &staging.dir.join(&rel))?;
            }
            let mut s = s.clone();
            let (old, new) = (
                run.display().to_string(),
                opts.run_dir.display().to_string(),
            );
            for r in &mut s.renders {
                r.command = r.command.replace(&old, &new);
            }
            scenes.push(s);
        }
    }
    // Probes first, as in a single run; then the scenes in file order.
    scenes.sort_by(|a, b| {
        (a.role != CALIBRATION_ROLE, &a.scene_file)
            .cmp(&(b.role != CALIBRATION_ROLE, &b.scene_file))
    });
    let manifest = Manifest {
        format: MANIFEST_FORMAT.into(),
        reference: first.reference.clone(),
        created_unix: manifests
            .iter()
            .map(|(_, m)| m.created_unix)
            .max()
            .unwrap_or(0),
        rendiff_version: first.rendiff_version.clone(),
        scenes,
        options: first.options.clone(),
        rerun: first.rerun.clone(),
        shard: None,
    };
    crate::exr_io::write_atomically(&staging.dir.join("manifest.json"), |tmp| {
        std::fs::write(tmp, serde_json::to_vec_pretty(&manifest)?)?;
        Ok(())
    })?;
    let staged = CheckOptions {
        run_dir: staging.dir.clone(),
        ..opts.clone()
    };
    let (results, table) = super::compare(&staged, &staging.dir.join("scratch"), &opts.run_dir)
        .map_err(|e| {
            anyhow::anyhow!(super::unstage(
                &format!("{e:#}"),
                &staging.dir,
                &opts.run_dir
            ))
        })?;
    staging.publish()?;
    Ok(CheckOutcome {
        manifest,
        results,
        table,
    })
}

/// Refuses a shard whose resolved scene is not the one it was rendered
/// from: merge judges each shard's renders again against
/// `scenes/<name>/resolved/`, so a changed triangle there (or a changed
/// hash in manifest.json) would re-judge correct renders against other
/// geometry, or hide the change. Each scene's folder is hashed as the check
/// did ([`super::inputs::Seal`]) and held to its `resolved_sha256`. A
/// shard run records one for every scene that loaded (the shard record and
/// the hash came in together), so a scene with a render but no hash is
/// refused too; one that did not load has neither.
fn check_resolved_seals(manifests: &[(PathBuf, Manifest)]) -> Result<()> {
    for (run, m) in manifests {
        let file = run.join("manifest.json");
        for s in &m.scenes {
            let name = crate::scene::printable(&s.scene, 100);
            let rendered = s.renders.iter().any(|r| r.status == RenderStatus::Ok);
            if s.resolved_sha256.is_empty() && !rendered {
                continue;
            }
            if s.resolved_sha256.is_empty() {
                bail!(
                    "{}: scene {name:?} records no resolved_sha256, so its resolved scene cannot be checked: run the shard again",
                    file.display()
                );
            }
            let dir = run.join("scenes").join(&s.scene).join("resolved");
            let now = super::inputs::Seal::of(&dir)
                .map_err(|e| anyhow::anyhow!("{}: scene {name:?}: {e:#}", file.display()))?;
            if now.digest != s.resolved_sha256 {
                bail!(
                    "{}: scene {name:?}: its resolved scene ({}) is not the one the shard rendered (resolved_sha256 {}, now {}): the run was changed after its check; run the shard again",
                    file.display(),
                    dir.display(),
                    crate::scene::printable(&s.resolved_sha256, 80),
                    now.digest
                );
            }
        }
    }
    Ok(())
}

/// Refuses a set of shard runs that is not one whole split run one way:
/// a run that is no shard, shards of different splits (another count, other
/// scenes, a same-named scene from another file), a shard given twice or
/// missing, shards run with different options (`--only`, `--renderers`,
/// calibration, the core's seed and samples), a shard whose scenes are not
/// the ones its split dealt it, a backend of two versions, and a probe that
/// differs between shards. Each refusal names the runs.
fn check_shard_set(manifests: &[(PathBuf, Manifest)]) -> Result<()> {
    let file = |run: &Path| run.join("manifest.json").display().to_string();
    let mut shards: Vec<(&PathBuf, &ShardRecord)> = Vec::new();
    for (run, m) in manifests {
        let Some(rec) = &m.shard else {
            bail!(
                "{}: not a shard run (no shard record: made without `check --shard K/N`, or by an older rendiff); merge joins the shard runs of one split",
                file(run)
            );
        };
        shards.push((run, rec));
    }
    let (first_run, first) = shards[0];
    for &(run, rec) in &shards[1..] {
        if let Some(why) = split_difference(first, rec) {
            bail!(
                "{} and {} are shards of different splits ({why}): merge the shard runs of one `check --shard K/N` over one set of scene files",
                first_run.display(),
                run.display()
            );
        }
    }
    let mut by_index: BTreeMap<usize, &PathBuf> = BTreeMap::new();
    for &(run, rec) in &shards {
        if let Some(prev) = by_index.insert(rec.index, run) {
            bail!(
                "{} and {} are both shard {}/{}: its scenes would be in two shards; merge each shard once",
                prev.display(),
                run.display(),
                rec.index,
                rec.total
            );
        }
    }
    let missing: Vec<String> = (1..=first.total)
        .filter(|k| !by_index.contains_key(k))
        .map(|k| format!("{k}/{}", first.total))
        .collect();
    if !missing.is_empty() {
        let lost: Vec<String> = first
            .deal
            .iter()
            .filter(|d| !by_index.contains_key(&d.shard))
            .take(5)
            .map(|d| format!("{:?}", crate::scene::printable(&d.scene, 100)))
            .collect();
        bail!(
            "shard{} {} of the split missing (its scenes, e.g. {}, would have no verdicts): merge all {} shard runs",
            if missing.len() == 1 { "" } else { "s" },
            missing.join(", "),
            lost.join(", "),
            first.total
        );
    }
    for (run, m) in manifests {
        let rec = m.shard.as_ref().expect("checked above");
        let mut have: Vec<&str> = m
            .scenes
            .iter()
            .filter(|s| s.role != CALIBRATION_ROLE)
            .map(|s| s.scene.as_str())
            .collect();
        let mut dealt: Vec<&str> = rec
            .deal
            .iter()
            .filter(|d| d.shard == rec.index)
            .map(|d| d.scene.as_str())
            .collect();
        have.sort_unstable();
        dealt.sort_unstable();
        if have != dealt {
            bail!(
                "{}: shard {}/{} holds scenes {:?}, but its split dealt it {:?}",
                file(run),
                rec.index,
                rec.total,
                have.iter()
                    .map(|n| crate::scene::printable(n, 100))
                    .collect::<Vec<_>>(),
                dealt
                    .iter()
                    .map(|n| crate::scene::printable(n, 100))
                    .collect::<Vec<_>>()
            );
        }
    }
    let (first_run, first_m) = (&manifests[0].0, &manifests[0].1);
    for (run, m) in &manifests[1..] {
        if m.options != first_m.options {
            bail!(
                "{} and {} were run with different options ({}): shards must be run alike",
                first_run.display(),
                run.display(),
                options_difference(first_m.options.as_ref(), m.options.as_ref())
            );
        }
    }
    // One version per backend, one resolved scene per probe.
    let mut versions: BTreeMap<&str, (&str, &PathBuf)> = BTreeMap::new();
    let mut probes: BTreeMap<&str, (&str, &PathBuf)> = BTreeMap::new();
    for (run, m) in manifests {
        for s in &m.scenes {
            if s.role == CALIBRATION_ROLE {
                let (was, at) = *probes
                    .entry(s.scene.as_str())
                    .or_insert((s.resolved_sha256.as_str(), run));
                if was != s.resolved_sha256 {
                    bail!(
                        "calibration probe {:?} differs between {} and {} (another resolved scene): shards must render the same probes",
                        crate::scene::printable(&s.scene, 100),
                        at.display(),
                        run.display()
                    );
                }
            }
            for r in s.renders.iter().filter(|r| r.status == RenderStatus::Ok) {
                let (was, at) = *versions
                    .entry(r.backend.as_str())
                    .or_insert((r.version.as_str(), run));
                if was != r.version {
                    bail!(
                        "{} is version {:?} in {} but {:?} in {}: shards must run the same renderers",
                        crate::scene::printable(&r.backend, 100),
                        crate::scene::printable(was, 200),
                        at.display(),
                        crate::scene::printable(&r.version, 200),
                        run.display()
                    );
                }
            }
        }
    }
    Ok(())
}

/// How two shards' splits differ, in words; None when they are one split.
fn split_difference(a: &ShardRecord, b: &ShardRecord) -> Option<String> {
    if a.total != b.total {
        return Some(format!("of {} and of {} shards", a.total, b.total));
    }
    let index = |r: &ShardRecord| -> BTreeMap<String, DealtScene> {
        r.deal
            .iter()
            .map(|d| (d.scene.clone(), d.clone()))
            .collect()
    };
    let (x, y) = (index(a), index(b));
    let name = |n: &str| format!("{:?}", crate::scene::printable(n, 100));
    if let Some(n) = x.keys().find(|n| !y.contains_key(*n)) {
        return Some(format!("scene {} is in one split only", name(n)));
    }
    if let Some(n) = y.keys().find(|n| !x.contains_key(*n)) {
        return Some(format!("scene {} is in one split only", name(n)));
    }
    for (n, d) in &x {
        let e = &y[n];
        if d.sha256 != e.sha256 {
            return Some(format!(
                "scene {} is another file in each ({} and {})",
                name(n),
                crate::scene::printable(&d.file, 200),
                crate::scene::printable(&e.file, 200)
            ));
        }
        if d.shard != e.shard {
            return Some(format!(
                "scene {} was dealt to shard {} in one and {} in the other (different --shard-costs?)",
                name(n),
                d.shard,
                e.shard
            ));
        }
    }
    (a.deal != b.deal).then(|| "the scene files are listed differently".to_string())
}

/// The first option two shards were run with differently, in words.
fn options_difference(
    a: Option<&super::manifest::RunOptions>,
    b: Option<&super::manifest::RunOptions>,
) -> String {
    let (Some(a), Some(b)) = (a, b) else {
        return "one records no options".into();
    };
    let only = |o: &Option<Vec<String>>| {
        o.as_ref().map_or("(every backend)".to_string(), |v| {
            crate::scene::printable(&v.join(","), 200)
        })
    };
    if a.only != b.only {
        return format!("--only {} and --only {}", only(&a.only), only(&b.only));
    }
    if a.renderers_sha256 != b.renderers_sha256 {
        return "different --renderers files".into();
    }
    if a.calibration != b.calibration {
        return "one without calibration (--no-calibration)".into();
    }
    "the core's seed, samples per pixel or injected bias".into()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paths(names: &[&str]) -> Vec<PathBuf> {
        names
            .iter()
            .map(|n| PathBuf::from(format!("s/{n}.toml")))
            .collect()
    }

    #[test]
    fn shards_partition_the_scenes_and_keep_their_order() {
        let all = paths(&["a", "b", "c", "d", "e", "f", "g"]);
        for n in 1..=4 {
            let mut union = Vec::new();
            for k in 1..=n {
                let part = select(&all, Shard { index: k, total: n }, &BTreeMap::new());
                let mut sorted = part.clone();
                sorted.sort();
                assert_eq!(part, sorted, "order kept");
                union.extend(part);
            }
            union.sort();
            assert_eq!(union, all, "every scene in exactly one of {n} shards");
        }
    }

    #[test]
    fn recorded_costs_balance_the_shards() {
        let all = paths(&["big", "m1", "m2", "m3", "m4"]);
        let costs: BTreeMap<String, f64> = [
            ("big", 4.0),
            ("m1", 1.0),
            ("m2", 1.0),
            ("m3", 1.0),
            ("m4", 1.0),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect();
        let one = select(&all, Shard { index: 1, total: 2 }, &costs);
        let two = select(&all, Shard { index: 2, total: 2 }, &costs);
        assert_eq!(one, paths(&["big"]));
        assert_eq!(two.len(), 4);
    }

    #[test]
    fn shard_syntax_is_checked() {
        assert_eq!(
            "2/4".parse::<Shard>().unwrap(),
            Shard { index: 2, total: 4 }
        );
        for bad in ["0/3", "4/3", "3", "a/b", "1/0"] {
            assert!(bad.parse::<Shard>().is_err(), "{bad}");
        }
    }
}
