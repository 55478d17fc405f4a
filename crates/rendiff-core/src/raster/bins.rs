//! The rasterizer's binning: every triangle's conservative box
//! ([`crate::raster::bounds`]), then the triangles each tile must consider,
//! in parallel and in a fixed order: the triangles facing the eye first,
//! then those facing away ([`crate::raster::bounds::faces_away`]), each in
//! triangle order. The keys are the same in any order; the operation counts
//! of early depth rejection are not, so the order is deterministic, and it
//! is chosen for them: a closed mesh's near side fills a tile before its far
//! side arrives, which is then skipped as hidden (on `million`, set-ups fell
//! from 647k to 446k and skipped triangles rose from 573k to 775k).

use crate::raster::bounds::BoxMargin;
use crate::raster::{PixelRect, TILE};
use crate::scene::resolve::ResolvedScene;
use rayon::prelude::*;

/// A triangle in a tile's bin, with the part of its box in the tile (tile
/// coordinates, `[lx0, lx1, ly0, ly1]` inclusive; [`TILE`] fits a byte) and
/// its face for early depth rejection ([`crate::raster::hiz::NearFaces::face`]), so that the tile
/// loop reads only the triangle itself, and not even that for a triangle it
/// skips as hidden.
#[derive(Debug, Clone, Copy)]
pub struct Binned {
    /// The triangle.
    pub prim: u32,
    /// Its box within the tile.
    pub rect: [u8; 4],
    /// Its face ([`crate::raster::hiz`]).
    pub face: f32,
}

const _: () = assert!(TILE <= 256);

/// A box over several tiles, in the binning's per-triangle tile index.
const MANY: u32 = u32::MAX - 1;

/// No box, in the binning's per-triangle tile index.
const NONE: u32 = u32::MAX;

/// Triangles binned into tiles, in parallel and deterministically: chunks of
/// consecutive triangles each sort their (triangle, key) pairs by key
/// (counting sort, keeping triangle order), where a tile's two keys are
/// `2 tile` for its triangles facing the eye and `2 tile + 1` for the
/// others; a tile's bin is its first key's run in every chunk, chunk after
/// chunk, then its second key's: each part in index order, as one serial
/// pass would list them (counts depend on that order).
pub struct Bins {
    /// Per chunk, its entries sorted by key.
    entries: Vec<Vec<Binned>>,
    /// Where each key's runs start in `runs` (one more offset than keys).
    key_runs: Vec<u32>,
    /// The non-empty runs, key by key and chunk after chunk within a key:
    /// `(chunk, start, end)` in that chunk's entries. A chunk's triangles are
    /// neighbours in the mesh and touch few tiles, so most (chunk, key)
    /// runs are empty; reading every chunk's offsets per tile cost a tenth
    /// of the pass on a million triangles (scattered loads).
    runs: Vec<[u32; 3]>,
}

impl Bins {
    /// Triangles per chunk.
    const GRAIN: usize = 4096;

    /// Bounds ([`crate::raster::bounds`]) and bins of every triangle.
    pub fn new(
        scene: &ResolvedScene,
        margin: Option<BoxMargin>,
        tiles_x: u32,
        tiles_y: u32,
    ) -> Bins {
        let cam = &scene.camera;
        let tiles = (tiles_x * tiles_y) as usize;
        // Keys stay below the markers.
        assert!(2 * tiles < MANY as usize, "{tiles_x} x {tiles_y} tiles");
        let chunks = scene
            .triangles
            .par_chunks(Self::GRAIN)
            .zip(scene.degenerate.par_chunks(Self::GRAIN))
            .enumerate()
            .map(|(ci, (tris, deg))| bin_chunk(cam, margin, tiles_x, ci * Self::GRAIN, tris, deg))
            .collect::<Vec<_>>();
        // Per key, the runs of every chunk in chunk order (a counting sort
        // of the few non-empty runs).
        let keys = 2 * tiles;
        let mut key_runs = vec![0u32; keys + 1];
        for (_, runs) in &chunks {
            for r in runs {
                key_runs[r[0] as usize + 1] += 1;
            }
        }
        for i in 0..keys {
            key_runs[i + 1] += key_runs[i];
        }
        let mut next = key_runs.clone();
        let mut runs = vec![[0u32; 3]; key_runs[keys] as usize];
        for (ci, (_, chunk_runs)) in chunks.iter().enumerate() {
            for &[key, a, b] in chunk_runs {
                let slot = &mut next[key as usize];
                runs[*slot as usize] = [ci as u32, a, b];
                *slot += 1;
            }
        }
        Bins {
            entries: chunks.into_iter().map(|(e, _)| e).collect(),
            key_runs,
            runs,
        }
    }

    /// Tile `i`'s bin into `bin` (cleared first): its triangles facing the
    /// eye, then the others, each in triangle order; returns how many face
    /// the eye.
    pub fn tile(&self, i: usize, bin: &mut Vec<Binned>) -> usize {
        bin.clear();
        // Keys `2i` and `2i + 1`: their runs are consecutive.
        let (a, mid, b) = (
            self.key_runs[2 * i] as usize,
            self.key_runs[2 * i + 1] as usize,
            self.key_runs[2 * i + 2] as usize,
        );
        let mut front = 0;
        for (j, &[c, s, e]) in self.runs[a..b].iter().enumerate() {
            bin.extend_from_slice(&self.entries[c as usize][s as usize..e as usize]);
            if a + j < mid {
                front = bin.len();
            }
        }
        front
    }
}

/// Boxes computed at a time in [`bin_chunk`], each reduced to its tile
/// while it is in the first-level cache (5 KB of boxes rather than a
/// chunk's 80 KB; alternated on `million`, no measurable change either way).
const BOXES: usize = 256;

/// One chunk's binning: its triangles' boxes, faces and sides, each box
/// reduced to its tile and its part of that tile while it is in the cache
/// (most boxes of a dense mesh lie in one tile), then a counting sort of the
/// (triangle, key) pairs by key ([`Bins`]) in triangle order. Returns the
/// entries and the non-empty runs `[key, start, end]`. Triangle `i` of
/// `tris` is `first + i`.
fn bin_chunk(
    cam: &crate::camera::Camera,
    margin: Option<BoxMargin>,
    tiles_x: u32,
    first: usize,
    tris: &[crate::scene::resolve::Tri],
    deg: &[bool],
) -> (Vec<Binned>, Vec<[u32; 3]>) {
    let (w, h) = (cam.width, cam.height);
    let n = tris.len();
    // Per triangle: its tile, or `MANY` / `NONE`; its box in that tile (for
    // one tile); its face; its side. Boxes over several tiles, with their
    // triangles' sides, in triangle order.
    let (mut tile, mut local, mut face) = (vec![NONE; n], vec![[0u8; 4]; n], vec![0f32; n]);
    let mut away = vec![false; n];
    let mut many: Vec<(PixelRect, bool)> = Vec::new();
    // The range of tiles the chunk meets (its triangles are neighbours in
    // the mesh: a few rows of tiles), so that its counts and offsets span
    // that range, not the image's tiles.
    let (mut lo, mut hi) = (u32::MAX, 0u32);
    let span = |r: &PixelRect| [r.x0 / TILE, r.x1 / TILE, r.y0 / TILE, r.y1 / TILE];
    let mut rects = [None; BOXES];
    for ((((tris, deg), face), away), (tile, local)) in tris
        .chunks(BOXES)
        .zip(deg.chunks(BOXES))
        .zip(face.chunks_mut(BOXES))
        .zip(away.chunks_mut(BOXES))
        .zip(tile.chunks_mut(BOXES).zip(local.chunks_mut(BOXES)))
    {
        let rects = &mut rects[..tris.len()];
        let out = crate::raster::bounds::BoundsOut {
            boxes: rects,
            faces: face,
            away: &mut *away,
        };
        crate::raster::bounds::bounds_into(cam, tris, deg, margin, out);
        for (((r, &side), t), l) in rects.iter().zip(&*away).zip(tile).zip(local) {
            let Some(r) = r else { continue };
            let [tx0, tx1, ty0, ty1] = span(r);
            let (a, b) = (ty0 * tiles_x + tx0, ty1 * tiles_x + tx1);
            if a == b {
                // Inside the tile and the image: no clipping.
                let (x0, y0) = (tx0 * TILE, ty0 * TILE);
                *t = a;
                *l = [r.x0 - x0, r.x1 - x0, r.y0 - y0, r.y1 - y0].map(|v| v as u8);
            } else {
                *t = MANY;
                many.push((*r, side));
            }
            (lo, hi) = (lo.min(a), hi.max(b));
        }
    }
    let m = if lo > hi { 0 } else { (hi - lo + 1) as usize };
    // Two buckets per tile, by key (`Bins::runs`): its triangles facing the
    // eye, then the others.
    let key = |t: u32, away: bool| 2 * (t - lo) as usize + usize::from(away);
    let mut start = vec![0u32; 2 * m + 1];
    for (&t, &a) in tile.iter().zip(&away) {
        if t < MANY {
            start[key(t, a) + 1] += 1;
        }
    }
    for (r, a) in &many {
        let [tx0, tx1, ty0, ty1] = span(r);
        for ty in ty0..=ty1 {
            for tx in tx0..=tx1 {
                start[key(ty * tiles_x + tx, *a) + 1] += 1;
            }
        }
    }
    for i in 0..2 * m {
        start[i + 1] += start[i];
    }
    let mut next = start.clone();
    let empty = Binned {
        prim: 0,
        rect: [0; 4],
        face: 0.0,
    };
    let mut entries = vec![empty; start[2 * m] as usize];
    let mut many = many.iter();
    let triangles = tile.iter().zip(&local).zip(face.iter().zip(&away));
    for (i, ((&t, &rect), (&face, &away))) in triangles.enumerate() {
        let prim = (first + i) as u32;
        if t < MANY {
            let slot = &mut next[key(t, away)];
            entries[*slot as usize] = Binned { prim, rect, face };
            *slot += 1;
            continue;
        }
        if t == NONE {
            continue;
        }
        let (r, _) = many
            .next()
            .expect("a box for each triangle over several tiles");
        let [tx0, tx1, ty0, ty1] = span(r);
        for ty in ty0..=ty1 {
            for tx in tx0..=tx1 {
                let (x0, y0) = (tx * TILE, ty * TILE);
                let (tw, th) = (TILE.min(w - x0), TILE.min(h - y0));
                let slot = &mut next[key(ty * tiles_x + tx, away)];
                entries[*slot as usize] = Binned {
                    prim,
                    rect: clip_to_tile(*r, x0, y0, tw, th).map(|v| v as u8),
                    face,
                };
                *slot += 1;
            }
        }
    }
    // The non-empty runs, by key.
    let runs: Vec<[u32; 3]> = (0..2 * m)
        .filter(|&i| start[i + 1] > start[i])
        .map(|i| [2 * lo + i as u32, start[i], start[i + 1]])
        .collect();
    (entries, runs)
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
    use crate::raster::bounds::faces_away;
    use crate::raster::screen_bounds;
    use crate::scene::generators::crossover_grid;

    /// Every tile's bin is what two serial passes over the triangles give:
    /// each triangle whose box meets the tile, those facing the eye in index
    /// order, then those facing away, with its box clipped to the tile and
    /// its face. The grids span several chunks, with boxes in one tile and
    /// boxes across many; every fourth triangle is turned round, so that
    /// both sides occur in a tile. The bin's count of triangles facing the
    /// eye is where the others begin.
    #[test]
    fn bins_are_the_serial_binning() {
        for (nx, size) in [(64, 200), (3, 200), (1, 100), (100, 70)] {
            let mut scene = crossover_grid(nx, size, false).unwrap();
            for t in scene.triangles.iter_mut().step_by(4) {
                t.swap(1, 2);
            }
            assert!(nx < 64 || scene.triangles.len() > Bins::GRAIN);
            let cam = &scene.camera;
            let margin = Some(BoxMargin::new(cam));
            let (tiles_x, tiles_y) = (cam.width.div_ceil(TILE), cam.height.div_ceil(TILE));
            let bins = Bins::new(&scene, margin, tiles_x, tiles_y);
            let faces = crate::raster::hiz::NearFaces::new(cam);
            let mut bin = Vec::new();
            let (mut entries, mut turned) = (0, 0);
            for ty in 0..tiles_y {
                for tx in 0..tiles_x {
                    let (x0, y0) = (tx * TILE, ty * TILE);
                    let (tw, th) = (TILE.min(cam.width - x0), TILE.min(cam.height - y0));
                    let away = |i: usize| faces_away(cam, &scene.triangles[i]);
                    let n = scene.triangles.len();
                    let want: Vec<(u32, [u8; 4], u32)> = (0..n)
                        .filter(|&i| !away(i))
                        .chain((0..n).filter(|&i| away(i)))
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
                    let front = bins.tile((ty * tiles_x + tx) as usize, &mut bin);
                    let got: Vec<(u32, [u8; 4], u32)> = bin
                        .iter()
                        .map(|b| (b.prim, b.rect, b.face.to_bits()))
                        .collect();
                    assert_eq!(got, want, "grid {nx} at {size}, tile ({tx}, {ty})");
                    let facing = got.iter().filter(|e| !away(e.0 as usize)).count();
                    assert_eq!(front, facing, "grid {nx} at {size}, tile ({tx}, {ty})");
                    entries += got.len();
                    turned += got.len() - facing;
                }
            }
            assert!(entries > 0);
            assert!(
                turned > 0 && turned < entries,
                "grid {nx}: {turned} of {entries} turned"
            );
        }
    }
}
