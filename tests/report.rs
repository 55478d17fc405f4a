//! The HTML report (`rendiff report`, and the end of every `rendiff check`):
//! it lists every scene, shows every backend's pictures and verdicts with the
//! commands that reproduce them, stays inside its folder (relative links, no
//! network), survives runs without radiance, verdicts or renders, and escapes
//! every name that comes from a scene file.

mod common_cli;

use common_cli::{need_venv, rendiff, small_check};
use std::path::{Path, PathBuf};

fn read(p: &Path) -> String {
    std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Every `attr="..."` value in `html`.
fn attrs<'a>(html: &'a str, attr: &str) -> Vec<&'a str> {
    let pat = format!(" {attr}=\"");
    html.match_indices(&pat)
        .map(|(i, _)| {
            let rest = &html[i + pat.len()..];
            &rest[..rest.find('"').unwrap()]
        })
        .collect()
}

fn files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(files(&p));
        } else {
            out.push(p);
        }
    }
    out
}

/// Links and images point inside the report folder, to files that exist, and nothing is fetched.
fn assert_self_contained(report: &Path) {
    for page in files(report)
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e == "html"))
    {
        let html = read(&page);
        assert!(
            !html.contains("http://") && !html.contains("https://"),
            "{}: external URL",
            page.display()
        );
        assert!(
            !html.contains("<link") && !html.contains("src=\"//"),
            "{}: external resource",
            page.display()
        );
        for target in attrs(&html, "src")
            .into_iter()
            .chain(attrs(&html, "href"))
            .chain(attrs(&html, "value"))
        {
            let path = target.split('#').next().unwrap();
            if path.is_empty() || !(path.ends_with(".html") || path.ends_with(".png")) {
                continue;
            }
            assert!(
                !path.starts_with('/') && !path.contains(".."),
                "{}: non-relative link {target}",
                page.display()
            );
            assert!(
                report.join(path).is_file(),
                "{}: broken link {target}",
                page.display()
            );
        }
    }
}

#[test]
fn check_writes_a_self_contained_report_of_every_scene_and_backend() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    small_check(&run);
    let report = run.join("report");
    let index = read(&report.join("index.html"));
    for scene in ["three_triangles", "pixel_grid"] {
        assert!(
            index.contains(&format!("href=\"{scene}.html\"")),
            "overview lacks {scene}"
        );
        let page = read(&report.join(format!("{scene}.html")));
        for backend in ["raster", "trace", "embree"] {
            for kind in ["depth", "ids"] {
                assert!(
                    page.contains(&format!("img/{scene}/{backend}.{kind}.png")),
                    "{scene}: no {backend} {kind} picture"
                );
            }
        }
        for backend in ["trace", "embree"] {
            assert!(
                page.contains(&format!("img/{scene}/{backend}.id.heat.diff.png")),
                "{scene}/{backend}: no ID map"
            );
            assert!(
                page.contains(&format!("img/{scene}/{backend}.Z.heat.diff.png")),
                "{scene}/{backend}: no Z map"
            );
            assert!(
                page.contains(&format!(
                    "rendiff check scenes/{scene}.toml --only {backend} -o"
                )),
                "{scene}/{backend}: no verdict command"
            );
        }
        assert!(page.contains(&format!(
            "rendiff render scenes/{scene}.toml --renderer trace -o"
        )));
        assert!(page.contains("class=\"flip\""), "{scene}: no flip viewer");
        assert!(page.contains("aria-label=\"depth error histograms\""));
        assert!(page.contains("aria-label=\"render times\""));
        assert!(
            page.contains("Embree 3") || page.contains("embree"),
            "no Embree version"
        );
    }
    // The numbers behind a verdict are on the page (pixel_grid: Embree's tie rule, an expectation).
    let results: serde_json::Value =
        serde_json::from_str(&read(&run.join("results.json"))).unwrap();
    let e = results["results"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["scene"] == "pixel_grid" && e["backend"] == "embree" && e["buffer"] == "id")
        .unwrap();
    let edge = e["edge_mismatches"].as_u64().unwrap();
    assert!(edge > 0);
    let page = read(&report.join("pixel_grid.html"));
    assert!(
        page.contains(&format!("<td class=\"num\">{edge}</td>")),
        "edge count {edge} not shown"
    );
    assert!(
        page.contains("expectation"),
        "the expectation's reason is not shown"
    );
    assert_self_contained(&report);

    // `rendiff report` rewrites it in place, leaving no temporary folders.
    let out = rendiff().arg("report").arg(&run).output().unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(report.join("index.html").is_file());
    let stray: Vec<_> = std::fs::read_dir(&run)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with(".report"))
        .collect();
    assert!(stray.is_empty(), "temporary report folders left behind");
}

const HOSTILE_STEM: &str = "\"><svg onload=alert(1)><script>alert(2)<";

#[test]
fn names_from_a_hostile_scene_file_are_escaped_everywhere() {
    need_venv();
    let dir = tempfile::tempdir().unwrap();
    let scenes = dir.path().join("scenes");
    std::fs::create_dir_all(&scenes).unwrap();
    let scene = scenes.join(format!("{HOSTILE_STEM}.toml"));
    std::fs::write(
        &scene,
        r#"
name = "<script>alert('name')</script>"
description = "<img src=x onerror=alert('description')>"
requires = ["depth", "ids"]

[camera]
eye = [0.0, 0.0, 5.0]
look_at = [0.0, 0.0, 0.0]
vfov = 45.0
width = 32
height = 24

[[materials]]
name = "</td><script>alert('material')</script>"
albedo = [0.8, 0.2, 0.2]

[[objects]]
name = "<img src=x onerror=alert('object')>"
material = "</td><script>alert('material')</script>"
shape = { kind = "three_triangles" }
"#,
    )
    .unwrap();
    let run = dir.path().join("run");
    let out = rendiff()
        .arg("check")
        .arg(&scene)
        .args(["--only", "trace", "--quiet", "-o"])
        .arg(&run)
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let report = run.join("report");
    let pages: Vec<PathBuf> = files(&report)
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e == "html"))
        .collect();
    assert_eq!(pages.len(), 2, "index plus one scene page: {pages:?}");
    for p in files(&report) {
        let name = p
            .strip_prefix(&report)
            .unwrap()
            .to_string_lossy()
            .into_owned();
        assert!(
            name.bytes()
                .all(|b| b.is_ascii_alphanumeric() || b"._-/+".contains(&b)),
            "unsafe report file name {name:?}"
        );
    }
    let mut shown = String::new();
    for p in &pages {
        let html = read(p);
        for raw in ["<script>alert", "<svg onload", "<img src=x", "</td><script"] {
            assert!(!html.contains(raw), "{}: unescaped {raw:?}", p.display());
        }
        // Only the report's own inline script.
        assert_eq!(
            html.matches("<script").count(),
            1,
            "{}: extra script tags",
            p.display()
        );
        // No attribute was opened by a name: every `on...=` handler would have to sit inside a tag.
        for tag in html.split('<').skip(1) {
            let tag = tag.split('>').next().unwrap_or("");
            assert!(
                !tag.contains(" onload=") && !tag.contains(" onerror="),
                "{}: event handler in <{tag}>",
                p.display()
            );
        }
        shown.push_str(&html);
    }
    // The names are shown, escaped.
    assert!(
        shown.contains("&lt;script&gt;alert(&#39;name&#39;)&lt;/script&gt;"),
        "scene name not shown"
    );
    assert!(
        shown.contains("&lt;img src=x onerror=alert(&#39;object&#39;)&gt;"),
        "object name not shown"
    );
    assert!(
        shown.contains("&quot;&gt;&lt;svg onload=alert(1)&gt;"),
        "scene stem not shown"
    );
    assert_self_contained(&report);

    // The gate's markdown (a PR comment renders HTML) escapes them too.
    let baseline = dir.path().join("baseline.json");
    let out = rendiff()
        .arg("bless")
        .arg(&run)
        .arg("--baseline")
        .arg(&baseline)
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut results: serde_json::Value =
        serde_json::from_str(&read(&run.join("results.json"))).unwrap();
    for e in results["results"].as_array_mut().unwrap() {
        e["status"] = "fail".into();
        e["reason"] = "<script>alert('reason')</script>".into();
    }
    std::fs::write(run.join("results.json"), results.to_string()).unwrap();
    let out = rendiff()
        .arg("gate")
        .arg("--baseline")
        .arg(&baseline)
        .arg(&run)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let md = String::from_utf8_lossy(&out.stdout);
    assert!(md.contains("new failure"), "{md}");
    assert!(
        !md.contains("<script") && !md.contains("<svg"),
        "unescaped markup in the gate summary:\n{md}"
    );
}

// ---------------------------------------------------------------- synthetic runs (no Python needed)

fn write_exr(
    path: &Path,
    w: usize,
    h: usize,
    z: Vec<f32>,
    prim: Vec<u32>,
    rgb: Option<[Vec<f32>; 3]>,
) {
    use exr::prelude::*;
    let object: Vec<u32> = prim
        .iter()
        .map(|&p| if p == u32::MAX { p } else { 0 })
        .collect();
    let mut ch = vec![
        AnyChannel::new("Z", FlatSamples::F32(z)),
        AnyChannel::new("id.prim", FlatSamples::U32(prim)),
        AnyChannel::new("id.object", FlatSamples::U32(object)),
    ];
    if let Some([r, g, b]) = rgb {
        ch.push(AnyChannel::new("R", FlatSamples::F32(r)));
        ch.push(AnyChannel::new("G", FlatSamples::F32(g)));
        ch.push(AnyChannel::new("B", FlatSamples::F32(b)));
    }
    let layer = Layer::new(
        (w, h),
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(SmallVec::from_vec(ch)),
    );
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    Image::from_layer(layer).write().to_file(path).unwrap();
}

/// A run folder written by hand: a reference with radiance, a backend that
/// fails, one skipped, one that errored; no diff images from the harness.
fn synthetic_run(run: &Path) {
    let (w, h) = (8, 6);
    let n = w * h;
    let z: Vec<f32> = (0..n)
        .map(|i| {
            if i % 7 == 0 {
                f32::INFINITY
            } else {
                2.0 + i as f32 * 0.01
            }
        })
        .collect();
    let prim: Vec<u32> = (0..n)
        .map(|i| if i % 7 == 0 { u32::MAX } else { (i % 2) as u32 })
        .collect();
    let rgb = [vec![0.5; n], vec![0.1; n], vec![2.0; n]];
    write_exr(
        &run.join("scenes/syn/raster.exr"),
        w,
        h,
        z.clone(),
        prim.clone(),
        Some(rgb),
    );
    let mut z2 = z.clone();
    z2[1] += 0.25;
    let mut p2 = prim.clone();
    p2[2] = 1 - p2[2];
    write_exr(&run.join("scenes/syn/fake.exr"), w, h, z2, p2, None);
    let manifest = serde_json::json!({
        "format": "rendiff-manifest/1", "reference": "raster", "created_unix": 1_795_000_000u64,
        "rendiff_version": "0.1.0",
        "scenes": [{
            "scene": "syn", "scene_file": "scenes/syn.toml", "resolved": "scenes/syn/resolved", "requires": ["depth", "ids"],
            "renders": [
                {"backend": "raster", "status": "ok", "exr": "scenes/syn/raster.exr", "time_s": 0.01, "version": "rendiff 0.1.0",
                 "command": "rendiff render scenes/syn.toml --renderer raster -o RUN/scenes/syn/raster.exr", "buffers": ["Z", "id"], "info": {}},
                {"backend": "fake", "status": "ok", "exr": "scenes/syn/fake.exr", "time_s": 0.5, "version": "Fake 9.9",
                 "command": "fake --render", "buffers": ["Z", "id"], "info": {"seed": 7}},
                {"backend": "skippy", "status": "skipped", "reason": "missing features: ids"},
                {"backend": "broken", "status": "error", "message": "broken failed (exit 3): segfault", "time_s": 1.0, "command": "broken --go"},
                {"backend": "escaper", "status": "ok", "exr": "../../etc/passwd", "time_s": 0.1}
            ]
        }]
    });
    std::fs::write(
        run.join("manifest.json"),
        serde_json::to_string_pretty(&manifest).unwrap(),
    )
    .unwrap();
    let entry = |backend: &str,
                 buffer: &str,
                 status: &str,
                 reason: &str,
                 edge: i64,
                 interior: i64| {
        serde_json::json!({"scene": "syn", "backend": backend, "buffer": buffer, "status": status, "reason": reason,
            "pixels": n, "edge_mismatches": edge, "interior_mismatches": interior, "mask_mismatches": 0,
            "max_abs_error": 0.25, "mean_abs_error": 0.01, "max_rel_error": 0.1, "tolerance": "exact", "bound": null,
            "time_s": 0.5, "version": "Fake 9.9", "command": "fake --render", "images": {}})
    };
    let results = serde_json::json!({
        "format": "rendiff-results/1", "reference": "raster", "expectations": "tests/expectations.toml",
        "results": [
            entry("skippy", "id", "skipped", "missing features: ids", 0, 0),
            entry("fake", "id", "fail", "1 interior mismatch at (2,0)", 0, 1),
            entry("fake", "Z", "pass", "", 0, 0),
            entry("broken", "id", "error", "broken failed (exit 3): segfault", 0, 0),
        ]
    });
    std::fs::write(
        run.join("results.json"),
        serde_json::to_string_pretty(&results).unwrap(),
    )
    .unwrap();
}

#[test]
fn a_synthetic_run_shows_radiance_every_status_and_fallback_diff_maps() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    synthetic_run(&run);
    let out = rendiff().arg("report").arg(&run).output().unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report = run.join("report");
    let index = read(&report.join("index.html"));
    // Failures first: the fail and the error come before the skip.
    let (fail, error, skipped) = (
        index.find(">fail<").unwrap(),
        index.find(">error<").unwrap(),
        index.find(">skipped<").unwrap(),
    );
    assert!(
        fail < skipped && error < skipped,
        "failures are not listed first"
    );
    assert!(
        index.contains("missing features: ids"),
        "skip reason not shown"
    );
    let page = read(&report.join("syn.html"));
    assert!(page.contains("segfault"), "error message not shown");
    assert!(
        report.join("img/syn/raster.radiance.png").is_file(),
        "no radiance preview"
    );
    assert!(report.join("img/syn/fake.depth.png").is_file());
    assert!(
        report
            .join("img/syn/fake.id.unclassified.diff.png")
            .is_file(),
        "no fallback ID map"
    );
    assert!(
        report.join("img/syn/fake.Z.own.diff.png").is_file(),
        "no fallback Z map"
    );
    assert!(
        page.contains("leaves the run folder"),
        "a buffer path outside the run was not refused"
    );
    assert!(!report.join("img/syn/escaper.depth.png").exists());
    assert!(page.contains("Fake 9.9") && page.contains("fake --render"));
    // The radiance preview is sRGB of the clamped linear values: (0.5, 0.1, 2.0) -> (188, 89, 255).
    let img = image::open(report.join("img/syn/raster.radiance.png"))
        .unwrap()
        .to_rgb8();
    assert_eq!(img.get_pixel(1, 0).0, [188, 89, 255]);
    assert_self_contained(&report);

    // Without results.json (the comparison died) the renders are still reported.
    std::fs::remove_file(run.join("results.json")).unwrap();
    let out = rendiff().arg("report").arg(&run).output().unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let index = read(&report.join("index.html"));
    assert!(
        index.contains("No verdicts"),
        "missing results.json not explained"
    );
    assert!(report.join("img/syn/fake.depth.png").is_file());

    // Without manifest.json there is nothing to report: exit 2, one line naming the file.
    std::fs::remove_file(run.join("manifest.json")).unwrap();
    let out = rendiff().arg("report").arg(&run).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("manifest.json"));
}
