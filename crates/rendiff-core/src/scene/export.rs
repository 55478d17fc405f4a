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
        "files": {"triangles": FILES[0], "object_ids": FILES[1], "vertex_ids": FILES[2]},
    })
}

/// The files of an export, in the order they are written: `scene.json`
/// last, as its presence says the others are complete.
const FILES: [&str; 4] = [
    "triangles.f32",
    "object_ids.u32",
    "vertex_ids.u32",
    "scene.json",
];

/// Index of `scene.json` in [`FILES`].
const META: usize = FILES.len() - 1;

/// Writes `scene.json`, `triangles.f32`, `object_ids.u32` and
/// `vertex_ids.u32` (vertex_ids.rs) into `dir` (each atomically). Every
/// path is checked before anything is written (a FIFO or folder in place of the last file left the new triangles beside the old
/// scene), and an earlier export's `scene.json` is removed first: an export
/// into a folder holding another scene's files that fails or is interrupted
/// leaves no scene.json, so the folder reads as incomplete, never as the old
/// scene over the new triangles.
pub fn export(scene: &ResolvedScene, dir: &Path) -> Result<()> {
    for f in FILES {
        crate::exr_io::check_output(&dir.join(f))?;
    }
    std::fs::create_dir_all(dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    // One export's files at a time: two exports to one folder at once
    // left one scene's triangles beside the other's object IDs.
    let _lock = crate::exr_io::lock_folder(dir)?;
    let vertex_ids = super::vertex_ids::vertex_ids(&scene.triangles)
        .with_context(|| format!("{}: cannot export", dir.display()))?;
    let meta_path = dir.join(FILES[META]);
    match std::fs::remove_file(&meta_path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
            return Err(e).with_context(|| {
                format!(
                    "{}: cannot remove the earlier export's",
                    meta_path.display()
                )
            });
        }
        _ => {}
    }
    let tri_path = dir.join(FILES[0]);
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
    write_atomically(&dir.join(FILES[1]), |tmp| {
        let bytes: Vec<u8> = scene
            .object_ids
            .iter()
            .flat_map(|i| i.to_le_bytes())
            .collect();
        std::fs::write(tmp, bytes)?;
        Ok(())
    })?;
    write_atomically(&dir.join(FILES[2]), |tmp| {
        let bytes: Vec<u8> = vertex_ids.iter().flat_map(|i| i.to_le_bytes()).collect();
        std::fs::write(tmp, bytes)?;
        Ok(())
    })?;
    write_atomically(&meta_path, |tmp| {
        std::fs::write(tmp, serde_json::to_vec_pretty(&metadata(scene))?)?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(name: &str) -> ResolvedScene {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../scenes/{name}.toml"));
        ResolvedScene::resolve(&super::super::Scene::load(&path).unwrap()).unwrap()
    }

    #[test]
    fn a_failed_export_never_leaves_another_scene_readable() {
        let t = tempfile::tempdir().unwrap();
        let dir = t.path().join("out");
        let (a, b) = (scene("three_triangles"), scene("icosphere"));
        export(&a, &dir).unwrap();
        let before: Vec<Vec<u8>> = FILES
            .iter()
            .map(|f| std::fs::read(dir.join(f)).unwrap())
            .collect();

        // A folder where a later file goes: refused before anything is written.
        std::fs::remove_file(dir.join(FILES[1])).unwrap();
        std::fs::create_dir(dir.join(FILES[1])).unwrap();
        let e = export(&b, &dir).unwrap_err().to_string();
        assert!(e.contains("object_ids.u32") && e.contains("folder"), "{e}");
        for i in [0, 2, META] {
            assert_eq!(
                std::fs::read(dir.join(FILES[i])).unwrap(),
                before[i],
                "{}",
                FILES[i]
            );
        }
        std::fs::remove_dir(dir.join(FILES[1])).unwrap();
        std::fs::write(dir.join(FILES[1]), &before[1]).unwrap();

        // A write that fails midway (the object ids' temporary file cannot be
        // made): the new triangles are in, so the old scene.json must be gone.
        let tmp = dir.join(format!(".{}.tmp-{}", FILES[1], std::process::id()));
        std::fs::create_dir(&tmp).unwrap();
        assert!(export(&b, &dir).is_err());
        assert_ne!(
            std::fs::read(dir.join(FILES[0])).unwrap(),
            before[0],
            "triangles were replaced"
        );
        assert!(
            !dir.join(FILES[META]).exists(),
            "the old scene.json describes other triangles"
        );
        std::fs::remove_dir(&tmp).unwrap();
        export(&b, &dir).unwrap();
        assert!(dir.join(FILES[META]).is_file());
    }

    #[test]
    fn exports_to_one_folder_take_turns() {
        // Another writer holds the folder: the export waits, writing nothing,
        // until it is released (two at once mixed their files).
        let t = tempfile::tempdir().unwrap();
        let dir = t.path().join("out");
        std::fs::create_dir_all(&dir).unwrap();
        let lock = crate::exr_io::lock_folder(&dir).unwrap();
        let d = dir.clone();
        let writer = std::thread::spawn(move || export(&scene("three_triangles"), &d));
        std::thread::sleep(std::time::Duration::from_millis(400));
        assert!(
            std::fs::read_dir(&dir).unwrap().next().is_none(),
            "written while locked"
        );
        drop(lock);
        writer.join().unwrap().unwrap();
        assert!(dir.join(FILES[META]).is_file());
    }
}
