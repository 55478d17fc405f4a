//! Rasterization: the outer loop runs over triangles, the inner over the pixels
//! of each triangle's bounding box, keeping the nearest hit in a z-buffer.
//!
//! Triangles are clipped against the near plane only to find a conservative
//! screen bounding box, with a margin derived from the rounding errors
//! ([`crate::raster::bounds`]: a triangle smaller than a pixel usually gets
//! none), and binned into tiles in parallel, those facing the eye first
//! ([`crate::raster::bins`]); bands of
//! tiles render in parallel straight into the image's key buffer. The
//! decision per pixel is [`crate::visibility`]'s, exactly as in the tracer:
//! the edge-function fast path ([`crate::raster::edges`]) settles only the
//! signs the predicate's own filter would settle at once (8 pixels at a time,
//! or a whole 8x8 block when its corners prove it), boxes of a few pixels ask
//! the predicate directly, a triangle that cannot beat any key in its box is
//! skipped ([`crate::raster::hiz`]), and [`render_exact`] keeps the pure
//! predicate loop to test it against (same boxes, same skipping, so the same
//! buffers and counts).
//!
//! Counts: `triangle_setups` and `coverage_tests` count the work done, so a
//! triangle with an empty box or skipped as hidden adds to neither.

pub mod bins;
pub mod bounds;
pub mod edges;
pub mod hiz;
pub mod screen_depth;
pub(crate) mod timing;

use crate::camera::{Camera, PixelRay};
use crate::frame::{BandBuffers, Frame, FrameBuffers, PixelKeys};
use crate::predicate::EdgePlane;
use crate::raster::bins::{Binned, Bins};
use crate::raster::bounds::BoxMargin;
use crate::raster::edges::{
    ChunkDepth, ChunkOps, ChunkSigns, FastEdges, TileColumns, TileRays, CHUNK,
};
use crate::raster::hiz::TileDepthBound;
use crate::raster::screen_depth::{BlockBound, ScreenDepth};
use crate::scene::resolve::{ResolvedScene, Tri};
#[cfg(target_arch = "x86_64")]
use crate::simd::Avx2;
use crate::simd::Portable;
use crate::visibility::{covers_by, edge_sign, hit_key, Counters, TriDepth, TriEdges, NO_HIT};
use rayon::prelude::*;
use std::mem::MaybeUninit;
use std::time::Instant;

/// Tile side in pixels: small enough for load balance, big enough to amortize setup.
pub const TILE: u32 = 32;

/// Inclusive pixel rectangle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PixelRect {
    /// First column.
    pub x0: u32,
    /// First row.
    pub y0: u32,
    /// Last column (inclusive).
    pub x1: u32,
    /// Last row (inclusive).
    pub y1: u32,
}

/// Conservative pixel bounding box of the part of a triangle at planar depth
/// at least `near` (clipped against the near plane, then projected), grown by
/// the rounding margin [`crate::raster::bounds`] derives. `None` when no
/// pixel can be covered. (Renders set the camera's constants up once.)
pub fn screen_bounds(cam: &Camera, t: &Tri) -> Option<PixelRect> {
    BoxMargin::new(cam).bounds(cam, t)
}

/// Options for one raster render.
#[derive(Debug, Clone, Copy, Default)]
pub struct RasterOptions {
    /// Also count every covering triangle per pixel (front/back), for watertightness tests.
    pub count_coverage: bool,
    /// Stop rasterizing when this passes (`check --timeout`); the frame is then partial.
    pub deadline: Option<Instant>,
}

/// Renders depth and IDs by rasterization. `progress` is called with the number
/// of tiles finished since the last call (from worker threads). Coverage goes
/// through the edge-function fast path ([`crate::raster::edges`]) first.
pub fn render(
    scene: &ResolvedScene,
    opts: RasterOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> Frame {
    let start = Instant::now();
    let mut buffers = FrameBuffers::with_capacity(scene.camera.pixel_count());
    let k = keys_impl(
        scene,
        opts,
        Mode::new(&scene.camera, true),
        progress,
        Some(&mut buffers),
    );
    // SAFETY: `keys_impl` filled every band of one `bands` call (it asserts
    // each band's keys were all written before filling its buffers).
    let buffers = unsafe { buffers.assume_filled() };
    Frame::from_buffers(
        scene,
        buffers,
        k.coverage,
        k.counters,
        k.renderer,
        start.elapsed().as_secs_f64(),
    )
}

/// [`render`] without the edge-function fast path: every bounding-box pixel
/// calls the orientation predicate. Kept as the reference the fast path must
/// equal bit for bit (buffers and counts, `fast_decided` aside), in tests and
/// benchmarks.
pub fn render_exact(
    scene: &ResolvedScene,
    opts: RasterOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> Frame {
    let start = Instant::now();
    let k = keys_impl(scene, opts, Mode::new(&scene.camera, false), progress, None);
    k.into_frame(scene, start.elapsed().as_secs_f64())
}

/// [`render`]'s visibility pass (binning, coverage, depth test) without the
/// frame's buffers.
pub fn render_keys(
    scene: &ResolvedScene,
    opts: RasterOptions,
    progress: &(dyn Fn(u64) + Sync),
) -> PixelKeys {
    keys_impl(scene, opts, Mode::new(&scene.camera, true), progress, None)
}

/// How [`keys_impl`] works: the fast path or the pure predicate, box
/// margins (`None`: every triangle gets the whole image, the reference tight
/// boxes must not lose pixels against), early depth rejection (tests turn it
/// off, or scale its bound).
#[derive(Debug, Clone, Copy)]
struct Mode {
    /// The edge-function fast path.
    fast: bool,
    /// Box margins.
    margin: Option<BoxMargin>,
    /// Skip hidden triangles ([`crate::raster::hiz`]); never while counting coverage.
    hiz: bool,
    /// Multiplies the depth bound (tests).
    hiz_factor: f64,
}

impl Mode {
    /// What renders use: tight boxes, hidden triangles skipped.
    fn new(cam: &Camera, fast: bool) -> Mode {
        Mode {
            fast,
            margin: Some(BoxMargin::new(cam)),
            hiz: true,
            hiz_factor: 1.0,
        }
    }
}

/// The visibility pass; with `frame`, each band of tiles also fills its
/// rows of the frame's buffers ([`crate::frame::BandBuffers::fill`]) right
/// after drawing them, while the band's triangles are still in cache
/// (every band of one `frame.bands` call); the keys returned are then
/// empty (each band's were kept only until its rows were filled).
fn keys_impl(
    scene: &ResolvedScene,
    opts: RasterOptions,
    mode: Mode,
    progress: &(dyn Fn(u64) + Sync),
    frame: Option<&mut FrameBuffers>,
) -> PixelKeys {
    let margin = mode.margin;
    let mode = Mode {
        hiz: mode.hiz && !opts.count_coverage,
        ..mode
    };
    let cam = &scene.camera;
    let (w, h) = (cam.width, cam.height);
    let tiles_x = w.div_ceil(TILE);
    let tiles_y = h.div_ceil(TILE);
    // Two serial set-ups, side by side: on few triangles they are a few
    // percent of a pass, and the join also wakes a second worker before
    // the tiles' loop needs it (alternated in one process, 3-5% off two
    // screen-filling triangles at 512x512 on 2 threads, 1 thread and
    // `million` unchanged).
    let (bins, columns) = rayon::join(
        || Bins::new(scene, margin, tiles_x, tiles_y),
        || TileColumns::new(cam, TILE),
    );
    let band = (w * TILE) as usize;
    // Never filled before the parallel loop (neither serially nor by
    // calloc, which zeroes reused memory): each tile writes its own keys
    // before it reads any (`TileOut::fill`, or its first triangle's keys
    // where that covers it whole), as the tracer's packet loop writes all
    // of its own.
    // With `frame`, the image's keys are not kept: each band's go to a
    // scratch band per worker, read back by the band's frame rows while
    // they are in cache (16 MB fewer at 1080p).
    let n = cam.pixel_count();
    let with_frame = frame.is_some();
    let mut keys: Vec<u64> = Vec::with_capacity(if with_frame { 0 } else { n });
    let key_bands: Vec<Option<&mut [MaybeUninit<u64>]>> = if with_frame {
        (0..tiles_y).map(|_| None).collect()
    } else {
        keys.spare_capacity_mut()[..n]
            .chunks_mut(band)
            .map(Some)
            .collect()
    };
    let mut coverage = vec![[0u16; 2]; if opts.count_coverage { n } else { 0 }];
    let mut cov_bands: Vec<&mut [[u16; 2]]> = if opts.count_coverage {
        coverage.chunks_mut(band).collect()
    } else {
        (0..tiles_y).map(|_| &mut [][..]).collect()
    };
    // One frame band per key band (each `fill` asserts its band's length
    // is its keys', so the frame has the keys' `n` pixels).
    let frame_bands: Vec<Option<BandBuffers>> = match frame {
        Some(f) => f.bands(band).into_iter().map(Some).collect(),
        None => (0..tiles_y).map(|_| None).collect(),
    };
    assert_eq!(frame_bands.len(), tiles_y as usize);
    let (counters, filled) = key_bands
        .into_par_iter()
        .zip(cov_bands.par_iter_mut())
        .zip(frame_bands)
        .enumerate()
        .map_init(Vec::new, |scratch, (ty, ((kband, cband), fband))| {
            let kband = match kband {
                Some(k) => k,
                None => {
                    let len = band.min(n - ty * band);
                    scratch.resize(len, MaybeUninit::uninit());
                    &mut scratch[..len]
                }
            };
            let mut c = Counters::default();
            let mut bin = Vec::new();
            let mut rays = TileRays::default();
            let mut setups = TriSetups::default();
            let mut written = 0;
            for tx in 0..tiles_x {
                let front = bins.tile((ty as u32 * tiles_x + tx) as usize, &mut bin);
                let (x0, y0) = (tx * TILE, ty as u32 * TILE);
                let mut out = TileOut {
                    keys: &mut kband[..],
                    cov: &mut cband[..],
                    stride: w as usize,
                    x0: x0 as usize,
                    tw: TILE.min(w - x0) as usize,
                    th: TILE.min(h - y0) as usize,
                    filled: false,
                };
                // Past the deadline a tile renders nothing (background).
                if !bin.is_empty() && !crate::deadline::past(opts.deadline) {
                    render_tile(
                        scene,
                        (&bin, front),
                        (x0, &columns),
                        y0,
                        mode,
                        &mut out,
                        &mut rays,
                        &mut setups,
                        &mut c,
                    );
                }
                out.fill();
                written += out.tw * out.th;
            }
            if let Some(fband) = fband {
                assert_eq!(written, kband.len(), "raster tiles left keys unwritten");
                // SAFETY: the band's tiles partition it and each wrote its
                // whole rectangle (`TileOut::fill`), `written` keys in all,
                // as many as the band holds; `MaybeUninit<u64>` and `u64`
                // share a layout.
                let kband = unsafe { &*(&kband[..] as *const [MaybeUninit<u64>] as *const [u64]) };
                fband.fill(scene, kband);
            }
            progress(u64::from(tiles_x));
            (c, written)
        })
        .reduce(
            || (Counters::default(), 0),
            |(mut a, n), (b, m)| {
                a += b;
                (a, n + m)
            },
        );
    // Every band was zipped with a coverage band, and each of its tiles
    // wrote all of its keys (else no key may be read).
    assert_eq!(filled, n, "raster tiles left keys unwritten");
    if !with_frame {
        // SAFETY: the tiles wrote `n` keys: each wrote its `tw x th`
        // rectangle whole (`TileOut::fill`), the tiles of a band partition
        // it, and the bands are the disjoint chunks of `0..n`, in order;
        // `n <= capacity`.
        unsafe { keys.set_len(n) };
    }
    PixelKeys {
        keys,
        coverage: opts.count_coverage.then_some(coverage),
        counters,
        renderer: "raster",
    }
}

/// Where one tile writes: its band of tile rows in the image's key (and
/// coverage) buffers, the image's row stride and the tile's rectangle. The
/// band's keys start unwritten: a tile writes all of its own (`fill`, or
/// `write_rows` over the whole tile) before any is read, and reads and writes
/// no other tile's.
struct TileOut<'a> {
    /// The band's keys, `stride` per row.
    keys: &'a mut [MaybeUninit<u64>],
    /// The band's coverage counts (empty when not counted).
    cov: &'a mut [[u16; 2]],
    /// Pixels per image row.
    stride: usize,
    /// The tile's first column.
    x0: usize,
    /// The tile's width.
    tw: usize,
    /// The tile's height.
    th: usize,
    /// Every key of the tile is written.
    filled: bool,
}

impl TileOut<'_> {
    /// Buffer index of tile pixel `(lx, ly)`.
    #[inline(always)]
    fn at(&self, lx: usize, ly: usize) -> usize {
        ly * self.stride + self.x0 + lx
    }

    /// Writes `NO_HIT` to every key of the tile, unless it is written.
    #[inline(always)]
    fn fill(&mut self) {
        if !self.filled {
            for ly in 0..self.th {
                let at = self.at(0, ly);
                self.keys[at..at + self.tw].fill(MaybeUninit::new(NO_HIT));
            }
            self.filled = true;
        }
    }

    /// Writes every key of the unwritten tile: row `ly` all `key[ly]`.
    #[inline(always)]
    fn write_rows(&mut self, key: &[u64]) {
        assert!(!self.filled && key.len() == self.th);
        for (ly, &k) in key.iter().enumerate() {
            let at = self.at(0, ly);
            self.keys[at..at + self.tw].fill(MaybeUninit::new(k));
        }
        self.filled = true;
    }

    /// The `n` keys of tile row `ly` from column `lx`.
    #[inline(always)]
    fn row(&self, lx: usize, ly: usize, n: usize) -> &[u64] {
        assert!(self.filled && lx + n <= self.tw && ly < self.th);
        let at = self.at(lx, ly);
        // SAFETY: the tile's keys are all written (`filled`), and these lie
        // in the tile (asserted); `MaybeUninit<u64>` and `u64` share a layout.
        unsafe { &*(&self.keys[at..at + n] as *const [MaybeUninit<u64>] as *const [u64]) }
    }

    /// [`TileOut::row`], to write.
    #[inline(always)]
    fn row_mut(&mut self, lx: usize, ly: usize, n: usize) -> &mut [u64] {
        assert!(self.filled && lx + n <= self.tw && ly < self.th);
        let at = self.at(lx, ly);
        // SAFETY: as in `row`.
        unsafe { &mut *(&mut self.keys[at..at + n] as *mut [MaybeUninit<u64>] as *mut [u64]) }
    }

    /// The 8 keys of tile row `ly` from column `lx`.
    #[inline(always)]
    fn chunk_mut(&mut self, lx: usize, ly: usize) -> &mut [u64; CHUNK] {
        self.row_mut(lx, ly, CHUNK).try_into().unwrap()
    }

    /// The 8 rows of 8 keys of the block whose top-left tile pixel is `(lx, ly)`.
    #[inline(always)]
    fn block_rows(&mut self, lx: usize, ly: usize) -> [&mut [u64; CHUNK]; CHUNK] {
        assert!(self.filled && lx + CHUNK <= self.tw && ly + CHUNK <= self.th);
        let (at, stride) = (self.at(lx, ly), self.stride);
        assert!(CHUNK <= stride && at + (CHUNK - 1) * stride + CHUNK <= self.keys.len());
        let base = self.keys.as_mut_ptr().cast::<u64>();
        // SAFETY: the rows lie in the tile (asserted), whose keys are all
        // written; they are disjoint (`stride >= CHUNK`) and within `keys`.
        std::array::from_fn(|i| unsafe { &mut *base.add(at + i * stride).cast::<[u64; CHUNK]>() })
    }

    /// A hit with key `k` at tile pixel `(lx, ly)`, covered with `facing`
    /// (+1 back, -1 front): the nearer key stays, and the hit is counted
    /// when coverage is.
    #[inline(always)]
    fn offer(&mut self, lx: usize, ly: usize, k: u64, facing: i8) {
        let at = self.at(lx, ly);
        let key = &mut self.row_mut(lx, ly, 1)[0];
        if k < *key {
            *key = k;
        }
        if let Some(cv) = self.cov.get_mut(at) {
            let slot = usize::from(facing > 0);
            cv[slot] = cv[slot].saturating_add(1);
        }
    }
}

/// Renders one tile's bin into `out`; on x86-64 CPUs with AVX2 the same code
/// runs compiled for 256-bit vectors (the fast path's 8-lane loops vectorize;
/// the arithmetic is unchanged, as Rust never contracts a*b+c into an FMA by itself).
#[allow(clippy::too_many_arguments)]
fn render_tile(
    scene: &ResolvedScene,
    bin: (&[Binned], usize),
    column: (u32, &TileColumns),
    y0: u32,
    mode: Mode,
    out: &mut TileOut,
    rays: &mut TileRays,
    setups: &mut TriSetups,
    c: &mut Counters,
) {
    #[cfg(target_arch = "x86_64")]
    if let Some(avx2) = Avx2::detect().filter(|_| mode.fast) {
        // SAFETY: the token proves the CPU has AVX2 and POPCNT.
        return unsafe {
            render_tile_avx2(avx2, scene, bin, column, y0, mode, out, rays, setups, c)
        };
    }
    render_tile_body(Portable, scene, bin, column, y0, mode, out, rays, setups, c)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,popcnt")]
#[allow(clippy::too_many_arguments)]
fn render_tile_avx2(
    avx2: Avx2,
    scene: &ResolvedScene,
    bin: (&[Binned], usize),
    column: (u32, &TileColumns),
    y0: u32,
    mode: Mode,
    out: &mut TileOut,
    rays: &mut TileRays,
    setups: &mut TriSetups,
    c: &mut Counters,
) {
    render_tile_body(avx2, scene, bin, column, y0, mode, out, rays, setups, c)
}

/// The tile's depth bound ([`crate::raster::hiz`]), computed the first time a
/// triangle's box is found full of hits (most tiles of big triangles never need it).
struct LazyBound {
    /// Skipping is on.
    on: bool,
    /// Multiplies the bound (tests).
    factor: f64,
    /// Computed yet, and its value.
    bound: Option<Option<TileDepthBound>>,
}

impl LazyBound {
    /// No bound yet.
    #[inline(always)]
    fn new(mode: Mode) -> Self {
        LazyBound {
            on: mode.hiz,
            factor: mode.hiz_factor,
            bound: None,
        }
    }

    /// True when triangle `prim`, of face `face` ([`crate::raster::hiz`]), can
    /// change no key in its box `[lx0, lx1, ly0, ly1]` of the tile: its
    /// lowest possible key is no smaller than every key there (none of which
    /// may then be background). `make` computes the tile's bound the first
    /// time one is needed. (The triangle's vertices are not read.)
    #[inline(always)]
    fn hidden(
        &mut self,
        make: impl FnOnce() -> Option<TileDepthBound>,
        face: f32,
        prim: u32,
        out: &TileOut,
        [lx0, lx1, ly0, ly1]: [usize; 4],
    ) -> bool {
        // An empty first pixel (a tile's first triangle) settles it at once.
        if !self.on || !out.filled || out.row(lx0, ly0, 1)[0] == NO_HIT {
            return false;
        }
        let Some(b) = self.bound(make) else {
            return false;
        };
        let low = b.lowest_key(face, prim);
        // `low` is 0 or a hit's key, below NO_HIT: a background pixel
        // fails `k <= low`, as does any key the triangle might beat, so the
        // scan stops at the first such key (at once, mostly, for a visible
        // triangle over a tile already drawn).
        low != 0 && (ly0..=ly1).all(|ly| out.row(lx0, ly, lx1 - lx0 + 1).iter().all(|&k| k <= low))
    }

    /// The largest key in the tile, when the tile has no background pixel
    /// left and a bound: every key there is then at most that, and stays so
    /// (keys only fall), so a triangle whose lowest possible key is no
    /// smaller is one [`LazyBound::hidden`] would skip ([`LazyBound::beaten`]),
    /// without reading its box. Checked once, where the bin's triangles
    /// facing away begin (mostly a closed mesh's far side).
    #[inline(always)]
    fn closed(
        &mut self,
        make: impl FnOnce() -> Option<TileDepthBound>,
        out: &TileOut,
    ) -> Option<u64> {
        if !self.on || !out.filled {
            return None;
        }
        let most = (0..out.th)
            .map(|ly| out.row(0, ly, out.tw).iter().fold(0, |m, &k| m.max(k)))
            .fold(0, u64::max);
        if most == NO_HIT {
            return None;
        }
        self.bound(make).map(|_| most)
    }

    /// The tile's bound, made by `make` the first time.
    #[inline(always)]
    fn bound(&mut self, make: impl FnOnce() -> Option<TileDepthBound>) -> Option<TileDepthBound> {
        let factor = self.factor;
        *self
            .bound
            .get_or_insert_with(|| make().map(|b| b.scaled(factor)))
    }

    /// True when triangle `prim` of face `face` cannot beat key `most`,
    /// the largest in a tile without background ([`LazyBound::closed`]):
    /// [`LazyBound::hidden`]'s test against that key for every pixel.
    #[inline(always)]
    fn beaten(&self, face: f32, prim: u32, most: u64) -> bool {
        let Some(Some(b)) = self.bound else {
            return false;
        };
        let low = b.lowest_key(face, prim);
        low != 0 && most <= low
    }
}

/// A big triangle's setups over one band of tiles: its edges, its depth
/// function's 8-lane form and its screen-space depth, which depend on the
/// camera and the triangle alone, and that depth's bound over the band (the
/// last three made when first needed).
struct TriSetup {
    /// The triangle.
    prim: u32,
    /// Its edge planes.
    edges: TriEdges,
    /// Its depth, 8 lanes at a time.
    depth: Option<ChunkDepth>,
    /// Its screen-space depth, before a tile's subnormal check
    /// ([`ScreenDepth::for_plane`]).
    screen: Option<Option<ScreenDepth>>,
    /// Its screen-space depth's bound over the band's rows across the whole
    /// image ([`ScreenDepth::band`]), made the first time it covers one
    /// of the band's tiles whole: it holds in each of them, so their keys
    /// need no bound of their own (`None` inside: the proof fails over the
    /// band, and each tile takes its own).
    band: Option<Option<BlockBound>>,
}

impl TriSetup {
    /// The edges now, the rest when needed.
    #[inline(always)]
    fn new(cam: &Camera, t: &Tri, prim: u32) -> TriSetup {
        TriSetup {
            prim,
            edges: TriEdges::new(cam, t),
            depth: None,
            screen: None,
            band: None,
        }
    }

    /// [`ScreenDepth::new`] for tile `rays`, the plane's part made once.
    #[inline(always)]
    fn screen_depth(
        plane: &mut Option<Option<ScreenDepth>>,
        cam: &Camera,
        d: &ChunkDepth,
        rays: &TileRays,
    ) -> Option<ScreenDepth> {
        if rays.subnormal() {
            return None;
        }
        *plane.get_or_insert_with(|| ScreenDepth::for_plane(cam, d, rays.eta()))
    }
}

/// The setups of the big triangles a band's tiles meet (a triangle of a
/// block or more in a tile usually spans several of the band's tiles),
/// by triangle, a few at a time. Made afresh for each band: a setup's band
/// bound ([`TriSetup::band`]) holds in that band alone.
#[derive(Default)]
struct TriSetups {
    /// Slot `prim % SETUP_SLOTS`.
    slots: [Option<TriSetup>; SETUP_SLOTS],
}

/// Big triangles remembered per band.
const SETUP_SLOTS: usize = 4;

impl TriSetups {
    /// Triangle `prim`'s setups, made if its slot holds another's.
    #[inline(always)]
    fn get(&mut self, cam: &Camera, t: &Tri, prim: u32) -> &mut TriSetup {
        let slot = &mut self.slots[prim as usize % SETUP_SLOTS];
        if slot.as_ref().is_none_or(|s| s.prim != prim) {
            *slot = Some(TriSetup::new(cam, t, prim));
        }
        slot.as_mut().unwrap()
    }
}

/// How many bin entries ahead the tile loop prefetches a triangle.
const PREFETCH_AHEAD: usize = 8;

/// Boxes of at most this many pixels skip the fast path's per-tile edge and
/// depth setup and ask the predicate and [`TriDepth::depth`] directly (what
/// [`render_exact`] does everywhere, so nothing can differ): for triangles
/// of about a pixel, the setup costs more than it saves.
const SMALL_BOX: usize = 4;

// One pixel of a small box per lane of `ChunkOps::filter4` (and per step of
// `ChunkOps::small_signs`).
const _: () = assert!(SMALL_BOX <= 4);

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn render_tile_body<L: ChunkOps>(
    l: L,
    scene: &ResolvedScene,
    (bin, front): (&[Binned], usize),
    (x0, columns): (u32, &TileColumns),
    y0: u32,
    mode: Mode,
    out: &mut TileOut,
    rays: &mut TileRays,
    setups: &mut TriSetups,
    c: &mut Counters,
) {
    let cam = &scene.camera;
    let tw = TILE.min(cam.width - x0);
    let th = TILE.min(cam.height - y0);
    let col = columns.at(x0);
    if mode.fast {
        rays.fill(l, cam, col, y0, th);
        fast_tile(l, scene, (bin, front), mode, out, rays, setups, c);
        return;
    }
    out.fill();
    // The pure predicate path: every bounding-box pixel asks `visibility`.
    let pixel_rays: Vec<PixelRay> = (0..th)
        .flat_map(|ly| (0..tw).map(move |lx| (lx, ly)))
        .map(|(lx, ly)| cam.pixel_ray(x0 + lx, y0 + ly))
        .collect();
    // The skipping bound the fast path uses, from the same tile frame (so
    // both skip the same triangles and their counts agree).
    let mut hiz = LazyBound::new(mode);
    for &Binned { prim, rect, face } in bin {
        let t = &scene.triangles[prim as usize];
        let [lx0, lx1, ly0, ly1] = rect.map(usize::from);
        let bound = || {
            rays.fill(l, cam, col, y0, th);
            rays.depth_bound(cam)
        };
        if hiz.hidden(bound, face, prim, out, [lx0, lx1, ly0, ly1]) {
            c.hidden_skipped += 1;
            continue;
        }
        c.triangle_setups += 1;
        let edges = TriEdges::new(cam, t);
        let mut depth: Option<TriDepth> = None;
        for ly in ly0..=ly1 {
            for lx in lx0..=lx1 {
                let ray = &pixel_rays[ly * tw as usize + lx];
                let facing = edges.covers(cam, ray, c);
                if facing != 0 {
                    let d = depth.get_or_insert_with(|| TriDepth::new(cam, t));
                    if let Some(z) = d.depth(cam, ray) {
                        out.offer(lx, ly, hit_key(z, prim), facing);
                    }
                }
            }
        }
    }
}

/// The fast path over one tile (whose `rays` are filled): per triangle, its edge
/// functions decide 8 pixels of a row at a time where their bound allows
/// ([`crate::raster::edges`]); undecided pixels go to the predicate exactly as
/// [`TriEdges::covers`] would ask it; covered pixels get their depth 8 at a
/// time from the same arithmetic as [`TriDepth::depth`]. Boxes of at most
/// [`SMALL_BOX`] pixels take the predicate path directly.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn fast_tile<L: ChunkOps>(
    l: L,
    scene: &ResolvedScene,
    (bin, front): (&[Binned], usize),
    mode: Mode,
    out: &mut TileOut,
    rays: &mut TileRays,
    setups: &mut TriSetups,
    c: &mut Counters,
) {
    let cam = &scene.camera;
    let mut hiz = LazyBound::new(mode);
    // No triangle has written in the tile yet: every key is `NO_HIT`.
    let mut fresh = true;
    // Prefetch while triangles are drawn, not while they are skipped as
    // hidden (a closed mesh's far side, last in the bin: its vertices are
    // never read, and fetching them only cost memory traffic; alternated
    // on `million`, 1-2% faster on 1 thread, 3.5% on 2).
    let mut ahead = true;
    let mut closed = None;
    for (i, &Binned { prim, rect, face }) in bin.iter().enumerate() {
        // Bins name triangles scattered through memory: ask for one a few
        // entries ahead (a hint; nothing observable changes).
        if ahead {
            if let Some(next) = bin.get(i + PREFETCH_AHEAD) {
                crate::simd::prefetch(&scene.triangles[next.prim as usize]);
            }
        }
        // Where the triangles facing away begin, a tile left without
        // background lets each be tested against its largest key alone
        // (`LazyBound::closed`; on `million` 7-9% off the pass, alternated).
        if i == front {
            closed = hiz.closed(|| rays.depth_bound(cam), out);
        }
        if let Some(most) = closed {
            if hiz.beaten(face, prim, most) {
                c.hidden_skipped += 1;
                ahead = false;
                continue;
            }
        }
        let [lx0, lx1, ly0, ly1] = rect.map(usize::from);
        let bound = || rays.depth_bound(cam);
        let hidden = hiz.hidden(bound, face, prim, out, [lx0, lx1, ly0, ly1]);
        ahead = !hidden;
        if hidden {
            c.hidden_skipped += 1;
            continue;
        }
        let t = &scene.triangles[prim as usize];
        c.triangle_setups += 1;
        if (lx1 - lx0 + 1) * (ly1 - ly0 + 1) <= SMALL_BOX {
            fresh = false;
            out.fill();
            rays.ensure_dirs(l);
            small_box(l, cam, t, prim, rays, [lx0, lx1, ly0, ly1], out, c);
            continue;
        }
        let (bw, bh) = (lx1 - lx0 + 1, ly1 - ly0 + 1);
        let big = bw >= CHUNK && bh >= CHUNK;
        // A big triangle's setups come from the band's (it meets the band's
        // other tiles too); a smaller one's are its own.
        let (mut own_edges, mut own_depth, mut own_screen) = (None, None, None);
        let (edges, depth, plane_screen, band) = if big {
            let s = setups.get(cam, t, prim);
            (&s.edges, &mut s.depth, &mut s.screen, Some(&mut s.band))
        } else {
            let e = &*own_edges.insert(TriEdges::new(cam, t));
            (e, &mut own_depth, &mut own_screen, None)
        };
        let f = FastEdges::new(edges, rays);
        // A box of a block or more, by its corners: rejected, it adds its
        // pixels' counts (as its blocks and chunks would); covered, every
        // full block in it takes these signs. (Smaller boxes, most of a
        // finely meshed scene's, rarely settle whole: they skip the test.)
        let whole = big.then(|| f.rect(rays, [lx0, lx1, ly0, ly1]));
        if whole.is_some_and(|g| g.rejected() == 0xff) {
            let n = (bw * bh) as u64;
            c.coverage_tests += n;
            c.fast_decided += n;
            continue;
        }
        // No earlier triangle wrote in the tile: its keys are `NO_HIT` (or
        // not yet written), so a box this triangle covers with one key per
        // row can set them without the z-test (`box_keys` below).
        let fresh_box = std::mem::replace(&mut fresh, false);
        let whole = whole.filter(|g| g.inside_pos() | g.inside_neg() == 0xff);
        // Set up with the first covered block: the screen-space depth (`None`:
        // it cannot run here) and its bound over the whole box in the tile
        // (`None`: each block asks for its own).
        let mut screen: Option<(Option<ScreenDepth>, Option<BlockBound>)> = None;
        // A covered box whose certified depth is constant along its rows
        // takes one key per row (`ScreenDepth::box_keys`), without blocks.
        if whole.is_some() && out.cov.is_empty() {
            let d = depth.get_or_insert_with(|| ChunkDepth::new(cam, &TriDepth::new(cam, t)));
            let rect = [lx0, lx1, ly0, ly1];
            // A triangle covering the tile whole takes the band's bound
            // where it holds (made once per band; alternated in one
            // process, 7-8% off the pass on two screen-filling triangles at
            // 512x512 on 1 and 2 threads, `million` and finer grids
            // unchanged), else the tile's own.
            let banded = match band {
                Some(band) if rect == [0, out.tw - 1, 0, out.th - 1] => {
                    match TriSetup::screen_depth(plane_screen, cam, d, rays) {
                        Some(s) => match *band.get_or_insert_with(|| s.band(cam, rays)) {
                            Some(b) if b.all_hit => s.box_keys(rays, rect, b.eu, prim),
                            _ => None,
                        },
                        None => None,
                    }
                }
                _ => None,
            };
            let keys = banded.or_else(|| {
                let &mut (s, bound) = screen.get_or_insert_with(|| {
                    let s = TriSetup::screen_depth(plane_screen, cam, d, rays);
                    let whole = s.and_then(|s| s.rect(rays, rect));
                    (s, whole)
                });
                match (s, bound) {
                    (Some(s), Some(b)) if b.all_hit => s.box_keys(rays, rect, b.eu, prim),
                    _ => None,
                }
            });
            if let Some(keys) = keys {
                let keys = &keys[..bh];
                if fresh_box && !out.filled && rect == [0, out.tw - 1, 0, out.th - 1] {
                    // The tile's first keys, all of them at once.
                    out.write_rows(keys);
                } else {
                    out.fill();
                    for (i, &k) in keys.iter().enumerate() {
                        let row = out.row_mut(lx0, ly0 + i, bw);
                        if fresh_box {
                            row.fill(k);
                        } else {
                            row.iter_mut().for_each(|key| *key = (*key).min(k));
                        }
                    }
                }
                let n = (bw * bh) as u64;
                c.coverage_tests += n;
                c.fast_decided += n;
                c.covered += n;
                continue;
            }
        }
        out.fill();
        // Boxes at least a chunk wide take chunks aligned to the tile's 8x8
        // blocks, so that whole blocks can be decided at once; narrower ones
        // take one chunk per row from their first column (any column:
        // `TileRays` pads its rows).
        let wide = lx1 - lx0 + 1 >= CHUNK;
        let first = if wide { lx0 & !(CHUNK - 1) } else { lx0 };
        for by in ly0 / CHUNK..=ly1 / CHUNK {
            let (r0, r1) = ((by * CHUNK).max(ly0), (by * CHUNK + CHUNK - 1).min(ly1));
            let full_rows = r1 - r0 == CHUNK - 1;
            for base in (first..=lx1).step_by(CHUNK) {
                let (a, b) = (lx0.saturating_sub(base), (lx1 - base).min(CHUNK - 1));
                let span: u32 = ((1u32 << (b + 1)) - 1) & !((1u32 << a) - 1);
                // A block inside the box whose certain signs settle all of it.
                let block = match whole {
                    Some(g) if full_rows && span == 0xff => Some(g),
                    _ => (full_rows && span == 0xff)
                        .then(|| f.block(rays, r0, base))
                        .filter(|g| g.rejected() | g.inside_pos() | g.inside_neg() == 0xff),
                };
                if block.is_some_and(|g| g.rejected() == 0xff) {
                    // What 64 settled, rejected lanes count (`chunk_hits`).
                    let n = (CHUNK * CHUNK) as u64;
                    c.coverage_tests += n;
                    c.fast_decided += n;
                    continue;
                }
                if block.is_some_and(|g| g.rejected() == 0) && out.cov.is_empty() {
                    let d =
                        depth.get_or_insert_with(|| ChunkDepth::new(cam, &TriDepth::new(cam, t)));
                    let &mut (s, whole) = screen.get_or_insert_with(|| {
                        let s = TriSetup::screen_depth(plane_screen, cam, d, rays);
                        let whole = s.and_then(|s| s.rect(rays, [lx0, lx1, ly0, ly1]));
                        (s, whole)
                    });
                    // (Matches, not closures: a closure would not inherit
                    // the caller's target features, nor inline its intrinsics.)
                    let bound = match (s, whole) {
                        (Some(_), Some(b)) => Some(b),
                        (Some(s), None) => s.block(rays, r0, base),
                        (None, _) => None,
                    };
                    let done = match (s, bound) {
                        (Some(s), Some(b)) => {
                            let at = (r0, base);
                            screen_block(l, cam, prim, rays, &s, d, b, at, out);
                            true
                        }
                        _ => false,
                    };
                    if done || {
                        rays.ensure_dirs(l);
                        covered_block(l, cam, prim, rays, d, (r0, base), out)
                    } {
                        // What 64 settled, covered lanes count (`chunk_hits`).
                        let n = (CHUNK * CHUNK) as u64;
                        c.coverage_tests += n;
                        c.fast_decided += n;
                        c.covered += n;
                        continue;
                    }
                }
                // The rows' depths from the screen-space interpolant where a
                // bound covers them: the box's, or a block's inside it.
                // (Boxes of a block or more: set up like the covered blocks'.
                // A smaller box's few rows take the rays' depths, which cost
                // less than this setup.)
                let rows_screen = if big {
                    let d =
                        depth.get_or_insert_with(|| ChunkDepth::new(cam, &TriDepth::new(cam, t)));
                    let &mut (s, whole) = screen.get_or_insert_with(|| {
                        let s = TriSetup::screen_depth(plane_screen, cam, d, rays);
                        let whole = s.and_then(|s| s.rect(rays, [lx0, lx1, ly0, ly1]));
                        (s, whole)
                    });
                    match (s, whole) {
                        (Some(s), Some(b)) => Some((s, b)),
                        (Some(s), None) if full_rows && span == 0xff => {
                            s.block(rays, r0, base).map(|b| (s, b))
                        }
                        _ => None,
                    }
                } else {
                    None
                };
                for ly in r0..=r1 {
                    let sg = match block {
                        Some(g) => g,
                        None => {
                            // Screen-space signs need no rays; where they
                            // leave a lane of the span open, the rays' own.
                            let g = f.screen_chunk(l, rays, ly, base);
                            if span & !(g.rejected() | g.inside_pos() | g.inside_neg()) == 0 {
                                g
                            } else {
                                rays.ensure_dirs(l);
                                f.chunk(l, rays, ly, base)
                            }
                        }
                    };
                    let at = (ly, base, span);
                    let d = &mut *depth;
                    chunk_hits(l, cam, t, prim, edges, rays, sg, at, d, rows_screen, out, c);
                }
            }
        }
    }
}

/// An 8x8 block (top-left tile pixel `(base, r0)`) the triangle covers
/// whole, by certain signs: the depths of its 64 pixels computed before any
/// is tested (so their divisions overlap), and the keys updated, when the
/// clamp-free shortcut settles every one of them ([`ChunkDepth`]); false,
/// with nothing written, when some lane needs the slab (the caller then
/// takes the block row by row).
#[inline(always)]
fn covered_block<L: ChunkOps>(
    l: L,
    cam: &Camera,
    prim: u32,
    rays: &TileRays,
    d: &ChunkDepth,
    (r0, base): (usize, usize),
    out: &mut TileOut,
) -> bool {
    let mut z = [[0f32; CHUNK]; CHUNK];
    let (mut ok, mut free) = ([0u32; CHUNK], 0xffu32);
    for (i, (z, ok)) in z.iter_mut().zip(&mut ok).enumerate() {
        match d.clamp_free(l, cam, rays.rays_at(r0 + i, base)) {
            Some((zi, oki, fi)) => {
                (*z, *ok) = (zi, oki);
                free &= fi;
            }
            None => return false,
        }
    }
    if free != 0xff {
        return false;
    }
    for (i, (z, &ok)) in z.iter().zip(&ok).enumerate() {
        l.min_keys(out.chunk_mut(base, r0 + i), z, ok, prim);
    }
    true
}

/// An 8x8 block the triangle covers whole, by certain signs, whose depths
/// come from its screen-space interpolant ([`crate::raster::screen_depth`])
/// under `bound` (the block's, or its box's): every lane the rounding
/// certificate settles keeps the interpolant's f32, the rest of its row
/// takes [`ChunkDepth`] (the depth function bit for bit), and the keys are
/// updated.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn screen_block<L: ChunkOps>(
    l: L,
    cam: &Camera,
    prim: u32,
    rays: &mut TileRays,
    s: &ScreenDepth,
    d: &ChunkDepth,
    bound: BlockBound,
    (r0, base): (usize, usize),
    out: &mut TileOut,
) {
    let done = if bound.all_hit {
        let mut rows = out.block_rows(base, r0);
        s.block_keys(l, rays, (r0, base), bound.eu, &mut rows, prim)
    } else {
        0
    };
    for i in (0..CHUNK).filter(|i| (done >> i) & 1 == 0) {
        let keys = out.chunk_mut(base, r0 + i);
        let (z, ok, sure) = s.row(l, rays, r0 + i, base, bound.eu);
        let (z, ok) = if sure == 0xff {
            (z, ok)
        } else {
            rays.ensure_dirs(l);
            d.depths(l, cam, rays.rays_at(r0 + i, base), 0xff)
        };
        l.min_keys(keys, &z, ok, prim);
    }
}

/// A box of at most [`SMALL_BOX`] pixels: the predicate per pixel, as
/// [`TriEdges::covers`] asks it, with the predicate's own f64 filter
/// ([`crate::predicate::EdgePlane::sign_with`]: same operands, same order)
/// evaluated here for every pixel and edge at once ([`ChunkOps::small_signs`]:
/// in AVX2 one edge plane per lane, 1-3% faster on `million` than one
/// pixel per lane), so only the signs it cannot settle call it (which
/// then counts its exact fallbacks and ties as always). When the filter
/// settles every sign of the box (nearly always), the coverage of all its
/// pixels is read off the sign masks at once, counted as [`covers_by`]
/// counts it (a branchy loop per pixel cost 6% of the raster's pass on
/// `million`). Depth by [`ChunkDepth::depth_at`], [`TriDepth::depth`] bit
/// for bit.
///
/// (The three edge planes are set up whether or not an early exit would
/// have spared one: on a million triangles, the branch per sign of the
/// lazy form cost more than the planes.)
/// A small box's pixels row by row, one lane each (spare lanes repeat the
/// first), and their count; from tables by the box's width, without a
/// loop whose branches follow the box's shape (mispredicted on a mesh of
/// small triangles of every orientation).
#[inline(always)]
fn small_box_pixels([lx0, lx1, ly0, ly1]: [usize; 4]) -> ([(usize, usize); SMALL_BOX], usize) {
    /// Per width `w` (index `w - 1`), lane `j`'s column and row: `(j % w,
    /// j / w)`.
    const STEP: [[(u8, u8); SMALL_BOX]; SMALL_BOX] = {
        let mut t = [[(0, 0); SMALL_BOX]; SMALL_BOX];
        let mut w = 1;
        while w <= SMALL_BOX {
            let mut j = 0;
            while j < SMALL_BOX {
                t[w - 1][j] = ((j % w) as u8, (j / w) as u8);
                j += 1;
            }
            w += 1;
        }
        t
    };
    let (w, n) = (lx1 - lx0 + 1, (lx1 - lx0 + 1) * (ly1 - ly0 + 1));
    debug_assert!((1..=SMALL_BOX).contains(&n));
    let step = &STEP[w - 1];
    let mut at = [(lx0, ly0); SMALL_BOX];
    for (j, (a, &(dx, dy))) in at.iter_mut().zip(step).enumerate() {
        if j < n {
            *a = (lx0 + usize::from(dx), ly0 + usize::from(dy));
        }
    }
    (at, n)
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn small_box<L: ChunkOps>(
    l: L,
    cam: &Camera,
    t: &Tri,
    prim: u32,
    rays: &TileRays,
    [lx0, lx1, ly0, ly1]: [usize; 4],
    out: &mut TileOut,
    c: &mut Counters,
) {
    let (at, n) = small_box_pixels([lx0, lx1, ly0, ly1]);
    let mut d = [[0f64; 4]; 3];
    for (j, &(lx, ly)) in at.iter().enumerate() {
        let v = rays.dir(lx, ly);
        (d[0][j], d[1][j], d[2][j]) = (v.x, v.y, v.z);
    }
    let e = cam.eye;
    let (front, back, open) = l.small_signs(e, t, &d, n);
    let mut depth: Option<ChunkDepth> = None;
    if open == 0 {
        // Every sign settled (the common case): what `covers_by` would
        // return and count, per lane, without asking it (it would call the
        // predicate for none of them).
        let hit = front | back;
        c.coverage_tests += n as u64;
        c.covered += u64::from(hit.count_ones());
        let mut rest = hit;
        while rest != 0 {
            let j = rest.trailing_zeros() as usize;
            rest &= rest - 1;
            let (lx, ly) = at[j];
            let facing = if (front >> j) & 1 == 1 { 1 } else { -1 };
            // (Inlined: out of line, the call cost a few percent on a
            // million small boxes. A `match`, not `get_or_insert_with`: a
            // second caller made the compiler keep that closure out of
            // line, compiled without AVX2, and every intrinsic in it became
            // a call; the whole pass ran 2.5x slower.)
            let d = match depth {
                Some(ref d) => d,
                None => &*depth.insert(l.chunk_depth(cam, t)),
            };
            if let Some(z) = d.depth_at(cam, rays, lx, ly) {
                out.offer(lx, ly, hit_key(z, prim), facing);
            }
        }
        return;
    }
    // Some sign open: the planes again, each sign from the filter's masks
    // or the predicate, in `covers_by`'s order. (Not array `map`: its
    // closure compiled to an out-of-line call here, once per small box.)
    let (a, b, v2) = (t[0].as_dvec3(), t[1].as_dvec3(), t[2].as_dvec3());
    let planes = [
        EdgePlane::new(e, a, b),
        EdgePlane::new(e, b, v2),
        EdgePlane::new(e, v2, a),
    ];
    let (pos, neg) = l.filter4(&planes, &d);
    for (j, &(lx, ly)) in at[..n].iter().enumerate() {
        let facing = covers_by(
            c,
            #[inline(always)]
            |k, c| {
                if (pos[k] >> j) & 1 == 1 {
                    1
                } else if (neg[k] >> j) & 1 == 1 {
                    -1
                } else {
                    edge_sign(cam, &planes[k], &rays.ray(lx, ly), c)
                }
            },
        );
        if facing != 0 {
            // (Inlined: out of line, the call cost a few percent on a
            // million small boxes. A `match`, not `get_or_insert_with`: a
            // second caller made the compiler keep that closure out of
            // line, compiled without AVX2, and every intrinsic in it became
            // a call; the whole pass ran 2.5x slower.)
            let d = match depth {
                Some(ref d) => d,
                None => &*depth.insert(l.chunk_depth(cam, t)),
            };
            if let Some(z) = d.depth_at(cam, rays, lx, ly) {
                out.offer(lx, ly, hit_key(z, prim), facing);
            }
        }
    }
}

/// One chunk of a triangle's box: lanes `span` of tile row `ly` from column
/// `base`, with certain signs `sg` (from the chunk or its whole block).
/// Settled lanes are counted as [`covers_by`] would count them, the rest ask
/// the predicate in its order; covered lanes get their depth 8 at a time and
/// update the keys (and coverage counts).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn chunk_hits<L: ChunkOps>(
    l: L,
    cam: &Camera,
    t: &Tri,
    prim: u32,
    edges: &TriEdges,
    rays: &mut TileRays,
    sg: ChunkSigns,
    (ly, base, span): (usize, usize, u32),
    depth: &mut Option<ChunkDepth>,
    screen: Option<(ScreenDepth, BlockBound)>,
    out: &mut TileOut,
    c: &mut Counters,
) {
    let rejected = sg.rejected() & span;
    let (mut back, mut front) = (sg.inside_pos() & span, sg.inside_neg() & span);
    let inside = back | front;
    // What `covers_by` would count for the lanes settled here.
    let decided = u64::from((rejected | inside).count_ones());
    c.coverage_tests += decided;
    c.fast_decided += decided;
    c.covered += u64::from(inside.count_ones());
    let mut unsure = span & !rejected & !inside;
    if unsure != 0 {
        rays.ensure_dirs(l);
    }
    while unsure != 0 {
        let j = unsure.trailing_zeros() as usize;
        unsure &= unsure - 1;
        let ray = rays.ray(base + j, ly);
        // Certain signs stand (they are the predicate's own);
        // the rest go to the predicate, in `covers_by`'s order.
        let facing = covers_by(c, |k, c| match sg.sign(k, j) {
            0 => edge_sign(cam, &edges.0[k], &ray, c),
            s => s,
        });
        back |= u32::from(facing > 0) << j;
        front |= u32::from(facing < 0) << j;
    }
    if back | front == 0 {
        return;
    }
    let covered = back | front;
    // Certified screen-space depths where they cover every covered lane
    // (`ScreenDepth::row`: the depth function's f32 and hit there), else
    // the depth function from the rays.
    let from_screen = screen.and_then(|(s, b)| {
        let (z, ok, sure) = s.row(l, rays, ly, base, b.eu);
        (covered & !sure == 0).then_some((z, ok))
    });
    let (z, ok) = match from_screen {
        Some(zo) => zo,
        None => {
            rays.ensure_dirs(l);
            let d = depth.get_or_insert_with(|| ChunkDepth::new(cam, &TriDepth::new(cam, t)));
            d.depths(l, cam, rays.rays_at(ly, base), covered)
        }
    };
    let mut m = covered & ok;
    if span == 0xff && out.cov.is_empty() {
        // All 8 lanes lie in the box (so in the tile): the z-buffer test 8 at a time.
        l.min_keys(out.chunk_mut(base, ly), &z, m, prim);
        return;
    }
    while m != 0 {
        let j = m.trailing_zeros() as usize;
        m &= m - 1;
        let facing = if (back >> j) & 1 == 1 { 1 } else { -1 };
        out.offer(base + j, ly, hit_key(z[j], prim), facing);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::predicate::tests::lcg;
    use glam::{DVec3, Vec3};

    /// Renders with and without the fast path, with and without coverage
    /// counts, and checks every buffer and count is the same bit for bit
    /// (`fast_decided` aside). Returns the fast render's counts.
    fn fast_equals_exact(what: &str, scene: &ResolvedScene) -> Counters {
        let mut out = Counters::default();
        for count_coverage in [false, true] {
            let opts = RasterOptions {
                count_coverage,
                deadline: None,
            };
            let f = render(scene, opts, &|_| {});
            let e = render_exact(scene, opts, &|_| {});
            for i in 0..f.prim.len() {
                let at = (i % f.width as usize, i / f.width as usize);
                assert_eq!(f.prim[i], e.prim[i], "{what}: id.prim at {at:?}");
                assert_eq!(f.z[i].to_bits(), e.z[i].to_bits(), "{what}: Z at {at:?}");
                assert_eq!(f.object[i], e.object[i], "{what}: id.object at {at:?}");
                let bits = |n: [f32; 3]| n.map(f32::to_bits);
                assert_eq!(bits(f.normal[i]), bits(e.normal[i]), "{what}: N at {at:?}");
            }
            assert_eq!(f.coverage, e.coverage, "{what}: coverage counts");
            assert_eq!(
                e.counters.fast_decided, 0,
                "{what}: the exact path took shortcuts"
            );
            let mut fc = f.counters;
            fc.fast_decided = 0;
            assert_eq!(fc, e.counters, "{what}: operation counts");
            out = f.counters;
        }
        out
    }

    fn camera(eye: DVec3, at: DVec3, vfov: f64, w: u32, h: u32) -> Camera {
        Camera::new(eye, at, DVec3::Y, vfov, w, h, 1e-3, f64::INFINITY).unwrap()
    }

    /// The point at ray parameter `t` along pixel `(x, y)`'s ray, rounded to f32:
    /// for the exact cameras below, exactly on the ray through the pixel center.
    fn on_ray(cam: &Camera, x: u32, y: u32, t: f64) -> Vec3 {
        (cam.eye + cam.pixel_ray(x, y).dir * t).as_vec3()
    }

    /// Triangles whose vertices lie on pixel-center rays (so edges pass through
    /// or within f32 rounding of pixel centers), pairs sharing such edges with
    /// both windings, slivers, huge triangles and triangles behind the eye.
    fn adversarial(cam: &Camera, seed: u64, n: usize) -> Vec<Tri> {
        let mut s = seed;
        let (w, h) = (cam.width, cam.height);
        let px = |s: &mut u64| {
            let x = ((lcg(s) * 0.5 + 0.5) * f64::from(w)) as u32;
            let y = ((lcg(s) * 0.5 + 0.5) * f64::from(h)) as u32;
            (x.min(w - 1), y.min(h - 1))
        };
        let depths = [1.0, 2.0, 1.5, 3.0, 1.25];
        let mut tris = Vec::new();
        for i in 0..n {
            let t = |s: &mut u64| depths[((lcg(s) * 0.5 + 0.5) * 5.0) as usize % 5];
            let (p, q, r) = (px(&mut s), px(&mut s), px(&mut s));
            let a = on_ray(cam, p.0, p.1, t(&mut s));
            let b = on_ray(cam, q.0, q.1, t(&mut s));
            let c = on_ray(cam, r.0, r.1, t(&mut s));
            match i % 5 {
                0 => tris.push([a, b, c]),
                1 => {
                    // A shared edge, the second triangle in either winding.
                    let d = on_ray(cam, px(&mut s).0, px(&mut s).1, t(&mut s));
                    tris.push([a, b, c]);
                    tris.push(if lcg(&mut s) > 0.0 {
                        [b, a, d]
                    } else {
                        [a, b, d]
                    });
                }
                2 => {
                    // A sliver: the third vertex within a few f32 ulps of the edge's middle.
                    let m = (a + b) * 0.5;
                    let e = Vec3::new(m.x.next_up(), m.y, m.z.next_down());
                    tris.push([a, b, if lcg(&mut s) > 0.0 { m } else { e }]);
                }
                3 => {
                    // Huge: far beyond the image, edges still through pixel centers.
                    let far = on_ray(cam, p.0, p.1, 1e6);
                    tris.push([far, b, c]);
                }
                _ => {
                    // One vertex behind the eye (clipped for the bounds only).
                    let behind = (cam.eye - cam.pixel_ray(q.0, q.1).dir * 0.5).as_vec3();
                    tris.push([a, behind, c]);
                }
            }
        }
        tris
    }

    /// Edges through and within a few ulps of pixel centers, at offsets from 0
    /// to 1e7, exact and tilted cameras, an odd image (a column of rays with
    /// `D.x = 0`), slivers, huge triangles: the fast path defers the undecidable
    /// pixels to the predicate (ties and exact fallbacks happen, with the same
    /// counts as the pure predicate path) and every buffer is the pure path's.
    #[test]
    fn fast_path_equals_the_predicate_path_at_pixel_centers() {
        let mut deferred = 0;
        let mut ties = 0;
        for (k, off) in [0.0, 1e3, 1e5, 12345.678, 1e7].into_iter().enumerate() {
            let o = DVec3::new(off, -off, off);
            for (w, h) in [(32, 32), (33, 33), (40, 24)] {
                let cams = [
                    // Exact: pixel centers are dyadic on the plane at depth 1.
                    camera(o + DVec3::Z, o, 90.0, w, h),
                    // Tilted, non-dyadic.
                    camera(
                        o + DVec3::new(0.3, 0.7, 2.1),
                        o + DVec3::new(0.1, -0.2, 0.0),
                        50.0,
                        w,
                        h,
                    ),
                ];
                for (ci, cam) in cams.into_iter().enumerate() {
                    let what = format!("offset {off}, {w}x{h}, camera {ci}");
                    let tris = adversarial(&cam, 17 + k as u64 * 31 + u64::from(w), 25);
                    let c = fast_equals_exact(&what, &ResolvedScene::from_triangles(cam, tris));
                    assert!(c.fast_decided > 0, "{what}: nothing decided fast");
                    deferred += c.coverage_tests - c.fast_decided;
                    ties += c.ties;
                }
            }
        }
        assert!(
            ties > 100 && deferred > 100,
            "ties {ties}, deferred {deferred}"
        );
    }

    /// The grid of `bench crossover`, exactly over the image: grid lines and
    /// diagonals through pixel centers, so every such center is a tie.
    #[test]
    fn aligned_grid_ties_are_deferred_and_decided_by_the_rule() {
        for nx in [1, 3, 8] {
            let cam = camera(DVec3::Z, DVec3::ZERO, 90.0, 64, 64);
            let tris = crate::scene::generators::grid([-1.0, -1.0], [1.0, 1.0], nx, nx)
                .iter()
                .map(|t| t.map(|v| v.as_vec3()))
                .collect();
            let scene = ResolvedScene::from_triangles(cam, tris);
            let c = fast_equals_exact(&format!("grid {nx}"), &scene);
            assert!(c.ties > 0 && c.fast_decided < c.coverage_tests);
            let f = render(&scene, RasterOptions::default(), &|_| {});
            assert!(f.prim.iter().all(|&p| p != u32::MAX), "grid {nx}: a crack");
        }
    }

    /// Random triangles at scales from 1e-6 to 1e6 seen from far away and
    /// close by: the depth of every lane and the coverage of every pixel match.
    #[test]
    fn fast_path_equals_the_predicate_path_at_extreme_scales() {
        let mut s = 99u64;
        for i in 0..24 {
            let scale = 10f64.powi((i % 13) - 6);
            let eye = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s) + 3.0) * scale;
            let cam = camera(
                eye,
                DVec3::ZERO,
                [30.0, 90.0, 120.0][i as usize % 3],
                37,
                29,
            );
            let tris = (0..30)
                .map(|_| {
                    let c = DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * scale;
                    let r = scale * [1.0, 0.01, 1e-4][(i as usize / 3) % 3];
                    [0; 3].map(|_| {
                        (c + DVec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * r).as_vec3()
                    })
                })
                .collect();
            fast_equals_exact(
                &format!("scale {scale}"),
                &ResolvedScene::from_triangles(cam, tris),
            );
        }
    }

    /// Planes filling the view, where whole blocks take their depth from
    /// the screen-space interpolant ([`crate::raster::screen_depth`]):
    /// facing the camera, world-axis walls, tilted up to grazing, a copy of
    /// one a hair behind and a coplanar duplicate (the z-test and the tie
    /// on prim), with the eye up to 1e7 from the origin and near and far
    /// planes cutting through them. Every buffer and count matches.
    #[test]
    fn screen_depth_blocks_equal_the_predicate_path() {
        let mut s = 5u64;
        for (i, off) in [0.0, 1e3, 1e5, 1e7].into_iter().enumerate() {
            let o = DVec3::new(off, -0.5 * off, off);
            for (near, far) in [(1e-3, f64::INFINITY), (2.2, 3.1)] {
                let cams = [
                    Camera::new(o + DVec3::Z, o, DVec3::Y, 90.0, 80, 72, near, far),
                    Camera::new(
                        o + DVec3::new(0.3, 0.7, 2.1),
                        o,
                        DVec3::Y,
                        50.0,
                        72,
                        64,
                        near,
                        far,
                    ),
                ];
                for cam in cams.map(Result::unwrap) {
                    let (e, f, r, u) = (cam.eye, cam.forward, cam.right, cam.up_ortho);
                    let mut tris = Vec::new();
                    let mut quad = |c: DVec3, a: DVec3, b: DVec3| {
                        let p = [c - a - b, c + a - b, c + a + b, c - a + b].map(|v| v.as_vec3());
                        tris.push([p[0], p[1], p[2]]);
                        tris.push([p[0], p[2], p[3]]);
                    };
                    let c = e + f * 2.5;
                    quad(c, r * 10.0, u * 10.0);
                    quad(c + f * 1e-4, r * 10.0, u * 10.0);
                    quad(c, r * 10.0, u * 10.0);
                    quad(c + f * 0.3, DVec3::X * 10.0, DVec3::Y * 10.0);
                    quad(c - f * 0.2, DVec3::Y * 10.0, DVec3::Z * 10.0);
                    let tilt = 0.01 + lcg(&mut s).abs();
                    quad(
                        c,
                        (r + f * tilt).normalize() * 10.0,
                        (u - f * tilt).normalize() * 10.0,
                    );
                    fast_equals_exact(
                        &format!("offset {off}, near {near}, far {far}, camera {i}"),
                        &ResolvedScene::from_triangles(cam, tris),
                    );
                }
            }
        }
    }

    /// Buffers of two key sets (the keys decide z, prim and the rest).
    fn same_keys(a: &PixelKeys, b: &PixelKeys) -> bool {
        a.keys == b.keys && a.coverage == b.coverage
    }

    /// Scenes whose vertices sit on pixel-center rays (so box edges fall on
    /// pixel centers, up to rounding) at offsets up to 1e7, tilted cameras,
    /// triangles crossing the near plane and behind the eye, and tiny ones.
    fn box_scenes() -> Vec<(String, ResolvedScene)> {
        let mut out = Vec::new();
        for (k, off) in [0.0, 1e3, 12345.678, 1e7].into_iter().enumerate() {
            let o = DVec3::new(off, -off, off);
            for (w, h) in [(33, 33), (40, 24)] {
                let cams = [
                    camera(o + DVec3::Z, o, 90.0, w, h),
                    camera(
                        o + DVec3::new(0.3, 0.7, 2.1),
                        o + DVec3::new(0.1, -0.2, 0.0),
                        50.0,
                        w,
                        h,
                    ),
                ];
                for (ci, cam) in cams.into_iter().enumerate() {
                    let mut tris = adversarial(&cam, 5 + k as u64 * 7 + u64::from(w), 40);
                    // Tiny triangles around pixel centers: most cover no center.
                    let mut s = 11 + k as u64;
                    for _ in 0..60 {
                        let (x, y) = (
                            ((lcg(&mut s) * 0.5 + 0.5) * f64::from(w)) as u32 % w,
                            ((lcg(&mut s) * 0.5 + 0.5) * f64::from(h)) as u32 % h,
                        );
                        let p = on_ray(&cam, x, y, 1.5).as_dvec3();
                        let d = 1e-2 * (1.0 + off.abs()).sqrt() * 1e-2;
                        let v =
                            |s: &mut u64| (p + DVec3::new(lcg(s), lcg(s), lcg(s)) * d).as_vec3();
                        tris.push([v(&mut s), v(&mut s), v(&mut s)]);
                    }
                    let what = format!("offset {off}, {w}x{h}, camera {ci}");
                    out.push((what, ResolvedScene::from_triangles(cam, tris)));
                }
            }
        }
        out
    }

    /// Tight boxes ([`crate::raster::bounds`]) against whole-image boxes: the
    /// same keys and coverage counts, so no box lost a pixel; and with the
    /// margin multiplied by 0 some box does lose one (the margin is needed,
    /// and this test would notice a wrong one).
    #[test]
    fn tight_boxes_lose_no_pixel() {
        let mut lost_without_margin = 0;
        for (what, scene) in box_scenes() {
            let opts = RasterOptions {
                count_coverage: true,
                deadline: None,
            };
            let exact = Mode::new(&scene.camera, false);
            let whole = keys_impl(
                &scene,
                opts,
                Mode {
                    margin: None,
                    ..exact
                },
                &|_| {},
                None,
            );
            let tight = render_keys(&scene, opts, &|_| {});
            assert!(
                same_keys(&whole, &tight),
                "{what}: a tight box lost a pixel"
            );
            let m = BoxMargin::new(&scene.camera).scaled(0.0);
            let bare = keys_impl(
                &scene,
                opts,
                Mode {
                    margin: Some(m),
                    ..exact
                },
                &|_| {},
                None,
            );
            lost_without_margin += usize::from(!same_keys(&whole, &bare));
            assert!(
                tight.counters.coverage_tests < whole.counters.coverage_tests,
                "{what}: boxes did not shrink"
            );
        }
        assert!(lost_without_margin > 0, "no scene needs the margin");
    }

    /// Layers of triangles nearly facing the camera, 0.4% apart in depth,
    /// drawn back to front and front to back, under an exact and a tilted
    /// camera at offsets up to 1e7, plus the adversarial scenes: hidden
    /// triangles abound.
    fn layered_scenes() -> Vec<(String, ResolvedScene)> {
        let mut out = box_scenes();
        for (k, off) in [0.0, 1e3, 1e7].into_iter().enumerate() {
            let o = DVec3::new(off, -off, off);
            let cams = [
                camera(o + DVec3::Z * 3.0, o, 60.0, 37, 29),
                camera(o + DVec3::new(0.4, -1.1, 3.0), o, 45.0, 48, 40),
                camera(o + DVec3::new(-3.0, 0.2, 0.1), o, 50.0, 40, 40),
            ];
            for (ci, cam) in cams.into_iter().enumerate() {
                let mut s = 7 + k as u64 * 13 + ci as u64;
                // A screen-filling wall facing the camera just behind the
                // nearest layers: what they hide behind is all known.
                let wall = cam.eye + cam.forward * (2.5 * 1.006);
                let (r, u) = (cam.right * 100.0, cam.up_ortho * 100.0);
                let mut tris = vec![[wall - r - u, wall + r - u, wall + u].map(|v| v.as_vec3())];
                for order in [1.0, -1.0] {
                    for i in 0..12 {
                        let t = 1.0 + order * 0.004 * f64::from(i);
                        let (x, y) = (
                            ((lcg(&mut s) * 0.5 + 0.5) * 30.0) as u32,
                            ((lcg(&mut s) * 0.5 + 0.5) * 25.0) as u32,
                        );
                        let c = cam.eye + cam.pixel_ray(x, y).dir * (2.5 * t);
                        // Every other triangle parallel to the image plane.
                        let tilt = if i % 2 == 0 { 0.0 } else { 0.05 };
                        let v = |s: &mut u64| {
                            let (a, b) = (lcg(s), lcg(s));
                            let w = cam.right * a + cam.up_ortho * b + cam.forward * lcg(s) * tilt;
                            (c + w * 1.5).as_vec3()
                        };
                        tris.push([v(&mut s), v(&mut s), v(&mut s)]);
                    }
                }
                let what = format!("layers, offset {off}, camera {ci}");
                out.push((what, ResolvedScene::from_triangles(cam, tris)));
            }
        }
        out
    }

    /// Skipping hidden triangles ([`crate::raster::hiz`]) changes no buffer,
    /// in the fast and the predicate path, and skips some; with the depth
    /// bound 1% too high some buffer changes (the bound is tight enough to
    /// matter and this test would notice a wrong one).
    /// A small box's lanes are its pixels row by row, then the first
    /// repeated, for every box shape and position.
    #[test]
    fn small_box_lanes_are_its_pixels_row_by_row() {
        for (lx0, ly0) in [(0, 0), (5, 30), (28, 1)] {
            for w in 1..=SMALL_BOX {
                for h in (1..=SMALL_BOX).filter(|h| w * h <= SMALL_BOX) {
                    let (lx1, ly1) = (lx0 + w - 1, ly0 + h - 1);
                    let mut want = vec![];
                    for ly in ly0..=ly1 {
                        for lx in lx0..=lx1 {
                            want.push((lx, ly));
                        }
                    }
                    let n = want.len();
                    want.resize(SMALL_BOX, (lx0, ly0));
                    assert_eq!(
                        small_box_pixels([lx0, lx1, ly0, ly1]),
                        (want.try_into().unwrap(), n),
                        "{w}x{h} at ({lx0}, {ly0})"
                    );
                }
            }
        }
    }

    #[test]
    fn hidden_triangles_are_skipped_exactly() {
        let (mut skipped, mut broken) = (0, 0);
        let opts = RasterOptions::default();
        for (what, scene) in layered_scenes() {
            for fast in [true, false] {
                let on = Mode::new(&scene.camera, fast);
                let off = keys_impl(&scene, opts, Mode { hiz: false, ..on }, &|_| {}, None);
                let with = keys_impl(&scene, opts, on, &|_| {}, None);
                assert!(same_keys(&off, &with), "{what}: skipping changed a key");
                // The counter says exactly what was skipped.
                assert_eq!(off.counters.hidden_skipped, 0, "{what}");
                assert_eq!(
                    off.counters.triangle_setups - with.counters.triangle_setups,
                    with.counters.hidden_skipped,
                    "{what}: hidden_skipped"
                );
                skipped += with.counters.hidden_skipped;
                let high = Mode {
                    hiz_factor: 1.01,
                    ..on
                };
                let wrong = keys_impl(&scene, opts, high, &|_| {}, None);
                broken += usize::from(!same_keys(&off, &wrong));
            }
            fast_equals_exact(&what, &scene);
        }
        assert!(skipped > 100, "only {skipped} setups skipped");
        assert!(broken > 0, "a bound 1% too high broke nothing");
    }
}
