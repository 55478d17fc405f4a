//! rendiff-wgpu: a headless wgpu (Vulkan) renderer of rendiff's resolved
//! scenes, writing depth and triangle/object IDs; and the template a user
//! copies to plug their own renderer into rendiff (README.md).
//!
//! The pieces, in the order a render uses them:
//! [`scene`] reads the resolved scene folder, [`camera`] turns the exported
//! camera into a view-projection matrix, [`gpu`] draws and reads back,
//! [`output`] writes the EXR, and [`precision`] derives how far this
//! renderer may legitimately differ from rendiff's exact core; [`pending`]
//! removes the temporary paths when the process is interrupted.

#![deny(missing_docs)]

pub mod camera;
pub mod gpu;
pub mod output;
pub mod pending;
pub mod precision;
pub mod scene;
