//! The buffers one render produces (docs/DESIGN.md "Buffers"), plus its operation counts.

use crate::scene::resolve::ResolvedScene;
use crate::visibility::{geometric_normal, key_depth, key_prim, Counters, NO_HIT};
use rayon::prelude::*;
use std::mem::MaybeUninit;

/// Background value of the ID buffers.
pub const BACKGROUND_ID: u32 = u32::MAX;

/// Image rows per task of [`Frame::from_keys`] (its normal table lives for
/// a task, so a triangle over a few rows is looked up once).
const FRAME_ROWS: usize = 16;

/// Slots of [`Frame::from_keys`]' table of normals by prim (20 KB: the
/// first-level cache).
const NORMAL_SLOTS: usize = 1024;

/// A frame's four buffers while bands of pixels fill them, unwritten until
/// then: zeroing 48 MB at 1080p only for the bands to overwrite every
/// element cost a memset as long as a tenth of the raster's frame. The
/// raster fills each band of tiles right after drawing it (its triangles
/// still in cache), the other loops through [`Frame::from_keys`]; both
/// through [`BandBuffers::fill`], so the buffers are the same function of
/// the keys.
pub(crate) struct FrameBuffers {
    /// Pixels.
    n: usize,
    /// Depth.
    z: Vec<f32>,
    /// Triangle ids.
    prim: Vec<u32>,
    /// Object ids.
    object: Vec<u32>,
    /// Normals.
    normal: Vec<[f32; 3]>,
}

/// One band of a [`FrameBuffers`], to fill.
pub(crate) struct BandBuffers<'a> {
    /// Depth.
    z: &'a mut [MaybeUninit<f32>],
    /// Triangle ids.
    prim: &'a mut [MaybeUninit<u32>],
    /// Object ids.
    object: &'a mut [MaybeUninit<u32>],
    /// Normals.
    normal: &'a mut [MaybeUninit<[f32; 3]>],
}

impl FrameBuffers {
    /// Room for `n` pixels, none written.
    pub(crate) fn with_capacity(n: usize) -> FrameBuffers {
        FrameBuffers {
            n,
            z: Vec::with_capacity(n),
            prim: Vec::with_capacity(n),
            object: Vec::with_capacity(n),
            normal: Vec::with_capacity(n),
        }
    }

    /// The pixels in bands of `len` (the last one shorter), in order.
    pub(crate) fn bands(&mut self, len: usize) -> Vec<BandBuffers<'_>> {
        let n = self.n;
        let z = self.z.spare_capacity_mut()[..n].chunks_mut(len);
        let prim = self.prim.spare_capacity_mut()[..n].chunks_mut(len);
        let object = self.object.spare_capacity_mut()[..n].chunks_mut(len);
        let normal = self.normal.spare_capacity_mut()[..n].chunks_mut(len);
        z.zip(prim)
            .zip(object.zip(normal))
            .map(|((z, prim), (object, normal))| BandBuffers {
                z,
                prim,
                object,
                normal,
            })
            .collect()
    }

    /// The four buffers, every pixel's.
    ///
    /// # Safety
    /// Every band of one call of [`FrameBuffers::bands`] was filled
    /// ([`BandBuffers::fill`]).
    pub(crate) unsafe fn assume_filled(mut self) -> (Vec<f32>, Vec<u32>, Vec<u32>, Vec<[f32; 3]>) {
        let n = self.n;
        // SAFETY: the caller's contract: the bands partition `0..n` of each
        // vector (`n` within each one's capacity) and `fill` wrote every
        // element of its band.
        unsafe {
            self.z.set_len(n);
            self.prim.set_len(n);
            self.object.set_len(n);
            self.normal.set_len(n);
        }
        (self.z, self.prim, self.object, self.normal)
    }
}

impl BandBuffers<'_> {
    /// Writes every pixel of the band from its `keys` (as many): depth and
    /// prim from the key, object id and normal looked up from the prim.
    /// A small table by prim keeps the object ids and normals of the
    /// triangles the band met (a normal is an f64 cross product, square
    /// root and division; on a dense mesh a triangle spans a few pixels
    /// over two or three rows).
    pub(crate) fn fill(self, scene: &ResolvedScene, keys: &[u64]) {
        let BandBuffers {
            z,
            prim,
            object,
            normal,
        } = self;
        let m = keys.len();
        assert!(z.len() == m && prim.len() == m && object.len() == m && normal.len() == m);
        // Slot `p % NORMAL_SLOTS` holds prim `p`'s object id and normal
        // when its tag is `p`. Every slot starts with a tag that does not
        // map to it (`u32::MAX` maps to the last slot, whose tag starts at
        // 0), so no prim reads a slot it did not fill.
        let mut cache = [(u32::MAX, BACKGROUND_ID, [0f32; 3]); NORMAL_SLOTS];
        cache[NORMAL_SLOTS - 1].0 = 0;
        for (i, &k) in keys.iter().enumerate() {
            z[i].write(key_depth(k));
            let p = key_prim(k);
            prim[i].write(p);
            if k == NO_HIT {
                object[i].write(BACKGROUND_ID);
                normal[i].write([0.0; 3]);
                continue;
            }
            let slot = &mut cache[p as usize % NORMAL_SLOTS];
            if slot.0 != p {
                let t = &scene.triangles[p as usize];
                *slot = (p, scene.object_ids[p as usize], geometric_normal(t));
            }
            object[i].write(slot.1);
            normal[i].write(slot.2);
        }
    }
}

/// Per-pixel results of a visibility render, row-major, row 0 at the top.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Planar depth, +inf for background.
    pub z: Vec<f32>,
    /// Triangle id, [`BACKGROUND_ID`] for background.
    pub prim: Vec<u32>,
    /// Object id, [`BACKGROUND_ID`] for background.
    pub object: Vec<u32>,
    /// Geometric normal of the visible triangle (world space), 0 for background.
    pub normal: Vec<[f32; 3]>,
    /// Optional per-pixel coverage counts (front-facing, back-facing), for watertightness checks.
    pub coverage: Option<Vec<[u16; 2]>>,
    /// What the render cost.
    pub counters: Counters,
    /// Which loop made it ("raster" or "trace").
    pub renderer: String,
    /// Wall-clock seconds of the visibility pass.
    pub seconds: f64,
}

impl Frame {
    /// Builds the buffers from per-pixel winner keys; normals and object ids are
    /// looked up from the winning prim, so both loops fill them identically.
    pub fn from_keys(
        scene: &ResolvedScene,
        keys: &[u64],
        coverage: Option<Vec<[u16; 2]>>,
        counters: Counters,
        renderer: &str,
        seconds: f64,
    ) -> Frame {
        let cam = &scene.camera;
        // Bands of rows across rayon's workers ([`BandBuffers::fill`]).
        let n = keys.len();
        let rows = (cam.width as usize).max(1) * FRAME_ROWS;
        let mut buffers = FrameBuffers::with_capacity(n);
        keys.par_chunks(rows)
            .zip(buffers.bands(rows))
            .for_each(|(keys, band)| band.fill(scene, keys));
        // SAFETY: every band of `bands(rows)` was zipped with the keys'
        // chunk of the same length (both chunk `0..n` by `rows`) and filled.
        let buffers = unsafe { buffers.assume_filled() };
        Frame::from_buffers(scene, buffers, coverage, counters, renderer, seconds)
    }

    /// The frame of buffers a loop filled band by band (the raster's).
    pub(crate) fn from_buffers(
        scene: &ResolvedScene,
        buffers: (Vec<f32>, Vec<u32>, Vec<u32>, Vec<[f32; 3]>),
        coverage: Option<Vec<[u16; 2]>>,
        counters: Counters,
        renderer: &str,
        seconds: f64,
    ) -> Frame {
        let (z, prim, object, normal) = buffers;
        Frame {
            width: scene.camera.width,
            height: scene.camera.height,
            z,
            prim,
            object,
            normal,
            coverage,
            counters,
            renderer: renderer.to_string(),
            seconds,
        }
    }

    /// Index of pixel (x, y).
    pub fn index(&self, x: u32, y: u32) -> usize {
        y as usize * self.width as usize + x as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::visibility::hit_key;

    /// Every pixel's buffers are its own key's: runs of one prim (where a
    /// band's table reuses a lookup), alternating prims, prims that share a
    /// slot of the table (the icosphere's 1280 triangles, prims 1024 apart)
    /// and background all match a per-pixel lookup, across row and band
    /// boundaries too.
    #[test]
    fn buffers_follow_each_pixels_key() {
        for (name, spread) in [("three_triangles", 1), ("icosphere", NORMAL_SLOTS as u32)] {
            buffers_follow_keys(name, spread);
        }
    }

    fn buffers_follow_keys(name: &str, spread: u32) {
        let s = crate::scene::Scene::load(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join(format!("../../scenes/{name}.toml")),
        )
        .unwrap();
        let scene = ResolvedScene::resolve(&s).unwrap();
        let cam = &scene.camera;
        let tris = scene.triangles.len() as u32;
        // Runs of 7 pixels alternate prims `j + spread` and `j`: on the
        // icosphere two prims of one slot.
        assert!(tris > spread, "{name}: too few triangles");
        let keys: Vec<u64> = (0..cam.pixel_count() as u32)
            .map(|i| match (i / 7) % 5 {
                0 => NO_HIT,
                r => hit_key(1.0 + i as f32, r % 2 * spread + i / 97 % (tris - spread)),
            })
            .collect();
        let f = Frame::from_keys(&scene, &keys, None, Counters::default(), "t", 0.0);
        for (i, &k) in keys.iter().enumerate() {
            assert_eq!(
                f.z[i].to_bits(),
                key_depth(k).to_bits(),
                "{name}: pixel {i}"
            );
            assert_eq!(f.prim[i], key_prim(k), "{name}: pixel {i}");
            if k == NO_HIT {
                assert_eq!(
                    (f.object[i], f.normal[i]),
                    (BACKGROUND_ID, [0.0; 3]),
                    "pixel {i}"
                );
            } else {
                let p = key_prim(k) as usize;
                assert_eq!(f.object[i], scene.object_ids[p], "pixel {i}");
                assert_eq!(
                    f.normal[i],
                    geometric_normal(&scene.triangles[p]),
                    "pixel {i}"
                );
            }
        }
    }
}

/// One visibility pass's answer, per-pixel nearest hit keys, before the
/// frame's buffers are filled from them. The raster and the tracer both stop
/// here, so benchmarks can time the two loops like for like.
#[derive(Debug, Clone)]
pub struct PixelKeys {
    /// Nearest hit key per pixel, row-major ([`NO_HIT`] for background).
    pub keys: Vec<u64>,
    /// Per-pixel (front, back) coverage counts, when asked for.
    pub coverage: Option<Vec<[u16; 2]>>,
    /// What the pass cost.
    pub counters: Counters,
    /// Which loop made them ("raster", "trace"), for the frame's record.
    pub renderer: &'static str,
}

impl PixelKeys {
    /// The frame these keys make (`seconds`: what the caller timed).
    pub fn into_frame(self, scene: &ResolvedScene, seconds: f64) -> Frame {
        Frame::from_keys(
            scene,
            &self.keys,
            self.coverage,
            self.counters,
            self.renderer,
            seconds,
        )
    }
}
