//! Watertightness: counting every covering triangle, not only the winner, in
//! both loops. A closed mesh has no cracks and no double coverage.

mod common;

use common::scenes::*;
use std::path::Path;

fn scene(name: &str) -> rendiff::scene::resolve::ResolvedScene {
    load(
        &Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("scenes")
            .join(name),
    )
}

#[test]
fn closed_icosphere_is_covered_once_from_the_front_and_once_from_the_back() {
    let s = scene("icosphere.toml");
    let (r, t) = both(&s, true);
    assert_identical("icosphere", &r, &t);
    for frame in [&r, &t] {
        let cov = frame.coverage.as_ref().unwrap();
        let mut inside = 0;
        for (i, [front, back]) in cov.iter().enumerate() {
            let (x, y) = (i % frame.width as usize, i / frame.width as usize);
            assert!(
                *front <= 1 && *back <= 1 && front == back,
                "{}: pixel ({x},{y}) covered by {front} front and {back} back faces",
                frame.renderer
            );
            if *front == 1 {
                inside += 1;
                assert_ne!(frame.prim[i], u32::MAX);
            } else {
                assert_eq!(frame.prim[i], u32::MAX, "hit without coverage at ({x},{y})");
            }
        }
        assert!(inside > 2000, "silhouette too small: {inside} pixels");
    }
}

#[test]
fn pixel_center_grid_has_no_cracks_and_no_double_coverage() {
    let s = scene("pixel_grid.toml");
    let (r, t) = both(&s, true);
    assert_identical("pixel_grid", &r, &t);
    // The grid spans z = 0 from -63/64 to 57/64 on both axes: its edges lie
    // exactly on the centers of columns 0 and 60 and rows 3 and 63. The top-left
    // rule keeps the left and top edges and drops the right and bottom ones, so
    // exactly columns 0..=59 and rows 3..=62 are covered, each exactly once.
    for frame in [&r, &t] {
        let cov = frame.coverage.as_ref().unwrap();
        for y in 0..64u32 {
            for x in 0..64u32 {
                let i = frame.index(x, y);
                let n = cov[i][0] + cov[i][1];
                let expected = u16::from(x <= 59 && (3..=62).contains(&y));
                assert_eq!(
                    n, expected,
                    "{}: pixel ({x},{y}) covered {n} times, expected {expected}",
                    frame.renderer
                );
            }
        }
    }
    assert!(
        r.counters.ties > 0 && t.counters.ties > 0,
        "the grid must exercise the tie rule"
    );
}
