//! A native Embree application for primary rays (native/embree_driver.c,
//! compiled against Embree's own headers by build.rs), driven from here:
//! the yardstick `bench peers` holds its Embree numbers against, so that
//! Embree is never reported below its best without the bench saying so
//! (docs/embree-fastest-path.md).
//!
//! What it does is what an Embree application does for primary rays: the
//! rays, in f32 ([`crate::embree_rays`]), go into Embree's own layout for
//! the entry point measured (`RTCRayHit`, `RTCRayHit4/8/16`, streams of
//! either) and are traced with flush-to-zero and denormals-are-zero set, as
//! Embree's documentation recommends; the hit distance and primitive ID of
//! each pixel come back ([`Hits`]) and become the core's hit keys
//! afterwards, untimed. The rays are either prepared once for the whole
//! image outside timing ([`NativeScene::trace`]: the trace alone) or made
//! strip by strip inside the timed call ([`NativeScene::trace_made`]: what
//! a frame costs an application, the core's rays being made inside its
//! timed queries too).
//! Rows of 4 pixels are traced in parallel on rayon's current pool, the
//! scheduler the core's tracer uses.
//!
//! The rays follow the core binding's convention (backends/embree.rs, module
//! doc): origin the eye rounded to f32, direction the core's pixel ray
//! rounded to f32, `tnear`/`tfar` from the camera's `near`/`far`, widened by
//! 1e-6 relative; so its hits must equal the binding's exactly (tested).
//! Unlike the binding it does not re-trace a hit found in front of `near`
//! after rounding; [`Hits::keys`] counts such pixels, and the bench records
//! them.

pub use crate::embree_rays::{CameraRays, PreparedRays};
use crate::embree_rays::{RayDepth, StripRays};
use rayon::prelude::*;
use rendiff::backends::embree::EmbreeRay;
use rendiff::frame::Frame;
use rendiff::scene::resolve::ResolvedScene;
use rendiff::visibility::{hit_key, Counters, NO_HIT};
use std::time::Instant;

/// Why the driver was not compiled in (empty when it was), from build.rs.
const ABSENT: &str = include_str!(concat!(env!("OUT_DIR"), "/native_embree_absent.txt"));

/// Rows per parallel work item: a multiple of every tile height (2 and 4).
const STRIP_ROWS: usize = 4;

/// An Embree entry point for primary rays, as the driver calls it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Entry {
    /// `rtcIntersect1` per pixel.
    One,
    /// `rtcIntersect4` on 2x2 tiles.
    Four,
    /// `rtcIntersect8` on 4x2 tiles.
    Eight,
    /// `rtcIntersect16` on 4x4 tiles.
    Sixteen,
    /// `rtcIntersect1M` on up to 1024 `RTCRayHit` in 4x4-tile order.
    Stream1M,
    /// `rtcIntersectNM` with N = 4 (2x2 tiles), 1024 rays per call.
    StreamN4,
    /// `rtcIntersectNM` with N = 8 (4x2 tiles), 1024 rays per call.
    StreamN8,
    /// `rtcIntersectNM` with N = 16 (4x4 tiles), 1024 rays per call.
    StreamN16,
}

impl Entry {
    /// Every entry point, in the driver's numbering.
    pub const ALL: [Entry; 8] = [
        Entry::One,
        Entry::Four,
        Entry::Eight,
        Entry::Sixteen,
        Entry::Stream1M,
        Entry::StreamN4,
        Entry::StreamN8,
        Entry::StreamN16,
    ];

    /// The C function called, for reports.
    pub fn entry_point(self) -> &'static str {
        match self {
            Entry::One => "rtcIntersect1",
            Entry::Four => "rtcIntersect4",
            Entry::Eight => "rtcIntersect8",
            Entry::Sixteen => "rtcIntersect16",
            Entry::Stream1M => "rtcIntersect1M",
            Entry::StreamN4 => "rtcIntersectNM (N=4)",
            Entry::StreamN8 => "rtcIntersectNM (N=8)",
            Entry::StreamN16 => "rtcIntersectNM (N=16)",
        }
    }

    /// Short name for JSON keys.
    pub fn name(self) -> &'static str {
        match self {
            Entry::One => "single",
            Entry::Four => "packet4",
            Entry::Eight => "packet8",
            Entry::Sixteen => "packet16",
            Entry::Stream1M => "stream1M",
            Entry::StreamN4 => "streamNM4",
            Entry::StreamN8 => "streamNM8",
            Entry::StreamN16 => "streamNM16",
        }
    }

    /// The driver's number for it (`RD_*` in embree_driver.c).
    fn code(self) -> i32 {
        Entry::ALL.iter().position(|&e| e == self).unwrap_or(0) as i32
    }
}

/// Embree's BVH build quality (`rtcSetSceneBuildQuality`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Quality {
    /// `RTC_BUILD_QUALITY_LOW`.
    Low,
    /// `RTC_BUILD_QUALITY_MEDIUM` (Embree's default).
    Medium,
    /// `RTC_BUILD_QUALITY_HIGH` (spatial splits).
    High,
}

impl Quality {
    /// Every quality, the cheapest build first.
    pub const ALL: [Quality; 3] = [Quality::Low, Quality::Medium, Quality::High];

    /// Short name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Quality::Low => "low",
            Quality::Medium => "medium",
            Quality::High => "high",
        }
    }

    fn code(self) -> i32 {
        match self {
            Quality::Low => 0,
            Quality::Medium => 1,
            Quality::High => 2,
        }
    }
}

/// One configuration of the driver: entry point, context flag, build quality.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Config {
    /// The entry point.
    pub entry: Entry,
    /// `RTC_INTERSECT_CONTEXT_FLAG_COHERENT` when true, else INCOHERENT.
    pub coherent: bool,
    /// The scene's build quality.
    pub quality: Quality,
}

impl Config {
    /// Every configuration: entry points x context flags x build qualities.
    pub fn all() -> Vec<Config> {
        let mut v = Vec::new();
        for quality in Quality::ALL {
            for entry in Entry::ALL {
                for coherent in [false, true] {
                    v.push(Config {
                        entry,
                        coherent,
                        quality,
                    });
                }
            }
        }
        v
    }

    /// Its name in records: "native packet16 coherent high".
    pub fn name(self) -> String {
        format!(
            "native {} {} {}",
            self.entry.name(),
            if self.coherent {
                "coherent"
            } else {
                "incoherent"
            },
            self.quality.name()
        )
    }
}

/// Whether the driver is usable here: `Err` says why not (not compiled in
/// because Embree's headers were absent at build time).
pub fn available() -> Result<(), String> {
    if cfg!(rendiff_native_embree) {
        Ok(())
    } else {
        Err(format!("native Embree driver not built: {ABSENT}"))
    }
}

/// Embree's version ("Embree 3.13.5") as the driver sees it.
pub fn version() -> Result<String, String> {
    available()?;
    let v = ffi::version();
    if v < 0 {
        return Err("rtcNewDevice failed".into());
    }
    Ok(format!(
        "Embree {}.{}.{}",
        v / 10000,
        v / 100 % 100,
        v % 100
    ))
}

/// What one traced frame gave: per pixel, Embree's hit distance (`+inf` on
/// a miss) and primitive ID (`u32::MAX` on a miss), and, for rays made
/// inside the trace ([`NativeScene::trace_made`]), each ray's planar depth
/// per unit of `t`.
pub struct Hits {
    /// `tfar` after the query.
    pub t: Vec<f32>,
    /// `primID`, the index in [`ResolvedScene::triangles`].
    pub prim: Vec<u32>,
    /// `D32·forward` of each pixel's ray, when the trace made the rays.
    planar: Vec<f64>,
}

impl Hits {
    /// Buffers for `rays`' frame (written in full by every trace).
    pub fn new(rays: &PreparedRays) -> Hits {
        Hits::with_len(rays.len())
    }

    /// Buffers for a frame of `rays`, made inside the trace.
    pub fn for_camera(rays: &CameraRays) -> Hits {
        Hits::with_len(rays.len())
    }

    fn with_len(n: usize) -> Hits {
        Hits {
            t: vec![f32::INFINITY; n],
            prim: vec![u32::MAX; n],
            planar: vec![0.0; n],
        }
    }

    /// The core's hit keys (planar depth rounded once to f32, then the
    /// triangle), as the binding computes them, and how many hits lay in
    /// front of `near` after rounding (the binding re-traces those; here
    /// they are counted and left as misses).
    pub fn keys(&self, rays: &PreparedRays) -> (Vec<u64>, usize) {
        self.keys_with(&rays.planar, rays.depth)
    }

    /// [`Hits::keys`] of a trace that made `rays` itself.
    pub fn keys_made(&self, rays: &CameraRays) -> (Vec<u64>, usize) {
        self.keys_with(&self.planar, rays.depth())
    }

    fn keys_with(&self, planar: &[f64], depth: RayDepth) -> (Vec<u64>, usize) {
        assert_eq!(planar.len(), self.t.len(), "hits of another frame");
        let mut in_front = 0;
        let keys = self
            .t
            .iter()
            .zip(&self.prim)
            .zip(planar)
            .map(|((&t, &prim), &planar)| {
                if prim == u32::MAX {
                    return NO_HIT;
                }
                let z = EmbreeRay::depth(depth.offset, planar, t);
                let zf = f64::from(z);
                if zf < depth.near {
                    in_front += 1;
                    NO_HIT
                } else if zf > depth.far {
                    NO_HIT
                } else {
                    hit_key(z, prim)
                }
            })
            .collect();
        (keys, in_front)
    }

    /// The frame these hits make (depth, IDs, normals), for agreement checks.
    pub fn frame(&self, scene: &ResolvedScene, rays: &PreparedRays) -> (Frame, usize) {
        Hits::frame_of(scene, self.keys(rays))
    }

    /// [`Hits::frame`] of a trace that made `rays` itself.
    pub fn frame_made(&self, scene: &ResolvedScene, rays: &CameraRays) -> (Frame, usize) {
        Hits::frame_of(scene, self.keys_made(rays))
    }

    fn frame_of(scene: &ResolvedScene, (keys, in_front): (Vec<u64>, usize)) -> (Frame, usize) {
        let f = Frame::from_keys(
            scene,
            &keys,
            None,
            Counters::default(),
            "embree_native",
            0.0,
        );
        (f, in_front)
    }
}

/// A committed Embree scene of the resolved triangles (unshared vertices,
/// primID = triangle index), built by the driver.
pub struct NativeScene {
    raw: ffi::Handle,
    /// Seconds `rd_build` took (device creation, buffers, BVH build).
    pub build_s: f64,
}

// SAFETY: after rtcCommitScene, Embree documents tracing a scene from many
// threads as safe; nothing changes the scene until `Drop` (exclusive).
unsafe impl Sync for NativeScene {}
// SAFETY: the handle is an owned heap object with no thread affinity.
unsafe impl Send for NativeScene {}

impl NativeScene {
    /// Builds `scene`'s triangles with `quality` (Embree's device gets
    /// `threads` threads for the build); `robust` sets RTC_SCENE_FLAG_ROBUST.
    pub fn build(
        scene: &ResolvedScene,
        quality: Quality,
        robust: bool,
        threads: usize,
    ) -> Result<NativeScene, String> {
        available()?;
        let tri: Vec<f32> = scene
            .triangles
            .iter()
            .flat_map(|t| t.iter().flat_map(|v| v.to_array()))
            .collect();
        let start = Instant::now();
        let raw = ffi::build(&tri, quality.code(), robust, threads)?;
        Ok(NativeScene {
            raw,
            build_s: start.elapsed().as_secs_f64(),
        })
    }

    /// Traces every ray of `rays` with `entry` and the context flag into
    /// `hits`, 4-row strips in parallel on rayon's current pool; returns the
    /// wall-clock seconds of the tracing alone.
    pub fn trace(&self, rays: &PreparedRays, entry: Entry, coherent: bool, hits: &mut Hits) -> f64 {
        let w = rays.width as usize;
        assert_eq!(hits.t.len(), rays.len(), "hits sized for another frame");
        let view = ffi::Rays::new(rays);
        let start = Instant::now();
        if w > 0 {
            hits.t
                .par_chunks_mut(STRIP_ROWS * w)
                .zip(hits.prim.par_chunks_mut(STRIP_ROWS * w))
                .enumerate()
                .for_each(|(i, (t, prim))| {
                    let y0 = i * STRIP_ROWS;
                    ffi::trace_strip(&self.raw, &view, entry.code(), coherent, y0, w, t, prim);
                });
        }
        start.elapsed().as_secs_f64()
    }

    /// [`NativeScene::trace`] with the rays made inside it: each 4-row
    /// strip's rays are made ([`CameraRays::fill`]) right before the strip
    /// is traced, as an application makes its rays every frame, and as the
    /// core's tracer makes its own inside its timed queries. Returns the
    /// wall-clock seconds of making and tracing.
    pub fn trace_made(
        &self,
        rays: &CameraRays,
        entry: Entry,
        coherent: bool,
        hits: &mut Hits,
    ) -> f64 {
        let w = rays.width();
        assert_eq!(hits.t.len(), rays.len(), "hits sized for another frame");
        let start = Instant::now();
        if w > 0 {
            hits.t
                .par_chunks_mut(STRIP_ROWS * w)
                .zip(hits.prim.par_chunks_mut(STRIP_ROWS * w))
                .zip(hits.planar.par_chunks_mut(STRIP_ROWS * w))
                .enumerate()
                .for_each_init(StripRays::default, |strip, (i, ((t, prim), planar))| {
                    let y0 = i * STRIP_ROWS;
                    rays.fill(y0, t.len() / w, strip, planar);
                    let view = ffi::Rays::strip(rays, strip, y0);
                    ffi::trace_strip(&self.raw, &view, entry.code(), coherent, y0, w, t, prim);
                });
        }
        start.elapsed().as_secs_f64()
    }
}

impl Drop for NativeScene {
    fn drop(&mut self) {
        ffi::release(&self.raw);
    }
}

/// The driver's C interface, or its absence.
#[cfg(rendiff_native_embree)]
mod ffi {
    use super::{CameraRays, PreparedRays, StripRays};
    use std::ffi::{c_char, c_int, c_long, c_uint, c_void};

    #[repr(C)]
    pub struct Rays {
        width: u32,
        height: u32,
        org: [f32; 3],
        dx: *const f32,
        dy: *const f32,
        dz: *const f32,
        tnear: *const f32,
        tfar: *const f32,
    }

    // SAFETY: read-only pointers into rays the caller borrows for as long
    // as the view lives (`trace` and `trace_made` hold both).
    unsafe impl Sync for Rays {}

    impl Rays {
        /// A view of every pixel's prepared ray.
        pub fn new(r: &PreparedRays) -> Rays {
            let s = &r.rays;
            Rays {
                width: r.width,
                height: r.height,
                org: r.org,
                dx: s.dx.as_ptr(),
                dy: s.dy.as_ptr(),
                dz: s.dz.as_ptr(),
                tnear: s.tnear.as_ptr(),
                tfar: s.tfar.as_ptr(),
            }
        }

        /// A view of one strip's rays, made for the rows from `y0`: the
        /// pointers are the strip's start moved back `y0` rows, so the
        /// driver's pixel index `y * width + x` lands in the strip for the
        /// strip's rows, the only ones it reads (embree_driver.c,
        /// `rd_trace_strip`). Never dereferenced here.
        pub fn strip(r: &CameraRays, s: &StripRays, y0: usize) -> Rays {
            let back = y0 * r.width();
            Rays {
                width: r.width() as u32,
                height: r.height() as u32,
                org: r.org,
                dx: s.dx.as_ptr().wrapping_sub(back),
                dy: s.dy.as_ptr().wrapping_sub(back),
                dz: s.dz.as_ptr().wrapping_sub(back),
                tnear: s.tnear.as_ptr().wrapping_sub(back),
                tfar: s.tfar.as_ptr().wrapping_sub(back),
            }
        }
    }

    pub struct Handle(*mut c_void);

    extern "C" {
        fn rd_version() -> c_long;
        fn rd_build(
            tri: *const f32,
            n: usize,
            quality: c_int,
            robust: c_int,
            threads: c_uint,
            err: *mut c_char,
            err_len: usize,
        ) -> *mut c_void;
        fn rd_release(s: *mut c_void);
        fn rd_trace_strip(
            s: *const c_void,
            r: *const Rays,
            entry: c_int,
            coherent: c_int,
            y0: u32,
            rows: u32,
            t_out: *mut f32,
            prim_out: *mut u32,
        ) -> c_int;
    }

    pub fn version() -> c_long {
        // SAFETY: no arguments; creates and releases its own device.
        unsafe { rd_version() }
    }

    pub fn build(
        tri: &[f32],
        quality: i32,
        robust: bool,
        threads: usize,
    ) -> Result<Handle, String> {
        let mut err = [0 as c_char; 256];
        // SAFETY: `tri` holds 9 floats per triangle (n = len / 9), read
        // during the call only (the driver copies them into Embree's
        // buffers); `err` is writable for its length.
        let raw = unsafe {
            rd_build(
                tri.as_ptr(),
                tri.len() / 9,
                quality,
                c_int::from(robust),
                threads.max(1) as c_uint,
                err.as_mut_ptr(),
                err.len(),
            )
        };
        if raw.is_null() {
            // SAFETY: the driver wrote a NUL-terminated message into `err`
            // (snprintf always terminates within the length).
            let msg = unsafe { std::ffi::CStr::from_ptr(err.as_ptr()) };
            return Err(msg.to_string_lossy().into_owned());
        }
        Ok(Handle(raw))
    }

    pub fn release(h: &Handle) {
        // SAFETY: `h` came from `rd_build` and is released once (Drop).
        unsafe { rd_release(h.0) }
    }

    /// Traces the strip whose slices `t` and `prim` start at row `y0` of an
    /// image `w` pixels wide.
    #[allow(clippy::too_many_arguments)]
    pub fn trace_strip(
        h: &Handle,
        r: &Rays,
        entry: i32,
        coherent: bool,
        y0: usize,
        w: usize,
        t: &mut [f32],
        prim: &mut [u32],
    ) {
        let rows = t.len() / w;
        assert!(t.len() == rows * w && prim.len() == t.len() && y0 + rows <= r.height as usize);
        // The driver indexes the whole frame (pixel y * w + x); these
        // pointers are the frame's start, so it writes only this strip's rows.
        let t0 = t.as_mut_ptr().wrapping_sub(y0 * w);
        let p0 = prim.as_mut_ptr().wrapping_sub(y0 * w);
        // SAFETY: the scene is committed and live; the driver reads the rays
        // of rows [y0, y0+rows) only, at `r.d* + y*w + x`, which `r` holds
        // for the call (a whole image's arrays, or a strip's of these rows
        // by `Rays::strip`); it writes exactly the pixels of those rows,
        // which are `t` and `prim` (exclusive borrows), at `t0 + y*w + x`,
        // inside those slices.
        let rc = unsafe {
            rd_trace_strip(
                h.0,
                r,
                entry,
                c_int::from(coherent),
                y0 as u32,
                rows as u32,
                t0,
                p0,
            )
        };
        assert_eq!(rc, 0, "embree_driver: unknown entry point {entry}");
    }
}

/// Stand-ins where the driver was not compiled: [`available`] fails first,
/// so none of these is reached.
#[cfg(not(rendiff_native_embree))]
mod ffi {
    use super::{CameraRays, PreparedRays, StripRays};

    pub struct Rays;
    pub struct Handle;

    impl Rays {
        pub fn new(_: &PreparedRays) -> Rays {
            Rays
        }

        pub fn strip(_: &CameraRays, _: &StripRays, _: usize) -> Rays {
            Rays
        }
    }

    pub fn version() -> std::ffi::c_long {
        -1
    }

    pub fn build(_: &[f32], _: i32, _: bool, _: usize) -> Result<Handle, String> {
        Err(super::available().unwrap_err())
    }

    pub fn release(_: &Handle) {}

    #[allow(clippy::too_many_arguments)]
    pub fn trace_strip(
        _: &Handle,
        _: &Rays,
        _: i32,
        _: bool,
        _: usize,
        _: usize,
        _: &mut [f32],
        _: &mut [u32],
    ) {
        unreachable!("no NativeScene exists without the driver")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every configuration once, named apart, numbered as the C enum
    /// (RD_1 = 0 ... RD_NM16 = 7, in `Entry::ALL`'s order).
    #[test]
    fn configurations_are_complete_and_named_apart() {
        let all = Config::all();
        assert_eq!(all.len(), Entry::ALL.len() * 2 * Quality::ALL.len());
        let names: std::collections::BTreeSet<String> = all.iter().map(|c| c.name()).collect();
        assert_eq!(names.len(), all.len());
        let codes: Vec<i32> = Entry::ALL.iter().map(|e| e.code()).collect();
        assert_eq!(codes, (0..8).collect::<Vec<i32>>());
        assert_eq!(
            Config {
                entry: Entry::Sixteen,
                coherent: true,
                quality: Quality::High
            }
            .name(),
            "native packet16 coherent high"
        );
    }

    /// Without the driver the reason names what is missing; with it, the
    /// reason file is empty.
    #[test]
    fn availability_says_why() {
        match available() {
            Ok(()) => assert!(ABSENT.is_empty()),
            Err(why) => assert!(why.contains("not built") && !ABSENT.is_empty(), "{why}"),
        }
    }
}
