//! docs/DESIGN.md's buffer files: one OpenEXR per render with `Z` (f32), `id.prim`
//! and `id.object` (u32) and `N.x N.y N.z` (f32), written atomically, with the
//! render's metadata (operation counts, timings) as text attributes.

use crate::frame::Frame;
use anyhow::{bail, Context, Result};
use exr::prelude::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Prefix of rendiff's own EXR header attributes.
pub const ATTR_PREFIX: &str = "rendiff:";

/// Refuses an output path that is a device, FIFO or socket: only a regular
/// file (or nothing) is ever replaced, as [`write_atomically`]'s rename would
/// put the result in place of the node itself. Commands call it before long
/// work too, so that the refusal comes first.
pub fn check_output(path: &Path) -> Result<()> {
    match crate::scene::special_entry(path) {
        Some(kind) => bail!(
            "{}: {kind}; rendiff writes its results to regular files only: choose another output",
            path.display()
        ),
        None => Ok(()),
    }
}

/// How long a writer waits for another rendiff writing the same output set
/// (a render's EXR and previews, an export's three files) before giving up.
const FOLDER_LOCK_WAIT: std::time::Duration = std::time::Duration::from_secs(120);

/// An exclusive advisory lock (flock) on a folder, held while a set of files
/// is written into it and released when dropped. Each file of a set is atomic
/// on its own, but two renders (or exports) to one output at once could
/// interleave their files: one scene's EXR beside another's depth preview,
/// one scene's triangles beside another's object IDs. With the lock, one
/// writer's whole set lands after the other's.
pub struct FolderLock {
    /// The open folder; closing it releases the lock.
    _folder: std::fs::File,
}

/// Locks `dir` (which must exist) for writing a set of files, waiting up to
/// [`FOLDER_LOCK_WAIT`] for another rendiff writing there.
pub fn lock_folder(dir: &Path) -> Result<FolderLock> {
    let f = std::fs::File::open(dir).with_context(|| {
        format!(
            "{}: cannot open the output folder to lock it",
            dir.display()
        )
    })?;
    let start = std::time::Instant::now();
    loop {
        use std::os::fd::AsRawFd;
        // SAFETY: flock(2) on a descriptor this function owns.
        if unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0 {
            return Ok(FolderLock { _folder: f });
        }
        let e = std::io::Error::last_os_error();
        if e.raw_os_error() != Some(libc::EWOULDBLOCK) {
            return Err(e)
                .with_context(|| format!("{}: cannot lock the output folder", dir.display()));
        }
        if start.elapsed() > FOLDER_LOCK_WAIT {
            bail!(
                "{}: another rendiff has been writing here for {} s; try again when it is done",
                dir.display(),
                FOLDER_LOCK_WAIT.as_secs()
            );
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// Writes `bytes`-producing work to `path` through a temporary file in the same
/// folder and a rename, so a reader never sees a half-written result.
pub fn write_atomically(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    check_output(path)?;
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create output folder", dir.display()))?;
    let name = path
        .file_name()
        .with_context(|| format!("{}: not a file path", path.display()))?;
    let tmp: PathBuf = dir.join(format!(
        ".{}.tmp-{}",
        name.to_string_lossy(),
        std::process::id()
    ));
    // Removed by the signal handler if rendiff is interrupted mid-write.
    let _pending = crate::pending::track_path(&tmp);
    let result = write(&tmp).and_then(|_| {
        std::fs::rename(&tmp, path)
            .with_context(|| format!("{}: cannot move result into place", path.display()))
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// The standard attributes of a core render: renderer, scene, timing, counters.
pub fn frame_attrs(frame: &Frame, scene: &str) -> BTreeMap<String, String> {
    let mut attrs = BTreeMap::new();
    attrs.insert("renderer".to_string(), frame.renderer.clone());
    attrs.insert("scene".to_string(), scene.to_string());
    attrs.insert("seconds".to_string(), format!("{:.6}", frame.seconds));
    attrs.insert(
        "counters".to_string(),
        serde_json::to_string(&frame.counters).unwrap_or_default(),
    );
    attrs
}

/// Writes a frame's buffers to `path` (atomically), with `attrs` as `rendiff:*` text attributes.
pub fn write_frame(path: &Path, frame: &Frame, attrs: &BTreeMap<String, String>) -> Result<()> {
    write_frame_with(path, frame, None, attrs)
}

/// Like [`write_frame`], plus radiance channels `R G B` (and `var.R var.G var.B`
/// for Monte Carlo) and their `spp`/`integrator` attributes when given.
pub fn write_frame_with(
    path: &Path,
    frame: &Frame,
    radiance: Option<&crate::shade::Radiance>,
    attrs: &BTreeMap<String, String>,
) -> Result<()> {
    let size = (frame.width as usize, frame.height as usize);
    let n: Vec<Vec<f32>> = (0..3)
        .map(|k| frame.normal.iter().map(|v| v[k]).collect())
        .collect();
    let mut list = vec![
        AnyChannel::new("Z", FlatSamples::F32(frame.z.clone())),
        AnyChannel::new("id.prim", FlatSamples::U32(frame.prim.clone())),
        AnyChannel::new("id.object", FlatSamples::U32(frame.object.clone())),
        AnyChannel::new("N.x", FlatSamples::F32(n[0].clone())),
        AnyChannel::new("N.y", FlatSamples::F32(n[1].clone())),
        AnyChannel::new("N.z", FlatSamples::F32(n[2].clone())),
    ];
    let mut attrs = attrs.clone();
    if let Some(r) = radiance {
        let split = |v: &[[f32; 3]], k: usize| v.iter().map(|p| p[k]).collect::<Vec<f32>>();
        for (k, name) in ["R", "G", "B"].iter().enumerate() {
            list.push(AnyChannel::new(*name, FlatSamples::F32(split(&r.rgb, k))));
            if let Some(var) = &r.var {
                list.push(AnyChannel::new(
                    format!("var.{name}").as_str(),
                    FlatSamples::F32(split(var, k)),
                ));
            }
        }
        attrs.insert("spp".into(), r.spp.to_string());
        attrs.insert("integrator".into(), r.integrator.to_string());
        attrs.insert("shade_seconds".into(), format!("{:.6}", r.seconds));
    }
    let channels = SmallVec::from_vec(list);
    let mut layer_attrs = LayerAttributes::default();
    for (k, v) in &attrs {
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
    write_atomically(path, |tmp| {
        image
            .write()
            .to_file(tmp)
            .with_context(|| format!("{}: cannot write EXR", path.display()))
    })
}

/// Buffers read back from an EXR (any backend's), exactly as stored.
#[derive(Debug, Clone, Default)]
pub struct Buffers {
    /// Image width.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// `Z` if present.
    pub z: Option<Vec<f32>>,
    /// `id.prim` if present, exact.
    pub prim: Option<Vec<u32>>,
    /// `id.object` if present, exact.
    pub object: Option<Vec<u32>>,
    /// `rendiff:*` text attributes, prefix removed.
    pub attrs: BTreeMap<String, String>,
}

/// Largest EXR file rendiff reads: 16 GiB. A frame at the largest image
/// (64 Mpixel) with every buffer, radiance and variance is about 3.5 GiB
/// uncompressed; this leaves room for any file rendiff or a renderer writes
/// and refuses what could only be a mistake.
pub const MAX_EXR_BYTES: u64 = 16 << 30;

/// An EXR a user or a renderer wrote, opened for the `exr` reader: a regular
/// file only, at most [`MAX_EXR_BYTES`] ([`crate::scene::open_regular_file`]:
/// a FIFO is refused, never waited on), buffered.
pub fn open_exr(path: &Path) -> Result<std::io::BufReader<std::fs::File>> {
    match crate::scene::open_regular_file(path, MAX_EXR_BYTES) {
        Ok((file, _)) => Ok(std::io::BufReader::new(file)),
        Err(e) if !path.exists() => bail!("{}: file not found ({e})", path.display()),
        Err(e) => bail!("{}: {e}", path.display()),
    }
}

/// The channels of an EXR's first layer, as stored.
pub type ExrLayer = Layer<AnyChannels<FlatSamples>>;

/// The ID channels (docs/DESIGN.md): compared exactly, so stored as uint.
pub const ID_CHANNELS: [&str; 2] = ["id.prim", "id.object"];

/// Reads every channel and attribute of an EXR's first layer: the one read
/// chain of every reader of rendiff's EXRs.
pub fn read_layer(path: &Path) -> Result<ExrLayer> {
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(open_exr(path)?)
        .with_context(|| format!("{}: not a readable OpenEXR file", path.display()))?;
    Ok(image.layer_data)
}

/// Refuses a layer (read from `path`) whose ID channel ([`ID_CHANNELS`]) is
/// not stored as uint: the readers that compare IDs compare them exactly.
pub fn require_uint_ids(path: &Path, layer: &ExrLayer) -> Result<()> {
    for ch in &layer.channel_data.list {
        let name = ch.name.to_string();
        if ID_CHANNELS.contains(&name.as_str()) && !matches!(ch.sample_data, FlatSamples::U32(_)) {
            bail!(
                "{}: channel {name} must be stored as uint to be compared exactly",
                path.display()
            );
        }
    }
    Ok(())
}

/// Reads the docs/DESIGN.md channels of an EXR; IDs must be stored as uint.
pub fn read_buffers(path: &Path) -> Result<Buffers> {
    let layer = &read_layer(path)?;
    require_uint_ids(path, layer)?;
    let mut out = Buffers {
        width: layer.size.width(),
        height: layer.size.height(),
        ..Buffers::default()
    };
    for (k, v) in &layer.attributes.other {
        let key = k.to_string();
        if let (Some(stripped), AttributeValue::Text(t)) = (key.strip_prefix(ATTR_PREFIX), v) {
            out.attrs.insert(stripped.to_string(), t.to_string());
        }
    }
    for ch in &layer.channel_data.list {
        let name = ch.name.to_string();
        match (name.as_str(), &ch.sample_data) {
            ("Z", FlatSamples::F32(v)) => out.z = Some(v.clone()),
            ("Z", FlatSamples::F16(v)) => out.z = Some(v.iter().map(|x| x.to_f32()).collect()),
            ("id.prim", FlatSamples::U32(v)) => out.prim = Some(v.clone()),
            ("id.object", FlatSamples::U32(v)) => out.object = Some(v.clone()),
            _ => {}
        }
    }
    Ok(out)
}

/// An RGB image with optional per-pixel variance of the mean.
#[derive(Debug, Clone)]
pub struct RgbImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Linear radiance per pixel.
    pub rgb: Vec<[f32; 3]>,
    /// Variance of each pixel's mean (`var.R/G/B`), when stored.
    pub var: Option<Vec<[f32; 3]>>,
}

/// Reads `R,G,B` and, if present, `var.R,var.G,var.B` from an EXR; `None` when
/// the file has no radiance (visibility-only scenes). The one reader of these
/// channels, shared by the report and the benchmarks.
pub fn read_radiance(path: &Path) -> Result<Option<RgbImage>> {
    let layer = &read_layer(path)?;
    let n = layer.size.width() * layer.size.height();
    let mut rgb = vec![[0f32; 3]; n];
    let mut var = vec![[0f32; 3]; n];
    let (mut seen_rgb, mut seen_var) = (0, 0);
    for ch in &layer.channel_data.list {
        let name = ch.name.to_string();
        let (target, k) = match name.as_str() {
            "R" => (&mut rgb, 0),
            "G" => (&mut rgb, 1),
            "B" => (&mut rgb, 2),
            "var.R" => (&mut var, 0),
            "var.G" => (&mut var, 1),
            "var.B" => (&mut var, 2),
            _ => continue,
        };
        if name.starts_with("var.") {
            seen_var += 1;
        } else {
            seen_rgb += 1;
        }
        let vals: Vec<f32> = match &ch.sample_data {
            FlatSamples::F32(v) => v.clone(),
            FlatSamples::F16(v) => v.iter().map(|x| x.to_f32()).collect(),
            FlatSamples::U32(v) => v.iter().map(|&x| x as f32).collect(),
        };
        for (o, v) in target.iter_mut().zip(vals) {
            o[k] = v;
        }
    }
    if seen_rgb != 3 {
        return Ok(None);
    }
    Ok(Some(RgbImage {
        width: layer.size.width(),
        height: layer.size.height(),
        rgb,
        var: (seen_var == 3).then_some(var),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::visibility::Counters;

    #[test]
    fn frame_round_trips_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.exr");
        let frame = Frame {
            width: 3,
            height: 2,
            z: vec![1.0, f32::INFINITY, 2.5, 1e-30, 3.0e30, 7.0],
            prim: vec![0, u32::MAX, (1 << 24) + 1, 5, u32::MAX - 1, 2],
            object: vec![0, u32::MAX, 1, 1, 2, 0],
            normal: vec![[0.0, 0.0, 1.0]; 6],
            coverage: None,
            counters: Counters::default(),
            renderer: "raster".into(),
            seconds: 0.0,
        };
        let mut attrs = BTreeMap::new();
        attrs.insert("renderer".to_string(), "raster".to_string());
        write_frame(&path, &frame, &attrs).unwrap();
        let b = read_buffers(&path).unwrap();
        assert_eq!((b.width, b.height), (3, 2));
        assert_eq!(b.prim.unwrap(), frame.prim);
        assert_eq!(b.object.unwrap(), frame.object);
        let z = b.z.unwrap();
        assert!(z
            .iter()
            .zip(&frame.z)
            .all(|(a, b)| a.to_bits() == b.to_bits()));
        assert_eq!(b.attrs["renderer"], "raster");
        let leftovers: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(leftovers.len(), 1, "no temporary file left behind");
    }

    #[test]
    fn radiance_round_trips_and_is_absent_without_shading() {
        let dir = tempfile::tempdir().unwrap();
        let frame = Frame {
            width: 2,
            height: 1,
            z: vec![1.0, 2.0],
            prim: vec![0, 1],
            object: vec![0, 0],
            normal: vec![[0.0, 0.0, 1.0]; 2],
            coverage: None,
            counters: Counters::default(),
            renderer: "raster".into(),
            seconds: 0.0,
        };
        let plain = dir.path().join("plain.exr");
        write_frame(&plain, &frame, &BTreeMap::new()).unwrap();
        assert!(read_radiance(&plain).unwrap().is_none());
        let r = crate::shade::Radiance {
            rgb: vec![[0.25, 1e-8, 3.5], [7.0, 0.0, 1.0]],
            var: Some(vec![[1e-3, 2e-3, 3e-3], [0.0, 0.5, 0.25]]),
            spp: 4,
            integrator: "path",
            seconds: 0.0,
        };
        let shaded = dir.path().join("shaded.exr");
        write_frame_with(&shaded, &frame, Some(&r), &BTreeMap::new()).unwrap();
        let img = read_radiance(&shaded).unwrap().unwrap();
        assert_eq!((img.width, img.height), (2, 1));
        assert_eq!(img.rgb, r.rgb);
        assert_eq!(img.var, r.var);
        assert_eq!(read_buffers(&shaded).unwrap().attrs["spp"], "4");
    }

    #[test]
    fn failed_write_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.exr");
        let r = write_atomically(&path, |tmp| {
            std::fs::write(tmp, b"half")?;
            bail!("simulated failure")
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn missing_file_is_named() {
        let e = read_buffers(Path::new("/nonexistent/a.exr")).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/a.exr"));
    }
}
