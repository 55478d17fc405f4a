//! Plots as inline SVG (text, so they need no image files, scale cleanly and
//! stay escapable): renderer times per scene, depth-error histograms and the
//! depth color bar. Every label goes through [`escape`].

use super::html::escape;
use super::stats::{Histogram, HI_EXP, LO_EXP, PER_DECADE};
use std::fmt::Write;

/// A stable color per backend, by its index in the run's backend list.
pub fn backend_color(index: usize) -> String {
    let c = colorous::TABLEAU10[index % colorous::TABLEAU10.len()];
    format!("#{:02x}{:02x}{:02x}", c.r, c.g, c.b)
}

/// One bar: backend, its color, seconds (None: did not run).
pub type Bar = (String, String, Option<f64>);

/// Horizontal bars of render times, grouped by scene, on a log axis (times
/// span milliseconds to minutes, so a linear axis would hide the fast ones).
pub fn time_bars(groups: &[(String, Vec<Bar>)]) -> String {
    let times: Vec<f64> = groups
        .iter()
        .flat_map(|g| g.1.iter().filter_map(|b| b.2))
        .filter(|t| t.is_finite() && *t > 0.0)
        .collect();
    if times.is_empty() {
        return "<p class=\"muted\">no render times recorded</p>".into();
    }
    let lo = times
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min)
        .max(1e-6);
    let hi = times.iter().copied().fold(0.0, f64::max);
    let (e0, e1) = (
        lo.log10().floor() as i32,
        (hi.log10().ceil() as i32).max(lo.log10().floor() as i32 + 1),
    );
    let (label_w, plot_w, bar_h, gap) = (230.0, 480.0, 13.0, 8.0);
    let x = |t: f64| {
        label_w + (t.max(10f64.powi(e0)).log10() - f64::from(e0)) / f64::from(e1 - e0) * plot_w
    };
    let rows: usize = groups.iter().map(|g| g.1.len() + 1).sum();
    let height = 30.0 + rows as f64 * (bar_h + 2.0) + groups.len() as f64 * gap;
    let width = label_w + plot_w + 90.0;
    let mut s = format!(
        "<svg width=\"{width}\" height=\"{height}\" viewBox=\"0 0 {width} {height}\" role=\"img\" aria-label=\"render times\" font-size=\"11\" font-family=\"sans-serif\">"
    );
    for e in e0..=e1 {
        let xe = x(10f64.powi(e));
        let _ = write!(
            s,
            "<line x1=\"{xe:.1}\" y1=\"14\" x2=\"{xe:.1}\" y2=\"{:.1}\" stroke=\"#ddd\"/><text x=\"{xe:.1}\" y=\"11\" text-anchor=\"middle\">{}</text>",
            height - 4.0,
            escape(&seconds_label(e))
        );
    }
    let mut y = 22.0;
    for (scene, bars) in groups {
        let _ = write!(
            s,
            "<text x=\"4\" y=\"{:.1}\" font-weight=\"bold\">{}</text>",
            y + bar_h - 3.0,
            escape(scene)
        );
        y += bar_h + 2.0;
        for (backend, color, t) in bars {
            let _ = write!(
                s,
                "<text x=\"16\" y=\"{:.1}\">{}</text>",
                y + bar_h - 3.0,
                escape(backend)
            );
            match t {
                Some(t) if t.is_finite() && *t > 0.0 => {
                    let w = (x(*t) - label_w).max(1.0);
                    let _ = write!(
                        s,
                        "<rect x=\"{label_w}\" y=\"{y:.1}\" width=\"{w:.1}\" height=\"{bar_h}\" fill=\"{}\"><title>{} {}: {t:.4} s</title></rect><text x=\"{:.1}\" y=\"{:.1}\">{}</text>",
                        escape(color),
                        escape(scene),
                        escape(backend),
                        label_w + w + 4.0,
                        y + bar_h - 3.0,
                        escape(&format_seconds(*t))
                    );
                }
                _ => {
                    let _ = write!(
                        s,
                        "<text x=\"{:.1}\" y=\"{:.1}\" fill=\"#888\">not run</text>",
                        label_w + 4.0,
                        y + bar_h - 3.0
                    );
                }
            }
            y += bar_h + 2.0;
        }
        y += gap;
    }
    s.push_str("</svg>");
    s
}

fn seconds_label(e: i32) -> String {
    match e {
        -4 => "0.1 ms".into(),
        -3 => "1 ms".into(),
        -2 => "10 ms".into(),
        -1 => "100 ms".into(),
        0 => "1 s".into(),
        1 => "10 s".into(),
        2 => "100 s".into(),
        _ => format!("1e{e} s"),
    }
}

/// Seconds in a readable unit.
pub fn format_seconds(t: f64) -> String {
    if t < 1.0 {
        format!("{:.1} ms", t * 1e3)
    } else {
        format!("{t:.2} s")
    }
}

/// Depth-error histograms, one row per backend, on shared log bins: where the
/// errors sit (ULP-level rounding vs real offsets) and how many pixels.
/// Bar heights are log(1 + count), the exact count is in each bar's tooltip.
pub fn histograms(series: &[(String, String, Histogram)]) -> String {
    if series.is_empty() {
        return "<p class=\"muted\">no depth comparisons</p>".into();
    }
    let used = series
        .iter()
        .filter_map(|s| s.2.used_bins())
        .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)));
    // Show whole decades around the used bins.
    let pd = PER_DECADE as usize;
    // At least four decades, so the axis reads as a scale even for tiny spreads.
    let (first, last) = match used {
        Some((a, b)) => {
            let decades = super::stats::BINS / pd;
            let d1 = (b / pd).max(a / pd + 3).min(decades - 1);
            let d0 = (a / pd).min(d1.saturating_sub(3));
            (d0 * pd, (d1 + 1) * pd - 1)
        }
        None => (0, 0),
    };
    let nb = if used.is_some() { last - first + 1 } else { 0 };
    // Columns: "= 0", "< 1e-12", the used bins, ">= 1e4", "hit/miss", "other triangle".
    let cols = nb + 5;
    let (label_w, col_w, row_h) = (150.0, 24.0, 46.0);
    let width = label_w + cols as f64 * col_w + 20.0;
    let height = 20.0 + series.len() as f64 * row_h + 20.0;
    let max = series
        .iter()
        .flat_map(|s| {
            let h = &s.2;
            [h.zero, h.under, h.over, h.mask_mismatches, h.other_prim]
                .into_iter()
                .chain(h.bins.iter().copied())
        })
        .max()
        .unwrap_or(0)
        .max(1);
    let scale = |c: u64| ((1.0 + c as f64).ln() / (1.0 + max as f64).ln()) * (row_h - 10.0);
    let mut s = format!(
        "<svg width=\"{width}\" height=\"{height}\" viewBox=\"0 0 {width} {height}\" role=\"img\" aria-label=\"depth error histograms\" font-size=\"11\" font-family=\"sans-serif\">"
    );
    let col_x = |k: usize| label_w + k as f64 * col_w;
    for (r, (backend, color, h)) in series.iter().enumerate() {
        let base = 20.0 + (r + 1) as f64 * row_h - 4.0;
        let _ = write!(
            s,
            "<text x=\"4\" y=\"{:.1}\" font-weight=\"bold\">{}</text><line x1=\"{label_w}\" y1=\"{base:.1}\" x2=\"{:.1}\" y2=\"{base:.1}\" stroke=\"#999\"/>",
            base - 20.0,
            escape(backend),
            col_x(cols)
        );
        let mut cells: Vec<(u64, String, &str)> = vec![
            (h.zero, "|ΔZ| = 0 (identical)".into(), "#888"),
            (h.under, format!("0 < |ΔZ| < 1e{LO_EXP}"), color.as_str()),
        ];
        for k in 0..nb {
            let b = first + k;
            cells.push((
                h.bins[b],
                format!(
                    "{:.2e} ≤ |ΔZ| < {:.2e}",
                    Histogram::bin_lo(b),
                    Histogram::bin_lo(b + 1)
                ),
                color.as_str(),
            ));
        }
        cells.push((h.over, format!("|ΔZ| ≥ 1e{HI_EXP}"), color.as_str()));
        cells.push((h.mask_mismatches, "hit/miss mismatch".into(), "#00b5b5"));
        cells.push((
            h.other_prim,
            "on different triangles (judged against the test's own plane, not binned)".into(),
            "#b58900",
        ));
        for (k, (count, what, fill)) in cells.iter().enumerate() {
            let bh = scale(*count);
            let _ = write!(
                s,
                "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{bh:.1}\" fill=\"{}\"><title>{}: {} px {}</title></rect>",
                col_x(k) + 1.0,
                base - bh,
                col_w - 2.0,
                escape(fill),
                escape(backend),
                count,
                escape(what)
            );
        }
        let total = h.total();
        let _ = write!(
            s,
            "<text x=\"4\" y=\"{:.1}\" fill=\"#666\">{total} common hits</text>",
            base - 6.0
        );
    }
    let axis = 20.0 + series.len() as f64 * row_h + 12.0;
    let label = |s: &mut String, k: usize, text: &str| {
        let _ = write!(
            s,
            "<text x=\"{:.1}\" y=\"{axis:.1}\" text-anchor=\"middle\">{}</text>",
            col_x(k) + col_w / 2.0,
            escape(text)
        );
    };
    label(&mut s, 0, "=0");
    label(&mut s, 1, "<");
    for k in (0..nb).step_by(pd) {
        let e = LO_EXP + ((first + k) / pd) as i32;
        let _ = write!(
            s,
            "<text x=\"{:.1}\" y=\"{axis:.1}\" text-anchor=\"middle\">1e{e}</text>",
            col_x(k + 2)
        );
    }
    label(&mut s, nb + 2, ">");
    label(&mut s, nb + 3, "h/m");
    label(&mut s, nb + 4, "≠tri");
    let _ = write!(
        s,
        "</svg><p class=\"muted\">|Z_test − Z_ref| over pixels both hit on the same triangle, log bins ({PER_DECADE} per decade, labels at their lower edges); gray: exactly 0; bar height ∝ log(1 + pixels), hover a bar for its count; “<”, “>”: below 1e{LO_EXP} and above 1e{HI_EXP}; h/m: hit on one side only; ≠tri: both hit, on different triangles (two surfaces, not a depth error: the verdict judges the test's depth there against its own triangle's plane).</p>"
    );
    s
}

/// The depth color bar (viridis) for the scene's shared range.
pub fn depth_bar(lo: f32, hi: f32) -> String {
    let mut stops = String::new();
    for k in 0..=10 {
        let c = colorous::VIRIDIS.eval_continuous(f64::from(k) / 10.0);
        let _ = write!(
            stops,
            "<stop offset=\"{}%\" stop-color=\"#{:02x}{:02x}{:02x}\"/>",
            k * 10,
            c.r,
            c.g,
            c.b
        );
    }
    format!(
        "<svg width=\"360\" height=\"40\" viewBox=\"0 0 360 40\" role=\"img\" aria-label=\"depth scale\" font-size=\"11\" font-family=\"sans-serif\"><defs><linearGradient id=\"viridis\">{stops}</linearGradient></defs><rect x=\"10\" y=\"4\" width=\"340\" height=\"14\" fill=\"url(#viridis)\"/><text x=\"10\" y=\"32\">{}</text><text x=\"350\" y=\"32\" text-anchor=\"end\">{}</text><text x=\"180\" y=\"32\" text-anchor=\"middle\">planar depth Z (background: black)</text></svg>",
        escape(&format!("{lo:.6}")),
        escape(&format!("{hi:.6}"))
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_are_escaped() {
        let bars = vec![(
            "<b>x</b>".to_string(),
            vec![("<i>".to_string(), backend_color(0), Some(0.5))],
        )];
        let s = time_bars(&bars);
        assert!(!s.contains("<b>") && !s.contains("<i>"));
        let mut h = Histogram::default();
        h.add(1e-6);
        let s = histograms(&[("<script>".into(), backend_color(1), h)]);
        assert!(!s.contains("<script>"));
        assert!(s.contains("1e-6"));
    }
}
