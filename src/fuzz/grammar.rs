//! The grammar of scenes that break renderers (docs/fuzzing.md): each
//! [`Family`] builds one situation renderers get wrong (slivers, shared
//! vertices on pixel centers, T-junctions, coplanar surfaces, a closed mesh
//! seen from inside, grazing planes, the near plane, huge triangles, dense
//! sub-pixel meshes, many small objects, mirrored transforms), and the
//! modifiers move the whole scene far from the origin or give it an odd
//! image shape.
//!
//! Every knob's range keeps the scene inside what docs/DESIGN.md defines;
//! the one rule behind them all: **a feature the scene relies on (a sliver's
//! width, a near-coplanar gap, a vertex's offset from a pixel center) is at
//! least [`FEATURE_ULPS`] f32 steps of the coordinates it is written in**,
//! so resolution's single rounding to f32 keeps it (no zero-area triangle,
//! no gap rounded shut, no pair swapped). The camera obeys the core's own
//! pose checks (`scene::validate_pose`). `tests` below generate thousands of
//! scenes and resolve every one: a scene the core refuses is a grammar bug.

use super::literal::{LiteralCamera, LiteralObject, LiteralScene, Tri};
use super::rng::{pow2, Rng};

/// How many f32 steps (of the scene's largest coordinate) a feature the
/// scene relies on spans at least. 64 steps = 6 bits of margin: rounding
/// each vertex once moves it by at most half a step, so a feature of 64
/// steps keeps its sign and at least 98% of its size.
pub const FEATURE_ULPS: f64 = 64.0;

/// Most triangles one generated scene has: small scenes are many scenes a
/// minute (docs/fuzzing.md), and every family here needs only a few.
pub const MAX_TRIANGLES: usize = 600;

/// One situation that breaks renderers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Family {
    /// Slivers (one very short altitude) and needles (two vertices close together).
    Sliver,
    /// A small mesh with every vertex on a pixel center (the top-left rule
    /// decides every shared edge), some nudged a hair off the center.
    PixelCenters,
    /// A vertex on another triangle's edge (not a shared vertex).
    TJunction,
    /// Duplicated, coplanar-overlapping, near-coplanar and intersecting surfaces.
    Coplanar,
    /// A closed box with the eye inside it.
    InsideBox,
    /// A plane that nearly contains the pixel rays.
    Grazing,
    /// Triangles crossing the near plane, some with a vertex behind the eye.
    NearPlane,
    /// Triangles reaching thousands of image widths off-screen.
    Huge,
    /// A mesh of sub-pixel cells.
    Dense,
    /// Many small triangles, each an object of its own.
    ManySmall,
    /// Objects under a mirroring transform (negative scale: winding flips).
    Mirrored,
}

impl Family {
    /// Every family, in the order the generator picks from.
    pub const ALL: [Family; 11] = [
        Family::Sliver,
        Family::PixelCenters,
        Family::TJunction,
        Family::Coplanar,
        Family::InsideBox,
        Family::Grazing,
        Family::NearPlane,
        Family::Huge,
        Family::Dense,
        Family::ManySmall,
        Family::Mirrored,
    ];

    /// The family's name in scene descriptions and findings.json.
    pub fn name(self) -> &'static str {
        match self {
            Family::Sliver => "sliver",
            Family::PixelCenters => "pixel_centers",
            Family::TJunction => "t_junction",
            Family::Coplanar => "coplanar",
            Family::InsideBox => "inside_box",
            Family::Grazing => "grazing",
            Family::NearPlane => "near_plane",
            Family::Huge => "huge",
            Family::Dense => "dense",
            Family::ManySmall => "many_small",
            Family::Mirrored => "mirrored",
        }
    }
}

/// A generated scene and what made it.
#[derive(Debug, Clone)]
pub struct Generated {
    /// The scene.
    pub scene: LiteralScene,
    /// Its families, the first the primary one.
    pub families: Vec<Family>,
    /// Its modifiers (`far_from_origin`, `odd_image`).
    pub modifiers: Vec<&'static str>,
}

/// Fields of view the grammar uses, with tan(vfov/2) written out (no libm:
/// see rng.rs); the core computes its own tangent, these only place geometry.
/// 90 degrees is exactly 1 in the core too (ARCHITECTURE.md), which puts
/// pixel centers on exact dyadic coordinates.
const FOVS: [(f64, f64); 4] = [
    (30.0, 0.267_949_192_431_122_7),
    (45.0, 0.414_213_562_373_095_03),
    (60.0, 0.577_350_269_189_625_8),
    (90.0, 1.0),
];

/// The local frame every family builds in: the eye at `(0, 0, d)` looking
/// down -z with +y up, so a point at pixel `(px, py)` (continuous, centers at
/// +0.5) and planar depth `z` is `at(px, py, z)`. The whole scene is then
/// scaled by `scale` and moved by `offset` (the far-from-origin modifier).
#[derive(Debug, Clone)]
struct View {
    w: f64,
    h: f64,
    tan: f64,
    d: f64,
    /// Smallest feature size (local units) the scene may rely on:
    /// [`FEATURE_ULPS`] f32 steps of its largest coordinate.
    min_feature: f64,
}

impl View {
    fn at(&self, px: f64, py: f64, z: f64) -> [f64; 3] {
        // Written so that with tan = 1, power-of-two sides and z = d = 1 a
        // pixel center is an exact dyadic (the pixel_grid scene's trick).
        let sx = (2.0 * px / self.w - 1.0) * (self.tan * self.w / self.h);
        let sy = (1.0 - 2.0 * py / self.h) * self.tan;
        [z * sx, z * sy, self.d - z]
    }

    /// Size of one pixel (local units) at planar depth `z`.
    fn pixel(&self, z: f64) -> f64 {
        2.0 * self.tan * z / self.h
    }

    /// A random point on (or a little off) the screen.
    fn screen(&self, rng: &mut Rng) -> (f64, f64) {
        (
            rng.range(-0.1 * self.w, 1.1 * self.w),
            rng.range(-0.1 * self.h, 1.1 * self.h),
        )
    }

    /// A random planar depth in front of the eye, among the scene's content.
    fn depth(&self, rng: &mut Rng) -> f64 {
        rng.range(0.5 * self.d, 1.5 * self.d)
    }
}

/// Generates scene `index` of run `seed`: the same pair always gives the
/// same scene (see rng.rs).
pub fn generate(seed: u64, index: u64) -> Generated {
    let mut rng = Rng::for_scene(seed, index);
    let primary = *rng.pick(&Family::ALL);
    let mut families = vec![primary];
    if rng.chance(0.35) {
        let second = *rng.pick(&Family::ALL);
        if second != primary && second != Family::PixelCenters && second != Family::InsideBox {
            families.push(second);
        }
    }
    let exact_centers = families.contains(&Family::PixelCenters);
    let mut modifiers = Vec::new();
    let (w, h, vfov, tan, d) = if exact_centers {
        // vfov 90, eye at distance 1 from the z = 0 plane, power-of-two
        // sides with a power-of-two ratio: every pixel center on that plane
        // is an exact dyadic, so vertices can sit exactly on them.
        let (w, h) = *rng.pick(&[(32u32, 32u32), (64, 32), (64, 64), (128, 64), (32, 64)]);
        (w, h, 90.0, 1.0, 1.0)
    } else {
        let (w, h) = if rng.chance(0.3) {
            modifiers.push("odd_image");
            // Odd shapes: any side from 16 to 128 (wide, tall, prime sides).
            (rng.int(16, 128) as u32, rng.int(16, 96) as u32)
        } else {
            *rng.pick(&[
                (32u32, 32u32),
                (64, 48),
                (48, 64),
                (96, 72),
                (128, 96),
                (64, 64),
            ])
        };
        let (vfov, tan) = *rng.pick(&FOVS);
        (w, h, vfov, tan, 4.0)
    };
    // Far from the origin: the whole scene (camera included) scaled by
    // `scale` and moved by `offset`, |offset| in 2^10..2^23 (about 1e3 to
    // 8e6) and 2^0..2^10 times the scene's size. The core's pixel rays stay
    // within 1/64 px at these distances (validate_pose's limit is far
    // beyond); the f32 grid at the offset is coarser, and `min_feature`
    // grows with it so that no feature rounds away.
    let (scale, offset) = if rng.chance(0.2) {
        modifiers.push("far_from_origin");
        let o = rng.log2_uniform(10, 23);
        let offset = [
            o * rng.sign() * rng.range(0.25, 1.0),
            o * rng.sign() * rng.range(0.25, 1.0),
            o * rng.sign(),
        ];
        let ratio = rng.log2_uniform(0, 10);
        (o / ratio / d, offset)
    } else {
        (1.0, [0.0; 3])
    };
    let largest = offset.iter().fold(0.0f64, |m, x| m.max(x.abs())) / scale + 3.0 * d;
    let view = View {
        w: f64::from(w),
        h: f64::from(h),
        tan,
        d,
        min_feature: FEATURE_ULPS * largest * pow2(-24),
    };
    let mut near = d * pow2(-8);
    let mut objects: Vec<LiteralObject> = Vec::new();
    for &f in &families {
        let before = objects.len();
        match f {
            Family::Sliver => sliver(&view, &mut rng, &mut objects),
            Family::PixelCenters => pixel_centers(&view, &mut rng, &mut objects),
            Family::TJunction => t_junction(&view, &mut rng, &mut objects),
            Family::Coplanar => coplanar(&view, &mut rng, &mut objects),
            Family::InsideBox => inside_box(&view, &mut rng, &mut objects),
            Family::Grazing => grazing(&view, &mut rng, &mut objects),
            Family::NearPlane => near = near_plane(&view, &mut rng, &mut objects),
            Family::Huge => huge(&view, &mut rng, &mut objects),
            Family::Dense => dense(&view, &mut rng, &mut objects),
            Family::ManySmall => many_small(&view, &mut rng, &mut objects),
            Family::Mirrored => {
                // Mirrored content of another kind: slivers, a T-junction or small triangles.
                match rng.int(0, 2) {
                    0 => sliver(&view, &mut rng, &mut objects),
                    1 => t_junction(&view, &mut rng, &mut objects),
                    _ => many_small(&view, &mut rng, &mut objects),
                }
                for o in &mut objects[before..] {
                    o.mirror = Some(([-1.0, 1.0, 1.0], [0.0; 3]));
                }
            }
        }
    }
    // Local frame to world: scale, offset; a mirrored object keeps its
    // world position and gets its x through the transform's -1.
    for o in &mut objects {
        for t in &mut o.triangles {
            for v in t.iter_mut() {
                *v = [0, 1, 2].map(|k| v[k] * scale + offset[k]);
            }
        }
        if o.mirror.is_some() {
            for t in &mut o.triangles {
                for v in t.iter_mut() {
                    v[0] = -(v[0] - offset[0]);
                }
            }
            o.mirror = Some(([-1.0, 1.0, 1.0], offset));
        }
    }
    let names: Vec<&str> = families.iter().map(|f| f.name()).collect();
    let mut description = format!(
        "rendiff fuzz seed {seed} scene {index}: {}",
        names.join(", ")
    );
    if !modifiers.is_empty() {
        description.push_str(&format!(" ({})", modifiers.join(", ")));
    }
    let scene = LiteralScene {
        description,
        requires: vec!["depth".into(), "ids".into()],
        camera: LiteralCamera {
            eye: [offset[0], offset[1], d * scale + offset[2]],
            look_at: offset,
            up: [0.0, 1.0, 0.0],
            vfov,
            width: w,
            height: h,
            near: near * scale,
            far: None,
        },
        objects,
        materials: Vec::new(),
        lights: Vec::new(),
        integrator: None,
    };
    debug_assert!(scene.triangle_count() <= MAX_TRIANGLES);
    Generated {
        scene,
        families,
        modifiers,
    }
}

fn push(objects: &mut Vec<LiteralObject>, triangles: Vec<Tri>) {
    objects.push(LiteralObject::new(triangles));
}

/// A screen-space thickness (pixels) at least `min_feature` in local units at depth `z`.
fn at_least(view: &View, px: f64, z: f64) -> f64 {
    px.max(view.min_feature / view.pixel(z))
}

/// Slivers: a long edge (4 px to the image's width) and an apex 2^-16 to
/// 2^-4 of its length off the line; needles: two vertices that close and a
/// third far away. Both at least [`FEATURE_ULPS`] steps wide.
fn sliver(view: &View, rng: &mut Rng, objects: &mut Vec<LiteralObject>) {
    let n = rng.int(1, 4);
    let mut tris = Vec::new();
    for _ in 0..n {
        let (ax, ay) = view.screen(rng);
        let len = rng.range(4.0, view.w);
        let (dx, dy) = unit2(rng);
        let (bx, by) = (ax + len * dx, ay + len * dy);
        let z = [view.depth(rng), view.depth(rng), view.depth(rng)];
        let thin = at_least(view, len * rng.log2_uniform(-16, -4), z[0].max(z[1]));
        let t = if rng.chance(0.5) {
            rng.range(0.05, 0.95) // sliver: apex along the edge
        } else {
            rng.range(-0.001, 0.001) // needle: apex next to a
        };
        let (cx, cy) = (ax + t * len * dx - thin * dy, ay + t * len * dy + thin * dx);
        let z2 = z[0] + t * (z[1] - z[0]);
        tris.push([
            view.at(ax, ay, z[0]),
            view.at(bx, by, z[1]),
            view.at(cx, cy, z2),
        ]);
    }
    push(objects, tris);
}

/// A random unit vector in the screen plane (no trigonometry: see rng.rs).
fn unit2(rng: &mut Rng) -> (f64, f64) {
    loop {
        let (x, y) = (rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
        let r = (x * x + y * y).sqrt();
        if r > 0.1 && r <= 1.0 {
            return (x / r, y / r);
        }
    }
}

/// A grid of 1 to 4 x 1 to 4 cells, 1 to 6 pixels each, every vertex on a
/// pixel center of the z = 0 plane (exact: `generate` chose vfov 90 and
/// power-of-two sides), each cell split along a random diagonal; and with
/// probability 1/2 a fan around one center whose spokes end on centers. A
/// quarter of the scenes nudge some vertices off their center by 2^-20 to
/// 2^-6 px, still at least [`FEATURE_ULPS`] steps (with z = 0 and
/// coordinates below 2, 2^-20 px is 2^-25 local units... so the nudge is
/// taken from `min_feature` up).
/// The two triangles of each cell of an `nx` x `ny` grid whose nodes are
/// `nodes` (row by row, `nx + 1` to a row), cells row by row: split on the
/// diagonal from the cell's first node when `first_diagonal()` says so (one
/// call per cell, in that order: the generator's draws), else on the other.
/// Shared nodes are the same values, so neighbours share edges bit for bit.
fn grid_cells(
    nodes: &[[f64; 3]],
    nx: i64,
    ny: i64,
    first_diagonal: &mut dyn FnMut() -> bool,
) -> Vec<Tri> {
    let node = |i: i64, j: i64| nodes[(j * (nx + 1) + i) as usize];
    let mut tris = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            let (a, b, c, d) = (
                node(i, j),
                node(i + 1, j),
                node(i + 1, j + 1),
                node(i, j + 1),
            );
            if first_diagonal() {
                tris.push([a, b, c]);
                tris.push([a, c, d]);
            } else {
                tris.push([a, b, d]);
                tris.push([b, c, d]);
            }
        }
    }
    tris
}

fn pixel_centers(view: &View, rng: &mut Rng, objects: &mut Vec<LiteralObject>) {
    let nudge = rng.chance(0.25);
    let center = |rng: &mut Rng, i: i64, j: i64| {
        let (mut x, mut y) = (i as f64 + 0.5, j as f64 + 0.5);
        if nudge && rng.chance(0.3) {
            let px = at_least(view, rng.log2_uniform(-20, -6), view.d);
            x += rng.sign() * px;
            y += rng.sign() * px;
        }
        view.at(x, y, view.d)
    };
    let (nx, ny) = (rng.int(1, 4), rng.int(1, 4));
    let cell = rng.int(1, 6);
    let i0 = rng.int(-2, view.w as i64 - 2);
    let j0 = rng.int(-2, view.h as i64 - 2);
    // Vertices once per grid node, so shared vertices are identical.
    let mut nodes = Vec::new();
    for j in 0..=ny {
        for i in 0..=nx {
            nodes.push(center(rng, i0 + i * cell, j0 + j * cell));
        }
    }
    let tris = grid_cells(&nodes, nx, ny, &mut || rng.chance(0.5));
    push(objects, tris);
    if rng.chance(0.5) {
        let (ci, cj) = (rng.int(0, view.w as i64 - 1), rng.int(0, view.h as i64 - 1));
        let hub = center(rng, ci, cj);
        let spokes = rng.int(3, 8);
        let r = rng.int(1, 5);
        // Spokes around a square of radius r, in order, closed.
        let ring: Vec<(i64, i64)> = (0..spokes)
            .map(|k| {
                let s = [
                    (1, 0),
                    (1, 1),
                    (0, 1),
                    (-1, 1),
                    (-1, 0),
                    (-1, -1),
                    (0, -1),
                    (1, -1),
                ];
                let (dx, dy) = s[(k * 8 / spokes) as usize];
                (ci + dx * r, cj + dy * r)
            })
            .collect();
        let pts: Vec<[f64; 3]> = ring.iter().map(|&(i, j)| center(rng, i, j)).collect();
        let mut fan = Vec::new();
        for k in 0..pts.len() {
            let (p, q) = (pts[k], pts[(k + 1) % pts.len()]);
            fan.push([hub, p, q]);
        }
        push(objects, fan);
    }
}

/// A vertex `m` at the midpoint of another triangle's edge `pq`: triangle
/// (p, q, r1) on one side, (p, m, r2) and (m, q, r2) on the other, all in
/// one plane at one depth (m rounds to f32 on its own, so it may land a
/// hair off the edge: what real T-junctions do).
fn t_junction(view: &View, rng: &mut Rng, objects: &mut Vec<LiteralObject>) {
    let z = view.depth(rng);
    let (px, py) = view.screen(rng);
    let len = rng.range(6.0, view.w);
    let (dx, dy) = unit2(rng);
    let (qx, qy) = (px + len * dx, py + len * dy);
    let (mx, my) = ((px + qx) / 2.0, (py + qy) / 2.0);
    let s1 = rng.range(2.0, len);
    let s2 = rng.range(2.0, len);
    let r1 = view.at(mx - s1 * dy, my + s1 * dx, z);
    let r2 = view.at(mx + s2 * dy, my - s2 * dx, z);
    let (p, q, m) = (view.at(px, py, z), view.at(qx, qy, z), view.at(mx, my, z));
    let big = vec![[p, q, r1]];
    let halves = vec![[p, m, r2], [m, q, r2]];
    if rng.chance(0.5) {
        push(objects, big);
        push(objects, halves);
    } else {
        let mut all = halves;
        all.extend(big);
        push(objects, all);
    }
}

/// Surfaces on top of each other: a triangle and (a) its exact duplicate,
/// (b) a copy moved along the pixel rays by a relative 2^-20 to 2^-6 of
/// its depth (same footprint on screen, a constant relative depth gap), (c)
/// a copy whose vertices move by different such gaps (the two planes
/// cross), or (d) another triangle in the same plane overlapping it. The
/// copy comes first or second (tie rules and depth tests see both orders).
/// A gap is at least `min_feature` (so at least [`FEATURE_ULPS`] f32 steps).
fn coplanar(view: &View, rng: &mut Rng, objects: &mut Vec<LiteralObject>) {
    let pairs = rng.int(1, 3);
    for _ in 0..pairs {
        let z = [view.depth(rng), view.depth(rng), view.depth(rng)];
        let pts: Vec<(f64, f64)> = (0..3).map(|_| view.screen(rng)).collect();
        let base: Tri = [0, 1, 2].map(|k| view.at(pts[k].0, pts[k].1, z[k]));
        let gap =
            |rng: &mut Rng| rng.sign() * rng.log2_uniform(-20, -6).max(view.min_feature / view.d);
        let copy: Tri = match rng.int(0, 3) {
            0 => base,
            1 => {
                let g = gap(rng);
                [0, 1, 2].map(|k| view.at(pts[k].0, pts[k].1, z[k] * (1.0 + g)))
            }
            2 => {
                let g = [gap(rng), gap(rng), gap(rng)];
                [0, 1, 2].map(|k| view.at(pts[k].0, pts[k].1, z[k] * (1.0 + g[k])))
            }
            _ => {
                // Same plane: points of the base's plane, by barycentric
                // combinations (-0.5..1.5) of its vertices.
                let mut t = [[0.0; 3]; 3];
                for v in &mut t {
                    let (u, w) = (rng.range(-0.5, 1.0), rng.range(-0.5, 1.0));
                    for k in 0..3 {
                        v[k] = base[0][k]
                            + u * (base[1][k] - base[0][k])
                            + w * (base[2][k] - base[0][k]);
                    }
                }
                if area2(&t) <= view.min_feature * view.min_feature * 1e4 {
                    base
                } else {
                    t
                }
            }
        };
        if rng.chance(0.5) {
            push(objects, vec![base]);
            push(objects, vec![copy]);
        } else {
            push(objects, vec![copy]);
            push(objects, vec![base]);
        }
    }
}

/// Twice the area of a triangle (local units squared).
fn area2(t: &Tri) -> f64 {
    let u = [0, 1, 2].map(|k| t[1][k] - t[0][k]);
    let v = [0, 1, 2].map(|k| t[2][k] - t[0][k]);
    let c = [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ];
    (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt()
}

/// A closed box (12 triangles sharing their 8 corners) with the eye inside:
/// each face 1 to 3 units from the eye, the view axis through one face.
fn inside_box(view: &View, rng: &mut Rng, objects: &mut Vec<LiteralObject>) {
    let e = [0.0, 0.0, view.d];
    let lo = [0, 1, 2].map(|k| e[k] - rng.range(1.0, 3.0));
    let hi = [0, 1, 2].map(|k| e[k] + rng.range(1.0, 3.0));
    let c = |i: usize| {
        [
            if i & 1 == 0 { lo[0] } else { hi[0] },
            if i & 2 == 0 { lo[1] } else { hi[1] },
            if i & 4 == 0 { lo[2] } else { hi[2] },
        ]
    };
    // Faces as corner quads (outward winding), two triangles each.
    let quads = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    let mut tris = Vec::new();
    for q in quads {
        tris.push([c(q[0]), c(q[1]), c(q[2])]);
        tris.push([c(q[0]), c(q[2]), c(q[3])]);
    }
    push(objects, tris);
}

/// A quad nearly containing the pixel rays: one edge runs from depth z to
/// 1.5 to 4 z while its screen image moves only 2^-10 to 1 px, so the plane
/// meets the rays at a grazing angle of about that over the depth span.
fn grazing(view: &View, rng: &mut Rng, objects: &mut Vec<LiteralObject>) {
    let z1 = view.depth(rng);
    let z2 = z1 * rng.range(1.5, 4.0);
    let (ax, ay) = view.screen(rng);
    let (dx, dy) = unit2(rng);
    let drift = at_least(view, rng.log2_uniform(-10, 0), z2);
    let (bx, by) = (ax + drift * dx, ay + drift * dy);
    let len = rng.range(4.0, view.w);
    let (cx, cy) = (ax - len * dy, ay + len * dx);
    let (ex, ey) = (bx - len * dy, by + len * dx);
    let (a, b) = (view.at(ax, ay, z1), view.at(bx, by, z2));
    let (c, e) = (view.at(cx, cy, z1), view.at(ex, ey, z2));
    push(objects, vec![[a, b, c], [b, e, c]]);
}

/// Triangles crossing the near plane (set to d 2^-6 to d 2^-2), some with a
/// vertex behind the eye (depth -d/2 to 0). Returns the near plane.
fn near_plane(view: &View, rng: &mut Rng, objects: &mut Vec<LiteralObject>) -> f64 {
    let near = view.d * rng.log2_uniform(-6, -2);
    let n = rng.int(1, 4);
    let mut tris = Vec::new();
    for _ in 0..n {
        let mut t = [[0.0; 3]; 3];
        for (k, v) in t.iter_mut().enumerate() {
            let (x, y) = view.screen(rng);
            let z = match k {
                0 => rng.range(0.0, near),
                1 => view.depth(rng),
                _ => rng.range(-0.5 * view.d, 1.5 * view.d),
            };
            *v = view.at(x, y, z);
        }
        // A vertex at depth ~0 sits on the eye's plane: keep the triangle
        // away from degenerate (all three points on one pixel ray).
        if area2(&t) > view.min_feature {
            tris.push(t);
        }
    }
    if tris.is_empty() {
        tris.push([
            view.at(0.0, 0.0, near * 0.5),
            view.at(view.w, 0.0, view.d),
            view.at(0.0, view.h, view.d),
        ]);
    }
    push(objects, tris);
    near
}

/// One or two triangles reaching 2^4 to 2^14 image widths off-screen,
/// tilted a little in depth, covering the whole image.
fn huge(view: &View, rng: &mut Rng, objects: &mut Vec<LiteralObject>) {
    let n = rng.int(1, 2);
    let mut tris = Vec::new();
    for _ in 0..n {
        let r = rng.log2_uniform(4, 14) * view.w;
        let (cx, cy) = (view.w / 2.0, view.h / 2.0);
        let z = view.depth(rng);
        let tilt = rng.range(-0.2, 0.2);
        // Keep every vertex in front of the eye: tilt times reach stays above -z/2.
        let zt = |s: f64| (z * (1.0 + tilt * s)).max(0.5 * z);
        tris.push([
            view.at(cx - r, cy - r, zt(-1.0)),
            view.at(cx + 2.0 * r, cy - 0.5 * r, zt(1.0)),
            view.at(cx - 0.5 * r, cy + 2.0 * r, zt(0.5)),
        ]);
    }
    push(objects, tris);
}

/// A grid of 2 to 12 x 2 to 12 cells of 2^-4 to 2^-1 px (sub-pixel, at
/// least [`FEATURE_ULPS`] steps), its vertices shared, on a slightly tilted plane.
fn dense(view: &View, rng: &mut Rng, objects: &mut Vec<LiteralObject>) {
    let (nx, ny) = (rng.int(2, 12), rng.int(2, 12));
    let z = view.depth(rng);
    let cell = at_least(view, rng.log2_uniform(-4, -1), z);
    let (x0, y0) = (rng.range(0.0, view.w), rng.range(0.0, view.h));
    let tilt = rng.range(-0.01, 0.01);
    let mut nodes = Vec::new();
    for j in 0..=ny {
        for i in 0..=nx {
            let (x, y) = (x0 + i as f64 * cell, y0 + j as f64 * cell);
            nodes.push(view.at(x, y, z * (1.0 + tilt * (i + j) as f64)));
        }
    }
    push(objects, grid_cells(&nodes, nx, ny, &mut || true));
}

/// 8 to 40 triangles of 0.5 to 4 px, each an object of its own, at random depths.
fn many_small(view: &View, rng: &mut Rng, objects: &mut Vec<LiteralObject>) {
    let n = rng.int(8, 40);
    for _ in 0..n {
        let (x, y) = (rng.range(0.0, view.w), rng.range(0.0, view.h));
        let z = view.depth(rng);
        let s = at_least(view, rng.range(0.5, 4.0), z);
        let (dx, dy) = unit2(rng);
        let t = [
            view.at(x, y, z),
            view.at(x + s * dx, y + s * dy, z * rng.range(0.98, 1.02)),
            view.at(x - s * dy * rng.range(0.2, 1.0), y + s * dx, z),
        ];
        push(objects, vec![t]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::resolve::ResolvedScene;
    use crate::scene::Scene;
    use std::path::Path;

    /// Every generated scene is one the core accepts: parsed, validated,
    /// resolved (no zero-area triangle after rounding, the camera within the
    /// core's ray precision), small. A refusal is a bug in the grammar.
    #[test]
    fn every_generated_scene_is_valid_and_small() {
        let mut seen = std::collections::BTreeSet::new();
        for seed in 0..3u64 {
            for i in 0..700u64 {
                let g = generate(seed, i);
                let text = g.scene.to_toml();
                let scene = Scene::parse(Path::new("gen.toml"), &text)
                    .unwrap_or_else(|e| panic!("seed {seed} scene {i}: {e}\n{text}"));
                let r = ResolvedScene::resolve(&scene)
                    .unwrap_or_else(|e| panic!("seed {seed} scene {i}: {e}\n{text}"));
                assert!(r.triangles.len() <= MAX_TRIANGLES, "seed {seed} scene {i}");
                assert!((16..=128).contains(&r.camera.width));
                assert!((16..=96).contains(&r.camera.height));
                for f in &g.families {
                    seen.insert(*f);
                }
            }
        }
        assert_eq!(seen.len(), Family::ALL.len(), "every family appears");
    }

    /// `View::at` places geometry by the camera convention, which has its
    /// home in `camera.rs`: the generator keeps its own copy only so that
    /// no libm tangent enters the scene files (rng.rs), and this test holds
    /// the copy to the core's camera. A point `at` a pixel center at planar
    /// depth `z` must be `eye + z * Camera::direction(x, y)`: bit for bit
    /// on the exact-centers cameras (vfov 90, power-of-two sides, the
    /// `pixel_centers` family's promise), and within a few ulps of the
    /// tangent elsewhere (the table's tangents against `tan_half_deg`).
    #[test]
    fn view_places_pixel_centers_where_the_core_camera_puts_them() {
        use crate::camera::{tan_half_deg, Camera};
        use glam::DVec3;
        for &(vfov, tan) in &FOVS {
            let core = tan_half_deg(vfov);
            assert!(
                (tan - core).abs() <= 4.0 * f64::EPSILON * core,
                "FOVS' tangent of {vfov} degrees is {tan}, the core's {core}"
            );
            for (w, h, d) in [
                (32u32, 32u32, 1.0),
                (64, 32, 1.0),
                (32, 64, 4.0),
                (37, 23, 4.0),
            ] {
                let v = View {
                    w: f64::from(w),
                    h: f64::from(h),
                    tan,
                    d,
                    min_feature: 0.0,
                };
                let cam = Camera::new(
                    DVec3::new(0.0, 0.0, d),
                    DVec3::ZERO,
                    DVec3::Y,
                    vfov,
                    w,
                    h,
                    1e-4,
                    f64::INFINITY,
                )
                .unwrap();
                for (x, y) in [(0, 0), (w - 1, h - 1), (w / 3, h / 2), (w - 2, 1)] {
                    let z = d;
                    let ours = DVec3::from(v.at(f64::from(x) + 0.5, f64::from(y) + 0.5, z));
                    let core_p = cam.eye + cam.direction(x, y) * z;
                    let exact = vfov == 90.0 && w.is_power_of_two() && h.is_power_of_two();
                    if exact {
                        assert_eq!(ours, core_p, "{vfov} deg {w}x{h} pixel ({x}, {y})");
                    } else {
                        let err = (ours - core_p).abs().max_element();
                        assert!(
                            err <= 16.0 * f64::EPSILON * (d + core_p.abs().max_element()),
                            "{vfov} deg {w}x{h} pixel ({x}, {y}): {ours} against {core_p}"
                        );
                    }
                }
            }
        }
    }
}
