//! ARCHITECTURE.md's "Invariants" that a grep can check: the core crate has
//! no command line and starts no process; only the tool does.

use std::path::Path;

fn core_sources() -> Vec<(String, String)> {
    let mut out = Vec::new();
    let mut stack = vec![Path::new(env!("CARGO_MANIFEST_DIR")).join("crates/rendiff-core/src")];
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
    assert!(out.len() > 10, "core sources not found");
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
    for (file, text) in core_sources() {
        for forbidden in ["Command::new", "process::Command", "clap::", "run_folder"] {
            assert!(
                !text.contains(forbidden),
                "{file} uses {forbidden}: the core never starts a process, parses a command line or reads a run folder"
            );
        }
    }
}
