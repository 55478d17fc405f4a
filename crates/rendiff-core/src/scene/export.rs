//! Writes the resolved scene for external backends (docs/resolved-scene.md).

use super::resolve::ResolvedScene;
use crate::exr_io::write_atomically;
use anyhow::{Context, Result};
use serde_json::json;
use std::io::Write;
use std::path::Path;

/// Format tag every reader checks.
pub const FORMAT: &str = "rendiff-resolved/1";

/// The `scene.json` metadata of a resolved scene.
pub fn metadata(scene: &ResolvedScene) -> serde_json::Value {
    let c = &scene.camera;
    let v = |d: glam::DVec3| [d.x, d.y, d.z];
    json!({
        "format": FORMAT,
        "name": scene.name,
        "source": scene.source.display().to_string(),
        "requires": scene.requires,
        "camera": {
            "eye": v(c.eye), "look_at": v(c.look_at), "up": v(c.up),
            "vfov_deg": c.vfov_deg, "tan_half_vfov": c.tan_half_vfov,
            "width": c.width, "height": c.height,
            "forward": v(c.forward), "right": v(c.right), "up_ortho": v(c.up_ortho),
            "near": c.near,
            "far": if c.far.is_finite() { Some(c.far) } else { None },
        },
        "triangle_count": scene.triangles.len(),
        "degenerate_count": scene.degenerate.iter().filter(|d| **d).count(),
        "objects": scene.objects,
        "materials": scene.materials,
        "lights": scene.lights,
        "integrator": scene.integrator,
        "files": {"triangles": "triangles.f32", "object_ids": "object_ids.u32"},
    })
}

/// Writes `scene.json`, `triangles.f32` and `object_ids.u32` into `dir` (each atomically).
pub fn export(scene: &ResolvedScene, dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    let tri_path = dir.join("triangles.f32");
    write_atomically(&tri_path, |tmp| {
        let mut f = std::io::BufWriter::new(std::fs::File::create(tmp)?);
        for t in &scene.triangles {
            for v in t {
                for k in 0..3 {
                    f.write_all(&v[k].to_le_bytes())?;
                }
            }
        }
        f.flush()?;
        Ok(())
    })?;
    write_atomically(&dir.join("object_ids.u32"), |tmp| {
        let bytes: Vec<u8> = scene
            .object_ids
            .iter()
            .flat_map(|i| i.to_le_bytes())
            .collect();
        std::fs::write(tmp, bytes)?;
        Ok(())
    })?;
    // scene.json last: its presence means the other two are complete.
    write_atomically(&dir.join("scene.json"), |tmp| {
        std::fs::write(tmp, serde_json::to_vec_pretty(&metadata(scene))?)?;
        Ok(())
    })
}
