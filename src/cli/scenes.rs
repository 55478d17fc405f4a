//! The scene commands: `scenes` (list a folder), `export` (the resolved
//! scene), `scene new` (a scene file for a model) and `vocab` (the words).

use super::{exit, load_scene};
use anyhow::{Context, Result};
use rendiff::scene::Scene;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// `rendiff scenes DIR`: each scene file with the features it requires and
/// its description; exit 2 when one does not load.
pub fn list(dir: &Path) -> Result<ExitCode> {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("{}: cannot list scenes", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    entries.sort();
    let mut failed = false;
    for p in entries {
        match Scene::load(&p) {
            Ok(s) => {
                // A file's name and its description are the user's text:
                // shown escaped, so that neither can forge a listing line
                // or send the terminal control sequences.
                let req: Vec<&str> = s.requires.iter().map(String::as_str).collect();
                let name = rendiff::scene::printable(&p.display().to_string(), 200);
                rendiff::outln!("{name:<28} requires: {}", req.join(", "));
                if !s.file.description.is_empty() {
                    let text = rendiff::scene::printable(&s.file.description, 500);
                    rendiff::outln!("{:<28}   {text}", "");
                }
            }
            Err(e) => {
                failed = true;
                rendiff::errln!("error: {e}");
            }
        }
    }
    Ok(exit(!failed, 2))
}

/// `rendiff export SCENE -o DIR`.
pub fn export(scene: &Path, output: &Path) -> Result<ExitCode> {
    let resolved = load_scene(scene)?;
    rendiff::scene::export::export(&resolved, output)?;
    rendiff::outln!(
        "exported {} triangles to {}",
        resolved.triangles.len(),
        output.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// `rendiff scene new MODEL -o SCENE.toml`.
pub fn new(model: &Path, output: &Path) -> Result<ExitCode> {
    let mesh = rendiff::scene::model::write_model_scene(model, output)?;
    rendiff::outln!(
        "wrote {} (mesh = {:?})",
        rendiff::scene::printable(&output.display().to_string(), 500),
        rendiff::scene::printable(&mesh, 500)
    );
    Ok(ExitCode::SUCCESS)
}

/// `rendiff vocab [--json]`: the words from their one definition.
pub fn vocab(json: bool) -> Result<ExitCode> {
    let v = rendiff::vocab::json();
    if json {
        rendiff::outln!("{v}");
    } else if let Some(map) = v.as_object() {
        for (k, words) in map {
            let list: Vec<&str> = words
                .as_array()
                .map(|a| a.iter().filter_map(|w| w.as_str()).collect())
                .unwrap_or_default();
            rendiff::outln!("{k:<20} {}", list.join(", "));
        }
    }
    Ok(ExitCode::SUCCESS)
}
