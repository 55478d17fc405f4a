//! rendiff-core: the renderer core of rendiff.
//!
//! The core renders visibility two ways, [`raster`] (outer loop over
//! triangles) and [`trace`] (outer loop over pixels), through one shared
//! definition in [`visibility`], shades only what a scene asks for
//! ([`shade`]), and writes docs/DESIGN.md's buffers ([`exr_io`]). Embree
//! ([`backends::embree`]) is here because it renders in process, through the
//! same scene and buffer types.
//!
//! Kept apart from the `rendiff` tool so that its invariants are visible in
//! the dependency graph: this crate has no command line, never starts a
//! process, and never reads a run folder (ARCHITECTURE.md, "Invariants").

pub mod backends;
pub mod camera;
pub mod deadline;
pub mod exr_io;
pub mod frame;
mod huge_pages;
pub mod loop_cost;
pub mod names;
pub mod pending;
pub mod predicate;
pub mod raster;
pub mod render;
pub mod scene;
pub mod shade;
pub mod simd;
pub mod trace;
pub mod visibility;
pub mod vocab;
