//! COLMAP sparse models with the images' `cam_from_world` replaced, in the model's own encoding
//! (text or binary): `images` is patched in place (2D points, camera ids and names as stored),
//! `cameras` and `points3D` are copied. The points are not re-triangulated.
//!
//! COLMAP 3.12+'s `rigs` and `frames` files are left out on purpose: a frame holds its own
//! `rig_from_world` pose, so copying them beside the patched `images` would keep the old poses
//! there, while a model without them is read as the legacy layout, one trivial rig per camera
//! and one frame per image, posed from `images`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::replacement::Replacement;
use crate::colmap::{PoseFields, binary, find_model_dir, text};
use crate::error::{Result, SceneError};

pub(super) fn write(root: &Path, poses: &[Replacement], out_dir: &Path) -> Result<Vec<PathBuf>> {
    let dir = find_model_dir(root)
        .ok_or_else(|| SceneError::format(root, "no COLMAP model to write refined poses into"))?;
    let binary_model = dir.join("cameras.bin").is_file();
    let ext = if binary_model { "bin" } else { "txt" };
    let by_id: BTreeMap<u32, PoseFields> = poses
        .iter()
        .map(|p| {
            let id = u32::try_from(p.entry).map_err(|_| {
                SceneError::invalid(
                    &dir,
                    format!("view {}: image id {} is not a u32", p.view, p.entry),
                )
            })?;
            let q = p.world_to_camera.quaternion();
            let t = p.world_to_camera.translation;
            Ok((id, ([q.w, q.i, q.j, q.k], [t.x, t.y, t.z])))
        })
        .collect::<Result<_>>()?;
    let images_in = dir.join(format!("images.{ext}"));
    let images = if binary_model {
        binary::replace_image_poses(&images_in, &by_id)?
    } else {
        text::replace_image_poses(&images_in, &by_id)?.into_bytes()
    };
    let out = out_dir.join("sparse_refined");
    std::fs::create_dir_all(&out).map_err(|e| SceneError::io(&out, e))?;
    let mut written = Vec::new();
    for name in ["cameras", "points3D"] {
        let from = dir.join(format!("{name}.{ext}"));
        let bytes = std::fs::read(&from).map_err(|e| SceneError::io(&from, e))?;
        let to = out.join(format!("{name}.{ext}"));
        crate::atomic::write_bytes(&to, &bytes)?;
        written.push(to);
    }
    let to = out.join(format!("images.{ext}"));
    crate::atomic::write_bytes(&to, &images)?;
    written.push(to);
    Ok(written)
}
