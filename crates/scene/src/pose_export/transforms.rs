//! `transforms.json` files (NeRF-synthetic, nerfstudio, instant-ngp) with the frames'
//! `transform_matrix` (camera-to-world, OpenGL axes) replaced; every other field is kept.

use std::path::{Path, PathBuf};

use serde_json::Value;

use super::replacement::{Replacement, refined_name};
use crate::axes::opengl_to_opencv;
use crate::dataset::Dataset;
use crate::error::{Result, SceneError};

/// NeRF-synthetic: training views are frames of `transforms_train.json`, test views of
/// `transforms_test.json` ([`crate::transforms::load_blender`]); a file is written only when
/// one of its frames changes.
pub(super) fn write_blender(
    root: &Path,
    dataset: &Dataset,
    poses: &[Replacement],
    out_dir: &Path,
) -> Result<Vec<PathBuf>> {
    let (train, test): (Vec<Replacement>, Vec<Replacement>) = poses
        .iter()
        .cloned()
        .partition(|p| dataset.train.contains(&p.view));
    let mut written = Vec::new();
    for (file, group) in [
        ("transforms_train.json", train),
        ("transforms_test.json", test),
    ] {
        if !group.is_empty() {
            written.push(write_one(&root.join(file), &group, out_dir)?);
        }
    }
    Ok(written)
}

/// One transforms file with the frames of `poses` (by position in `frames`) replaced.
pub(super) fn write_one(input: &Path, poses: &[Replacement], out_dir: &Path) -> Result<PathBuf> {
    let text = std::fs::read_to_string(input).map_err(|e| SceneError::io(input, e))?;
    // Parsed as the loader parses it, so a file it refuses is refused here too.
    crate::transforms::parse_transforms(&text, input)?;
    let mut doc: Value = serde_json::from_str(&text)
        .map_err(|e| SceneError::format(input, format!("invalid transforms JSON: {e}")))?;
    let frames = doc
        .get_mut("frames")
        .and_then(Value::as_array_mut)
        .ok_or_else(|| SceneError::format(input, "no frames array"))?;
    let n_frames = frames.len();
    for p in poses {
        let frame = frames.get_mut(p.entry).ok_or_else(|| {
            SceneError::invalid(
                input,
                format!(
                    "no frame {} for view {} ({n_frames} frames)",
                    p.entry, p.view
                ),
            )
        })?;
        let gl = opengl_to_opencv(&p.world_to_camera.inverse()).to_matrix4();
        let rows: Vec<Vec<f64>> = (0..4)
            .map(|r| (0..4).map(|c| gl[(r, c)]).collect())
            .collect();
        frame["transform_matrix"] = serde_json::json!(rows);
    }
    let out = refined_name(input, out_dir);
    let text = serde_json::to_string_pretty(&doc)
        .map_err(|e| SceneError::format(input, format!("cannot write JSON: {e}")))?;
    crate::atomic::write_bytes(&out, text.as_bytes())?;
    Ok(out)
}
