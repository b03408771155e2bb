//! A folder of photos in, a folder `fewview train --data` reads out: what `fewview poses` runs,
//! and what `train` and `fusion` run first when their `--data` folder holds only photos.

use std::path::Path;

use fewview_scene::load::detect_format;

use crate::error::Result;
use crate::export::{place_images, write_model};
use crate::photos::{DEFAULT_FOV_DEG, load_folder, photo_files};
use crate::poses::{PoseModel, PoseOptions, PoseProgress, estimate_poses_with};

/// Options of [`poses_for_folder`].
#[derive(Clone, Debug, PartialEq)]
pub struct FolderOptions {
    /// Photos are matched with their longer side scaled down to at most this many pixels.
    pub max_side: usize,
    /// Horizontal field of view (degrees) of photos without an EXIF focal length.
    pub fov_deg: f64,
    pub poses: PoseOptions,
}

impl Default for FolderOptions {
    fn default() -> Self {
        Self {
            max_side: 1024,
            fov_deg: DEFAULT_FOV_DEG,
            poses: PoseOptions::default(),
        }
    }
}

/// Estimates the poses of the photos in `images` and writes the model, with the registered
/// photos, into `out` ([`crate::export`]), reporting progress to `on_progress`. Nothing is
/// written when no model comes out.
pub fn poses_for_folder(
    images: &Path,
    out: &Path,
    options: &FolderOptions,
    on_progress: impl Fn(&PoseProgress) + Sync,
) -> Result<PoseModel> {
    let photos = load_folder(images, options.max_side, options.fov_deg)?;
    let model = estimate_poses_with(&photos, &options.poses, on_progress)?;
    // The photos first: the model's report, written last, marks a finished folder.
    place_images(&model, images, out)?;
    write_model(&model, out)?;
    Ok(model)
}

/// The long side (pixels) photos are trained at by default: about 1,000 px, the size at which
/// a few photos train in minutes on a CPU and which the sparse-view benchmarks use (LLFF at
/// 1008×756 and 504×378, DTU at 800×600 and 400×300).
pub const WORKING_LONG_SIDE: usize = 1000;

/// The integer factor that brings photos whose longer side is `long_side` pixels closest to
/// [`WORKING_LONG_SIDE`] (1 for photos of that size or smaller).
pub fn working_downscale(long_side: usize) -> u32 {
    ((long_side as f64 / WORKING_LONG_SIDE as f64).round() as u32).max(1)
}

/// The longest side (pixels) among the photos of `dir`, read from their headers.
pub fn longest_photo_side(dir: &Path) -> Result<usize> {
    let mut longest = 0;
    for file in photo_files(dir)? {
        let (w, h) = fewview_scene::Image::dimensions(&file)?;
        longest = longest.max(w.max(h));
    }
    Ok(longest)
}

/// Whether `dir` holds photos but no cameras in any format a dataset loader reads.
pub fn holds_only_photos(dir: &Path) -> bool {
    detect_format(dir).is_err() && photo_files(dir).is_ok_and(|f| !f.is_empty())
}

/// Whether `out` holds a model that [`poses_for_folder`] finished (its report is written last).
pub fn has_model(out: &Path) -> bool {
    out.join("sparse/0/images.txt").is_file() && out.join("poses_report.json").is_file()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn photos_are_brought_to_about_a_thousand_pixels() {
        for (side, k) in [
            (504, 1),
            (1024, 1),
            (1400, 1),
            (1920, 2),
            (3264, 3),
            (4032, 4),
        ] {
            assert_eq!(working_downscale(side), k, "{side}");
        }
    }
}
