//! The benchmark pages: one static HTML file per benchmark (tables, inline SVG
//! plots, the environment it ran in) and an index of the folder. Built on the
//! check report's page shell and styles so both look alike (inlined on one
//! line, so a page needs no file beside it); every piece of text that can
//! come from a scene, a renderer or a command line is escaped here, and only
//! SVG made by [`super::plot`] (itself escaped) is inserted as markup.

use anyhow::Result;
use rendiff::report::html::{escape, page_without_script, url};
use serde_json::Value;
use std::fmt::Write;
use std::path::Path;

/// The benchmark pages the index knows, with one line on what each answers.
pub const PAGES: &[(&str, &str)] = &[
    (
        "knobs",
        "every speed/accuracy knob against one reference, with the Pareto front",
    ),
    (
        "peers",
        "the core against Embree, pyrender and Mitsuba, as throughput ratios",
    ),
    ("crossover", "raster against trace as triangles shrink"),
    (
        "scale",
        "the main job's wall time: a process per render, the default pool, shards",
    ),
    (
        "stability",
        "where each renderer breaks on numerical extremes",
    ),
    ("core", "raster and trace on one scene per thread count"),
    (
        "fuzz",
        "generated scenes a minute through rendiff fuzz; start-up shares; reduction time per finding",
    ),
    (
        "variance",
        "is the path tracer's variance estimate calibrated; bias against the reference",
    ),
];

/// A page under construction: markup made only from escaped text and our own SVG.
#[derive(Debug, Default)]
pub struct Page {
    title: String,
    body: String,
}

impl Page {
    /// A page titled `title` (plain text), with a link back to the index.
    pub fn new(title: &str) -> Page {
        let mut p = Page {
            title: title.to_string(),
            body: String::new(),
        };
        let _ = write!(
            p.body,
            "<p><a href=\"index.html\">benchmarks</a></p><h1>{}</h1>",
            escape(title)
        );
        p
    }

    /// A section heading.
    pub fn heading(&mut self, text: &str) -> &mut Self {
        let _ = write!(self.body, "<h2>{}</h2>", escape(text));
        self
    }

    /// A paragraph of plain text.
    pub fn para(&mut self, text: &str) -> &mut Self {
        let _ = write!(self.body, "<p>{}</p>", escape(text));
        self
    }

    /// A highlighted note (a skipped part and why, a caveat on a number).
    pub fn note(&mut self, text: &str) -> &mut Self {
        let _ = write!(self.body, "<div class=\"note\">{}</div>", escape(text));
        self
    }

    /// A note in red (the report's failure colour): a number the page cannot
    /// stand behind, such as a peer measured below its own best.
    pub fn alarm(&mut self, text: &str) -> &mut Self {
        let _ = write!(
            self.body,
            "<div class=\"note s-fail\">{}</div>",
            escape(text)
        );
        self
    }

    /// A command to reproduce the page.
    pub fn command(&mut self, cmd: &str) -> &mut Self {
        self.body
            .push_str(&rendiff::report::html::command_block(cmd));
        self
    }

    /// An SVG made by [`super::plot`] (already escaped inside), plus a link to its standalone file.
    pub fn svg(&mut self, svg: &str, file: Option<&str>) -> &mut Self {
        let _ = write!(self.body, "<figure>{svg}");
        if let Some(f) = file {
            let _ = write!(
                self.body,
                "<figcaption><a href=\"{}\">{}</a></figcaption>",
                url(f),
                escape(f)
            );
        }
        self.body.push_str("</figure>");
        self
    }

    /// A table of plain-text cells; cells that parse as numbers are right-aligned.
    pub fn table(&mut self, headers: &[&str], rows: &[Vec<String>]) -> &mut Self {
        self.body.push_str("<table><tr>");
        for h in headers {
            let _ = write!(self.body, "<th>{}</th>", escape(h));
        }
        self.body.push_str("</tr>");
        for r in rows {
            self.body.push_str("<tr>");
            for c in r {
                let numeric = c.trim().parse::<f64>().is_ok()
                    || c.trim_end_matches(['x', '×', '%', 's'])
                        .trim()
                        .parse::<f64>()
                        .is_ok();
                let _ = write!(
                    self.body,
                    "<td{}>{}</td>",
                    if numeric { " class=\"num\"" } else { "" },
                    escape(c)
                );
            }
            self.body.push_str("</tr>");
        }
        self.body.push_str("</table>");
        self
    }

    /// The environment record (CPU, load before/after, build) as a table; an
    /// entry with a `summary` (the CPU time's shares) shows that sentence.
    pub fn environment(&mut self, env: &Value) -> &mut Self {
        self.heading("Environment");
        let shown = |v: &Value| match v.get("summary") {
            Some(Value::String(s)) => s.clone(),
            _ => compact(v),
        };
        let rows: Vec<Vec<String>> = env
            .as_object()
            .map(|m| m.iter().map(|(k, v)| vec![k.clone(), shown(v)]).collect())
            .unwrap_or_default();
        self.table(&["what", "value"], &rows)
    }

    /// The finished HTML document, styled like the report.
    pub fn finish(&self) -> String {
        page_without_script(&self.title, &self.body)
    }
}

/// A JSON value as one short line (strings without quotes).
pub fn compact(v: &Value) -> String {
    match v {
        Value::String(s) => s.clone(),
        Value::Null => "-".into(),
        other => other.to_string(),
    }
}

/// A number with `digits` significant digits, or "-" when absent or not finite.
pub fn num(v: Option<f64>, digits: usize) -> String {
    match v {
        Some(x) if x.is_finite() && x.fract() == 0.0 && x.abs() < 1e6 => format!("{x:.0}"),
        Some(x) if x.is_finite() => {
            if x != 0.0 && (x.abs() < 1e-3 || x.abs() >= 1e6) {
                format!("{x:.prec$e}", prec = digits.saturating_sub(1))
            } else {
                let mag = if x == 0.0 {
                    0
                } else {
                    x.abs().log10().floor() as i32
                };
                let dec = (digits as i32 - 1 - mag).max(0) as usize;
                format!("{x:.dec$}")
            }
        }
        _ => "-".into(),
    }
}

/// Rewrites `index.html`: a link to each benchmark page present in `dir`.
pub fn write_index(dir: &Path) -> Result<()> {
    let html = index_html(dir, None);
    rendiff::exr_io::write_atomically(&dir.join("index.html"), |tmp| {
        std::fs::write(tmp, html)?;
        Ok(())
    })
}

/// The index page of `dir`: a link to each benchmark page present there,
/// and to `also`'s (a page about to be written with it).
pub fn index_html(dir: &Path, also: Option<&str>) -> String {
    let mut p = Page {
        title: "rendiff benchmarks".into(),
        body: "<h1>rendiff benchmarks</h1><p>Measurements, never assertions: each page says how it was run and the machine's load while it ran.</p><ul>".into(),
    };
    for (stem, what) in PAGES {
        if also == Some(*stem) || dir.join(format!("{stem}.html")).exists() {
            let _ = write!(
                p.body,
                "<li><a href=\"{}\">{}</a> — {} (<a href=\"{}\">JSON</a>)</li>",
                url(&format!("{stem}.html")),
                escape(stem),
                escape(what),
                url(&format!("{stem}.json"))
            );
        }
    }
    p.body.push_str("</ul>");
    p.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_text_is_escaped_everywhere() {
        let mut p = Page::new("<x-title>");
        p.heading("<x-h>")
            .para("a < b & c")
            .note("\"q\"")
            .table(&["<x-th>"], &[vec!["<x-td>".into(), "1.5".into()]]);
        let html = p.finish();
        for bad in ["<x-title>", "<x-h>", "<x-th>", "<x-td>", "a < b", "\"q\""] {
            assert!(!html.contains(bad), "{bad} reached the markup");
        }
        assert!(html.contains("class=\"num\">1.5"));
    }

    #[test]
    fn pages_carry_the_report_styles_and_no_script() {
        let html = Page::new("t").finish();
        assert!(html.contains("<style>body{font:14px"), "{html}");
        assert!(!html.contains("<link") && !html.contains("<script>"));
    }

    #[test]
    fn numbers_are_short() {
        assert_eq!(num(Some(0.123456), 3), "0.123");
        assert_eq!(num(Some(12.3456), 3), "12.3");
        assert_eq!(num(Some(1.5e-5), 3), "1.50e-5");
        assert_eq!(num(None, 3), "-");
        assert_eq!(num(Some(0.0), 3), "0");
        assert_eq!(num(Some(517.0), 3), "517");
    }
}
