//! The HTML report (`rendiff report`, and the end of every `rendiff check`):
//! it lists every scene, shows every backend's pictures and verdicts with the
//! commands that reproduce them, stays inside its folder (relative links, no
//! network), survives runs without radiance, verdicts or renders, and escapes
//! every name that comes from a scene file.

mod common;

use common::cli::{bless_command, gate_command, need_venv, rendiff, small_check, succeeds};
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
    // The numbers behind a verdict are on the page (pixel_grid: Embree's edge mismatches).
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
    // Its reason (an expectation's, when one applies) and the comparison's
    // explanation of the mismatching pixels are on the page too.
    let reason = e["reason"].as_str().unwrap_or("");
    assert!(
        reason.is_empty() || page.contains(&rendiff::report::html::escape(reason)),
        "the verdict's reason {reason:?} is not shown"
    );
    if let Some(first) = e["explanations"].as_array().and_then(|a| a.first()) {
        let why = first["why"].as_str().unwrap();
        assert!(
            page.contains(&rendiff::report::html::escape(why)),
            "explanation {why:?} not shown"
        );
        assert!(page.contains("id=\"why-embree-id\""));
    }
    assert_self_contained(&report);

    // `rendiff report` rewrites it in place, leaving no temporary folders.
    report_of(&run);
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
    succeeds(
        rendiff()
            .arg("check")
            .arg(&scene)
            // Escaping is the point here, not cameras: no probe pages.
            .args(["--only", "trace", "--no-calibration", "--quiet", "-o"])
            .arg(&run),
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
    succeeds(&mut bless_command(&run, &baseline));
    let mut results: serde_json::Value =
        serde_json::from_str(&read(&run.join("results.json"))).unwrap();
    for e in results["results"].as_array_mut().unwrap() {
        e["status"] = "fail".into();
        e["reason"] = "<script>alert('reason')</script>".into();
    }
    std::fs::write(run.join("results.json"), results.to_string()).unwrap();
    let out = gate_command(&run, &baseline).output().unwrap();
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
    let report = report_of(&run);
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
    report_of(&run);
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

// ---------------------------------------------------------------- the verifier's fields (issue 11)

/// The synthetic run with what the verifier writes: class counts, explanations,
/// normals (N), camera probe entries, the top-level calibration, and a scene
/// that could not be loaded. `calibration: false` leaves the calibration out
/// (an older run).
fn verifier_run(run: &Path, calibration: bool) {
    synthetic_run(run);
    let path = run.join("results.json");
    let mut r: serde_json::Value = serde_json::from_str(&read(&path)).unwrap();
    for e in r["results"].as_array_mut().unwrap() {
        if e["backend"] == "fake" && e["buffer"] == "id" {
            e["edge_mismatches"] = 3.into();
            e["tie_mismatches"] = 1.into();
            e["crack_mismatches"] = 2.into();
            e["interior_mismatches"] = 1.into();
            e["explanations"] = serde_json::json!([
                {"class": "tie", "ref_prim": 0, "test_prim": 1, "pixels": 1, "example": [3, 4],
                 "why": "prims 0 and 1 are identical triangles: tie"},
                {"class": "interior", "ref_prim": 1, "test_prim": 0, "pixels": 1, "example": [2, 0],
                 "why": "<script>alert('why')</script> inside prim 1"},
                {"class": "crack", "ref_prim": 1, "test_prim": null, "pixels": 2, "example": [5, 1],
                 "why": "background seen on the edge of prims 0 and 1: crack"},
                "not an object: ignored"
            ]);
        }
    }
    let arr = r["results"].as_array_mut().unwrap();
    arr.push(serde_json::json!({"scene": "syn", "backend": "fake", "buffer": "N", "status": "pass", "reason": "",
        "compared_pixels": 40, "interior_mismatches": 0, "max_angle_rad": 0.0125, "tolerance": "1e-2 rad"}));
    arr.push(serde_json::json!({"scene": "syn", "backend": "fake", "buffer": "camera", "status": "pass", "reason": "",
        "offset_x_px": 0.0004, "offset_y_px": -0.0002, "scale_x": 1.000001, "scale_y": 0.999999,
        "rotation": 1e-7, "rms_px": 0.0031, "bound_px": 0.01}));
    arr.push(serde_json::json!({"scene": "zz_unloadable", "backend": "raster", "buffer": "scene", "status": "error",
        "reason": "cannot load scene: unknown shape kind \"blob\""}));
    if calibration {
        r["calibration"] = serde_json::json!({
            "fake": {"offset_x_px": 0.0004, "offset_y_px": -0.0002, "scale_x": 1.000001, "scale_y": 0.999999,
                     "rotation": 1e-7, "rms_px": 0.0031, "bound_px": 0.01, "status": "pass", "reason": ""},
            "<b>povray</b>": {"offset_x_px": 0.5, "offset_y_px": 0.5, "scale_x": 1.0, "scale_y": 1.0,
                     "rotation": 0.0, "rms_px": 0.71, "bound_px": 0.01, "status": "fail",
                     "reason": "pixel centers offset by (0.5, 0.5) px: exporter convention error"}
        });
    }
    std::fs::write(&path, serde_json::to_string_pretty(&r).unwrap()).unwrap();
}

/// The part of `html` from the `<h2 id="{id}">` heading to the next `<h2`.
fn section<'a>(html: &'a str, id: &str) -> &'a str {
    let start = html
        .find(&format!("<h2 id=\"{id}\">"))
        .unwrap_or_else(|| panic!("no section {id}"));
    let rest = &html[start..];
    let end = rest[4..].find("<h2").map_or(rest.len(), |i| i + 4);
    &rest[..end]
}

fn report_of(run: &Path) -> PathBuf {
    succeeds(rendiff().arg("report").arg(run));
    run.join("report")
}

/// The report of [`verifier_run`]'s run, in a folder that lives as long as
/// the returned guard.
fn verifier_report() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    verifier_run(&run, true);
    let report = report_of(&run);
    (dir, report)
}

#[test]
fn the_overview_shows_failures_apart_from_skips_class_counts_and_calibration() {
    let (_dir, report) = verifier_report();
    let index = read(&report.join("index.html"));

    // Needs attention: failures and errors only, the unloadable scene first.
    let attention = section(&index, "attention");
    let (load, fail, error) = (
        attention
            .find("cannot load scene: unknown shape kind")
            .unwrap(),
        attention.find("1 interior mismatch at (2,0)").unwrap(),
        attention.find("segfault").unwrap(),
    );
    assert!(load < fail && load < error, "scene load errors come first");
    assert!(
        !attention.contains(">skipped<") && !attention.contains("missing features: ids"),
        "skips are not failures: {attention}"
    );
    assert!(!attention.contains(">pass<"));
    // Skipped: its own section, with the reason.
    let skipped = section(&index, "skipped");
    assert!(skipped.contains(">skipped<") || skipped.contains("skippy"));
    assert!(skipped.contains("missing features: ids"), "{skipped}");
    assert!(index.find("id=\"attention\"").unwrap() < index.find("id=\"skipped\"").unwrap());

    // The matrix: edge/tie/crack/interior per entry, camera entries their rms.
    let matrix = section(&index, "matrix");
    assert!(matrix.contains(">3/1/2/1</span>"), "{matrix}");
    assert!(matrix.contains("title=\"3 edge, 1 tie, 2 crack, 1 interior\""));
    assert!(matrix.contains(">-/-/-/0</span>"), "N: interior only");
    assert!(matrix.contains("rms 0.003100 px"), "{matrix}");
    assert!(
        index.contains("zz_unloadable.html"),
        "the unloadable scene has a page"
    );

    // Camera calibration: every backend, its numbers, status and reason; names escaped.
    let cal = section(&index, "calibration");
    for needle in [
        "&lt;b&gt;povray&lt;/b&gt;",
        "<td class=\"num\">0.5000</td>",
        "<td class=\"num\">0.7100</td>",
        "<td class=\"num\">1.000001</td>",
        "<td class=\"num\">0.999999</td>",
        "<td class=\"num\">1.000e-7</td>",
        "pixel centers offset by (0.5, 0.5) px: exporter convention error",
        "offset x (px)",
        "rms (px)",
        "bound (px)",
        "syn.html#camera",
    ] {
        assert!(cal.contains(needle), "calibration lacks {needle:?}: {cal}");
    }
    assert!(!index.contains("<b>povray</b>"));
    assert!(cal.find(">fake<").is_some() && cal.contains(">fail<") && cal.contains(">pass<"));
    assert_self_contained(&report);
}

#[test]
fn scene_pages_explain_mismatches_normals_cameras_and_load_errors() {
    let (_dir, report) = verifier_report();
    let page = read(&report.join("syn.html"));

    let why = section(&page, "why");
    for needle in [
        "id=\"why-fake-id\"",
        "<span class=\"cls c-tie\">tie</span>",
        "<span class=\"cls c-crack\">crack</span>",
        "<span class=\"cls c-interior\">interior</span>",
        "prims 0 and 1 are identical triangles: tie",
        "background seen on the edge of prims 0 and 1: crack",
        "&lt;script&gt;alert(&#39;why&#39;)&lt;/script&gt; inside prim 1",
        "<td>(3, 4)</td>",
        "<td>(5, 1)</td>",
        "<td class=\"num\">2</td>",
    ] {
        assert!(why.contains(needle), "explanations lack {needle:?}: {why}");
    }
    assert_eq!(
        why.matches("<tr><td><span class=\"cls").count(),
        3,
        "the non-object is skipped"
    );
    assert!(!page.contains("<script>alert"), "unescaped why");

    // Verdicts: the four classes and the normals' largest angle.
    let verdicts = section(&page, "verdicts");
    assert!(verdicts.contains("<th>tie</th><th>crack</th>"));
    assert!(
        verdicts.contains("<td class=\"num\">3</td><td class=\"num\">1</td><td class=\"num\">2</td><td class=\"num\">1</td>"),
        "{verdicts}"
    );
    assert!(verdicts.contains("0.01250 rad (0.716°)"), "{verdicts}");
    // Camera probe numbers of this scene.
    let cam = section(&page, "camera");
    assert!(
        cam.contains("<td class=\"num\">0.003100</td>") && cam.contains("1.000001"),
        "{cam}"
    );

    // The scene that could not be loaded says so at the top of its page.
    let broken = read(&report.join("zz_unloadable.html"));
    assert!(
        broken.contains("This scene could not be loaded")
            && broken.contains("cannot load scene: unknown shape kind &quot;blob&quot;"),
        "{broken}"
    );
    assert_self_contained(&report);
}

#[test]
fn calibration_is_shown_when_everything_passes_and_absent_fields_are_not_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    verifier_run(&run, true);
    // Everything passes: no attention rows, the calibration table is still there.
    let path = run.join("results.json");
    let mut r: serde_json::Value = serde_json::from_str(&read(&path)).unwrap();
    r["results"]
        .as_array_mut()
        .unwrap()
        .retain(|e| e["status"] == "pass");
    r["calibration"]["<b>povray</b>"]["status"] = "pass".into();
    std::fs::write(&path, r.to_string()).unwrap();
    let report = report_of(&run);
    let index = read(&report.join("index.html"));
    // A render that failed is listed even without a verdict about it.
    let attention = section(&index, "attention");
    assert!(attention.contains("segfault") && attention.contains("<td>render</td>"));
    let mpath = run.join("manifest.json");
    let mut m: serde_json::Value = serde_json::from_str(&read(&mpath)).unwrap();
    m["scenes"][0]["renders"]
        .as_array_mut()
        .unwrap()
        .retain(|r| r["status"] == "ok");
    std::fs::write(&mpath, m.to_string()).unwrap();
    let report = report_of(&run);
    let index = read(&report.join("index.html"));
    assert!(section(&index, "attention").contains("Nothing failed"));
    assert!(section(&index, "calibration").contains("<table class=\"calibration\">"));
    assert!(section(&index, "skipped").contains("Nothing was skipped"));

    // An older run: no calibration, no class fields beyond edge/interior, no explanations.
    let old = dir.path().join("old");
    synthetic_run(&old);
    let report = report_of(&old);
    let index = read(&report.join("index.html"));
    assert!(section(&index, "calibration").contains("Not recorded"));
    assert!(section(&index, "matrix").contains(">0/-/-/1</span>"));
    let page = read(&report.join("syn.html"));
    assert!(section(&page, "why").contains("No explanations recorded"));
    assert!(!page.contains("id=\"camera\""));
}
