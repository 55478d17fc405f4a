//! Known findings: one small declaration per understood disagreement, matched
//! to a fuzz run's findings by signature, so that every finding on the
//! findings page is classified (renderer bug, exporter bug, verifier false
//! alarm) with its reason, and one that matches no declaration shows as
//! unclassified: unexplained until someone explains it.
//!
//! A declaration is a TOML file in the known folder (rendiff's own:
//! scenes/found/known/, one per finding in scenes/found/README.md; `fuzz
//! --known DIR` for yours):
//!
//! ```toml
//! classification = "renderer_bug"    # or "exporter_bug", "verifier_false_alarm"
//! reason = "POV-Ray drops every hit farther than 1e7 along the ray"
//! scene = "scenes/found/povray_max_distance_boundary.toml"   # optional: its repro
//! [signature]
//! backend = "povray"
//! buffers = ["id", "Z"]
//! class = "interior"
//! situation = ["distant"]            # optional: tags the finding's scene must have
//! ```
//!
//! A finding matches when its backend and class are the declaration's, its
//! buffer is one of `buffers`, and its situation (`situation.rs`) holds every
//! tag listed. Bad declarations are refused with the file and the problem.

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// What a finding is, once understood.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    /// The renderer is wrong (or has a limit the contract does not).
    RendererBug,
    /// rendiff's exporter for that renderer is wrong.
    ExporterBug,
    /// The verifier failed a render the contract allows.
    VerifierFalseAlarm,
    /// No declaration matches: not explained yet.
    Unclassified,
}

impl Kind {
    /// The words the page shows.
    pub fn label(self) -> &'static str {
        match self {
            Kind::RendererBug => "renderer bug",
            Kind::ExporterBug => "exporter bug",
            Kind::VerifierFalseAlarm => "verifier false alarm",
            Kind::Unclassified => "unclassified",
        }
    }
}

/// A declaration's signature.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct KnownSignature {
    backend: String,
    buffers: Vec<String>,
    class: String,
    #[serde(default)]
    situation: Vec<String>,
}

/// One declaration file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct KnownFile {
    classification: Kind,
    reason: String,
    #[serde(default)]
    scene: Option<String>,
    signature: KnownSignature,
}

/// A loaded declaration.
#[derive(Debug, Clone)]
pub struct Known {
    /// Its file (shown on the page, recorded in findings.json).
    pub file: PathBuf,
    decl: KnownFile,
}

/// A finding's classification, as findings.json records it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Classification {
    /// The kind.
    pub kind: Kind,
    /// Why (the declaration's reason), or why it is unclassified.
    pub reason: String,
    /// The declaration file that matched; empty when none did.
    #[serde(skip_serializing_if = "String::is_empty")]
    pub known: String,
    /// The declaration's repro scene, when it names one.
    #[serde(skip_serializing_if = "String::is_empty")]
    pub scene: String,
}

/// Reads every `*.toml` in `dir` (sorted; none when the folder is absent).
pub fn load(dir: &Path) -> Result<Vec<Known>> {
    if !dir.is_dir() {
        return Ok(Vec::new());
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("{}: cannot list", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    files.into_iter().map(|f| parse(&f)).collect()
}

fn parse(file: &Path) -> Result<Known> {
    let text = std::fs::read_to_string(file)
        .with_context(|| format!("{}: cannot read", file.display()))?;
    let decl: KnownFile = toml::from_str(&text).map_err(|e| {
        anyhow::anyhow!(
            "{}: not a known-finding declaration: {}",
            file.display(),
            crate::scene::printable(&e.to_string(), 300)
        )
    })?;
    if decl.classification == Kind::Unclassified {
        bail!(
            "{}: classification \"unclassified\" is what no declaration gives; \
             declare renderer_bug, exporter_bug or verifier_false_alarm",
            file.display()
        );
    }
    if decl.reason.trim().is_empty() || decl.signature.buffers.is_empty() {
        bail!(
            "{}: a declaration needs a reason and at least one buffer",
            file.display()
        );
    }
    Ok(Known {
        file: file.to_path_buf(),
        decl,
    })
}

/// The classification of a finding with this signature and situation: the
/// first matching declaration (files in name order), else unclassified.
pub fn classify(
    known: &[Known],
    backend: &str,
    buffer: &str,
    class: &str,
    situation: &[String],
) -> Classification {
    let hit = known.iter().find(|k| {
        let s = &k.decl.signature;
        s.backend == backend
            && s.class == class
            && s.buffers.iter().any(|b| b == buffer)
            && s.situation.iter().all(|t| situation.contains(t))
    });
    match hit {
        Some(k) => Classification {
            kind: k.decl.classification,
            reason: k.decl.reason.clone(),
            known: k.file.display().to_string(),
            scene: k.decl.scene.clone().unwrap_or_default(),
        },
        None => Classification {
            kind: Kind::Unclassified,
            reason: format!(
                "no declaration in the known folder ({} read) matches {backend} {buffer} {class} [{}]",
                known.len(),
                situation.join(", ")
            ),
            known: String::new(),
            scene: String::new(),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, text: &str) {
        std::fs::write(dir.join(name), text).unwrap();
    }

    const POVRAY: &str = r#"
classification = "renderer_bug"
reason = "beyond 1e7"
scene = "scenes/found/x.toml"
[signature]
backend = "povray"
buffers = ["id", "Z"]
class = "interior"
situation = ["distant"]
"#;

    #[test]
    fn a_finding_is_classified_only_by_a_declaration_that_matches_all_of_it() {
        let dir = tempfile::tempdir().unwrap();
        write(dir.path(), "a.toml", POVRAY);
        write(dir.path(), "notes.txt", "not read");
        let known = load(dir.path()).unwrap();
        assert_eq!(known.len(), 1);
        let tags = |t: &[&str]| t.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let c = classify(
            &known,
            "povray",
            "Z",
            "interior",
            &tags(&["distant", "huge"]),
        );
        assert_eq!(c.kind, Kind::RendererBug);
        assert_eq!(c.reason, "beyond 1e7");
        assert_eq!(c.scene, "scenes/found/x.toml");
        assert!(c.known.ends_with("a.toml"));
        // Each part of the signature matters: backend, buffer, class, situation.
        for (b, buf, cls, sit) in [
            ("mitsuba", "Z", "interior", &["distant"][..]),
            ("povray", "N", "interior", &["distant"][..]),
            ("povray", "Z", "crack", &["distant"][..]),
            ("povray", "Z", "interior", &["huge"][..]),
        ] {
            let c = classify(&known, b, buf, cls, &tags(sit));
            assert_eq!(c.kind, Kind::Unclassified, "{b} {buf} {cls} {sit:?}");
            assert!(c.reason.contains("no declaration"), "{}", c.reason);
        }
        // No folder: nothing known, everything unclassified.
        assert!(load(&dir.path().join("absent")).unwrap().is_empty());
    }

    #[test]
    fn bad_declarations_are_refused_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        for (name, text, says) in [
            (
                "kind.toml",
                &POVRAY.replace("renderer_bug", "bug")[..],
                "not a known-finding",
            ),
            (
                "extra.toml",
                &format!("colour = 1\n{POVRAY}")[..],
                "not a known-finding",
            ),
            (
                "unc.toml",
                &POVRAY.replace("renderer_bug", "unclassified")[..],
                "what no declaration gives",
            ),
            (
                "why.toml",
                &POVRAY.replace("beyond 1e7", " ")[..],
                "needs a reason",
            ),
        ] {
            let sub = dir.path().join(name.trim_end_matches(".toml"));
            std::fs::create_dir(&sub).unwrap();
            write(&sub, name, text);
            let e = format!("{:#}", load(&sub).unwrap_err());
            assert!(e.contains(name) && e.contains(says), "{e}");
        }
    }
}
