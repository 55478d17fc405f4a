//! External renderers for benchmarks: the Python harness's `render` command
//! (pyrender, Mitsuba, POV-Ray) as a subprocess with a timeout, exactly as
//! `rendiff check` runs it, returning the wall time, the harness's own
//! `time_s` and the backend's sub-timings (`info`). A missing venv or a failing
//! renderer becomes a recorded reason, never a failed benchmark.

use rendiff::check::process::run_with_timeout;
use rendiff::scene::resolve::ResolvedScene;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

/// One harness render.
#[derive(Debug, Clone)]
pub struct HarnessRun {
    /// Subprocess wall-clock seconds (Python start-up and imports included).
    pub wall_s: f64,
    /// The harness's `time_s`: the backend's render call (imports excluded).
    pub time_s: Option<f64>,
    /// The backend's `info` (settings, sub-timings).
    pub info: Value,
    /// Backend version string.
    pub version: Option<String>,
}

/// Where a harness render is run from.
#[derive(Debug, Clone)]
pub struct Harness {
    /// Repository root (holds `harness/` and the venv).
    pub root: PathBuf,
    /// Time limit per render.
    pub timeout: Duration,
    /// Scratch folder for captured output.
    pub scratch: PathBuf,
}

impl Harness {
    /// The harness if its Python exists, else why not (recorded as the skip reason).
    pub fn find(root: &Path, timeout: Duration, scratch: &Path) -> Result<Harness, String> {
        if let Some(missing) = rendiff::check::home::missing_python(root) {
            return Err(missing);
        }
        Ok(Harness {
            root: root.to_path_buf(),
            timeout,
            scratch: scratch.to_path_buf(),
        })
    }

    /// Exports `scene` to `dir/resolved` for the harness to read.
    pub fn export(&self, scene: &ResolvedScene, dir: &Path) -> Result<PathBuf, String> {
        let out = dir.join("resolved");
        rendiff::scene::export::export(scene, &out).map_err(|e| format!("export failed: {e:#}"))?;
        Ok(out)
    }

    /// Renders a resolved scene with one backend into `out` (EXR), at the
    /// backend's default samples, seed and settings.
    pub fn render(&self, backend: &str, resolved: &Path, out: &Path) -> Result<HarnessRun, String> {
        self.render_with(backend, resolved, out, None, None, &[])
    }

    /// Like [`Harness::render`], plus the backend's own quality settings as
    /// `render` options (e.g. `--aa-method 2`), which the harness validates and
    /// refuses for a backend without them. A skipped render (the backend cannot
    /// model the scene, exit 3) is an error carrying the harness's reason.
    pub fn render_with(
        &self,
        backend: &str,
        resolved: &Path,
        out: &Path,
        spp: Option<u32>,
        seed: Option<u64>,
        settings: &[String],
    ) -> Result<HarnessRun, String> {
        let mut cmd = Command::new(rendiff::check::python(&self.root));
        rendiff::check::home::harness_path(&mut cmd, &self.root);
        cmd.current_dir(&self.root)
            .args(["-m", "rendiff_harness", "render", "--backend", backend])
            .arg("--scene")
            .arg(resolved)
            .arg("--out")
            .arg(out)
            .arg("--timeout")
            .arg(self.timeout.as_secs().to_string());
        if let Some(s) = spp {
            cmd.arg("--spp").arg(s.to_string());
        }
        if let Some(s) = seed {
            cmd.arg("--seed").arg(s.to_string());
        }
        cmd.args(settings);
        let limit = self.timeout + Duration::from_secs(30);
        let o = run_with_timeout(cmd, limit, &self.scratch.join(backend))
            .map_err(|e| format!("{backend}: cannot run the harness: {e:#}"))?;
        if o.timed_out {
            return Err(format!("{backend}: timed out after {} s", limit.as_secs()));
        }
        if o.code == Some(rendiff::check::isolated::EXIT_SKIPPED) {
            let reason = last_json_line(&o.stdout)
                .and_then(|v| v.get("reason").and_then(Value::as_str).map(String::from))
                .unwrap_or_else(|| "no reason given".into());
            return Err(format!("{backend}: skipped: {reason}"));
        }
        if o.code != Some(0) {
            return Err(format!(
                "{backend}: exit {:?}: {}",
                o.code,
                o.stderr_tail(4)
            ));
        }
        let line = o
            .stdout
            .lines()
            .rev()
            .find(|l| l.trim_start().starts_with('{'))
            .ok_or_else(|| format!("{backend}: no JSON line on stdout"))?;
        let v: Value = serde_json::from_str(line)
            .map_err(|e| format!("{backend}: unreadable JSON line: {e}"))?;
        Ok(HarnessRun {
            wall_s: o.seconds,
            time_s: v.get("time_s").and_then(Value::as_f64),
            info: v.get("info").cloned().unwrap_or(Value::Null),
            version: v.get("version").and_then(Value::as_str).map(String::from),
        })
    }
}

/// The last line of `stdout` that parses as a JSON object (the harness's result line).
fn last_json_line(stdout: &str) -> Option<Value> {
    stdout
        .lines()
        .rev()
        .filter(|l| l.trim_start().starts_with('{'))
        .find_map(|l| serde_json::from_str(l).ok())
}

/// Reads a number at a JSON path like `["radiance", "timings_s", "render"]`.
pub fn number_at(v: &Value, path: &[&str]) -> Option<f64> {
    path.iter().try_fold(v, |v, k| v.get(k))?.as_f64()
}
