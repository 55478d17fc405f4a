//! The report's index page: what failed first, then the whole scene × backend ×
//! buffer matrix, render times, depth-error distributions and versions, each
//! linking to the scene pages that explain it.

use super::data::{num, status_rank, RunData, SceneData, CLASSES};
use super::html::{badge, command_block, escape, page, url};
use super::images::{Kind, SceneImages};
use super::stats::Histogram;
use super::svg;
use crate::check::manifest::{RenderRecord, ResultEntry};
use crate::vocab::{RenderStatus, Status};
use serde_json::Value;
use std::collections::BTreeMap;
use std::fmt::Write;

/// A UTC timestamp for people, from seconds since the epoch (no date crate needed).
pub fn utc(secs: u64) -> String {
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    // Howard Hinnant's civil_from_days.
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// A count or "-" when not compared.
pub fn count(e: &ResultEntry, key: &str) -> String {
    num(e, key).map_or_else(|| "-".into(), |v| format!("{v}"))
}

/// What the four mismatch classes mean, for the tables' captions.
pub const CLASS_WORDS: &str = "edge: within the renderer's rounding distance of an edge the two triangles share (allowed); \
     tie: both triangles cover the pixel at the same depth (coplanar or duplicate surfaces; allowed); \
     crack: a watertightness leak near an edge (allowed only for a backend that declares it); \
     interior: anything else (a bug)";

/// One `<td class="num">` per mismatch class (edge, tie, crack, interior).
pub fn class_cells(e: &ResultEntry) -> String {
    CLASSES
        .iter()
        .map(|(k, _)| format!("<td class=\"num\">{}</td>", count(e, k)))
        .collect()
}

/// A verdict's class counts in one short span (`edge/tie/crack/interior`),
/// "" when it recorded none of them; a camera probe's RMS residual instead.
pub fn compact_counts(e: &ResultEntry) -> String {
    if CLASSES.iter().any(|(k, _)| num(e, k).is_some()) {
        let counts: Vec<String> = CLASSES.iter().map(|(k, _)| count(e, k)).collect();
        let title: Vec<String> = CLASSES
            .iter()
            .map(|(k, w)| format!("{} {w}", count(e, k)))
            .collect();
        format!(
            " <span class=\"counts\" title=\"{}\">{}</span>",
            escape(&title.join(", ")),
            escape(&counts.join("/"))
        )
    } else if let Some(rms) = num(e, "rms_px") {
        format!(" <span class=\"counts\">rms {} px</span>", sig(rms))
    } else {
        String::new()
    }
}

/// A number with about four significant digits.
pub fn sig(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else if !v.is_finite() {
        format!("{v}")
    } else if (1e-3..1e5).contains(&v.abs()) {
        let decimals = (3 - v.abs().log10().floor() as i32).max(0) as usize;
        format!("{v:.decimals$}")
    } else {
        format!("{v:.3e}")
    }
}

/// The numbers of a camera calibration (results.json's `calibration` and
/// `camera` entries), with the column titles the report gives them.
pub const CAMERA_FIELDS: &[(&str, &str)] = &[
    ("offset_x_px", "offset x (px)"),
    ("offset_y_px", "offset y (px)"),
    ("scale_x", "scale x"),
    ("scale_y", "scale y"),
    ("rotation", "rotation"),
    ("rms_px", "rms (px)"),
    ("bound_px", "bound (px)"),
];

/// One camera number as the calibration tables show it: scales with six
/// decimals (a field-of-view error is a small deviation from 1), the rest
/// with four significant digits; "-" when not recorded.
pub fn camera_value(field: &str, v: Option<&Value>) -> String {
    match v.and_then(Value::as_f64) {
        None => "-".into(),
        Some(x) if field.starts_with("scale") => format!("{x:.6}"),
        Some(x) => sig(x),
    }
}

/// The header cells of a camera table.
pub fn camera_header() -> String {
    CAMERA_FIELDS
        .iter()
        .map(|(_, title)| format!("<th>{title}</th>"))
        .collect()
}

/// The number cells of a camera table, from an object holding [`CAMERA_FIELDS`].
pub fn camera_cells(get: impl Fn(&str) -> Option<Value>) -> String {
    CAMERA_FIELDS
        .iter()
        .map(|(k, _)| {
            format!(
                "<td class=\"num\">{}</td>",
                camera_value(k, get(k).as_ref())
            )
        })
        .collect()
}

/// The "Camera calibration" section: one row per backend from results.json's
/// top-level `calibration`, and links to the probe scenes whose `camera`
/// entries it was measured on.
fn calibration_section(data: &RunData) -> String {
    let mut b = String::from(
        "<h2 id=\"calibration\">Camera calibration</h2><p class=\"muted\">Each backend's camera measured on the probe scenes against the reference conventions \
         (pixel-center offset, scale, rotation; the RMS residual of the fit and the bound it is held to). An offset beyond its bound is a convention error in the renderer (for a built-in backend, in rendiff's exporter for it).</p>",
    );
    match &data.calibration {
        None => b.push_str("<p class=\"muted\">Not recorded: this run's results.json has no <code>calibration</code> (an older comparison, or none ran).</p>"),
        Some(c) if c.is_empty() => b.push_str("<p class=\"muted\">No backend was calibrated.</p>"),
        Some(c) => {
            let _ = write!(
                b,
                "<table class=\"calibration\"><tr><th>backend</th>{}<th>status</th></tr>",
                camera_header()
            );
            for (be, v) in c {
                let status = v.get("status").and_then(Value::as_str).unwrap_or("");
                let reason = v.get("reason").and_then(Value::as_str).unwrap_or("");
                let _ = write!(
                    b,
                    "<tr><td>{}</td>{}<td>{} <span class=\"reason\">{}</span></td></tr>",
                    escape(be),
                    camera_cells(|k| v.get(k).cloned()),
                    if status.is_empty() {
                        "-".into()
                    } else {
                        badge(status, reason)
                    },
                    escape(reason)
                );
            }
            b.push_str("</table>");
        }
    }
    let probes: Vec<&SceneData> = data
        .scenes
        .iter()
        .filter(|s| {
            s.results.iter().any(|e| e.buffer == "camera")
                || s.runs.as_ref().is_some_and(|r| r.role == "calibration")
        })
        .collect();
    if !probes.is_empty() {
        let links: Vec<String> = probes.iter().map(|s| scene_link(s, "#camera")).collect();
        let _ = write!(b, "<p>Per-probe measurements: {}.</p>", links.join(", "));
    }
    b
}

/// The expectations file the comparison used, when it is not check's default.
pub fn expectations_arg(data: &RunData) -> Option<String> {
    data.expectations
        .clone()
        .filter(|e| e != "tests/expectations.toml")
}

fn tally(data: &RunData) -> BTreeMap<String, usize> {
    let mut t = BTreeMap::new();
    for s in &data.scenes {
        for e in &s.results {
            *t.entry(e.status.clone()).or_insert(0) += 1;
        }
    }
    t
}

fn scene_link(s: &SceneData, anchor: &str) -> String {
    format!(
        "<a href=\"{}\">{}</a>",
        url(&format!("{}.html{anchor}", s.page)),
        escape(&s.name)
    )
}

/// The first line of a reason (the line that names the fault).
fn first_line(text: &str) -> &str {
    text.lines().next().unwrap_or("")
}

/// "Needs attention": one row per root cause (causes.rs) with its count, the
/// reason that names it and a link to the evidence; under each, the verdicts
/// it explains (without class counts under a failed calibration: they were
/// measured with the wrong camera).
fn attention_section(data: &RunData) -> String {
    let mut b = String::from("<h2 id=\"attention\">Needs attention</h2>");
    let causes = super::causes::group(data);
    if causes.is_empty() {
        b.push_str(if data.results.is_some() {
            "<p>Nothing failed: no fail, error or unexpected_pass.</p>"
        } else {
            "<p class=\"muted\">No verdicts and no failed render.</p>"
        });
        return b;
    }
    let total: usize = causes.iter().map(|c| c.members.len()).sum();
    let _ = write!(
        b,
        "<p class=\"muted\">{total} failing verdicts and failed renders from {} {}, one row each: failed camera calibrations first \
         (fix those before reading anything else: the verdicts they spoil hang under them), then scenes that could not be loaded, \
         renderer errors, and each class of mismatch per renderer and buffer across scenes. Classes: {}.</p>\
         <table class=\"causes\"><tr><th>cause</th><th>renderer</th><th>count</th><th>evidence</th><th>why</th></tr>",
        causes.len(),
        if causes.len() == 1 { "cause" } else { "causes" },
        CLASS_WORDS
    );
    for (i, c) in causes.iter().enumerate() {
        let evidence = match &c.evidence {
            Some((s, anchor)) => scene_link(s, anchor),
            None => "<a href=\"#calibration\">calibration</a>".into(),
        };
        let _ = write!(
            b,
            "<tr class=\"cause\" id=\"cause-{i}\" data-kind=\"{}\"><td>{}</td><td>{}</td><td class=\"num\">{}</td><td>{evidence}</td><td class=\"reason\">{}</td></tr>",
            match c.kind {
                super::causes::Kind::Calibration => "calibration",
                super::causes::Kind::Scene => "scene",
                super::causes::Kind::RendererError => "error",
                super::causes::Kind::Mismatch => "mismatch",
            },
            escape(&c.title),
            escape(&c.backend),
            c.members.len(),
            escape(first_line(&c.why))
        );
        let what = if c.counts_valid {
            "verdicts"
        } else if c.kind == super::causes::Kind::Calibration {
            "verdicts on the probes, and verdicts not judged because of it (their counts were measured with the wrong camera and are not shown)"
        } else {
            "verdicts"
        };
        let _ = write!(
            b,
            "<tr class=\"members\"><td colspan=\"5\"><details><summary>{} {what}</summary><table><tr><th>status</th><th>scene</th><th>buffer</th>{}<th>why</th></tr>",
            c.members.len(),
            if c.counts_valid {
                "<th>edge</th><th>tie</th><th>crack</th><th>interior</th>"
            } else {
                ""
            }
        );
        for m in &c.members {
            let counts = match (c.counts_valid, m.entry) {
                (true, Some(e)) => class_cells(e),
                (true, None) => "<td class=\"num\">-</td>".repeat(CLASSES.len()),
                (false, _) => String::new(),
            };
            let _ = write!(
                b,
                "<tr class=\"member\"><td>{}</td><td>{}</td><td>{}</td>{counts}<td class=\"reason\">{}</td></tr>",
                badge(&m.status, &m.reason),
                scene_link(m.scene, &format!("#b-{}", super::data::page_stem(&c.backend))),
                escape(&m.buffer),
                escape(first_line(&m.reason))
            );
        }
        b.push_str("</table></details></td></tr>");
    }
    b.push_str("</table>");
    b
}

/// Renders index.html. `images` holds each scene's pictures (same order as `data.scenes`).
pub fn render(data: &RunData, images: &[SceneImages]) -> String {
    let mut b = String::new();
    let m = &data.manifest;
    let _ = write!(
        b,
        "<h1>rendiff report</h1><p>Run folder <code>{}</code>, created {}, rendiff {}; reference backend <b>{}</b>. \
         Each scene is rendered by every backend and compared with the reference, buffer by buffer.</p>",
        escape(&data.dir.display().to_string()),
        escape(&utc(m.created_unix)),
        escape(&m.rendiff_version),
        escape(&m.reference)
    );
    if let Some(p) = &data.results_problem {
        let _ = write!(b, "<p class=\"note\">No verdicts: {}</p>", escape(p));
    }
    let t = tally(data);
    b.push_str("<p>");
    for (status, n) in &t {
        let _ = write!(b, "{} {n} &nbsp; ", badge(status, ""));
    }
    b.push_str("</p>");

    // ---- failures grouped by cause, failed calibrations first (causes.rs)
    b.push_str(&attention_section(data));

    // ---- known failures, then skips, each with its reason
    let listed = |status: &str| -> Vec<(&SceneData, &ResultEntry)> {
        let mut v: Vec<(&SceneData, &ResultEntry)> = data
            .scenes
            .iter()
            .flat_map(|s| s.results.iter().map(move |e| (s, e)))
            .filter(|(_, e)| e.status == status)
            .collect();
        v.sort_by_key(|(s, e)| (s.name.clone(), e.backend.clone(), e.buffer.clone()));
        v
    };
    let expected = listed(Status::ExpectedFail.as_str());
    if !expected.is_empty() {
        b.push_str("<h2 id=\"expected\">Known failures (expected)</h2><p class=\"muted\">Failing as the expectations file says, with its reason; they do not turn the run red.</p><table><tr><th>scene</th><th>backend</th><th>buffer</th><th>edge</th><th>tie</th><th>crack</th><th>interior</th><th>expectation</th></tr>");
        for (s, e) in expected {
            let _ = write!(
                b,
                "<tr><td>{}</td><td>{}</td><td>{}</td>{}<td class=\"reason\">{}</td></tr>",
                scene_link(s, &format!("#b-{}", super::data::page_stem(&e.backend))),
                escape(&e.backend),
                escape(&e.buffer),
                class_cells(e),
                escape(&e.reason)
            );
        }
        b.push_str("</table>");
    }
    let skipped = listed(Status::Skipped.as_str());
    // Renders skipped with no verdict saying so (results.json missing).
    let render_skips: Vec<(&SceneData, &RenderRecord)> = data
        .scenes
        .iter()
        .flat_map(|s| {
            s.unjudged_renders(RenderStatus::Skipped)
                .map(move |r| (s, r))
        })
        .collect();
    b.push_str("<h2 id=\"skipped\">Skipped</h2>");
    if skipped.is_empty() && render_skips.is_empty() {
        b.push_str("<p class=\"muted\">Nothing was skipped.</p>");
    } else {
        b.push_str("<table><tr><th>scene</th><th>backend</th><th>buffer</th><th>reason</th></tr>");
        for (s, e) in skipped {
            let _ = write!(
                b,
                "<tr><td>{}</td><td>{}</td><td>{}</td><td class=\"reason\">{}</td></tr>",
                scene_link(s, &format!("#b-{}", super::data::page_stem(&e.backend))),
                escape(&e.backend),
                escape(&e.buffer),
                escape(&e.reason)
            );
        }
        for (s, r) in render_skips {
            let _ = write!(
                b,
                "<tr><td>{}</td><td>{}</td><td>render</td><td class=\"reason\">{}</td></tr>",
                scene_link(s, &format!("#b-{}", super::data::page_stem(&r.backend))),
                escape(&r.backend),
                escape(&r.reason)
            );
        }
        b.push_str("</table>");
    }

    // ---- camera calibration (shown even when every backend passes)
    b.push_str(&calibration_section(data));

    // ---- matrix
    let backends = data.backends();
    let buffers = data.buffers();
    let mut order: Vec<usize> = (0..data.scenes.len()).collect();
    order.sort_by_key(|&i| (data.scenes[i].worst_rank(), data.scenes[i].name.clone()));
    let _ = write!(
        b,
        "<h2 id=\"matrix\">Scene × backend × buffer</h2><p class=\"muted\">Scenes with failures first. Hover a badge for its reason; the reference column shows its render. Buffers: {}. \
         Numbers after a verdict are its mismatch counts per class, <span class=\"counts\">edge/tie/crack/interior</span> (- where not compared); camera entries show their RMS residual. The table scrolls sideways inside its box when it is wider than the page.</p><div class=\"scroll\" id=\"matrix-box\"><table class=\"matrix\"><tr><th>scene</th>",
        escape(&buffers.join(", "))
    );
    for be in &backends {
        let _ = write!(b, "<th>{}</th>", escape(be));
    }
    b.push_str("</tr>");
    for &i in &order {
        let s = &data.scenes[i];
        let _ = write!(b, "<tr><td class=\"scene\">{}</td>", scene_link(s, ""));
        for be in &backends {
            b.push_str("<td>");
            let entries: Vec<&ResultEntry> =
                s.results.iter().filter(|e| &e.backend == be).collect();
            if entries.is_empty() {
                match s.render(be) {
                    Some(r) => {
                        let why = if r.status == RenderStatus::Ok {
                            format!("{:.3} s", r.time_s)
                        } else {
                            format!("{}{}", r.reason, r.message)
                        };
                        let _ = write!(b, "{}", badge(r.status.as_str(), &why));
                    }
                    None => b.push_str("<span class=\"muted\">—</span>"),
                }
            }
            for e in entries {
                let _ = write!(
                    b,
                    "<a href=\"{}\">{}:&nbsp;{}</a>{}<br>",
                    url(&format!("{}.html#b-{}", s.page, super::data::page_stem(be))),
                    escape(&e.buffer),
                    badge(&e.status, &e.reason),
                    compact_counts(e)
                );
            }
            b.push_str("</td>");
        }
        b.push_str("</tr>");
    }
    b.push_str("</table></div>");

    // ---- scenes with thumbnails
    b.push_str("<h2 id=\"scenes\">Scenes</h2><div class=\"grid\">");
    for &i in &order {
        let s = &data.scenes[i];
        let _ = write!(
            b,
            "<figure><a href=\"{}\">",
            url(&format!("{}.html", s.page))
        );
        // The reference's radiance if any, else its IDs (they show the triangles), else depth.
        let thumb = [Kind::Radiance, Kind::Ids, Kind::Depth]
            .iter()
            .find_map(|k| {
                images[i]
                    .pictures
                    .iter()
                    .find(|p| p.backend == m.reference && p.kind == *k)
            });
        if let Some(p) = thumb {
            let _ = write!(
                b,
                "<img src=\"{}\" alt=\"{}\">",
                url(&p.file),
                escape(&p.caption)
            );
        }
        let display = s.resolved.as_ref().map(|r| r.name.as_str()).unwrap_or("");
        let _ = write!(
            b,
            "</a><figcaption>{} {}",
            scene_link(s, ""),
            if display.is_empty() || display == s.name {
                String::new()
            } else {
                format!("(“{}”)", escape(display))
            }
        );
        let failing = s
            .results
            .iter()
            .filter(|e| status_rank(&e.status) == 0)
            .count();
        if failing > 0 {
            let _ = write!(
                b,
                " {}",
                badge("fail", &format!("{failing} failing verdicts"))
            );
        }
        b.push_str("</figcaption></figure>");
    }
    b.push_str("</div>");

    // ---- plots
    let color = |be: &str| svg::backend_color(backends.iter().position(|x| x == be).unwrap_or(0));
    let groups: Vec<(String, Vec<svg::Bar>)> = order
        .iter()
        .map(|&i| {
            let s = &data.scenes[i];
            let bars = s
                .backends()
                .into_iter()
                .map(|be| {
                    let t = s.render(&be).filter(|r| r.time_s > 0.0).map(|r| r.time_s);
                    let c = color(&be);
                    (be, c, t)
                })
                .collect();
            (s.name.clone(), bars)
        })
        .collect();
    let _ = write!(b, "<h2 id=\"times\">Render times per scene</h2><p class=\"muted\">Wall-clock seconds as recorded by check (external renderers include process start and their conversion).</p>{}", svg::time_bars(&groups));
    let mut agg: Vec<(String, String, Histogram)> = Vec::new();
    for imgs in images {
        for (be, h) in &imgs.histograms {
            match agg.iter_mut().find(|a| &a.0 == be) {
                Some(a) => a.2.merge(h),
                None => agg.push((be.clone(), color(be), h.clone())),
            }
        }
    }
    let _ = write!(
        b,
        "<h2 id=\"errors\">Depth errors per backend, all scenes</h2>{}",
        svg::histograms(&agg)
    );

    // ---- versions
    b.push_str(
        "<h2 id=\"versions\">Backend versions</h2><table><tr><th>backend</th><th>version</th></tr>",
    );
    let mut versions: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
    for s in &data.scenes {
        for r in s.runs.iter().flat_map(|r| r.renders.iter()) {
            let v = versions.entry(r.backend.as_str()).or_default();
            if !r.version.is_empty() && !v.contains(&r.version.as_str()) {
                v.push(r.version.as_str());
            }
        }
    }
    for (be, v) in versions {
        let _ = write!(
            b,
            "<tr><td>{}</td><td>{}</td></tr>",
            escape(be),
            escape(&v.join("; "))
        );
    }
    b.push_str("</table>");
    let _ = write!(
        b,
        "<h2 id=\"rerun\">Rerun</h2><p>The same scenes and options, into a new folder beside this run (this one is left as it is); each scene page has the command for one scene and one backend.</p>{}",
        command_block(&super::rerun::run_command(data))
    );
    page("rendiff report", &b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_formats_known_instants() {
        assert_eq!(utc(0), "1970-01-01T00:00:00Z");
        assert_eq!(utc(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(utc(1_795_340_886), "2026-11-22T09:48:06Z");
    }
}
