//! `FOLDER/findings.html`: the findings of a fuzz run as one static page in
//! the report's style (`report::html`: same shell, same escaping), written
//! next to findings.json. Each distinct finding shows its signature and
//! situation, its classification with the reason (unclassified when no
//! declaration matched: `known.rs`), how many scenes hit it and of which
//! families, the verifier's explanation, the reduced scene (its text, sizes
//! and the one command that reproduces it), and the pictures of the scene it
//! was reduced from, drawn by the report's own `report::images` into
//! `FOLDER/findings/<id>/`. Every string from a scene, a renderer or a
//! declaration goes through `html::escape`.

use super::findings::{Finding, Ledger};
use super::known::Kind;
use crate::report::{data::RunData, html, images};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// File name of the page in the fuzz folder.
pub const PAGE: &str = "findings.html";
/// Folder (in the fuzz folder) of the page's pictures, one subfolder per finding.
pub const IMAGES: &str = "findings";

/// Longest reduced scene text shown inline (bytes); longer ones are linked.
const MAX_INLINE: usize = 16_384;
/// Scene names listed per finding.
const MAX_NAMES: usize = 40;

/// The run folder holding `scene` of this ledger (`run`, or its batch's
/// folder under `--minutes`), None when the name is not a generated one.
pub fn scene_run(folder: &Path, ledger: &Ledger, scene: &str) -> Option<PathBuf> {
    if ledger.run != "runs" {
        return Some(folder.join(&ledger.run));
    }
    let index: u64 = scene.rsplit('_').next()?.parse().ok()?;
    Some(folder.join(super::batch_run(index / super::BATCH)))
}

/// Writes FOLDER/findings.html (and its pictures) and returns its path.
pub fn write(folder: &Path, ledger: &Ledger) -> anyhow::Result<PathBuf> {
    let img_root = folder.join(IMAGES);
    let _ = std::fs::remove_dir_all(&img_root);
    let mut loaded: Vec<(PathBuf, Option<RunData>)> = Vec::new();
    let mut body = String::new();
    let what = if ledger.from.is_empty() {
        format!("seed {}, {} scenes", ledger.seed, ledger.scenes)
    } else {
        format!(
            "{} variants of {} ({} scene(s))",
            ledger.scenes,
            ledger.from.join(", "),
            ledger.from.len()
        )
    };
    let _ = writeln!(
        body,
        "<h1>Findings: {}</h1>\n<p>{} failing verdicts, {} findings ({}). \
         The ledger: <a href=\"findings.json\">findings.json</a>. \
         Classifications come from the known-finding declarations (docs/fuzzing.md); \
         a finding no declaration matches is unclassified: not explained yet.</p>",
        html::escape(&what),
        ledger.failures.len(),
        ledger.findings.len(),
        html::escape(&tally(ledger)),
    );
    if !ledger.base_failures.is_empty() {
        let _ = writeln!(
            body,
            "<p class=\"note\">The base scenes themselves fail {} verdict(s) (in findings.json, \
             <code>base_failures</code>); a variant failing the same way is no finding.</p>",
            ledger.base_failures.len()
        );
    }
    if !ledger.camera_failures.is_empty() {
        let _ = writeln!(
            body,
            "<p class=\"note\">{} camera calibration failures (not reduced: they are probes, not generated scenes).</p>",
            ledger.camera_failures.len()
        );
    }
    body.push_str(&summary_table(ledger));
    for f in &ledger.findings {
        body.push_str(&finding_section(folder, ledger, f, &mut loaded));
    }
    let page = html::page(
        &format!("rendiff fuzz findings, seed {}", ledger.seed),
        &body,
    );
    let path = folder.join(PAGE);
    crate::exr_io::write_atomically(&path, |tmp| Ok(std::fs::write(tmp, &page)?))?;
    Ok(path)
}

/// "2 renderer bug, 1 unclassified".
fn tally(ledger: &Ledger) -> String {
    let mut counts: Vec<(Kind, usize)> = Vec::new();
    for f in &ledger.findings {
        let k = f
            .classification
            .as_ref()
            .map_or(Kind::Unclassified, |c| c.kind);
        match counts.iter_mut().find(|(c, _)| *c == k) {
            Some((_, n)) => *n += 1,
            None => counts.push((k, 1)),
        }
    }
    if counts.is_empty() {
        return "none".into();
    }
    counts
        .iter()
        .map(|(k, n)| format!("{n} {}", k.label()))
        .collect::<Vec<_>>()
        .join(", ")
}

fn kind_badge(f: &Finding) -> String {
    let (kind, reason) = f
        .classification
        .as_ref()
        .map_or((Kind::Unclassified, ""), |c| (c.kind, c.reason.as_str()));
    // The report's badge colours: a bug is a failure, a false alarm the
    // verifier's, unclassified an error until explained.
    let status = match kind {
        Kind::RendererBug | Kind::ExporterBug => "fail",
        Kind::VerifierFalseAlarm => "expected_fail",
        Kind::Unclassified => "error",
    };
    format!(
        "<span class=\"badge s-{}\" title=\"{}\">{}</span>",
        html::status_class(status),
        html::escape(reason),
        html::escape(kind.label())
    )
}

fn summary_table(ledger: &Ledger) -> String {
    let mut t = String::from(
        "<table class=\"matrix\"><tr><th>finding</th><th>backend</th><th>buffer</th><th>class</th>\
         <th>situation</th><th>hits</th><th>triangles</th><th>classification</th></tr>\n",
    );
    for f in &ledger.findings {
        let s = &f.signature;
        let tris = f
            .reduced
            .as_ref()
            .filter(|r| r.error.is_empty())
            .map_or("-".to_string(), |r| {
                format!("{} &rarr; {}", r.triangles_before, r.triangles_after)
            });
        let _ = writeln!(
            t,
            "<tr><td class=\"scene\"><a href=\"#{id}\">{id}</a></td><td>{}</td><td>{}</td><td>{}</td>\
             <td>{}</td><td class=\"num\">{}</td><td>{tris}</td><td>{}</td></tr>",
            html::escape(&s.backend),
            html::escape(&s.buffer),
            html::escape(&s.class),
            html::escape(&f.signature.situation.join(", ")),
            f.hits,
            kind_badge(f),
            id = html::escape(&f.id),
        );
    }
    t.push_str("</table>\n");
    t
}

fn finding_section(
    folder: &Path,
    ledger: &Ledger,
    f: &Finding,
    loaded: &mut Vec<(PathBuf, Option<RunData>)>,
) -> String {
    let s = &f.signature;
    let mut b = String::new();
    let _ = writeln!(
        b,
        "<h2 id=\"{id}\">{id}: {} fails {} ({}) {}</h2>",
        html::escape(&s.backend),
        html::escape(&s.buffer),
        html::escape(&s.class),
        kind_badge(f),
        id = html::escape(&f.id)
    );
    if let Some(c) = &f.classification {
        let _ = write!(
            b,
            "<p><b>{}</b>: {}",
            html::escape(c.kind.label()),
            html::escape(&c.reason)
        );
        if !c.known.is_empty() {
            let _ = write!(
                b,
                " <span class=\"muted\">(declared in {})</span>",
                html::escape(&c.known)
            );
        }
        if !c.scene.is_empty() {
            let _ = write!(b, " Known repro: <code>{}</code>.", html::escape(&c.scene));
        }
        b.push_str("</p>\n");
    }
    let families: Vec<String> = f.families.iter().map(|(k, n)| format!("{k} {n}")).collect();
    let mut names: Vec<&str> = f
        .scenes
        .iter()
        .take(MAX_NAMES)
        .map(String::as_str)
        .collect();
    if f.scenes.len() > MAX_NAMES {
        names.push("...");
    }
    let _ = writeln!(
        b,
        "<p>Situation: {}. Hit by {} scene(s) (by family: {}): <span class=\"counts\">{}</span></p>\n\
         <p>The verifier: <span class=\"reason\">{}</span></p>",
        html::escape(&if f.signature.situation.is_empty() {
            "none of the tagged ones".to_string()
        } else {
            f.signature.situation.join(", ")
        }),
        f.hits,
        html::escape(&families.join(", ")),
        html::escape(&names.join(" ")),
        html::escape(&f.reason)
    );
    match &f.reduced {
        Some(r) if r.error.is_empty() => {
            let _ = writeln!(
                b,
                "<h3>Reduced scene</h3>\n<p>From {}: {}. <a href=\"{}\">{}</a></p>",
                html::escape(&r.from),
                r.sizes("&rarr;"),
                html::url(&r.scene),
                html::escape(&r.scene)
            );
            if !r.image_note.is_empty() {
                let _ = writeln!(b, "<p>{}.</p>", html::escape(&r.image_note));
            }
            if let Some(t) = &r.failure_triangles {
                let list: Vec<String> = t.iter().map(usize::to_string).collect();
                let _ = writeln!(
                    b,
                    "<p>Every step failed near the triangles the failure was on at the start: \
                     {} of {}.</p>",
                    list.join(", "),
                    html::escape(&r.from)
                );
            }
            if let Some(size) = r.failure_size {
                let _ = writeln!(
                    b,
                    "<p>Every step failed with an interior error at least {} of the first                      failure's ({size:.3e}).</p>",
                    html::escape(&format!("1/{}", (1.0 / super::reduce::SIZE_FRACTION).round()))
                );
            }
            b.push_str(&html::command_block(&r.command));
            match std::fs::read_to_string(folder.join(&r.scene)) {
                Ok(text) if text.len() <= MAX_INLINE => {
                    let _ = writeln!(b, "<details><summary>scene text</summary><pre class=\"cmd\"><code>{}</code></pre></details>", html::escape(&text));
                }
                Ok(_) => {
                    b.push_str("<p class=\"muted\">(too long to show here: follow the link)</p>\n")
                }
                Err(e) => {
                    let _ = writeln!(
                        b,
                        "<p class=\"note\">{}: {}</p>",
                        html::escape(&r.scene),
                        html::escape(&e.to_string())
                    );
                }
            }
        }
        Some(r) => {
            let _ = writeln!(
                b,
                "<p class=\"note\">Not reduced ({}): {}</p>",
                html::escape(&r.from),
                html::escape(&r.error)
            );
        }
        None => b.push_str("<p class=\"muted\">Not reduced (--reduce-budget 0).</p>\n"),
    }
    let example = f
        .reduced
        .as_ref()
        .map_or_else(|| f.scenes[0].clone(), |r| r.from.clone());
    b.push_str(&pictures(folder, ledger, f, &example, loaded));
    b
}

/// The pictures of `scene` (the reference's and the finding's backend),
/// drawn by the report into FOLDER/findings/<id>/.
fn pictures(
    folder: &Path,
    ledger: &Ledger,
    f: &Finding,
    scene: &str,
    loaded: &mut Vec<(PathBuf, Option<RunData>)>,
) -> String {
    let Some(run) = scene_run(folder, ledger, scene) else {
        return String::new();
    };
    if !loaded.iter().any(|(p, _)| *p == run) {
        loaded.push((run.clone(), RunData::load(&run).ok()));
    }
    let Some((_, Some(data))) = loaded.iter().find(|(p, _)| *p == run) else {
        return format!(
            "<p class=\"note\">No pictures: the run {} cannot be read.</p>\n",
            html::escape(&run.display().to_string())
        );
    };
    let Some(sd) = data.scenes.iter().find(|s| s.name == scene) else {
        return String::new();
    };
    // The finding's id is ours ("F<n>"): a safe folder name.
    let rel = format!("{IMAGES}/{}", f.id);
    let imgs = images::build(&data.dir, &data.manifest.reference, sd, &folder.join(&rel));
    let backend = &f.signature.backend;
    let mut b = format!(
        "<h3>Pictures of {} (the scene it was reduced from)</h3>\n<div class=\"grid\">\n",
        html::escape(scene)
    );
    for p in imgs
        .pictures
        .iter()
        .filter(|p| p.backend == *backend || p.backend == data.manifest.reference)
    {
        let _ = writeln!(
            b,
            "<figure><img src=\"{}\" alt=\"{cap}\"><figcaption>{cap}</figcaption></figure>",
            html::url(&format!("{rel}/{}", p.file)),
            cap = html::escape(&p.caption)
        );
    }
    b.push_str("</div>\n");
    for n in &imgs.notes {
        let _ = writeln!(b, "<p class=\"note\">{}</p>", html::escape(n));
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fuzz::findings::{ReducedRecord, Signature};
    use crate::fuzz::known::Classification;
    use std::collections::BTreeMap;

    fn finding(backend: &str, reason: &str, classification: Option<Classification>) -> Finding {
        Finding {
            id: "F1".into(),
            signature: Signature {
                backend: backend.into(),
                buffer: "id".into(),
                class: "interior".into(),
                situation: vec!["shared_edge".into()],
            },
            hits: 2,
            scenes: vec!["s1_00001".into(), "s1_00007".into()],
            families: BTreeMap::from([("coplanar".to_string(), 2)]),
            reason: reason.into(),
            reduced: Some(ReducedRecord {
                from: "s1_00001".into(),
                scene: "reduced/F1.toml".into(),
                command: "rendiff check 'x<y>.toml'".into(),
                triangles_before: 9,
                triangles_after: 2,
                objects_before: 3,
                objects_after: 1,
                lights_before: 0,
                lights_after: 0,
                bytes_before: 900,
                bytes_after: 300,
                image_before: [64, 48],
                image_after: [20, 12],
                image_note: String::new(),
                check_runs: 4,
                candidates: 20,
                complete: true,
                failure_triangles: Some(vec![0, 1]),
                failure_size: None,
                error: String::new(),
            }),
            classification,
        }
    }

    fn ledger(findings: Vec<Finding>) -> Ledger {
        Ledger {
            format: super::super::findings::FINDINGS_FORMAT.into(),
            seed: 1,
            scenes: 10,
            run: "run".into(),
            from: Vec::new(),
            base_failures: Vec::new(),
            failures: Vec::new(),
            camera_failures: Vec::new(),
            findings,
        }
    }

    #[test]
    fn every_string_is_escaped_and_each_finding_says_what_it_is() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(dir.path().join("reduced")).unwrap();
        std::fs::write(dir.path().join("reduced/F1.toml"), "# <b>scene</b>\n").unwrap();
        let hostile = "<script>alert(1)</script>";
        let mut second = finding(hostile, &format!("reason {hostile}"), None);
        second.id = "F2".into();
        let l = ledger(vec![
            finding(
                "povray",
                "interior 1",
                Some(Classification {
                    kind: Kind::RendererBug,
                    reason: format!("a <limit> & {hostile}"),
                    known: "k.toml".into(),
                    scene: String::new(),
                }),
            ),
            second,
        ]);
        let path = write(dir.path(), &l).unwrap();
        let page = std::fs::read_to_string(path).unwrap();
        assert!(
            !page.contains("<script>alert"),
            "unescaped text on the page"
        );
        assert!(page.contains("&lt;script&gt;alert(1)&lt;/script&gt;"));
        assert!(page.contains("a &lt;limit&gt; &amp;"));
        assert!(
            page.contains("&lt;b&gt;scene&lt;/b&gt;"),
            "the reduced scene's text, escaped"
        );
        assert!(page.contains("rendiff check &#39;x&lt;y&gt;.toml&#39;"));
        assert!(page.contains("1 renderer bug, 1 unclassified"));
        // The signature's situation, and the triangles the reduction kept to.
        assert!(page.contains("shared_edge"));
        assert!(page.contains("the failure was on at the start: 0, 1 of s1_00001"));
        // The run is absent: a note instead of pictures, never a failed page.
        assert!(page.contains("cannot be read"));
    }

    #[test]
    fn batches_are_found_from_the_scene_index() {
        let mut l = ledger(Vec::new());
        let root = Path::new("/f");
        assert_eq!(scene_run(root, &l, "s1_00120"), Some(root.join("run")));
        l.run = "runs".into();
        assert_eq!(
            scene_run(root, &l, "s1_00120"),
            Some(root.join("runs/b0002"))
        );
        assert_eq!(
            scene_run(root, &l, "s1_00049"),
            Some(root.join("runs/b0000"))
        );
        assert_eq!(scene_run(root, &l, "odd"), None);
    }
}
