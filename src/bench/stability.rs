//! `rendiff bench stability`: where each renderer breaks on numerical extremes.
//!
//! Parameterized scene families (translation offsets, scales, near/far
//! ratios, slivers, grazing views) are written as TOML into a temporary
//! folder and run through `rendiff check` itself ([`crate::check::run`]), so
//! every backend sees exactly what a user's scene would give it. For each
//! renderer and family the table names the first parameter value where it
//! breaks, and how: a render error, interior ID mismatches (edge mismatches are
//! rounding, not breakage), hit/miss mismatches, or a failed depth verdict.
//! Raster == trace is checked bit for bit from the buffers at every value.

use super::page::Page;
use super::plot::{matrix, Cell};
use super::Common;
use crate::check::{self, manifest::ResultEntry, CheckOptions};
use crate::exr_io::read_buffers;
use anyhow::{Context, Result};
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::Path;
use std::time::Duration;

/// What `bench stability` runs.
#[derive(Debug, Clone)]
pub struct StabilityOptions {
    /// Shared options (quick: two values per family, core and Embree only).
    pub common: Common,
    /// Only these backends (None: all); the raster reference always runs.
    pub only: Option<Vec<String>>,
}

/// One family: its name, what the parameter means, and (label, value, TOML) in order of difficulty.
pub struct Family {
    /// Short name.
    pub name: &'static str,
    /// What the parameter is.
    pub parameter: &'static str,
    /// The scenes, easiest first.
    pub members: Vec<(String, f64, String)>,
}

fn sci(x: f64) -> String {
    let e = x.abs().log10().round() as i32;
    if (x - 10f64.powi(e)).abs() <= 1e-9 * x.abs() {
        format!("1e{e}")
    } else {
        format!("{x:e}")
    }
}

fn v3(v: [f64; 3]) -> String {
    format!("[{:?}, {:?}, {:?}]", v[0], v[1], v[2])
}

/// An icosphere over a ground grid, scaled by `s` and moved by `off`, the camera
/// at a fixed relative position; `near`/`far` as ratios of the eye's distance.
fn sphere_scene(s: f64, off: [f64; 3], near_ratio: f64, far_ratio: Option<f64>) -> String {
    let rel = [1.3, 0.9, 3.1];
    let eye = [
        rel[0] * s + off[0],
        rel[1] * s + off[1],
        rel[2] * s + off[2],
    ];
    let dist = (rel[0] * rel[0] + rel[1] * rel[1] + rel[2] * rel[2]).sqrt() * s;
    let far = far_ratio
        .map(|f| format!("far = {:?}\n", f * dist))
        .unwrap_or_default();
    format!(
        r#"requires = ["depth", "ids"]
[camera]
eye = {}
look_at = {}
vfov = 45.0
width = 48
height = 36
near = {:?}
{far}
[[objects]]
name = "sphere"
shape = {{ kind = "icosphere", subdivisions = 2, radius = 1.0 }}
transform = {{ scale = {}, translate = {} }}
allow_degenerate = true

[[objects]]
name = "ground"
shape = {{ kind = "grid", min = [-3.0, -3.0], max = [3.0, 3.0], nx = 6, ny = 6 }}
transform = {{ scale = {}, rotate = [-90.0, 0.0, 0.0], translate = {} }}
allow_degenerate = true
"#,
        v3(eye),
        v3(off),
        near_ratio * dist,
        v3([s; 3]),
        v3(off),
        v3([s; 3]),
        v3([off[0], off[1] - s, off[2]])
    )
}

/// Eight slivers 1.9 long and 1.9/aspect high, each at its own depth (so
/// overlaps at low aspect ratios are decided by depth, never by coplanar ties),
/// in front of a backdrop.
fn sliver_scene(aspect: f64) -> String {
    let mut verts = String::new();
    for k in 0..8 {
        let y = -0.8 + 0.2 * f64::from(k);
        let z = -0.05 * f64::from(k);
        let h = 1.9 / aspect;
        let _ = write!(
            verts,
            "[-0.95, {y:?}, {z:?}], [0.95, {:?}, {z:?}], [0.95, {y:?}, {z:?}], ",
            y + h
        );
    }
    format!(
        r#"requires = ["depth", "ids"]
[camera]
eye = [0.0, 0.0, 1.0]
look_at = [0.0, 0.0, 0.0]
vfov = 90.0
width = 64
height = 64
near = 0.001

[[objects]]
name = "slivers"
shape = {{ kind = "triangles", vertices = [{verts}] }}
allow_degenerate = true

[[objects]]
name = "backdrop"
shape = {{ kind = "quad", size = [4.0, 4.0] }}
transform = {{ translate = [0.0, 0.0, -1.0] }}
"#
    )
}

fn grazing_scene(tilt: f64) -> String {
    format!(
        r#"requires = ["depth", "ids"]
[camera]
eye = [0.0, {tilt:?}, 5.0]
look_at = [0.0, 0.0, 0.0]
vfov = 40.0
width = 48
height = 36
near = 0.0001

[[objects]]
name = "floor"
shape = {{ kind = "grid", min = [-4.0, -4.0], max = [4.0, 4.0], nx = 16, ny = 16 }}
transform = {{ rotate = [-90.0, 0.0, 0.0] }}
"#
    )
}

/// The families, full or quick (two values each, two families).
pub fn families(quick: bool) -> Vec<Family> {
    let pick = |v: Vec<i32>| -> Vec<i32> {
        if quick {
            vec![v[0], v[v.len() - 1]]
        } else {
            v
        }
    };
    let mut out = vec![
        Family {
            name: "offset",
            parameter: "translation of the whole scene (eye included)",
            members: pick((0..=7).collect())
                .into_iter()
                .map(|k| {
                    let o = 10f64.powi(k);
                    (
                        format!("offset_1e{k}"),
                        o,
                        sphere_scene(1.0, [o, -0.5 * o, 0.25 * o], 1e-4, None),
                    )
                })
                .collect(),
        },
        Family {
            name: "grazing",
            parameter: "eye height above a floor 5 units away",
            members: pick((1..=6).collect())
                .into_iter()
                .map(|k| {
                    let t = 10f64.powi(-k);
                    (format!("grazing_1e-{k}"), t, grazing_scene(t))
                })
                .collect(),
        },
    ];
    if quick {
        return out;
    }
    out.push(Family {
        name: "scale down",
        parameter: "uniform scale of scene and camera",
        members: (0..=6)
            .map(|k| {
                let s = 10f64.powi(-k);
                (
                    format!("scale_1e-{k}"),
                    s,
                    sphere_scene(s, [0.0; 3], 1e-4, None),
                )
            })
            .collect(),
    });
    out.push(Family {
        name: "scale up",
        parameter: "uniform scale of scene and camera",
        members: (0..=6)
            .map(|k| {
                let s = 10f64.powi(k);
                (
                    format!("scale_1e{k}"),
                    s,
                    sphere_scene(s, [0.0; 3], 1e-4, None),
                )
            })
            .collect(),
    });
    out.push(Family {
        name: "near/far",
        parameter: "near / far (far = 10 x the eye's distance)",
        members: (1..=7)
            .map(|k| {
                let r = 10f64.powi(-k);
                (
                    format!("nearfar_1e-{k}"),
                    r,
                    sphere_scene(1.0, [0.0; 3], 10.0 * r, Some(10.0)),
                )
            })
            .collect(),
    });
    out.push(Family {
        name: "sliver",
        parameter: "aspect ratio of sliver triangles",
        members: (0..=6)
            .map(|k| {
                let a = 10f64.powi(k);
                (format!("sliver_1e{k}"), a, sliver_scene(a))
            })
            .collect(),
    });
    out
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

/// Runs every family through `rendiff check` and returns the JSON record, the page and the SVGs.
pub fn run(opts: &StabilityOptions) -> Result<super::Output> {
    let environment = super::environment();
    let fams = families(opts.common.quick);
    let tmp = super::Scratch::new("stability")?;
    let scene_dir = tmp.path().join("scenes");
    std::fs::create_dir_all(&scene_dir)?;
    let mut files = Vec::new();
    for f in &fams {
        for (name, _, toml) in &f.members {
            let p = scene_dir.join(format!("{name}.toml"));
            std::fs::write(&p, toml).with_context(|| format!("{}: cannot write", p.display()))?;
            files.push(p);
        }
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
    let check_opts = CheckOptions {
        scenes: files,
        run_dir: tmp.path().join("run"),
        root: opts.common.root.clone(),
        only: only.clone(),
        timeout: Duration::from_secs(opts.common.timeout_s),
        expectations,
        quiet: true,
        references: None,
        core: check::CoreShading::default(),
    };
    eprintln!(
        "stability: {} scenes through rendiff check ({})",
        check_opts.scenes.len(),
        only.as_ref()
            .map(|o| o.join(","))
            .unwrap_or_else(|| "all backends".into())
    );
    let start = std::time::Instant::now();
    let outcome = check::run(&check_opts);
    let check_s = start.elapsed().as_secs_f64();
    let mut record = json!({
        "benchmark": "stability",
        "environment": environment,
        "config": {
            "quick": opts.common.quick, "only": only, "timeout_s": opts.common.timeout_s,
            "broken_means": "a render error, interior ID mismatches > 0, hit/miss mismatches > 0, or a failed depth verdict (edge mismatches are rounding, not breakage)",
            "families": fams.iter().map(|f| json!({
                "name": f.name, "parameter": f.parameter,
                "values": f.members.iter().map(|m| m.1).collect::<Vec<_>>(),
                "scenes": f.members.iter().map(|m| m.0.clone()).collect::<Vec<_>>(),
            })).collect::<Vec<_>>(),
        },
        "check_seconds": check_s,
    });
    let (table, raster_trace) = match &outcome {
        Ok(o) => (
            break_table(&fams, &o.results.results),
            raster_equals_trace(&fams, &check_opts.run_dir),
        ),
        Err(e) => {
            record["error"] = json!(format!("rendiff check failed: {e:#}"));
            (json!([]), json!(null))
        }
    };
    if let Ok(o) = &outcome {
        record["verdicts"] = Value::Array(
            o.results
                .results
                .iter()
                .map(|e| {
                    json!({"scene": e.scene, "backend": e.backend, "buffer": e.buffer, "status": e.status,
                           "edge": e.details.get("edge_mismatches"), "interior": e.details.get("interior_mismatches"),
                           "mask": e.details.get("mask_mismatches"), "max_rel_error": e.details.get("max_rel_error"),
                           "broken": breakage(e)})
                })
                .collect(),
        );
    }
    record["breaks"] = table;
    record["raster_equals_trace"] = raster_trace;
    super::finish_environment(&mut record);
    let svg = chart(&record);
    let html = page(&record, &svg);
    Ok(super::Output {
        record,
        html,
        svgs: vec![("matrix".into(), svg)],
    })
}

/// For each family and backend: the first value where it breaks, and how.
fn break_table(fams: &[Family], results: &[ResultEntry]) -> Value {
    let mut backends: Vec<String> = Vec::new();
    for r in results {
        if !backends.contains(&r.backend) {
            backends.push(r.backend.clone());
        }
    }
    let mut rows = Vec::new();
    for f in fams {
        for b in &backends {
            let mut first: Option<Value> = None;
            let mut ran = 0;
            let mut skipped = Vec::new();
            for (name, value, _) in &f.members {
                let entries: Vec<&ResultEntry> = results
                    .iter()
                    .filter(|r| &r.scene == name && &r.backend == b)
                    .collect();
                if entries.iter().all(|e| e.status == "skipped") {
                    if let Some(e) = entries.first() {
                        skipped.push(first_line(&e.reason));
                    }
                    continue;
                }
                ran += 1;
                let why: Vec<String> = entries
                    .iter()
                    .filter_map(|e| breakage(e).map(|w| format!("{}: {w}", e.buffer)))
                    .collect();
                if first.is_none() && !why.is_empty() {
                    first = Some(
                        json!({"value": value, "label": sci(*value), "scene": name, "how": why.join("; ")}),
                    );
                }
            }
            rows.push(json!({
                "family": f.name, "backend": b, "values_run": ran,
                "max_value": f.members.last().map(|m| m.1),
                "first_break": first,
                "skipped": skipped.first(),
            }));
        }
    }
    Value::Array(rows)
}

/// Raster vs trace from the run's buffers, bit for bit, per scene (None where either is missing).
fn raster_equals_trace(fams: &[Family], run: &Path) -> Value {
    let mut m = BTreeMap::new();
    for f in fams {
        for (name, _, _) in &f.members {
            let dir = run.join("scenes").join(name);
            let same = match (
                read_buffers(&dir.join("raster.exr")),
                read_buffers(&dir.join("trace.exr")),
            ) {
                (Ok(a), Ok(b)) => {
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
            m.insert(name.clone(), same);
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
                    format!("skipped: {}", super::page::compact(&r["skipped"]))
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
            ]
        })
        .collect();
    p.table(&["family", "parameter", "values (easiest first)"], &fams);
    p.para(&format!(
        "Raster == trace bit for bit at every value: {} (check took {} s).",
        super::page::compact(&record["raster_equals_trace"]["all"]),
        super::page::num(record["check_seconds"].as_f64(), 3)
    ));
    p.environment(&record["environment"]);
    p.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_family_scene_parses_and_resolves() {
        let dir = tempfile::tempdir().unwrap();
        for f in families(false) {
            for (name, _, toml) in &f.members {
                let p = dir.path().join(format!("{name}.toml"));
                let s =
                    crate::scene::Scene::parse(&p, toml).unwrap_or_else(|e| panic!("{name}: {e}"));
                crate::scene::resolve::ResolvedScene::resolve(&s)
                    .unwrap_or_else(|e| panic!("{name}: {e}"));
            }
        }
    }

    #[test]
    fn labels_are_powers_of_ten() {
        assert_eq!(sci(1e-7), "1e-7");
        assert_eq!(sci(1000.0), "1e3");
    }
}
