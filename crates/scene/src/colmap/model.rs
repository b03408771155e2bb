//! The records of a COLMAP model, as both encodings read them: cameras, images (with their
//! poses) and points, and where an images file holds each image's pose.

use std::collections::BTreeMap;
use std::path::Path;

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use crate::camera::Se3;
use crate::dataset::PointCloud;
use crate::distortion::{LensCamera, camera_from_colmap};
use crate::error::{Result, SceneError};
use crate::view_files;

/// COLMAP's camera models, with their numeric ids (binary files) and parameter counts.
pub const CAMERA_MODELS: [(&str, usize); 18] = [
    ("SIMPLE_PINHOLE", 3),
    ("PINHOLE", 4),
    ("SIMPLE_RADIAL", 4),
    ("RADIAL", 5),
    ("OPENCV", 8),
    ("OPENCV_FISHEYE", 8),
    ("FULL_OPENCV", 12),
    ("FOV", 5),
    ("SIMPLE_RADIAL_FISHEYE", 4),
    ("RADIAL_FISHEYE", 5),
    ("THIN_PRISM_FISHEYE", 12),
    ("RAD_TAN_THIN_PRISM_FISHEYE", 16),
    ("SIMPLE_DIVISION", 4),
    ("DIVISION", 5),
    ("SIMPLE_FISHEYE", 3),
    ("FISHEYE", 4),
    ("EUCM", 6),
    ("EQUIRECTANGULAR", 2),
];

/// The parameter count of a model name.
pub fn model_param_count(model: &str) -> Option<usize> {
    CAMERA_MODELS
        .iter()
        .find(|(m, _)| *m == model)
        .map(|&(_, n)| n)
}

/// One camera of `cameras.{txt,bin}`.
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapCamera {
    pub id: u32,
    pub model: String,
    pub width: u64,
    pub height: u64,
    pub params: Vec<f64>,
}

impl ColmapCamera {
    /// The camera with its lens ([`crate::distortion::camera_from_colmap`]), or why it cannot
    /// be read.
    pub fn lens(&self) -> std::result::Result<LensCamera, String> {
        match model_param_count(&self.model) {
            Some(n) if n == self.params.len() => {}
            Some(n) => {
                return Err(format!(
                    "{} needs {n} parameters, has {}",
                    self.model,
                    self.params.len()
                ));
            }
            None => return Err(format!("unknown camera model {}", self.model)),
        }
        let (width, height) = match (u32::try_from(self.width), u32::try_from(self.height)) {
            (Ok(w), Ok(h)) if w > 0 && h > 0 => (w, h),
            _ => {
                return Err(format!(
                    "image size {}×{} is invalid",
                    self.width, self.height
                ));
            }
        };
        camera_from_colmap(&self.model, &self.params, width, height)
    }
}

/// One registered image of `images.{txt,bin}` (its 2D points are skipped).
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapImage {
    pub id: u32,
    /// `cam_from_world` rotation as `(qw, qx, qy, qz)`.
    pub qvec: [f64; 4],
    /// `cam_from_world` translation.
    pub tvec: [f64; 3],
    pub camera_id: u32,
    pub name: String,
}

impl ColmapImage {
    /// The world-to-camera pose (quaternion normalised; zero or non-finite is an error).
    pub fn world_to_camera(&self) -> std::result::Result<Se3, String> {
        let [w, x, y, z] = self.qvec;
        let q = Quaternion::new(w, x, y, z);
        let n = q.norm();
        let finite = n.is_finite() && self.tvec.iter().all(|v| v.is_finite());
        if !finite || n < 1e-9 {
            return Err(format!(
                "image {} ({}): pose contains NaN, Inf or a zero quaternion",
                self.id, self.name
            ));
        }
        let r = UnitQuaternion::from_quaternion(q)
            .to_rotation_matrix()
            .into_inner();
        Ok(Se3::new(r, Vector3::from(self.tvec)))
    }
}

/// One point of `points3D.{txt,bin}` (its track is skipped).
#[derive(Clone, Debug, PartialEq)]
pub struct ColmapPoint {
    pub id: u64,
    pub xyz: [f64; 3],
    pub rgb: [u8; 3],
    pub error: f64,
}

impl ColmapPoint {
    /// Why the point cannot be used, if it cannot: a position that is NaN, infinite or beyond
    /// [`view_files::MAX_CAMERA_MAGNITUDE`] (training computes in single precision, where such a value
    /// overflows). The message names the point id; the readers add the file. Colours are bytes,
    /// so every stored colour is valid.
    pub fn problem(&self) -> Option<String> {
        const AXES: [&str; 3] = ["x", "y", "z"];
        AXES.iter().zip(&self.xyz).find_map(|(axis, &v)| {
            (!v.is_finite() || v.abs() > view_files::MAX_CAMERA_MAGNITUDE).then(|| {
                format!(
                    "point {}: coordinate {axis} = {v:.3e} is not a finite value within {:.0e}",
                    self.id,
                    view_files::MAX_CAMERA_MAGNITUDE
                )
            })
        })
    }
}

/// A sparse model.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ColmapModel {
    pub cameras: BTreeMap<u32, ColmapCamera>,
    pub images: Vec<ColmapImage>,
    pub points: Vec<ColmapPoint>,
}

impl ColmapModel {
    /// The points as a coloured cloud (`f32`, colours in `[0, 1]`).
    pub fn point_cloud(&self) -> PointCloud {
        PointCloud {
            positions: self
                .points
                .iter()
                .map(|p| p.xyz.map(|v| v as f32))
                .collect(),
            colors: self
                .points
                .iter()
                .map(|p| p.rgb.map(|c| c as f32 / 255.0))
                .collect(),
            ..PointCloud::default()
        }
    }
}

/// A pose to write into an images file: quaternion `(qw, qx, qy, qz)` and translation.
pub type PoseFields = ([f64; 4], [f64; 3]);

/// Where each image of `poses` stands in an images file (`found`: each image with its place,
/// a byte offset or a line), with its id and new pose. An id the file lacks is an error naming
/// `path`.
pub(super) fn locate_poses<'a, L: Copy>(
    found: Vec<(ColmapImage, L)>,
    poses: &'a BTreeMap<u32, PoseFields>,
    path: &Path,
) -> Result<Vec<(L, u32, &'a PoseFields)>> {
    let places: BTreeMap<u32, L> = found
        .into_iter()
        .map(|(image, place)| (image.id, place))
        .collect();
    poses
        .iter()
        .map(|(id, pose)| match places.get(id) {
            Some(&place) => Ok((place, *id, pose)),
            None => Err(SceneError::invalid(
                path,
                format!("no image with id {id} to give a refined pose"),
            )),
        })
        .collect()
}
