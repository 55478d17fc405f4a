//! A run folder made of its two JSON files alone (included with `mod`, and
//! by the gate's unit tests through `#[path]`): the one fake run that the
//! gate, bless, merge and run-integrity tests start from.

#![allow(dead_code)]

use serde_json::{json, Value};
use std::path::Path;

/// Writes `run/manifest.json` and `run/results.json` for `scenes` rendered
/// by `backends` (status ok, version `rendiff 0.1.0`, no EXR written: bless
/// reads renders only for depth scales and seeds, which then default), with
/// one passing entry per scene, backend and buffer in `buffers`: no
/// mismatch, no error, then `fields` (an object) merged over each entry.
pub fn json_run(run: &Path, scenes: &[&str], backends: &[&str], buffers: &[&str], fields: Value) {
    std::fs::create_dir_all(run).unwrap();
    let manifest = json!({
        "format": "rendiff-manifest/1", "reference": "raster", "created_unix": 1_795_000_000u64,
        "rendiff_version": "0.1.0",
        "scenes": scenes.iter().map(|s| json!({
            "scene": s, "scene_file": format!("scenes/{s}.toml"), "resolved": format!("scenes/{s}/resolved"),
            "requires": ["depth", "ids"],
            "renders": backends.iter().map(|b| json!({"backend": b, "status": "ok",
                "exr": format!("scenes/{s}/{b}.exr"), "version": "rendiff 0.1.0", "time_s": 0.1}))
                .collect::<Vec<_>>()
        })).collect::<Vec<_>>()
    });
    let mut entries = Vec::new();
    for s in scenes {
        for b in backends {
            for buf in buffers {
                let mut e = json!({"scene": s, "backend": b, "buffer": buf, "status": "pass", "reason": "",
                       "edge_mismatches": 0, "tie_mismatches": 0, "crack_mismatches": 0,
                       "interior_mismatches": 0, "mask_mismatches": 0,
                       "max_abs_error": 0.0, "max_rel_error": 0.0});
                for (k, v) in fields.as_object().unwrap() {
                    e[k] = v.clone();
                }
                entries.push(e);
            }
        }
    }
    let results = json!({"format": "rendiff-results/1", "reference": "raster", "results": entries});
    std::fs::write(run.join("manifest.json"), manifest.to_string()).unwrap();
    std::fs::write(run.join("results.json"), results.to_string()).unwrap();
}

/// Rewrites `run/results.json` with `f`'s change.
pub fn edit_results(run: &Path, f: impl FnOnce(&mut Value)) {
    let path = run.join("results.json");
    let mut r: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    f(&mut r);
    std::fs::write(&path, r.to_string()).unwrap();
}
