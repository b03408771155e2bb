//! Photos as `fewview poses` reads them: JPEG or PNG files of a folder, turned upright by their
//! EXIF orientation, with a starting focal length from their EXIF data where it has one.

use std::path::{Path, PathBuf};

use fewview_scene::{Image, Intrinsics};
use serde::Serialize;

use crate::error::{Result, SfmError};

/// Horizontal field of view assumed for a photo without a usable EXIF focal length: a phone's
/// main camera is 65–75°, a normal lens 40–50°; 50° is COLMAP's default guess (its focal of
/// 1.2 × the longer side) within a few degrees.
pub const DEFAULT_FOV_DEG: f64 = 50.0;

/// Where a photo's starting focal length came from.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum FocalSource {
    /// EXIF `FocalLengthIn35mmFilm`: the focal of a 36 × 24 mm frame with the same angle of
    /// view across the diagonal.
    Exif35mm,
    /// No usable EXIF focal: [`DEFAULT_FOV_DEG`] (or the caller's) across the width.
    AssumedFov,
}

/// One photo, at the resolution it is matched at.
#[derive(Clone, Debug)]
pub struct Photo {
    /// The file name (`IMG_0001.JPG`).
    pub name: String,
    /// Upright, scaled so that its longer side is at most the working size.
    pub image: Image,
    /// Of `image`.
    pub intrinsics: Intrinsics,
    /// Width and height of the file (upright), which the written model describes.
    pub full_size: (usize, usize),
    pub focal_from: FocalSource,
}

/// The photo files of `dir` (`.jpg`, `.jpeg`, `.png`, any case), sorted by name.
pub fn photo_files(dir: &Path) -> Result<Vec<PathBuf>> {
    Ok(files_of(dir)?.into_iter().filter(|p| is_photo(p)).collect())
}

/// The other files of `dir` (not hidden, not photos by their extension), sorted by name: what
/// the poses step leaves out, for a warning.
pub fn other_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let hidden = |p: &Path| {
        p.file_name()
            .is_some_and(|n| n.to_string_lossy().starts_with('.'))
    };
    Ok(files_of(dir)?
        .into_iter()
        .filter(|p| !is_photo(p) && !hidden(p))
        .collect())
}

/// The regular files of `dir`, sorted by name.
fn files_of(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir).map_err(|e| SfmError::io(dir, e))?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    Ok(files)
}

fn is_photo(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "jpg" | "jpeg" | "png"))
}

/// Every photo of `dir` ([`photo_files`]) read by [`load_photo`]; a folder without photos, or a
/// photo that cannot be read, is an error naming it.
pub fn load_folder(dir: &Path, max_side: usize, fov_deg: f64) -> Result<Vec<Photo>> {
    let files = photo_files(dir)?;
    if files.is_empty() {
        return Err(SfmError::input(
            dir,
            "no .jpg, .jpeg or .png photos in this folder",
        ));
    }
    files
        .iter()
        .map(|f| load_photo(f, max_side, fov_deg))
        .collect()
}

/// Reads `path` upright, scaled to at most `max_side` pixels on its longer side, with its
/// focal length from EXIF or `fov_deg` across the width.
pub fn load_photo(path: &Path, max_side: usize, fov_deg: f64) -> Result<Photo> {
    let image = Image::load(path)?;
    let (w, h) = (image.width, image.height);
    let (f_full, focal_from) = match exif_focal_35mm(path) {
        Some(f35) => (focal_from_35mm(f35, w, h), FocalSource::Exif35mm),
        None => (
            0.5 * w as f64 / (0.5 * fov_deg.to_radians()).tan(),
            FocalSource::AssumedFov,
        ),
    };
    let scale = (max_side as f64 / w.max(h) as f64).min(1.0);
    let (sw, sh) = (
        ((w as f64 * scale).round() as usize).max(1),
        ((h as f64 * scale).round() as usize).max(1),
    );
    let image = if (sw, sh) == (w, h) {
        image
    } else {
        image.resize(sw, sh)
    };
    let (sx, sy) = (sw as f64 / w as f64, sh as f64 / h as f64);
    let intrinsics = Intrinsics {
        fx: f_full * sx,
        fy: f_full * sy,
        cx: 0.5 * sw as f64,
        cy: 0.5 * sh as f64,
        width: sw as u32,
        height: sh as u32,
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| SfmError::input(path, "not a file name"))?;
    Ok(Photo {
        name,
        image,
        intrinsics,
        full_size: (w, h),
        focal_from,
    })
}

/// The focal length in pixels of a `w × h` image whose 35 mm equivalent is `f35` mm: the same
/// angle of view across the diagonal as a 36 × 24 mm frame (diagonal 43.27 mm).
pub fn focal_from_35mm(f35: f64, w: usize, h: usize) -> f64 {
    let diagonal_px = (w as f64).hypot(h as f64);
    f35 * diagonal_px / 36f64.hypot(24.0)
}

/// Writes `image` as a JPEG photo (quality 95) with an EXIF `FocalLengthIn35mmFilm` of
/// `focal_35mm` millimetres (rounded, as the tag is a whole number) when given: a camera's
/// file as [`load_photo`] reads it, e.g. a rendered scene handed over as photos without poses.
/// Written atomically.
pub fn save_photo_jpeg(image: &Image, focal_35mm: Option<f64>, path: &Path) -> Result<()> {
    use image::ImageEncoder;
    let exif = match focal_35mm {
        Some(f) => {
            let field = exif::Field {
                tag: exif::Tag::FocalLengthIn35mmFilm,
                ifd_num: exif::In::PRIMARY,
                value: exif::Value::Short(vec![f.round().clamp(1.0, 65535.0) as u16]),
            };
            let mut writer = exif::experimental::Writer::new();
            writer.push_field(&field);
            let mut tiff = std::io::Cursor::new(Vec::new());
            writer
                .write(&mut tiff, false)
                .map_err(|e| SfmError::input(path, format!("cannot encode EXIF: {e}")))?;
            tiff.into_inner()
        }
        None => Vec::new(),
    };
    let color = match image.channels {
        1 => image::ExtendedColorType::L8,
        3 => image::ExtendedColorType::Rgb8,
        c => {
            return Err(SfmError::input(
                path,
                format!("a {c}-channel image is not a photo"),
            ));
        }
    };
    let bytes = image.to_u8();
    fewview_scene::atomic::write_with(path, |file| {
        let mut encoder = image::codecs::jpeg::JpegEncoder::new_with_quality(file, 95);
        encoder
            .set_exif_metadata(exif)
            .map_err(std::io::Error::other)?;
        encoder
            .write_image(&bytes, image.width as u32, image.height as u32, color)
            .map_err(std::io::Error::other)
    })?;
    Ok(())
}

/// The 35 mm equivalent focal length (mm) of a camera whose `w × h` image has focal length
/// `focal_px` pixels: the inverse of [`focal_from_35mm`].
pub fn focal_35mm(focal_px: f64, w: usize, h: usize) -> f64 {
    focal_px * 36f64.hypot(24.0) / (w as f64).hypot(h as f64)
}

/// EXIF `FocalLengthIn35mmFilm` of the file, when it has a positive one.
fn exif_focal_35mm(path: &Path) -> Option<f64> {
    let file = std::fs::File::open(path).ok()?;
    let mut reader = std::io::BufReader::new(file);
    let exif = exif::Reader::new().read_from_container(&mut reader).ok()?;
    let field = exif.get_field(exif::Tag::FocalLengthIn35mmFilm, exif::In::PRIMARY)?;
    let f = field.value.get_uint(0)? as f64;
    (f > 0.0).then_some(f)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 36 × 24 frame: the 35 mm focal in pixels is f35 / 36 × the width.
    #[test]
    fn a_3_by_2_photo_has_the_width_of_a_35mm_frame() {
        let f = focal_from_35mm(50.0, 3600, 2400);
        assert!((f - 5000.0).abs() < 1e-9, "{f}");
    }

    /// A PNG without EXIF gets the assumed field of view, and the scaled intrinsics keep it.
    #[test]
    fn photos_without_exif_take_the_assumed_field_of_view() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.png");
        Image::filled(400, 300, &[0.5, 0.5, 0.5])
            .save_png(&path)
            .unwrap();
        let photo = load_photo(&path, 200, 50.0).unwrap();
        assert_eq!((photo.image.width, photo.image.height), (200, 150));
        assert_eq!(photo.full_size, (400, 300));
        assert_eq!(photo.focal_from, FocalSource::AssumedFov);
        let fov = 2.0 * (0.5 * 200.0 / photo.intrinsics.fx).atan();
        assert!((fov.to_degrees() - 50.0).abs() < 1e-9);
    }

    /// A photo written with a 35 mm focal reads back with that focal (to the whole millimetre
    /// the tag holds) and its pixels within JPEG's loss.
    #[test]
    fn a_written_photo_reads_back_with_its_focal() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.jpg");
        let mut image = Image::new(120, 80, 3);
        for (i, v) in image.data.iter_mut().enumerate() {
            *v = ((i / 3) % 120) as f32 / 120.0;
        }
        let f35 = focal_35mm(100.0, 120, 80);
        save_photo_jpeg(&image, Some(f35), &path).unwrap();
        let photo = load_photo(&path, 200, 50.0).unwrap();
        assert_eq!(photo.focal_from, FocalSource::Exif35mm);
        let want = focal_from_35mm(f35.round(), 120, 80);
        assert!(
            (photo.intrinsics.fx - want).abs() < 1e-9,
            "{}",
            photo.intrinsics.fx
        );
        assert!((photo.intrinsics.fx - 100.0).abs() < 100.0 * 0.5 / f35);
        let worst = photo
            .image
            .data
            .iter()
            .zip(&image.data)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(worst < 0.05, "{worst}");
        // Without a focal: the assumed field of view.
        save_photo_jpeg(&image, None, &path).unwrap();
        assert_eq!(
            load_photo(&path, 200, 50.0).unwrap().focal_from,
            FocalSource::AssumedFov
        );
    }

    #[test]
    fn a_corrupt_file_is_an_error_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("broken.jpg");
        std::fs::write(&path, b"\xff\xd8\xff\xe0 not a jpeg").unwrap();
        let err = load_photo(&path, 200, 50.0).unwrap_err().to_string();
        assert!(err.contains("broken.jpg"), "{err}");
    }
}
