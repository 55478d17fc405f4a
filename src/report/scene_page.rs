//! One page per scene: the verdicts with every number and the reason for each
//! classification, every backend's pictures side by side with a flip viewer,
//! where the mismatches fall (per object), the depth-error distribution, times,
//! versions and the exact commands that reproduce each result.

use super::data::{
    explanations, is_scene_error, num, page_stem, status_rank, text, RunData, SceneData, CLASSES,
};
use super::html::{badge, command_block, escape, page, url};
use super::images::{Kind, SceneImages};
use super::overview::{camera_cells, camera_header, class_cells, count, CLASS_WORDS};
use super::svg;
use crate::check::manifest::ResultEntry;
use std::fmt::Write;

fn err(e: &ResultEntry, key: &str) -> String {
    num(e, key).map_or_else(
        || "-".into(),
        |v| {
            if v == 0.0 {
                "0".into()
            } else {
                format!("{v:.3e}")
            }
        },
    )
}

/// The largest normal angle of an `N` verdict, in radians and degrees ("-" when absent).
fn angle(e: &ResultEntry) -> String {
    num(e, "max_angle_rad").map_or_else(
        || "-".into(),
        |r| format!("{} rad ({:.3}°)", super::overview::sig(r), r.to_degrees()),
    )
}

/// A prim ID with the object that owns it in the resolved scene; null is the background.
fn prim_cell(scene: &SceneData, p: Option<u64>) -> String {
    let Some(p) = p else {
        return "<span class=\"muted\">background</span>".into();
    };
    match scene.resolved.as_ref().and_then(|r| r.object_of(p)) {
        Some((i, o)) if !o.name.is_empty() => {
            format!(
                "{p} <span class=\"muted\">(object {i}: {})</span>",
                escape(&o.name)
            )
        }
        Some((i, _)) => format!("{p} <span class=\"muted\">(object {i})</span>"),
        None => p.to_string(),
    }
}

/// CSS class of a mismatch class; anything unknown gets a neutral look.
fn class_css(class: &str) -> &'static str {
    match class {
        "edge" => "c-edge",
        "tie" => "c-tie",
        "crack" => "c-crack",
        "interior" => "c-interior",
        _ => "c-other",
    }
}

/// "Why pixels differ": each verdict's `explanations` as a table.
fn explanation_section(scene: &SceneData, rows: &[&ResultEntry]) -> String {
    let mut b = String::from(
        "<h2 id=\"why\">Why pixels differ</h2><p class=\"muted\">The comparison's explanation of each group of mismatching pixels: its class, \
         the triangles (prims) the reference and the backend saw, how many pixels, one example pixel (x, y) and the reason.</p>",
    );
    let mut any = false;
    for e in rows {
        let list = explanations(e);
        if list.is_empty() {
            continue;
        }
        any = true;
        let _ = write!(
            b,
            "<h3 id=\"why-{}-{}\">{} · {}</h3>",
            escape(&page_stem(&e.backend)),
            escape(&page_stem(&e.buffer)),
            escape(&e.backend),
            escape(&e.buffer),
        );
        let total: f64 = CLASSES.iter().filter_map(|(k, _)| num(e, k)).sum();
        let explained: u64 = list.iter().filter_map(|x| x.pixels).sum();
        if total > 0.0 {
            let _ = write!(
                b,
                "<p class=\"muted\">{} group{} explaining {explained} of {total} mismatching pixels (the comparison lists only the first groups).</p>",
                list.len(),
                if list.len() == 1 { "" } else { "s" }
            );
        }
        let _ = write!(
            b,
            "<table class=\"why\"><tr><th>class</th><th>reference prim</th><th>{} prim</th><th>pixels</th><th>example pixel</th><th>why</th></tr>",
            escape(&e.backend)
        );
        for x in &list {
            let _ = write!(
                b,
                "<tr><td><span class=\"cls {}\">{}</span></td><td>{}</td><td>{}</td><td class=\"num\">{}</td><td>{}</td><td class=\"reason\">{}</td></tr>",
                class_css(&x.class),
                escape(&x.class),
                prim_cell(scene, x.ref_prim),
                prim_cell(scene, x.test_prim),
                x.pixels.map_or_else(|| "-".into(), |n| n.to_string()),
                x.example
                    .map_or_else(|| "-".into(), |(px, py)| format!("({px}, {py})")),
                escape(&x.why)
            );
        }
        b.push_str("</table>");
    }
    if !any {
        b.push_str("<p class=\"muted\">No explanations recorded for this scene (every verdict matched, or an older comparison that did not write them).</p>");
    }
    b
}

/// The camera probe measurements of this scene (its `camera` entries), if any.
fn camera_section(rows: &[&ResultEntry]) -> String {
    let cams: Vec<&&ResultEntry> = rows.iter().filter(|e| e.buffer == "camera").collect();
    if cams.is_empty() {
        return String::new();
    }
    let mut b = format!(
        "<h2 id=\"camera\">Camera calibration probe</h2><p class=\"muted\">Each backend's camera as measured on this probe scene; the calibration on the overview combines every probe.</p><table><tr><th>backend</th>{}<th>status</th></tr>",
        camera_header()
    );
    for e in cams {
        let _ = write!(
            b,
            "<tr><td>{}</td>{}<td>{} <span class=\"reason\">{}</span></td></tr>",
            escape(&e.backend),
            camera_cells(|k| e.details.get(k).cloned()),
            badge(&e.status, &e.reason),
            escape(&e.reason)
        );
    }
    b.push_str("</table>");
    b
}

/// What a Z verdict judged beyond the pixels where both saw the same triangle
/// (judge/depth.py): the test's depths against its own triangle's plane where
/// it saw another, and the pixels that could be judged neither way, with why.
/// Without it a Z pass with "max |ΔZ| 0" stood beside a histogram of large
/// errors, which came from pixels of different triangles.
fn own_plane_note(e: &ResultEntry) -> String {
    let mut out = String::new();
    if let Some(n) = num(e, "own_plane_pixels").filter(|n| *n > 0.0) {
        let _ = write!(
            out,
            "<br><span class=\"muted\">{n} px where it saw another triangle than the reference: its depth judged against that triangle's own plane at the pixel center (max |ΔZ| {}).</span>",
            err(e, "own_plane_max_abs_error")
        );
    }
    if let Some(m) = e
        .details
        .get("not_comparable")
        .and_then(serde_json::Value::as_object)
        .filter(|m| !m.is_empty())
    {
        let parts: Vec<String> = m.iter().map(|(why, n)| format!("{n} px: {why}")).collect();
        let _ = write!(
            out,
            "<br><span class=\"muted\">Not comparable (both hit, judged neither way): {}.</span>",
            escape(&parts.join("; "))
        );
    }
    out
}

fn bound_text(e: &ResultEntry) -> String {
    match e.details.get("bound") {
        Some(serde_json::Value::Object(m)) => m
            .iter()
            .map(|(k, v)| format!("{k} {v}"))
            .collect::<Vec<_>>()
            .join(", "),
        _ => String::new(),
    }
}

/// Fields of a verdict that have no column (e.g. radiance's mode, p-value, FLIP),
/// so nothing the comparison recorded is hidden from the reviewer.
fn extra_fields(e: &ResultEntry) -> String {
    use crate::gate::{COUNT_METRICS, ERROR_METRICS};
    // Besides the gated counts and errors, what this page shows in columns
    // (the entry's typed fields, scene to reason, are not in `details`).
    const SHOWN: &[&str] = &[
        "bound",
        "bound_px",
        "command",
        "compared_pixels",
        "explanations",
        "images",
        "max_angle_rad",
        "mean_abs_error",
        "not_comparable",
        "offset_x_px",
        "offset_y_px",
        "own_plane_max_abs_error",
        "own_plane_pixels",
        "pixels",
        "rms_px",
        "rotation",
        "scale_x",
        "scale_y",
        "time_s",
        "tolerance",
        "version",
    ];
    let shown =
        |k: &str| SHOWN.contains(&k) || COUNT_METRICS.contains(&k) || ERROR_METRICS.contains(&k);
    let rows: Vec<String> = e
        .details
        .iter()
        .filter(|(k, v)| !shown(k) && !v.is_null() && v.as_str() != Some(""))
        .map(|(k, v)| {
            let v = v.as_str().map_or_else(|| v.to_string(), String::from);
            format!("{}: {}", escape(k), escape(&v))
        })
        .collect();
    if rows.is_empty() {
        String::new()
    } else {
        format!(
            "<details><summary>more</summary>{}</details>",
            rows.join("<br>")
        )
    }
}

fn legend() -> &'static str {
    "<p class=\"legend\">ID mismatch maps: <span class=\"sw\" style=\"background:#383838\"></span>same ID \
     <span class=\"sw\" style=\"background:#ffbf00\"></span>edge mismatch (center within the backend's rounding distance of an edge) \
     <span class=\"sw\" style=\"background:#ff00ff\"></span>interior mismatch (a bug) \
     <span class=\"sw\" style=\"background:#ff3030\"></span>mismatch, unclassified (the comparison drew no map) \
     <span class=\"sw\" style=\"background:#000\"></span>background in both. \
     Z maps: <span class=\"sw\" style=\"background:linear-gradient(90deg,#000004,#bc3754,#fcffa4)\"></span>|ΔZ| from 0 to the largest error \
     <span class=\"sw\" style=\"background:#00ffff\"></span>hit on one side only. \
     RGB maps: largest channel error in units of the tolerance (1 = at the limit, inferno), failing pixels amber (edge) or magenta (interior).</p>"
}

/// Renders `<page>.html` for one scene.
pub fn render(data: &RunData, scene: &SceneData, imgs: &SceneImages) -> String {
    let mut b = String::new();
    let reference = &data.manifest.reference;
    let _ = write!(
        b,
        "<p><a href=\"index.html\">← overview</a></p><h1>Scene {}</h1>",
        escape(&scene.name)
    );
    b.push_str("<table>");
    if let Some(r) = &scene.runs {
        let _ = write!(b, "<tr><th>scene file</th><td><code>{}</code></td></tr><tr><th>requires</th><td>{}</td></tr>", escape(&r.scene_file), escape(&r.requires.join(", ")));
    }
    if let Some(r) = &scene.resolved {
        let _ = write!(
            b,
            "<tr><th>name</th><td>{}</td></tr><tr><th>image</th><td>{} × {} px, {} triangles, {} objects</td></tr>",
            escape(&r.name), r.width, r.height, r.triangle_count, r.objects.len()
        );
    }
    let _ = write!(
        b,
        "<tr><th>reference</th><td>{}</td></tr></table>",
        escape(reference)
    );
    if let Some(p) = &data.results_problem {
        let _ = write!(b, "<p class=\"note\">No verdicts: {}</p>", escape(p));
    }
    for e in scene.results.iter().filter(|e| is_scene_error(e)) {
        let _ = write!(
            b,
            "<p class=\"note\">{} This scene could not be loaded, so nothing in it was compared: {}</p>",
            badge(&e.status, &e.reason),
            escape(&e.reason)
        );
    }

    // ---- verdicts
    let mut rows: Vec<&ResultEntry> = scene.results.iter().collect();
    rows.sort_by_key(|e| (status_rank(&e.status), e.backend.clone(), e.buffer.clone()));
    let _ = write!(b, "<h2 id=\"verdicts\">Verdicts</h2><p class=\"muted\">Failures first. Mismatch classes: {}. Mask: hit on one side only. Errors are |Z_test − Z_ref| where both hit the same triangle (where they hit different ones, the test's depth is judged against its own triangle's plane, said under the verdict); max angle: the largest angle between the normals (N) where both hit the same triangle. - : not compared.</p>", escape(CLASS_WORDS));
    b.push_str("<table><tr><th>backend</th><th>buffer</th><th>status</th><th>edge</th><th>tie</th><th>crack</th><th>interior</th><th>mask</th><th>compared px</th><th>max |ΔZ|</th><th>mean |ΔZ|</th><th>max rel</th><th>max angle</th><th>bound</th><th>why</th></tr>");
    for e in &rows {
        let tol = text(e, "tolerance");
        let _ = write!(
            b,
            "<tr><td><a href=\"#b-{}\">{}</a></td><td>{}</td><td>{}</td>{}<td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td>{}</td><td class=\"reason\">{}{}{}{}</td></tr>",
            url(&page_stem(&e.backend)),
            escape(&e.backend),
            escape(&e.buffer),
            badge(&e.status, &e.reason),
            class_cells(e),
            count(e, "mask_mismatches"),
            count(e, "compared_pixels"),
            err(e, "max_abs_error"),
            err(e, "mean_abs_error"),
            err(e, "max_rel_error"),
            escape(&angle(e)),
            escape(&bound_text(e)),
            escape(&e.reason),
            own_plane_note(e),
            if tol.is_empty() { String::new() } else { format!("<details><summary>tolerance</summary>{}</details>", escape(tol)) },
            extra_fields(e),
        );
    }
    b.push_str("</table>");
    b.push_str(&explanation_section(scene, &rows));
    b.push_str(&camera_section(&rows));

    // ---- pictures
    b.push_str("<h2 id=\"images\">Images</h2>");
    if let Some((lo, hi, from)) = &imgs.depth_range {
        let _ = write!(b, "<p>Depth uses one color scale for every backend of this scene: the range of {}. {}</p>", escape(from), svg::depth_bar(*lo, *hi));
        for (be, n) in &imgs.clamped {
            let _ = write!(
                b,
                "<p class=\"note\">{}: {n} px outside that range, drawn at its ends.</p>",
                escape(be)
            );
        }
    }
    b.push_str(legend());
    if imgs.pictures.len() >= 2 {
        b.push_str("<div class=\"flip\"><div class=\"flip-stage\">");
        let first = &imgs.pictures[0];
        let second = imgs
            .pictures
            .iter()
            .find(|p| p.backend != first.backend && p.kind == first.kind)
            .unwrap_or(&imgs.pictures[1]);
        let _ = write!(b, "<img class=\"flip-view\" src=\"{}\" alt=\"flip view\"></div><div class=\"flip-controls\"><b class=\"flip-label\"></b><br><span class=\"flip-pos muted\"></span>", url(&first.file));
        for (side, chosen) in [("a", first), ("b", second)] {
            let _ = write!(
                b,
                "<label>{} <select class=\"flip-{side}\">",
                side.to_uppercase()
            );
            for p in &imgs.pictures {
                let _ = write!(
                    b,
                    "<option value=\"{}\"{}>{}</option>",
                    url(&p.file),
                    if std::ptr::eq(p, chosen) {
                        " selected"
                    } else {
                        ""
                    },
                    escape(&p.caption)
                );
            }
            b.push_str("</select></label>");
        }
        b.push_str("<label><input type=\"checkbox\" class=\"flip-hover\" checked> hover shows B</label><p class=\"muted\">Click the image to flip between A and B; the buttons under each picture below pick A or B.</p></div></div>");
    }
    let backends = scene.backends();
    for be in &backends {
        let pics: Vec<_> = imgs.pictures.iter().filter(|p| &p.backend == be).collect();
        if pics.is_empty() {
            continue;
        }
        let _ = write!(
            b,
            "<h3>{}{}</h3><div class=\"grid\">",
            escape(be),
            if be == reference { " (reference)" } else { "" }
        );
        for p in pics {
            let src = url(&p.file);
            let _ = write!(
                b,
                "<figure><img src=\"{src}\" alt=\"{c}\" title=\"{c}\"><figcaption>{c}<button data-flip=\"a\" data-src=\"{src}\">A</button><button data-flip=\"b\" data-src=\"{src}\">B</button></figcaption></figure>",
                c = escape(&p.caption)
            );
        }
        b.push_str("</div>");
    }
    if !imgs.pictures.iter().any(|p| p.kind == Kind::Radiance) {
        b.push_str("<p class=\"muted\">No radiance: no backend wrote R,G,B for this scene.</p>");
    }

    // ---- where
    if let Some(r) = &scene.resolved {
        if !imgs.objects.is_empty() && !r.objects.is_empty() {
            b.push_str("<h2 id=\"where\">ID mismatches per object</h2><p class=\"muted\">Pixels whose id.prim differs from the reference, by the object the reference sees there (the backend's object where the reference sees background).</p><table><tr><th>object</th><th>name</th><th>material</th><th>prims</th>");
            for (be, _) in &imgs.objects {
                let _ = write!(b, "<th>{}</th>", escape(be));
            }
            b.push_str("</tr>");
            for (i, o) in r.objects.iter().enumerate() {
                let mat = o
                    .material
                    .and_then(|m| r.materials.get(m))
                    .map(String::as_str)
                    .unwrap_or("");
                let _ = write!(
                    b,
                    "<tr><td class=\"num\">{i}</td><td>{}</td><td>{}</td><td>{}..{}</td>",
                    escape(&o.name),
                    escape(mat),
                    o.first_prim,
                    o.first_prim + o.prim_count
                );
                for (_, m) in &imgs.objects {
                    let _ = write!(
                        b,
                        "<td class=\"num\">{}</td>",
                        m.by_object.get(i).copied().unwrap_or(0)
                    );
                }
                b.push_str("</tr>");
            }
            b.push_str("<tr><th colspan=\"4\">total</th>");
            for (_, m) in &imgs.objects {
                let _ = write!(b, "<th class=\"num\">{}</th>", m.total);
            }
            b.push_str("</tr></table>");
        }
    }

    // ---- plots
    let all = data.backends();
    let color = |be: &str| svg::backend_color(all.iter().position(|x| x == be).unwrap_or(0));
    let series: Vec<_> = imgs
        .histograms
        .iter()
        .map(|(be, h)| (be.clone(), color(be), h.clone()))
        .collect();
    let _ = write!(
        b,
        "<h2 id=\"errors\">Depth errors</h2>{}",
        svg::histograms(&series)
    );
    let bars = backends
        .iter()
        .map(|be| {
            (
                be.clone(),
                color(be),
                scene
                    .render(be)
                    .filter(|r| r.time_s > 0.0)
                    .map(|r| r.time_s),
            )
        })
        .collect();
    let _ = write!(
        b,
        "<h2 id=\"times\">Render times</h2>{}",
        svg::time_bars(&[(scene.name.clone(), bars)])
    );

    // ---- per backend: versions, times, commands
    b.push_str("<h2 id=\"backends\">Backends: versions, times, commands</h2><p class=\"muted\">The render command reproduces the buffer; the check command reproduces the verdict with the options of this run (the reference always renders too), into a new folder beside this run.</p>");
    for be in &backends {
        let _ = write!(
            b,
            "<h3 id=\"b-{}\">{}</h3>",
            escape(&page_stem(be)),
            escape(be)
        );
        match scene.render(be) {
            Some(r) => {
                let _ = write!(
                    b,
                    "<p>{} version <b>{}</b>, {}</p>",
                    badge(r.status.as_str(), &format!("{}{}", r.reason, r.message)),
                    escape(if r.version.is_empty() {
                        "?"
                    } else {
                        &r.version
                    }),
                    if r.time_s > 0.0 {
                        escape(&svg::format_seconds(r.time_s))
                    } else {
                        "no time recorded".into()
                    }
                );
                if !r.reason.is_empty() || !r.message.is_empty() {
                    let _ = write!(
                        b,
                        "<p class=\"reason\">{}</p>",
                        escape(&format!("{}{}", r.reason, r.message))
                    );
                }
                if !r.command.is_empty() {
                    let _ = write!(b, "render: {}", command_block(&r.command));
                }
                if !r.info.is_null() {
                    let info = serde_json::to_string_pretty(&r.info).unwrap_or_default();
                    let _ = write!(
                        b,
                        "<details><summary>backend info</summary><pre>{}</pre></details>",
                        escape(&info)
                    );
                }
            }
            None => b.push_str("<p class=\"muted\">not in manifest.json</p>"),
        }
        for e in scene.results.iter().filter(|e| &e.backend == be) {
            let cmd = text(e, "command");
            if !cmd.is_empty() && scene.render(be).is_none_or(|r| r.command != cmd) {
                let _ = write!(b, "{} render: {}", escape(&e.buffer), command_block(cmd));
            }
        }
        if be != reference {
            if let Some(cmd) = super::rerun::verdict_command(data, scene, be) {
                let _ = write!(b, "verdict: {}", command_block(&cmd));
            }
        }
    }
    if !imgs.notes.is_empty() {
        b.push_str("<h2>Report notes</h2><ul>");
        for n in &imgs.notes {
            let _ = write!(b, "<li>{}</li>", escape(n));
        }
        b.push_str("</ul>");
    }
    page(&format!("rendiff: {}", scene.name), &b)
}
