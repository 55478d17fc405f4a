//! One vocabulary for Rust and Python: the harness's `vocab.py` must spell
//! every feature, status, buffer and mismatch class exactly as
//! `rendiff_core::vocab` does (what `rendiff vocab --json` prints), in the
//! same order. A word added or renamed on one side only fails here.

use std::path::Path;
use std::process::Command;

#[test]
fn python_spells_the_vocabulary_as_rust_does() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let python = root.join(".venv/bin/python");
    assert!(
        python.exists(),
        "{} is missing: run scripts/setup.sh",
        python.display()
    );
    let out = Command::new(&python)
        .env("PYTHONPATH", root.join("harness"))
        .args([
            "-c",
            "import json; from rendiff_harness.contract import vocab; print(json.dumps(vocab.as_json()))",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let python: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rust = rendiff::vocab::json();
    assert_eq!(
        python, rust,
        "harness/rendiff_harness/contract/vocab.py and crates/rendiff-core/src/vocab.rs differ"
    );
    // The CLI prints the same.
    let cli = Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .args(["vocab", "--json"])
        .output()
        .unwrap();
    let cli: serde_json::Value = serde_json::from_slice(&cli.stdout).unwrap();
    assert_eq!(cli, rust);
}
