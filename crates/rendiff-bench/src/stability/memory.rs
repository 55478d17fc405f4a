//! The triangle-count family: each size through `rendiff check` with every
//! render in a child process of its own (`check::run_isolating`), so the peak
//! memory (`wait4`'s max RSS) and the time are per renderer. Sizes run smallest
//! first; a renderer whose next size, scaled linearly from the last one it
//! ran, would exceed the memory or time budget is not run there, and the table
//! says so with the projection.

use super::families::Family;
use anyhow::Result;
use rendiff::check::{self, manifest::SceneRuns, CheckOptions};
use rendiff::vocab::RenderStatus;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// Projected peak memory above which a renderer is not run on the next size.
pub const MEMORY_BUDGET_BYTES: f64 = 8.0 * (1u64 << 30) as f64;
/// Projected seconds above which a renderer is not run on the next size.
pub const TIME_BUDGET_S: f64 = 240.0;

/// One size's check run.
pub struct SizeRun {
    /// Its run folder.
    pub run_dir: PathBuf,
    /// What the check rendered and compared, or why it failed.
    pub outcome: Result<check::CheckOutcome>,
}

/// Runs the family's sizes; `files[i]` is member `i`'s scene file; `template`
/// gives the check options every size shares (its scenes and run folder are replaced).
pub fn run(
    fam: &Family,
    files: &[PathBuf],
    template: &CheckOptions,
    run_root: &Path,
) -> (Vec<SizeRun>, Value) {
    // The isolated renders run `rendiff render` and `rendiff peak-rss`: the tool's binary.
    let bin = super::super::rendiff_binary().ok();
    let mut dropped: Vec<(String, String)> = Vec::new();
    let mut last: Vec<(String, f64, f64)> = Vec::new(); // (backend, rss, seconds) at the previous size
    let mut runs = Vec::new();
    let mut rows = Vec::new();
    let mut seen: Vec<String> = Vec::new(); // backends the previous size ran
    for (i, (m, file)) in fam.members.iter().zip(files).enumerate() {
        let tris = m.triangles.unwrap_or(0) as f64;
        if i > 0 {
            let ratio = tris / fam.members[i - 1].triangles.unwrap_or(1).max(1) as f64;
            for (b, rss, secs) in &last {
                let (prss, psecs) = (rss * ratio, secs * ratio);
                if (prss > MEMORY_BUDGET_BYTES || psecs > TIME_BUDGET_S)
                    && !dropped.iter().any(|d| &d.0 == b)
                {
                    dropped.push((
                        b.clone(),
                        format!(
                            "not run from {} triangles on: projected {:.1} GiB, {:.0} s from the previous size exceed the budget ({:.0} GiB, {:.0} s)",
                            m.triangles.unwrap_or(0),
                            prss / (1u64 << 30) as f64,
                            psecs,
                            MEMORY_BUDGET_BYTES / (1u64 << 30) as f64,
                            TIME_BUDGET_S
                        ),
                    ));
                }
            }
        }
        let only = if dropped.is_empty() {
            template.only.clone()
        } else {
            Some(
                seen.iter()
                    .filter(|b| !dropped.iter().any(|d| &d.0 == *b))
                    .cloned()
                    .collect(),
            )
        };
        let run_dir = run_root.join(&m.name);
        let opts = CheckOptions {
            scenes: vec![file.clone()],
            run_dir: run_dir.clone(),
            only,
            ..template.clone()
        };
        rendiff::errln!(
            "stability: {} ({} triangles), each renderer in its own process",
            m.name,
            m.triangles.unwrap_or(0)
        );
        let outcome = check::run_isolating(&opts, bin.as_deref());
        last.clear();
        if let Ok(o) = &outcome {
            for sr in &o.manifest.scenes {
                rows.extend(size_rows(sr, m.triangles.unwrap_or(0), &mut last));
                seen = sr.renders.iter().map(|r| r.backend.clone()).collect();
            }
        }
        for (b, why) in &dropped {
            rows.push(
                json!({"triangles": m.triangles, "backend": b, "status": "not run", "note": why}),
            );
        }
        runs.push(SizeRun { run_dir, outcome });
    }
    let marginal = marginal_bytes(&rows);
    let table = json!({
        "budget": {"max_rss_bytes": MEMORY_BUDGET_BYTES, "seconds": TIME_BUDGET_S,
                   "rule": "a renderer runs the next size only if its peak memory and wall time, scaled linearly by the triangle count, stay within the budget"},
        "measured_as": "peak resident memory (max RSS from wait4) of the child process that rendered, its own reaped children included; wall seconds of that process (scene loading, BVH build, render, EXR write; Python start-up for the harness renderers)",
        "rows": rows,
        "marginal_bytes_per_triangle": marginal,
    });
    (runs, table)
}

fn size_rows(sr: &SceneRuns, tris: u64, last: &mut Vec<(String, f64, f64)>) -> Vec<Value> {
    sr.renders
        .iter()
        .map(|r| {
            let rss = r.max_rss_bytes;
            if r.status == RenderStatus::Ok {
                if let Some(b) = rss {
                    last.push((r.backend.clone(), b as f64, r.time_s));
                }
            }
            let note = match r.status {
                RenderStatus::Ok => String::new(),
                RenderStatus::Skipped => r.reason.clone(),
                RenderStatus::Error => r.message.lines().next().unwrap_or("").to_string(),
            };
            json!({
                "triangles": tris, "backend": r.backend, "status": r.status,
                "wall_s": r.time_s,
                "render_s": r.info.get("render_seconds").cloned().unwrap_or(Value::Null),
                "max_rss_bytes": rss,
                "bytes_per_triangle": rss.filter(|_| tris > 0).map(|b| b as f64 / tris as f64),
                "note": note,
            })
        })
        .collect()
}

/// Per backend: (peak(N2) - peak(N1)) / (N2 - N1) between its two largest
/// sizes that ran, which removes the fixed cost (process, libraries, image).
fn marginal_bytes(rows: &[Value]) -> Value {
    let mut out = serde_json::Map::new();
    let mut backends: Vec<&str> = rows.iter().filter_map(|r| r["backend"].as_str()).collect();
    backends.dedup();
    for b in backends {
        let pts: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r["backend"] == json!(b) && r["status"] == json!("ok"))
            .filter_map(|r| Some((r["triangles"].as_f64()?, r["max_rss_bytes"].as_f64()?)))
            .collect();
        if let [.., (n1, m1), (n2, m2)] = pts.as_slice() {
            if n2 > n1 {
                out.insert(
                    b.to_string(),
                    json!({"from": n1, "to": n2, "bytes_per_triangle": (m2 - m1) / (n2 - n1)}),
                );
            }
        }
    }
    Value::Object(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn marginal_cost_removes_the_fixed_part() {
        let rows = vec![
            json!({"backend": "x", "status": "ok", "triangles": 1e6, "max_rss_bytes": 1.5e8}),
            json!({"backend": "x", "status": "ok", "triangles": 4e6, "max_rss_bytes": 4.5e8}),
            json!({"backend": "y", "status": "error", "triangles": 4e6, "max_rss_bytes": null}),
        ];
        let m = marginal_bytes(&rows);
        assert_eq!(m["x"]["bytes_per_triangle"], json!(100.0));
        assert!(m.get("y").is_none());
    }
}
