//! Smoke tests of `rendiff bench`: each subcommand runs on its tiny `--quick`
//! configuration and writes well-formed output (JSON, an HTML page with an
//! inline SVG, standalone SVG files). Speed is never asserted here: the
//! numbers of a quick run mean nothing; only the shape of the output does.

use rendiff_bench::pareto;
use serde_json::Value;
use std::path::Path;
use std::process::Command;

/// Runs `rendiff-bench <what> --quick -o DIR` (what `rendiff bench` runs) from the
/// repository root and returns the JSON record.
fn bench(what: &str, dir: &Path) -> Value {
    bench_with(what, dir, &[])
}

/// [`bench`] with extra arguments after `--quick`.
fn bench_with(what: &str, dir: &Path, extra: &[&str]) -> Value {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let out = Command::new(env!("CARGO_BIN_EXE_rendiff-bench"))
        .current_dir(root)
        .args([what, "--quick"])
        .args(extra)
        .arg("-o")
        .arg(dir)
        .output()
        .expect("rendiff runs");
    assert!(
        out.status.success(),
        "bench {what} failed: {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let json = std::fs::read_to_string(dir.join(format!("{what}.json"))).expect("JSON written");
    let record: Value = serde_json::from_str(&json).expect("well-formed JSON");
    assert_eq!(record["benchmark"], what);
    let env = &record["environment"];
    assert!(env["cpus"].as_u64().is_some_and(|n| n >= 1));
    assert!(env.get("load_average_before").is_some() && env.get("load_average_after").is_some());
    assert!(
        env.get("cpu_counters_at_start").is_none(),
        "the start counters are consumed, not left in the record"
    );
    let cpu = &env["cpu_during_run"];
    if std::path::Path::new("/proc/stat").exists() {
        assert!(cpu["summary"].is_string(), "{what}: {cpu}");
    }
    // A run within one tick of the kernel's counters has no shares.
    if cpu["cpu_seconds"].as_f64().is_some_and(|s| s > 0.0) {
        let share = |k: &str| cpu[k].as_f64().unwrap_or_else(|| panic!("{what}: no {k}"));
        let parts = [
            "this_benchmark",
            "other_processes",
            "hypervisor_steal",
            "idle",
        ];
        assert!(parts.iter().all(|k| share(k) >= 0.0), "{what}: {cpu}");
        assert!(
            share("this_benchmark") > 0.0,
            "{what}: the benchmark's own time: {cpu}"
        );
        assert!(cpu["summary"]
            .as_str()
            .is_some_and(|s| s.contains("other processes")));
    }
    let html = std::fs::read_to_string(dir.join(format!("{what}.html"))).expect("HTML written");
    assert!(
        html.starts_with("<!DOCTYPE html>") && html.contains("<svg"),
        "{what}.html has no plot"
    );
    if cpu["cpu_seconds"].as_f64().is_some_and(|s| s > 0.0) {
        assert!(
            html.contains("other processes"),
            "{what}.html shows who used the CPUs"
        );
    }
    let svgs: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.extension().is_some_and(|x| x == "svg")
                && p.file_name()
                    .unwrap()
                    .to_string_lossy()
                    .starts_with(&format!("{what}-"))
        })
        .collect();
    assert!(!svgs.is_empty(), "no standalone SVG for {what}");
    for p in svgs {
        let s = std::fs::read_to_string(&p).unwrap();
        assert!(
            s.starts_with("<?xml")
                && s.contains("xmlns=\"http://www.w3.org/2000/svg\"")
                && s.trim_end().ends_with("</svg>"),
            "{}: not a standalone SVG",
            p.display()
        );
    }
    assert!(dir.join("index.html").exists());
    // The report's styles, inlined: no sheet to copy beside the pages.
    assert!(
        html.contains("<style>body{"),
        "{what}.html: no inline styles"
    );
    assert!(
        !dir.join("style.css").exists(),
        "a style sheet beside the pages"
    );
    record
}

#[test]
fn knobs_writes_groups_with_a_non_dominated_pareto_front() {
    let dir = tempfile::tempdir().unwrap();
    let record = bench("knobs", dir.path());
    let groups = record["groups"].as_array().expect("groups");
    assert!(groups.len() >= 2, "visibility and radiance groups");
    for g in groups {
        let points = g["points"].as_array().expect("points");
        assert!(!points.is_empty(), "{}: no points", g["id"]);
        let xy: Vec<(f64, f64)> = points
            .iter()
            .map(|p| {
                let t = p["time_s"].as_f64().expect("time_s");
                assert!(t > 0.0 && t.is_finite());
                (t, p["error"].as_f64().unwrap_or(f64::NAN))
            })
            .collect();
        // Recompute the front from the numbers alone; it must match the marks.
        let front = pareto::front(&xy);
        assert!(!front.is_empty(), "{}: empty Pareto front", g["id"]);
        for (i, p) in points.iter().enumerate() {
            assert_eq!(
                p["pareto"].as_bool(),
                Some(front.contains(&i)),
                "{}: point {i}",
                g["id"]
            );
        }
        for &i in &front {
            assert!(
                !xy.iter().any(|&q| pareto::dominates(q, xy[i])),
                "{}: Pareto point {i} is dominated",
                g["id"]
            );
        }
    }
    // Raster and trace are the same computation: the record says so.
    assert_eq!(groups[0]["facts"]["raster_equals_trace_every_bvh"], true);
    // Direct lighting: the core's supersampling converges to its own K×K reference,
    // and the external renderers' settings are recorded as not measured, with why.
    let direct = groups
        .iter()
        .find(|g| {
            g["id"]
                .as_str()
                .is_some_and(|id| id.starts_with("radiance-direct-"))
        })
        .expect("a direct-lighting group");
    let errors: Vec<f64> = direct["points"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| p["knob"] == "core supersampling")
        .filter_map(|p| p["error"].as_f64())
        .collect();
    assert!(
        errors.len() >= 2 && errors.windows(2).all(|w| w[1] < w[0]) && errors[0] > 0.0,
        "{errors:?}"
    );
    assert!(direct["facts"]["reference_floor_rmse"].as_f64().is_some());
    assert!(direct["skipped"][0]["reason"]
        .as_str()
        .is_some_and(|r| r.contains("external renderers off")));
}

#[test]
fn peers_writes_throughput_ratios() {
    let dir = tempfile::tempdir().unwrap();
    // A small real scan stands in for the default 100k-triangle one.
    let record = bench_with(
        "peers",
        dir.path(),
        &[
            "--scanned-scene",
            "scenes/corpus/demosthenes_scan.toml@48x36",
            // Three rounds, so a median differs from a mean or a first round.
            "--runs",
            "3",
        ],
    );
    let scanned = &record["scanned_mesh"];
    assert_eq!(scanned["triangles"], 16_719, "{scanned}");
    let srows = scanned["trace_throughput"]
        .as_array()
        .expect("scanned rows");
    assert_eq!(srows[0]["core_trace"]["raster_equals_trace"], true);
    assert!(srows[0]["core_trace"]["mrays_per_s"]
        .as_f64()
        .is_some_and(|x| x > 0.0));
    assert_eq!(
        record["goals"]["core_trace_vs_embree_best_scanned_mesh"]
            .as_array()
            .map(Vec::len),
        Some(srows.len())
    );
    let rows = record["trace_throughput"].as_array().expect("rows");
    assert!(!rows.is_empty());
    assert!(rows[0]["core_trace"]["mrays_per_s"]
        .as_f64()
        .is_some_and(|x| x > 0.0));
    // Mrays/s come from the queries alone; the whole render is recorded beside them.
    assert!(rows[0]["core_trace"]["queries"]["median_s"]
        .as_f64()
        .is_some());
    assert!(rows[0]["core_trace"]["timing"]["trace"]["median_s"]
        .as_f64()
        .is_some());
    assert_eq!(rows[0]["core_trace"]["raster_equals_trace"], true);
    assert_eq!(
        rows[0]["core_trace_single_rays"]["raster_equals_trace"],
        true
    );
    // The raster-vs-trace passes in alternating rounds: the headline is the
    // median of the per-round trace / raster time ratios.
    let rt = &rows[0]["raster_vs_trace_passes"];
    let (r_s, t_s) = (&rt["raster_keys_s"], &rt["trace_keys_s"]);
    let mut speedups: Vec<f64> = (0..rt["rounds"].as_u64().unwrap() as usize)
        .map(|i| t_s[i].as_f64().unwrap() / r_s[i].as_f64().unwrap())
        .collect();
    assert!(!speedups.is_empty());
    speedups.sort_by(f64::total_cmp);
    let n = speedups.len();
    let median = (speedups[(n - 1) / 2] + speedups[n / 2]) / 2.0;
    // Not bit for bit: serde_json's parser (without its float_roundtrip
    // feature) may read a number 1 ulp off the one written, so the ratio of
    // two read-back times can differ by a few ulps (~1e-15) from the one the
    // bench computed; 1e-12 relative covers that and nothing a wrong median
    // (another round's ratio) could hide in.
    let headline = rt["raster_speedup_over_trace"].as_f64().unwrap();
    assert!((headline - median).abs() <= 1e-12 * median, "{rt}");
    assert_eq!(
        record["goals"]["core_raster_vs_trace_passes"][0]["raster_speedup_over_trace"],
        rt["raster_speedup_over_trace"]
    );
    assert!(record.get("goals").is_some());
    // With Embree: every configuration kept, the fastest named, the core's ratio against it.
    let embree = rows[0]["embree"].as_object().expect("embree rows");
    if !embree.is_empty() {
        assert_eq!(
            embree.len(),
            48,
            "6 query paths x 2 context flags x 2 scene flags x 2 build qualities"
        );
        for key in ["embree single", "embree packet8", "embree_robust single"] {
            assert!(embree.contains_key(key), "{key}: earlier records' keys");
        }
        for (k, v) in embree {
            assert_ne!(v["same_keys_as_embree_single"], false, "{k}");
        }
        // The native driver's rows: every entry point x context flag x
        // build quality, each reproducing the binding's single-ray keys.
        let native = rows[0]["embree_native"]["rows"]
            .as_object()
            .expect("native driver rows beside the binding's");
        assert_eq!(native.len(), 48, "8 entry points x 2 flags x 3 qualities");
        for (k, v) in native {
            assert_eq!(v["same_keys_as_embree_single"], true, "{k}");
            assert_eq!(v["hits_in_front_of_near"], 0, "{k}");
        }
        // The best is the faster (by the sweep) of the binding's fastest row
        // and the driver's runoff winner (its best, which need not be the
        // sweep's fastest native row).
        let best = rows[0]["embree_best"]["name"].as_str().expect("best named");
        let mrays = |v: &Value| v["mrays_per_s"].as_f64().unwrap();
        let binding_fastest = embree.values().map(mrays).fold(0.0, f64::max);
        let winner = rows[0]["embree_native"]["runoff"]["winner"]
            .as_str()
            .expect("runoff winner");
        let want = if mrays(&native[winner]) >= binding_fastest {
            &native[winner]
        } else {
            embree
                .values()
                .find(|v| mrays(v) == binding_fastest)
                .unwrap()
        };
        let best_row = embree
            .get(best)
            .or_else(|| native.get(best))
            .expect("best row");
        assert_eq!(best_row, want, "{best}");
        assert_eq!(rows[0]["embree_best"]["source"], best_row["source"]);
        // The check of the binding against the driver: paired rounds, their
        // median, an interval around it, and the 5% verdict from them.
        let c = &rows[0]["embree_check"];
        let per_round: Vec<f64> = c["binding_over_native_per_round"]
            .as_array()
            .expect("check rounds")
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(per_round.len(), 3, "--quick: 3 rounds");
        let ratio = c["binding_over_native"].as_f64().unwrap();
        let [lo, hi] = [0, 1].map(|i| c["binding_over_native_interval_95"][i].as_f64().unwrap());
        assert!(lo <= ratio && ratio <= hi, "{c}");
        assert_eq!(c["within_5_percent"], (ratio - 1.0).abs() <= 0.05, "{c}");
        assert_eq!(rows[0]["ratios"]["embree_best"], best);
        assert!(rows[0]["ratios"]["core_over_embree_best"]
            .as_f64()
            .is_some_and(|x| x > 0.0));
        // The headline ratio comes from alternating rounds of the core and
        // that configuration, recomputed here from the recorded times.
        let b = &rows[0]["embree_best"];
        assert_eq!(b["core_over_embree_best_basis"], "paired rounds", "{b}");
        let p = &b["paired"];
        let series = |k: &str| -> Vec<f64> {
            p[k].as_array()
                .expect("series")
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect()
        };
        let (core_s, embree_s) = (series("core_s"), series("embree_trace_s"));
        assert_eq!(core_s.len(), p["rounds"].as_u64().unwrap() as usize);
        assert_eq!(embree_s.len(), core_s.len());
        let rays = |k: &str| p[k].as_f64().expect("ray count");
        assert_eq!(
            rays("core_rays"),
            f64::from(64u32 * 48),
            "--quick: icosphere at 64x48"
        );
        let mut ratios: Vec<f64> = core_s
            .iter()
            .zip(&embree_s)
            .map(|(c, e)| (rays("core_rays") / c) / (rays("embree_rays") / e))
            .collect();
        ratios.sort_by(f64::total_cmp);
        let n = ratios.len();
        let median = if n % 2 == 1 {
            ratios[n / 2]
        } else {
            (ratios[n / 2 - 1] + ratios[n / 2]) / 2.0
        };
        // Three rounds under --quick, and a bootstrap interval around their median.
        assert_eq!(core_s.len(), 3, "--quick: 3 paired rounds");
        let [lo, hi] = [0, 1].map(|i| b["core_over_embree_best_interval_95"][i].as_f64().unwrap());
        assert!(lo <= median && median <= hi, "{b}");
        // Within a few ulps, as for the raster-vs-trace median above.
        let headline = b["core_over_embree_best"].as_f64().unwrap();
        assert!(
            (headline - median).abs() <= 1e-12 * median,
            "{headline} vs {median}"
        );
        assert!(rows[0]["ratios"]["core_trace_over_embree_single"]
            .as_f64()
            .is_some());
        assert!(record["goals"]["core_trace_vs_embree_best"].is_array());
        // The driver's best is the runoff's least median among the sweep's
        // fastest rows, and the check and the per-frame table use it.
        let runoff = &rows[0]["embree_native"]["runoff"];
        let cands = runoff["candidates"].as_array().expect("runoff candidates");
        assert!(!cands.is_empty() && cands.len() <= 6, "{runoff}");
        let least = cands
            .iter()
            .min_by(|a, b| {
                let m = |v: &Value| v["trace_s_median"].as_f64().unwrap();
                m(a).total_cmp(&m(b))
            })
            .unwrap();
        assert_eq!(runoff["winner"], least["name"], "{runoff}");
        assert!(cands
            .iter()
            .all(|c| c["trace_s"].as_array().unwrap().len() == 3));
        assert_eq!(rows[0]["embree_check"]["native_best"], runoff["winner"]);
        assert_eq!(rows[0]["per_frame"]["embree"]["config"], runoff["winner"]);
        // The per-frame table: the core's new camera counted, per round.
        let f = &rows[0]["per_frame"];
        let at = |v: &Value, k: &str| -> Vec<f64> {
            v[k].as_array()
                .expect(k)
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        };
        let (cam, tr, em) = (
            at(&f["core"], "new_camera_s"),
            at(&f["core"], "trace_s"),
            at(&f["embree"], "trace_s"),
        );
        assert_eq!((cam.len(), tr.len(), em.len()), (3, 3, 3), "{f}");
        assert!(
            cam.iter().all(|&c| c > 0.0),
            "a new camera costs the core something"
        );
        assert_eq!(f["embree"]["new_camera_s_median"], 0.0);
        // Embree makes its rays inside its timed frame, as the core does;
        // its trace alone, on prepared rays, is timed beside in the rounds.
        assert!(
            f["embree"]["rays"]
                .as_str()
                .unwrap()
                .starts_with("made inside"),
            "{f}"
        );
        assert_eq!(at(&f["embree"], "trace_alone_s").len(), 3, "{f}");
        let counted = at(&f["core_over_embree_new_camera_counted"], "per_round");
        for i in 0..3 {
            let want = em[i] / (cam[i] + tr[i]);
            assert!((counted[i] - want).abs() <= 1e-12 * want, "{f}");
        }
        // Time to first image: Embree's row and every other row's ratio to it.
        let t = &rows[0]["time_to_first_image"];
        let trows = t["rows"].as_array().expect("first-image rows");
        let embree_row = trows
            .iter()
            .find(|r| Some(r["name"].as_str().unwrap()) == t["embree"].as_str())
            .expect("Embree's first-image row");
        let e = at(embree_row, "seconds");
        // Its rays are made inside its trace, not prepared apart.
        let parts = &embree_row["parts_median_s"];
        assert!(
            parts["rays_and_trace_s"].as_f64().is_some_and(|x| x > 0.0)
                && parts["rays_s"].is_null(),
            "{embree_row}"
        );
        for r in trows.iter().filter(|r| r["name"] != embree_row["name"]) {
            let s = at(r, "seconds");
            let per = at(&r["over_embree"], "per_round");
            for i in 0..3 {
                assert!((per[i] - e[i] / s[i]).abs() <= 1e-12 * per[i], "{r}");
            }
            assert!(r["over_embree"]["interval_95"].is_array(), "{r}");
        }
    }
    // Both tables are there with or without Embree, and the goals name them.
    let t = &rows[0]["time_to_first_image"];
    let names: Vec<&str> = t["rows"]
        .as_array()
        .expect("first-image rows")
        .iter()
        .map(|r| r["name"].as_str().unwrap())
        .collect();
    for want in [
        "core raster",
        "core trace (linear BVH)",
        "core trace (fastest BVH)",
        "core trace (fast BVH)",
        "core trace (medium BVH)",
        "core trace (slow BVH)",
    ] {
        assert!(names.contains(&want), "{want}: {names:?}");
    }
    let medium = &t["rows"][names
        .iter()
        .position(|&n| n == "core trace (medium BVH)")
        .unwrap()];
    assert!(
        medium["parts_median_s"]["tree_s"]
            .as_f64()
            .is_some_and(|x| x > 0.0),
        "{medium}"
    );
    assert!(
        medium["parts_median_s"]["camera_setup_s"]
            .as_f64()
            .is_some_and(|x| x > 0.0),
        "{medium}"
    );
    assert!(
        names.contains(&t["cost_model_pick"].as_str().unwrap()),
        "{t}"
    );
    // The goal's row times `render --renderer core` whole: the decision is
    // one of its parts, and it ran the loop the model names.
    let pick = &t["rows"][names
        .iter()
        .position(|&n| n == t["cost_model_pick"])
        .unwrap()];
    assert!(
        pick["parts_median_s"]["decide_s"]
            .as_f64()
            .is_some_and(|x| x > 0.0 && x < pick["median_s"].as_f64().unwrap()),
        "{pick}"
    );
    let ran = pick["parts_s"]["loop"][0].as_str().unwrap();
    assert_eq!(
        format!("core {ran}"),
        t["cost_model_loop"]
            .as_str()
            .unwrap()
            .split(" (")
            .next()
            .unwrap(),
        "{t}"
    );
    let goals = record["goals"]["issue_39"]
        .as_array()
        .expect("issue-39 goals");
    assert!(goals.iter().any(|g| g["table"] == "per frame"));
    assert!(goals.iter().any(|g| g["table"] == "time to first image"));
    for g in goals {
        let verdict = g["verdict"].as_str().unwrap();
        let met = g["median"]
            .as_f64()
            .map(|m| m >= g["target"].as_f64().unwrap());
        assert_eq!(
            verdict,
            match met {
                Some(true) => "met",
                Some(false) => "not met",
                None => "not measured",
            },
            "{g}"
        );
    }
    let two = &record["two_screen_filling_triangles"][0];
    assert!(two["raster_over_trace"]["median"].as_f64().is_some());
    // The 10x goal is the visibility passes' ratio (the README's, `bench
    // crossover`'s), not the first image's, and it carries that median.
    let pass = two["pass"]["raster_over_trace"]["median"].as_f64().unwrap();
    let g = goals
        .iter()
        .find(|g| g["table"] == "visibility pass")
        .expect("the two-triangle goal");
    assert_eq!(g["median"].as_f64(), Some(pass), "{g}");
    assert_eq!(g["target"].as_f64(), Some(10.0), "{g}");
    assert_eq!(
        two["pass"]["raster_keys_s"].as_array().map(Vec::len),
        two["raster_s"].as_array().map(Vec::len)
    );
}

#[test]
fn crossover_writes_rows_with_operation_counts() {
    let dir = tempfile::tempdir().unwrap();
    let record = bench("crossover", dir.path());
    let rows = record["rows"].as_array().expect("rows");
    assert!(rows.len() >= 2);
    for r in rows {
        assert!(r["raster_counters"]["triangle_setups"].as_u64().is_some());
        assert!(r["trace_counters"]["bvh_nodes_visited"].as_u64().is_some());
        // The two passes timed again in alternation, with their speed-up.
        assert!(r["paired"]["rounds"].as_u64().is_some_and(|n| n >= 1));
        assert!(r["raster_speedup_paired"].as_f64().is_some_and(|x| x > 0.0));
    }
    assert!(record["crossover_triangles"]["raster_vs_trace_paired"].is_array());
    assert_eq!(record["raster_equals_trace_everywhere"], true);
    // The corpus is measured in two sweeps: each verdict carries the
    // second's faster loop and whether the two agree, and the summary
    // counts the decided rows.
    let corpus = record["which_loop"]["corpus"].as_array().expect("corpus");
    assert!(!corpus.is_empty());
    for r in corpus {
        for budget in ["one_frame", "bvh_shared"] {
            let v = &r[budget];
            let agree = v["reproducible"].as_bool().expect("reproducible");
            assert_eq!(agree, v["faster"] == v["second_sweep"]["faster"], "{v}");
        }
    }
    let s = &record["which_loop"]["summary"]["one_frame"];
    assert_eq!(
        s["decided"]["of"].as_u64().unwrap() + s["undecided"].as_u64().unwrap(),
        s["of"].as_u64().unwrap(),
        "{s}"
    );
}

#[test]
fn stability_writes_a_break_table() {
    let dir = tempfile::tempdir().unwrap();
    let record = bench("stability", dir.path());
    // Without the Python harness the check cannot compare; the record then says why.
    if record.get("error").is_none() {
        let rows = record["breaks"].as_array().expect("breaks");
        assert!(!rows.is_empty());
        assert!(rows
            .iter()
            .all(|r| r["family"].is_string() && r["backend"].is_string()));
        // The exact-truth families judge the raster reference too.
        for fam in ["pixel centers, offset", "coplanar", "z-fighting"] {
            assert!(
                rows.iter().any(|r| r["family"] == fam
                    && r["backend"] == "raster"
                    && r["values_run"] == 2),
                "{fam}: no raster row"
            );
        }
        // Peak memory is measured per renderer, each in its own process.
        let mem = record["memory"]["rows"].as_array().expect("memory rows");
        for b in ["raster", "trace"] {
            let r = mem
                .iter()
                .find(|r| r["backend"] == b)
                .unwrap_or_else(|| panic!("no memory row for {b}"));
            assert_eq!(r["status"], "ok", "{b}: {r}");
            let rss = r["max_rss_bytes"].as_u64().expect("max_rss_bytes");
            assert!(rss > 1 << 20, "{b}: peak {rss} bytes");
            assert!(r["bytes_per_triangle"].as_f64().is_some_and(|x| x > 0.0));
        }
    }
}

#[test]
fn variance_writes_calibration_split_and_the_quick_tests_power() {
    let dir = tempfile::tempdir().unwrap();
    let record = bench("variance", dir.path());
    let rows = record["settings"].as_array().expect("settings");
    assert!(!rows.is_empty());
    for r in rows {
        let c = &r["calibration"];
        for k in ["pooled", "balanced"] {
            let ci = &c[k]["ci95"];
            assert!(
                ci[0].as_f64().unwrap() <= c[k]["ratio"].as_f64().unwrap()
                    && c[k]["ratio"].as_f64().unwrap() <= ci[1].as_f64().unwrap(),
                "{k}: the interval holds the estimate"
            );
        }
        let s = &r["split"];
        assert!(s["rmse_single_render"].as_f64().is_some_and(|x| x > 0.0));
        assert!(s["bias2"]["mean"].as_f64().is_some_and(f64::is_finite));
    }
    // The injected halving and doubling are far outside the test's threshold.
    let power = record["quick_test"]["power"].as_array().expect("power");
    assert_eq!(power.len(), 2);
    assert!(power.iter().all(|p| p["rejected"] == true));
}

#[test]
fn scale_times_the_main_job_and_its_shards() {
    let dir = tempfile::tempdir().unwrap();
    let record = bench("scale", dir.path());
    let configs = record["configurations"].as_array().unwrap();
    let names: Vec<&str> = configs
        .iter()
        .map(|c| c["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        ["process_per_render_sequential", "default", "no_wait_slots"]
    );
    for c in configs {
        assert!(c["median_s"].as_f64().is_some_and(|t| t > 0.0), "{c}");
    }
    assert!(record["speedup_default_over_sequential"].as_f64().is_some());
    assert!(record["speedup_default_over_no_wait_slots"]
        .as_f64()
        .is_some());
    let shards = record["shards"].as_array().unwrap();
    assert_eq!(shards[0]["shards"], 2);
    assert_eq!(shards[0]["shard_s"].as_array().unwrap().len(), 2);
    // Per scene and renderer, from the default run's manifest.
    let per = record["per_scene_s"].as_object().unwrap();
    assert!(
        per["three_triangles"]["povray"].as_f64().is_some(),
        "{per:?}"
    );
}

/// `bench fuzz --quick`: a few scenes through the tracer, once through all
/// the backends asked for and once through each; the start-up probe; no
/// planted renderer.
#[test]
fn fuzz_records_scenes_a_minute_and_startup_shares() {
    let dir = tempfile::tempdir().unwrap();
    let record = bench("fuzz", dir.path());
    assert_eq!(
        (record["scenes"].as_u64(), record["runs"].as_u64()),
        (Some(4), Some(1))
    );
    assert_eq!(record["backends"], serde_json::json!(["trace"]));
    let configs = record["configurations"].as_array().unwrap();
    let names: Vec<&str> = configs
        .iter()
        .map(|c| c["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["all", "trace"]);
    for c in configs {
        assert_eq!(c["runs_s"].as_array().unwrap().len(), 1, "{c}");
        assert!(
            c["scenes_per_minute"]["median"]
                .as_f64()
                .is_some_and(|r| r > 0.0),
            "{c}"
        );
        // Every scene rendered by the reference and the tracer.
        assert_eq!(c["render_s"]["trace"]["renders"], 4, "{c}");
        assert_eq!(c["render_s"]["raster"]["renders"], 4, "{c}");
    }
    let start = &record["startup"]["per_backend"]["trace"];
    assert!(start["startup_share"].as_f64().is_some(), "{start}");
    assert!(record["goal_met"].is_boolean());
    assert!(record["reduction"]["planted"]
        .as_array()
        .unwrap()
        .is_empty());
}

/// Counts and sizes a benchmark cannot honour are refused before anything
/// runs: exit code 2, an error naming the option, and no output folder.
/// (`--runs 0` and `--threads 0` used to be raised to 1 silently, `--size
/// 20000` and `--nx 100000` aborted on an allocation, and a huge
/// `--timeout` panicked.) Run without `--quick`, whose fixed sizes would
/// hide the options.
#[test]
fn impossible_options_are_refused_before_any_work() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let cases: &[(&[&str], &str)] = &[
        (&["crossover", "--runs", "0"], "--runs"),
        (&["crossover", "--runs", "100000000000000"], "--runs"),
        (&["crossover", "--threads", "0"], "--threads"),
        (&["crossover", "--nx", "0,1"], "--nx 0"),
        (&["crossover", "--nx", "1,100000"], "20000000000 triangles"),
        (&["crossover", "--size", "0"], "at least 1x1"),
        (&["crossover", "--size", "20000"], "per side"),
        (&["peers", "--threads", "1,0"], "--threads"),
        (&["peers", "--timeout", "0"], "--timeout"),
        (&["peers", "--timeout", "18446744073709551615"], "--timeout"),
        (&["peers", "--mitsuba-spp", "0"], "--mitsuba-spp"),
        (&["knobs", "--spp", "1,0"], "--spp"),
        (&["knobs", "--scales", "0.5,nan"], "--scales"),
        (&["knobs", "--supersample", "4096"], "--supersample"),
        (
            &[
                "knobs",
                "--scene",
                "scenes/icosphere.toml@64x48",
                "--scales",
                "1e9",
            ],
            "per side",
        ),
        (
            &[
                "knobs",
                "--scene",
                "scenes/icosphere.toml@64x48",
                "--scales",
                "1e-9",
            ],
            "at least 1x1",
        ),
        (
            &["scenes/icosphere.toml", "--size", "16384x16384"],
            "Mpixel",
        ),
        (&["scale", "--shards", "0"], "--shards"),
        (&["stability", "--only", "trace,bogus"], "--only bogus"),
        (&["variance", "--threads", "100000"], "--threads"),
        (&["fuzz", "--count", "0"], "--count"),
        (&["fuzz", "--jobs", "0"], "--jobs"),
        (&["--runs", "0"], "--runs"),
    ];
    for (args, names) in cases {
        let dir = tempfile::tempdir().unwrap();
        let out_dir = dir.path().join("out");
        let out = Command::new(env!("CARGO_BIN_EXE_rendiff-bench"))
            .current_dir(&root)
            .args(*args)
            .arg("-o")
            .arg(&out_dir)
            .output()
            .expect("rendiff-bench runs");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        let first = err.lines().next().unwrap_or_default();
        assert!(
            first.starts_with("error: ") && first.contains(names),
            "{args:?}: {err}"
        );
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        assert!(!out_dir.exists(), "{args:?} wrote {}", out_dir.display());
        // Refused before the first step: no progress line, only the error
        // (and clap's pointer to --help).
        for line in err.lines().skip(1).filter(|l| !l.trim().is_empty()) {
            assert!(line.starts_with("For more information"), "{args:?}: {err}");
        }
    }
}
