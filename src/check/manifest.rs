//! The run's machine-readable records (docs/run-format.md): what was rendered
//! (manifest.json, written here) and how it compared (results.json, written by
//! the Python comparison and read back here).

use serde::{Deserialize, Serialize};

/// File in a run folder whose `check` has started and not finished (it was
/// interrupted, or failed before results.json): `gate`, `report` and `bless`
/// refuse such a folder (`run_folder::ensure_complete`).
pub const INCOMPLETE_MARKER: &str = "INCOMPLETE";

pub use crate::vocab::{MANIFEST_FORMAT, RESULTS_FORMAT};

/// Largest run record (manifest.json, results.json, a baseline) rendiff
/// reads: 256 MiB. The main job's 520 entries make a 0.7 MiB results.json
/// (about 1.4 KiB an entry), so this is some 180,000 entries, 350 times
/// today's; a bigger file, a device (`/dev/zero` as a baseline filled
/// memory until the kernel killed the process) or a FIFO is refused with
/// one line instead.
pub const MAX_RECORD_BYTES: u64 = 256 << 20;

/// A run record's text, read as scene files are
/// ([`crate::scene::read_regular_file`]: regular files only, at most
/// [`MAX_RECORD_BYTES`], never blocking on a FIFO); the problem in words
/// otherwise (the caller names the file).
pub fn read_record(path: &std::path::Path) -> Result<String, String> {
    crate::scene::read_regular_file(path, MAX_RECORD_BYTES).and_then(crate::scene::utf8_text)
}

/// manifest.json.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Manifest {
    /// Format tag.
    pub format: String,
    /// Backend every other one is compared against.
    pub reference: String,
    /// When the run started (seconds since the Unix epoch).
    pub created_unix: u64,
    /// rendiff's version.
    pub rendiff_version: String,
    /// One entry per scene.
    pub scenes: Vec<SceneRuns>,
    /// The options that decide the run's verdicts besides its scenes and
    /// renderers (absent in runs of older rendiffs): `merge` refuses shards
    /// run with different ones.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub options: Option<RunOptions>,
    /// Where check ran and the files it was given that a reproduction needs
    /// again (absent in runs of older rendiffs): the report's commands carry them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rerun: Option<Rerun>,
    /// The split this run is a shard of (`check --shard K/N`); absent in a
    /// run of all scenes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shard: Option<ShardRecord>,
}

/// What a check was told that changes its verdicts: shards of one run must
/// agree on every field (`merge`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RunOptions {
    /// `--only`, as given (None: every backend).
    pub only: Option<Vec<String>>,
    /// Hash of the run's copy of the `--renderers` file (`sha256:` and hex;
    /// empty without one): the declarations, precision included.
    #[serde(default)]
    pub renderers_sha256: String,
    /// Whether the calibration probes ran.
    pub calibration: bool,
    /// The core's path-tracing seed.
    pub seed: u64,
    /// The core's samples per pixel (None: each scene's own).
    pub spp: Option<u32>,
    /// The injected shading error, if any (`--inject-bias`).
    pub bias: Option<String>,
}

/// What a printed reproduction command needs besides [`RunOptions`]
/// (report/rerun.rs): the folder check ran in (scene paths are relative to
/// it), the renderers file (a declared renderer's name means nothing
/// without it) and a probe folder other than rendiff's own.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Rerun {
    /// The working folder of the check.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cwd: Option<String>,
    /// `--renderers`, absolute.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub renderers_file: Option<String>,
    /// `--calibration`, when not rendiff's scenes/calibration.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration_dir: Option<String>,
    /// `--expectations`, when not rendiff's tests/expectations.toml.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub expectations_file: Option<String>,
}

/// A shard's place in its split: its index and the whole deal, so that
/// `merge` can tell a missing shard, a shard of another split and a scene
/// of the same name from another file apart.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ShardRecord {
    /// This shard, 1-based.
    pub index: usize,
    /// Shards in the split.
    pub total: usize,
    /// Every scene of the split (all shards), in the order given.
    pub deal: Vec<DealtScene>,
}

/// One scene of a split and the shard it was dealt to.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct DealtScene {
    /// Scene name (the file's stem).
    pub scene: String,
    /// The scene file, as given to check.
    pub file: String,
    /// Hash of the scene file's bytes (`sha256:` and hex).
    pub sha256: String,
    /// The shard (1-based) that renders it.
    pub shard: usize,
}

/// All renders of one scene.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SceneRuns {
    /// Scene file stem (the folder name under scenes/).
    pub scene: String,
    /// The scene file.
    pub scene_file: String,
    /// Resolved scene folder, relative to the run.
    pub resolved: String,
    /// Hash of that folder as exported (`sha256:` and hex, `check::inputs`):
    /// every external render reads a copy of it and is checked against it
    /// afterwards; empty in runs of older rendiffs.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub resolved_sha256: String,
    /// Features the scene requires.
    pub requires: Vec<String>,
    /// Why the scene is in the run: empty for an ordinary scene,
    /// `"calibration"` for a camera calibration probe (`check::CALIBRATION_ROLE`).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub role: String,
    /// One entry per backend.
    pub renders: Vec<RenderRecord>,
}

/// One backend's render of one scene.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct RenderRecord {
    /// Backend name.
    pub backend: String,
    /// What happened (`ok`, `skipped`, `error`: `vocab::RenderStatus`, spelled
    /// in the file as before).
    pub status: crate::vocab::RenderStatus,
    /// Why it was skipped.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub reason: String,
    /// What went wrong.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub message: String,
    /// Buffer file, relative to the run.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub exr: String,
    /// Seconds the render took (including process start for external ones).
    #[serde(default)]
    pub time_s: f64,
    /// Backend version string.
    #[serde(default)]
    pub version: String,
    /// Command that reproduces this render, its buffer written beside the
    /// run (`RUN.repro/render/...`), never over the run's own.
    #[serde(default)]
    pub command: String,
    /// Buffers it produced.
    #[serde(default)]
    pub buffers: Vec<String>,
    /// Backend-specific details (settings, precision, operation counts).
    #[serde(default)]
    pub info: serde_json::Value,
    /// Peak resident memory (bytes) of the process that rendered, in measuring
    /// runs (`check::run_isolating`), where every render runs in a child
    /// process of its own: memory per renderer.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_rss_bytes: Option<u64>,
}

/// results.json.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Results {
    /// Format tag.
    pub format: String,
    /// Reference backend.
    pub reference: String,
    /// One entry per (scene, backend, buffer).
    pub results: Vec<ResultEntry>,
}

/// One comparison verdict.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ResultEntry {
    /// Scene stem.
    pub scene: String,
    /// Backend compared with the reference.
    pub backend: String,
    /// `id` or `Z`.
    pub buffer: String,
    /// pass | fail | skipped | error | expected_fail | unexpected_pass.
    pub status: String,
    /// Why (skip reason, error message, failure summary, expectation reason).
    #[serde(default)]
    pub reason: String,
    /// Everything else (counts, errors, tolerance, images, command).
    #[serde(flatten)]
    pub details: serde_json::Map<String, serde_json::Value>,
}

impl ResultEntry {
    /// True for verdicts that must turn a run red.
    pub fn is_failure(&self) -> bool {
        crate::vocab::Status::parse(&self.status).is_some_and(crate::vocab::Status::is_bad)
    }

    /// `scene::backend::buffer`, the name a test or a report row uses.
    pub fn key(&self) -> String {
        format!("{}::{}::{}", self.scene, self.backend, self.buffer)
    }
}
