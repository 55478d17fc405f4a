//! Helpers shared by the integration tests (`tests/common/`).

#![allow(dead_code)]

use glam::{DVec3, Vec3};
use rendiff::camera::Camera;
use rendiff::frame::Frame;
use rendiff::raster::{self, RasterOptions};
use rendiff::scene::resolve::{ResolvedScene, Tri};
use rendiff::scene::Scene;
use rendiff::trace::{self, TraceOptions};
use std::path::{Path, PathBuf};

/// A scene file's `[camera]` table as a `&'static str` (a newline before and
/// after), so that a test's scene texts stay `const`s read with `{CAMERA}` in
/// `format!`: `camera_toml!(eye [0.0, 0.0, 5.0], look_at [0.0, 0.0, 0.0],
/// vfov 45.0, 16 x 12)`.
#[macro_export]
macro_rules! camera_toml {
    (eye $eye:tt, look_at $at:tt, vfov $vfov:literal, $w:literal x $h:literal) => {
        concat!(
            "\n[camera]\neye = ",
            stringify!($eye),
            "\nlook_at = ",
            stringify!($at),
            "\nvfov = ",
            stringify!($vfov),
            "\nwidth = ",
            stringify!($w),
            "\nheight = ",
            stringify!($h),
            "\n"
        )
    };
}

/// Every scene file in scenes/.
pub fn scene_files() -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    v.sort();
    v
}

/// Loads and resolves a scene file, panicking with its error.
pub fn load(path: &Path) -> ResolvedScene {
    let s = Scene::load(path).unwrap_or_else(|e| panic!("{e}"));
    ResolvedScene::resolve(&s).unwrap_or_else(|e| panic!("{e}"))
}

/// Renders with both loops.
pub fn both(scene: &ResolvedScene, count_coverage: bool) -> (Frame, Frame) {
    let r = raster::render(
        scene,
        RasterOptions {
            count_coverage,
            ..RasterOptions::default()
        },
        &|_| {},
    );
    let t = trace::render(
        scene,
        TraceOptions {
            count_coverage,
            ..TraceOptions::default()
        },
        &|_| {},
    );
    (r, t)
}

/// Traces with a chosen kernel (packets or single rays), without coverage counts.
pub fn trace_kernel(scene: &ResolvedScene, kernel: trace::TraceKernel) -> Frame {
    trace::render(
        scene,
        TraceOptions {
            kernel,
            ..TraceOptions::default()
        },
        &|_| {},
    )
}

/// Panics with the first differing pixel if `id.prim` or `Z` differ in any bit.
pub fn assert_identical(what: &str, r: &Frame, t: &Frame) {
    for i in 0..r.prim.len() {
        let (x, y) = (i % r.width as usize, i / r.width as usize);
        assert_eq!(
            r.prim[i], t.prim[i],
            "{what}: id.prim differs at pixel ({x},{y}): raster {} trace {}",
            r.prim[i], t.prim[i]
        );
        assert_eq!(
            r.z[i].to_bits(),
            t.z[i].to_bits(),
            "{what}: Z differs at pixel ({x},{y}): raster {} trace {}",
            r.z[i],
            t.z[i]
        );
    }
    assert_eq!(r.object, t.object, "{what}: id.object differs");
}

/// A camera looking down -z from (0, 0, 1) with vfov 90: pixel centers of a
/// power-of-two image lie exactly on z = 0 at odd multiples of 1/W.
pub fn exact_camera(w: u32) -> Camera {
    Camera::new(
        DVec3::new(0.0, 0.0, 1.0),
        DVec3::ZERO,
        DVec3::Y,
        90.0,
        w,
        w,
        1e-3,
        f64::INFINITY,
    )
    .unwrap()
}

/// Triangle from three points.
pub fn tri(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> Tri {
    [Vec3::from(a), Vec3::from(b), Vec3::from(c)]
}
