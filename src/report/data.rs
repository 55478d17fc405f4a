//! Everything the report shows, read from a run folder: manifest.json (what was
//! rendered), results.json (how it compared; may be missing when the comparison
//! itself failed, and the report must still show the renders), and each scene's
//! resolved scene.json (display name, objects), grouped per scene.

use crate::check::manifest::{
    Manifest, RenderRecord, ResultEntry, Results, SceneRuns, MANIFEST_FORMAT, RESULTS_FORMAT,
};
use crate::vocab::RenderStatus;
use anyhow::{Context, Result};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Component, Path, PathBuf};

/// One run folder, loaded and grouped per scene.
#[derive(Debug, Clone)]
pub struct RunData {
    /// The run folder.
    pub dir: PathBuf,
    /// manifest.json.
    pub manifest: Manifest,
    /// results.json, when it could be read.
    pub results: Option<Results>,
    /// Why results.json could not be read (shown as a banner).
    pub results_problem: Option<String>,
    /// The expectations file the comparison used (results.json `expectations`).
    pub expectations: Option<String>,
    /// The camera calibration per backend (results.json `calibration`), None
    /// when the comparison did not record one (older runs).
    pub calibration: Option<serde_json::Map<String, Value>>,
    /// Scenes in manifest order (plus any only results.json names).
    pub scenes: Vec<SceneData>,
}

/// One scene: its renders, its verdicts and what its resolved scene says.
#[derive(Debug, Clone)]
pub struct SceneData {
    /// Scene file stem, as in manifest/results (untrusted text).
    pub name: String,
    /// File stem of its report page (safe for paths and URLs).
    pub page: String,
    /// What was rendered (None if only results.json knows the scene).
    pub runs: Option<SceneRuns>,
    /// Its verdicts, as in results.json.
    pub results: Vec<ResultEntry>,
    /// Display name, size and objects from the resolved scene, when readable.
    pub resolved: Option<ResolvedInfo>,
}

/// What the report uses of a resolved scene (docs/resolved-scene.md).
#[derive(Debug, Clone, Default)]
pub struct ResolvedInfo {
    /// The TOML `name` (untrusted text).
    pub name: String,
    /// Image width.
    pub width: u64,
    /// Image height.
    pub height: u64,
    /// Triangles after resolution.
    pub triangle_count: u64,
    /// Objects in ID order.
    pub objects: Vec<ObjectInfo>,
    /// Material names in index order.
    pub materials: Vec<String>,
}

/// One object: its name and the prim IDs it owns.
#[derive(Debug, Clone, Default)]
pub struct ObjectInfo {
    /// Object name from the scene file (untrusted text).
    pub name: String,
    /// First prim ID.
    pub first_prim: u64,
    /// Number of prims.
    pub prim_count: u64,
    /// Material index.
    pub material: Option<usize>,
}

impl ResolvedInfo {
    /// The index and object that owns prim `p`.
    pub fn object_of(&self, p: u64) -> Option<(usize, &ObjectInfo)> {
        self.objects
            .iter()
            .enumerate()
            .find(|(_, o)| p >= o.first_prim && p - o.first_prim < o.prim_count)
    }
}

impl SceneData {
    /// The render record of `backend`, if the manifest has one.
    pub fn render(&self, backend: &str) -> Option<&RenderRecord> {
        self.runs
            .as_ref()
            .and_then(|r| r.renders.iter().find(|x| x.backend == backend))
    }

    /// Backends in manifest order, then any only results.json names.
    pub fn backends(&self) -> Vec<String> {
        let mut out: Vec<String> = Vec::new();
        if let Some(r) = &self.runs {
            for rec in &r.renders {
                if !out.contains(&rec.backend) {
                    out.push(rec.backend.clone());
                }
            }
        }
        for e in &self.results {
            if !out.contains(&e.backend) {
                out.push(e.backend.clone());
            }
        }
        out
    }

    /// The worst status among its verdicts (for sorting failures first).
    pub fn worst_rank(&self) -> u8 {
        self.results
            .iter()
            .map(|e| status_rank(&e.status))
            .min()
            .unwrap_or(if self.has_render_errors() { 0 } else { 4 })
    }

    /// Its renders with `status` that no verdict speaks for (results.json
    /// has no entry of their backend for this scene): the report lists them
    /// from the manifest itself.
    pub fn unjudged_renders(&self, status: RenderStatus) -> impl Iterator<Item = &RenderRecord> {
        self.runs
            .iter()
            .flat_map(|r| r.renders.iter())
            .filter(move |r| {
                r.status == status && !self.results.iter().any(|e| e.backend == r.backend)
            })
    }

    /// True when a render failed (shown even if results.json is missing).
    pub fn has_render_errors(&self) -> bool {
        self.runs
            .as_ref()
            .is_some_and(|r| r.renders.iter().any(|x| x.status == RenderStatus::Error))
    }
}

/// Sort rank of a status: failures first, then known failures, skips, passes.
pub fn status_rank(status: &str) -> u8 {
    use crate::vocab::Status;
    match Status::parse(status) {
        Some(s) if s.is_bad() => 0,
        Some(Status::ExpectedFail) => 1,
        Some(Status::Skipped) => 2,
        Some(Status::Pass) => 3,
        _ => 0,
    }
}

/// A number field of a verdict (counts and errors), None when null or absent.
pub fn num(e: &ResultEntry, key: &str) -> Option<f64> {
    e.details.get(key).and_then(Value::as_f64)
}

/// The mismatch classes the verifier records, with their short names
/// (results.json `<class>_mismatches`), in the order the report shows them.
pub const CLASSES: &[(&str, &str)] = &[
    ("edge_mismatches", "edge"),
    ("tie_mismatches", "tie"),
    ("crack_mismatches", "crack"),
    ("interior_mismatches", "interior"),
];

/// Buffer of the entry a scene that could not be loaded gets.
pub const SCENE_BUFFER: &str = "scene";

/// True for the verdict that says a scene could not be loaded.
pub fn is_scene_error(e: &ResultEntry) -> bool {
    e.buffer == SCENE_BUFFER && status_rank(&e.status) == 0
}

/// One line of a verdict's `explanations`: why a group of pixels differs.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Explanation {
    /// edge | tie | crack | interior (untrusted text).
    pub class: String,
    /// The reference's prim there (None: background or not recorded).
    pub ref_prim: Option<u64>,
    /// The test backend's prim there.
    pub test_prim: Option<u64>,
    /// How many pixels this explains.
    pub pixels: Option<u64>,
    /// One such pixel.
    pub example: Option<(i64, i64)>,
    /// The reason, in words (untrusted text).
    pub why: String,
}

/// A verdict's `explanations`, skipping anything that is not an object (an
/// older run has none).
pub fn explanations(e: &ResultEntry) -> Vec<Explanation> {
    let Some(list) = e.details.get("explanations").and_then(Value::as_array) else {
        return Vec::new();
    };
    list.iter()
        .filter_map(Value::as_object)
        .map(|o| {
            let s = |k: &str| o.get(k).and_then(Value::as_str).unwrap_or("").to_string();
            let example = o.get("example").and_then(Value::as_array).and_then(|a| {
                match (a.first()?.as_f64(), a.get(1)?.as_f64()) {
                    (Some(x), Some(y)) => Some((x as i64, y as i64)),
                    _ => None,
                }
            });
            Explanation {
                class: s("class"),
                ref_prim: o.get("ref_prim").and_then(Value::as_u64),
                test_prim: o.get("test_prim").and_then(Value::as_u64),
                pixels: o.get("pixels").and_then(Value::as_u64),
                example,
                why: s("why"),
            }
        })
        .collect()
}

/// A text field of a verdict, "" when absent.
pub fn text<'a>(e: &'a ResultEntry, key: &str) -> &'a str {
    e.details.get(key).and_then(Value::as_str).unwrap_or("")
}

/// A path from the run's JSON, relative to the run and never leaving it (the
/// files are the run's own; a hostile or broken entry must not make the report
/// read elsewhere): no absolute path, no `..`, and no symlink on the way
/// inside the run (a link to /etc/hostname as a diff image was copied into
/// the report). A path that does not exist is returned: reading it names it.
pub fn run_relative(run: &Path, rel: &str) -> Option<PathBuf> {
    let p = Path::new(rel);
    if rel.is_empty() || !p.components().all(|c| matches!(c, Component::Normal(_))) {
        return None;
    }
    let mut at = run.to_path_buf();
    for c in p.components() {
        at.push(c);
        match std::fs::symlink_metadata(&at) {
            Ok(meta) if meta.file_type().is_symlink() => return None,
            Ok(_) => {}
            Err(_) => break,
        }
    }
    Some(run.join(p))
}

/// The file stem of a scene's page: the scene name itself when it is a plain
/// file name (so `RUN/report/<scene>.html` is predictable), otherwise a
/// sanitized name plus a hash of the original, so any name maps to a safe,
/// distinct file.
pub fn page_stem(scene: &str) -> String {
    let plain = !scene.is_empty()
        && scene.len() <= 100
        && scene.as_bytes()[0].is_ascii_alphanumeric()
        && scene
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"._+-".contains(&b))
        && scene != "index"
        && !scene.contains("..");
    if plain {
        return scene.to_string();
    }
    let mut clean: String = scene
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .take(40)
        .collect();
    if clean.is_empty() {
        clean.push_str("scene");
    }
    // FNV-1a, 64 bit: stable across runs and platforms, no dependency.
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in scene.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    format!("{clean}-{h:016x}")
}

impl RunData {
    /// Reads RUN/manifest.json (required) and RUN/results.json (optional).
    pub fn load(dir: &Path) -> Result<RunData> {
        crate::check::run_folder::ensure_complete(dir)?;
        let mpath = dir.join("manifest.json");
        let mtext = crate::check::manifest::read_record(&mpath).map_err(|e| {
            anyhow::anyhow!(
                "{}: cannot read (run `rendiff check` first): {e}",
                mpath.display()
            )
        })?;
        let manifest: Manifest = serde_json::from_str(&mtext)
            .with_context(|| format!("{}: not a rendiff manifest", mpath.display()))?;
        if manifest.format != MANIFEST_FORMAT {
            anyhow::bail!(
                "{}: format is {:?}, expected {MANIFEST_FORMAT:?}",
                mpath.display(),
                crate::scene::printable(&manifest.format, 100)
            );
        }
        let rpath = dir.join("results.json");
        let (results, results_problem) = match crate::check::manifest::read_record(&rpath) {
            Err(e) => (
                None,
                Some(format!(
                    "{}: {e} (the comparison did not finish; renders are shown without verdicts)",
                    rpath.display()
                )),
            ),
            Ok(t) => match serde_json::from_str::<Results>(&t) {
                Ok(r) if r.format != RESULTS_FORMAT => (
                    None,
                    Some(format!(
                        "{}: format is {:?}, expected {RESULTS_FORMAT:?}: verdicts not shown",
                        rpath.display(),
                        crate::scene::printable(&r.format, 100)
                    )),
                ),
                Ok(r) => (Some(r), None),
                Err(e) => (None, Some(format!("{}: unreadable: {e}", rpath.display()))),
            },
        };
        let raw = crate::check::manifest::read_record(&rpath)
            .ok()
            .and_then(|t| serde_json::from_str::<Value>(&t).ok());
        let expectations = raw
            .as_ref()
            .and_then(|v| v.get("expectations")?.as_str().map(String::from));
        let calibration = raw
            .as_ref()
            .and_then(|v| v.get("calibration")?.as_object().cloned());
        let mut by_scene: BTreeMap<String, Vec<ResultEntry>> = BTreeMap::new();
        for e in results.iter().flat_map(|r| r.results.iter()) {
            by_scene.entry(e.scene.clone()).or_default().push(e.clone());
        }
        let mut scenes = Vec::new();
        for runs in &manifest.scenes {
            let resolved = run_relative(dir, &runs.resolved).and_then(|p| load_resolved(&p));
            scenes.push(SceneData {
                name: runs.scene.clone(),
                page: page_stem(&runs.scene),
                results: by_scene.remove(&runs.scene).unwrap_or_default(),
                runs: Some(runs.clone()),
                resolved,
            });
        }
        for (name, results) in by_scene {
            scenes.push(SceneData {
                page: page_stem(&name),
                name,
                runs: None,
                results,
                resolved: None,
            });
        }
        Ok(RunData {
            dir: dir.to_path_buf(),
            manifest,
            results,
            results_problem,
            expectations,
            calibration,
            scenes,
        })
    }

    /// Every backend seen in the run, reference first, then in first-seen order.
    pub fn backends(&self) -> Vec<String> {
        let mut out = vec![self.manifest.reference.clone()];
        for s in &self.scenes {
            for b in s.backends() {
                if !out.contains(&b) {
                    out.push(b);
                }
            }
        }
        out
    }

    /// Every buffer name in results.json (id, Z, and whatever comes later), in first-seen order.
    pub fn buffers(&self) -> Vec<String> {
        let mut out: Vec<String> = Vec::new();
        for s in &self.scenes {
            for e in &s.results {
                if !out.contains(&e.buffer) {
                    out.push(e.buffer.clone());
                }
            }
        }
        out
    }
}

fn load_resolved(dir: &Path) -> Option<ResolvedInfo> {
    let v: Value =
        serde_json::from_str(&crate::check::manifest::read_record(&dir.join("scene.json")).ok()?)
            .ok()?;
    let u = |x: &Value, k: &str| x.get(k).and_then(Value::as_u64).unwrap_or(0);
    let cam = v.get("camera").cloned().unwrap_or(Value::Null);
    Some(ResolvedInfo {
        name: v
            .get("name")
            .and_then(Value::as_str)
            .unwrap_or("")
            .to_string(),
        width: u(&cam, "width"),
        height: u(&cam, "height"),
        triangle_count: u(&v, "triangle_count"),
        objects: v
            .get("objects")
            .and_then(Value::as_array)
            .map(|a| {
                a.iter()
                    .map(|o| ObjectInfo {
                        name: o.get("name").and_then(Value::as_str).unwrap_or("").into(),
                        first_prim: u(o, "first_prim"),
                        prim_count: u(o, "prim_count"),
                        material: o
                            .get("material")
                            .and_then(Value::as_u64)
                            .map(|m| m as usize),
                    })
                    .collect()
            })
            .unwrap_or_default(),
        materials: v
            .get("materials")
            .and_then(Value::as_array)
            .map(|a| {
                a.iter()
                    .map(|m| m.get("name").and_then(Value::as_str).unwrap_or("").into())
                    .collect()
            })
            .unwrap_or_default(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_scene_names_keep_their_page_name() {
        assert_eq!(page_stem("pixel_grid"), "pixel_grid");
        assert_eq!(page_stem("a.b-c+1"), "a.b-c+1");
    }

    #[test]
    fn hostile_or_reserved_names_get_safe_distinct_pages() {
        let a = page_stem("<script>alert(1)</script>");
        let b = page_stem("<script>alert(2)</script>");
        assert_ne!(a, b);
        for p in [
            &a,
            &b,
            &page_stem("index"),
            &page_stem(""),
            &page_stem("../x"),
        ] {
            assert!(p
                .bytes()
                .all(|c| c.is_ascii_alphanumeric() || c == b'_' || c == b'-'));
            assert_ne!(p.as_str(), "index");
        }
    }

    #[test]
    fn run_paths_never_leave_the_run() {
        let run = Path::new("/r");
        assert_eq!(
            run_relative(run, "scenes/a/b.exr"),
            Some(PathBuf::from("/r/scenes/a/b.exr"))
        );
        assert_eq!(run_relative(run, "../x"), None);
        assert_eq!(run_relative(run, "/etc/passwd"), None);
        assert_eq!(run_relative(run, ""), None);
    }

    #[test]
    fn run_paths_never_go_through_a_symlink() {
        let t = tempfile::tempdir().unwrap();
        let run = t.path();
        std::fs::create_dir_all(run.join("scenes/a")).unwrap();
        std::fs::write(run.join("scenes/a/real.png"), "png").unwrap();
        std::os::unix::fs::symlink("/etc/hostname", run.join("scenes/a/link.png")).unwrap();
        std::os::unix::fs::symlink(run.join("scenes/a"), run.join("scenes/b")).unwrap();
        let real = run_relative(run, "scenes/a/real.png");
        assert_eq!(real, Some(run.join("scenes/a/real.png")));
        assert_eq!(run_relative(run, "scenes/a/link.png"), None);
        assert_eq!(run_relative(run, "scenes/b/real.png"), None);
        // Missing: returned, so that reading it says what is missing.
        assert!(run_relative(run, "scenes/a/none.png").is_some());
    }
}
