//! The commands the report prints to reproduce a verdict or a whole run. A
//! printed command used to fail for a declared renderer (`--only castr: no
//! such backend`: the `--renderers` file was missing) and would have
//! overwritten the run being viewed. Each command now carries every option
//! that made the run's verdicts (manifest.json `options` and `rerun`: the
//! renderers file, the probes or `--no-calibration`, seed, samples, injected
//! bias, the expectations file), runs from the folder check ran in, and
//! writes to a new folder beside the run, never to the run itself.

use super::data::{page_stem, RunData, SceneData};
use crate::check::process::shell_line;

/// The folder a reproduction writes to: beside the run, named after what it
/// reruns (`RUN.repro/<what>`); never the run being viewed.
pub fn repro_dir(data: &RunData, what: &str) -> String {
    let mut dir = data.dir.clone().into_os_string();
    dir.push(".repro");
    std::path::Path::new(&dir).join(what).display().to_string()
}

/// The options after the scenes that made this run's verdicts.
fn options(data: &RunData) -> Vec<String> {
    let mut words = Vec::new();
    let rerun = data.manifest.rerun.clone().unwrap_or_default();
    if let Some(f) = &rerun.renderers_file {
        words.extend(["--renderers".to_string(), f.clone()]);
    }
    if let Some(o) = &data.manifest.options {
        if !o.calibration {
            words.push("--no-calibration".into());
        } else if let Some(dir) = &rerun.calibration_dir {
            words.extend(["--calibration".to_string(), dir.clone()]);
        }
        if o.seed != crate::check::CHECK_SEED {
            words.extend(["--seed".to_string(), o.seed.to_string()]);
        }
        if let Some(spp) = o.spp {
            words.extend(["--spp".to_string(), spp.to_string()]);
        }
        if let Some(bias) = &o.bias {
            words.extend(["--inject-bias".to_string(), bias.clone()]);
        }
    }
    // Runs that recorded their inputs name a non-default expectations file
    // there; older ones only in results.json.
    let expectations = match &data.manifest.rerun {
        Some(r) => r.expectations_file.clone(),
        None => super::overview::expectations_arg(data),
    };
    if let Some(e) = expectations {
        words.extend(["--expectations".to_string(), e]);
    }
    words
}

/// `cd FOLDER && ` where check ran (its scene paths are relative to it), ""
/// for a run that did not record it.
fn cd(data: &RunData) -> String {
    match data.manifest.rerun.as_ref().and_then(|r| r.cwd.as_ref()) {
        Some(dir) => format!("{} && ", shell_line(vec!["cd".to_string(), dir.clone()])),
        None => String::new(),
    }
}

/// The command that reruns one backend on one scene and compares it again,
/// with the run's options, into a new folder.
pub fn verdict_command(data: &RunData, scene: &SceneData, backend: &str) -> Option<String> {
    let file = &scene.runs.as_ref()?.scene_file;
    let mut words = vec![
        "rendiff".to_string(),
        "check".into(),
        file.clone(),
        "--only".into(),
        backend.to_string(),
    ];
    words.extend(options(data));
    words.push("-o".into());
    words.push(repro_dir(
        data,
        &format!("{}-{}", page_stem(&scene.name), page_stem(backend)),
    ));
    Some(format!("{}{}", cd(data), shell_line(words)))
}

/// The command that reruns the whole run (its scenes, its `--only`), with its
/// options, into a new folder.
pub fn run_command(data: &RunData) -> String {
    let mut words: Vec<String> = vec!["rendiff".into(), "check".into()];
    for s in &data.scenes {
        if let Some(r) = s.runs.as_ref().filter(|r| r.role != "calibration") {
            words.push(r.scene_file.clone());
        }
    }
    if let Some(only) = data.manifest.options.as_ref().and_then(|o| o.only.clone()) {
        words.push("--only".into());
        words.push(only.join(","));
    }
    words.extend(options(data));
    words.push("-o".into());
    words.push(repro_dir(data, "all"));
    format!("{}{}", cd(data), shell_line(words))
}
