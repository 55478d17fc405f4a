//! The extreme scene families of `bench stability`, written as scene TOML so
//! that every backend sees exactly what a user's scene would give it.
//!
//! Families whose truth is known exactly (fill rule, coplanar ties, z-fighting,
//! geometry next to the eye) keep their vertices on dyadic coordinates that f32
//! stores exactly, so the scene every renderer reads is the scene the truth is
//! computed for (the unit tests check that the rounding is lossless).

use std::fmt::Write;

/// How a family's renders are judged.
#[derive(Debug, Clone, PartialEq)]
pub enum Judge {
    /// Against the core raster: interior ID mismatches, hit/miss mismatches and
    /// failed depth verdicts break; edge mismatches are rounding.
    Reference,
    /// Every pixel center lies on an edge or vertex: any winner other than the
    /// top-left rule's (the raster's) and any crack break.
    FillRule,
    /// A per-pixel truth from the scene itself: nearest surface wins, exact ties
    /// to the lower id; losing by less than the renderer's depth resolution does
    /// not break. `ties_break`: whether a tie won by the higher id breaks (the
    /// coplanar family) or is only counted (z-fighting, where f32 rounding can
    /// collapse the two planes into one).
    Truth {
        /// A tie won by the higher id breaks.
        ties_break: bool,
    },
    /// Reference criterion, every render in a child process for its peak memory.
    Memory,
}

/// Where the watertight meshes of a fill-rule scene lie, as closed pixel rectangles
/// `[x0, x1] x [y0, y1]` of the pixel centers their boundaries pass through.
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    /// Closed regions, one per mesh.
    pub regions: Vec<[u32; 4]>,
}

impl Layout {
    /// Strictly inside a region: the pixel must be covered exactly once.
    pub fn inside(&self, x: u32, y: u32) -> bool {
        self.regions
            .iter()
            .any(|r| x > r[0] && x < r[1] && y > r[2] && y < r[3])
    }

    /// Outside every closed region: the pixel must be background.
    pub fn outside(&self, x: u32, y: u32) -> bool {
        !self
            .regions
            .iter()
            .any(|r| x >= r[0] && x <= r[1] && y >= r[2] && y <= r[3])
    }
}

/// One member: a label, the parameter value and the scene TOML.
#[derive(Debug, Clone)]
pub struct Member {
    /// Scene name (file stem).
    pub name: String,
    /// Parameter value.
    pub value: f64,
    /// Scene file text.
    pub toml: String,
    /// Triangles it resolves to (for memory per triangle), where the family counts them.
    pub triangles: Option<u64>,
    /// Where its watertight meshes lie (fill-rule families).
    pub layout: Option<Layout>,
}

/// One family: its name, what the parameter means, its members in order of difficulty.
#[derive(Debug, Clone)]
pub struct Family {
    /// Short name.
    pub name: &'static str,
    /// What the parameter is.
    pub parameter: &'static str,
    /// How its renders are judged.
    pub judge: Judge,
    /// The scenes, easiest first.
    pub members: Vec<Member>,
}

fn member(name: String, value: f64, toml: String) -> Member {
    Member {
        name,
        value,
        toml,
        triangles: None,
        layout: None,
    }
}

fn v3(v: [f64; 3]) -> String {
    format!("[{:?}, {:?}, {:?}]", v[0], v[1], v[2])
}

fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// The start of every family's scene: the buffers it is judged on and its
/// camera (`near` and `far` left to their defaults where `None`), then the
/// blank line before its objects.
fn head(
    eye: [f64; 3],
    look_at: [f64; 3],
    vfov: f64,
    (width, height): (u32, u32),
    near: Option<f64>,
    far: Option<f64>,
) -> String {
    let mut s = format!(
        "requires = [\"depth\", \"ids\"]\n[camera]\neye = {}\nlook_at = {}\nvfov = {vfov:?}\n\
         width = {width}\nheight = {height}\n",
        v3(eye),
        v3(look_at)
    );
    for (key, v) in [("near", near), ("far", far)] {
        if let Some(v) = v {
            let _ = writeln!(s, "{key} = {v:?}");
        }
    }
    s.push('\n');
    s
}

/// Two triangles covering the rectangle from `(x0, y0)` to `(x1, y1)`,
/// vertices placed by `p`, as the text of a `triangles` shape's list.
fn quad(p: impl Fn(f64, f64) -> String, (x0, y0): (f64, f64), (x1, y1): (f64, f64)) -> String {
    format!(
        "{}, {}, {}, {}, {}, {}",
        p(x0, y0),
        p(x1, y0),
        p(x1, y1),
        p(x0, y0),
        p(x1, y1),
        p(x0, y1)
    )
}

/// An icosphere over a ground grid, scaled by `s` and moved by `off`, the camera
/// at a fixed relative position; `near`/`far` as ratios of the eye's distance.
fn sphere_scene(s: f64, off: [f64; 3], near_ratio: f64, far_ratio: Option<f64>) -> String {
    let rel = [1.3, 0.9, 3.1];
    let eye = [
        rel[0] * s + off[0],
        rel[1] * s + off[1],
        rel[2] * s + off[2],
    ];
    let dist = (rel[0] * rel[0] + rel[1] * rel[1] + rel[2] * rel[2]).sqrt() * s;
    format!(
        r#"{}[[objects]]
name = "sphere"
shape = {{ kind = "icosphere", subdivisions = 2, radius = 1.0 }}
transform = {{ scale = {}, translate = {} }}
allow_degenerate = true

[[objects]]
name = "ground"
shape = {{ kind = "grid", min = [-3.0, -3.0], max = [3.0, 3.0], nx = 6, ny = 6 }}
transform = {{ scale = {}, rotate = [-90.0, 0.0, 0.0], translate = {} }}
allow_degenerate = true
"#,
        head(
            eye,
            off,
            45.0,
            (48, 36),
            Some(near_ratio * dist),
            far_ratio.map(|f| f * dist)
        ),
        v3([s; 3]),
        v3(off),
        v3([s; 3]),
        v3([off[0], off[1] - s, off[2]])
    )
}

/// Eight slivers 1.9 long and 1.9/aspect high, each at its own depth (so
/// overlaps at low aspect ratios are decided by depth, never by coplanar ties),
/// in front of a backdrop.
fn sliver_scene(aspect: f64) -> String {
    let mut verts = String::new();
    for k in 0..8 {
        let y = -0.8 + 0.2 * f64::from(k);
        let z = -0.05 * f64::from(k);
        let h = 1.9 / aspect;
        let _ = write!(
            verts,
            "[-0.95, {y:?}, {z:?}], [0.95, {:?}, {z:?}], [0.95, {y:?}, {z:?}], ",
            y + h
        );
    }
    let head = head([0.0, 0.0, 1.0], [0.0; 3], 90.0, (64, 64), Some(0.001), None);
    format!(
        r#"{head}[[objects]]
name = "slivers"
shape = {{ kind = "triangles", vertices = [{verts}] }}
allow_degenerate = true

[[objects]]
name = "backdrop"
shape = {{ kind = "quad", size = [4.0, 4.0] }}
transform = {{ translate = [0.0, 0.0, -1.0] }}
"#
    )
}

fn grazing_scene(tilt: f64) -> String {
    let head = head(
        [0.0, tilt, 5.0],
        [0.0; 3],
        40.0,
        (48, 36),
        Some(0.0001),
        None,
    );
    format!(
        r#"{head}[[objects]]
name = "floor"
shape = {{ kind = "grid", min = [-4.0, -4.0], max = [4.0, 4.0], nx = 16, ny = 16 }}
transform = {{ rotate = [-90.0, 0.0, 0.0] }}
"#
    )
}

/// A `w` x `w` image at vfov 90 from 1 above the plane z = 0 (all moved by
/// `off`): pixel centers lie at odd multiples of 1/w. The left half holds a
/// grid of 2-pixel cells (every center is a vertex, on a horizontal or
/// vertical edge, or on a diagonal), the right half a fan whose spokes run to
/// every pixel center on a square rim (slopes k/R, through centers wherever
/// gcd(k, R) > 1). Both are watertight: each center strictly inside must be
/// covered once, and which triangle covers it is the top-left rule's choice.
pub fn pixel_centers_scene(w: u32, off: [f64; 3]) -> (String, Layout) {
    assert!(
        w >= 16 && w.is_power_of_two(),
        "pixel-center scenes need w = 2^k >= 16"
    );
    let wf = f64::from(w);
    // World coordinates of pixel center (i, j) on the plane, before the offset.
    let px = |i: i64| -1.0 + (2 * i + 1) as f64 / wf;
    let py = |j: i64| 1.0 - (2 * j + 1) as f64 / wf;
    let half = i64::from(w / 2);
    // Grid: columns 0..=half-2, rows 1..=w-1, cells of 2 pixels.
    let (gx1, gy0, gy1) = (half - 2, 1, i64::from(w) - 1);
    let (nx, ny) = (gx1 / 2, (gy1 - gy0) / 2);
    // Fan: center (3w/4, w/2), rim at R = w/4 - 2 pixels.
    let (cx, cy, r) = (3 * i64::from(w) / 4, half, i64::from(w) / 4 - 2);
    let mut rim = Vec::new();
    for k in -r..r {
        rim.push((cx + k, cy + r)); // bottom row (y down), left to right
    }
    for k in -r..r {
        rim.push((cx + r, cy - k)); // right column, bottom to top
    }
    for k in -r..r {
        rim.push((cx - k, cy - r)); // top row, right to left
    }
    for k in -r..r {
        rim.push((cx - r, cy + k)); // left column, top to bottom
    }
    let mut fan = String::new();
    for k in 0..rim.len() {
        let (a, b) = (rim[k], rim[(k + 1) % rim.len()]);
        let _ = write!(
            fan,
            "[{:?}, {:?}, 0.0], [{:?}, {:?}, 0.0], [{:?}, {:?}, 0.0], ",
            px(cx),
            py(cy),
            px(a.0),
            py(a.1),
            px(b.0),
            py(b.1)
        );
    }
    let toml = format!(
        r#"{}[[objects]]
name = "grid"
shape = {{ kind = "grid", min = [{:?}, {:?}], max = [{:?}, {:?}], nx = {nx}, ny = {ny} }}
transform = {{ translate = {} }}

[[objects]]
name = "fan"
shape = {{ kind = "triangles", vertices = [{fan}] }}
transform = {{ translate = {} }}
"#,
        head(
            add(off, [0.0, 0.0, 1.0]),
            off,
            90.0,
            (w, w),
            Some(0.001),
            None
        ),
        px(0),
        py(gy1),
        px(gx1),
        py(gy0),
        v3(off),
        v3(off),
    );
    let layout = Layout {
        regions: vec![
            [0, gx1 as u32, gy0 as u32, gy1 as u32],
            [
                (cx - r) as u32,
                (cx + r) as u32,
                (cy - r) as u32,
                (cy + r) as u32,
            ],
        ],
    };
    (toml, layout)
}

/// Coplanar overlaps on the tilted plane z = x/4 + y/8 (dyadic, so every
/// vertex lies exactly on it), seen from a fixed relative eye, all moved by
/// `off`: a base quad (ids 0, 1), an overlapping quad with different vertices
/// (2, 3) and one triangle twice (4, 5), each partly outside the others. Equal
/// depth goes to the lower id (docs/DESIGN.md), so the truth is the lowest covering id.
pub fn coplanar_scene(off: [f64; 3]) -> String {
    let p = |x: f64, y: f64| v3(add(off, [x, y, x / 4.0 + y / 8.0]));
    let tri = format!("{}, {}, {}", p(-1.25, -1.0), p(2.0, -0.5), p(-0.5, 1.25));
    format!(
        r#"{}[[objects]]
name = "base"
shape = {{ kind = "triangles", vertices = [{}] }}

[[objects]]
name = "overlap"
shape = {{ kind = "triangles", vertices = [{}] }}

[[objects]]
name = "twin_a"
shape = {{ kind = "triangles", vertices = [{tri}] }}

[[objects]]
name = "twin_b"
shape = {{ kind = "triangles", vertices = [{tri}] }}
"#,
        head(
            add(off, [0.5, 0.75, 4.0]),
            off,
            60.0,
            (64, 48),
            Some(0.001),
            None
        ),
        quad(p, (-1.5, -1.5), (1.5, 1.5)),
        quad(p, (-0.5, -1.25), (1.75, 0.75)),
    )
}

/// Two parallel quads on the tilted plane z = x/4 + y/8, the nearer one moved
/// `rel` x 10 toward an eye 10 away and given the higher ids (2, 3), so that the
/// tie rule can never hide a lost depth test: the nearer surface must win.
pub fn zfight_scene(rel: f64) -> String {
    let sep = 10.0 * rel;
    let tilted =
        |h: f64, dz: f64| quad(|x, y| v3([x, y, x / 4.0 + y / 8.0 + dz]), (-h, -h), (h, h));
    let head = head([1.0, 2.0, 10.0], [0.0; 3], 40.0, (64, 48), Some(0.01), None);
    format!(
        r#"{head}[[objects]]
name = "far"
shape = {{ kind = "triangles", vertices = [{}] }}

[[objects]]
name = "near"
shape = {{ kind = "triangles", vertices = [{}] }}
allow_degenerate = true
"#,
        tilted(4.0, 0.0),
        tilted(2.5, sep),
    )
}

/// A small tilted triangle `d` in front of an eye at (1, 0.5, 1) (so f32
/// renderers subtract nearly equal coordinates), the near plane at d/2, a
/// backdrop 1 away. The triangle is scaled with `d` to cover the image's middle.
pub fn near_eye_scene(d: f64) -> String {
    let eye = [1.0, 0.5, 1.0];
    let p = |x: f64, y: f64, z: f64| v3(add(eye, [x * d, y * d, -z * d]));
    format!(
        r#"{}[[objects]]
name = "near"
shape = {{ kind = "triangles", vertices = [{}, {}, {}] }}
allow_degenerate = true

[[objects]]
name = "backdrop"
shape = {{ kind = "quad", size = [4.0, 4.0] }}
transform = {{ translate = {} }}
"#,
        head(
            eye,
            add(eye, [0.0, 0.0, -1.0]),
            60.0,
            (48, 36),
            Some(d / 2.0),
            None
        ),
        p(-0.4, -0.35, 1.0),
        p(0.45, -0.3, 1.2),
        p(0.0, 0.4, 0.9),
        v3(add(eye, [0.0, 0.0, -1.0])),
    )
}

/// An `n` x `n` grid (2n^2 triangles, most smaller than a pixel) tilted away
/// from the camera: the memory family.
pub fn count_scene(n: u32) -> String {
    let head = head([0.0, 1.5, 3.5], [0.0; 3], 50.0, (512, 384), None, None);
    format!(
        r#"{head}[[objects]]
name = "grid"
shape = {{ kind = "grid", min = [-2.0, -2.0], max = [2.0, 2.0], nx = {n}, ny = {n} }}
transform = {{ rotate = [-60.0, 0.0, 0.0] }}
"#
    )
}

/// Grid sides for the memory family: about 1M, 4M and 16M triangles (quick: 20k).
pub fn count_sides(quick: bool) -> Vec<u32> {
    if quick {
        vec![100]
    } else {
        vec![707, 1414, 2828]
    }
}

fn fill_member(name: String, value: f64, w: u32, off: [f64; 3]) -> Member {
    let (toml, layout) = pixel_centers_scene(w, off);
    Member {
        layout: Some(layout),
        ..member(name, value, toml)
    }
}

fn powers(lo: i32, hi: i32) -> Vec<i32> {
    (lo..=hi).collect()
}

/// The families, full or quick (first and last value of a few cheap families,
/// and the memory family at 20k triangles).
pub fn families(quick: bool) -> Vec<Family> {
    let pick = |v: Vec<i32>| -> Vec<i32> {
        if quick {
            vec![v[0], v[v.len() - 1]]
        } else {
            v
        }
    };
    let reference = |name, parameter, members| Family {
        name,
        parameter,
        judge: Judge::Reference,
        members,
    };
    let mut out = vec![
        reference(
            "offset",
            "translation of the whole scene (eye included)",
            pick(powers(0, 7))
                .into_iter()
                .map(|k| {
                    let o = 10f64.powi(k);
                    member(
                        format!("offset_1e{k}"),
                        o,
                        sphere_scene(1.0, [o, -0.5 * o, 0.25 * o], 1e-4, None),
                    )
                })
                .collect(),
        ),
        reference(
            "grazing",
            "eye height above a floor 5 units away",
            pick(powers(1, 6))
                .into_iter()
                .map(|k| {
                    let t = 10f64.powi(-k);
                    member(format!("grazing_1e-{k}"), t, grazing_scene(t))
                })
                .collect(),
        ),
    ];
    // Pixel centers moved by 10^k stay exact in f32 up to 1e5 at 64 px (17 + 6 bits).
    out.push(Family {
        name: "pixel centers, offset",
        parameter:
            "translation of a 64 px fill-rule scene (every vertex and edge on pixel centers)",
        judge: Judge::FillRule,
        members: pick(powers(0, 5))
            .into_iter()
            .map(|k| {
                let o = 10f64.powi(k);
                fill_member(format!("pixelcenters_off_1e{k}"), o, 64, [o, -o, o])
            })
            .collect(),
    });
    out.push(Family {
        name: "coplanar",
        parameter: "translation of coplanar overlapping and duplicated triangles (exact ties)",
        judge: Judge::Truth { ties_break: true },
        members: pick(powers(0, 5))
            .into_iter()
            .map(|k| {
                let o = 10f64.powi(k);
                member(format!("coplanar_1e{k}"), o, coplanar_scene([o, o, -o]))
            })
            .collect(),
    });
    out.push(Family {
        name: "z-fighting",
        parameter: "separation of two parallel planes / distance from the eye",
        judge: Judge::Truth { ties_break: false },
        members: pick(powers(1, 9))
            .into_iter()
            .map(|k| {
                let r = 10f64.powi(-k);
                member(format!("zfight_1e-{k}"), r, zfight_scene(r))
            })
            .collect(),
    });
    out.push(Family {
        name: "triangle count",
        parameter: "triangles (grid of mostly sub-pixel triangles, 512x384)",
        judge: Judge::Memory,
        members: count_sides(quick)
            .into_iter()
            .map(|n| {
                let t = 2 * u64::from(n) * u64::from(n);
                Member {
                    name: format!("count_{t}"),
                    value: t as f64,
                    toml: count_scene(n),
                    triangles: Some(t),
                    layout: None,
                }
            })
            .collect(),
    });
    if quick {
        return out;
    }
    out.push(reference(
        "scale down",
        "uniform scale of scene and camera",
        powers(0, 6)
            .into_iter()
            .map(|k| {
                let s = 10f64.powi(-k);
                member(
                    format!("scale_1e-{k}"),
                    s,
                    sphere_scene(s, [0.0; 3], 1e-4, None),
                )
            })
            .collect(),
    ));
    out.push(reference(
        "scale up",
        "uniform scale of scene and camera",
        powers(0, 6)
            .into_iter()
            .map(|k| {
                let s = 10f64.powi(k);
                member(
                    format!("scale_1e{k}"),
                    s,
                    sphere_scene(s, [0.0; 3], 1e-4, None),
                )
            })
            .collect(),
    ));
    out.push(reference(
        "near/far",
        "near / far (far = 10 x the eye's distance)",
        powers(1, 7)
            .into_iter()
            .map(|k| {
                let r = 10f64.powi(-k);
                member(
                    format!("nearfar_1e-{k}"),
                    r,
                    sphere_scene(1.0, [0.0; 3], 10.0 * r, Some(10.0)),
                )
            })
            .collect(),
    ));
    out.push(reference(
        "sliver",
        "aspect ratio of sliver triangles",
        powers(0, 6)
            .into_iter()
            .map(|k| {
                let a = 10f64.powi(k);
                member(format!("sliver_1e{k}"), a, sliver_scene(a))
            })
            .collect(),
    ));
    out.push(Family {
        name: "pixel centers",
        parameter: "image size of a fill-rule scene (every vertex and edge on pixel centers)",
        judge: Judge::FillRule,
        members: [16u32, 64, 256, 1024]
            .into_iter()
            .map(|w| fill_member(format!("pixelcenters_{w}"), f64::from(w), w, [0.0; 3]))
            .collect(),
    });
    out.push(Family {
        name: "near the eye",
        parameter: "distance of a triangle from the eye (near plane at half of it)",
        judge: Judge::Truth { ties_break: true },
        members: powers(1, 7)
            .into_iter()
            .map(|k| {
                let d = 10f64.powi(-k);
                member(format!("neareye_1e-{k}"), d, near_eye_scene(d))
            })
            .collect(),
    });
    out
}
