//! The report in a real browser (headless Chromium): every picture on the
//! overview and on a scene page loads, the inline script runs (the flip viewer
//! labels itself), and the overview lists every scene. Leaves a screenshot of
//! the overview beside the report (RUN/report/overview.png) for people.
//!
//! A missing browser fails the test with the fix (`scripts/setup.sh` installs
//! chromium); only RENDIFF_ALLOW_NO_BROWSER=1 turns that into a skip.

mod common_cli;

use common_cli::small_check;
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
