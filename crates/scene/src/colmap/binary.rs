//! COLMAP's binary model format (`cameras.bin`, `images.bin`, `points3D.bin`), little-endian, as
//! COLMAP writes it:
//!
//! * cameras: `u64` count; per camera `u32` id, `i32` model id, `u64` width, `u64` height,
//!   `f64` × (the model's parameter count).
//! * images: `u64` count; per image `u32` id, `f64` qw qx qy qz, `f64` tx ty tz, `u32` camera id,
//!   NUL-terminated name, `u64` point count, then per point `f64` x, `f64` y, `i64` point id.
//! * points: `u64` count; per point `u64` id, `f64` x y z, `u8` r g b, `f64` error, `u64` track
//!   length, then per element `u32` image id, `u32` point index.
//!
//! Counts come from the file, so no buffer is sized by them: a corrupt count ends in a
//! "truncated" error instead of a huge allocation.

use std::collections::BTreeMap;
use std::path::Path;

use super::model::{
    CAMERA_MODELS, ColmapCamera, ColmapImage, ColmapPoint, PoseFields, locate_poses,
};
use crate::error::{Result, SceneError};

/// A bounds-checked little-endian reader over a whole file.
struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
    path: &'a Path,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        if self.bytes.len() - self.pos < n {
            return Err(SceneError::format(
                self.path,
                format!("truncated at byte {} while reading {what}", self.pos),
            ));
        }
        let s = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N]> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N, what)?);
        Ok(a)
    }

    fn u8(&mut self, what: &str) -> Result<u8> {
        Ok(self.array::<1>(what)?[0])
    }
    fn u32(&mut self, what: &str) -> Result<u32> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }
    fn i32(&mut self, what: &str) -> Result<i32> {
        Ok(i32::from_le_bytes(self.array(what)?))
    }
    fn u64(&mut self, what: &str) -> Result<u64> {
        Ok(u64::from_le_bytes(self.array(what)?))
    }
    fn f64(&mut self, what: &str) -> Result<f64> {
        Ok(f64::from_le_bytes(self.array(what)?))
    }

    /// Skips `count` records of `size` bytes.
    fn skip(&mut self, count: u64, size: usize, what: &str) -> Result<()> {
        let n = usize::try_from(count)
            .ok()
            .and_then(|c| c.checked_mul(size))
            .unwrap_or(usize::MAX);
        self.take(n, what).map(|_| ())
    }

    fn name(&mut self) -> Result<String> {
        let rest = &self.bytes[self.pos..];
        let end = rest.iter().position(|&b| b == 0).ok_or_else(|| {
            SceneError::format(
                self.path,
                format!("truncated at byte {} while reading an image name", self.pos),
            )
        })?;
        let name = std::str::from_utf8(&rest[..end])
            .map_err(|_| {
                SceneError::format(
                    self.path,
                    format!("image name at byte {} is not UTF-8", self.pos),
                )
            })?
            .to_owned();
        self.pos += end + 1;
        Ok(name)
    }

    /// The file must end exactly after the last record.
    fn finish(&self) -> Result<()> {
        let left = self.bytes.len() - self.pos;
        if left != 0 {
            return Err(SceneError::format(
                self.path,
                format!("corrupt file: {left} bytes left over after the last record"),
            ));
        }
        Ok(())
    }
}

fn read_file(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| SceneError::io(path, e))
}

pub fn read_cameras(path: &Path) -> Result<BTreeMap<u32, ColmapCamera>> {
    let bytes = read_file(path)?;
    let mut r = Reader {
        bytes: &bytes,
        pos: 0,
        path,
    };
    let count = r.u64("the camera count")?;
    let mut out = BTreeMap::new();
    for _ in 0..count {
        let id = r.u32("a camera id")?;
        let model_id = r.i32("a camera model")?;
        let (model, n_params) = usize::try_from(model_id)
            .ok()
            .and_then(|m| CAMERA_MODELS.get(m))
            .ok_or_else(|| {
                SceneError::format(
                    path,
                    format!("camera {id}: unknown camera model id {model_id}"),
                )
            })?;
        let width = r.u64("a camera width")?;
        let height = r.u64("a camera height")?;
        let params = (0..*n_params)
            .map(|_| r.f64("camera parameters"))
            .collect::<Result<Vec<_>>>()?;
        let cam = ColmapCamera {
            id,
            model: model.to_string(),
            width,
            height,
            params,
        };
        if out.insert(id, cam).is_some() {
            return Err(SceneError::format(
                path,
                format!("camera {id} defined twice"),
            ));
        }
    }
    r.finish()?;
    Ok(out)
}

pub fn read_images(path: &Path) -> Result<Vec<ColmapImage>> {
    let bytes = read_file(path)?;
    Ok(images_with_pose_offsets(&bytes, path)?
        .into_iter()
        .map(|(image, _)| image)
        .collect())
}

/// Parses `images.bin` held in memory: each image with the byte offset of its pose (the four
/// quaternion and three translation `f64`s that follow the image id).
fn images_with_pose_offsets(bytes: &[u8], path: &Path) -> Result<Vec<(ColmapImage, usize)>> {
    let mut r = Reader {
        bytes,
        pos: 0,
        path,
    };
    let count = r.u64("the image count")?;
    let mut out = Vec::new();
    for _ in 0..count {
        let id = r.u32("an image id")?;
        let pose_offset = r.pos;
        let mut qvec = [0.0; 4];
        for q in &mut qvec {
            *q = r.f64("a quaternion")?;
        }
        let mut tvec = [0.0; 3];
        for t in &mut tvec {
            *t = r.f64("a translation")?;
        }
        let camera_id = r.u32("a camera id")?;
        let name = r.name()?;
        let n_points = r.u64("a 2D point count")?;
        r.skip(n_points, 24, "2D points")?;
        let image = ColmapImage {
            id,
            qvec,
            tvec,
            camera_id,
            name,
        };
        out.push((image, pose_offset));
    }
    r.finish()?;
    Ok(out)
}

/// `images.bin` (read from `path`) with the poses of the images in `poses` (by id:
/// `cam_from_world` quaternion `(qw, qx, qy, qz)` and translation) replaced; every other byte,
/// the 2D points included, as stored. An id the file lacks is an error.
pub fn replace_image_poses(path: &Path, poses: &BTreeMap<u32, PoseFields>) -> Result<Vec<u8>> {
    let mut bytes = read_file(path)?;
    let offsets = images_with_pose_offsets(&bytes, path)?;
    for (offset, _, (qvec, tvec)) in locate_poses(offsets, poses, path)? {
        for (k, v) in qvec.iter().chain(tvec).enumerate() {
            bytes[offset + 8 * k..offset + 8 * k + 8].copy_from_slice(&v.to_le_bytes());
        }
    }
    Ok(bytes)
}

pub fn read_points(path: &Path) -> Result<Vec<ColmapPoint>> {
    let bytes = read_file(path)?;
    let mut r = Reader {
        bytes: &bytes,
        pos: 0,
        path,
    };
    let count = r.u64("the point count")?;
    let mut out = Vec::new();
    for _ in 0..count {
        let id = r.u64("a point id")?;
        let xyz = [
            r.f64("a position")?,
            r.f64("a position")?,
            r.f64("a position")?,
        ];
        let rgb = [r.u8("a colour")?, r.u8("a colour")?, r.u8("a colour")?];
        let error = r.f64("a reprojection error")?;
        let track = r.u64("a track length")?;
        r.skip(track, 8, "a track")?;
        let point = ColmapPoint {
            id,
            xyz,
            rgb,
            error,
        };
        if let Some(problem) = point.problem() {
            return Err(SceneError::invalid(path, problem));
        }
        out.push(point);
    }
    r.finish()?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `points3D.bin` with one point at `xyz` and an empty track.
    fn points_file(xyz: [f64; 3]) -> Vec<u8> {
        let mut b = Vec::new();
        b.extend(1u64.to_le_bytes());
        b.extend(7u64.to_le_bytes());
        for v in xyz {
            b.extend(v.to_le_bytes());
        }
        b.extend([10u8, 20, 30]);
        b.extend(0.5f64.to_le_bytes());
        b.extend(0u64.to_le_bytes());
        b
    }

    /// A NaN or 1e300 coordinate is refused when reading, naming the file and the point id.
    #[test]
    fn points_with_non_finite_or_huge_coordinates_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("points3D.bin");
        std::fs::write(&path, points_file([1.0, 2.0, 3.0])).unwrap();
        assert_eq!(read_points(&path).unwrap()[0].xyz, [1.0, 2.0, 3.0]);
        for (xyz, axis) in [([f64::NAN, 0.0, 0.0], "x"), ([0.0, 0.0, 1e300], "z")] {
            std::fs::write(&path, points_file(xyz)).unwrap();
            let err = read_points(&path).unwrap_err().to_string();
            assert!(err.contains("points3D.bin: point 7: coordinate"), "{err}");
            assert!(err.contains(&format!("{axis} = ")), "{err}");
            assert!(err.contains("not a finite value"), "{err}");
        }
    }
}
