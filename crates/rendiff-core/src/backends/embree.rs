//! Embree 3 as an external reference renderer for depth and IDs, called in process.
//!
//! Why in process: Embree is a C library, so the cheapest faithful adapter is to
//! hand it the resolved triangles and trace **the core's own pixel rays**
//! ([`Camera::pixel_ray`]) through it. Any difference from the core is then
//! Embree's intersection arithmetic (f32 watertight test, BVH traversal), not a
//! different camera or sampling convention.
//!
//! Why loaded at run time ([`libloading`]): the crate must build and run on
//! machines without Embree. When `libembree3` cannot be opened, every entry
//! point returns [`EmbreeError::Unavailable`] and the caller reports the
//! backend as *skipped*.
//!
//! Conventions (docs/DESIGN.md):
//! - The ray of pixel (x, y) has origin `eye` and direction `D` of
//!   [`PixelRay`], both rounded to f32 (Embree's precision). Planar depth of a
//!   hit at ray parameter `t` is `(o32 - eye)·f + t·(D32·f)`, evaluated in f64
//!   and rounded once to f32; the first term is the (tiny) offset of the f32
//!   origin from the f64 eye.
//! - `near`/`far` become `tnear`/`tfar`, slightly widened, and the rounded
//!   depth is then checked against `[near, far]` exactly as the core does: a
//!   hit in front of `near` is skipped by re-tracing from just beyond it, a hit
//!   beyond `far` is a miss.
//! - One triangle geometry with unshared vertices: Embree's `primID` is the
//!   index in [`ResolvedScene::triangles`]. Embree drops degenerate triangles
//!   itself (they are never visible, as in the core).
//! - Back faces are not culled (Debian's build has culling off; checked via the
//!   device property at setup).
//!
//! Counters: Embree does not expose its triangle or node tests, so
//! [`Counters`] stay zero rather than being filled with numbers of another
//! meaning. Rays traced equal the pixel count (plus rare near-plane re-traces).
//!
//! Floating-point environment: Embree recommends FTZ/DAZ in MXCSR for speed;
//! changing MXCSR under Rust code is undefined behaviour, so it is left alone.

use crate::camera::{Camera, PixelRay};
use crate::frame::Frame;
use crate::scene::resolve::ResolvedScene;
use crate::visibility::{fill_no_hit, hit_key, Counters, NO_HIT};
use libloading::Library;
use rayon::prelude::*;
use std::ffi::{c_char, c_void, CStr, CString};
use std::mem::MaybeUninit;
use std::sync::{Mutex, OnceLock};
use std::time::Instant;

/// Shared-library names tried in order: Debian's runtime package (`libembree3-3`)
/// ships the versioned name; the unversioned one comes with `libembree-dev`.
const LIBRARY_NAMES: [&str; 2] = ["libembree3.so.3", "libembree3.so"];

/// What to tell a person whose machine lacks Embree.
const INSTALL_HINT: &str =
    "libembree3 not found: install Debian's libembree3-3 (apt-get install libembree-dev)";

/// Which Embree configuration: the comparison reports both, because Embree's
/// default traversal may leak through edges where ROBUST mode does not.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EmbreeMode {
    /// Default scene flags, medium build quality.
    Default,
    /// `RTC_SCENE_FLAG_ROBUST`: conservative traversal and watertight tests, slower.
    Robust,
}

impl EmbreeMode {
    /// Backend name used in file names, reports and [`Frame::renderer`].
    pub fn name(self) -> &'static str {
        match self {
            EmbreeMode::Default => "embree",
            EmbreeMode::Robust => "embree_robust",
        }
    }
}

/// How rays are handed to Embree. `Single` is the reference path (the check
/// and the agreement tests run it); the others exist so that benchmarks can
/// measure Embree at its best, through every entry point Embree offers for
/// primary rays. Packets and streams are filled with screen-space tiles, so
/// the rays Embree traces together are neighbours (coherent).
///
/// Every variant traces the same f32 rays and turns hits into keys the same
/// way, so all produce the keys of `Single` (tests/embree_backend.rs checks it).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum EmbreeQuery {
    /// `rtcIntersect1` per pixel, rows in parallel.
    #[default]
    Single,
    /// `rtcIntersect4` on 2x2 pixel tiles (masked at the image border).
    Packet4,
    /// `rtcIntersect8` on 4x2 pixel tiles (masked at the image border).
    Packet8,
    /// `rtcIntersect16` on 4x4 pixel tiles (masked at the image border).
    Packet16,
    /// `rtcIntersect1M`: an array of `RTCRayHit` (stride 80 bytes) over
    /// 4-row strips in 4x4-tile order, up to [`STREAM_RAYS`] rays per call,
    /// so that the packets Embree forms from consecutive rays are tiles.
    Stream1M,
    /// `rtcIntersectNM` with N = 8: an array of 4x2-tile `RTCRayHit8`
    /// packets over 2-row strips, up to [`STREAM_RAYS`] rays per call (lanes
    /// outside the image are inactive: tnear > tfar).
    StreamNM8,
}

/// Rays per stream call (`rtcIntersect1M`, `rtcIntersectNM`): 80 KiB of ray
/// and hit data, small enough to stay in L2 cache between writing the rays
/// and reading the hits, large enough that the call overhead vanishes.
pub const STREAM_RAYS: usize = 1024;

impl EmbreeQuery {
    /// Every query path, the reference (`Single`) first.
    pub const ALL: [EmbreeQuery; 6] = [
        EmbreeQuery::Single,
        EmbreeQuery::Packet4,
        EmbreeQuery::Packet8,
        EmbreeQuery::Packet16,
        EmbreeQuery::Stream1M,
        EmbreeQuery::StreamNM8,
    ];

    /// Short name for reports and JSON keys ("single", "packet8", ...).
    pub fn name(self) -> &'static str {
        match self {
            EmbreeQuery::Single => "single",
            EmbreeQuery::Packet4 => "packet4",
            EmbreeQuery::Packet8 => "packet8",
            EmbreeQuery::Packet16 => "packet16",
            EmbreeQuery::Stream1M => "stream1M",
            EmbreeQuery::StreamNM8 => "streamNM8",
        }
    }

    /// The Embree function this path calls, so reports name what was measured.
    pub fn entry_point(self) -> &'static str {
        match self {
            EmbreeQuery::Single => "rtcIntersect1",
            EmbreeQuery::Packet4 => "rtcIntersect4",
            EmbreeQuery::Packet8 => "rtcIntersect8",
            EmbreeQuery::Packet16 => "rtcIntersect16",
            EmbreeQuery::Stream1M => "rtcIntersect1M",
            EmbreeQuery::StreamNM8 => "rtcIntersectNM (N=8)",
        }
    }

    /// How pixels are grouped into one call, for reports.
    pub fn layout(self) -> &'static str {
        match self {
            EmbreeQuery::Single => "one pixel per call, rows in parallel",
            EmbreeQuery::Packet4 => "2x2 tiles, 2-row strips in parallel",
            EmbreeQuery::Packet8 => "4x2 tiles, 2-row strips in parallel",
            EmbreeQuery::Packet16 => "4x4 tiles, 4-row strips in parallel",
            EmbreeQuery::Stream1M => {
                "1024 RTCRayHit in 4x4-tile order per call, 4-row strips in parallel"
            }
            EmbreeQuery::StreamNM8 => {
                "128 4x2-tile RTCRayHit8 packets per call, 2-row strips in parallel"
            }
        }
    }
}

/// The `RTCIntersectContext` flag rays are traced with. Embree's documentation
/// asks for `COHERENT` when the rays of a packet or stream are coherent, as
/// primary rays of neighbouring pixels are; Embree may then switch to
/// traversal made for such rays. `Incoherent` is what `rtcInitIntersectContext`
/// sets, and what [`render`], [`render_packets`] and the check use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum EmbreeCoherence {
    /// `RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT` (Embree's default).
    #[default]
    Incoherent,
    /// `RTC_INTERSECT_CONTEXT_FLAG_COHERENT`.
    Coherent,
}

impl EmbreeCoherence {
    /// Both flags, the default first.
    pub const ALL: [EmbreeCoherence; 2] = [EmbreeCoherence::Incoherent, EmbreeCoherence::Coherent];

    /// Short name for reports ("incoherent", "coherent").
    pub fn name(self) -> &'static str {
        match self {
            EmbreeCoherence::Incoherent => "incoherent",
            EmbreeCoherence::Coherent => "coherent",
        }
    }

    fn flags(self) -> u32 {
        match self {
            EmbreeCoherence::Incoherent => ffi::INTERSECT_CONTEXT_FLAG_INCOHERENT,
            EmbreeCoherence::Coherent => ffi::INTERSECT_CONTEXT_FLAG_COHERENT,
        }
    }
}

/// The BVH build quality Embree is asked for (`rtcSetSceneBuildQuality`).
/// `Medium` is Embree's default and what renders and checks use; `High`
/// ("higher quality data structures for final-frame rendering", a spatial
/// split BVH for triangles) trades build time for traversal speed, so the
/// throughput benchmark measures Embree with both.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum EmbreeBuild {
    /// `RTC_BUILD_QUALITY_MEDIUM`.
    #[default]
    Medium,
    /// `RTC_BUILD_QUALITY_HIGH`.
    High,
}

impl EmbreeBuild {
    /// Both qualities, the default first.
    pub const ALL: [EmbreeBuild; 2] = [EmbreeBuild::Medium, EmbreeBuild::High];

    /// Short name for reports ("medium", "high").
    pub fn name(self) -> &'static str {
        match self {
            EmbreeBuild::Medium => "medium",
            EmbreeBuild::High => "high",
        }
    }

    fn quality(self) -> u32 {
        match self {
            EmbreeBuild::Medium => ffi::BUILD_QUALITY_MEDIUM,
            EmbreeBuild::High => ffi::BUILD_QUALITY_HIGH,
        }
    }
}

/// Which ray-query features this Embree build has natively (device
/// properties), so a benchmark can say whether a packet size it measured is
/// native or emulated by Embree.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct EmbreeFeatures {
    /// `RTC_DEVICE_PROPERTY_NATIVE_RAY4_SUPPORTED`.
    pub native_ray4: bool,
    /// `RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED`.
    pub native_ray8: bool,
    /// `RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED`.
    pub native_ray16: bool,
    /// `RTC_DEVICE_PROPERTY_RAY_STREAM_SUPPORTED`.
    pub ray_stream: bool,
}

/// Why an Embree render did not happen. `Unavailable` means "skip this backend",
/// `Failed` means a real error that the report must show.
#[derive(Debug, thiserror::Error)]
pub enum EmbreeError {
    /// The library could not be loaded (not installed, or a symbol missing).
    #[error("{0}")]
    Unavailable(String),
    /// Embree was loaded but refused a call (error code and message).
    #[error("embree failed: {0}")]
    Failed(String),
}

/// Wall-clock split of one render, for the speed-versus-accuracy tables.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EmbreeTimings {
    /// Device creation (thread pool, ISA selection).
    pub device_seconds: f64,
    /// Buffer setup and BVH build (`rtcCommitScene`).
    pub build_seconds: f64,
    /// Preparing every pixel's ray in f32 (once per camera: it depends on
    /// the camera only, and an application would keep its rays in f32).
    pub rays_seconds: f64,
    /// Tracing all pixel rays (copied into Embree's layout) and assembling keys.
    pub trace_seconds: f64,
    /// Rays handed to Embree (pixels plus near-plane re-traces).
    pub rays: u64,
}

/// Version string like "Embree 3.13.5", so reports say which library produced a result.
pub fn version() -> Result<String, EmbreeError> {
    let api = api()?;
    let device = Device::new(api, 1)?;
    let [major, minor, patch] = [
        ffi::DEVICE_PROPERTY_VERSION_MAJOR,
        ffi::DEVICE_PROPERTY_VERSION_MINOR,
        ffi::DEVICE_PROPERTY_VERSION_PATCH,
    ]
    // SAFETY: `device.raw` is a live device; property queries have no other preconditions.
    .map(|p| unsafe { (api.get_device_property)(device.raw, p) });
    device.check("rtcGetDeviceProperty")?;
    Ok(format!("Embree {major}.{minor}.{patch}"))
}

/// The native packet sizes and stream support of the loaded library.
pub fn features() -> Result<EmbreeFeatures, EmbreeError> {
    let api = api()?;
    let device = Device::new(api, 1)?;
    // SAFETY: `device.raw` is a live device; property queries have no other preconditions.
    let prop = |p| unsafe { (api.get_device_property)(device.raw, p) } != 0;
    let f = EmbreeFeatures {
        native_ray4: prop(ffi::DEVICE_PROPERTY_NATIVE_RAY4_SUPPORTED),
        native_ray8: prop(ffi::DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED),
        native_ray16: prop(ffi::DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED),
        ray_stream: prop(ffi::DEVICE_PROPERTY_RAY_STREAM_SUPPORTED),
    };
    device.check("rtcGetDeviceProperty")?;
    Ok(f)
}

/// Renders depth and IDs with `rtcIntersect1` per pixel (the reference path):
/// rows in parallel on rayon's current pool, device `threads=N` matching it.
/// `Frame::seconds` covers device creation, BVH build and tracing.
pub fn render(scene: &ResolvedScene, mode: EmbreeMode) -> Result<Frame, EmbreeError> {
    render_timed(scene, mode, EmbreeQuery::Single).map(|(f, _)| f)
}

/// Like [`render`] but with `rtcIntersect8` on 4x2 tiles (incoherent context,
/// as [`render`]): Embree's packet path, kept as its own entry point because
/// its results could differ from the single-ray path in ROBUST mode. For
/// every query path and both context flags see [`render_timed_with`].
pub fn render_packets(scene: &ResolvedScene, mode: EmbreeMode) -> Result<Frame, EmbreeError> {
    render_timed(scene, mode, EmbreeQuery::Packet8).map(|(f, _)| f)
}

/// Renders with the chosen query path and Embree's default (incoherent)
/// context, and returns the timing split as well (for benchmarks that
/// separate BVH build from tracing).
pub fn render_timed(
    scene: &ResolvedScene,
    mode: EmbreeMode,
    query: EmbreeQuery,
) -> Result<(Frame, EmbreeTimings), EmbreeError> {
    render_timed_with(
        scene,
        mode,
        EmbreeBuild::Medium,
        query,
        EmbreeCoherence::Incoherent,
    )
}

/// Like [`render_timed`] with the build quality and the intersect-context
/// flag chosen too: the benchmarks try every query path with both flags and
/// both qualities to find Embree's fastest.
pub fn render_timed_with(
    scene: &ResolvedScene,
    mode: EmbreeMode,
    build: EmbreeBuild,
    query: EmbreeQuery,
    coherence: EmbreeCoherence,
) -> Result<(Frame, EmbreeTimings), EmbreeError> {
    let start = Instant::now();
    let api = api()?;
    let threads = rayon::current_num_threads();
    let device = Device::new(api, threads)?;
    let device_seconds = start.elapsed().as_secs_f64();
    let t_build = Instant::now();
    let built = BuiltScene::new(device, scene, mode, build)?;
    let build_seconds = t_build.elapsed().as_secs_f64();
    // Every pixel's ray in f32 before the trace is timed: an Embree
    // application keeps its rays in f32 and hands them over as they are;
    // deriving them from the core's f64 pixel rays (a division per ray, and
    // two more for tnear/tfar) is this adapter's cost, not Embree's, and
    // inside `trace_seconds` it made the packet paths about half as fast as
    // a native driver's (docs/embree-fastest-path.md).
    let t_rays = Instant::now();
    let cam = &scene.camera;
    let rays = RayGen::new(cam);
    let rays_seconds = t_rays.elapsed().as_secs_f64();
    let t_trace = Instant::now();
    // No serial pre-fill inside the timed region (`vec![NO_HIT; n]` wrote
    // the whole buffer on one thread, about 3 ms of `million`'s 1080p on
    // this machine, charged to Embree): each strip fills its own rows in
    // parallel ([`strips`]), the core's key-buffer policy.
    let n = cam.pixel_count();
    let mut keys: Vec<u64> = Vec::with_capacity(n);
    let w = cam.width as usize;
    let flags = coherence.flags();
    let ctx = || ffi::IntersectContext::new(flags);
    let spare = &mut keys.spare_capacity_mut()[..n];
    let retraces: u64 = match query {
        EmbreeQuery::Single => strips(spare, w, 1, |y, row| {
            let mut ctx = ctx();
            let mut n = 0;
            for (x, k) in row.iter_mut().enumerate() {
                let (key, extra) = built.trace1(&rays, &mut ctx, x as u32, y);
                *k = key;
                n += extra;
            }
            n
        }),
        EmbreeQuery::Packet4 => strips(spare, w, 2, |y0, rows| {
            built.trace_tiles(
                &rays,
                &mut ctx(),
                Packets::Each(api.intersect4),
                2,
                y0,
                rows,
            )
        }),
        EmbreeQuery::Packet8 => strips(spare, w, 2, |y0, rows| {
            built.trace_tiles(
                &rays,
                &mut ctx(),
                Packets::Each(api.intersect8),
                4,
                y0,
                rows,
            )
        }),
        EmbreeQuery::Packet16 => strips(spare, w, 4, |y0, rows| {
            built.trace_tiles(
                &rays,
                &mut ctx(),
                Packets::Each(api.intersect16),
                4,
                y0,
                rows,
            )
        }),
        EmbreeQuery::Stream1M => strips(spare, w, 4, |y0, rows| {
            built.trace_stream1(&rays, &mut ctx(), y0, rows)
        }),
        EmbreeQuery::StreamNM8 => strips(spare, w, 2, |y0, rows| {
            built.trace_tiles::<8>(&rays, &mut ctx(), Packets::Stream, 4, y0, rows)
        }),
    };
    // SAFETY: `strips` initialized every element of `keys[..n]` (its
    // chunks partition the slice, each filled before it is traced), and
    // `n` is the capacity asked for.
    unsafe { keys.set_len(n) };
    let trace_seconds = t_trace.elapsed().as_secs_f64();
    drop(built);
    let frame = Frame::from_keys(
        scene,
        &keys,
        None,
        Counters::default(),
        mode.name(),
        start.elapsed().as_secs_f64(),
    );
    Ok((
        frame,
        EmbreeTimings {
            device_seconds,
            build_seconds,
            rays_seconds,
            trace_seconds,
            rays: cam.pixel_count() as u64 + retraces,
        },
    ))
}

/// Splits the (uninitialized) key buffer into strips of `h` rows (`w`
/// pixels each), fills each with `NO_HIT` and has it traced by
/// `trace(first_row, strip)`, all in parallel; returns the summed re-traces.
/// Every element of `keys` is initialized on return.
fn strips(
    keys: &mut [MaybeUninit<u64>],
    w: usize,
    h: usize,
    trace: impl Fn(u32, &mut [u64]) -> u64 + Sync + Send,
) -> u64 {
    keys.par_chunks_mut(h * w)
        .enumerate()
        .map(|(i, rows)| trace((i * h) as u32, fill_no_hit(rows)))
        .sum()
}

/// The core's pixel rays as Embree rays, every pixel's prepared up front,
/// with the constants that turn hits back into planar depths.
struct RayGen<'a> {
    cam: &'a Camera,
    /// The eye rounded to f32: every ray's origin.
    org: [f32; 3],
    /// `(org - eye)·forward`: planar depth of the f32 origin.
    offset: f64,
    /// Every pixel's ray, row-major ([`RayGen::prepare`]).
    prepared: Vec<EmbreeRay>,
}

/// One pixel's ray in Embree's precision, with its depth conversion: the
/// one definition of the convention, which the bench's native Embree driver
/// uses too (`rendiff-bench`'s `embree_rays`), so its hits are this
/// binding's bit for bit.
#[derive(Debug, Clone, Copy)]
pub struct EmbreeRay {
    /// The core's pixel ray direction rounded to f32.
    pub dir: [f32; 3],
    /// `D32·forward`: planar depth per unit of `t`.
    pub planar: f64,
    /// Where the hit interval starts (the near plane, widened).
    pub tnear: f32,
    /// Where it ends (the far plane, widened; +inf when the far plane is).
    pub tfar: f32,
}

impl EmbreeRay {
    /// The origin every ray of `cam` starts from (the eye rounded to f32)
    /// and its planar depth offset `(org - eye)·forward`.
    pub fn origin(cam: &Camera) -> ([f32; 3], f64) {
        let org = cam.eye.as_vec3();
        (org.to_array(), (org.as_dvec3() - cam.eye).dot(cam.forward))
    }

    /// The ray through screen point `(sx, sy)` ([`Camera::screen`]) for a
    /// camera whose origin offset is `offset` ([`EmbreeRay::origin`]).
    #[inline]
    pub fn at(cam: &Camera, offset: f64, sx: f64, sy: f64) -> EmbreeRay {
        let pr: PixelRay = cam.screen_ray(sx, sy);
        let d = pr.dir.as_vec3();
        let planar = d.as_dvec3().dot(cam.forward);
        // Widened by 1e-6 relative so rounding never hides a hit inside [near, far];
        // `depth_in_range` then applies the exact rule on the rounded depth.
        let tnear = ((cam.near - offset) / planar * (1.0 - 1e-6)).max(0.0) as f32;
        let tfar = if cam.far.is_finite() {
            ((cam.far - offset) / planar * (1.0 + 1e-6)) as f32
        } else {
            f32::INFINITY
        };
        EmbreeRay {
            dir: d.to_array(),
            planar,
            tnear,
            tfar,
        }
    }

    /// Planar depth of a hit at ray parameter `t`, rounded once to f32.
    #[inline]
    pub fn depth(offset: f64, planar: f64, t: f32) -> f32 {
        (offset + f64::from(t) * planar) as f32
    }
}

impl<'a> RayGen<'a> {
    fn new(cam: &'a Camera) -> Self {
        let (org, offset) = EmbreeRay::origin(cam);
        let mut gen = RayGen {
            cam,
            org,
            offset,
            prepared: Vec::new(),
        };
        let w = cam.width as usize;
        gen.prepared = (0..cam.pixel_count())
            .into_par_iter()
            .map(|p| gen.prepare((p % w) as u32, (p / w) as u32))
            .collect();
        gen
    }

    /// The prepared ray of pixel (x, y).
    #[inline]
    fn ray(&self, x: u32, y: u32) -> EmbreeRay {
        self.prepared[y as usize * self.cam.width as usize + x as usize]
    }

    fn prepare(&self, x: u32, y: u32) -> EmbreeRay {
        let (sx, sy) = self.cam.screen(x, y);
        EmbreeRay::at(self.cam, self.offset, sx, sy)
    }

    /// Planar depth of a hit at ray parameter `t`, rounded once to f32.
    #[inline]
    fn depth(&self, r: &EmbreeRay, t: f32) -> f32 {
        EmbreeRay::depth(self.offset, r.planar, t)
    }

    /// The core's visibility interval, applied to the rounded depth.
    #[inline]
    fn depth_in_range(&self, z: f32) -> std::cmp::Ordering {
        let zf = f64::from(z);
        if zf < self.cam.near {
            std::cmp::Ordering::Less
        } else if zf > self.cam.far {
            std::cmp::Ordering::Greater
        } else {
            std::cmp::Ordering::Equal
        }
    }
}

/// The loaded library: function pointers plus the [`Library`] that keeps them valid.
struct Api {
    new_device: unsafe extern "C" fn(*const c_char) -> ffi::Device,
    release_device: unsafe extern "C" fn(ffi::Device),
    get_device_property: unsafe extern "C" fn(ffi::Device, u32) -> isize,
    get_device_error: unsafe extern "C" fn(ffi::Device) -> u32,
    set_device_error_function:
        unsafe extern "C" fn(ffi::Device, Option<ffi::ErrorFunction>, *mut c_void),
    new_scene: unsafe extern "C" fn(ffi::Device) -> ffi::Scene,
    release_scene: unsafe extern "C" fn(ffi::Scene),
    set_scene_flags: unsafe extern "C" fn(ffi::Scene, u32),
    set_scene_build_quality: unsafe extern "C" fn(ffi::Scene, u32),
    attach_geometry: unsafe extern "C" fn(ffi::Scene, ffi::Geometry) -> u32,
    commit_scene: unsafe extern "C" fn(ffi::Scene),
    new_geometry: unsafe extern "C" fn(ffi::Device, u32) -> ffi::Geometry,
    #[allow(clippy::type_complexity)]
    set_shared_geometry_buffer:
        unsafe extern "C" fn(ffi::Geometry, u32, u32, u32, *const c_void, usize, usize, usize),
    commit_geometry: unsafe extern "C" fn(ffi::Geometry),
    release_geometry: unsafe extern "C" fn(ffi::Geometry),
    intersect1: unsafe extern "C" fn(ffi::Scene, *mut ffi::IntersectContext, *mut ffi::RayHit),
    intersect4: ffi::IntersectN<4>,
    intersect8: ffi::IntersectN<8>,
    intersect16: ffi::IntersectN<16>,
    intersect1m:
        unsafe extern "C" fn(ffi::Scene, *mut ffi::IntersectContext, *mut ffi::RayHit, u32, usize),
    /// `rtcIntersectNM`: the packets' type (`RTCRayHitN`) is opaque in C.
    intersect_nm:
        unsafe extern "C" fn(ffi::Scene, *mut ffi::IntersectContext, *mut c_void, u32, u32, usize),
    /// Never dropped (the `Api` lives in a static), so the pointers above stay valid.
    _lib: Library,
}

static API: OnceLock<Result<Api, String>> = OnceLock::new();

/// The process-wide loaded library, or why it is unavailable (tried once).
fn api() -> Result<&'static Api, EmbreeError> {
    API.get_or_init(load)
        .as_ref()
        .map_err(|e| EmbreeError::Unavailable(e.clone()))
}

fn load() -> Result<Api, String> {
    let mut tried = Vec::new();
    let mut lib = None;
    for name in LIBRARY_NAMES {
        // SAFETY: loading Embree runs its (and TBB's) static initializers, which
        // have no preconditions; we load it by its well-known soname only.
        match unsafe { Library::new(name) } {
            Ok(l) => {
                lib = Some(l);
                break;
            }
            Err(e) => tried.push(format!("{name}: {e}")),
        }
    }
    let lib = lib.ok_or_else(|| format!("{INSTALL_HINT} (tried {})", tried.join("; ")))?;
    macro_rules! sym {
        ($name:literal) => {
            // SAFETY: the symbol's type is transcribed from Embree 3.13's
            // headers (rtcore_*.h); the pointer is copied out and used only
            // while `lib`, moved into the returned `Api`, stays loaded.
            *unsafe { lib.get(concat!($name, "\0").as_bytes()) }
                .map_err(|e| format!("libembree3 lacks {}: {e}", $name))?
        };
    }
    Ok(Api {
        new_device: sym!("rtcNewDevice"),
        release_device: sym!("rtcReleaseDevice"),
        get_device_property: sym!("rtcGetDeviceProperty"),
        get_device_error: sym!("rtcGetDeviceError"),
        set_device_error_function: sym!("rtcSetDeviceErrorFunction"),
        new_scene: sym!("rtcNewScene"),
        release_scene: sym!("rtcReleaseScene"),
        set_scene_flags: sym!("rtcSetSceneFlags"),
        set_scene_build_quality: sym!("rtcSetSceneBuildQuality"),
        attach_geometry: sym!("rtcAttachGeometry"),
        commit_scene: sym!("rtcCommitScene"),
        new_geometry: sym!("rtcNewGeometry"),
        set_shared_geometry_buffer: sym!("rtcSetSharedGeometryBuffer"),
        commit_geometry: sym!("rtcCommitGeometry"),
        release_geometry: sym!("rtcReleaseGeometry"),
        intersect1: sym!("rtcIntersect1"),
        intersect4: sym!("rtcIntersect4"),
        intersect8: sym!("rtcIntersect8"),
        intersect16: sym!("rtcIntersect16"),
        intersect1m: sym!("rtcIntersect1M"),
        intersect_nm: sym!("rtcIntersectNM"),
        _lib: lib,
    })
}

/// Messages Embree reported through its error callback since the last check.
type ErrorLog = Mutex<Vec<String>>;

extern "C" fn on_error(user: *mut c_void, code: u32, msg: *const c_char) {
    let text = if msg.is_null() {
        String::new()
    } else {
        // SAFETY: Embree passes a NUL-terminated message valid for this call.
        unsafe { CStr::from_ptr(msg) }
            .to_string_lossy()
            .into_owned()
    };
    // SAFETY: `user` is the `ErrorLog` boxed in `Device`, which outlives the
    // device handle (released in `Device::drop` before the box is freed).
    let log = unsafe { &*(user as *const ErrorLog) };
    if let Ok(mut v) = log.lock() {
        v.push(format!("{}: {text}", ffi::error_name(code)));
    }
}

/// An Embree device (RAII): released on drop, after every scene built on it.
struct Device {
    api: &'static Api,
    raw: ffi::Device,
    errors: Box<ErrorLog>,
}

impl Device {
    fn new(api: &'static Api, threads: usize) -> Result<Device, EmbreeError> {
        let config = CString::new(format!("threads={}", threads.max(1))).expect("no NUL");
        // SAFETY: `config` is a valid NUL-terminated string for the duration of the call.
        let raw = unsafe { (api.new_device)(config.as_ptr()) };
        if raw.is_null() {
            // SAFETY: a null device asks for the thread-local error of the failed creation.
            let code = unsafe { (api.get_device_error)(std::ptr::null_mut()) };
            return Err(EmbreeError::Failed(format!(
                "rtcNewDevice(\"threads={threads}\"): {}",
                ffi::error_name(code)
            )));
        }
        let errors: Box<ErrorLog> = Box::default();
        // SAFETY: `raw` is live; the user pointer is the boxed log, which lives
        // as long as this `Device` (dropped after `release_device`).
        unsafe {
            (api.set_device_error_function)(
                raw,
                Some(on_error),
                &*errors as *const ErrorLog as *mut c_void,
            )
        };
        let device = Device { api, raw, errors };
        // SAFETY: `raw` is live; property queries have no other preconditions.
        let culling = unsafe {
            (api.get_device_property)(raw, ffi::DEVICE_PROPERTY_BACKFACE_CULLING_ENABLED)
        };
        if culling != 0 {
            return Err(EmbreeError::Failed(
                "this libembree3 was built with back-face culling, which docs/DESIGN.md forbids"
                    .into(),
            ));
        }
        device.check("rtcNewDevice")?;
        Ok(device)
    }

    /// Maps a pending device error (and any callback messages) to [`EmbreeError::Failed`].
    fn check(&self, what: &str) -> Result<(), EmbreeError> {
        // SAFETY: `self.raw` is a live device.
        let code = unsafe { (self.api.get_device_error)(self.raw) };
        let messages = self
            .errors
            .lock()
            .map(|mut v| std::mem::take(&mut *v))
            .unwrap_or_default();
        if code == ffi::ERROR_NONE && messages.is_empty() {
            return Ok(());
        }
        let mut s = format!("{what}: {}", ffi::error_name(code));
        for m in messages {
            s.push_str("; ");
            s.push_str(&m);
        }
        Err(EmbreeError::Failed(s))
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        // SAFETY: `raw` is live and released exactly once; scenes built on it
        // hold their own reference, and `BuiltScene` releases them first.
        unsafe { (self.api.release_device)(self.raw) };
    }
}

/// A committed Embree scene over the resolved triangles, with the shared
/// buffers it reads (RAII: scene released before buffers and device).
struct BuiltScene {
    raw: ffi::Scene,
    /// Shared vertex buffer: 3 unshared vertices per triangle, padded by one
    /// float so Embree's 16-byte load of the last vertex stays in bounds.
    _vertices: Vec<f32>,
    /// Shared index buffer `0..3N`.
    _indices: Vec<u32>,
    /// Dropped after `raw` is released (field order).
    device: Device,
}

// SAFETY: after `rtcCommitScene`, Embree documents `rtcIntersect*` on a scene as
// thread-safe; nothing mutates the scene, buffers or device until drop, which
// needs `&mut self` (exclusive access).
unsafe impl Sync for BuiltScene {}

impl BuiltScene {
    fn new(
        device: Device,
        scene: &ResolvedScene,
        mode: EmbreeMode,
        build: EmbreeBuild,
    ) -> Result<BuiltScene, EmbreeError> {
        let api = device.api;
        let n = scene.triangles.len();
        if n.checked_mul(3).is_none_or(|m| m > u32::MAX as usize) {
            return Err(EmbreeError::Failed(format!(
                "{n} triangles exceed Embree's 32-bit vertex indices"
            )));
        }
        let mut vertices = Vec::with_capacity(9 * n + 1);
        for t in &scene.triangles {
            for v in t {
                vertices.extend_from_slice(&v.to_array());
            }
        }
        vertices.push(0.0);
        let indices: Vec<u32> = (0..3 * n as u32).collect();
        // SAFETY: `device.raw` is live.
        let raw = unsafe { (api.new_scene)(device.raw) };
        device.check("rtcNewScene")?;
        if raw.is_null() {
            return Err(EmbreeError::Failed("rtcNewScene returned null".into()));
        }
        let built = BuiltScene {
            raw,
            _vertices: vertices,
            _indices: indices,
            device,
        };
        let dev = &built.device;
        let flags = match mode {
            EmbreeMode::Default => ffi::SCENE_FLAG_NONE,
            EmbreeMode::Robust => ffi::SCENE_FLAG_ROBUST,
        };
        // SAFETY: `raw` is a live, uncommitted scene; the arguments are valid enum values.
        unsafe {
            (api.set_scene_flags)(raw, flags);
            (api.set_scene_build_quality)(raw, build.quality());
        }
        dev.check("rtcSetSceneFlags/rtcSetSceneBuildQuality")?;
        if n > 0 {
            // SAFETY: `dev.raw` is live; TRIANGLE is a valid geometry type.
            let geom = unsafe { (api.new_geometry)(dev.raw, ffi::GEOMETRY_TYPE_TRIANGLE) };
            dev.check("rtcNewGeometry")?;
            if geom.is_null() {
                return Err(EmbreeError::Failed("rtcNewGeometry returned null".into()));
            }
            // SAFETY: both buffers are owned by `built` and outlive the scene
            // (released in `Drop` before the fields are freed); their sizes
            // match the item counts (3n vertices of 12 bytes + 4 bytes of
            // padding, n index triples of 12 bytes), strides are 4-aligned.
            // The geometry is released right after attaching: the scene holds
            // its own reference.
            unsafe {
                (api.set_shared_geometry_buffer)(
                    geom,
                    ffi::BUFFER_TYPE_VERTEX,
                    0,
                    ffi::FORMAT_FLOAT3,
                    built._vertices.as_ptr().cast(),
                    0,
                    12,
                    3 * n,
                );
                (api.set_shared_geometry_buffer)(
                    geom,
                    ffi::BUFFER_TYPE_INDEX,
                    0,
                    ffi::FORMAT_UINT3,
                    built._indices.as_ptr().cast(),
                    0,
                    12,
                    n,
                );
                (api.commit_geometry)(geom);
                let id = (api.attach_geometry)(raw, geom);
                (api.release_geometry)(geom);
                if id != 0 {
                    return Err(EmbreeError::Failed(format!(
                        "rtcAttachGeometry gave geomID {id}, expected 0"
                    )));
                }
            }
            dev.check("rtcSetSharedGeometryBuffer/rtcCommitGeometry/rtcAttachGeometry")?;
        }
        // SAFETY: `raw` is live and its geometry committed.
        unsafe { (api.commit_scene)(raw) };
        dev.check("rtcCommitScene")?;
        Ok(built)
    }

    /// Traces one pixel with `rtcIntersect1`; returns its key and how many
    /// extra rays the near-plane rule needed.
    fn trace1(&self, gen: &RayGen, ctx: &mut ffi::IntersectContext, x: u32, y: u32) -> (u64, u64) {
        let r = gen.ray(x, y);
        let mut tnear = r.tnear;
        let mut extra = 0;
        loop {
            let mut rh = ffi::RayHit::new(gen.org, r.dir, tnear, r.tfar);
            // SAFETY: the scene is committed and live; `ctx` is initialized
            // like rtcInitIntersectContext; `rh` is a 16-byte aligned RTCRayHit.
            unsafe { (self.device.api.intersect1)(self.raw, ctx, &mut rh) };
            if rh.hit.geom_id == ffi::INVALID_GEOMETRY_ID {
                return (NO_HIT, extra);
            }
            let z = gen.depth(&r, rh.ray.tfar);
            match gen.depth_in_range(z) {
                std::cmp::Ordering::Equal => return (hit_key(z, rh.hit.prim_id), extra),
                std::cmp::Ordering::Greater => return (NO_HIT, extra),
                std::cmp::Ordering::Less => {
                    // In front of `near` after rounding: look again from just beyond it.
                    tnear = rh.ray.tfar.next_up();
                    extra += 1;
                }
            }
        }
    }

    /// Writes the key of pixel `(x, y0 + dy)`, traced on a packet or stream
    /// path, into `rows` (the strip starting at row `y0`), from Embree's
    /// hit `(geom_id, prim_id, tfar)`. A hit in front of `near` after
    /// rounding (rare) is redone on the single-ray path, which re-traces
    /// from beyond it; returns the extra rays traced.
    #[allow(clippy::too_many_arguments)]
    fn store_hit(
        &self,
        gen: &RayGen,
        ctx: &mut ffi::IntersectContext,
        (geom_id, prim_id, tfar): (u32, u32, f32),
        x: u32,
        y0: u32,
        dy: u32,
        rows: &mut [u64],
    ) -> u64 {
        let (key, extra) = if geom_id == ffi::INVALID_GEOMETRY_ID {
            (NO_HIT, 0)
        } else {
            let z = gen.depth(&gen.ray(x, y0 + dy), tfar);
            match gen.depth_in_range(z) {
                std::cmp::Ordering::Equal => (hit_key(z, prim_id), 0),
                std::cmp::Ordering::Greater => (NO_HIT, 0),
                std::cmp::Ordering::Less => {
                    let (k, e) = self.trace1(gen, ctx, x, y0 + dy);
                    (k, e + 1)
                }
            }
        };
        rows[(dy * gen.cam.width + x) as usize] = key;
        extra
    }

    /// Fills `packet` with the tile of `tile_w` x `N / tile_w` pixels whose
    /// top-left pixel is (x0, y0); lane `i` is pixel `(i % tile_w, i / tile_w)`
    /// of the tile, its hit reset to none. Returns the `valid` mask: -1 for
    /// lanes in the image, 0 for lanes outside it (x >= width or row >=
    /// `nrows`), which keep whatever they held (an empty packet's tnear >
    /// tfar, so the stream API, which has no mask, skips them too).
    ///
    /// Only the mask comes back, not the lanes' rays: a packet's hits are
    /// turned into keys by reading the prepared rays again
    /// ([`BuiltScene::store_packet`]). Carrying an `Option` of every lane's
    /// ray through each call, and zeroing a fresh packet per tile, cost the
    /// packet paths up to 40% of their speed on `million`
    /// (docs/embree-fastest-path.md).
    fn fill_packet<const N: usize>(
        gen: &RayGen,
        packet: &mut ffi::RayHitN<N>,
        tile_w: u32,
        x0: u32,
        y0: u32,
        nrows: u32,
    ) -> ffi::Valid<N> {
        let w = gen.cam.width;
        let mut valid = ffi::Valid([0; N]);
        for lane in 0..N {
            let (x, dy) = (x0 + lane as u32 % tile_w, lane as u32 / tile_w);
            if x < w && dy < nrows {
                let r = gen.ray(x, y0 + dy);
                packet.set(lane, gen.org, r.dir, r.tnear, r.tfar);
                packet.hit.geom_id[lane] = ffi::INVALID_GEOMETRY_ID;
                valid.0[lane] = -1;
            }
        }
        valid
    }

    /// Writes the keys of a traced tile (see [`BuiltScene::fill_packet`],
    /// whose mask is `valid`) into `rows`, the strip starting at row `y0`;
    /// returns the extra rays traced.
    #[allow(clippy::too_many_arguments)]
    fn store_packet<const N: usize>(
        &self,
        gen: &RayGen,
        ctx: &mut ffi::IntersectContext,
        packet: &ffi::RayHitN<N>,
        valid: &ffi::Valid<N>,
        tile_w: u32,
        x0: u32,
        y0: u32,
        rows: &mut [u64],
    ) -> u64 {
        let mut extra = 0;
        for lane in 0..N {
            if valid.0[lane] == 0 {
                continue;
            }
            let (x, dy) = (x0 + lane as u32 % tile_w, lane as u32 / tile_w);
            let hit = (
                packet.hit.geom_id[lane],
                packet.hit.prim_id[lane],
                packet.ray.tfar[lane],
            );
            extra += self.store_hit(gen, ctx, hit, x, y0, dy, rows);
        }
        extra
    }

    /// Traces the strip `rows` (starting at row `y0`, at most 4 rows) with
    /// `rtcIntersect1M`: streams of up to [`STREAM_RAYS`] `RTCRayHit`, laid
    /// out tile by tile (4x4 pixels, row-major inside a tile) so that the
    /// packets Embree forms from consecutive rays are compact tiles.
    fn trace_stream1(
        &self,
        gen: &RayGen,
        ctx: &mut ffi::IntersectContext,
        y0: u32,
        rows: &mut [u64],
    ) -> u64 {
        let w = gen.cam.width;
        let nrows = (rows.len() / w as usize) as u32;
        let block_w = (STREAM_RAYS / 16 * 4) as u32;
        let mut stream: Vec<ffi::RayHit> = Vec::with_capacity(STREAM_RAYS);
        let mut pixels: Vec<(u32, u32)> = Vec::with_capacity(STREAM_RAYS);
        let mut extra = 0;
        for bx in (0..w).step_by(block_w as usize) {
            stream.clear();
            pixels.clear();
            for x0 in (bx..w.min(bx + block_w)).step_by(4) {
                for dy in 0..nrows {
                    for x in x0..w.min(x0 + 4) {
                        let r = gen.ray(x, y0 + dy);
                        stream.push(ffi::RayHit::new(gen.org, r.dir, r.tnear, r.tfar));
                        pixels.push((x, dy));
                    }
                }
            }
            // SAFETY: the scene is committed and live; `stream` holds
            // `stream.len()` (<= STREAM_RAYS) initialized, 16-byte aligned
            // RTCRayHit at a stride of their size (80 bytes, checked in
            // `ffi::layout`), read and written by Embree during the call only.
            unsafe {
                (self.device.api.intersect1m)(
                    self.raw,
                    ctx,
                    stream.as_mut_ptr(),
                    stream.len() as u32,
                    std::mem::size_of::<ffi::RayHit>(),
                )
            };
            for (rh, &(x, dy)) in stream.iter().zip(&pixels) {
                let hit = (rh.hit.geom_id, rh.hit.prim_id, rh.ray.tfar);
                extra += self.store_hit(gen, ctx, hit, x, y0, dy, rows);
            }
        }
        extra
    }

    /// Traces the strip `rows` (starting at row `y0`, `N / tile_w` rows or
    /// fewer at the bottom) in packets of `N` rays on `tile_w`-wide tiles,
    /// handed to Embree as `how` says: one packet a call with its mask
    /// (`rtcIntersect4/8/16`), or up to [`STREAM_RAYS`] / `N` packets a
    /// call (`rtcIntersectNM`, which has no mask: lanes outside the image
    /// are inactive, tnear > tfar). Either way every tile's rays and keys
    /// are the same ([`BuiltScene::fill_packet`], [`BuiltScene::store_packet`]).
    fn trace_tiles<const N: usize>(
        &self,
        gen: &RayGen,
        ctx: &mut ffi::IntersectContext,
        how: Packets<N>,
        tile_w: u32,
        y0: u32,
        rows: &mut [u64],
    ) -> u64 {
        let w = gen.cam.width;
        let nrows = (rows.len() / w as usize) as u32;
        let per_call = match how {
            Packets::Each(_) => 1,
            Packets::Stream => (STREAM_RAYS / N).max(1),
        };
        let tiles: Vec<u32> = (0..w).step_by(tile_w as usize).collect();
        // The packets are reused from call to call: each tile rewrites its
        // lanes' rays and hits (`fill_packet`). Only the stream empties a
        // packet first, as its lanes outside the image must be inactive.
        let mut packets: Vec<ffi::RayHitN<N>> =
            (0..per_call).map(|_| ffi::RayHitN::empty()).collect();
        let mut masks: Vec<ffi::Valid<N>> = (0..per_call).map(|_| ffi::Valid([0; N])).collect();
        let mut extra = 0;
        for chunk in tiles.chunks(per_call) {
            for ((p, valid), &x0) in packets.iter_mut().zip(&mut masks).zip(chunk) {
                if matches!(how, Packets::Stream) {
                    *p = ffi::RayHitN::empty();
                }
                *valid = Self::fill_packet(gen, p, tile_w, x0, y0, nrows);
            }
            match how {
                Packets::Each(intersect) => {
                    // SAFETY: the scene is committed and live; `intersect` is
                    // the rtcIntersect<N> matching `N` (typed by
                    // `IntersectN<N>`); `masks[0]` and `packets[0]` are 64-byte
                    // aligned with the RTCRayHit<N> layout (checked in
                    // `ffi::layout`); invalid lanes are masked.
                    unsafe { intersect(&masks[0], self.raw, ctx, &mut packets[0]) }
                }
                Packets::Stream => {
                    // SAFETY: the scene is committed and live; `packets` holds
                    // at least `chunk.len()` initialized RTCRayHit<N>-layout
                    // packets (64-byte aligned, checked in `ffi::layout`) at a
                    // stride of their size; unused lanes have tnear > tfar,
                    // which the stream API skips.
                    unsafe {
                        (self.device.api.intersect_nm)(
                            self.raw,
                            ctx,
                            packets.as_mut_ptr().cast(),
                            N as u32,
                            chunk.len() as u32,
                            std::mem::size_of::<ffi::RayHitN<N>>(),
                        )
                    }
                }
            }
            for ((p, valid), &x0) in packets.iter().zip(&masks).zip(chunk) {
                extra += self.store_packet(gen, ctx, p, valid, tile_w, x0, y0, rows);
            }
        }
        extra
    }
}

/// How [`BuiltScene::trace_tiles`] hands its packets of `N` rays to Embree.
#[derive(Clone, Copy)]
enum Packets<const N: usize> {
    /// One packet a call, with its valid mask: `rtcIntersect4/8/16`.
    Each(ffi::IntersectN<N>),
    /// A stream of packets a call: `rtcIntersectNM`.
    Stream,
}

impl Drop for BuiltScene {
    fn drop(&mut self) {
        // SAFETY: `raw` is live and released exactly once, before the shared
        // buffers and the device (fields) are dropped.
        unsafe { (self.device.api.release_scene)(self.raw) };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Same policy as tests/embree_backend.rs: missing Embree fails unless allowed.
    fn api_or_skip() -> Option<&'static Api> {
        match api() {
            Ok(a) => Some(a),
            Err(e) if std::env::var("RENDIFF_ALLOW_NO_EMBREE").as_deref() == Ok("1") => {
                eprintln!("SKIPPED (RENDIFF_ALLOW_NO_EMBREE=1): {e}");
                None
            }
            Err(e) => panic!("{e}"),
        }
    }

    #[test]
    fn device_errors_are_reported_with_their_code_name() {
        let Some(api) = api_or_skip() else { return };
        let device = Device::new(api, 1).unwrap();
        device.check("fresh device").unwrap();
        // SAFETY: `device.raw` is live; the geometry is released below. The
        // buffer call is invalid on purpose (stride not a multiple of 4), so
        // Embree rejects it without reading `data`.
        unsafe {
            let geom = (api.new_geometry)(device.raw, ffi::GEOMETRY_TYPE_TRIANGLE);
            let data = [0f32; 16];
            (api.set_shared_geometry_buffer)(
                geom,
                ffi::BUFFER_TYPE_VERTEX,
                0,
                ffi::FORMAT_FLOAT3,
                data.as_ptr().cast(),
                0,
                13,
                3,
            );
            (api.release_geometry)(geom);
        }
        let err = device.check("rtcSetSharedGeometryBuffer").unwrap_err();
        let text = err.to_string();
        // Code name from rtcGetDeviceError, message from the error callback.
        assert!(text.contains("RTC_ERROR_INVALID_OPERATION"), "{text}");
        assert!(text.contains("aligned"), "{text}");
        // The error is consumed: the device is usable again.
        device.check("after").unwrap();
    }
}

/// Hand-written bindings for the parts of Embree 3.13's C API used here.
/// Layouts follow rtcore_ray.h / rtcore_common.h with
/// `RTC_MAX_INSTANCE_LEVEL_COUNT == 1` and `RTC_MIN_WIDTH == 0` (Debian's build).
mod ffi {
    use std::ffi::{c_char, c_void};

    pub type Device = *mut c_void;
    pub type Scene = *mut c_void;
    pub type Geometry = *mut c_void;
    pub type ErrorFunction = extern "C" fn(*mut c_void, u32, *const c_char);

    pub const DEVICE_PROPERTY_VERSION_MAJOR: u32 = 1;
    pub const DEVICE_PROPERTY_VERSION_MINOR: u32 = 2;
    pub const DEVICE_PROPERTY_VERSION_PATCH: u32 = 3;
    pub const DEVICE_PROPERTY_NATIVE_RAY4_SUPPORTED: u32 = 32;
    pub const DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED: u32 = 33;
    pub const DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED: u32 = 34;
    pub const DEVICE_PROPERTY_RAY_STREAM_SUPPORTED: u32 = 35;
    pub const DEVICE_PROPERTY_BACKFACE_CULLING_ENABLED: u32 = 65;
    pub const ERROR_NONE: u32 = 0;
    pub const SCENE_FLAG_NONE: u32 = 0;
    pub const SCENE_FLAG_ROBUST: u32 = 1 << 2;
    pub const BUILD_QUALITY_MEDIUM: u32 = 1;
    pub const BUILD_QUALITY_HIGH: u32 = 2;
    pub const GEOMETRY_TYPE_TRIANGLE: u32 = 0;
    pub const BUFFER_TYPE_INDEX: u32 = 0;
    pub const BUFFER_TYPE_VERTEX: u32 = 1;
    pub const FORMAT_UINT3: u32 = 0x5003;
    pub const FORMAT_FLOAT3: u32 = 0x9003;
    pub const INVALID_GEOMETRY_ID: u32 = u32::MAX;
    pub const INTERSECT_CONTEXT_FLAG_INCOHERENT: u32 = 0;
    pub const INTERSECT_CONTEXT_FLAG_COHERENT: u32 = 1;

    /// The `RTCError` enum's names, for messages.
    pub fn error_name(code: u32) -> String {
        match code {
            0 => "RTC_ERROR_NONE".into(),
            1 => "RTC_ERROR_UNKNOWN".into(),
            2 => "RTC_ERROR_INVALID_ARGUMENT".into(),
            3 => "RTC_ERROR_INVALID_OPERATION".into(),
            4 => "RTC_ERROR_OUT_OF_MEMORY".into(),
            5 => "RTC_ERROR_UNSUPPORTED_CPU".into(),
            6 => "RTC_ERROR_CANCELLED".into(),
            c => format!("RTC_ERROR({c})"),
        }
    }

    /// `struct RTCIntersectContext` (flags, filter, instID[1]).
    #[repr(C)]
    pub struct IntersectContext {
        flags: u32,
        filter: Option<unsafe extern "C" fn(*const c_void)>,
        inst_id: [u32; 1],
    }

    impl IntersectContext {
        /// `rtcInitIntersectContext` (inline in the header), then `flags`
        /// (`INTERSECT_CONTEXT_FLAG_*`) instead of its INCOHERENT.
        pub fn new(flags: u32) -> Self {
            IntersectContext {
                flags,
                filter: None,
                inst_id: [INVALID_GEOMETRY_ID],
            }
        }
    }

    /// `struct RTCRay` (16-byte aligned).
    #[repr(C, align(16))]
    pub struct Ray {
        pub org: [f32; 3],
        pub tnear: f32,
        pub dir: [f32; 3],
        pub time: f32,
        pub tfar: f32,
        pub mask: u32,
        pub id: u32,
        pub flags: u32,
    }

    /// `struct RTCHit` (16-byte aligned).
    #[repr(C, align(16))]
    pub struct Hit {
        pub ng: [f32; 3],
        pub u: f32,
        pub v: f32,
        pub prim_id: u32,
        pub geom_id: u32,
        pub inst_id: [u32; 1],
    }

    /// `struct RTCRayHit`.
    #[repr(C, align(16))]
    pub struct RayHit {
        pub ray: Ray,
        pub hit: Hit,
    }

    impl RayHit {
        pub fn new(org: [f32; 3], dir: [f32; 3], tnear: f32, tfar: f32) -> Self {
            RayHit {
                ray: Ray {
                    org,
                    tnear,
                    dir,
                    time: 0.0,
                    tfar,
                    mask: u32::MAX,
                    id: 0,
                    flags: 0,
                },
                hit: Hit {
                    ng: [0.0; 3],
                    u: 0.0,
                    v: 0.0,
                    prim_id: INVALID_GEOMETRY_ID,
                    geom_id: INVALID_GEOMETRY_ID,
                    inst_id: [INVALID_GEOMETRY_ID],
                },
            }
        }
    }

    /// `struct RTCRay4/8/16` (structure of arrays). Aligned to 64 bytes for
    /// every `N`: C aligns them to 16/32/64 bytes, and for N = 4, 8, 16 every
    /// array field is 4N bytes and the struct 12 * 4N, a multiple of 64, so
    /// the stricter alignment adds no padding and keeps C's layout.
    #[repr(C, align(64))]
    pub struct RayN<const N: usize> {
        pub org_x: [f32; N],
        pub org_y: [f32; N],
        pub org_z: [f32; N],
        pub tnear: [f32; N],
        pub dir_x: [f32; N],
        pub dir_y: [f32; N],
        pub dir_z: [f32; N],
        pub time: [f32; N],
        pub tfar: [f32; N],
        pub mask: [u32; N],
        pub id: [u32; N],
        pub flags: [u32; N],
    }

    /// `struct RTCHit4/8/16` (8 arrays of N: a multiple of 64 bytes too).
    #[repr(C, align(64))]
    pub struct HitN<const N: usize> {
        pub ng_x: [f32; N],
        pub ng_y: [f32; N],
        pub ng_z: [f32; N],
        pub u: [f32; N],
        pub v: [f32; N],
        pub prim_id: [u32; N],
        pub geom_id: [u32; N],
        pub inst_id: [[u32; N]; 1],
    }

    /// `struct RTCRayHit4/8/16`, and one packet of `rtcIntersectNM`'s `RTCRayHitN`.
    #[repr(C, align(64))]
    pub struct RayHitN<const N: usize> {
        pub ray: RayN<N>,
        pub hit: HitN<N>,
    }

    impl<const N: usize> RayHitN<N> {
        /// All lanes empty (tnear > tfar, so even an unmasked lane would miss,
        /// and the stream API treats the lane as inactive).
        pub fn empty() -> Self {
            RayHitN {
                ray: RayN {
                    org_x: [0.0; N],
                    org_y: [0.0; N],
                    org_z: [0.0; N],
                    tnear: [1.0; N],
                    dir_x: [0.0; N],
                    dir_y: [0.0; N],
                    dir_z: [1.0; N],
                    time: [0.0; N],
                    tfar: [0.0; N],
                    mask: [u32::MAX; N],
                    id: [0; N],
                    flags: [0; N],
                },
                hit: HitN {
                    ng_x: [0.0; N],
                    ng_y: [0.0; N],
                    ng_z: [0.0; N],
                    u: [0.0; N],
                    v: [0.0; N],
                    prim_id: [INVALID_GEOMETRY_ID; N],
                    geom_id: [INVALID_GEOMETRY_ID; N],
                    inst_id: [[INVALID_GEOMETRY_ID; N]; 1],
                },
            }
        }

        pub fn set(&mut self, lane: usize, org: [f32; 3], dir: [f32; 3], tnear: f32, tfar: f32) {
            let r = &mut self.ray;
            (r.org_x[lane], r.org_y[lane], r.org_z[lane]) = (org[0], org[1], org[2]);
            (r.dir_x[lane], r.dir_y[lane], r.dir_z[lane]) = (dir[0], dir[1], dir[2]);
            r.tnear[lane] = tnear;
            r.tfar[lane] = tfar;
        }
    }

    /// The `valid` mask of `rtcIntersect4/8/16`: -1 traces the lane, 0 skips
    /// it. Aligned like the packet (64 bytes covers C's 16/32/64).
    #[repr(C, align(64))]
    pub struct Valid<const N: usize>(pub [i32; N]);

    /// `rtcIntersect4/8/16`, typed so that a packet of N rays can only go to
    /// the function for N.
    pub type IntersectN<const N: usize> =
        unsafe extern "C" fn(*const Valid<N>, Scene, *mut IntersectContext, *mut RayHitN<N>);

    #[cfg(test)]
    mod layout {
        use super::*;
        use std::mem::{align_of, offset_of, size_of};

        #[test]
        fn structs_match_the_c_headers() {
            assert_eq!(size_of::<Ray>(), 48);
            assert_eq!(size_of::<Hit>(), 32);
            assert_eq!(size_of::<RayHit>(), 80);
            assert_eq!(offset_of!(RayHit, hit), 48);
            assert_eq!(offset_of!(Ray, tfar), 32);
            assert_eq!(offset_of!(Hit, prim_id), 20);
            assert_eq!(align_of::<RayHit>(), 16);
            // RTCRayHit4/8/16: fields of 4N bytes, no padding anywhere.
            fn packet<const N: usize>() {
                let a = 4 * N;
                assert_eq!(size_of::<RayN<N>>(), 12 * a, "RTCRay{N}");
                assert_eq!(offset_of!(RayN<N>, tfar), 8 * a, "RTCRay{N}");
                assert_eq!(offset_of!(RayN<N>, flags), 11 * a, "RTCRay{N}");
                assert_eq!(size_of::<HitN<N>>(), 8 * a, "RTCHit{N}");
                assert_eq!(offset_of!(HitN<N>, prim_id), 5 * a, "RTCHit{N}");
                assert_eq!(offset_of!(HitN<N>, geom_id), 6 * a, "RTCHit{N}");
                assert_eq!(offset_of!(RayHitN<N>, hit), 12 * a, "RTCRayHit{N}");
                assert_eq!(size_of::<RayHitN<N>>(), 20 * a, "RTCRayHit{N}");
                assert!(align_of::<RayHitN<N>>() >= a.min(64), "RTCRayHit{N}");
                assert!(align_of::<Valid<N>>() >= a.min(64), "valid{N}");
                assert_eq!(std::mem::offset_of!(Valid<N>, 0), 0);
            }
            packet::<4>();
            packet::<8>();
            packet::<16>();
            assert_eq!(size_of::<IntersectContext>(), 24);
            assert_eq!(offset_of!(IntersectContext, inst_id), 16);
        }
    }
}
