//! The core's promise: raster and trace compute one visibility. `id.prim` and
//! `Z` must be byte-identical on every scene and on randomized adversarial ones.

mod common;

use common::scenes::*;
use proptest::prelude::*;
use rendiff::scene::resolve::ResolvedScene;
use rendiff::trace::TraceKernel;

#[test]
fn every_scene_renders_identically_in_both_loops() {
    let files = scene_files();
    assert!(
        files.len() >= 6,
        "expected the starter scenes, found {files:?}"
    );
    for path in files {
        let scene = load(&path);
        let (r, t) = both(&scene, false);
        assert_identical(&path.display().to_string(), &r, &t);
        let single = trace_kernel(&scene, TraceKernel::SingleRays);
        assert_identical(&format!("{} (single rays)", path.display()), &r, &single);
        let hits = r.prim.iter().filter(|&&p| p != u32::MAX).count();
        assert!(hits > 0, "{}: nothing visible", path.display());
    }
}

/// Snaps a coordinate in [-1, 1] to the nearest pixel-center coordinate of a
/// 32x32 exact camera (odd multiples of 1/32) when `snap` is set.
fn coord(v: f32, snap: bool) -> f32 {
    if snap {
        ((v * 16.0).floor() * 2.0 + 1.0) / 32.0
    } else {
        v
    }
}

fn arb_point() -> impl Strategy<Value = [f32; 3]> {
    (-1.2f32..1.2, -1.2f32..1.2, -0.8f32..0.6, any::<bool>())
        .prop_map(|(x, y, z, snap)| [coord(x, snap), coord(y, snap), if snap { 0.0 } else { z }])
}

#[derive(Debug, Clone)]
enum Piece {
    Random([[f32; 3]; 3]),
    /// Two triangles sharing an edge (opposite or same winding).
    SharedEdge([[f32; 3]; 4], bool),
    /// The same triangle twice, coplanar overlap.
    Duplicate([[f32; 3]; 3]),
    /// A sliver: third vertex almost on the first edge.
    Sliver([[f32; 3]; 2], f32),
}

fn arb_piece() -> impl Strategy<Value = Piece> {
    prop_oneof![
        [arb_point(), arb_point(), arb_point()].prop_map(Piece::Random),
        (
            [arb_point(), arb_point(), arb_point(), arb_point()],
            any::<bool>()
        )
            .prop_map(|(p, flip)| Piece::SharedEdge(p, flip)),
        [arb_point(), arb_point(), arb_point()].prop_map(Piece::Duplicate),
        ([arb_point(), arb_point()], -1e-4f32..1e-4).prop_map(|(p, e)| Piece::Sliver(p, e)),
    ]
}

fn build(pieces: &[Piece]) -> ResolvedScene {
    let mut tris = Vec::new();
    for p in pieces {
        match p {
            Piece::Random([a, b, c]) => tris.push(tri(*a, *b, *c)),
            Piece::SharedEdge([a, b, c, d], flip) => {
                tris.push(tri(*a, *b, *c));
                if *flip {
                    tris.push(tri(*b, *a, *d));
                } else {
                    tris.push(tri(*a, *b, *d));
                }
            }
            Piece::Duplicate([a, b, c]) => {
                tris.push(tri(*a, *b, *c));
                tris.push(tri(*b, *c, *a));
            }
            Piece::Sliver([a, b], e) => {
                let m = [
                    (a[0] + b[0]) / 2.0 + e,
                    (a[1] + b[1]) / 2.0,
                    (a[2] + b[2]) / 2.0,
                ];
                tris.push(tri(*a, *b, m));
            }
        }
    }
    ResolvedScene::from_triangles(exact_camera(32), tris)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn random_adversarial_scenes_render_identically(pieces in prop::collection::vec(arb_piece(), 1..12)) {
        let scene = build(&pieces);
        let (r, t) = both(&scene, true);
        assert_identical("random scene", &r, &t);
        prop_assert_eq!(&r.coverage, &t.coverage, "coverage counts differ");
        // Without coverage counts the tracer prunes, in 4x2 packets and in single rays.
        assert_identical("random scene (packets)", &r, &trace_kernel(&scene, TraceKernel::Packets));
        assert_identical("random scene (single rays)", &r, &trace_kernel(&scene, TraceKernel::SingleRays));
        // The raster's edge-function fast path against its pure predicate path.
        let exact = rendiff::raster::render_exact(&scene, rendiff::raster::RasterOptions { count_coverage: true, deadline: None }, &|_| {});
        assert_identical("random scene (raster without fast path)", &r, &exact);
        prop_assert_eq!(&r.coverage, &exact.coverage, "coverage counts differ from the pure predicate path");
        let mut counts = r.counters;
        counts.fast_decided = 0;
        prop_assert_eq!(counts, exact.counters, "operation counts differ from the pure predicate path");
    }
}

#[test]
fn float_only_predicates_still_agree_between_loops_but_skip_exact_work() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/pixel_grid.toml");
    let mut scene = load(&path);
    let (exact, _) = both(&scene, false);
    scene.camera.precision = rendiff::predicate::Precision::FloatOnly;
    let (r, t) = both(&scene, false);
    assert_identical("pixel_grid float-only", &r, &t);
    assert_eq!(r.counters.exact_fallbacks, 0);
    assert!(exact.counters.exact_fallbacks > 0);
}

/// Image sizes that are not multiples of the 8x8 packet: border lanes are
/// masked off and every pixel still gets the single-ray answer.
#[test]
fn packets_handle_partial_tiles_at_the_image_border() {
    let text = std::fs::read_to_string("scenes/icosphere.toml").unwrap();
    let dir = tempfile::tempdir().unwrap();
    for (w, h) in [(37, 23), (1, 1), (9, 5), (5, 3)] {
        let sized: String = text
            .lines()
            .map(|l| {
                if l.starts_with("width") {
                    format!("width = {w}")
                } else if l.starts_with("height") {
                    format!("height = {h}")
                } else {
                    l.to_string()
                }
            })
            .collect::<Vec<_>>()
            .join("\n");
        let path = dir.path().join(format!("ico_{w}x{h}.toml"));
        std::fs::write(&path, sized).unwrap();
        let scene = load(&path);
        assert_eq!((scene.camera.width, scene.camera.height), (w, h));
        let (r, t) = both(&scene, false);
        assert_identical(&format!("{w}x{h}"), &r, &t);
        assert_identical(
            &format!("{w}x{h} single rays"),
            &r,
            &trace_kernel(&scene, TraceKernel::SingleRays),
        );
    }
}

/// Thousands of triangles sharing one box (exact copies, rotations of one
/// triangle, the same box's other diagonal) beside distinct ones: the tracer
/// hands each shared box to the BVH builder once and expands its leaf
/// afterwards (`trace::same_box`), and every pixel must still get the raster's
/// key, in packets and in single rays, at every BVH quality.
#[test]
fn triangles_sharing_a_box_by_the_thousand_render_identically() {
    let mut tris = Vec::new();
    let (a, b, c, d) = (
        [-0.9f32, -0.9, 0.0],
        [0.9, -0.9, 0.0],
        [-0.9, 0.9, 0.0],
        [0.9, 0.9, 0.0],
    );
    for k in 0..3000 {
        tris.push(match k % 4 {
            0 => tri(a, b, c),
            1 => tri(b, c, a),
            2 => tri(d, c, b), // the box's other half
            _ => tri(a, b, c),
        });
        if k % 100 == 0 {
            // Distinct triangles, some in front and some behind the stack.
            let s = k as f32 / 3000.0;
            let z = if k % 200 == 0 { 0.3 } else { -0.3 };
            tris.push(tri([-0.5 + s, -0.5, z], [0.5, -0.4 + s, z], [0.0, 0.6, z]));
        }
    }
    let scene = ResolvedScene::from_triangles(exact_camera(32), tris);
    let (r, t) = both(&scene, true);
    assert_identical("shared boxes", &r, &t);
    assert_eq!(&r.coverage, &t.coverage, "coverage counts differ");
    for kernel in [TraceKernel::Packets, TraceKernel::SingleRays] {
        assert_identical("shared boxes", &r, &trace_kernel(&scene, kernel));
    }
    for quality in [
        rendiff::trace::BvhQuality::Linear,
        rendiff::trace::BvhQuality::Fastest,
        rendiff::trace::BvhQuality::Medium,
        rendiff::trace::BvhQuality::Slow,
    ] {
        let bvh = rendiff::trace::TraceBvh::build(&scene, quality);
        let keys = rendiff::trace::trace_keys(
            &scene,
            &bvh,
            rendiff::trace::TraceOptions::default(),
            &|_| {},
        );
        let raster = rendiff::raster::render_keys(
            &scene,
            rendiff::raster::RasterOptions::default(),
            &|_| {},
        );
        assert!(
            keys.keys == raster.keys,
            "{quality:?}: keys differ from the raster's"
        );
    }
}

/// `render --renderer core` and `check`'s reference render through the loop
/// the cost model (`rendiff::loop_cost`) picks: whichever it is, the buffers
/// are both loops' own, so the choice never changes a verdict. Every starter
/// scene through the pick for one frame, and through the pick when the BVH is
/// shared by many frames (which is the tracer on the dense grid below), so
/// both picks are exercised.
#[test]
fn the_loop_the_cost_model_picks_renders_both_loops_buffers() {
    use rendiff::loop_cost::{self, Loop, Workload};
    use rendiff::render::{self, Backend, RenderOptions};
    let mut scenes: Vec<(String, ResolvedScene)> = scene_files()
        .into_iter()
        .map(|p| (p.display().to_string(), load(&p)))
        .collect();
    // 8 triangles per pixel, screen-filling: the passes favour the tracer.
    let dense = rendiff::scene::generators::crossover_grid(128, 64, false).unwrap();
    scenes.push(("dense grid".into(), dense));
    let mut picked = std::collections::BTreeSet::new();
    for (name, scene) in &scenes {
        let (r, t) = both(scene, false);
        assert_identical(name, &r, &t);
        let shared = Workload {
            frames: 1000,
            ..loop_cost::workload(scene, 2)
        };
        let picks = [
            render::core_loop(scene, 2).0,
            match loop_cost::choose(&shared).pick {
                Loop::Raster => Backend::Raster,
                Loop::Trace => Backend::Trace,
            },
        ];
        for backend in picks {
            picked.insert(backend.name());
            let got = render::render(scene, backend, RenderOptions::default(), &|_| {})
                .unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_identical(&format!("{name} ({})", backend.name()), &r, &got.frame);
        }
    }
    assert_eq!(
        picked.into_iter().collect::<Vec<_>>(),
        ["raster", "trace"],
        "both loops picked somewhere"
    );
}
