//! Loading a photo through its lens: undistorted on first use, then read back from a cache.
//!
//! The cache lives in the dataset folder, `<dataset>/.fewview-cache/undistorted/` (or the
//! folder [`crate::LoadOptions::cache_dir`] names), one 16-bit PNG per photo, named after the
//! photo and a 64-bit FNV-1a hash of everything the result depends on: the photo's path, size
//! in bytes and modification time, the lens, the framing, the resampling kernel and the output
//! camera. A changed
//! photo or camera therefore misses and is undistorted again; stale entries are never read.
//! A dataset folder that cannot be written is not an error: the photo is undistorted in memory
//! and the load report says the cache could not be written.

use std::io::Cursor;
use std::path::{Path, PathBuf};

use super::lens::{Distortion, LensCamera};
use super::remap::{Resample, UndistortFit, undistort_image, undistorted_intrinsics, valid_mask};
use crate::camera::Intrinsics;
use crate::error::{Result, SceneError};
use crate::image::Image;

/// The cache folder inside a dataset folder.
pub const CACHE_SUBDIR: &str = ".fewview-cache/undistorted";

/// What the cache did for one photo.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum CacheOutcome {
    /// The lens has no distortion (or distortion is ignored): nothing to undistort.
    Pinhole,
    /// The undistorted photo was read from the cache.
    Hit,
    /// The photo was undistorted and the result written to the cache.
    Written,
    /// The photo was undistorted but the cache could not be written (the reason).
    Unwritable(String),
}

/// A photo resampled to its undistorted pinhole camera.
#[derive(Clone, Debug)]
pub struct UndistortedPhoto {
    /// All the photo's channels (alpha too), not yet composited.
    pub image: Image,
    /// The pinhole camera of `image`.
    pub intrinsics: Intrinsics,
    /// Output pixels the photo covers (1) or not (0); `None` when it covers them all.
    pub valid: Option<Image>,
    pub outcome: CacheOutcome,
}

/// 64-bit FNV-1a, stable across builds and platforms (the standard hasher is not).
struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
    fn bytes(&mut self, b: &[u8]) {
        for &x in b {
            self.0 ^= x as u64;
            self.0 = self.0.wrapping_mul(0x0100_0000_01b3);
        }
    }
    fn f64s(&mut self, v: &[f64]) {
        for x in v {
            self.bytes(&x.to_le_bytes());
        }
    }
}

/// How a photo is undistorted: the framing of the output camera and the resampling kernel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct UndistortHow {
    pub fit: UndistortFit,
    pub resample: Resample,
}

/// The cache file name of `photo` undistorted from `lens` to `out` as `how` says.
fn cache_key(
    photo: &Path,
    lens: &LensCamera,
    how: UndistortHow,
    out: &Intrinsics,
) -> Result<String> {
    let meta = std::fs::metadata(photo).map_err(|e| SceneError::io(photo, e))?;
    let mtime = meta
        .modified()
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_nanos());
    let mut h = Fnv::new();
    h.bytes(b"fewview-undistort-v1");
    let canonical = photo.canonicalize().unwrap_or_else(|_| photo.to_owned());
    h.bytes(canonical.to_string_lossy().as_bytes());
    h.bytes(&meta.len().to_le_bytes());
    h.bytes(&mtime.to_le_bytes());
    for k in [&lens.intrinsics, out] {
        h.f64s(&[k.fx, k.fy, k.cx, k.cy, k.width as f64, k.height as f64]);
    }
    match &lens.distortion {
        Some(Distortion::Fisheye { .. }) => h.bytes(b"fisheye"),
        Some(Distortion::RadialTangential { .. }) => h.bytes(b"radtan"),
        None => h.bytes(b"pinhole"),
    }
    if let Some(d) = &lens.distortion {
        h.f64s(&d.coefficients());
    }
    h.bytes(&[how.fit as u8]);
    h.bytes(how.resample.name().as_bytes());
    let stem = photo
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    Ok(format!("{stem}-{:016x}.png", h.0))
}

/// The image with every value rounded as [`encode_png16`] stores it, so that the run that
/// writes a cache entry trains on exactly what later runs read back from it (the same seed then
/// gives the same result whether the cache was warm or not).
fn quantize16(mut img: Image) -> Image {
    for v in &mut img.data {
        *v = (v.clamp(0.0, 1.0) * 65535.0).round() as u16 as f32 / 65535.0;
    }
    img
}

/// Encodes an image (1, 3 or 4 channels) as a 16-bit PNG.
fn encode_png16(img: &Image) -> std::io::Result<Vec<u8>> {
    let (w, h) = (img.width as u32, img.height as u32);
    let px: Vec<u16> = img
        .data
        .iter()
        .map(|v| (v.clamp(0.0, 1.0) * 65535.0).round() as u16)
        .collect();
    let bad = || std::io::Error::other("image buffer size");
    let dynamic = match img.channels {
        1 => image::DynamicImage::ImageLuma16(
            image::ImageBuffer::from_raw(w, h, px).ok_or_else(bad)?,
        ),
        3 => {
            image::DynamicImage::ImageRgb16(image::ImageBuffer::from_raw(w, h, px).ok_or_else(bad)?)
        }
        4 => image::DynamicImage::ImageRgba16(
            image::ImageBuffer::from_raw(w, h, px).ok_or_else(bad)?,
        ),
        c => return Err(std::io::Error::other(format!("{c} channels"))),
    };
    let mut out = Cursor::new(Vec::new());
    dynamic
        .write_to(&mut out, image::ImageFormat::Png)
        .map_err(std::io::Error::other)?;
    Ok(out.into_inner())
}

/// Reads a cached entry if it exists and has the expected shape.
fn read_cached(path: &Path, out: &Intrinsics, channels: Option<usize>) -> Option<Image> {
    if !path.is_file() {
        return None;
    }
    let img = Image::load(path).ok()?;
    let shape_ok = img.width == out.width as usize
        && img.height == out.height as usize
        && channels.is_none_or(|c| c == img.channels);
    shape_ok.then_some(img)
}

/// The photo at `path`, taken through `lens`, as an ideal pinhole image framed and resampled as
/// `how` says, read from `cache_dir` when an entry for exactly this photo, camera and kernel is
/// there, else undistorted and written there. `lens` must hold the photo's full-resolution size; a lens that does not
/// invert inside the image is an error naming `source` (the camera file).
pub fn load_undistorted(
    path: &Path,
    lens: &LensCamera,
    how: UndistortHow,
    cache_dir: &Path,
    source: &Path,
    what: &str,
) -> Result<UndistortedPhoto> {
    if lens.distortion.is_none() {
        return Ok(UndistortedPhoto {
            image: Image::load(path)?,
            intrinsics: lens.intrinsics,
            valid: None,
            outcome: CacheOutcome::Pinhole,
        });
    }
    lens.check_invertible()
        .map_err(|m| SceneError::invalid(source, format!("{what}: {m}")))?;
    let out = undistorted_intrinsics(lens, how.fit).ok_or_else(|| {
        SceneError::invalid(
            source,
            format!("{what}: the lens distortion does not invert at the image border"),
        )
    })?;
    let valid = valid_mask(lens, &out);
    let entry = cache_dir.join(cache_key(path, lens, how, &out)?);
    if let Some(image) = read_cached(&entry, &out, None) {
        return Ok(UndistortedPhoto {
            image,
            intrinsics: out,
            valid,
            outcome: CacheOutcome::Hit,
        });
    }
    let photo = Image::load(path)?;
    if photo.width != lens.intrinsics.width as usize
        || photo.height != lens.intrinsics.height as usize
    {
        return Err(SceneError::invalid(
            path,
            format!(
                "image is {}×{} but its camera is {}×{}",
                photo.width, photo.height, lens.intrinsics.width, lens.intrinsics.height
            ),
        ));
    }
    let image = quantize16(undistort_image(&photo, lens, &out, how.resample));
    let written = std::fs::create_dir_all(cache_dir)
        .map_err(|e| SceneError::io(cache_dir, e))
        .and_then(|()| {
            let bytes = encode_png16(&image).map_err(|e| SceneError::io(&entry, e))?;
            crate::atomic::write_bytes(&entry, &bytes)
        });
    let outcome = match written {
        Ok(()) => CacheOutcome::Written,
        Err(e) => CacheOutcome::Unwritable(e.to_string()),
    };
    Ok(UndistortedPhoto {
        image,
        intrinsics: out,
        valid,
        outcome,
    })
}

/// The cache folder of a dataset: `opts_dir` when given, else [`CACHE_SUBDIR`] in `root`.
pub fn cache_dir(root: &Path, opts_dir: Option<&Path>) -> PathBuf {
    opts_dir.map_or_else(|| root.join(CACHE_SUBDIR), Path::to_owned)
}
