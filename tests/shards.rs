//! `check --shard K/N` on two machines (here: one after the other) and
//! `rendiff merge` give the verdicts of one `check` over all scenes.

use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

const SCENES: [&str; 3] = [
    "scenes/three_triangles.toml",
    "scenes/icosphere.toml",
    "scenes/pixel_grid.toml",
];

fn rendiff(args: &[&str], extra: &[&Path]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(args)
        .args(extra)
        .output()
        .unwrap()
}

/// Verdicts by key, without what differs between any two runs (wall times,
/// the run folder named in commands).
fn verdicts(run: &Path) -> BTreeMap<String, Value> {
    let r: Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("results.json")).unwrap()).unwrap();
    r["results"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| {
            let mut e = e.clone();
            let o = e.as_object_mut().unwrap();
            o.remove("time_s");
            o.remove("command");
            let key = format!("{}::{}::{}", o["scene"], o["backend"], o["buffer"]);
            (key, e)
        })
        .collect()
}

#[test]
fn merged_shards_give_the_verdicts_of_one_run() {
    let t = tempfile::tempdir().unwrap();
    let common = ["--only", "trace,embree", "--quiet", "-o"];
    let whole = t.path().join("whole");
    let mut args = vec!["check"];
    args.extend(SCENES);
    args.extend(common);
    let o = rendiff(&args, &[&whole]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut shard_runs = Vec::new();
    for k in ["1/2", "2/2"] {
        let run = t.path().join(format!("shard{}", &k[..1]));
        let mut args = vec!["check"];
        args.extend(SCENES);
        args.extend(["--shard", k]);
        args.extend(common);
        let o = rendiff(&args, &[&run]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        shard_runs.push(run);
    }
    let merged = t.path().join("merged");
    let mut extra: Vec<&Path> = shard_runs.iter().map(|p| p.as_path()).collect();
    extra.push(Path::new("-o"));
    extra.push(&merged);
    let o = rendiff(&["merge", "--quiet"], &extra);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (a, b) = (verdicts(&whole), verdicts(&merged));
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (k, v) in &a {
        assert_eq!(v, &b[k], "{k}");
    }
    // Each shard ran only its share (plus the probes every shard renders).
    let shard_scenes = |run: &Path| -> Vec<String> {
        let m: Value =
            serde_json::from_str(&std::fs::read_to_string(run.join("manifest.json")).unwrap())
                .unwrap();
        m["scenes"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|s| s["role"].as_str().unwrap_or("").is_empty())
            .map(|s| s["scene"].as_str().unwrap().to_string())
            .collect()
    };
    let (one, two) = (shard_scenes(&shard_runs[0]), shard_scenes(&shard_runs[1]));
    assert_eq!(one.len() + two.len(), SCENES.len());
    assert!(one.iter().all(|s| !two.contains(s)));
    // The merged run is a finished run: report (like gate and bless) reads it.
    let g = rendiff(&["report"], &[&merged]);
    assert!(g.status.success(), "{}", String::from_utf8_lossy(&g.stderr));
    // The same shard twice is refused.
    let dup = t.path().join("dup");
    let o = rendiff(
        &["merge", "--quiet"],
        &[&shard_runs[0], &shard_runs[0], Path::new("-o"), &dup],
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("in two shards"));
    assert!(!dup.exists(), "a refused merge made its output folder");
    // ... and it leaves a good run given as its output as it was (it wrote
    // the run's incomplete marker before it checked the shards).
    let o = rendiff(
        &["merge", "--quiet"],
        &[&shard_runs[0], &shard_runs[0], Path::new("-o"), &merged],
    );
    assert_eq!(o.status.code(), Some(2));
    let g = rendiff(&["report"], &[&merged]);
    assert!(g.status.success(), "{}", String::from_utf8_lossy(&g.stderr));
    // A shard whose manifest names a scene outside its scenes/ folder.
    let hostile = t.path().join("hostile");
    std::fs::create_dir_all(&hostile).unwrap();
    let m = std::fs::read_to_string(shard_runs[1].join("manifest.json")).unwrap();
    let mut m: Value = serde_json::from_str(&m).unwrap();
    let scenes = m["scenes"].as_array_mut().unwrap();
    let last = scenes.len() - 1;
    scenes[last]["scene"] = "../../outside".into();
    std::fs::write(hostile.join("manifest.json"), m.to_string()).unwrap();
    let out = t.path().join("out");
    let o = rendiff(&["merge", "--quiet"], &[&hostile, Path::new("-o"), &out]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("\"../../outside\" cannot name a folder"),
        "{err}"
    );
    assert!(!out.exists());
}

/// `rendiff check` from a folder outside the checkout, on the user's own
/// scene: rendiff's harness, probes and expectations come from its checkout,
/// the run goes where the user said.
#[test]
fn check_runs_from_any_folder() {
    let t = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    std::fs::copy(
        root.join("scenes/three_triangles.toml"),
        t.path().join("mine.toml"),
    )
    .unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .current_dir(t.path())
        .env("RENDIFF_HOME", root)
        .args([
            "check",
            "mine.toml",
            "--only",
            "trace",
            "--quiet",
            "-o",
            "out",
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let results = std::fs::read_to_string(t.path().join("out/results.json")).unwrap();
    assert!(results.contains("\"mine\""), "the user's scene was checked");
    assert!(results.contains("camera_near"), "rendiff's probes ran");
    // A wrong RENDIFF_HOME is one clear line.
    let o = Command::new(env!("CARGO_BIN_EXE_rendiff"))
        .current_dir(t.path())
        .env("RENDIFF_HOME", t.path())
        .args(["check", "mine.toml", "-o", "out2"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("not a rendiff checkout"));
}
