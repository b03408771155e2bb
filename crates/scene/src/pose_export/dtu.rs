//! IDR / NeuS camera files with `world_mat_i` replaced by `K [R | t]` in the file's own world
//! (millimetres for DTU), `K` decomposed from the stored `world_mat_i`; every other array
//! (`scale_mat_i`, `camera_mat_i`, …) is copied.

use std::path::{Path, PathBuf};

use nalgebra::{Matrix3x4, Matrix4};

use super::replacement::{PoseSource, Replacement, refined_name};
use crate::dtu::{cameras_path, decompose_projection};
use crate::error::{Result, SceneError};
use crate::numpy::{self, Array};

pub(super) fn write(source: PoseSource, poses: &[Replacement], out_dir: &Path) -> Result<PathBuf> {
    let input = cameras_path(source.root, source.options);
    let mut arrays = numpy::read_npz(&input)?;
    for p in poses {
        let name = format!("world_mat_{}", p.entry);
        let stored = arrays
            .get(&name)
            .ok_or_else(|| SceneError::format(&input, format!("no {name} for view {}", p.view)))?;
        let world = crate::dtu::matrix4(stored, &name, &input)?;
        let projection: Matrix3x4<f64> = world.fixed_view::<3, 4>(0, 0).into_owned();
        let k = decompose_projection(&projection)
            .map_err(|m| SceneError::invalid(&input, format!("{name}: {m}")))?
            .k;
        let mut new = world;
        new.fixed_view_mut::<3, 4>(0, 0)
            .copy_from(&(k * p.world_to_camera.to_matrix4().fixed_view::<3, 4>(0, 0)));
        arrays.insert(name, array_like(stored, &new));
    }
    let out = refined_name(&input, out_dir);
    numpy::save_npz(&out, &arrays)?;
    Ok(out)
}

/// `m` in the shape of `stored` (IDR files hold 4×4 matrices; some tools write 3×4).
fn array_like(stored: &Array, m: &Matrix4<f64>) -> Array {
    let rows = stored.shape[0];
    Array {
        shape: stored.shape.clone(),
        data: (0..rows)
            .flat_map(|r| (0..4).map(move |c| m[(r, c)]))
            .collect(),
    }
}
