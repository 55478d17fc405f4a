//! ARCHITECTURE.md's "Invariants" that a grep can check: the core crate has
//! no command line and starts no process; only the tool does. Statuses
//! come from `vocab` only where the tool orchestrates (`check`, `gate`). SIMD
//! intrinsics live in the core's `simd` module only, and no closure wraps one.

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

/// The core crate's sources.
fn core_sources() -> Vec<(String, String)> {
    sources("crates/rendiff-core/src")
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

/// The part of a source file that is not test code: unit tests write the
/// wire format (a synthetic results.json with `"status": "pass"`) on purpose,
/// so a `tests.rs` module counts for nothing and a file stops at `#[cfg(test)]`.
fn non_test_code<'a>(file: &str, text: &'a str) -> &'a str {
    if file.ends_with("/tests.rs") {
        return "";
    }
    text.split("#[cfg(test)]").next().unwrap_or("")
}

#[test]
fn test_code_is_left_to_write_the_wire_format() {
    let text = "let s = Status::Pass;\n#[cfg(test)]\nmod tests { const J: &str = \"pass\"; }\n";
    assert_eq!(
        non_test_code("src/gate/policy.rs", text),
        "let s = Status::Pass;\n"
    );
    assert_eq!(non_test_code("src/gate/tests.rs", text), "");
    assert_eq!(
        raw_statuses(non_test_code("src/gate/policy.rs", "x == \"fail\"")),
        ["1:\"fail\""]
    );
}

#[test]
fn check_and_gate_spell_no_status_themselves() {
    let mut bad = Vec::new();
    let mut files = 0;
    for dir in ["src/check", "src/gate"] {
        for (file, text) in sources(dir) {
            files += 1;
            bad.extend(
                raw_statuses(non_test_code(&file, &text))
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

/// `path` relative to the core crate's `src/`, with `/` separators.
fn core_relative(path: &str) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("crates/rendiff-core/src");
    Path::new(path)
        .strip_prefix(&root)
        .unwrap()
        .to_string_lossy()
        .replace('\\', "/")
}

#[test]
fn simd_intrinsics_and_cpu_detection_live_in_the_simd_module_only() {
    for (file, text) in core_sources() {
        let rel = core_relative(&file);
        if rel.starts_with("simd/") {
            continue;
        }
        let code = strip_comments_and_strings(&text);
        for forbidden in ["arch::", "_mm", "is_x86_feature_detected"] {
            assert!(
                !code.contains(forbidden),
                "{file} uses {forbidden}: intrinsics and CPU detection live in \
                 crates/rendiff-core/src/simd/ (ARCHITECTURE.md); kernels call its traits"
            );
        }
    }
}

#[test]
fn no_closure_or_array_map_wraps_an_intrinsic() {
    let mut found = Vec::new();
    for (file, text) in core_sources() {
        let code = strip_comments_and_strings(&text);
        let line = |at: usize| code[..at].matches('\n').count() + 1;
        for (at, body) in closures(&code) {
            if body.contains("_mm") {
                found.push(format!("{file}:{}: closure around an intrinsic", line(at)));
            }
        }
        let squeezed: String = code.chars().filter(|c| !c.is_whitespace()).collect();
        for call in ["map(_mm", "from_fn(_mm"] {
            if squeezed.contains(call) {
                found.push(format!("{file}: {call}..): an intrinsic passed to {call}"));
            }
        }
    }
    // The checker itself: it must see this closure, and not a boolean `||`.
    let planted = "let a = x || y; let v = |p: Vec3| _mm_setr_ps(p.x, 0.0, 0.0, 0.0);";
    let seen: Vec<_> = closures(planted).into_iter().map(|(_, b)| b).collect();
    assert_eq!(seen, ["|p: Vec3| _mm_setr_ps(p.x, 0.0, 0.0, 0.0)"]);
    assert!(
        found.is_empty(),
        "a closure or array map wraps an intrinsic (ARCHITECTURE.md, \"Why the kernels look \
         the way they do\": compiled out of line, each intrinsic becomes a call):\n{}",
        found.join("\n")
    );
}

/// `text` with its `//` comments and string literals blanked (same length,
/// so offsets keep their lines).
fn strip_comments_and_strings(text: &str) -> String {
    let s = text.as_bytes();
    let mut out = s.to_vec();
    let mut i = 0;
    while i < s.len() {
        if s[i..].starts_with(b"//") {
            while i < s.len() && s[i] != b'\n' {
                out[i] = b' ';
                i += 1;
            }
        } else if s[i..].starts_with(b"'\"'") {
            i += 3;
        } else if s[i] == b'"' {
            i += 1;
            while i < s.len() && s[i] != b'"' {
                let step = if s[i] == b'\\' { 2 } else { 1 };
                for o in out.iter_mut().skip(i).take(step) {
                    if *o != b'\n' {
                        *o = b' ';
                    }
                }
                i += step;
            }
            i += 1;
        } else {
            i += 1;
        }
    }
    String::from_utf8(out).unwrap()
}

/// Every closure in `code` (comments and strings blanked): its offset and
/// its text from the parameter list to the end of its body. A `|` opens one
/// where it follows `=`, `(`, `,`, `{`, `;`, `move` or `return` (where a
/// binary `|` or `||` cannot stand).
fn closures(code: &str) -> Vec<(usize, &str)> {
    let s = code.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < s.len() {
        if s[i] != b'|' {
            i += 1;
            continue;
        }
        let before = code[..i].trim_end();
        let comparison = ["==", "<=", ">=", "!="]
            .iter()
            .any(|op| before.ends_with(op));
        let opens = (before.ends_with(['=', '(', ',', '{', ';']) && !comparison)
            || before.ends_with("move")
            || before.ends_with("return");
        if !opens {
            i += 1;
            continue;
        }
        let params_end = if s.get(i + 1) == Some(&b'|') {
            i + 1
        } else {
            match code[i + 1..].find('|') {
                Some(k) => i + 1 + k,
                None => break,
            }
        };
        let mut b = params_end + 1;
        while b < s.len() && s[b].is_ascii_whitespace() {
            b += 1;
        }
        if code[b..].starts_with("->") {
            b += code[b..].find('{').unwrap_or(0);
        }
        let mut depth = 0i32;
        let mut e = b;
        if s.get(b) == Some(&b'{') {
            while e < s.len() {
                match s[e] {
                    b'{' | b'(' | b'[' => depth += 1,
                    b'}' | b')' | b']' => depth -= 1,
                    _ => {}
                }
                e += 1;
                if depth == 0 {
                    break;
                }
            }
        } else {
            while e < s.len() {
                match s[e] {
                    b'{' | b'(' | b'[' => depth += 1,
                    b'}' | b')' | b']' if depth == 0 => break,
                    b'}' | b')' | b']' => depth -= 1,
                    b',' | b';' if depth == 0 => break,
                    _ => {}
                }
                e += 1;
            }
        }
        out.push((i, &code[i..e]));
        i = params_end + 1;
    }
    out
}
