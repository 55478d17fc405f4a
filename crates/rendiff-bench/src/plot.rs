//! SVG plots of the benchmark pages: time against error with the Pareto front,
//! log-log lines (crossover) and a colored matrix (stability). Separate from
//! the check report's plots (`report::svg`) because the shapes differ; the
//! label escaping and colors are the report's own, so every label from a
//! scene or a renderer goes through [`escape`].

use rendiff::report::html::escape;
use rendiff::report::svg::backend_color;
use std::fmt::Write;

/// One configuration on a time-vs-error plot.
#[derive(Debug, Clone)]
pub struct ScatterPoint {
    /// Short label drawn next to the point.
    pub label: String,
    /// Knob family: one color per family.
    pub group: String,
    /// Seconds (> 0).
    pub x: f64,
    /// Error (>= 0; 0 goes to its own lane under the log axis).
    pub y: f64,
    /// On the Pareto front (drawn ringed and joined by the front's staircase).
    pub pareto: bool,
}

/// One line of a line chart.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// (x, y) points, both > 0 (others are skipped: the axes are logarithmic).
    pub points: Vec<(f64, f64)>,
    /// Dashed stroke (e.g. operation counts next to times).
    pub dashed: bool,
}

/// One cell of a matrix chart: text, fill color, tooltip.
pub type Cell = (String, String, String);

const W: f64 = 780.0;
const H: f64 = 430.0;
const LEFT: f64 = 78.0;
const RIGHT: f64 = 210.0;
const TOP: f64 = 34.0;
const BOTTOM: f64 = 56.0;

/// The SVG as a file of its own: XML prolog, and `xmlns` added where the
/// inline copy did without (the report's plots); anything that is not an SVG
/// (a "nothing measured" paragraph) becomes a one-line SVG saying so.
pub fn standalone(svg: &str) -> String {
    let body = if !svg.starts_with("<svg") {
        format!(
            "{}<text x=\"8\" y=\"20\">nothing to plot</text></svg>",
            open(300.0, 30.0, "empty plot")
        )
    } else if svg
        .split('>')
        .next()
        .is_some_and(|tag| !tag.contains("xmlns="))
    {
        svg.replacen("<svg", "<svg xmlns=\"http://www.w3.org/2000/svg\"", 1)
    } else {
        svg.to_string()
    };
    format!("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n{body}\n")
}

fn open(width: f64, height: f64, label: &str) -> String {
    format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width}\" height=\"{height}\" viewBox=\"0 0 {width} {height}\" role=\"img\" aria-label=\"{}\" font-size=\"11\" font-family=\"sans-serif\"><rect width=\"{width}\" height=\"{height}\" fill=\"#fff\"/>",
        escape(label)
    )
}

/// A power of ten as a short label: plain between 0.001 and 10000, else 1eN.
pub fn decade_label(e: i32) -> String {
    match e {
        -3 => "0.001".into(),
        -2 => "0.01".into(),
        -1 => "0.1".into(),
        0..=4 => format!("{}", 10u64.pow(e as u32)),
        _ => format!("1e{e}"),
    }
}

/// Decades covering the positive finite values (at least one decade wide).
fn decades(values: impl Iterator<Item = f64>) -> (i32, i32) {
    let (mut lo, mut hi) = (f64::INFINITY, 0f64);
    for v in values.filter(|v| v.is_finite() && *v > 0.0) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0, 1);
    }
    // A little headroom, so points and their labels never sit on the frame.
    let e0 = (lo.log10() - 0.1).floor() as i32;
    let e1 = ((hi.log10() + 0.15).ceil() as i32).max(e0 + 1);
    (e0, e1)
}

struct LogAxis {
    e0: i32,
    e1: i32,
    a: f64,
    b: f64,
}

impl LogAxis {
    /// The x axis over the decades `(e0, e1)`, across the plot area.
    fn x((e0, e1): (i32, i32)) -> LogAxis {
        LogAxis {
            e0,
            e1,
            a: LEFT,
            b: W - RIGHT,
        }
    }

    /// The y axis over the decades `(e0, e1)`, from `bottom` up to the plot area's top.
    fn y((e0, e1): (i32, i32), bottom: f64) -> LogAxis {
        LogAxis {
            e0,
            e1,
            a: bottom,
            b: TOP,
        }
    }

    /// Maps a positive value into [a, b] (pixels; b may be below a for a y axis).
    fn at(&self, v: f64) -> f64 {
        let t = (v.log10() - f64::from(self.e0)) / f64::from(self.e1 - self.e0);
        self.a + t * (self.b - self.a)
    }
}

fn axes(
    s: &mut String,
    x: &LogAxis,
    y: &LogAxis,
    x_label: &str,
    y_label: &str,
    y_top: f64,
    y_bottom: f64,
) {
    for e in x.e0..=x.e1 {
        let px = x.at(10f64.powi(e));
        let _ = write!(
            s,
            "<line x1=\"{px:.1}\" y1=\"{y_top:.1}\" x2=\"{px:.1}\" y2=\"{y_bottom:.1}\" stroke=\"#e4e4e4\"/><text x=\"{px:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>",
            y_bottom + 14.0,
            escape(&decade_label(e))
        );
    }
    for e in y.e0..=y.e1 {
        let py = y.at(10f64.powi(e));
        let _ = write!(
            s,
            "<line x1=\"{LEFT}\" y1=\"{py:.1}\" x2=\"{:.1}\" y2=\"{py:.1}\" stroke=\"#e4e4e4\"/><text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{}</text>",
            W - RIGHT,
            LEFT - 4.0,
            py + 4.0,
            escape(&decade_label(e))
        );
    }
    let _ = write!(
        s,
        "<rect x=\"{LEFT}\" y=\"{y_top:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"none\" stroke=\"#888\"/><text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text><text transform=\"translate(14 {:.1}) rotate(-90)\" text-anchor=\"middle\">{}</text>",
        W - RIGHT - LEFT,
        y_bottom - y_top,
        (LEFT + W - RIGHT) / 2.0,
        H - 12.0,
        escape(x_label),
        (y_top + y_bottom) / 2.0,
        escape(y_label)
    );
}

fn title(s: &mut String, t: &str) {
    let _ = write!(
        s,
        "<text x=\"{LEFT}\" y=\"20\" font-size=\"13\" font-weight=\"bold\">{}</text>",
        escape(t)
    );
}

fn legend(s: &mut String, entries: &[(String, String, bool)]) {
    for (i, (name, color, dashed)) in entries.iter().enumerate() {
        let y = TOP + 10.0 + i as f64 * 16.0;
        let x = W - RIGHT + 12.0;
        let dash = if *dashed {
            " stroke-dasharray=\"5 3\""
        } else {
            ""
        };
        let _ = write!(
            s,
            "<line x1=\"{x:.1}\" y1=\"{y:.1}\" x2=\"{:.1}\" y2=\"{y:.1}\" stroke=\"{c}\" stroke-width=\"2\"{dash}/><circle cx=\"{:.1}\" cy=\"{y:.1}\" r=\"3.5\" fill=\"{c}\"/><text x=\"{:.1}\" y=\"{:.1}\">{}</text>",
            x + 18.0,
            x + 9.0,
            x + 24.0,
            y + 4.0,
            escape(name),
            c = escape(color)
        );
    }
}

/// Time (x, log) against error (y, log, with a lane for exact zeros) with the
/// Pareto front ringed and joined by its staircase.
pub fn scatter(plot_title: &str, x_label: &str, y_label: &str, pts: &[ScatterPoint]) -> String {
    let mut groups: Vec<String> = Vec::new();
    for p in pts {
        if !groups.contains(&p.group) {
            groups.push(p.group.clone());
        }
    }
    let color = |g: &str| backend_color(groups.iter().position(|x| x == g).unwrap_or(0));
    let zero_lane = H - BOTTOM - 10.0;
    let y_bottom = H - BOTTOM;
    let xa = LogAxis::x(decades(pts.iter().map(|p| p.x)));
    let ya = LogAxis::y(decades(pts.iter().map(|p| p.y)), zero_lane - 22.0);
    let py = |y: f64| if y > 0.0 { ya.at(y) } else { zero_lane };
    let mut s = open(W, H, plot_title);
    title(&mut s, plot_title);
    axes(&mut s, &xa, &ya, x_label, y_label, TOP, y_bottom);
    let _ = write!(
        s,
        "<line x1=\"{LEFT}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"#bbb\" stroke-dasharray=\"2 3\"/><text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">0</text>",
        zero_lane - 11.0,
        W - RIGHT,
        zero_lane - 11.0,
        LEFT - 4.0,
        zero_lane + 4.0
    );
    // The front's staircase: fastest first, each step down to the next better error.
    let mut front: Vec<&ScatterPoint> = pts
        .iter()
        .filter(|p| p.pareto && p.x > 0.0 && p.x.is_finite() && p.y.is_finite())
        .collect();
    front.sort_by(|a, b| a.x.total_cmp(&b.x).then(b.y.total_cmp(&a.y)));
    if let Some(first) = front.first() {
        let mut d = format!("M{:.1} {:.1}", xa.at(first.x), py(first.y));
        for p in &front[1..] {
            let _ = write!(d, " H{:.1} V{:.1}", xa.at(p.x), py(p.y));
        }
        let _ = write!(
            s,
            "<path d=\"{d}\" fill=\"none\" stroke=\"#111\" stroke-width=\"1.5\" stroke-dasharray=\"6 3\"><title>Pareto front</title></path>"
        );
    }
    let mut placed: Vec<[f64; 4]> = Vec::new();
    for p in pts
        .iter()
        .filter(|p| p.x > 0.0 && p.x.is_finite() && p.y.is_finite())
    {
        let (cx, cy) = (xa.at(p.x), py(p.y));
        let c = color(&p.group);
        if p.pareto {
            let _ = write!(
                s,
                "<circle cx=\"{cx:.1}\" cy=\"{cy:.1}\" r=\"7\" fill=\"none\" stroke=\"#111\" stroke-width=\"1.5\"/>"
            );
        }
        let _ = write!(
            s,
            "<circle cx=\"{cx:.1}\" cy=\"{cy:.1}\" r=\"4\" fill=\"{}\"><title>{}: {:.4} s, error {}{}</title></circle>",
            escape(&c),
            escape(&p.label),
            p.x,
            escape(&format!("{:.4e}", p.y)),
            if p.pareto { " (Pareto)" } else { "" },
        );
        let (lx, ly) = place_label(&mut placed, cx + 8.0, cy - 5.0, p.label.chars().count());
        if (ly - (cy - 5.0)).abs() > 0.5 {
            let _ = write!(
                s,
                "<line x1=\"{cx:.1}\" y1=\"{cy:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"#bbb\" stroke-width=\"0.7\"/>",
                lx - 1.0,
                ly - 3.0
            );
        }
        let _ = write!(
            s,
            "<text x=\"{lx:.1}\" y=\"{ly:.1}\" font-size=\"9\" fill=\"#333\">{}</text>",
            escape(&p.label)
        );
    }
    let mut entries: Vec<(String, String, bool)> = groups
        .iter()
        .map(|g| (g.clone(), color(g), false))
        .collect();
    entries.push(("Pareto front (ringed)".into(), "#111".into(), true));
    legend(&mut s, &entries);
    s.push_str("</svg>");
    s
}

/// Picks a label position near (x, y) that overlaps no label placed before
/// (greedy: same line first, then alternately above and below), and records it.
fn place_label(placed: &mut Vec<[f64; 4]>, x: f64, y: f64, chars: usize) -> (f64, f64) {
    let w = 5.2 * chars as f64;
    let h = 10.0;
    let free = |ly: f64, placed: &[[f64; 4]]| {
        ly - h >= TOP - 4.0
            && ly <= H - BOTTOM + 8.0
            && placed
                .iter()
                .all(|b| x + w <= b[0] || b[2] <= x || ly <= b[1] || b[3] <= ly - h)
    };
    let ly = (0..14)
        .map(|k| {
            let step = f64::from((k + 1) / 2) * (h + 1.0);
            if k % 2 == 1 {
                y - step
            } else {
                y + step
            }
        })
        .find(|&ly| free(ly, placed))
        .unwrap_or(y);
    placed.push([x, ly - h, x + w, ly]);
    (x, ly)
}

/// Log-log lines, one per series, with optional labelled vertical markers.
pub fn lines(
    plot_title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    marks: &[(f64, String)],
) -> String {
    let pos = |v: &(f64, f64)| v.0 > 0.0 && v.1 > 0.0 && v.0.is_finite() && v.1.is_finite();
    let y_bottom = H - BOTTOM;
    let xa = LogAxis::x(decades(
        series.iter().flat_map(|s| s.points.iter().map(|p| p.0)),
    ));
    let ya = LogAxis::y(
        decades(
            series
                .iter()
                .flat_map(|s| s.points.iter().filter(|p| pos(p)).map(|p| p.1)),
        ),
        y_bottom,
    );
    let mut s = open(W, H, plot_title);
    title(&mut s, plot_title);
    axes(&mut s, &xa, &ya, x_label, y_label, TOP, y_bottom);
    for (x, label) in marks.iter().filter(|m| m.0 > 0.0 && m.0.is_finite()) {
        let px = xa.at(*x);
        // Labels right of the middle go to the line's left, clear of the legend.
        let (tx, anchor) = if px > (LEFT + W - RIGHT) / 2.0 {
            (px - 3.0, "end")
        } else {
            (px + 3.0, "start")
        };
        let _ = write!(
            s,
            "<line x1=\"{px:.1}\" y1=\"{TOP}\" x2=\"{px:.1}\" y2=\"{y_bottom:.1}\" stroke=\"#c00\" stroke-dasharray=\"3 3\"/><text x=\"{tx:.1}\" y=\"{:.1}\" fill=\"#c00\" text-anchor=\"{anchor}\">{}</text>",
            TOP + 12.0,
            escape(label)
        );
    }
    let mut entries = Vec::new();
    for (i, se) in series.iter().enumerate() {
        let c = backend_color(i);
        let pts: Vec<&(f64, f64)> = se.points.iter().filter(|p| pos(p)).collect();
        let dash = if se.dashed {
            " stroke-dasharray=\"5 3\""
        } else {
            ""
        };
        if pts.len() > 1 {
            let d: Vec<String> = pts
                .iter()
                .enumerate()
                .map(|(k, p)| {
                    format!(
                        "{}{:.1} {:.1}",
                        if k == 0 { "M" } else { "L" },
                        xa.at(p.0),
                        ya.at(p.1)
                    )
                })
                .collect();
            let _ = write!(
                s,
                "<path d=\"{}\" fill=\"none\" stroke=\"{}\" stroke-width=\"2\"{dash}/>",
                d.join(" "),
                escape(&c)
            );
        }
        for p in pts {
            let _ = write!(
                s,
                "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"3\" fill=\"{}\"><title>{}: x {}, y {}</title></circle>",
                xa.at(p.0),
                ya.at(p.1),
                escape(&c),
                escape(&se.name),
                escape(&format!("{:.4e}", p.0)),
                escape(&format!("{:.4e}", p.1))
            );
        }
        entries.push((se.name.clone(), c, se.dashed));
    }
    legend(&mut s, &entries);
    s.push_str("</svg>");
    s
}

/// A matrix of colored cells (rows x columns) with row and column headings.
pub fn matrix(plot_title: &str, rows: &[String], cols: &[String], cells: &[Vec<Cell>]) -> String {
    let (label_w, cell_w, cell_h, head_h) = (150.0, 104.0, 24.0, 44.0);
    let width = label_w + cols.len().max(1) as f64 * cell_w + 10.0;
    let height = head_h + rows.len() as f64 * cell_h + 10.0;
    let mut s = open(width, height, plot_title);
    let _ = write!(
        s,
        "<text x=\"4\" y=\"16\" font-size=\"13\" font-weight=\"bold\">{}</text>",
        escape(plot_title)
    );
    for (j, c) in cols.iter().enumerate() {
        let _ = write!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\" font-weight=\"bold\">{}</text>",
            label_w + (j as f64 + 0.5) * cell_w,
            head_h - 8.0,
            escape(c)
        );
    }
    for (i, r) in rows.iter().enumerate() {
        let y = head_h + i as f64 * cell_h;
        let _ = write!(
            s,
            "<text x=\"4\" y=\"{:.1}\">{}</text>",
            y + cell_h - 8.0,
            escape(r)
        );
        for (j, (text, fill, tip)) in cells
            .get(i)
            .map(|v| v.as_slice())
            .unwrap_or(&[])
            .iter()
            .enumerate()
        {
            let x = label_w + j as f64 * cell_w;
            let _ = write!(
                s,
                "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"{}\" stroke=\"#fff\"><title>{}</title></rect><text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>",
                x,
                y,
                cell_w,
                cell_h,
                escape(fill),
                escape(tip),
                x + cell_w / 2.0,
                y + cell_h - 8.0,
                escape(text)
            );
        }
    }
    s.push_str("</svg>");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scatter_escapes_labels_and_marks_the_front() {
        let pts = vec![
            ScatterPoint {
                label: "<script>".into(),
                group: "a&b".into(),
                x: 0.1,
                y: 0.0,
                pareto: true,
            },
            ScatterPoint {
                label: "slow".into(),
                group: "a&b".into(),
                x: 2.0,
                y: 3.0,
                pareto: false,
            },
        ];
        let s = scatter("t", "time", "error", &pts);
        assert!(s.starts_with("<svg xmlns="));
        assert!(!s.contains("<script>") && s.contains("&lt;script&gt;"));
        assert!(s.contains("Pareto front"));
        assert!(s.ends_with("</svg>"));
    }

    #[test]
    fn lines_and_matrix_are_well_formed() {
        let s = lines(
            "t",
            "x",
            "y",
            &[Series {
                name: "n".into(),
                points: vec![(1.0, 2.0), (10.0, 0.0), (100.0, 20.0)],
                dashed: true,
            }],
            &[(5.0, "cross".into())],
        );
        assert_eq!(s.matches("<circle").count(), 2 + 1);
        let m = matrix(
            "m",
            &["r".into()],
            &["c".into()],
            &[vec![("x".into(), "#fff".into(), "<b>".into())]],
        );
        assert!(!m.contains("<b>"));
    }
}
