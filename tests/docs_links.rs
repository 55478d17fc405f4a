//! The contract lives in the repository: every relative link in the README,
//! ARCHITECTURE.md and docs/ points at a file that exists, and no file cites
//! a path outside the repository (a clone must carry what it refers to).

use std::path::{Path, PathBuf};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn documents() -> Vec<PathBuf> {
    let mut v = vec![root().join("README.md"), root().join("ARCHITECTURE.md")];
    for e in std::fs::read_dir(root().join("docs")).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "md") {
            v.push(p);
        }
    }
    v
}

/// Targets of markdown links `[text](target)` that are relative paths.
fn relative_links(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(i) = rest.find("](") {
        rest = &rest[i + 2..];
        let Some(end) = rest.find(')') else { break };
        let target = rest[..end].split('#').next().unwrap_or("").trim();
        if !target.is_empty() && !target.contains("://") && !target.starts_with("mailto:") {
            out.push(target.to_string());
        }
    }
    out
}

#[test]
fn every_relative_link_in_the_docs_resolves() {
    let mut broken = Vec::new();
    for doc in documents() {
        let text = std::fs::read_to_string(&doc).unwrap();
        for link in relative_links(&text) {
            let target = doc.parent().unwrap().join(&link);
            if !target.exists() {
                broken.push(format!("{}: {link}", doc.display()));
            }
        }
    }
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

#[test]
fn the_contract_is_in_the_repository() {
    assert!(root().join("docs/DESIGN.md").is_file());
    assert!(root().join("docs/external-renderers.md").is_file());
    let mut outside = Vec::new();
    let mut stack = vec![root().to_path_buf()];
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            if p.is_dir() {
                if !name.starts_with('.') && name != "target" && name != "reports" {
                    stack.push(p);
                }
                continue;
            }
            let text_like = ["rs", "py", "md", "toml", "sh", "txt"]
                .iter()
                .any(|x| p.extension().is_some_and(|e| e == *x));
            if !text_like || p.ends_with("tests/docs_links.rs") {
                continue;
            }
            let Ok(text) = std::fs::read_to_string(&p) else {
                continue;
            };
            for needle in ["../shared/", "/work/shared"] {
                if text.contains(needle) {
                    outside.push(format!("{} cites {needle}", p.display()));
                }
            }
        }
    }
    assert!(
        outside.is_empty(),
        "files citing paths outside the repository:\n{}",
        outside.join("\n")
    );
}
