//! The pieces every format loader shares: listing, reading and checking a view's image and
//! mask files, downscaling them with their camera, and choosing the train/test split, so that
//! the formats differ only where their files do. A leaf module, so that the loaders and the
//! entry point that dispatches to them (`load`) do not import each other.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::camera::{Camera, Intrinsics};
use crate::distortion::LensCamera;
use crate::distortion::cache::{self, CacheOutcome};
use crate::error::{Result, SceneError};
use crate::image::Image;
use crate::load_options::LoadOptions;
use crate::split;

/// The largest magnitude a loaded camera centre, focal length, principal point or depth bound
/// may have. Training and rendering compute in single precision, where a squared distance
/// overflows near 1.8·10¹⁹; 10¹² leaves that margin and lies far beyond any capture's
/// coordinates (geocentric ones are about 6.4·10⁶ m).
pub const MAX_CAMERA_MAGNITUDE: f64 = 1e12;

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

/// The file stem (lossy UTF-8; empty when there is none), for [`crate::View::name`].
pub fn stem(path: &Path) -> String {
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
    split_photo(Image::load(path)?, background, path)
}

/// A decoded photo (1, 3 or 4 channels) as RGB and alpha, as [`load_photo`]; `path` names it
/// in errors.
pub(crate) fn split_photo(img: Image, background: [f32; 3], path: &Path) -> Result<Photo> {
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

/// A photo taken through `lens`, loaded as RGB + alpha for its undistorted pinhole camera
/// (or as it is, when `opts` ignores distortion), with its validity mask; the cache's outcome
/// goes into `report`. `source` (the camera file) and `what` (the view) name errors.
pub(crate) struct LensPhoto {
    pub photo: Photo,
    pub intrinsics: Intrinsics,
    pub valid: Option<Image>,
    pub outcome: CacheOutcome,
}

pub(crate) fn load_lens_photo(
    path: &Path,
    lens: &LensCamera,
    opts: &LoadOptions,
    root: &Path,
    background: [f32; 3],
    (source, what): (&Path, &str),
) -> Result<LensPhoto> {
    // Ignoring distortion is loading through a pinhole, whose framing does not matter.
    let (lens, fit) = match opts.undistort.fit() {
        Some(fit) => (*lens, fit),
        None => (LensCamera::new(lens.intrinsics, None), Default::default()),
    };
    let how = cache::UndistortHow {
        fit,
        resample: opts.resample,
    };
    let dir = cache::cache_dir(root, opts.cache_dir.as_deref());
    let u = cache::load_undistorted(path, &lens, how, &dir, source, what)?;
    Ok(LensPhoto {
        photo: split_photo(u.image, background, path)?,
        intrinsics: u.intrinsics,
        valid: u.valid,
        outcome: u.outcome,
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
