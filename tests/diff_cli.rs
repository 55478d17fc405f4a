//! `rendiff diff A.exr B.exr` through the real binary: every buffer present in
//! either file is judged bit for bit (IDs, depth, normals, radiance), a buffer
//! in one file only is a difference that names it, and two files that share
//! no buffer are an error. EXRs come from `rendiff render`, then small
//! hand-made changes to copies of them.

use exr::prelude::*;
use std::path::{Path, PathBuf};
use std::process::Output;

mod common;
use common::cli::{render_ok, rendiff};

fn render(scene: &str, renderer: &str, out: &Path) {
    render_ok(scene, renderer, &["--spp", "2"], out);
}

fn diff(a: &Path, b: &Path) -> (Option<i32>, String, String) {
    let o: Output = rendiff().arg("diff").arg(a).arg(b).output().unwrap();
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// Copies `src` to `dst`, passing every channel (name, samples) through `f`;
/// `f` returns false to drop a channel.
fn rewrite(src: &Path, dst: &Path, f: impl Fn(&str, &mut FlatSamples) -> bool) {
    let layer = rendiff::exr_io::read_layer(src).unwrap();
    let mut list = Vec::new();
    for ch in layer.channel_data.list {
        let name = ch.name.to_string();
        let mut samples = ch.sample_data;
        if f(&name, &mut samples) {
            list.push(AnyChannel::new(name.as_str(), samples));
        }
    }
    let layer = Layer::new(
        layer.size,
        layer.attributes,
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(SmallVec::from_vec(list)),
    );
    Image::from_layer(layer).write().to_file(dst).unwrap();
}

/// The line of `out` about `buffer`.
fn line<'a>(out: &'a str, buffer: &str) -> &'a str {
    out.lines()
        .find(|l| l.starts_with(&format!("{buffer}: ")))
        .unwrap_or_else(|| panic!("no line for {buffer} in:\n{out}"))
}

const VISIBILITY: [&str; 6] = ["id.prim", "id.object", "Z", "N.x", "N.y", "N.z"];

struct Renders {
    _dir: tempfile::TempDir,
    dir: PathBuf,
    raster: PathBuf,
    trace: PathBuf,
}

/// A shaded scene rendered by both core loops (visibility and radiance).
fn shaded() -> Renders {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().to_path_buf();
    let (raster, trace) = (d.join("raster.exr"), d.join("trace.exr"));
    render("scenes/lambert_point.toml", "raster", &raster);
    render("scenes/lambert_point.toml", "trace", &trace);
    Renders {
        _dir: dir,
        dir: d,
        raster,
        trace,
    }
}

#[test]
fn identical_renders_get_one_identical_line_per_buffer() {
    let r = shaded();
    let (code, out, err) = diff(&r.raster, &r.trace);
    assert_eq!(code, Some(0), "{out}{err}");
    for b in VISIBILITY.iter().chain(&["R", "G", "B"]) {
        assert!(
            line(&out, b).contains("identical"),
            "{b} not identical:\n{out}"
        );
    }
}

#[test]
fn one_flipped_normal_is_a_difference_at_its_pixel() {
    let r = shaded();
    let bad = r.dir.join("flipped.exr");
    let width = rendiff::exr_io::read_buffers(&r.trace).unwrap().width;
    let k = 5 * width + 7; // pixel (7, 5)
    rewrite(&r.trace, &bad, |name, s| {
        if let (true, FlatSamples::F32(v)) = (name == "N.z", s) {
            v[k] = -v[k];
        }
        true
    });
    let (code, out, err) = diff(&r.raster, &bad);
    assert_eq!(code, Some(1), "{out}{err}");
    let l = line(&out, "N.z");
    assert!(
        l.contains("1 of") && l.contains("first at (7, 5)"),
        "{l}\n{out}"
    );
    for b in ["id.prim", "Z", "N.x", "N.y", "R"] {
        assert!(line(&out, b).contains("identical"), "{out}");
    }
}

#[test]
fn one_changed_radiance_value_is_a_difference() {
    let r = shaded();
    let bad = r.dir.join("r.exr");
    rewrite(&r.trace, &bad, |name, s| {
        if let (true, FlatSamples::F32(v)) = (name == "R", s) {
            let i = v.len() / 2;
            v[i] = f32::from_bits(v[i].to_bits() ^ 1); // one last bit
        }
        true
    });
    let (code, out, err) = diff(&r.raster, &bad);
    assert_eq!(code, Some(1), "{out}{err}");
    assert!(line(&out, "R").contains("1 of"), "{out}");
    assert!(line(&out, "G").contains("identical"), "{out}");
}

#[test]
fn a_dropped_channel_is_a_difference_that_names_it() {
    let r = shaded();
    let bad = r.dir.join("dropped.exr");
    rewrite(&r.trace, &bad, |name, _| name != "N.y");
    let (code, out, err) = diff(&r.raster, &bad);
    assert_eq!(code, Some(1), "{out}{err}");
    let l = line(&out, "N.y");
    assert!(l.contains("only in") && l.contains("raster.exr"), "{l}");
    let (code, out, _) = diff(&bad, &r.raster);
    assert_eq!(code, Some(1));
    assert!(line(&out, "N.y").contains("missing in"), "{out}");
}

#[test]
fn buffers_both_files_lack_are_not_differences() {
    let r = shaded();
    let (a, b) = (r.dir.join("a.exr"), r.dir.join("b.exr"));
    let no_ids = |name: &str, _: &mut FlatSamples| !name.starts_with("id.");
    rewrite(&r.raster, &a, no_ids);
    rewrite(&r.trace, &b, no_ids);
    let (code, out, err) = diff(&a, &b);
    assert_eq!(code, Some(0), "{out}{err}");
    assert!(!out.contains("id.prim"), "{out}");
    assert!(line(&out, "Z").contains("identical"), "{out}");
}

#[test]
fn files_with_no_buffer_in_common_are_an_error() {
    let r = shaded();
    let (a, b) = (r.dir.join("z_only.exr"), r.dir.join("n_only.exr"));
    rewrite(&r.raster, &a, |name, _| name == "Z");
    rewrite(&r.trace, &b, |name, _| name.starts_with("N."));
    let (code, out, err) = diff(&a, &b);
    assert_eq!(code, Some(2), "{out}{err}");
    assert!(out.is_empty(), "{out}");
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    assert!(
        err.contains("no buffer in common") && err.contains("z_only.exr"),
        "{err}"
    );
}

#[test]
fn one_depth_bit_is_a_difference() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a.exr"), dir.path().join("b.exr"));
    render("scenes/three_triangles.toml", "raster", &a);
    let width = rendiff::exr_io::read_buffers(&a).unwrap().width;
    let z = rendiff::exr_io::read_buffers(&a).unwrap().z.unwrap();
    let k = z.iter().position(|v| v.is_finite()).unwrap();
    rewrite(&a, &b, |name, s| {
        if let (true, FlatSamples::F32(v)) = (name == "Z", s) {
            v[k] = f32::from_bits(v[k].to_bits() + 1);
        }
        true
    });
    let (code, out, err) = diff(&a, &b);
    assert_eq!(code, Some(1), "{out}{err}");
    let l = line(&out, "Z");
    assert!(
        l.contains("1 of") && l.contains(&format!("first at ({}, {})", k % width, k / width)),
        "{l}"
    );
}
