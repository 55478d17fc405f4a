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
use crate::visibility::{hit_key, Counters, NO_HIT};
use libloading::Library;
use rayon::prelude::*;
use std::ffi::{c_char, c_void, CStr, CString};
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

/// How rays are handed to Embree: one at a time (the reference path) or in
/// packets of eight (for throughput measurements).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EmbreeQuery {
    /// `rtcIntersect1` per pixel.
    #[default]
    Single,
    /// `rtcIntersect8` on 4x2 pixel tiles (masked at the image border).
    Packet8,
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
    /// Tracing all pixel rays and assembling keys.
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

/// Renders depth and IDs with `rtcIntersect1` per pixel (the reference path):
/// rows in parallel on rayon's current pool, device `threads=N` matching it.
/// `Frame::seconds` covers device creation, BVH build and tracing.
pub fn render(scene: &ResolvedScene, mode: EmbreeMode) -> Result<Frame, EmbreeError> {
    render_timed(scene, mode, EmbreeQuery::Single).map(|(f, _)| f)
}

/// Like [`render`] but with `rtcIntersect8` on 4x2 tiles: Embree's faster
/// coherent path, measured separately because its results may differ from the
/// single-ray path in ROBUST mode.
pub fn render_packets(scene: &ResolvedScene, mode: EmbreeMode) -> Result<Frame, EmbreeError> {
    render_timed(scene, mode, EmbreeQuery::Packet8).map(|(f, _)| f)
}

/// Renders with the chosen query path and returns the timing split as well
/// (for benchmarks that separate BVH build from tracing).
pub fn render_timed(
    scene: &ResolvedScene,
    mode: EmbreeMode,
    query: EmbreeQuery,
) -> Result<(Frame, EmbreeTimings), EmbreeError> {
    let start = Instant::now();
    let api = api()?;
    let threads = rayon::current_num_threads();
    let device = Device::new(api, threads)?;
    let device_seconds = start.elapsed().as_secs_f64();
    let t_build = Instant::now();
    let built = BuiltScene::new(device, scene, mode)?;
    let build_seconds = t_build.elapsed().as_secs_f64();
    let t_trace = Instant::now();
    let cam = &scene.camera;
    let rays = RayGen::new(cam);
    let mut keys = vec![NO_HIT; cam.pixel_count()];
    let w = cam.width as usize;
    let retraces: u64 = match query {
        EmbreeQuery::Single => keys
            .par_chunks_mut(w)
            .enumerate()
            .map(|(y, row)| {
                let mut ctx = ffi::IntersectContext::new();
                let mut n = 0;
                for (x, k) in row.iter_mut().enumerate() {
                    let (key, extra) = built.trace1(&rays, &mut ctx, x as u32, y as u32);
                    *k = key;
                    n += extra;
                }
                n
            })
            .sum(),
        EmbreeQuery::Packet8 => keys
            .par_chunks_mut(2 * w)
            .enumerate()
            .map(|(ty, rows)| {
                let mut ctx = ffi::IntersectContext::new();
                built.trace_rows8(&rays, &mut ctx, 2 * ty as u32, rows)
            })
            .sum(),
    };
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
            trace_seconds,
            rays: cam.pixel_count() as u64 + retraces,
        },
    ))
}

/// Per-render constants that turn the core's pixel rays into Embree rays.
struct RayGen<'a> {
    cam: &'a Camera,
    /// The eye rounded to f32: every ray's origin.
    org: [f32; 3],
    /// `(org - eye)·forward`: planar depth of the f32 origin.
    offset: f64,
}

/// One pixel's ray in Embree's precision, with its depth conversion.
struct EmbreeRay {
    dir: [f32; 3],
    /// `D32·forward`: planar depth per unit of `t`.
    planar: f64,
    tnear: f32,
    tfar: f32,
}

impl<'a> RayGen<'a> {
    fn new(cam: &'a Camera) -> Self {
        let org = cam.eye.as_vec3();
        RayGen {
            cam,
            org: org.to_array(),
            offset: (org.as_dvec3() - cam.eye).dot(cam.forward),
        }
    }

    fn ray(&self, x: u32, y: u32) -> EmbreeRay {
        let pr: PixelRay = self.cam.pixel_ray(x, y);
        let d = pr.dir.as_vec3();
        let planar = d.as_dvec3().dot(self.cam.forward);
        // Widened by 1e-6 relative so rounding never hides a hit inside [near, far];
        // `depth_in_range` then applies the exact rule on the rounded depth.
        let tnear = ((self.cam.near - self.offset) / planar * (1.0 - 1e-6)).max(0.0) as f32;
        let tfar = if self.cam.far.is_finite() {
            ((self.cam.far - self.offset) / planar * (1.0 + 1e-6)) as f32
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
    fn depth(&self, r: &EmbreeRay, t: f32) -> f32 {
        (self.offset + f64::from(t) * r.planar) as f32
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
    intersect8: unsafe extern "C" fn(
        *const ffi::Valid8,
        ffi::Scene,
        *mut ffi::IntersectContext,
        *mut ffi::RayHit8,
    ),
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
        intersect8: sym!("rtcIntersect8"),
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
            (api.set_scene_build_quality)(raw, ffi::BUILD_QUALITY_MEDIUM);
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

    /// Traces rows `y0` and `y0 + 1` (those present in `rows`) in 4x2 packets.
    fn trace_rows8(
        &self,
        gen: &RayGen,
        ctx: &mut ffi::IntersectContext,
        y0: u32,
        rows: &mut [u64],
    ) -> u64 {
        let w = gen.cam.width;
        let nrows = (rows.len() / w as usize) as u32;
        let mut extra = 0;
        for x0 in (0..w).step_by(4) {
            let mut valid = ffi::Valid8([0; 8]);
            let mut packet = ffi::RayHit8::empty();
            let mut planar = [0.0f64; 8];
            let mut rays: [Option<EmbreeRay>; 8] = Default::default();
            for lane in 0..8 {
                let (x, dy) = (x0 + lane as u32 % 4, lane as u32 / 4);
                if x >= w || dy >= nrows {
                    continue;
                }
                let r = gen.ray(x, y0 + dy);
                valid.0[lane] = -1;
                packet.set(lane, gen.org, r.dir, r.tnear, r.tfar);
                planar[lane] = r.planar;
                rays[lane] = Some(r);
            }
            // SAFETY: the scene is committed and live; `valid` and `packet` are
            // 32-byte aligned RTCRayHit8-layout structs; invalid lanes are masked.
            unsafe { (self.device.api.intersect8)(&valid, self.raw, ctx, &mut packet) };
            for (lane, r) in rays.iter().enumerate() {
                let Some(r) = r else { continue };
                let (x, dy) = (x0 + lane as u32 % 4, lane as u32 / 4);
                let key = if packet.hit.geom_id[lane] == ffi::INVALID_GEOMETRY_ID {
                    NO_HIT
                } else {
                    let z = gen.depth(r, packet.ray.tfar[lane]);
                    match gen.depth_in_range(z) {
                        std::cmp::Ordering::Equal => hit_key(z, packet.hit.prim_id[lane]),
                        std::cmp::Ordering::Greater => NO_HIT,
                        // Rare: redo this pixel on the single-ray path.
                        std::cmp::Ordering::Less => {
                            let (k, e) = self.trace1(gen, ctx, x, y0 + dy);
                            extra += e + 1;
                            k
                        }
                    }
                };
                rows[(dy * w + x) as usize] = key;
            }
        }
        extra
    }
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
    pub const DEVICE_PROPERTY_BACKFACE_CULLING_ENABLED: u32 = 65;
    pub const ERROR_NONE: u32 = 0;
    pub const SCENE_FLAG_NONE: u32 = 0;
    pub const SCENE_FLAG_ROBUST: u32 = 1 << 2;
    pub const BUILD_QUALITY_MEDIUM: u32 = 1;
    pub const GEOMETRY_TYPE_TRIANGLE: u32 = 0;
    pub const BUFFER_TYPE_INDEX: u32 = 0;
    pub const BUFFER_TYPE_VERTEX: u32 = 1;
    pub const FORMAT_UINT3: u32 = 0x5003;
    pub const FORMAT_FLOAT3: u32 = 0x9003;
    pub const INVALID_GEOMETRY_ID: u32 = u32::MAX;
    const INTERSECT_CONTEXT_FLAG_INCOHERENT: u32 = 0;

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
        /// `rtcInitIntersectContext`, which is inline in the header.
        pub fn new() -> Self {
            IntersectContext {
                flags: INTERSECT_CONTEXT_FLAG_INCOHERENT,
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

    /// `struct RTCRay8` (32-byte aligned, structure of arrays).
    #[repr(C, align(32))]
    pub struct Ray8 {
        pub org_x: [f32; 8],
        pub org_y: [f32; 8],
        pub org_z: [f32; 8],
        pub tnear: [f32; 8],
        pub dir_x: [f32; 8],
        pub dir_y: [f32; 8],
        pub dir_z: [f32; 8],
        pub time: [f32; 8],
        pub tfar: [f32; 8],
        pub mask: [u32; 8],
        pub id: [u32; 8],
        pub flags: [u32; 8],
    }

    /// `struct RTCHit8` (32-byte aligned).
    #[repr(C, align(32))]
    pub struct Hit8 {
        pub ng_x: [f32; 8],
        pub ng_y: [f32; 8],
        pub ng_z: [f32; 8],
        pub u: [f32; 8],
        pub v: [f32; 8],
        pub prim_id: [u32; 8],
        pub geom_id: [u32; 8],
        pub inst_id: [[u32; 8]; 1],
    }

    /// `struct RTCRayHit8`.
    #[repr(C, align(32))]
    pub struct RayHit8 {
        pub ray: Ray8,
        pub hit: Hit8,
    }

    impl RayHit8 {
        /// All lanes empty (tnear > tfar, so even an unmasked lane would miss).
        pub fn empty() -> Self {
            RayHit8 {
                ray: Ray8 {
                    org_x: [0.0; 8],
                    org_y: [0.0; 8],
                    org_z: [0.0; 8],
                    tnear: [1.0; 8],
                    dir_x: [0.0; 8],
                    dir_y: [0.0; 8],
                    dir_z: [1.0; 8],
                    time: [0.0; 8],
                    tfar: [0.0; 8],
                    mask: [u32::MAX; 8],
                    id: [0; 8],
                    flags: [0; 8],
                },
                hit: Hit8 {
                    ng_x: [0.0; 8],
                    ng_y: [0.0; 8],
                    ng_z: [0.0; 8],
                    u: [0.0; 8],
                    v: [0.0; 8],
                    prim_id: [INVALID_GEOMETRY_ID; 8],
                    geom_id: [INVALID_GEOMETRY_ID; 8],
                    inst_id: [[INVALID_GEOMETRY_ID; 8]; 1],
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

    /// The `valid` mask of `rtcIntersect8`: -1 traces the lane, 0 skips it.
    #[repr(C, align(32))]
    pub struct Valid8(pub [i32; 8]);

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
            assert_eq!(size_of::<Ray8>(), 12 * 32);
            assert_eq!(size_of::<Hit8>(), 8 * 32);
            assert_eq!(offset_of!(RayHit8, hit), 12 * 32);
            assert_eq!(offset_of!(Hit8, geom_id), 6 * 32);
            assert_eq!(align_of::<RayHit8>(), 32);
            assert_eq!(size_of::<IntersectContext>(), 24);
            assert_eq!(offset_of!(IntersectContext, inst_id), 16);
        }
    }
}
