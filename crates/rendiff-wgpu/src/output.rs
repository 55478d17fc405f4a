//! Writing the buffers as docs/resolved-scene.md's OpenEXR: channels `Z`
//! (f32), `id.prim` and `id.object` (u32), scanline, ZIP, plus `rendiff:*`
//! text attributes; written to a temporary name in the output folder and
//! renamed into place only when complete, so a reader never sees half a file.
//! Only a regular file (or nothing) is ever replaced ([`check_output`]).

use crate::gpu::Buffers;
use anyhow::{bail, Context, Result};
use exr::prelude::*;
use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;

/// Prefix of rendiff's EXR header attributes.
pub const ATTR_PREFIX: &str = "rendiff:";

/// Refuses an output path that is a folder, device, FIFO or socket: the
/// rename that puts the result in place would replace the node itself (a
/// FIFO or `/dev/null` swapped for a file). A link is not followed (the
/// rename replaces the link). `main` calls it before rendering, so that the
/// refusal comes first; [`write_exr`] again before it writes.
pub fn check_output(path: &Path) -> Result<()> {
    let Ok(meta) = std::fs::symlink_metadata(path) else {
        return Ok(());
    };
    if meta.file_type().is_symlink() {
        return Ok(());
    }
    match crate::scene::special_kind(&meta.file_type()) {
        Some(kind) => bail!(
            "{}: {kind}; the output must be a regular file: choose another output",
            path.display()
        ),
        None => Ok(()),
    }
}

/// Writes `buffers` to `path` with `attrs` as `rendiff:<key>` attributes.
pub fn write_exr(path: &Path, buffers: &Buffers, attrs: &BTreeMap<String, String>) -> Result<()> {
    check_output(path)?;
    let size = (buffers.width as usize, buffers.height as usize);
    let channels = SmallVec::from_vec(vec![
        AnyChannel::new("Z", FlatSamples::F32(buffers.z.clone())),
        AnyChannel::new("id.prim", FlatSamples::U32(buffers.prim.clone())),
        AnyChannel::new("id.object", FlatSamples::U32(buffers.object.clone())),
    ]);
    let mut layer_attrs = LayerAttributes::default();
    for (k, v) in attrs {
        layer_attrs.other.insert(
            Text::from(format!("{ATTR_PREFIX}{k}").as_str()),
            AttributeValue::Text(Text::from(v.as_str())),
        );
    }
    let layer = Layer::new(
        size,
        layer_attrs,
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(channels),
    );
    let image = Image::from_layer(layer);

    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create output folder", dir.display()))?;
    let name = path
        .file_name()
        .with_context(|| format!("{}: not a file path", path.display()))?;
    let tmp = dir.join(format!(
        ".{}.tmp-{}",
        name.to_string_lossy(),
        std::process::id()
    ));
    // Removed by the signal handler if the process is interrupted mid-write.
    let _pending = crate::pending::track_path(&tmp);
    let result = create_new(&tmp)
        .and_then(|file| {
            let mut w = std::io::BufWriter::new(file);
            image
                .write()
                .to_buffered(&mut w)
                .map_err(|e| anyhow::anyhow!("{}: cannot write EXR: {e}", tmp.display()))?;
            w.flush()
                .with_context(|| format!("{}: cannot write EXR", tmp.display()))
        })
        .and_then(|_| {
            std::fs::rename(&tmp, path)
                .with_context(|| format!("{}: cannot move result into place", path.display()))
        });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Creates the temporary file `tmp`, never opening what is already there (a
/// FIFO would block, a link would lead elsewhere): a leftover of a killed
/// process with this pid that is not a folder is removed first.
fn create_new(tmp: &Path) -> Result<std::fs::File> {
    let open = || {
        std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(tmp)
    };
    let file = match open() {
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
            if std::fs::symlink_metadata(tmp).is_ok_and(|m| !m.is_dir()) {
                let _ = std::fs::remove_file(tmp);
            }
            open()
        }
        other => other,
    };
    file.with_context(|| format!("{}: cannot create", tmp.display()))
}

/// The three channels of an EXR, exactly as stored (for tests and for users
/// checking their own output).
#[derive(Debug, Clone)]
pub struct ReadBack {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `Z`.
    pub z: Vec<f32>,
    /// `id.prim`.
    pub prim: Vec<u32>,
    /// `id.object`.
    pub object: Vec<u32>,
    /// `rendiff:*` attributes, prefix removed.
    pub attrs: BTreeMap<String, String>,
}

/// Reads `Z`, `id.prim` and `id.object` from an EXR (IDs must be uint).
pub fn read_exr(path: &Path) -> Result<ReadBack> {
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| anyhow::anyhow!("{}: not a readable OpenEXR file: {e}", path.display()))?;
    let layer = &image.layer_data;
    let (mut z, mut prim, mut object) = (None, None, None);
    for ch in &layer.channel_data.list {
        match (ch.name.to_string().as_str(), &ch.sample_data) {
            ("Z", FlatSamples::F32(v)) => z = Some(v.clone()),
            ("id.prim", FlatSamples::U32(v)) => prim = Some(v.clone()),
            ("id.object", FlatSamples::U32(v)) => object = Some(v.clone()),
            _ => {}
        }
    }
    let mut attrs = BTreeMap::new();
    for (k, v) in &layer.attributes.other {
        if let (Some(key), AttributeValue::Text(t)) = (k.to_string().strip_prefix(ATTR_PREFIX), v) {
            attrs.insert(key.to_string(), t.to_string());
        }
    }
    let missing = |c: &str| anyhow::anyhow!("{}: no {c} channel (f32 Z, u32 IDs)", path.display());
    Ok(ReadBack {
        width: layer.size.width(),
        height: layer.size.height(),
        z: z.ok_or_else(|| missing("Z"))?,
        prim: prim.ok_or_else(|| missing("id.prim"))?,
        object: object.ok_or_else(|| missing("id.object"))?,
        attrs,
    })
}
