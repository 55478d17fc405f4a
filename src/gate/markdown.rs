//! The gate's markdown summary (`RUN/gate.md`, a pull-request comment):
//! every cell escaped, so no name from a scene can carry markup or links.

use super::*;

/// Escapes text for a markdown table cell in a PR comment (markdown renders
/// inline HTML, so names from scene files must not reach it raw).
pub fn md(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        if let Some(entity) = crate::report::html::markup_entity(c) {
            out.push_str(entity);
            continue;
        }
        match c {
            '|' => out.push_str("\\|"),
            '\n' | '\r' => out.push(' '),
            // Other control characters (a terminal escape in a scene's file
            // name) and bidi overrides are written as escapes: the summary
            // is printed on the terminal too.
            c if c.is_control() || crate::scene::is_bidi_control(c) => {
                out.extend(c.escape_unicode())
            }
            '\\' | '`' | '*' | '[' | ']' | '~' => {
                out.push('\\');
                out.push(c);
            }
            c => out.push(c),
        }
    }
    out
}

fn link_target(path: &str) -> String {
    crate::report::html::url(path)
}

/// The renderer versions of a run, one string per backend.
pub fn renderer_versions(m: &Manifest) -> BTreeMap<String, String> {
    let mut v: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for s in &m.scenes {
        for r in &s.renders {
            let e = v.entry(r.backend.clone()).or_default();
            if !r.version.is_empty() && !e.contains(&r.version) {
                e.push(r.version.clone());
            }
        }
    }
    v.into_iter().map(|(k, e)| (k, e.join("; "))).collect()
}

/// Rows per section of the summary: a PR comment must stay short; the report has the rest.
pub const MAX_ROWS: usize = 40;

/// The PR-comment summary: verdict, regressions, improvements, notes (one row
/// per changed entry), each row linking to its scene's report page
/// (RUN/report/<scene>.html).
pub fn markdown(
    outcome: &Outcome,
    baseline: &Baseline,
    baseline_path: &str,
    run: &Path,
    manifest: Option<&Manifest>,
) -> String {
    let mut s = String::new();
    // One row per (scene, backend, buffer), in the section of its worst change.
    let mut rows: Vec<(ChangeKind, Vec<&Change>)> = Vec::new();
    for c in &outcome.changes {
        let same = |r: &&mut (ChangeKind, Vec<&Change>)| {
            let f = r.1[0];
            (&f.scene, &f.backend, &f.buffer) == (&c.scene, &c.backend, &c.buffer)
        };
        match rows.iter_mut().find(same) {
            Some(r) => {
                r.0 = r.0.min(c.kind);
                r.1.push(c);
            }
            None => rows.push((c.kind, vec![c])),
        }
    }
    let count = |k: ChangeKind| rows.iter().filter(|r| r.0 == k).count();
    let (n, improvements) = (
        count(ChangeKind::Regression),
        count(ChangeKind::Improvement),
    );
    let run_s = run.display().to_string();
    let _ = writeln!(
        s,
        "## rendiff gate: {} — {n} regressed entr{}, {improvements} improved\n",
        if outcome.regressions() == 0 {
            "PASS"
        } else {
            "FAIL"
        },
        if n == 1 { "y" } else { "ies" },
    );
    let p = &baseline.provenance;
    let _ = writeln!(
        s,
        "Run `{}` against baseline `{}` (blessed {} on {}, rendiff {}); {} entries compared. Report: [{}]({}).\n",
        run_s.replace('`', "'"),
        baseline_path.replace('`', "'"),
        md(&p.blessed),
        md(&p.cpu),
        md(&p.rendiff_version),
        outcome.compared,
        md(&format!("{run_s}/report/index.html")),
        link_target(&format!("{run_s}/report/index.html"))
    );
    let sections = [
        (ChangeKind::Regression, "Regressions (fail the gate)"),
        (
            ChangeKind::Improvement,
            "Improvements (run `rendiff bless` to lock them in)",
        ),
        (ChangeKind::Note, "Notes"),
    ];
    for (kind, title) in sections {
        let mine: Vec<&Vec<&Change>> = rows.iter().filter(|r| r.0 == kind).map(|r| &r.1).collect();
        if mine.is_empty() {
            continue;
        }
        let _ = writeln!(
            s,
            "### {title}: {}\n\n| scene | backend | buffer | what changed | page |\n|---|---|---|---|---|",
            mine.len()
        );
        for changes in mine.iter().take(MAX_ROWS) {
            let c = changes[0];
            let rel = format!(
                "{run_s}/{}#b-{}",
                crate::report::scene_page_path(&c.scene),
                crate::report::page_stem(&c.backend)
            );
            let page = format!(
                "[{}]({})",
                md(&crate::report::scene_page_path(&c.scene)),
                link_target(&rel)
            );
            let what: Vec<String> = changes.iter().map(|c| md(&c.phrase())).collect();
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {page} |",
                md(&c.scene),
                md(&c.backend),
                md(&c.buffer),
                what.join("; ")
            );
        }
        if mine.len() > MAX_ROWS {
            let _ = writeln!(
                s,
                "\n… and {} more; every verdict is in the report.",
                mine.len() - MAX_ROWS
            );
        }
        s.push('\n');
    }
    if let Some(m) = manifest {
        let now = renderer_versions(m);
        let mut lines = Vec::new();
        for (be, v) in &now {
            match p.renderers.get(be) {
                Some(old) if old != v => {
                    lines.push(format!("- {}: {} → {}", md(be), md(old), md(v)))
                }
                None => lines.push(format!("- {}: new backend ({})", md(be), md(v))),
                _ => {}
            }
        }
        if !lines.is_empty() {
            let _ = writeln!(
                s,
                "### Renderer versions changed since the baseline\n\n{}\n",
                lines.join("\n")
            );
        }
    }
    if !run.join("report/index.html").exists() {
        let _ = writeln!(
            s,
            "_No report in this run folder yet: `rendiff report {}` writes it._\n",
            run_s.replace('`', "'")
        );
    }
    if outcome.changes.is_empty() {
        s.push_str("Every verdict and number matches the baseline within its noise bounds.\n");
    }
    s
}
