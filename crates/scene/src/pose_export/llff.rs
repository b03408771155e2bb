//! `poses_bounds.npy` with rows replaced: columns (down, right, back) of the camera-to-world
//! rotation and the camera centre; `hwf` and the depth bounds stay as stored.

use std::path::{Path, PathBuf};

use super::replacement::{Replacement, refined_name};
use crate::axes::opengl_to_opencv;
use crate::error::{Result, SceneError};
use crate::numpy;

pub(super) fn write(root: &Path, poses: &[Replacement], out_dir: &Path) -> Result<PathBuf> {
    let input = root.join("poses_bounds.npy");
    let mut array = numpy::read_npy(&input)?;
    // Parsed as the loader parses it, so a file it refuses is refused here too.
    let rows = crate::llff::poses_from_array(&array, &input)?;
    for p in poses {
        if p.entry >= rows.len() {
            return Err(SceneError::invalid(
                &input,
                format!(
                    "no row {} for view {} ({} rows)",
                    p.entry,
                    p.view,
                    rows.len()
                ),
            ));
        }
        // OpenCV camera-to-world → OpenGL (right, up, back) → LLFF (down, right, back).
        let gl = opengl_to_opencv(&p.world_to_camera.inverse());
        let right = gl.rotation.column(0);
        let down = -gl.rotation.column(1);
        let back = gl.rotation.column(2);
        let row = &mut array.data[17 * p.entry..17 * p.entry + 17];
        for r in 0..3 {
            row[5 * r] = down[r];
            row[5 * r + 1] = right[r];
            row[5 * r + 2] = back[r];
            row[5 * r + 3] = gl.translation[r];
        }
    }
    let out = refined_name(&input, out_dir);
    numpy::save_npy(&out, &array)?;
    Ok(out)
}
