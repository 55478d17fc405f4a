//! The rasterizer's binning: every triangle's conservative box
//! ([`crate::raster_bounds`]), then the triangles each tile must consider,
//! in parallel and in triangle order (the keys are the same in any order,
//! but the operation counts of early depth rejection are not).

use crate::raster::{PixelRect, TILE};
use crate::raster_bounds::BoxMargin;
use crate::scene::resolve::ResolvedScene;
use rayon::prelude::*;

/// A triangle in a tile's bin, with the part of its box in the tile (tile
/// coordinates, `[lx0, lx1, ly0, ly1]` inclusive; [`TILE`] fits a byte) and
/// its face for early depth rejection ([`crate::raster_hiz::NearFaces::face`]), so that the tile
/// loop reads only the triangle itself, and not even that for a triangle it
/// skips as hidden.
#[derive(Debug, Clone, Copy)]
pub struct Binned {
    /// The triangle.
    pub prim: u32,
    /// Its box within the tile.
    pub rect: [u8; 4],
    /// Its face ([`crate::raster_hiz`]).
    pub face: f32,
}

const _: () = assert!(TILE <= 256);

/// A box over several tiles, in the binning's per-triangle tile index.
const MANY: u32 = u32::MAX - 1;

/// No box, in the binning's per-triangle tile index.
const NONE: u32 = u32::MAX;

/// Triangles binned into tiles, in parallel and deterministically: chunks of
/// consecutive triangles each sort their (triangle, tile) pairs by tile
/// (counting sort, keeping triangle order), and a tile's bin is its run in
/// every chunk, chunk after chunk: triangles in index order, as one serial
/// pass would bin them (keys and counts depend on that order).
pub struct Bins {
    /// Per chunk, its entries sorted by tile.
    entries: Vec<Vec<Binned>>,
    /// Where each tile's runs start in `runs` (one more offset than tiles).
    tile_runs: Vec<u32>,
    /// The non-empty runs, tile by tile and chunk after chunk within a tile:
    /// `(chunk, start, end)` in that chunk's entries. A chunk's triangles are
    /// neighbours in the mesh and touch few tiles, so most (chunk, tile)
    /// runs are empty; reading every chunk's offsets per tile cost a tenth
    /// of the pass on a million triangles (scattered loads).
    runs: Vec<[u32; 3]>,
}

impl Bins {
    /// Triangles per chunk.
    const GRAIN: usize = 4096;

    /// Bounds ([`crate::raster_bounds`]) and bins of every triangle.
    pub fn new(
        scene: &ResolvedScene,
        margin: Option<BoxMargin>,
        tiles_x: u32,
        tiles_y: u32,
    ) -> Bins {
        let cam = &scene.camera;
        let (w, h) = (cam.width, cam.height);
        let tiles = (tiles_x * tiles_y) as usize;
        // Tile indices stay below the markers.
        assert!(tiles < MANY as usize, "{tiles_x} x {tiles_y} tiles");
        let chunks = scene
            .triangles
            .par_chunks(Self::GRAIN)
            .zip(scene.degenerate.par_chunks(Self::GRAIN))
            .enumerate()
            .map(|(ci, (tris, deg))| {
                let (mut rects, mut face) = (vec![None; tris.len()], vec![0f32; tris.len()]);
                crate::raster_bounds::bounds_into(cam, tris, deg, margin, &mut rects, &mut face);
                // Each box's tile (most boxes of a dense mesh lie in one), or
                // `MANY` / `NONE`, computed once for both passes; and the
                // range of tiles the chunk meets (its triangles are
                // neighbours in the mesh: a few rows of tiles), so that its
                // counts and offsets span that range, not the image's tiles.
                let span = |r: &PixelRect| [r.x0 / TILE, r.x1 / TILE, r.y0 / TILE, r.y1 / TILE];
                let mut tile = vec![NONE; tris.len()];
                let (mut lo, mut hi) = (u32::MAX, 0u32);
                for (r, t) in rects.iter().zip(&mut tile) {
                    let Some(r) = r else { continue };
                    let [tx0, tx1, ty0, ty1] = span(r);
                    let (first, last) = (ty0 * tiles_x + tx0, ty1 * tiles_x + tx1);
                    *t = if first == last { first } else { MANY };
                    (lo, hi) = (lo.min(first), hi.max(last));
                }
                let n = if lo > hi { 0 } else { (hi - lo + 1) as usize };
                let mut start = vec![0u32; n + 1];
                for (r, &t) in rects.iter().zip(&tile) {
                    if t < MANY {
                        start[(t - lo) as usize + 1] += 1;
                    } else if let (MANY, Some(r)) = (t, r) {
                        let [tx0, tx1, ty0, ty1] = span(r);
                        for ty in ty0..=ty1 {
                            for tx in tx0..=tx1 {
                                start[(ty * tiles_x + tx - lo) as usize + 1] += 1;
                            }
                        }
                    }
                }
                for i in 0..n {
                    start[i + 1] += start[i];
                }
                let mut next = start.clone();
                let empty = Binned {
                    prim: 0,
                    rect: [0; 4],
                    face: 0.0,
                };
                let mut entries = vec![empty; start[n] as usize];
                for (i, (r, &t)) in rects.iter().zip(&tile).enumerate() {
                    let prim = (ci * Self::GRAIN + i) as u32;
                    let face = face[i];
                    if t < MANY {
                        // One tile: no loops, and the box (inside the tile
                        // and the image) needs no clipping.
                        let Some(r) = r else { continue };
                        let slot = &mut next[(t - lo) as usize];
                        let (x0, y0) = (r.x0 / TILE * TILE, r.y0 / TILE * TILE);
                        entries[*slot as usize] = Binned {
                            prim,
                            rect: [r.x0 - x0, r.x1 - x0, r.y0 - y0, r.y1 - y0].map(|v| v as u8),
                            face,
                        };
                        *slot += 1;
                        continue;
                    }
                    let (MANY, Some(r)) = (t, r) else { continue };
                    let [tx0, tx1, ty0, ty1] = span(r);
                    for ty in ty0..=ty1 {
                        for tx in tx0..=tx1 {
                            let (x0, y0) = (tx * TILE, ty * TILE);
                            let (tw, th) = (TILE.min(w - x0), TILE.min(h - y0));
                            let slot = &mut next[(ty * tiles_x + tx - lo) as usize];
                            entries[*slot as usize] = Binned {
                                prim,
                                rect: clip_to_tile(*r, x0, y0, tw, th).map(|v| v as u8),
                                face,
                            };
                            *slot += 1;
                        }
                    }
                }
                // This chunk's non-empty runs, by tile.
                let runs: Vec<[u32; 3]> = (0..n)
                    .filter(|&i| start[i + 1] > start[i])
                    .map(|i| [lo + i as u32, start[i], start[i + 1]])
                    .collect();
                (entries, runs)
            })
            .collect::<Vec<_>>();
        // Per tile, the runs of every chunk in chunk order (a counting sort
        // of the few non-empty runs).
        let mut tile_runs = vec![0u32; tiles + 1];
        for (_, runs) in &chunks {
            for r in runs {
                tile_runs[r[0] as usize + 1] += 1;
            }
        }
        for i in 0..tiles {
            tile_runs[i + 1] += tile_runs[i];
        }
        let mut next = tile_runs.clone();
        let mut runs = vec![[0u32; 3]; tile_runs[tiles] as usize];
        for (ci, (_, chunk_runs)) in chunks.iter().enumerate() {
            for &[tile, a, b] in chunk_runs {
                let slot = &mut next[tile as usize];
                runs[*slot as usize] = [ci as u32, a, b];
                *slot += 1;
            }
        }
        Bins {
            entries: chunks.into_iter().map(|(e, _)| e).collect(),
            tile_runs,
            runs,
        }
    }

    /// Tile `i`'s bin, in triangle order, into `bin` (cleared first).
    pub fn tile(&self, i: usize, bin: &mut Vec<Binned>) {
        bin.clear();
        let runs = &self.runs[self.tile_runs[i] as usize..self.tile_runs[i + 1] as usize];
        for &[c, a, b] in runs {
            bin.extend_from_slice(&self.entries[c as usize][a as usize..b as usize]);
        }
    }
}

/// The part of triangle `prim`'s box inside the tile at `(x0, y0)` of size
/// `tw` x `th`, in tile coordinates: `(lx0, lx1, ly0, ly1)`, inclusive.
#[inline(always)]
pub fn clip_to_tile(r: PixelRect, x0: u32, y0: u32, tw: u32, th: u32) -> [usize; 4] {
    [
        (r.x0.max(x0) - x0) as usize,
        (r.x1.min(x0 + tw - 1) - x0) as usize,
        (r.y0.max(y0) - y0) as usize,
        (r.y1.min(y0 + th - 1) - y0) as usize,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::screen_bounds;
    use crate::scene::generators::crossover_grid;

    /// Every tile's bin is what one serial pass over the triangles gives:
    /// each triangle whose box meets the tile, in index order, with its box
    /// clipped to the tile and its face. The grids span several chunks, with boxes in one
    /// tile and boxes across many.
    #[test]
    fn bins_are_the_serial_binning() {
        for (nx, size) in [(64, 200), (3, 200), (1, 100), (100, 70)] {
            let scene = crossover_grid(nx, size, false).unwrap();
            assert!(nx < 64 || scene.triangles.len() > Bins::GRAIN);
            let cam = &scene.camera;
            let margin = Some(BoxMargin::new(cam));
            let (tiles_x, tiles_y) = (cam.width.div_ceil(TILE), cam.height.div_ceil(TILE));
            let bins = Bins::new(&scene, margin, tiles_x, tiles_y);
            let faces = crate::raster_hiz::NearFaces::new(cam);
            let mut bin = Vec::new();
            let mut entries = 0;
            for ty in 0..tiles_y {
                for tx in 0..tiles_x {
                    let (x0, y0) = (tx * TILE, ty * TILE);
                    let (tw, th) = (TILE.min(cam.width - x0), TILE.min(cam.height - y0));
                    let want: Vec<(u32, [u8; 4], u32)> = (0..scene.triangles.len())
                        .filter(|&i| !scene.degenerate[i])
                        .filter_map(|i| Some((i, screen_bounds(cam, &scene.triangles[i])?)))
                        .filter(|(_, r)| {
                            r.x0 < x0 + tw && r.x1 >= x0 && r.y0 < y0 + th && r.y1 >= y0
                        })
                        .map(|(i, r)| {
                            let c = clip_to_tile(r, x0, y0, tw, th).map(|v| v as u8);
                            (i as u32, c, faces.face(&scene.triangles[i]).to_bits())
                        })
                        .collect();
                    bins.tile((ty * tiles_x + tx) as usize, &mut bin);
                    let got: Vec<(u32, [u8; 4], u32)> = bin
                        .iter()
                        .map(|b| (b.prim, b.rect, b.face.to_bits()))
                        .collect();
                    assert_eq!(got, want, "grid {nx} at {size}, tile ({tx}, {ty})");
                    entries += got.len();
                }
            }
            assert!(entries > 0);
        }
    }
}
