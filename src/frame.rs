//! The buffers one render produces (DESIGN.md "Buffers"), plus its operation counts.

use crate::scene::resolve::ResolvedScene;
use crate::visibility::{geometric_normal, key_depth, key_prim, Counters, NO_HIT};
use rayon::prelude::*;

/// Background value of the ID buffers.
pub const BACKGROUND_ID: u32 = u32::MAX;

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
        // One pass per buffer, each split across rayon's workers: at 1080p the
        // lookups touch 2M random triangles, and a serial pass took about an
        // eighth of a one-thread trace.
        let z: Vec<f32> = keys.par_iter().map(|&k| key_depth(k)).collect();
        let prim: Vec<u32> = keys.par_iter().map(|&k| key_prim(k)).collect();
        let object: Vec<u32> = keys
            .par_iter()
            .map(|&k| match k {
                NO_HIT => BACKGROUND_ID,
                k => scene.object_ids[key_prim(k) as usize],
            })
            .collect();
        let normal: Vec<[f32; 3]> = keys
            .par_iter()
            .map(|&k| match k {
                NO_HIT => [0.0; 3],
                k => geometric_normal(&scene.triangles[key_prim(k) as usize]),
            })
            .collect();
        Frame {
            width: cam.width,
            height: cam.height,
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
