//! `rendiff doctor`: what this installation found, in one screen, so a new
//! user (or a bug report) sees at once which binary, harness, Python and
//! renderers a `check` would use, and why one is missing.
//!
//! The harness is found exactly as `check` finds it ([`crate::check::home`]),
//! and asked the same questions (`where --json`, `info --json`), so what the
//! doctor says is what a run would get.

use crate::check::home;
use crate::check::process::run_with_timeout;
use crate::scene::printable;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

/// How long one harness question may take: `info` asks every renderer its
/// version once, each bounded by the harness's own version timeout.
const ASK_TIMEOUT: Duration = Duration::from_secs(120);

/// Prints the report to stdout; false when the harness could not be found or
/// did not answer (the reason is printed with the one command that fixes it).
pub fn run(renderers: Option<&Path>) -> bool {
    let exe = std::env::current_exe()
        .map(|p| p.display().to_string())
        .unwrap_or_else(|e| format!("unknown ({e})"));
    crate::outln!(
        "rendiff {}: {}",
        env!("CARGO_PKG_VERSION"),
        printable(&exe, 500)
    );
    crate::outln!("core renderers: raster, trace (built in)");
    match crate::backends::embree::version() {
        Ok(v) => crate::outln!("embree: {} (linked in)", printable(&v, 200)),
        Err(e) => crate::outln!("embree: unavailable: {}", printable(&e.to_string(), 500)),
    }
    let found = match home::search() {
        Ok(f) => f,
        Err(e) => {
            crate::outln!("harness: NOT FOUND: {}", printable(&format!("{e:#}"), 2000));
            return false;
        }
    };
    crate::outln!("harness: found through {}", found.how);
    crate::outln!(
        "rendiff's data: {}",
        printable(&found.root.display().to_string(), 500)
    );
    crate::outln!(
        "python: {}",
        printable(&found.python.display().to_string(), 500)
    );
    let scratch = std::env::temp_dir();
    let ask = |args: &[&str]| {
        let mut cmd = Command::new(&found.python);
        cmd.current_dir(&found.root)
            .args(["-m", "rendiff_harness"])
            .args(args);
        home::harness_path(&mut cmd, &found.root);
        match renderers {
            Some(f) => cmd.env(crate::check::RENDERERS_ENV, f),
            None => cmd.env_remove(crate::check::RENDERERS_ENV),
        };
        run_with_timeout(cmd, ASK_TIMEOUT, &scratch)
    };
    let answer = |args: &[&str]| -> Result<serde_json::Value, String> {
        let o = ask(args).map_err(|e| format!("cannot run it: {e:#}"))?;
        if o.code != Some(0) {
            return Err(format!("{}: {}", o.how(), o.stderr_tail(3)));
        }
        serde_json::from_str(o.stdout.trim()).map_err(|e| format!("unreadable answer: {e}"))
    };
    let fix = "run scripts/setup.sh in the checkout (or reinstall the harness: VENV/bin/pip install ./harness)";
    match answer(&["where", "--json"]) {
        Ok(w) => {
            let field = |k: &str| w.get(k).and_then(|v| v.as_str()).unwrap_or("?").to_string();
            crate::outln!(
                "harness package: {} (version {}, Python {})",
                printable(&field("package"), 500),
                printable(&field("version"), 100),
                printable(&field("python_version"), 100)
            );
        }
        Err(why) => {
            crate::outln!(
                "harness: DOES NOT START ({}); fix: {fix}",
                printable(&why, 2000)
            );
            return false;
        }
    }
    let info = match answer(&["info", "--json"]) {
        Ok(v) => v,
        Err(why) => {
            crate::outln!(
                "renderers: the harness could not list them ({}); fix: {fix}",
                printable(&why, 2000)
            );
            return false;
        }
    };
    crate::outln!("renderers of the harness:");
    let rows = info
        .get("backends")
        .and_then(|b| b.as_array())
        .cloned()
        .unwrap_or_default();
    for b in rows {
        let text = |k: &str| b.get(k).and_then(|v| v.as_str()).map(|s| printable(s, 300));
        let name = text("name").unwrap_or_else(|| "?".into());
        let status = if b.get("available").and_then(|v| v.as_bool()) == Some(true) {
            "ok".to_string()
        } else {
            format!("unavailable: {}", text("reason").unwrap_or_default())
        };
        let declared = text("declared_in")
            .map(|f| format!(" (declared in {f})"))
            .unwrap_or_default();
        crate::outln!(
            "  {name}: {} [{status}]{declared}",
            text("version").unwrap_or_else(|| "-".into())
        );
    }
    true
}
