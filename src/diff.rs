//! `rendiff diff A.exr B.exr`: the core-vs-core tool. Every buffer present in
//! either file is judged, exactly: `id.prim` and `id.object` as u32, and every
//! float buffer (`Z`, `N.x N.y N.z`, `R G B`, `var.R var.G var.B`, anything
//! else) bit for bit, since raster and trace must agree to the last bit. A
//! buffer present in one file only is a difference that names it; two files
//! that share no buffer at all cannot be compared (an error, not "differ").
//!
//! The channels are read by [`crate::exr_io::read_layer`], the read chain of
//! [`crate::exr_io::read_buffers`] too, and the same rule holds here
//! ([`crate::exr_io::require_uint_ids`]): IDs must be stored as uint.

use anyhow::{bail, Result};
use exr::prelude::*;
use std::collections::BTreeMap;
use std::path::Path;

/// The buffers of docs/DESIGN.md in the order `diff` reports them; other channels follow, sorted.
pub const KNOWN_BUFFERS: &[&str] = &[
    "id.prim",
    "id.object",
    "Z",
    "N.x",
    "N.y",
    "N.z",
    "R",
    "G",
    "B",
    "var.R",
    "var.G",
    "var.B",
];

/// One channel's samples, exactly as stored (half floats widened to f32, which is exact).
#[derive(Debug, Clone, PartialEq)]
pub enum Samples {
    /// Unsigned integers (IDs).
    U32(Vec<u32>),
    /// Floats.
    F32(Vec<f32>),
}

impl Samples {
    fn kind(&self) -> &'static str {
        match self {
            Samples::U32(_) => "uint",
            Samples::F32(_) => "float",
        }
    }
}

/// Every channel of an EXR's first layer.
#[derive(Debug, Clone, Default)]
pub struct Channels {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Samples by channel name.
    pub channels: BTreeMap<String, Samples>,
}

/// Reads every channel of an EXR; ID channels must be stored as uint.
pub fn read_channels(path: &Path) -> Result<Channels> {
    let layer = &crate::exr_io::read_layer(path)?;
    crate::exr_io::require_uint_ids(path, layer)?;
    let mut out = Channels {
        width: layer.size.width(),
        height: layer.size.height(),
        ..Channels::default()
    };
    for ch in &layer.channel_data.list {
        let name = ch.name.to_string();
        let samples = match &ch.sample_data {
            FlatSamples::U32(v) => Samples::U32(v.clone()),
            FlatSamples::F32(v) => Samples::F32(v.clone()),
            FlatSamples::F16(v) => Samples::F32(v.iter().map(|x| x.to_f32()).collect()),
        };
        out.channels.insert(name, samples);
    }
    Ok(out)
}

/// How one buffer compares.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    /// Every pixel is identical (bit for bit).
    Identical {
        /// Pixels compared.
        pixels: usize,
    },
    /// Some pixels differ.
    Differs {
        /// Pixels that differ.
        count: usize,
        /// Pixels compared.
        pixels: usize,
        /// The first differing pixel (x, y), in row order from the top.
        first: (usize, usize),
        /// Its value in A and in B.
        values: (String, String),
    },
    /// Stored as uint in one file and as float in the other.
    TypeDiffers {
        /// Sample type in A and in B.
        kinds: (&'static str, &'static str),
    },
    /// Present in A only.
    OnlyInA,
    /// Present in B only.
    OnlyInB,
}

/// One buffer's line of the diff.
#[derive(Debug, Clone, PartialEq)]
pub struct BufferDiff {
    /// Channel name.
    pub name: String,
    /// The verdict.
    pub verdict: Verdict,
    /// Extra words (depth statistics for `Z`), "" when none.
    pub note: String,
}

impl BufferDiff {
    /// True unless identical.
    pub fn differs(&self) -> bool {
        !matches!(self.verdict, Verdict::Identical { .. })
    }

    /// The line `diff` prints; `a` and `b` are the file names.
    pub fn line(&self, a: &str, b: &str) -> String {
        let mut s = match &self.verdict {
            Verdict::Identical { pixels } => format!("{}: identical ({pixels} pixels)", self.name),
            Verdict::Differs {
                count,
                pixels,
                first,
                values,
            } => format!(
                "{}: {count} of {pixels} pixels differ, first at ({}, {}): {} vs {}",
                self.name, first.0, first.1, values.0, values.1
            ),
            Verdict::TypeDiffers { kinds } => format!(
                "{}: stored as {} in {a} but as {} in {b}",
                self.name, kinds.0, kinds.1
            ),
            Verdict::OnlyInA => format!("{}: only in {a} (missing in {b})", self.name),
            Verdict::OnlyInB => format!("{}: only in {b} (missing in {a})", self.name),
        };
        if !self.note.is_empty() {
            s.push_str("; ");
            s.push_str(&self.note);
        }
        s
    }
}

/// The whole comparison of two files.
#[derive(Debug, Clone, PartialEq)]
pub enum FileDiff {
    /// The images have different sizes: nothing else is compared.
    SizeDiffers {
        /// Width and height of A.
        a: (usize, usize),
        /// Width and height of B.
        b: (usize, usize),
    },
    /// One entry per buffer present in either file.
    Buffers(Vec<BufferDiff>),
}

impl FileDiff {
    /// True on any difference.
    pub fn differs(&self) -> bool {
        match self {
            FileDiff::SizeDiffers { .. } => true,
            FileDiff::Buffers(v) => v.iter().any(BufferDiff::differs),
        }
    }

    /// The lines `diff` prints.
    pub fn lines(&self, a: &str, b: &str) -> Vec<String> {
        match self {
            FileDiff::SizeDiffers { a: sa, b: sb } => vec![format!(
                "size differs: {}x{} in {a} vs {}x{} in {b}",
                sa.0, sa.1, sb.0, sb.1
            )],
            FileDiff::Buffers(v) => v.iter().map(|d| d.line(a, b)).collect(),
        }
    }
}

/// A float's value for a message: its shortest exact decimal, with the bits
/// when the decimals alone would not show the difference (NaN payloads).
fn show_f32(x: f32, other: f32) -> String {
    if format!("{x:?}") == format!("{other:?}") {
        format!("{x:?} (0x{:08x})", x.to_bits())
    } else {
        format!("{x:?}")
    }
}

/// Count of differing pixels and the index and values of the first.
fn first_difference<T: Copy>(
    a: &[T],
    b: &[T],
    same: impl Fn(T, T) -> bool,
) -> (usize, Option<(usize, T, T)>) {
    let mut count = 0;
    let mut first = None;
    for (i, (&x, &y)) in a.iter().zip(b).enumerate() {
        if !same(x, y) {
            count += 1;
            first.get_or_insert((i, x, y));
        }
    }
    (count, first)
}

/// The verdict on two sample lists of one buffer (`width` pixels a row)
/// whose samples are equal where `same` says, the first difference shown
/// by `show`; and how many pixels differ.
fn verdict_of<T: Copy>(
    p: &[T],
    q: &[T],
    same: impl Fn(T, T) -> bool,
    show: impl Fn(T, T) -> (String, String),
    width: usize,
) -> (Verdict, usize) {
    let pixels = p.len();
    let (count, first) = first_difference(p, q, same);
    let verdict = match first {
        None => Verdict::Identical { pixels },
        Some((i, a, b)) => Verdict::Differs {
            count,
            pixels,
            first: (i % width.max(1), i / width.max(1)),
            values: show(a, b),
        },
    };
    (verdict, count)
}

/// Compares one buffer present in both files (same size).
fn compare_buffer(name: &str, x: &Samples, y: &Samples, width: usize) -> BufferDiff {
    let (verdict, note) = match (x, y) {
        (Samples::U32(p), Samples::U32(q)) => {
            let show = |a: u32, b: u32| (a.to_string(), b.to_string());
            (
                verdict_of(p, q, |a, b| a == b, show, width).0,
                String::new(),
            )
        }
        (Samples::F32(p), Samples::F32(q)) => {
            let show = |a: f32, b: f32| (show_f32(a, b), show_f32(b, a));
            let same = |a: f32, b: f32| a.to_bits() == b.to_bits();
            let (verdict, count) = verdict_of(p, q, same, show, width);
            let note = if name == "Z" && count > 0 {
                let s = crate::compare_depth(p, q);
                format!(
                    "{} hit/miss mismatches, max abs {:.3e}, max rel {:.3e}, mean abs {:.3e} over {} common hits",
                    s.mask_mismatches, s.max_abs, s.max_rel, s.mean_abs, s.common_hits
                )
            } else {
                String::new()
            };
            (verdict, note)
        }
        _ => (
            Verdict::TypeDiffers {
                kinds: (x.kind(), y.kind()),
            },
            String::new(),
        ),
    };
    BufferDiff {
        name: name.to_string(),
        verdict,
        note,
    }
}

/// The order buffers are reported in: docs/DESIGN.md's first, then the rest by name.
fn order(name: &str) -> (usize, &str) {
    (
        KNOWN_BUFFERS
            .iter()
            .position(|k| *k == name)
            .unwrap_or(KNOWN_BUFFERS.len()),
        name,
    )
}

/// Compares two sets of channels. An error when they have no buffer in
/// common (nothing can be judged); `a` and `b` name the files in it.
pub fn compare(x: &Channels, y: &Channels, a: &str, b: &str) -> Result<FileDiff> {
    let common = x
        .channels
        .keys()
        .filter(|k| y.channels.contains_key(*k))
        .count();
    if common == 0 {
        let list = |c: &Channels| {
            if c.channels.is_empty() {
                "no buffers".to_string()
            } else {
                let mut v: Vec<&str> = c.channels.keys().map(String::as_str).collect();
                v.sort_by_key(|n| order(n));
                v.join(" ")
            }
        };
        bail!(
            "{a} and {b} have no buffer in common, nothing to compare ({a}: {}; {b}: {})",
            list(x),
            list(y)
        );
    }
    if (x.width, x.height) != (y.width, y.height) {
        return Ok(FileDiff::SizeDiffers {
            a: (x.width, x.height),
            b: (y.width, y.height),
        });
    }
    let mut names: Vec<&str> = x
        .channels
        .keys()
        .chain(y.channels.keys())
        .map(String::as_str)
        .collect();
    names.sort_by_key(|n| order(n));
    names.dedup();
    let buffers = names
        .into_iter()
        .map(|name| match (x.channels.get(name), y.channels.get(name)) {
            (Some(p), Some(q)) => compare_buffer(name, p, q, x.width),
            (Some(_), None) => BufferDiff {
                name: name.into(),
                verdict: Verdict::OnlyInA,
                note: String::new(),
            },
            _ => BufferDiff {
                name: name.into(),
                verdict: Verdict::OnlyInB,
                note: String::new(),
            },
        })
        .collect();
    Ok(FileDiff::Buffers(buffers))
}

/// Reads and compares two EXR files.
pub fn diff_files(a: &Path, b: &Path) -> Result<FileDiff> {
    let x = read_channels(a)?;
    let y = read_channels(b)?;
    compare(&x, &y, &a.display().to_string(), &b.display().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chans(list: &[(&str, Samples)]) -> Channels {
        Channels {
            width: 2,
            height: 2,
            channels: list
                .iter()
                .map(|(n, s)| (n.to_string(), s.clone()))
                .collect(),
        }
    }

    #[test]
    fn floats_are_compared_bit_for_bit() {
        let a = chans(&[("N.x", Samples::F32(vec![0.0, 1.0, 2.0, f32::NAN]))]);
        let b = chans(&[("N.x", Samples::F32(vec![-0.0, 1.0, 2.0, f32::NAN]))]);
        let FileDiff::Buffers(d) = compare(&a, &b, "a", "b").unwrap() else {
            panic!()
        };
        assert_eq!(
            d[0].verdict,
            Verdict::Differs {
                count: 1,
                pixels: 4,
                first: (0, 0),
                values: ("0.0".into(), "-0.0".into())
            }
        );
    }

    #[test]
    fn buffers_come_in_design_order_and_one_sided_ones_are_named() {
        let a = chans(&[
            ("Z", Samples::F32(vec![1.0; 4])),
            ("id.prim", Samples::U32(vec![1; 4])),
        ]);
        let b = chans(&[
            ("Z", Samples::F32(vec![1.0; 4])),
            ("N.y", Samples::F32(vec![1.0; 4])),
            ("id.prim", Samples::U32(vec![1, 1, 1, 7])),
        ]);
        let d = compare(&a, &b, "a", "b").unwrap();
        assert!(d.differs());
        assert_eq!(
            d.lines("a", "b"),
            vec![
                "id.prim: 1 of 4 pixels differ, first at (1, 1): 1 vs 7",
                "Z: identical (4 pixels)",
                "N.y: only in b (missing in a)",
            ]
        );
    }

    #[test]
    fn nothing_in_common_is_an_error() {
        let e = compare(&chans(&[]), &chans(&[]), "a", "b").unwrap_err();
        assert!(e.to_string().contains("no buffer in common"), "{e}");
    }
}
