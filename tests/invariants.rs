//! ARCHITECTURE.md's "Invariants" that a grep can check: the core crate has
//! no command line and starts no process; only the tool does. And statuses
//! come from `vocab` only where the tool orchestrates (`check`, `gate`).

use rendiff::vocab::{RenderStatus, Status};
use std::path::Path;

/// Every `.rs` file under `rel` (from the repository root), with its text.
fn sources(rel: &str) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let mut stack = vec![Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)];
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push((
                    p.display().to_string(),
                    std::fs::read_to_string(&p).unwrap(),
                ));
            }
        }
    }
    assert!(out.len() > 2, "{rel}: sources not found");
    out
}

#[test]
fn the_core_crate_has_no_command_line_and_starts_no_process() {
    let manifest = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("crates/rendiff-core/Cargo.toml"),
    )
    .unwrap();
    for dep in ["clap", "indicatif", "signal-hook", "rendiff ="] {
        assert!(
            !manifest.contains(dep),
            "rendiff-core must not depend on {dep}"
        );
    }
    for (file, text) in sources("crates/rendiff-core/src") {
        for forbidden in ["Command::new", "process::Command", "clap::", "run_folder"] {
            assert!(
                !text.contains(forbidden),
                "{file} uses {forbidden}: the core never starts a process, parses a command line or reads a run folder"
            );
        }
    }
}

/// The status words `vocab` spells, render statuses and verdict statuses.
fn status_words() -> Vec<&'static str> {
    let mut words = RenderStatus::names();
    words.extend(Status::names());
    // `skipped` and `error` are both kinds of status: each word once.
    words.sort_unstable();
    words.dedup();
    words
}

/// `line:literal` for each status spelling written as a string literal in
/// `text`, comments aside (text after `//` on a line is not code).
fn raw_statuses(text: &str) -> Vec<String> {
    let words = status_words();
    let mut found = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let code = line.split("//").next().unwrap_or("");
        for w in &words {
            if code.contains(&format!("\"{w}\"")) {
                found.push(format!("{}:\"{w}\"", i + 1));
            }
        }
    }
    found
}

#[test]
fn the_scanner_finds_a_raw_status_and_ignores_comments() {
    let text = "let a = RenderStatus::Ok;\n// answers \"ok\"\nrec.status = \"error\".into();\nif s == \"expected_fail\" {}\n";
    assert_eq!(raw_statuses(text), ["3:\"error\"", "4:\"expected_fail\""]);
}

#[test]
fn check_and_gate_spell_no_status_themselves() {
    let mut bad = Vec::new();
    let mut files = 0;
    for dir in ["src/check", "src/gate"] {
        for (file, text) in sources(dir) {
            files += 1;
            bad.extend(
                raw_statuses(&text)
                    .into_iter()
                    .map(|at| format!("{file}:{at}")),
            );
        }
    }
    assert!(files > 10, "sources not found");
    assert!(
        bad.is_empty(),
        "status spelled as a string literal (use vocab::RenderStatus / vocab::Status): {bad:?}"
    );
}
