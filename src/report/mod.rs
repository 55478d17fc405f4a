//! `rendiff report RUN`: a static HTML report of a check run, written to
//! RUN/report/ (index.html plus one page per scene, PNG pictures under img/).
//! It needs no server and no network: styles and the one small script are
//! inline, links are relative, and the diff images are copied in, so the
//! folder alone (e.g. a CI artifact) shows what differs, where, by how much,
//! why it was classified that way, and how to rerun it.
//!
//! Layout: [`data`] reads the run, [`images`] draws pictures, [`stats`]
//! computes histograms, [`svg`] plots, [`html`] escapes and wraps pages,
//! [`overview`] and [`scene_page`] compose them.

pub mod causes;
pub mod data;
pub mod html;
pub mod images;
pub mod overview;
pub mod rerun;
pub mod scene_page;
pub mod stats;
pub mod svg;

pub use data::page_stem;

use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// Name of the report folder inside a run.
pub const REPORT_DIR: &str = "report";

/// Where the page of `scene` lives, relative to the run folder (the gate links to it).
pub fn scene_page_path(scene: &str) -> String {
    format!("{REPORT_DIR}/{}.html", page_stem(scene))
}

/// Writes RUN/report/ and returns the path of its index.html. The folder is
/// built beside the old one and swapped in at the end, so a reader never sees
/// a half-written report.
pub fn write(run: &Path) -> Result<PathBuf> {
    let data = data::RunData::load(run)?;
    // A report interrupted while it wrote images could leave its folder
    // (a writer recreated it after the signal handler removed it).
    crate::check::run_folder::remove_abandoned(
        run,
        &[format!(".{REPORT_DIR}.tmp-"), format!(".{REPORT_DIR}.old-")],
    );
    let tmp = run.join(format!(".{REPORT_DIR}.tmp-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    let _pending = crate::shutdown::track_path(&tmp);
    std::fs::create_dir_all(&tmp)
        .with_context(|| format!("{}: cannot create report folder", tmp.display()))?;
    let result = build(&data, &tmp);
    if let Err(e) = result {
        let _ = std::fs::remove_dir_all(&tmp);
        return Err(e);
    }
    let dest = run.join(REPORT_DIR);
    let old = run.join(format!(".{REPORT_DIR}.old-{}", std::process::id()));
    if dest.exists() {
        std::fs::rename(&dest, &old)
            .with_context(|| format!("{}: cannot replace the old report", dest.display()))?;
    }
    std::fs::rename(&tmp, &dest)
        .with_context(|| format!("{}: cannot move the report into place", dest.display()))?;
    let _ = std::fs::remove_dir_all(&old);
    Ok(dest.join("index.html"))
}

fn build(data: &data::RunData, dir: &Path) -> Result<()> {
    let reference = &data.manifest.reference;
    let images: Vec<images::SceneImages> = data
        .scenes
        .iter()
        .map(|s| images::build(&data.dir, reference, s, dir))
        .collect();
    for (s, imgs) in data.scenes.iter().zip(&images) {
        let path = dir.join(format!("{}.html", s.page));
        std::fs::write(&path, scene_page::render(data, s, imgs))
            .with_context(|| format!("{}: cannot write", path.display()))?;
    }
    let index = dir.join("index.html");
    std::fs::write(&index, overview::render(data, &images))
        .with_context(|| format!("{}: cannot write", index.display()))?;
    Ok(())
}
