//! Images for people: IDs in false color, depth through a color map, radiance
//! through the sRGB transfer, written as PNG. The one home of these encodings:
//! `render`'s previews and the report's images both use them. They are never
//! compared; the EXR is the result.

use crate::exr_io::{check_output, write_atomically};
use crate::frame::{Frame, BACKGROUND_ID};
use anyhow::{Context, Result};
use std::path::{Path, PathBuf};

/// A stable, well-spread color for an ID (background is black).
pub fn id_color(id: u32) -> [u8; 3] {
    if id == BACKGROUND_ID {
        return [0, 0, 0];
    }
    let mut h = id.wrapping_add(1).wrapping_mul(0x9E37_79B9);
    h ^= h >> 15;
    h = h.wrapping_mul(0x85EB_CA6B);
    h ^= h >> 13;
    [
        64 + (h & 0xBF) as u8,
        64 + ((h >> 8) & 0xBF) as u8,
        64 + ((h >> 16) & 0xBF) as u8,
    ]
}

/// The nearest and farthest finite depth, if any pixel has one.
pub fn finite_range(z: &[f32]) -> Option<(f32, f32)> {
    let mut it = z.iter().copied().filter(|v| v.is_finite());
    let first = it.next()?;
    Some(it.fold((first, first), |(lo, hi), v| (lo.min(v), hi.max(v))))
}

/// Depth through viridis on a fixed range (the report shares one range across
/// a scene's renders); returns the colors and how many pixels were clamped.
/// Background (non-finite) is black.
pub fn depth_colors(z: &[f32], lo: f32, hi: f32) -> (Vec<[u8; 3]>, u64) {
    let span = if hi > lo { hi - lo } else { 1.0 };
    let mut clamped = 0;
    let px = z
        .iter()
        .map(|&v| {
            if !v.is_finite() {
                return [0, 0, 0];
            }
            if v < lo || v > hi {
                clamped += 1;
            }
            let t = f64::from(((v - lo) / span).clamp(0.0, 1.0));
            let c = colorous::VIRIDIS.eval_continuous(t);
            [c.r, c.g, c.b]
        })
        .collect();
    (px, clamped)
}

/// Depth through viridis between the frame's own nearest and farthest depth.
pub fn depth_rgb(z: &[f32]) -> Vec<[u8; 3]> {
    let (lo, hi) = finite_range(z).unwrap_or((0.0, 1.0));
    depth_colors(z, lo, hi).0
}

/// Writes an 8-bit RGB PNG atomically.
pub fn save_png(path: &Path, w: u32, h: u32, px: &[[u8; 3]]) -> Result<()> {
    let buf: Vec<u8> = px.iter().flatten().copied().collect();
    let img = image::RgbImage::from_raw(w, h, buf).context("image buffer size")?;
    write_atomically(path, |tmp| {
        img.save_with_format(tmp, image::ImageFormat::Png)
            .with_context(|| format!("{}: cannot write PNG", path.display()))
    })
}

fn save(path: &Path, w: u32, h: u32, px: Vec<[u8; 3]>) -> Result<()> {
    save_png(path, w, h, &px)
}

/// Linear radiance to 8-bit sRGB (display transfer, clipped; NaN and infinities
/// black), for people only.
pub fn srgb8(v: f32) -> u8 {
    let v = if v.is_finite() {
        v.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let s = if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

/// What each preview beside an EXR shows: its file name is `<stem>.<suffix>`.
const PREVIEW_SUFFIXES: [&str; 3] = [".ids.png", ".depth.png", ".rgb.png"];

/// The previews `render` may write beside `exr_path`, in [`PREVIEW_SUFFIXES`]'
/// order: the one list behind writing them and clearing stale ones.
pub fn preview_paths(exr_path: &Path) -> [PathBuf; 3] {
    let stem = exr_path.with_extension("");
    PREVIEW_SUFFIXES.map(|suffix| {
        let mut name = stem.clone().into_os_string();
        name.push(suffix);
        PathBuf::from(name)
    })
}

/// Refuses preview paths beside `exr_path` that are devices, FIFOs or
/// sockets, before a render starts ([`check_output`]'s rule for every file
/// rendiff writes).
pub fn check_preview_paths(exr_path: &Path) -> Result<()> {
    preview_paths(exr_path)
        .iter()
        .try_for_each(|p| check_output(p))
}

/// Removes the previews an earlier render left beside `exr_path`, before a
/// new result goes there: a render with `--no-preview`, or without radiance,
/// left the last render's pictures beside its new EXR, showing another
/// scene. Only files and symlinks are removed; a folder there is an error
/// naming it.
pub fn remove_previews(exr_path: &Path) -> Result<()> {
    for p in preview_paths(exr_path) {
        let Ok(meta) = std::fs::symlink_metadata(&p) else {
            continue;
        };
        if !(meta.is_file() || meta.file_type().is_symlink()) {
            anyhow::bail!(
                "{}: a preview's path, and not a file: cannot clear it (choose another output)",
                p.display()
            );
        }
        std::fs::remove_file(&p)
            .with_context(|| format!("{}: cannot remove the stale preview", p.display()))?;
    }
    Ok(())
}

/// Writes `<stem>.rgb.png`: radiance through the sRGB transfer.
pub fn write_radiance_preview(exr_path: &Path, w: u32, h: u32, rgb: &[[f32; 3]]) -> Result<()> {
    let px = rgb.iter().map(|p| p.map(srgb8)).collect();
    save(&preview_paths(exr_path)[2], w, h, px)
}

/// Writes `<stem>.ids.png` and `<stem>.depth.png` beside `exr_path`.
pub fn write_previews(exr_path: &Path, frame: &Frame) -> Result<()> {
    let [ids_path, depth_path, _] = preview_paths(exr_path);
    let ids = frame.prim.iter().map(|&p| id_color(p)).collect();
    save(&ids_path, frame.width, frame.height, ids)?;
    save(&depth_path, frame.width, frame.height, depth_rgb(&frame.z))
}
