//! Built-in geometry generators, so test scenes need no mesh files.
//!
//! Generators produce f64 triangles in object space; resolution applies the
//! object's transform and rounds to f32 exactly once.

use glam::DVec3;
use serde::Deserialize;
use std::collections::HashMap;

/// Largest icosphere subdivision level accepted (20·4^9 ≈ 5.2M triangles).
pub const MAX_ICOSPHERE_LEVEL: u32 = 9;
/// Largest grid side accepted, in cells.
pub const MAX_GRID_CELLS: u32 = 4096;

/// A built-in generator, selected by `kind` in the scene file.
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Shape {
    /// The course lesson's three overlapping triangles at depths 1, 0 and -1 along z.
    ThreeTriangles,
    /// Closed icosphere: each level splits every triangle into four.
    Icosphere {
        subdivisions: u32,
        #[serde(default = "one")]
        radius: f64,
    },
    /// Flat grid in the z = 0 plane from `min` to `max`, `nx` x `ny` cells of two triangles.
    Grid {
        min: [f64; 2],
        max: [f64; 2],
        nx: u32,
        ny: u32,
    },
    /// Unit-free quad in the z = 0 plane, centered, facing +z (two triangles).
    Quad {
        #[serde(default = "one2")]
        size: [f64; 2],
    },
    /// Closed axis-aligned box (12 triangles), outward-facing unless `inward`.
    Box {
        min: [f64; 3],
        max: [f64; 3],
        #[serde(default)]
        inward: bool,
    },
    /// Literal triangles: every three vertices make one triangle.
    Triangles { vertices: Vec<[f64; 3]> },
}

fn one() -> f64 {
    1.0
}
fn one2() -> [f64; 2] {
    [1.0, 1.0]
}

/// One triangle in f64, before rounding.
pub type Tri64 = [DVec3; 3];

impl Shape {
    /// Checks parameters that serde cannot; returns the problem in words.
    pub fn validate(&self) -> Result<(), String> {
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        match self {
            Shape::ThreeTriangles => Ok(()),
            Shape::Icosphere {
                subdivisions,
                radius,
            } => {
                if *subdivisions > MAX_ICOSPHERE_LEVEL {
                    Err(format!(
                        "icosphere subdivisions must be at most {MAX_ICOSPHERE_LEVEL}, got {subdivisions}"
                    ))
                } else if !(radius.is_finite() && *radius > 0.0) {
                    Err(format!(
                        "icosphere radius must be finite and > 0, got {radius}"
                    ))
                } else {
                    Ok(())
                }
            }
            Shape::Grid { min, max, nx, ny } => {
                if !finite(min) || !finite(max) {
                    Err("grid min/max must be finite".into())
                } else if *nx == 0 || *ny == 0 || *nx > MAX_GRID_CELLS || *ny > MAX_GRID_CELLS {
                    Err(format!(
                        "grid nx and ny must be in 1..={MAX_GRID_CELLS}, got {nx} x {ny}"
                    ))
                } else if !(max[0] > min[0] && max[1] > min[1]) {
                    Err("grid max must be greater than min on both axes".into())
                } else {
                    Ok(())
                }
            }
            Shape::Quad { size } => {
                if finite(size) && size[0] > 0.0 && size[1] > 0.0 {
                    Ok(())
                } else {
                    Err(format!("quad size must be finite and > 0, got {size:?}"))
                }
            }
            Shape::Box { min, max, .. } => {
                if !finite(min) || !finite(max) {
                    Err("box min/max must be finite".into())
                } else if (0..3).any(|k| max[k] <= min[k]) {
                    Err("box max must be greater than min on every axis".into())
                } else {
                    Ok(())
                }
            }
            Shape::Triangles { vertices } => {
                if vertices.is_empty() || vertices.len() % 3 != 0 {
                    Err(format!(
                        "triangles needs a non-zero multiple of 3 vertices, got {}",
                        vertices.len()
                    ))
                } else if let Some(i) = vertices.iter().position(|v| !finite(v)) {
                    Err(format!("vertices[{i}] is not finite: {:?}", vertices[i]))
                } else {
                    Ok(())
                }
            }
        }
    }

    /// How many triangles [`Shape::triangles`] will generate, computed without
    /// generating them (so budgets are checked before any allocation). Call it
    /// after [`Shape::validate`]; the arithmetic saturates either way.
    pub fn triangle_count(&self) -> u64 {
        match self {
            Shape::ThreeTriangles => 3,
            Shape::Icosphere { subdivisions, .. } => {
                20u64.saturating_mul(4u64.saturating_pow(*subdivisions))
            }
            Shape::Grid { nx, ny, .. } => 2 * u64::from(*nx) * u64::from(*ny),
            Shape::Quad { .. } => 2,
            Shape::Box { .. } => 12,
            Shape::Triangles { vertices } => vertices.len() as u64 / 3,
        }
    }

    /// Generates the triangles in object space.
    pub fn triangles(&self) -> Vec<Tri64> {
        match self {
            Shape::ThreeTriangles => three_triangles(),
            Shape::Icosphere {
                subdivisions,
                radius,
            } => icosphere(*subdivisions, *radius),
            Shape::Grid { min, max, nx, ny } => grid(*min, *max, *nx, *ny),
            Shape::Quad { size } => grid(
                [-size[0] / 2.0, -size[1] / 2.0],
                [size[0] / 2.0, size[1] / 2.0],
                1,
                1,
            ),
            Shape::Box { min, max, inward } => cube(DVec3::from(*min), DVec3::from(*max), *inward),
            Shape::Triangles { vertices } => vertices
                .chunks_exact(3)
                .map(|c| [c[0].into(), c[1].into(), c[2].into()])
                .collect(),
        }
    }
}

/// The lesson's three overlapping triangles, each at its own depth.
pub fn three_triangles() -> Vec<Tri64> {
    let t = |a: [f64; 3], b: [f64; 3], c: [f64; 3]| [a.into(), b.into(), c.into()];
    vec![
        t([-1.5, -1.0, 0.0], [0.5, -1.0, 0.0], [-0.5, 1.2, 0.0]),
        t([-0.5, -1.2, -1.0], [1.5, -1.2, -1.0], [0.5, 1.0, -1.0]),
        t([-1.0, -0.2, 1.0], [1.0, -0.2, 1.0], [0.0, 0.6, 1.0]),
    ]
}

/// Icosphere with outward counter-clockwise winding.
pub fn icosphere(level: u32, radius: f64) -> Vec<Tri64> {
    let p = (1.0 + 5f64.sqrt()) / 2.0;
    let mut verts: Vec<DVec3> = [
        [-1.0, p, 0.0],
        [1.0, p, 0.0],
        [-1.0, -p, 0.0],
        [1.0, -p, 0.0],
        [0.0, -1.0, p],
        [0.0, 1.0, p],
        [0.0, -1.0, -p],
        [0.0, 1.0, -p],
        [p, 0.0, -1.0],
        [p, 0.0, 1.0],
        [-p, 0.0, -1.0],
        [-p, 0.0, 1.0],
    ]
    .iter()
    .map(|v| DVec3::from(*v).normalize())
    .collect();
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..level {
        let mut cache: HashMap<(u32, u32), u32> = HashMap::with_capacity(faces.len() * 2);
        let mut mid = |a: u32, b: u32, verts: &mut Vec<DVec3>| -> u32 {
            let key = (a.min(b), a.max(b));
            *cache.entry(key).or_insert_with(|| {
                verts.push(((verts[a as usize] + verts[b as usize]) * 0.5).normalize());
                (verts.len() - 1) as u32
            })
        };
        let mut next = Vec::with_capacity(faces.len() * 4);
        for [a, b, c] in faces {
            let ab = mid(a, b, &mut verts);
            let bc = mid(b, c, &mut verts);
            let ca = mid(c, a, &mut verts);
            next.extend_from_slice(&[[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    faces
        .iter()
        .map(|f| f.map(|i| verts[i as usize] * radius))
        .collect()
}

/// Grid in z = 0; each cell split along its (i,j)-(i+1,j+1) diagonal, facing +z.
pub fn grid(min: [f64; 2], max: [f64; 2], nx: u32, ny: u32) -> Vec<Tri64> {
    let at = |i: u32, j: u32| {
        DVec3::new(
            min[0] + (max[0] - min[0]) * f64::from(i) / f64::from(nx),
            min[1] + (max[1] - min[1]) * f64::from(j) / f64::from(ny),
            0.0,
        )
    };
    let mut out = Vec::with_capacity((nx * ny * 2) as usize);
    for j in 0..ny {
        for i in 0..nx {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            out.push([a, b, c]);
            out.push([a, c, d]);
        }
    }
    out
}

/// Checks [`crossover_grid`]'s arguments before anything is allocated (and
/// `bench crossover`'s whole sweep before its first size runs): at least
/// one cell per side, at most [`crate::scene::MAX_SCENE_TRIANGLES`]
/// triangles (`2 nx²`), an image within the scenes' limits
/// ([`crate::scene::check_image_size`]).
pub fn check_crossover_grid(nx: u32, size: u32) -> Result<(), String> {
    let triangles = 2 * u64::from(nx) * u64::from(nx);
    if nx == 0 {
        Err("grid of 0x0 cells: nx must be at least 1".into())
    } else if triangles > crate::scene::MAX_SCENE_TRIANGLES {
        Err(format!(
            "grid of {nx}x{nx} cells is {triangles} triangles, more than the limit of {} (64 Mi) per scene",
            crate::scene::MAX_SCENE_TRIANGLES
        ))
    } else {
        crate::scene::check_image_size(size, size)
    }
}

/// The crossover bench's scene (`rendiff bench crossover`, and the raster and
/// trace timing loops): an `nx` x `nx` grid at z = 0 seen from (0, 0, 1) with
/// a 90° field of view, covering the whole `size` x `size` image whatever
/// `nx`. `aligned`: exactly [-1, 1]², so grid lines, diagonals and (at nx =
/// size) vertices pass through pixel centers: every such center is a tie for
/// the exact predicate. Otherwise the grid overhangs the image by small
/// non-dyadic margins and ties are rare: the generic case.
pub fn crossover_grid(
    nx: u32,
    size: u32,
    aligned: bool,
) -> Result<crate::scene::resolve::ResolvedScene, String> {
    check_crossover_grid(nx, size)?;
    let cam = crate::camera::Camera::new(
        DVec3::new(0.0, 0.0, 1.0),
        DVec3::ZERO,
        DVec3::Y,
        90.0,
        size,
        size,
        1e-3,
        f64::INFINITY,
    )?;
    let (min, max) = if aligned {
        ([-1.0, -1.0], [1.0, 1.0])
    } else {
        ([-1.012_34, -1.017_1], [1.023_45, 1.008_9])
    };
    let tris = grid(min, max, nx, nx)
        .iter()
        .map(|t| t.map(|v| v.as_vec3()))
        .collect();
    Ok(crate::scene::resolve::ResolvedScene::from_triangles(
        cam, tris,
    ))
}

/// Closed axis-aligned box; outward counter-clockwise winding unless `inward`.
pub fn cube(min: DVec3, max: DVec3, inward: bool) -> Vec<Tri64> {
    let v = |x: usize, y: usize, z: usize| {
        DVec3::new(
            if x == 0 { min.x } else { max.x },
            if y == 0 { min.y } else { max.y },
            if z == 0 { min.z } else { max.z },
        )
    };
    // Each face as four corners counter-clockwise seen from outside.
    let faces = [
        [v(0, 0, 0), v(0, 0, 1), v(0, 1, 1), v(0, 1, 0)], // -x
        [v(1, 0, 0), v(1, 1, 0), v(1, 1, 1), v(1, 0, 1)], // +x
        [v(0, 0, 0), v(1, 0, 0), v(1, 0, 1), v(0, 0, 1)], // -y
        [v(0, 1, 0), v(0, 1, 1), v(1, 1, 1), v(1, 1, 0)], // +y
        [v(0, 0, 0), v(0, 1, 0), v(1, 1, 0), v(1, 0, 0)], // -z
        [v(0, 0, 1), v(1, 0, 1), v(1, 1, 1), v(0, 1, 1)], // +z
    ];
    let mut out = Vec::with_capacity(12);
    for [a, b, c, d] in faces {
        if inward {
            out.push([a, c, b]);
            out.push([a, d, c]);
        } else {
            out.push([a, b, c]);
            out.push([a, c, d]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The crossover grid refuses, before allocating, what no render could
    /// hold or what is no grid at all, naming the limit; the largest
    /// accepted sizes pass the check.
    #[test]
    fn crossover_grid_sizes_are_checked() {
        let err = |nx, size| crossover_grid(nx, size, false).err().unwrap_or_default();
        assert!(err(0, 64).contains("at least 1"), "{}", err(0, 64));
        assert!(
            err(100_000, 64).contains("20000000000 triangles"),
            "{}",
            err(100_000, 64)
        );
        assert!(err(1, 0).contains("at least 1x1"), "{}", err(1, 0));
        assert!(err(1, 20_000).contains("per side"), "{}", err(1, 20_000));
        assert!(err(1, 16_384).contains("Mpixel"), "{}", err(1, 16_384));
        // 2 * 5793² = 67,117,698 > 2^26 = 67,108,864 >= 2 * 5792² = 67,094,528.
        assert!(err(5793, 8).contains("more than the limit"));
        assert_eq!(check_crossover_grid(5792, 8192), Ok(()));
        assert!(crossover_grid(2, 8, true).is_ok());
    }

    fn normal(t: &Tri64) -> DVec3 {
        (t[1] - t[0]).cross(t[2] - t[0])
    }

    #[test]
    fn icosphere_counts_and_outward_winding() {
        for level in 0..4 {
            let tris = icosphere(level, 2.0);
            assert_eq!(tris.len(), 20 * 4usize.pow(level));
            for t in &tris {
                let c = (t[0] + t[1] + t[2]) / 3.0;
                assert!(normal(t).dot(c) > 0.0, "inward face at level {level}");
                for v in t {
                    assert!((v.length() - 2.0).abs() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn cube_winding_follows_inward_flag() {
        let (lo, hi) = (DVec3::splat(-1.0), DVec3::splat(1.0));
        for t in cube(lo, hi, false) {
            assert!(normal(&t).dot((t[0] + t[1] + t[2]) / 3.0) > 0.0);
        }
        for t in cube(lo, hi, true) {
            assert!(normal(&t).dot((t[0] + t[1] + t[2]) / 3.0) < 0.0);
        }
    }

    #[test]
    fn grid_vertices_are_exact_dyadics() {
        let g = grid([-0.96875, -0.96875], [0.90625, 0.90625], 15, 15);
        assert_eq!(g.len(), 450);
        assert_eq!(g[0][1].x, -0.96875 + 0.125);
        assert!(normal(&g[0]).z > 0.0);
    }

    #[test]
    fn triangle_count_matches_generation() {
        let shapes = [
            Shape::ThreeTriangles,
            Shape::Icosphere {
                subdivisions: 3,
                radius: 1.0,
            },
            Shape::Grid {
                min: [0.0, 0.0],
                max: [1.0, 1.0],
                nx: 7,
                ny: 5,
            },
            Shape::Quad { size: [1.0, 2.0] },
            Shape::Box {
                min: [0.0; 3],
                max: [1.0; 3],
                inward: true,
            },
            Shape::Triangles {
                vertices: vec![[0.0; 3]; 6],
            },
        ];
        for s in shapes {
            assert_eq!(s.triangle_count(), s.triangles().len() as u64, "{s:?}");
        }
    }

    #[test]
    fn validation_rejects_bad_parameters() {
        assert!(Shape::Icosphere {
            subdivisions: 12,
            radius: 1.0
        }
        .validate()
        .is_err());
        assert!(Shape::Triangles {
            vertices: vec![[0.0; 3]; 2]
        }
        .validate()
        .is_err());
        assert!(Shape::Triangles {
            vertices: vec![[f64::NAN, 0.0, 0.0]; 3]
        }
        .validate()
        .is_err());
        assert!(Shape::Box {
            min: [0.0; 3],
            max: [1.0, 0.0, 1.0],
            inward: false
        }
        .validate()
        .is_err());
    }
}
