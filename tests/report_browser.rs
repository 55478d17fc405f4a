//! The report in a real browser (headless Chromium): every picture on the
//! overview and on a scene page loads, the inline script runs (the flip viewer
//! labels itself), and the overview lists every scene. Leaves a screenshot of
//! the overview beside the report (RUN/report/overview.png) for people.
//!
//! A missing browser fails the test with the fix (`scripts/setup.sh` installs
//! chromium); only RENDIFF_ALLOW_NO_BROWSER=1 turns that into a skip.

mod common;

use common::cli::small_check;
use std::path::{Path, PathBuf};
use std::process::Command;

const CHROMIUM: &str = "/usr/bin/chromium";

fn chromium(profile: &Path, args: &[String]) -> String {
    let out = Command::new("timeout")
        .arg("120")
        .arg(CHROMIUM)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(args)
        .output()
        .expect("cannot start chromium");
    assert!(
        out.status.success(),
        "chromium failed ({:?}): {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn url(p: &Path) -> String {
    format!("file://{}", p.canonicalize().unwrap().display())
}

/// The DOM after scripts ran; asserts every <img> loaded.
fn loaded_dom(profile: &Path, page: &Path) -> String {
    let dom = chromium(
        profile,
        &[
            "--virtual-time-budget=5000".into(),
            "--dump-dom".into(),
            url(page),
        ],
    );
    let imgs: Vec<&str> = dom
        .split("<img")
        .skip(1)
        .map(|t| t.split('>').next().unwrap())
        .collect();
    assert!(!imgs.is_empty(), "{}: no images", page.display());
    for tag in &imgs {
        assert!(
            tag.contains("data-loaded=\"1\""),
            "{}: image did not load: <img{tag}>",
            page.display()
        );
    }
    assert!(
        dom.contains("data-images-failed=\"0\""),
        "{}: the page counted failed images",
        page.display()
    );
    assert!(
        dom.contains("data-images-pending=\"0\""),
        "{}: images still pending",
        page.display()
    );
    dom
}

#[test]
fn the_report_renders_in_a_headless_browser() {
    if !Path::new(CHROMIUM).exists() {
        if std::env::var("RENDIFF_ALLOW_NO_BROWSER").as_deref() == Ok("1") {
            eprintln!("SKIPPED: {CHROMIUM} not found and RENDIFF_ALLOW_NO_BROWSER=1");
            return;
        }
        panic!("{CHROMIUM} not found: run scripts/setup.sh (it installs chromium), or set RENDIFF_ALLOW_NO_BROWSER=1 to skip");
    }
    // Kept under target/tmp so the screenshot can be looked at after the test.
    let run: PathBuf = Path::new(env!("CARGO_TARGET_TMPDIR")).join("report-browser-run");
    let _ = std::fs::remove_dir_all(&run);
    small_check(&run);
    let report = run.join("report");
    let profile = tempfile::tempdir().unwrap();

    let dom = loaded_dom(profile.path(), &report.join("index.html"));
    for scene in ["three_triangles", "pixel_grid"] {
        assert!(
            dom.contains(&format!("href=\"{scene}.html\">{scene}</a>")),
            "overview does not list {scene}"
        );
    }
    let dom = loaded_dom(profile.path(), &report.join("pixel_grid.html"));
    assert!(
        dom.contains("class=\"flip-label\">A: raster depth<"),
        "the flip viewer's script did not run"
    );

    let shot = report.join("overview.png");
    chromium(
        profile.path(),
        &[
            format!("--screenshot={}", shot.display()),
            "--window-size=1280,900".into(),
            url(&report.join("index.html")),
        ],
    );
    let png = std::fs::read(&shot).expect("no screenshot written");
    assert!(
        png.starts_with(b"\x89PNG") && png.len() > 10_000,
        "screenshot is not a real PNG"
    );
    eprintln!("screenshot: {}", shot.display());
}

/// A number the report's script wrote on `<body>` (`data-NAME="N"`).
fn body_number(dom: &str, name: &str) -> i64 {
    let key = format!("data-{name}=\"");
    let at = dom
        .find(&key)
        .unwrap_or_else(|| panic!("the script recorded no {name}"));
    let rest = &dom[at + key.len()..];
    rest[..rest.find('"').unwrap()].parse().unwrap()
}

/// The report of a run with a failed camera calibration, in Chromium: the
/// causes come first, one row each, calibration before all else; every
/// evidence link points at a page and an anchor that exist; the matrix stays
/// inside the page at 1400 px and scrolls inside its own box on a narrow
/// window. Screenshots stay in target/report-browser/ (a CI artifact).
#[test]
fn causes_links_and_the_matrix_in_a_headless_browser() {
    if !Path::new(CHROMIUM).exists() {
        if std::env::var("RENDIFF_ALLOW_NO_BROWSER").as_deref() == Ok("1") {
            eprintln!("SKIPPED: {CHROMIUM} not found and RENDIFF_ALLOW_NO_BROWSER=1");
            return;
        }
        panic!("{CHROMIUM} not found: run scripts/setup.sh (it installs chromium), or set RENDIFF_ALLOW_NO_BROWSER=1 to skip");
    }
    common::cli::need_venv();
    let root = common::cli::root();
    let keep = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/report-browser");
    let run = keep.join("causes-run");
    let _ = std::fs::remove_dir_all(&run);
    std::fs::create_dir_all(&keep).unwrap();
    let path = format!(
        "{}:{}",
        root.join(".venv/bin").display(),
        std::env::var("PATH").unwrap_or_default()
    );
    // A renderer sampling pixel corners fails its calibration and spoils its
    // verdicts; the core's tracer and Embree pass beside it.
    let out = common::cli::rendiff()
        .env("PATH", path)
        .args([
            "check",
            "scenes/three_triangles.toml",
            "scenes/pixel_grid.toml",
            "--renderers",
            "tests/fuzz_renderers/cameras.toml",
            "--only",
            "corner_sample,trace,embree",
            "--jobs",
            "2",
            "--quiet",
            "-o",
        ])
        .arg(&run)
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report = run.join("report");
    let profile = tempfile::tempdir().unwrap();
    let dom = loaded_dom(profile.path(), &report.join("index.html"));

    // Grouping: one cause, the calibration, before anything else.
    let attention = &dom[dom.find("id=\"attention\"").unwrap()..];
    let attention = &attention[..attention.find("<h2").unwrap()];
    let causes: Vec<&str> = attention
        .split("<tr class=\"cause\"")
        .skip(1)
        .map(|r| &r[..r.find("</tr>").unwrap()])
        .collect();
    assert_eq!(causes.len(), 1, "{attention}");
    assert!(
        causes[0].contains("data-kind=\"calibration\"") && causes[0].contains("corner_sample"),
        "{}",
        causes[0]
    );

    // Links: every link in the causes reaches a page, and its anchor is on it.
    let mut links = 0;
    for href in attention.split("href=\"").skip(1) {
        let href = &href[..href.find('"').unwrap()];
        let (file, anchor) = href.split_once('#').unwrap_or((href, ""));
        let target = report.join(file);
        let page = std::fs::read_to_string(&target)
            .unwrap_or_else(|e| panic!("link {href}: {}: {e}", target.display()));
        if !anchor.is_empty() {
            assert!(
                page.contains(&format!("id=\"{anchor}\"")),
                "link {href}: no anchor {anchor} on {}",
                target.display()
            );
        }
        links += 1;
    }
    assert!(links >= 2, "the causes link to no evidence: {attention}");

    // The matrix: inside the page at 1400 px, and at 600 px it scrolls in its box.
    for (width, must_scroll) in [(1400, false), (600, true)] {
        let dom = chromium(
            profile.path(),
            &[
                format!("--window-size={width},900"),
                "--virtual-time-budget=3000".into(),
                "--dump-dom".into(),
                url(&report.join("index.html")),
            ],
        );
        let right = body_number(&dom, "matrix-right");
        let viewport = body_number(&dom, "viewport-width");
        assert!(
            right <= viewport,
            "at {width} px the matrix box ends at {right} px, past the page's {viewport} px"
        );
        if must_scroll {
            assert_eq!(
                body_number(&dom, "matrix-scrolls"),
                1,
                "at {width} px the matrix should scroll inside its box"
            );
        }
        let shot = keep.join(format!("overview-{width}.png"));
        chromium(
            profile.path(),
            &[
                format!("--screenshot={}", shot.display()),
                format!("--window-size={width},900"),
                url(&report.join("index.html")),
            ],
        );
        let png = std::fs::read(&shot).expect("no screenshot written");
        assert!(png.starts_with(b"\x89PNG"), "screenshot is not a PNG");
        eprintln!("screenshot: {}", shot.display());
    }
}
