//! `rendiff bench stability`: where each renderer breaks on numerical extremes.
//!
//! Parameterized scene families (translation offsets, scales, near/far
//! ratios, slivers, grazing views) are written as TOML into a temporary
//! folder and run through `rendiff check` itself ([`rendiff::check::run`]), so
//! every backend sees exactly what a user's scene would give it. For each
//! renderer and family the table names the first parameter value where it
//! breaks, and how: a render error, interior ID mismatches (edge mismatches are
//! rounding, not breakage), hit/miss mismatches, or a failed depth verdict.
//! Raster == trace is checked bit for bit from the buffers at every value.

pub mod families;
pub mod judge;
pub mod memory;

use super::page::Page;
use super::plot::{matrix, Cell};
use super::Common;
use anyhow::{Context, Result};
pub use families::{families, Family, Judge, Member};
use rendiff::check::{self, manifest::ResultEntry, manifest::SceneRuns, CheckOptions};
use rendiff::exr_io::read_buffers;
use rendiff::raster::{self, RasterOptions};
use rendiff::scene::resolve::ResolvedScene;
use rendiff::vocab::{RenderStatus, Status};
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// What `bench stability` runs.
#[derive(Debug, Clone)]
pub struct StabilityOptions {
    /// Shared options (quick: two values per family, core and Embree only).
    pub common: Common,
    /// Only these backends (None: all); the raster reference always runs.
    pub only: Option<Vec<String>>,
}

/// A parameter value as a label: powers of ten as 1eK, small integers as
/// they are, anything else in three significant digits.
fn sci(x: f64) -> String {
    let e = x.abs().log10().round() as i32;
    if (x - 10f64.powi(e)).abs() <= 1e-9 * x.abs() {
        format!("1e{e}")
    } else if x.fract() == 0.0 && x.abs() < 1e5 {
        format!("{x}")
    } else {
        format!("{x:.3e}")
    }
}

/// Why one verdict counts as broken, or None when it does not.
pub fn breakage(e: &ResultEntry) -> Option<String> {
    let n = |k: &str| e.details.get(k).and_then(Value::as_u64).unwrap_or(0);
    match e.status.as_str() {
        "skipped" => return None,
        "error" => return Some(format!("error: {}", first_line(&e.reason))),
        _ => {}
    }
    let mut why = Vec::new();
    if n("interior_mismatches") > 0 {
        let what = if e.buffer == "Z" { "depth" } else { "ID" };
        why.push(format!(
            "{} interior {what} mismatches",
            n("interior_mismatches")
        ));
    }
    if n("mask_mismatches") > 0 {
        why.push(format!(
            "{} hit/miss mismatches ({})",
            n("mask_mismatches"),
            e.buffer
        ));
    }
    if e.buffer == "Z" && e.status == "fail" {
        why.push(format!("depth fail: {}", first_line(&e.reason)));
    }
    (!why.is_empty()).then(|| why.join("; "))
}

fn first_line(s: &str) -> String {
    let mut l: String = s.lines().next().unwrap_or("").chars().take(160).collect();
    if l.is_empty() {
        l = "(no reason given)".into();
    }
    l
}

/// The check runs behind one stability run: verdicts, and per scene its run
/// folder and manifest entry (to read buffers and render infos).
struct Runs {
    results: Vec<ResultEntry>,
    scenes: BTreeMap<String, (PathBuf, SceneRuns)>,
}

impl Runs {
    fn add(&mut self, run_dir: &Path, o: &check::CheckOutcome) {
        self.results.extend(o.results.results.iter().cloned());
        for sr in &o.manifest.scenes {
            self.scenes
                .insert(sr.scene.clone(), (run_dir.to_path_buf(), sr.clone()));
        }
    }

    fn exr(&self, scene: &str, backend: &str) -> Option<PathBuf> {
        let (dir, sr) = self.scenes.get(scene)?;
        let r = sr.renders.iter().find(|r| r.backend == backend)?;
        (r.status == RenderStatus::Ok && !r.exr.is_empty()).then(|| dir.join(&r.exr))
    }

    fn info(&self, scene: &str, backend: &str) -> Value {
        self.scenes
            .get(scene)
            .and_then(|(_, sr)| sr.renders.iter().find(|r| r.backend == backend))
            .map(|r| r.info.clone())
            .unwrap_or(Value::Null)
    }
}

/// Runs every family through `rendiff check` and returns the JSON record, the page and the SVGs.
pub fn run(opts: &StabilityOptions) -> Result<super::Output> {
    let environment = super::environment();
    let fams = families(opts.common.quick);
    let tmp = super::Scratch::new("stability")?;
    let scene_dir = tmp.path().join("scenes");
    std::fs::create_dir_all(&scene_dir)?;
    let mut files: Vec<Vec<PathBuf>> = Vec::new();
    for f in &fams {
        let mut v = Vec::new();
        for m in &f.members {
            let p = scene_dir.join(format!("{}.toml", m.name));
            std::fs::write(&p, &m.toml)
                .with_context(|| format!("{}: cannot write", p.display()))?;
            v.push(p);
        }
        files.push(v);
    }
    let expectations = tmp.path().join("expectations.toml");
    std::fs::write(&expectations, "# none: every divergence counts\n")?;
    let only = opts.only.clone().or_else(|| {
        opts.common.quick.then(|| {
            ["raster", "trace", "embree", "embree_robust"]
                .map(String::from)
                .to_vec()
        })
    });
    let scenes = fams
        .iter()
        .zip(&files)
        .filter(|(f, _)| f.judge != Judge::Memory)
        .flat_map(|(_, v)| v.iter().cloned())
        .collect();
    let check_opts = CheckOptions {
        only: only.clone(),
        timeout: Duration::from_secs(opts.common.timeout_s),
        expectations,
        // No calibration probes (the default): the bench looks for where each renderer
        // breaks, and the probes would only add their renders to a long run.
        jobs: 1,
        wait_slots: 0,
        ..CheckOptions::new(scenes, tmp.path().join("run"), opts.common.root.clone())
    };
    // A name in --only that no backend has fails here, not in every check below.
    check::check_only_option(&check_opts)?;
    rendiff::errln!(
        "stability: {} scenes through rendiff check ({})",
        check_opts.scenes.len(),
        only.as_ref()
            .map(|o| o.join(","))
            .unwrap_or_else(|| "all backends".into())
    );
    let start = std::time::Instant::now();
    let mut runs = Runs {
        results: Vec::new(),
        scenes: BTreeMap::new(),
    };
    let mut errors = Vec::new();
    match check::run(&check_opts) {
        Ok(o) => runs.add(&check_opts.run_dir, &o),
        Err(e) => errors.push(format!("rendiff check failed: {e:#}")),
    }
    let mut memory_table = Value::Null;
    for (f, v) in fams.iter().zip(&files) {
        if f.judge == Judge::Memory {
            let (sizes, table) = memory::run(f, v, &check_opts, &tmp.path().join("sizes"));
            for s in sizes {
                match &s.outcome {
                    Ok(o) => runs.add(&s.run_dir, o),
                    Err(e) => errors.push(format!("rendiff check failed: {e:#}")),
                }
            }
            memory_table = table;
        }
    }
    let check_s = start.elapsed().as_secs_f64();
    let mut record = json!({
        "benchmark": "stability",
        "environment": environment,
        "config": {
            "quick": opts.common.quick, "only": only, "timeout_s": opts.common.timeout_s,
            "broken_means": "per family (see each family's rule): against the core raster, a render error, interior ID mismatches > 0, hit/miss mismatches > 0, or a failed depth verdict (edge mismatches are rounding, not breakage)",
            "families": fams.iter().map(|f| json!({
                "name": f.name, "parameter": f.parameter, "rule": rule_text(&f.judge),
                "values": f.members.iter().map(|m| m.value).collect::<Vec<_>>(),
                "scenes": f.members.iter().map(|m| m.name.clone()).collect::<Vec<_>>(),
            })).collect::<Vec<_>>(),
        },
        "check_seconds": check_s,
    });
    if !errors.is_empty() {
        record["error"] = json!(errors.join("; "));
    }
    let judged = judge_all(&fams, &scene_dir, &runs);
    record["verdicts"] = Value::Array(
        runs.results
            .iter()
            .map(|e| {
                json!({"scene": e.scene, "backend": e.backend, "buffer": e.buffer, "status": e.status,
                       "edge": e.details.get("edge_mismatches"), "interior": e.details.get("interior_mismatches"),
                       "mask": e.details.get("mask_mismatches"), "max_rel_error": e.details.get("max_rel_error"),
                       "broken": breakage(e)})
            })
            .collect(),
    );
    record["judged"] = judged.clone();
    record["breaks"] = break_table(&fams, &judged);
    record["zfight"] = zfight_table(&fams, &judged);
    record["memory"] = memory_table;
    record["raster_equals_trace"] = raster_equals_trace(&fams, &runs);
    Ok(super::Output::with_plot(record, "matrix", chart, page))
}

fn rule_text(j: &Judge) -> &'static str {
    match j {
        Judge::Reference | Judge::Memory => "against the core raster: a render error, interior ID mismatches, hit/miss mismatches or a failed depth verdict",
        Judge::FillRule => "every center lies on an edge or vertex: a crack (background strictly inside a watertight mesh), a winner or boundary coverage other than the top-left rule's (the raster's), a hit outside the meshes, or interior depth mismatches; the core is also checked for double coverage from its coverage counts",
        Judge::Truth { .. } => "per-pixel truth from the scene (pixels 1 px from every edge): background where a surface is, a hit where none is, an exact coplanar tie won by the higher id (except in z-fighting, where f32 vertices can collapse the planes into one), or a farther surface winning by more than the renderer's depth resolution; plus interior depth mismatches against the raster",
    }
}

/// Every (scene, backend) judged by its family's rule: why it breaks (empty when it holds) and counts.
fn judge_all(fams: &[Family], scene_dir: &Path, runs: &Runs) -> Value {
    let mut backends: Vec<String> = Vec::new();
    for r in &runs.results {
        if !backends.contains(&r.backend) {
            backends.push(r.backend.clone());
        }
    }
    let mut out = Vec::new();
    for f in fams {
        // The reference has entries of its own now (its normals), so it is in `backends`
        // already; the exact judges want it first, once.
        let mut rows: Vec<String> = backends
            .iter()
            .filter(|b| b.as_str() != check::REFERENCE)
            .cloned()
            .collect();
        if matches!(f.judge, Judge::FillRule | Judge::Truth { .. })
            || backends.iter().any(|b| b == check::REFERENCE)
        {
            rows.insert(0, check::REFERENCE.to_string());
        }
        for m in &f.members {
            // Only the exact judges need the scene (the triangle-count scenes are large).
            let scene = if matches!(f.judge, Judge::FillRule | Judge::Truth { .. }) {
                load(&scene_dir.join(format!("{}.toml", m.name)))
            } else {
                Err(anyhow::anyhow!("not loaded: judged against the reference"))
            };
            let truth = matches!(f.judge, Judge::Truth { .. })
                .then(|| scene.as_ref().ok().map(judge::truth))
                .flatten();
            for b in &rows {
                let entries: Vec<&ResultEntry> = runs
                    .results
                    .iter()
                    .filter(|r| r.scene == m.name && &r.backend == b)
                    .collect();
                let (status, why, stats) =
                    judge_one(f, m, b, &entries, runs, scene.as_ref(), truth.as_ref());
                out.push(json!({"family": f.name, "scene": m.name, "value": m.value,
                                "backend": b, "status": status, "broken": why, "stats": stats}));
            }
        }
    }
    Value::Array(out)
}

fn load(path: &Path) -> Result<ResolvedScene> {
    super::load_scene(path)
}

/// One (member, backend): "ran" | "skipped: why" | "not run", the reasons it breaks, and counts.
fn judge_one(
    f: &Family,
    m: &Member,
    backend: &str,
    entries: &[&ResultEntry],
    runs: &Runs,
    scene: Result<&ResolvedScene, &anyhow::Error>,
    truth: Option<&judge::Truth>,
) -> (String, Vec<String>, Value) {
    let is_ref = backend == check::REFERENCE;
    if !is_ref {
        if entries.is_empty() {
            return ("not run".into(), vec![], Value::Null);
        }
        if entries.iter().all(|e| e.status == Status::Skipped.as_str()) {
            return (
                format!("skipped: {}", first_line(&entries[0].reason)),
                vec![],
                Value::Null,
            );
        }
        if let Some(e) = entries.iter().find(|e| e.status == "error") {
            return (
                "ran".into(),
                vec![format!("error: {}", first_line(&e.reason))],
                Value::Null,
            );
        }
    }
    let mut why: Vec<String> = Vec::new();
    if matches!(f.judge, Judge::Reference | Judge::Memory) {
        why = entries
            .iter()
            .filter_map(|e| breakage(e).map(|w| format!("{}: {w}", e.buffer)))
            .collect();
        return ("ran".into(), why, Value::Null);
    }
    // Interior depth mismatches against the raster still break (depth is compared where both see the same triangle).
    for e in entries.iter().filter(|e| e.buffer == "Z") {
        let n = e
            .details
            .get("interior_mismatches")
            .and_then(Value::as_u64)
            .unwrap_or(0);
        if n > 0 {
            why.push(format!(
                "Z: {n} interior depth mismatches beyond the renderer's tolerance"
            ));
        }
    }
    let scene = match scene {
        Ok(s) => s,
        Err(e) => return ("ran".into(), vec![format!("scene: {e:#}")], Value::Null),
    };
    let (w, h) = (scene.camera.width as usize, scene.camera.height as usize);
    let Some(path) = runs.exr(&m.name, backend) else {
        return (
            "ran".into(),
            vec!["no buffers to judge".into()],
            Value::Null,
        );
    };
    let test = match read_buffers(&path) {
        Ok(b) => b,
        Err(e) => {
            return (
                "ran".into(),
                vec![format!("unreadable buffers: {e:#}")],
                Value::Null,
            )
        }
    };
    let Some(test_ids) = judge::Ids::of(&test, w, h) else {
        return (
            "ran".into(),
            vec!["buffers lack id.prim of the scene's size".into()],
            Value::Null,
        );
    };
    let (broken, stats) = match (&f.judge, truth) {
        (Judge::Truth { ties_break }, Some(t)) => judge::judge_truth(
            t,
            &test_ids,
            backend,
            &runs.info(&m.name, backend),
            *ties_break,
        ),
        (Judge::FillRule, _) => match m.layout.as_ref() {
            None => (
                Some("no layout for this fill-rule scene".into()),
                Value::Null,
            ),
            Some(layout) if is_ref => {
                let opts = RasterOptions {
                    count_coverage: true,
                    deadline: None,
                };
                judge::fill_rule_coverage(layout, &raster::render(scene, opts, &|_| {}))
            }
            Some(layout) => match runs
                .exr(&m.name, check::REFERENCE)
                .map(|p| read_buffers(&p))
            {
                Some(Ok(r)) => match judge::Ids::of(&r, w, h) {
                    Some(ri) => judge::fill_rule(layout, &ri, &test_ids),
                    None => (Some("reference buffers lack id.prim".into()), Value::Null),
                },
                _ => (Some("no reference buffers".into()), Value::Null),
            },
        },
        _ => (Some("no truth for this scene".into()), Value::Null),
    };
    why.extend(broken.map(|b| format!("id: {b}")));
    ("ran".into(), why, stats)
}

/// For each family and backend: the first value where it breaks, and how.
fn break_table(fams: &[Family], judged: &Value) -> Value {
    let rows_in = judged.as_array().cloned().unwrap_or_default();
    let mut rows = Vec::new();
    for f in fams {
        let mut backends: Vec<String> = Vec::new();
        for r in rows_in.iter().filter(|r| r["family"] == json!(f.name)) {
            let b = super::page::compact(&r["backend"]);
            if !backends.contains(&b) {
                backends.push(b);
            }
        }
        for b in &backends {
            let mine: Vec<&Value> = rows_in
                .iter()
                .filter(|r| r["family"] == json!(f.name) && r["backend"] == json!(b))
                .collect();
            let ran: Vec<&&Value> = mine
                .iter()
                .filter(|r| r["status"] == json!("ran"))
                .collect();
            let first = ran
                .iter()
                .find(|r| r["broken"].as_array().is_some_and(|a| !a.is_empty()));
            let first_break = first.map(|r| {
                let how: Vec<String> = r["broken"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .map(super::page::compact)
                    .collect();
                json!({"value": r["value"], "label": r["value"].as_f64().map(sci), "scene": r["scene"], "how": how.join("; ")})
            });
            let skipped = mine
                .iter()
                .find(|r| r["status"].as_str().is_some_and(|s| s != "ran"))
                .map(|r| r["status"].clone());
            rows.push(json!({
                "family": f.name, "backend": b, "values_run": ran.len(),
                "max_value": ran.last().map(|r| r["value"].clone()),
                "first_break": first_break,
                "skipped": skipped,
            }));
        }
    }
    Value::Array(rows)
}

/// z-fighting: per renderer, the largest separation at which the nearer surface
/// loses any judged pixel (within its depth resolution or not), and whether that breaks.
fn zfight_table(fams: &[Family], judged: &Value) -> Value {
    let Some(f) = fams.iter().find(|f| f.name == "z-fighting") else {
        return Value::Null;
    };
    let rows_in = judged.as_array().cloned().unwrap_or_default();
    let mut backends: Vec<String> = Vec::new();
    for r in rows_in.iter().filter(|r| r["family"] == json!(f.name)) {
        let b = super::page::compact(&r["backend"]);
        if !backends.contains(&b) {
            backends.push(b);
        }
    }
    let lost = |r: &Value| {
        let n = |k: &str| r["stats"][k].as_u64().unwrap_or(0);
        n("nearer_lost") + n("nearer_lost_below_resolution") + n("missing")
    };
    Value::Array(
        backends
            .iter()
            .map(|b| {
                let first = rows_in.iter().find(|r| {
                    r["family"] == json!(f.name) && r["backend"] == json!(b) && lost(r) > 0
                });
                json!({
                    "backend": b,
                    "starts_losing_at": first.map(|r| r["value"].clone()),
                    "pixels_lost_there": first.map(lost),
                    "of_judged": first.map(|r| r["stats"]["judged_pixels"].clone()),
                    "largest_gap_lost": first.map(|r| r["stats"]["largest_lost_gap"].clone()),
                    "resolution_there": first.map(|r| r["stats"]["resolution_there"].clone()),
                    "breaks": first.map(|r| r["broken"].as_array().is_some_and(|a| !a.is_empty())),
                })
            })
            .collect(),
    )
}

/// Raster vs trace from the run's buffers, bit for bit, per scene (None where either is missing).
fn raster_equals_trace(fams: &[Family], runs: &Runs) -> Value {
    let mut m = BTreeMap::new();
    for f in fams {
        for mem in &f.members {
            let same = match (
                runs.exr(&mem.name, "raster").map(|p| read_buffers(&p)),
                runs.exr(&mem.name, "trace").map(|p| read_buffers(&p)),
            ) {
                (Some(Ok(a)), Some(Ok(b))) => {
                    let z = match (&a.z, &b.z) {
                        (Some(x), Some(y)) => {
                            x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits())
                        }
                        _ => false,
                    };
                    json!(a.prim == b.prim && z)
                }
                _ => Value::Null,
            };
            m.insert(mem.name.clone(), same);
        }
    }
    let all = m.values().all(|v| v == &json!(true));
    json!({"all": all, "per_scene": m})
}

fn chart(record: &Value) -> String {
    let rows_v = record["breaks"].as_array().cloned().unwrap_or_default();
    let mut fams: Vec<String> = Vec::new();
    let mut backends: Vec<String> = Vec::new();
    for r in &rows_v {
        let f = super::page::compact(&r["family"]);
        let b = super::page::compact(&r["backend"]);
        if !fams.contains(&f) {
            fams.push(f);
        }
        if !backends.contains(&b) {
            backends.push(b);
        }
    }
    let cells: Vec<Vec<Cell>> = fams
        .iter()
        .map(|f| {
            backends
                .iter()
                .map(|b| {
                    let r = rows_v
                        .iter()
                        .find(|r| r["family"] == json!(f) && r["backend"] == json!(b));
                    match r {
                        None if b == check::REFERENCE => (
                            "reference".into(),
                            "#eee".into(),
                            "the others are compared with it".into(),
                        ),
                        None => ("-".into(), "#eee".into(), "not run".into()),
                        Some(r) if r["values_run"] == json!(0) => (
                            "skipped".into(),
                            "#ddd".into(),
                            super::page::compact(&r["skipped"]),
                        ),
                        Some(r) => match r["first_break"].as_object() {
                            Some(fb) => (
                                format!("breaks at {}", super::page::compact(&fb["label"])),
                                "#f3b3b3".into(),
                                super::page::compact(&fb["how"]),
                            ),
                            None => (
                                "holds".into(),
                                "#c9ebc9".into(),
                                format!(
                                    "no break up to {}",
                                    r["max_value"].as_f64().map(sci).unwrap_or_default()
                                ),
                            ),
                        },
                    }
                })
                .collect()
        })
        .collect();
    matrix(
        "first breaking value per family and renderer",
        &fams,
        &backends,
        &cells,
    )
}

fn page(record: &Value, svg: &str) -> String {
    let mut p = Page::new("rendiff bench stability: where each renderer breaks");
    p.para(&format!(
        "Scene families pushed to numerical extremes, each run through rendiff check with every backend against the core raster. Broken means {}.",
        super::page::compact(&record["config"]["broken_means"])
    ))
    .command("rendiff bench stability");
    if let Some(e) = record["error"].as_str() {
        p.note(e);
    }
    p.svg(svg, Some("stability-matrix.svg"));
    p.heading("first break per family and renderer");
    let rows: Vec<Vec<String>> = record["breaks"]
        .as_array()
        .into_iter()
        .flatten()
        .map(|r| {
            let fb = &r["first_break"];
            vec![
                super::page::compact(&r["family"]),
                super::page::compact(&r["backend"]),
                if r["values_run"] == json!(0) {
                    super::page::compact(&r["skipped"])
                } else if fb.is_object() {
                    super::page::compact(&fb["label"])
                } else {
                    format!(
                        "holds to {}",
                        r["max_value"].as_f64().map(sci).unwrap_or_default()
                    )
                },
                if fb.is_object() {
                    super::page::compact(&fb["how"])
                } else {
                    String::new()
                },
            ]
        })
        .collect();
    p.table(&["family", "renderer", "first break", "how"], &rows);
    memory_section(&mut p, &record["memory"]);
    zfight_section(&mut p, &record["zfight"]);
    p.heading("families");
    let fams: Vec<Vec<String>> = record["config"]["families"]
        .as_array()
        .into_iter()
        .flatten()
        .map(|f| {
            vec![
                super::page::compact(&f["name"]),
                super::page::compact(&f["parameter"]),
                f["values"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .filter_map(Value::as_f64)
                    .map(sci)
                    .collect::<Vec<_>>()
                    .join(", "),
                super::page::compact(&f["rule"]),
            ]
        })
        .collect();
    p.table(
        &[
            "family",
            "parameter",
            "values (easiest first)",
            "broken means",
        ],
        &fams,
    );
    p.para(&format!(
        "Raster == trace bit for bit at every value: {} (check took {} s).",
        super::page::compact(&record["raster_equals_trace"]["all"]),
        super::page::num(record["check_seconds"].as_f64(), 3)
    ));
    p.environment(&record["environment"]);
    p.finish()
}

fn memory_section(p: &mut Page, mem: &Value) {
    let Some(rows) = mem["rows"].as_array() else {
        return;
    };
    p.heading("memory and time by triangle count (each renderer in its own process)");
    p.para(&format!(
        "{} Budget: {}",
        super::page::compact(&mem["measured_as"]),
        super::page::compact(&mem["budget"]["rule"])
    ));
    let mib = |v: &Value| {
        v.as_f64()
            .map(|b| format!("{:.0}", b / f64::from(1u32 << 20)))
    };
    let table: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            vec![
                super::page::compact(&r["triangles"]),
                super::page::compact(&r["backend"]),
                super::page::compact(&r["status"]),
                super::page::num(r["wall_s"].as_f64(), 3),
                super::page::num(r["render_s"].as_f64(), 3),
                mib(&r["max_rss_bytes"]).unwrap_or_default(),
                super::page::num(r["bytes_per_triangle"].as_f64(), 3),
                super::page::compact(&r["note"]),
            ]
        })
        .collect();
    p.table(
        &[
            "triangles",
            "renderer",
            "status",
            "wall s",
            "render s",
            "peak MiB",
            "peak bytes / triangle",
            "note",
        ],
        &table,
    );
    if let Some(m) = mem["marginal_bytes_per_triangle"].as_object() {
        let rows: Vec<Vec<String>> = m
            .iter()
            .map(|(b, v)| {
                vec![
                    b.clone(),
                    format!(
                        "{} to {}",
                        super::page::compact(&v["from"]),
                        super::page::compact(&v["to"])
                    ),
                    super::page::num(v["bytes_per_triangle"].as_f64(), 3),
                ]
            })
            .collect();
        p.table(
            &["renderer", "between sizes", "marginal bytes / triangle"],
            &rows,
        );
    }
}

fn zfight_section(p: &mut Page, z: &Value) {
    let Some(rows) = z.as_array() else {
        return;
    };
    p.heading("z-fighting: where the nearer surface starts losing");
    p.para("Separation as a fraction of the distance from the eye (10). Losing within the renderer's depth resolution is expected; losing above it breaks.");
    let table: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            vec![
                super::page::compact(&r["backend"]),
                r["starts_losing_at"]
                    .as_f64()
                    .map(sci)
                    .unwrap_or_else(|| "never (down to 1e-9)".into()),
                format!(
                    "{} of {}",
                    super::page::compact(&r["pixels_lost_there"]),
                    super::page::compact(&r["of_judged"])
                ),
                super::page::num(r["largest_gap_lost"].as_f64(), 3),
                super::page::num(r["resolution_there"].as_f64(), 3),
                super::page::compact(&r["breaks"]),
            ]
        })
        .collect();
    p.table(
        &[
            "renderer",
            "starts losing at",
            "pixels lost there",
            "largest gap lost",
            "depth resolution there",
            "breaks",
        ],
        &table,
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_family_scene_parses_and_resolves() {
        let dir = tempfile::tempdir().unwrap();
        for f in families(false) {
            for m in f.members.iter().filter(|m| m.triangles.is_none()) {
                let p = dir.path().join(format!("{}.toml", m.name));
                let s = rendiff::scene::Scene::parse(&p, &m.toml)
                    .unwrap_or_else(|e| panic!("{}: {e}", m.name));
                ResolvedScene::resolve(&s).unwrap_or_else(|e| panic!("{}: {e}", m.name));
            }
        }
    }

    #[test]
    fn labels_are_powers_of_ten() {
        assert_eq!(sci(1e-7), "1e-7");
        assert_eq!(sci(1000.0), "1e3");
        assert_eq!(sci(64.0), "64");
        assert_eq!(sci(999_698.0), "9.997e5");
    }
}
