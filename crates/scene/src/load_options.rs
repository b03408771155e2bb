//! What the user chooses when loading a dataset: [`LoadOptions`] and the [`DatasetFormat`]s
//! that [`crate::load::load_dataset`] reads. A leaf module: the format loaders take these
//! options without depending on the entry point that dispatches to them.

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::distortion::{Resample, UndistortFit};
use crate::error::{Result, SceneError};

/// What loading does with a camera's lens distortion.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum UndistortMode {
    /// Undistort into a pinhole with no blank border (COLMAP `image_undistorter`'s default).
    #[default]
    NoBorder,
    /// Undistort keeping every photo pixel; the blank border is masked out of losses and
    /// metrics.
    AllPixels,
    /// Ignore the distortion: the photos are used as if taken by the pinhole of the same
    /// intrinsics (a baseline, wrong for real lenses).
    Ignore,
}

impl UndistortMode {
    /// The framing of the undistorted image; `None` when distortion is ignored.
    pub fn fit(self) -> Option<UndistortFit> {
        match self {
            UndistortMode::NoBorder => Some(UndistortFit::NoBorder),
            UndistortMode::AllPixels => Some(UndistortFit::AllPixels),
            UndistortMode::Ignore => None,
        }
    }
}

impl FromStr for UndistortMode {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "no-border" => Ok(UndistortMode::NoBorder),
            "all-pixels" => Ok(UndistortMode::AllPixels),
            "ignore" => Ok(UndistortMode::Ignore),
            _ => Err(format!(
                "unknown undistortion mode {s:?}: expected no-border, all-pixels or ignore"
            )),
        }
    }
}

/// The dataset layouts [`crate::load_dataset`] reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DatasetFormat {
    /// LLFF forward-facing captures: `poses_bounds.npy` + `images_N/`.
    Llff,
    /// NeRF-synthetic ("Blender"): `transforms_train.json` + `transforms_test.json`.
    Blender,
    /// nerfstudio / instant-ngp: one `transforms.json`.
    Nerfstudio,
    /// IDR / NeuS DTU: `cameras_sphere.npz` (or `cameras.npz`) + `image/` + `mask/`.
    DtuIdr,
    /// A COLMAP sparse model (`sparse/0/`, text or binary) + `images/`.
    Colmap,
}

impl DatasetFormat {
    pub const ALL: [DatasetFormat; 5] = [
        DatasetFormat::Llff,
        DatasetFormat::Blender,
        DatasetFormat::Nerfstudio,
        DatasetFormat::DtuIdr,
        DatasetFormat::Colmap,
    ];

    pub fn name(self) -> &'static str {
        match self {
            DatasetFormat::Llff => "llff",
            DatasetFormat::Blender => "blender",
            DatasetFormat::Nerfstudio => "nerfstudio",
            DatasetFormat::DtuIdr => "dtu",
            DatasetFormat::Colmap => "colmap",
        }
    }
}

impl fmt::Display for DatasetFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for DatasetFormat {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let s = s.to_ascii_lowercase();
        Self::ALL
            .into_iter()
            .find(|f| f.name() == s || (s == "idr" && *f == DatasetFormat::DtuIdr))
            .ok_or_else(|| {
                format!("unknown dataset format {s:?}: expected llff, blender, nerfstudio, dtu or colmap")
            })
    }
}

/// What the user chooses when loading. `LoadOptions::default()` gives each format's standard
/// sparse-view protocol at the stored resolution.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct LoadOptions {
    /// Force a format instead of detecting it from the folder contents.
    pub format: Option<DatasetFormat>,
    /// Integer downscale of the images as stored (1 = as stored; for LLFF, of the
    /// `images_{llff_factor}` images). Box filter ([`crate::Image::downscale`]); intrinsics divide by
    /// exactly this factor.
    pub downscale: u32,
    /// Number of training views of the standard split; `None` = the format's default
    /// (LLFF 3, Blender 8, DTU 3, COLMAP and nerfstudio: every non-test view).
    pub n_train: Option<usize>,
    /// Explicit training views, overriding `n_train`. Indices into the view list (sorted file
    /// order; LLFF: rows of `poses_bounds.npy`; DTU: image index), for Blender into the frames of
    /// `transforms_train.json`.
    pub train_views: Option<Vec<usize>>,
    /// Explicit test views, same indexing (for Blender: frames of `transforms_test.json`).
    pub test_views: Option<Vec<usize>>,
    /// Colour RGBA images are composited over; `None` = white for `transforms` data (the NeRF
    /// protocol), black otherwise.
    pub background: Option<[f32; 3]>,
    /// DTU: the camera file inside the scene folder (`cameras_sphere.npz` when present, else
    /// `cameras.npz`; `cameras_linear_init.npz` gives the perturbed initial poses).
    pub cameras_file: Option<String>,
    /// LLFF: which `images_N` resolution the `poses_bounds.npy` focal length is divided for
    /// (8 is the sparse-view standard, 504×378 for fern). A missing folder is made from a larger
    /// one (`images_4`, `images_2`, `images`) by box-filter downscaling.
    pub llff_factor: u32,
    /// LLFF: apply NeRF's `load_llff_data` normalisation (scale so the smallest near bound is
    /// `1/0.75`, i.e. `bd_factor = 0.75`, then recenter on the average pose). On by default, as
    /// in NeRF, RegNeRF and SPARF; off keeps the poses and bounds as stored.
    pub llff_normalize: bool,
    /// LLFF / COLMAP / nerfstudio hold-out: every `holdout_every`-th view is a test view
    /// (NeRF's `llffhold = 8`).
    pub holdout_every: usize,
    /// COLMAP / nerfstudio: what to do with lens distortion (undistort on load by default).
    pub undistort: UndistortMode,
    /// COLMAP / nerfstudio: the kernel undistortion resamples photos with (bilinear by default,
    /// as COLMAP's `image_undistorter` and `cv2.undistort`; bicubic keeps finer detail).
    pub resample: Resample,
    /// Where undistorted photos are cached; `None` = `.fewview-cache/undistorted/` in the
    /// dataset folder ([`crate::distortion::cache`]).
    pub cache_dir: Option<PathBuf>,
}

impl Default for LoadOptions {
    fn default() -> Self {
        Self {
            format: None,
            downscale: 1,
            n_train: None,
            train_views: None,
            test_views: None,
            background: None,
            cameras_file: None,
            llff_factor: 8,
            llff_normalize: true,
            holdout_every: 8,
            undistort: UndistortMode::default(),
            resample: Resample::default(),
            cache_dir: None,
        }
    }
}

impl LoadOptions {
    pub(crate) fn validate(&self, root: &Path) -> Result<()> {
        if self.downscale == 0 {
            return Err(SceneError::invalid(
                root,
                "downscale factor must be at least 1",
            ));
        }
        if self.llff_factor == 0 {
            return Err(SceneError::invalid(
                root,
                "LLFF image factor must be at least 1",
            ));
        }
        if self.holdout_every == 0 {
            return Err(SceneError::invalid(
                root,
                "hold-out interval must be at least 1",
            ));
        }
        if self.n_train == Some(0) {
            return Err(SceneError::invalid(
                root,
                "the train split is empty (n_train = 0)",
            ));
        }
        if let Some(bg) = self.background
            && !bg.iter().all(|v| v.is_finite())
        {
            return Err(SceneError::invalid(root, "background colour is not finite"));
        }
        Ok(())
    }
}
