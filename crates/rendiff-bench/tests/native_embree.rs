//! The native Embree driver (native/embree_driver.c through
//! `rendiff_bench::native_embree`) traces what the core's binding traces:
//! for every entry point, context flag and build quality its hits make the
//! binding's keys bit for bit, with its rays prepared before the trace or
//! made inside it, and the core's triangle IDs and depths.
//!
//! Where Embree is absent these tests FAIL with the reason, unless
//! `RENDIFF_ALLOW_NO_EMBREE=1` is set, in which case they print a skip
//! notice (the policy of tests/embree_backend.rs: a silent skip would hide a
//! broken setup).

use rendiff::backends::embree::{self, EmbreeMode};
use rendiff::camera::Camera;
use rendiff::scene::resolve::ResolvedScene;
use rendiff::scene::Scene;
use rendiff::trace::{self, TraceOptions};
use rendiff_bench::native_embree::{self, CameraRays, Config, Hits, NativeScene, PreparedRays};
use std::path::Path;

/// True when the driver and the library are usable; panics (test failure)
/// when they are not, unless the environment allows running without Embree.
fn driver_available() -> bool {
    let why = match (native_embree::version(), embree::version()) {
        (Ok(_), Ok(_)) => return true,
        (Err(e), _) => e,
        (_, Err(e)) => e.to_string(),
    };
    if std::env::var("RENDIFF_ALLOW_NO_EMBREE").as_deref() == Ok("1") {
        eprintln!("SKIPPED (RENDIFF_ALLOW_NO_EMBREE=1): {why}");
        false
    } else {
        panic!("{why}\n(set RENDIFF_ALLOW_NO_EMBREE=1 to skip the Embree tests)");
    }
}

fn scene(name: &str) -> ResolvedScene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenes")
        .join(format!("{name}.toml"));
    let s = Scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
    ResolvedScene::resolve(&s).unwrap_or_else(|e| panic!("{e}"))
}

fn resized(name: &str, w: u32, h: u32) -> ResolvedScene {
    let mut s = scene(name);
    let c = &s.camera;
    s.camera = Camera::new(c.eye, c.look_at, c.up, c.vfov_deg, w, h, c.near, c.far).unwrap();
    s
}

/// Scenes with partial tiles, masked lanes, a short last strip and rows
/// wider than one stream call (1024 rays), and nothing at the near plane
/// (the driver does not re-trace there; the binding does).
fn cases() -> Vec<(&'static str, ResolvedScene)> {
    vec![
        ("three_triangles", scene("three_triangles")),
        ("icosphere", scene("icosphere")),
        ("icosphere 37x29", resized("icosphere", 37, 29)),
        ("icosphere 1100x6", resized("icosphere", 1100, 6)),
    ]
}

#[test]
fn every_configuration_gives_the_bindings_keys() {
    if !driver_available() {
        return;
    }
    assert!(native_embree::version().unwrap().starts_with("Embree 3."));
    for (name, s) in cases() {
        let want = embree::render(&s, EmbreeMode::Default).unwrap();
        assert!(want.prim.iter().any(|&p| p != u32::MAX), "{name}: empty");
        let rays = PreparedRays::new(&s.camera);
        let mut built = None;
        for config in Config::all() {
            let what = format!("{name} {}", config.name());
            // One build per quality (Config::all groups them).
            if built
                .as_ref()
                .is_none_or(|(q, _): &(native_embree::Quality, NativeScene)| *q != config.quality)
            {
                let sc = NativeScene::build(&s, config.quality, false, 1)
                    .unwrap_or_else(|e| panic!("{what}: {e}"));
                built = Some((config.quality, sc));
            }
            let sc = &built.as_ref().unwrap().1;
            // Stale values must not survive: every pixel is written.
            let mut hits = Hits::new(&rays);
            hits.t.fill(-1.0);
            hits.prim.fill(7);
            let seconds = sc.trace(&rays, config.entry, config.coherent, &mut hits);
            assert!(seconds >= 0.0, "{what}");
            let (f, in_front) = hits.frame(&s, &rays);
            assert_eq!(in_front, 0, "{what}");
            let prim = (0..f.prim.len())
                .filter(|&i| f.prim[i] != want.prim[i])
                .count();
            let z = (0..f.z.len())
                .filter(|&i| f.z[i].to_bits() != want.z[i].to_bits())
                .count();
            assert_eq!((prim, z), (0, 0), "{what}: (prim, Z bits) differ at px");
            // The same with the rays made strip by strip inside the trace:
            // the same keys, every pixel written again.
            let made = CameraRays::new(&s.camera);
            let mut made_hits = Hits::for_camera(&made);
            made_hits.t.fill(-1.0);
            made_hits.prim.fill(7);
            assert!(sc.trace_made(&made, config.entry, config.coherent, &mut made_hits) >= 0.0);
            assert_eq!(made_hits.t, hits.t, "{what}: made rays, t");
            assert_eq!(made_hits.prim, hits.prim, "{what}: made rays, prim");
            assert_eq!(
                made_hits.keys_made(&made),
                hits.keys(&rays),
                "{what}: made rays, keys"
            );
        }
    }
}

/// On a scene whose pixel centers lie well inside its triangles (no center
/// within 1e-3 px of an edge, which tests/embree_backend.rs's agreement
/// check would otherwise excuse), the driver sees the core tracer's
/// triangle at every pixel, at the same planar depth to within Embree's f32
/// arithmetic: t from a watertight f32 test carries a relative error of a
/// few units in the last place (2^-24 each), and the planar depth is
/// rounded once more; 1e-5 relative (tests/embree_backend.rs's Z_REL_TOL)
/// is about 170 such units, far below any depth a wrong triangle would give
/// on this scene, whose triangles are separated in depth by more than 1%.
#[test]
fn hits_are_the_core_tracers_triangles_and_depths() {
    if !driver_available() {
        return;
    }
    let s = scene("three_triangles");
    let core = trace::render(&s, TraceOptions::default(), &|_| {});
    let rays = PreparedRays::new(&s.camera);
    let sc = NativeScene::build(&s, native_embree::Quality::Medium, false, 1).unwrap();
    let mut hits = Hits::new(&rays);
    for entry in native_embree::Entry::ALL {
        sc.trace(&rays, entry, true, &mut hits);
        let (f, _) = hits.frame(&s, &rays);
        let mut covered = 0;
        for i in 0..f.prim.len() {
            assert_eq!(f.prim[i], core.prim[i], "{} px {i}", entry.name());
            if core.prim[i] != u32::MAX {
                covered += 1;
                let (a, b) = (f64::from(f.z[i]), f64::from(core.z[i]));
                assert!(
                    (a - b).abs() <= 1e-5 * b.abs(),
                    "{} px {i}: {a} vs {b}",
                    entry.name()
                );
            }
        }
        assert!(
            covered > f.prim.len() / 10,
            "{}: {covered} px covered",
            entry.name()
        );
    }
}

/// The driver sets flush-to-zero and denormals-are-zero only for its own
/// calls: Rust code around it runs with the floating-point environment it had.
#[cfg(target_arch = "x86_64")]
#[test]
fn mxcsr_is_restored_after_tracing() {
    if !driver_available() {
        return;
    }
    #[allow(deprecated)]
    // SAFETY: reading MXCSR (SSE, present on every x86_64) touches no memory.
    let before = unsafe { std::arch::x86_64::_mm_getcsr() };
    let s = scene("three_triangles");
    let rays = PreparedRays::new(&s.camera);
    let sc = NativeScene::build(&s, native_embree::Quality::Low, false, 1).unwrap();
    let mut hits = Hits::new(&rays);
    // On this thread (rayon's pool of one may run the strip here or on its worker).
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .use_current_thread()
        .build()
        .unwrap()
        .install(|| sc.trace(&rays, native_embree::Entry::Sixteen, true, &mut hits));
    #[allow(deprecated)]
    // SAFETY: as above.
    let after = unsafe { std::arch::x86_64::_mm_getcsr() };
    assert_eq!(before, after);
    // The default environment has neither FTZ (bit 15) nor DAZ (bit 6).
    assert_eq!(before & 0x8040, 0);
}

/// Measurement, not a test (`cargo test --release -p rendiff-bench --test
/// native_embree -- --ignored --nocapture`): on `million` at 1920x1080, the
/// native driver's every configuration and the binding's packet and stream
/// rows with the coherent flag, on RENDIFF_THREADS threads (default 1).
#[test]
#[ignore]
fn measure_million() {
    use rendiff::backends::embree::{EmbreeBuild, EmbreeCoherence, EmbreeQuery};
    if !driver_available() {
        return;
    }
    let threads: usize = std::env::var("RENDIFF_THREADS")
        .ok()
        .and_then(|t| t.parse().ok())
        .unwrap_or(1);
    // As `bench peers` does: the binding's per-frame key buffer reuses pages.
    rendiff_bench::keep_freed_memory();
    let s = resized("million", 1920, 1080);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let rays = PreparedRays::new(&s.camera);
        let n = rays.len() as f64;
        // RENDIFF_BINDING_ONLY=1: the binding's rows alone (for a profiler).
        let qualities = if std::env::var_os("RENDIFF_BINDING_ONLY").is_some() {
            vec![]
        } else {
            native_embree::Quality::ALL.to_vec()
        };
        for q in qualities {
            let sc = NativeScene::build(&s, q, false, threads).unwrap();
            eprintln!("build {}: {:.3} s", q.name(), sc.build_s);
            for c in Config::all().into_iter().filter(|c| c.quality == q) {
                let (times, _) = rendiff_bench::measure::native_frames(&sc, &rays, c, 3);
                eprintln!(
                    "{:40} {:7.2} Mrays/s",
                    c.name(),
                    n / rendiff_bench::median(&times) / 1e6
                );
            }
        }
        for query in [
            EmbreeQuery::Packet8,
            EmbreeQuery::Packet16,
            EmbreeQuery::Stream1M,
        ] {
            let mut t = vec![];
            for _ in 0..3 {
                let (_, tm) = embree::render_timed_with(
                    &s,
                    EmbreeMode::Default,
                    EmbreeBuild::Medium,
                    query,
                    EmbreeCoherence::Coherent,
                )
                .unwrap();
                t.push(tm.trace_seconds);
            }
            eprintln!(
                "binding {:32} {:7.2} Mrays/s",
                query.name(),
                n / rendiff_bench::median(&t) / 1e6
            );
        }
    });
}
