//! The one entry point for datasets: [`load_dataset`] detects the format of a folder and hands it
//! to the format's loader; [`LoadOptions`] holds what the user can choose (resolution, split,
//! background, camera file).
//!
//! Every loader converts to the crate's convention (OpenCV axes, world-to-camera, pinhole
//! intrinsics in pixels, pixel centres at half-integers) and shares the helpers below for
//! images, masks, downscaling and split selection, so the formats differ only where their files
//! do.

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::camera::{Camera, Intrinsics};
use crate::dataset::Dataset;
use crate::error::{Result, SceneError};
use crate::image::Image;
use crate::split;

/// The dataset layouts [`load_dataset`] reads.
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
    /// `images_{llff_factor}` images). Box filter ([`Image::downscale`]); intrinsics divide by
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
        }
    }
}

impl LoadOptions {
    fn validate(&self, root: &Path) -> Result<()> {
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
    if !path.is_dir() {
        let e = std::io::Error::new(std::io::ErrorKind::NotFound, "no such dataset folder");
        return Err(SceneError::io(path, e));
    }
    opts.validate(path)?;
    let dataset = match opts.format_of(path)? {
        DatasetFormat::Llff => crate::llff::load(path, opts),
        DatasetFormat::Blender => crate::transforms::load_blender(path, opts),
        DatasetFormat::Nerfstudio => crate::transforms::load_nerfstudio(path, opts),
        DatasetFormat::DtuIdr => crate::dtu::load(path, opts),
        DatasetFormat::Colmap => crate::colmap::load(path, opts),
    }?;
    check_camera_magnitudes(path, &dataset)?;
    Ok(dataset)
}

/// The largest magnitude a loaded camera centre, focal length, principal point or depth bound
/// may have. Training and rendering compute in single precision, where a squared distance
/// overflows near 1.8·10¹⁹; 10¹² leaves that margin and lies far beyond any capture's
/// coordinates (geocentric ones are about 6.4·10⁶ m).
pub const MAX_CAMERA_MAGNITUDE: f64 = 1e12;

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

/// The folder name, for [`Dataset::name`].
pub(crate) fn scene_name(root: &Path) -> String {
    root.canonicalize()
        .ok()
        .as_deref()
        .unwrap_or(root)
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene".to_owned())
}

/// The image files (PNG/JPEG, any case) of a folder, sorted by name.
pub(crate) fn list_images(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir).map_err(|e| SceneError::io(dir, e))?;
    let mut out = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| SceneError::io(dir, e))?;
        let p = entry.path();
        let ext = p
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        if p.is_file() && matches!(ext.as_str(), "png" | "jpg" | "jpeg") {
            out.push(p);
        }
    }
    out.sort();
    if out.is_empty() {
        return Err(SceneError::format(
            dir,
            "no PNG or JPEG images in this folder",
        ));
    }
    Ok(out)
}

/// The views of a parallel load in order, or the error of the first view (in file order) that
/// failed. Rayon's own `collect::<Result<_>>` returns whichever error a thread meets first, so
/// a folder with several bad files would name a different one from run to run.
pub(crate) fn first_error_in_order<T: Send>(
    loads: impl IndexedParallelIterator<Item = Result<T>>,
) -> Result<Vec<T>> {
    let results: Vec<Result<T>> = loads.collect();
    results.into_iter().collect()
}

/// The file stem, for [`crate::View::name`].
pub(crate) fn stem(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// An RGB image and, for RGBA files, its alpha: the colour composited over `background`.
pub(crate) struct Photo {
    pub rgb: Image,
    pub alpha: Option<Image>,
}

/// Loads a photo as RGB (grey is replicated; RGBA is composited over `background`, the alpha
/// returned separately).
pub(crate) fn load_photo(path: &Path, background: [f32; 3]) -> Result<Photo> {
    let img = Image::load(path)?;
    Ok(match img.channels {
        1 => Photo {
            rgb: Image::from_vec(
                img.width,
                img.height,
                3,
                img.data.iter().flat_map(|&v| [v, v, v]).collect(),
            ),
            alpha: None,
        },
        3 => Photo {
            rgb: img,
            alpha: None,
        },
        4 => Photo {
            alpha: Some(img.channel(3)),
            rgb: img.composite_over(background),
        },
        c => {
            return Err(SceneError::format(
                path,
                format!("unsupported image with {c} channels"),
            ));
        }
    })
}

/// Loads a binary mask: the first channel thresholded at one half (IDR's `alpha > 127.5`), as a
/// 1-channel image of 0 and 1.
pub(crate) fn load_binary_mask(path: &Path) -> Result<Image> {
    let img = Image::load(path)?;
    Ok(binarize(&img.channel(0)))
}

/// 1 where the value is at least one half, else 0.
pub(crate) fn binarize(img: &Image) -> Image {
    let data = img
        .data
        .iter()
        .map(|&v| if v >= 0.5 { 1.0 } else { 0.0 })
        .collect();
    Image::from_vec(img.width, img.height, img.channels, data)
}

/// The camera of an image downscaled by `k` with [`Image::downscale`]: output pixel `i` covers
/// input pixels `[k·i, k·i + k)`, so `fx, fy, cx, cy` divide by exactly `k` even when trailing
/// rows/columns are cropped (where [`Camera::resized`] would scale by the cropped ratio; both
/// agree when `k` divides the size).
pub(crate) fn downscale_camera(camera: &Camera, k: u32) -> Camera {
    if k <= 1 {
        return camera.clone();
    }
    let kf = k as f64;
    let i = &camera.intrinsics;
    let intrinsics = Intrinsics {
        fx: i.fx / kf,
        fy: i.fy / kf,
        cx: i.cx / kf,
        cy: i.cy / kf,
        width: i.width / k,
        height: i.height / k,
    };
    Camera::new(intrinsics, camera.world_to_camera)
}

/// Downscales an image by `k`, refusing sizes that would vanish.
pub(crate) fn downscale_image(img: &Image, k: u32, path: &Path) -> Result<Image> {
    if k <= 1 {
        return Ok(img.clone());
    }
    if img.width < k as usize || img.height < k as usize {
        return Err(SceneError::invalid(
            path,
            format!(
                "image is {}×{}, too small to downscale by {k}",
                img.width, img.height
            ),
        ));
    }
    Ok(img.downscale(k as usize))
}

/// Downscales a mask: binary masks are re-thresholded at one half (a pixel stays foreground
/// when at least half its block was, as the DTU masks were made), soft masks (alpha) averaged.
pub(crate) fn downscale_mask(mask: &Image, k: u32, binary: bool, path: &Path) -> Result<Image> {
    let m = downscale_image(mask, k, path)?;
    Ok(if binary && k > 1 { binarize(&m) } else { m })
}

/// Checks that an image has the size its camera was made for.
pub(crate) fn check_size(img: &Image, camera: &Camera, path: &Path, what: &str) -> Result<()> {
    if img.width != camera.width() as usize || img.height != camera.height() as usize {
        return Err(SceneError::invalid(
            path,
            format!(
                "{what} is {}×{} but its camera is {}×{}",
                img.width,
                img.height,
                camera.width(),
                camera.height()
            ),
        ));
    }
    Ok(())
}

/// Checks a camera for NaN/Inf and non-positive focal lengths.
pub(crate) fn check_camera(camera: &Camera, source: &Path, what: &str) -> Result<()> {
    if !camera.world_to_camera.is_finite() {
        return Err(SceneError::invalid(
            source,
            format!("{what}: pose contains NaN or Inf"),
        ));
    }
    if !camera.intrinsics.is_finite() {
        let i = &camera.intrinsics;
        return Err(SceneError::invalid(
            source,
            format!(
                "{what}: intrinsics are not finite positive (fx={}, fy={}, cx={}, cy={})",
                i.fx, i.fy, i.cx, i.cy
            ),
        ));
    }
    Ok(())
}

/// The train/test split: user-given views win; otherwise `default_train` builds the format's
/// standard training views from `n_train` (called only when no training views are given) and
/// `default_test` its test views. Both sides are validated against `n_views`.
pub(crate) fn choose_split(
    opts: &LoadOptions,
    n_views: usize,
    source: &Path,
    default_train: impl FnOnce(Option<usize>) -> Result<Vec<usize>>,
    default_test: impl FnOnce() -> Vec<usize>,
) -> Result<(Vec<usize>, Vec<usize>)> {
    let train = match &opts.train_views {
        Some(v) => v.clone(),
        None => default_train(opts.n_train)?,
    };
    let test = match &opts.test_views {
        Some(v) => v.clone(),
        None => default_test(),
    };
    split::validate_split(&train, n_views, "train", source)?;
    split::validate_split(&test, n_views, "test", source)?;
    Ok((train, test))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Se3;

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
