//! The one entry point for datasets: [`load_dataset`] detects the format of a folder and hands it
//! to the format's loader; [`LoadOptions`] holds what the user can choose (resolution, split,
//! background, camera file).
//!
//! Every loader converts to the crate's convention (OpenCV axes, world-to-camera, pinhole
//! intrinsics in pixels, pixel centres at half-integers) and shares the helpers of
//! `view_files` for images, masks, downscaling and split selection, so the formats
//! differ only where their files do.

use std::path::Path;

use crate::dataset::Dataset;
use crate::error::{Result, SceneError};
pub use crate::load_options::{DatasetFormat, LoadOptions, UndistortMode};
pub use crate::load_report::LoadReport;
pub use crate::view_files::MAX_CAMERA_MAGNITUDE;

impl LoadOptions {
    /// The format these options read `path` as: the forced one, else the detected one.
    pub fn format_of(&self, path: &Path) -> Result<DatasetFormat> {
        match self.format {
            Some(f) => Ok(f),
            None => detect_format(path),
        }
    }
}

/// Loads the dataset in `path`, detecting its format from the folder contents (see
/// [`detect_format`]) unless `opts.format` forces one.
pub fn load_dataset(path: &Path, opts: &LoadOptions) -> Result<Dataset> {
    load_dataset_with_report(path, opts).map(|(d, _)| d)
}

/// [`load_dataset`], with what the load did besides: frames skipped, photos undistorted, how
/// the undistortion cache served them, and warnings to show the user.
pub fn load_dataset_with_report(path: &Path, opts: &LoadOptions) -> Result<(Dataset, LoadReport)> {
    let mut report = LoadReport::default();
    if !path.is_dir() {
        let e = std::io::Error::new(std::io::ErrorKind::NotFound, "no such dataset folder");
        return Err(SceneError::io(path, e));
    }
    opts.validate(path)?;
    let dataset = match opts.format_of(path)? {
        DatasetFormat::Llff => crate::llff::load(path, opts),
        DatasetFormat::Blender => crate::transforms::load_blender(path, opts, &mut report),
        DatasetFormat::Nerfstudio => crate::transforms::load_nerfstudio(path, opts, &mut report),
        DatasetFormat::DtuIdr => crate::dtu::load(path, opts),
        DatasetFormat::Colmap => crate::colmap::load(path, opts, &mut report),
    }?;
    check_camera_magnitudes(path, &dataset)?;
    Ok((dataset, report))
}
/// Refuses a dataset whose cameras, after the format's own normalisation, hold a value the
/// single-precision maths cannot use (e.g. a camera file with a 10³⁰⁰ that is finite but
/// corrupt), so that a run fails before it writes anything instead of diverging to NaN.
fn check_camera_magnitudes(path: &Path, dataset: &Dataset) -> Result<()> {
    for view in &dataset.views {
        let bounds = view.depth_bounds.map_or([0.0; 2], |(n, f)| [n, f]);
        let values = [("camera centre", view.camera.center().norm())]
            .into_iter()
            .chain(view.camera.intrinsics.named_values())
            .chain([
                ("near depth bound", bounds[0]),
                ("far depth bound", bounds[1]),
            ]);
        for (what, v) in values {
            if !v.is_finite() || v.abs() > MAX_CAMERA_MAGNITUDE {
                return Err(SceneError::invalid(
                    path,
                    format!(
                        "view {} (entry {} of the camera file): {what} {v:.3e} is not a finite value within {MAX_CAMERA_MAGNITUDE:.0e} after loading; is the camera file corrupt?",
                        view.name, view.source_index
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// The format of a dataset folder, from the files it holds, checked in this order:
/// `poses_bounds.npy` (LLFF), `transforms_train.json` (Blender), `transforms.json`
/// (nerfstudio), `cameras_sphere.npz` / `cameras.npz` (DTU), a COLMAP model (`sparse/0/`,
/// `sparse/` or the folder itself).
pub fn detect_format(path: &Path) -> Result<DatasetFormat> {
    let has = |name: &str| path.join(name).is_file();
    if has("poses_bounds.npy") {
        Ok(DatasetFormat::Llff)
    } else if has("transforms_train.json") {
        Ok(DatasetFormat::Blender)
    } else if has("transforms.json") {
        Ok(DatasetFormat::Nerfstudio)
    } else if has("cameras_sphere.npz") || has("cameras.npz") {
        Ok(DatasetFormat::DtuIdr)
    } else if crate::colmap::find_model_dir(path).is_some() {
        Ok(DatasetFormat::Colmap)
    } else {
        Err(SceneError::format(
            path,
            "no known dataset format: expected poses_bounds.npy (LLFF), transforms_train.json (Blender), transforms.json (nerfstudio), cameras_sphere.npz (DTU) or a COLMAP sparse model",
        ))
    }
}
#[cfg(test)]
mod tests {
    use rayon::prelude::*;

    use super::*;
    use crate::camera::{Camera, Intrinsics, Se3};
    use crate::view_files::*;

    #[test]
    fn a_parallel_load_reports_the_first_bad_file_in_order() {
        let names = ["a.png", "b.png", "c.png", "d.png"];
        for _ in 0..20 {
            let loads = names.par_iter().enumerate().map(|(i, n)| {
                if i == 0 {
                    Ok(i)
                } else {
                    Err(SceneError::invalid(*n, "bad"))
                }
            });
            let e = first_error_in_order(loads).unwrap_err().to_string();
            assert!(e.starts_with("b.png"), "{e}");
        }
        let all_good = (0..3usize).into_par_iter().map(Ok);
        assert_eq!(first_error_in_order(all_good).unwrap(), vec![0, 1, 2]);
    }

    #[test]
    fn format_names_parse() {
        for f in DatasetFormat::ALL {
            assert_eq!(f.name().parse::<DatasetFormat>().unwrap(), f);
        }
        assert_eq!(
            "IDR".parse::<DatasetFormat>().unwrap(),
            DatasetFormat::DtuIdr
        );
        assert!("ply".parse::<DatasetFormat>().is_err());
    }

    #[test]
    fn downscaled_camera_projects_to_the_downscaled_pixel() {
        // A 9×7 image downscaled by 2 keeps 4×3 blocks; the point seen at input (u, v) must be
        // seen at (u/2, v/2) whether or not the size divides.
        let cam = Camera::new(
            Intrinsics {
                fx: 10.0,
                fy: 11.0,
                cx: 4.3,
                cy: 3.6,
                width: 9,
                height: 7,
            },
            Se3::identity(),
        );
        let small = downscale_camera(&cam, 2);
        assert_eq!((small.width(), small.height()), (4, 3));
        let p = nalgebra::Vector3::new(0.1, -0.2, 2.0);
        let (u, v, _) = cam.project(&p).unwrap();
        let (us, vs, _) = small.project(&p).unwrap();
        assert!((us - u / 2.0).abs() < 1e-12 && (vs - v / 2.0).abs() < 1e-12);
        // Where the size divides, this is `Camera::resized`.
        let even = Camera::new(
            Intrinsics {
                width: 8,
                height: 6,
                ..cam.intrinsics
            },
            Se3::identity(),
        );
        assert_eq!(downscale_camera(&even, 2), even.resized(4, 3));
    }

    #[test]
    fn options_are_checked() {
        let dir = tempfile::tempdir().unwrap();
        let opts = LoadOptions {
            downscale: 0,
            ..Default::default()
        };
        let e = load_dataset(dir.path(), &opts).unwrap_err().to_string();
        assert!(e.contains("downscale"), "{e}");
        let opts = LoadOptions {
            n_train: Some(0),
            ..Default::default()
        };
        let e = load_dataset(dir.path(), &opts).unwrap_err().to_string();
        assert!(e.contains("train split is empty"), "{e}");
        let e = load_dataset(dir.path(), &LoadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("no known dataset format"), "{e}");
        let missing = dir.path().join("nope");
        let e = load_dataset(&missing, &LoadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("nope") && e.contains("no such dataset folder"),
            "{e}"
        );
    }
}
