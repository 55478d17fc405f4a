//! The report's pictures of one scene, written as PNG files beside its pages:
//! every backend's radiance (when its EXR has R,G,B), depth on one color scale
//! shared by all backends of the scene (so colors compare across images), IDs
//! in false color, and the diff maps. The harness's diff maps (ID mismatches
//! colored edge vs interior, depth-error heat) are copied so the report folder
//! stands alone; where the harness wrote none, simpler ones are drawn here.
//! A broken or missing EXR becomes a note on the page, never a failed report.

use super::data::{page_stem, run_relative, SceneData};
use super::stats::{object_mismatches, Histogram, ObjectMismatches};
use crate::exr_io::{read_buffers, Buffers};
use crate::frame::BACKGROUND_ID;
use crate::preview::{depth_colors, finite_range, id_color, srgb8 as srgb};
use crate::vocab::RenderStatus;
use anyhow::Result;
use std::path::Path;

/// What a picture shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Linear R,G,B, clamped to [0, 1] and sRGB-encoded.
    Radiance,
    /// Planar depth through viridis on the scene's shared range.
    Depth,
    /// id.prim in false color.
    Ids,
    /// ID mismatches against the reference (edge vs interior when the harness classified them).
    IdDiff,
    /// |ΔZ| heat map against the reference.
    DepthDiff,
    /// Radiance error against the reference, in units of its tolerance.
    RadianceDiff,
    /// Any other diff image the comparison listed for an entry.
    OtherDiff,
}

impl Kind {
    /// Short label used in captions and the flip menus.
    pub fn label(self) -> &'static str {
        match self {
            Kind::Radiance => "radiance",
            Kind::Depth => "depth",
            Kind::Ids => "ids",
            Kind::IdDiff => "id diff",
            Kind::DepthDiff => "Z diff",
            Kind::RadianceDiff => "RGB diff",
            Kind::OtherDiff => "diff",
        }
    }

    /// True for comparisons against the reference.
    pub fn is_diff(self) -> bool {
        matches!(
            self,
            Kind::IdDiff | Kind::DepthDiff | Kind::RadianceDiff | Kind::OtherDiff
        )
    }
}

/// One picture in the report folder.
#[derive(Debug, Clone)]
pub struct Picture {
    /// Backend it belongs to.
    pub backend: String,
    /// What it shows.
    pub kind: Kind,
    /// Path relative to the report folder (safe characters only).
    pub file: String,
    /// Caption text (plain, escaped by the page).
    pub caption: String,
}

/// Everything drawn or measured for one scene.
#[derive(Debug, Clone, Default)]
pub struct SceneImages {
    /// Pictures in backend order, then kind order.
    pub pictures: Vec<Picture>,
    /// The shared depth range (lo, hi) and where it came from.
    pub depth_range: Option<(f32, f32, String)>,
    /// Pixels clamped to the shared range, per backend (only nonzero ones).
    pub clamped: Vec<(String, u64)>,
    /// Depth error histogram per non-reference backend with Z.
    pub histograms: Vec<(String, Histogram)>,
    /// ID mismatches per object, per non-reference backend with IDs.
    pub objects: Vec<(String, ObjectMismatches)>,
    /// Problems met while drawing (unreadable EXRs, size mismatches...).
    pub notes: Vec<String>,
}

struct Loaded {
    backend: String,
    buffers: Buffers,
    rgb: Option<Vec<[f32; 3]>>,
}

/// Reads R,G,B from an EXR if it has all three (radiance is optional per scene).
pub fn read_rgb(path: &Path) -> Result<Option<Vec<[f32; 3]>>> {
    Ok(crate::exr_io::read_radiance(path)?.map(|img| img.rgb))
}

fn save_png(path: &Path, w: usize, h: usize, px: &[[u8; 3]]) -> Result<()> {
    crate::preview::save_png(path, w as u32, h as u32, px)
}

/// Fallback ID map when the harness wrote none: no edge/interior classes, just where IDs differ.
fn id_diff_colors(r: &[u32], t: &[u32]) -> Vec<[u8; 3]> {
    r.iter()
        .zip(t)
        .map(|(&a, &b)| match (a == b, a == BACKGROUND_ID) {
            (true, true) => [0, 0, 0],
            (true, false) => [56, 56, 56],
            (false, _) => [255, 48, 48],
        })
        .collect()
}

/// Fallback |ΔZ| map (same look as the harness's): inferno scaled by the largest
/// error, cyan where only one side hits, black where neither does.
fn depth_diff_colors(r: &[f32], t: &[f32]) -> Vec<[u8; 3]> {
    let max = r
        .iter()
        .zip(t)
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| (f64::from(*a) - f64::from(*b)).abs())
        .fold(0.0, f64::max);
    let s = if max > 0.0 { max } else { 1.0 };
    r.iter()
        .zip(t)
        .map(|(&a, &b)| match (a.is_finite(), b.is_finite()) {
            (false, false) => [0, 0, 0],
            (true, true) => {
                let c = colorous::INFERNO
                    .eval_continuous(((f64::from(a) - f64::from(b)).abs() / s).clamp(0.0, 1.0));
                [c.r, c.g, c.b]
            }
            _ => [0, 255, 255],
        })
        .collect()
}

/// Largest diff image copied into a report: a PNG of the largest image
/// rendiff renders (16384 x 16384 pixels, 3 bytes each, uncompressed) fits.
const MAX_DIFF_IMAGE_BYTES: u64 = 1 << 30;

/// Copies a diff image the comparison wrote, only if it is a regular file
/// within [`MAX_DIFF_IMAGE_BYTES`] (`std::fs::copy` on a FIFO there blocked
/// the report forever).
fn copy_regular(src: &Path, dst: &Path) -> std::result::Result<(), String> {
    use std::io::Read;
    let (file, _) = crate::scene::open_regular_file(src, MAX_DIFF_IMAGE_BYTES)?;
    let mut out = std::fs::File::create(dst).map_err(|e| format!("cannot be written: {e}"))?;
    std::io::copy(&mut file.take(MAX_DIFF_IMAGE_BYTES), &mut out)
        .map(|_| ())
        .map_err(|e| format!("cannot be copied: {e}"))
}

/// Draws and measures everything for one scene into `report_dir/img/<page>/`.
pub fn build(run: &Path, reference: &str, scene: &SceneData, report_dir: &Path) -> SceneImages {
    let mut out = SceneImages::default();
    let rel_dir = format!("img/{}", scene.page);
    let dir = report_dir.join(&rel_dir);
    if let Err(e) = std::fs::create_dir_all(&dir) {
        out.notes
            .push(format!("{}: cannot create: {e}", dir.display()));
        return out;
    }
    let mut loaded: Vec<Loaded> = Vec::new();
    for backend in scene.backends() {
        let Some(rec) = scene.render(&backend) else {
            continue;
        };
        if rec.status != RenderStatus::Ok || rec.exr.is_empty() {
            continue;
        }
        let Some(path) = run_relative(run, &rec.exr) else {
            out.notes.push(format!(
                "{backend}: buffer path {:?} leaves the run folder (absolute, `..` or through a symlink); not shown",
                rec.exr
            ));
            continue;
        };
        match read_buffers(&path) {
            Err(e) => out.notes.push(format!("{backend}: {e:#}")),
            Ok(buffers) => {
                let rgb = read_rgb(&path).unwrap_or_else(|e| {
                    out.notes.push(format!("{backend}: {e:#}"));
                    None
                });
                loaded.push(Loaded {
                    backend,
                    buffers,
                    rgb,
                });
            }
        }
    }
    let reference_buf = loaded
        .iter()
        .find(|l| l.backend == reference)
        .map(|l| &l.buffers);
    // One depth scale for the scene: the reference's range (so one wild backend
    // cannot flatten everyone else's colors), else the union of all.
    let range = reference_buf
        .and_then(|b| b.z.as_deref())
        .and_then(finite_range)
        .map(|(lo, hi)| (lo, hi, format!("the reference ({reference})")))
        .or_else(|| {
            loaded
                .iter()
                .filter_map(|l| l.buffers.z.as_deref().and_then(finite_range))
                .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)))
                .map(|(lo, hi)| (lo, hi, "all backends".to_string()))
        });
    // Pad the range a little, so last-bit differences are not "outside" it and
    // a flat scene (one depth) still gets a scale.
    let range = range.map(|(lo, hi, from)| {
        let pad = ((hi - lo) * 0.02)
            .max(hi.abs().max(lo.abs()) * 1e-3)
            .max(f32::MIN_POSITIVE);
        (lo - pad, hi + pad, from)
    });
    out.depth_range = range.clone();
    let add = |out: &mut SceneImages,
               backend: &str,
               kind: Kind,
               name: &str,
               caption: String,
               px: Option<&[[u8; 3]]>,
               size: (usize, usize)| {
        let file = format!("{rel_dir}/{}.{name}.png", page_stem(backend));
        if let Some(px) = px {
            if let Err(e) = save_png(&report_dir.join(&file), size.0, size.1, px) {
                out.notes.push(format!("{backend}: {e:#}"));
                return;
            }
        }
        out.pictures.push(Picture {
            backend: backend.to_string(),
            kind,
            file,
            caption,
        });
    };
    for l in &loaded {
        let b = &l.buffers;
        let size = (b.width, b.height);
        if let Some(rgb) = &l.rgb {
            let px: Vec<[u8; 3]> = rgb
                .iter()
                .map(|c| [srgb(c[0]), srgb(c[1]), srgb(c[2])])
                .collect();
            add(
                &mut out,
                &l.backend,
                Kind::Radiance,
                "radiance",
                format!("{} radiance", l.backend),
                Some(&px),
                size,
            );
        }
        if let (Some(z), Some((lo, hi, _))) = (&b.z, &range) {
            let (px, clamped) = depth_colors(z, *lo, *hi);
            if clamped > 0 {
                out.clamped.push((l.backend.clone(), clamped));
            }
            add(
                &mut out,
                &l.backend,
                Kind::Depth,
                "depth",
                format!("{} depth", l.backend),
                Some(&px),
                size,
            );
        }
        if let Some(p) = &b.prim {
            let px: Vec<[u8; 3]> = p.iter().map(|&id| id_color(id)).collect();
            add(
                &mut out,
                &l.backend,
                Kind::Ids,
                "ids",
                format!("{} ids", l.backend),
                Some(&px),
                size,
            );
        }
        if l.backend == reference {
            continue;
        }
        let Some(r) = reference_buf else { continue };
        if (r.width, r.height) != size {
            out.notes.push(format!(
                "{}: {}x{} px, the reference is {}x{}: not diffed here",
                l.backend, b.width, b.height, r.width, r.height
            ));
            continue;
        }
        // Diff images the comparison wrote, copied; fallbacks for id and Z.
        let mut have = (false, false);
        for e in scene.results.iter().filter(|e| e.backend == l.backend) {
            let Some(imgs) = e.details.get("images").and_then(|v| v.as_object()) else {
                continue;
            };
            for (key, v) in imgs {
                let Some(src) = v.as_str().and_then(|s| run_relative(run, s)) else {
                    continue;
                };
                let kind = match (e.buffer.as_str(), key.as_str()) {
                    ("id", "heat") => Kind::IdDiff,
                    ("Z", "heat") => Kind::DepthDiff,
                    ("RGB", "heat") => Kind::RadianceDiff,
                    _ => Kind::OtherDiff,
                };
                let name = format!("{}.{}.diff", page_stem(&e.buffer), page_stem(key));
                let file = format!("{rel_dir}/{}.{name}.png", page_stem(&l.backend));
                match copy_regular(&src, &report_dir.join(&file)) {
                    Err(err) => out.notes.push(format!(
                        "{}: diff image {} not copied: {err}",
                        l.backend,
                        src.display()
                    )),
                    Ok(_) => {
                        have.0 |= kind == Kind::IdDiff;
                        have.1 |= kind == Kind::DepthDiff;
                        let caption = match kind {
                            Kind::IdDiff => format!("{} id mismatches", l.backend),
                            Kind::DepthDiff => format!("{} |ΔZ|", l.backend),
                            Kind::RadianceDiff => format!("{} RGB error", l.backend),
                            _ => format!("{} {} {}", l.backend, e.buffer, key),
                        };
                        add(&mut out, &l.backend, kind, &name, caption, None, size);
                    }
                }
            }
        }
        if let (false, Some(rp), Some(tp)) = (have.0, &r.prim, &b.prim) {
            let px = id_diff_colors(rp, tp);
            add(
                &mut out,
                &l.backend,
                Kind::IdDiff,
                "id.unclassified.diff",
                format!("{} id mismatches (unclassified)", l.backend),
                Some(&px),
                size,
            );
        }
        if let (false, Some(rz), Some(tz)) = (have.1, &r.z, &b.z) {
            let px = depth_diff_colors(rz, tz);
            add(
                &mut out,
                &l.backend,
                Kind::DepthDiff,
                "Z.own.diff",
                format!("{} |ΔZ|", l.backend),
                Some(&px),
                size,
            );
        }
        if let (Some(rz), Some(tz)) = (&r.z, &b.z) {
            let prims = match (&r.prim, &b.prim) {
                (Some(rp), Some(tp)) => Some((rp.as_slice(), tp.as_slice())),
                _ => None,
            };
            out.histograms.push((
                l.backend.clone(),
                Histogram::of_depth_same_prims(rz, tz, prims),
            ));
        }
        if let (Some(rp), Some(tp)) = (&r.prim, &b.prim) {
            let objects = scene.resolved.as_ref().map_or(0, |s| s.objects.len());
            out.objects.push((
                l.backend.clone(),
                object_mismatches(rp, r.object.as_deref(), tp, b.object.as_deref(), objects),
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn diff_images_are_copied_from_regular_files_only() {
        // A FIFO as a diff image blocked the report forever (std::fs::copy
        // waits for a writer); a device is refused the same way.
        let t = tempfile::tempdir().unwrap();
        let (src, dst) = (t.path().join("a.png"), t.path().join("b.png"));
        std::fs::write(&src, "png bytes").unwrap();
        copy_regular(&src, &dst).unwrap();
        assert_eq!(std::fs::read(&dst).unwrap(), b"png bytes");
        let fifo = t.path().join("fifo.png");
        let c = std::ffi::CString::new(fifo.as_os_str().as_encoded_bytes()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        let e = copy_regular(&fifo, &t.path().join("c.png")).unwrap_err();
        assert!(e.contains("FIFO"), "{e}");
        let e = copy_regular(Path::new("/dev/zero"), &t.path().join("d.png")).unwrap_err();
        assert!(e.contains("not a regular file"), "{e}");
    }

    #[test]
    fn depth_colors_share_a_range_and_count_clamps() {
        // preview.rs owns the encoding; the report relies on these properties.
        let (px, clamped) = depth_colors(&[1.0, 2.0, 3.0, f32::INFINITY], 1.0, 2.0);
        assert_eq!(clamped, 1);
        assert_eq!(px[1], px[2], "above the range clamps to the top color");
        assert_eq!(px[3], [0, 0, 0]);
        assert_ne!(px[0], px[1]);
    }

    #[test]
    fn srgb_encodes_and_clamps() {
        assert_eq!(srgb(0.0), 0);
        assert_eq!(srgb(1.0), 255);
        assert_eq!(srgb(7.0), 255);
        assert_eq!(srgb(f32::NAN), 0);
        assert_eq!(srgb(0.5), 188);
    }
}
