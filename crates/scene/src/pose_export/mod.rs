//! Refined poses written back in the input's own format: a copy of the dataset's camera file in
//! which the given views carry new poses and everything else (other views, intrinsics, bounds,
//! 2D points, extra fields) is as stored, so the file can stand in for the original in the tools
//! that read that format (NeuS for IDR `cameras_sphere.npz`, NeRF loaders for
//! `poses_bounds.npy`, nerfstudio / instant-ngp for `transforms.json`, COLMAP for a sparse model).
//!
//! Poses arrive in the dataset's world frame (the one its cameras were loaded into) and are
//! mapped back to the file's own frame by [`Dataset::to_source_world`] (DTU's `scale_mat`, LLFF's
//! undone normalisation). Intrinsics are never rewritten: the stored ones stay, whatever
//! resolution the views were loaded at.
//!
//! Outputs, in the output folder (the original name with `_refined`):
//!
//! | input | written |
//! |---|---|
//! | LLFF | `poses_bounds_refined.npy` |
//! | IDR / NeuS DTU | `<camera file>_refined.npz` (e.g. `cameras_sphere_refined.npz`) |
//! | NeRF-synthetic | `transforms_train_refined.json` (and `transforms_test_refined.json` when test views are given) |
//! | nerfstudio | `transforms_refined.json` |
//! | COLMAP | `sparse_refined/` with `cameras`, `images`, `points3D` in the model's own encoding |

mod colmap;
mod dtu;
mod llff;
mod replacement;
#[cfg(test)]
mod round_trip_tests;
mod transforms;

use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Matrix4};

use crate::camera::Se3;
use crate::dataset::Dataset;
use crate::error::{Result, SceneError};
use crate::load::DatasetFormat;

pub use self::replacement::PoseSource;
use self::replacement::Replacement;

/// Writes the camera file of `source` into `out_dir` with the views `poses` (indices into
/// `dataset.views`, world-to-camera poses in the dataset's frame) replaced; returns the files
/// written. `dataset` must be what `source` loads to (its views' [`crate::View::source_index`]
/// say which entries to replace). Every file is written atomically.
pub fn write_refined_poses(
    source: PoseSource,
    dataset: &Dataset,
    poses: &[(usize, Se3)],
    out_dir: &Path,
) -> Result<Vec<PathBuf>> {
    let in_source = poses
        .iter()
        .map(|(view, pose)| {
            if *view >= dataset.views.len() {
                return Err(SceneError::invalid(
                    source.root,
                    format!("view {view} does not exist ({} views)", dataset.views.len()),
                ));
            }
            let pose = pose_in_source_world(pose, dataset.to_source_world.as_ref())
                .map_err(|m| SceneError::invalid(source.root, m))?;
            Ok(Replacement {
                view: *view,
                entry: dataset.views[*view].source_index,
                world_to_camera: pose,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    std::fs::create_dir_all(out_dir).map_err(|e| SceneError::io(out_dir, e))?;
    match source.options.format_of(source.root)? {
        DatasetFormat::Llff => llff::write(source.root, &in_source, out_dir).map(|p| vec![p]),
        DatasetFormat::DtuIdr => dtu::write(source, &in_source, out_dir).map(|p| vec![p]),
        DatasetFormat::Blender => {
            transforms::write_blender(source.root, dataset, &in_source, out_dir)
        }
        DatasetFormat::Nerfstudio => {
            transforms::write_one(&source.root.join("transforms.json"), &in_source, out_dir)
                .map(|p| vec![p])
        }
        DatasetFormat::Colmap => colmap::write(source.root, &in_source, out_dir),
    }
}

/// A world-to-camera pose of the dataset's frame in the source's frame, where
/// `x_source = M · x` for a similarity `M` (scale times rotation, plus translation): the camera
/// centre maps by `M`, its axes rotate by `M`'s rotation.
fn pose_in_source_world(
    world_to_camera: &Se3,
    to_source: Option<&Matrix4<f64>>,
) -> std::result::Result<Se3, String> {
    let Some(m) = to_source else {
        return Ok(*world_to_camera);
    };
    let linear: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    let det = linear.determinant();
    let bottom_ok = (m[(3, 0)], m[(3, 1)], m[(3, 2)], m[(3, 3)]) == (0.0, 0.0, 0.0, 1.0);
    if !(det > 0.0 && det.is_finite() && bottom_ok) {
        return Err(format!(
            "the map to the source frame is not a similarity (det {det:.3e})"
        ));
    }
    let rotation = linear / det.cbrt();
    let off = (rotation.transpose() * rotation - Matrix3::identity())
        .abs()
        .max();
    if off > 1e-6 {
        return Err(format!(
            "the map to the source frame is not a similarity (|RᵀR − I| = {off:.1e} after removing the scale)"
        ));
    }
    let camera_to_world = world_to_camera.inverse();
    let center = m
        .transform_point(&camera_to_world.translation.into())
        .coords;
    Ok(Se3::new(rotation * camera_to_world.rotation, center).inverse())
}

#[cfg(test)]
mod tests {
    use super::replacement::refined_name;
    use super::*;
    use nalgebra::{Rotation3, Vector3};

    #[test]
    fn a_similarity_moves_the_centre_and_turns_the_axes() {
        // M: scale 2, rotation 90° about z, translation (1, 2, 3).
        let r = Rotation3::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2);
        let mut m = Matrix4::identity();
        m.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(r.matrix() * 2.0));
        m[(0, 3)] = 1.0;
        m[(1, 3)] = 2.0;
        m[(2, 3)] = 3.0;
        let c2w = Se3::new(
            Rotation3::from_euler_angles(0.1, -0.4, 0.7).into_inner(),
            Vector3::new(0.5, -1.0, 2.0),
        );
        let out = pose_in_source_world(&c2w.inverse(), Some(&m))
            .unwrap()
            .inverse();
        // Centre: 2 · Rz(90°) · (0.5, −1, 2) + (1, 2, 3) = 2 · (1, 0.5, 2) + (1, 2, 3).
        assert!((out.translation - Vector3::new(3.0, 3.0, 7.0)).norm() < 1e-12);
        assert!((out.rotation - r.matrix() * c2w.rotation).abs().max() < 1e-12);
        // A point seen by the camera keeps its camera coordinates up to the scale.
        let p = Vector3::new(0.2, 0.3, -0.1);
        let in_camera = c2w.inverse().transform_point(&p);
        let p_source = m.transform_point(&p.into()).coords;
        let in_camera_source = out.inverse().transform_point(&p_source);
        assert!((in_camera_source - 2.0 * in_camera).norm() < 1e-12);
        // Not a similarity: refused.
        let mut shear = m;
        shear[(0, 1)] += 0.5;
        assert!(pose_in_source_world(&c2w, Some(&shear)).is_err());
    }

    #[test]
    fn refined_names_keep_the_extension() {
        let out = Path::new("/o");
        assert_eq!(
            refined_name(Path::new("/d/cameras_sphere.npz"), out),
            Path::new("/o/cameras_sphere_refined.npz")
        );
        assert_eq!(
            refined_name(Path::new("/d/transforms.json"), out),
            Path::new("/o/transforms_refined.json")
        );
    }
}
