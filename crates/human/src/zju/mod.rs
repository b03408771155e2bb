//! The ZJU-MoCap layout, so the method runs on the real benchmark of "PoseGaussian:
//! Pose-Driven Novel View Synthesis for Robust 3D Human Reconstruction".
//!
//! A capture folder holds `annots.npy` (cameras and per-frame image lists, see [`annots`]), the
//! images `Camera_B*/NNNNNN.jpg` at the paths it lists, masks at the same relative paths with a
//! `.png` extension in `mask/` (or, when that folder is absent, `mask_cihp/`; any non-zero value
//! is foreground, as Neural Body reads them), and optionally SMPL parameters in `params/` (or
//! `new_params/`) and world joints in `joints3d/`, both `<n>.npy` where `n` is the integer in the
//! frame's image name (Neural Body's convention).
//!
//! **Conversion.** `T` is in millimetres and becomes metres; `K`, `R` are OpenCV's with pixel
//! centres at integers and are converted to fewview-scene's half-integer centres
//! ([`crate::opencv`]). Images and masks are undistorted with `D` into pinhole views with the
//! same `K` ([`undistort`]) on every access, so the cameras carry no distortion.
//!
//! **2D pose — a limitation.** PoseGaussian takes the 2D pose from SMPL joints projected into
//! each view. SMPL's forward kinematics needs the SMPL model files, which cannot be shipped or
//! fetched here, so `params/` is read ([`ZjuDataset::smpl_params`]) but not posed. Instead the
//! 2D joints are the projections of `joints3d/<n>.npy`, a `(J, 3)` float array of world joints in
//! metres (for instance the SMPL joints exported once with the model, where it is available).
//! Without that folder [`MultiView::joints2d`] and [`MultiView::joints3d`] are errors.

pub mod annots;
pub mod numpy;
pub mod pickle;
pub mod undistort;

use std::path::{Path, PathBuf};

use fewview_scene::distortion::Distortion;
use fewview_scene::{Camera, Image};
use nalgebra::{Matrix3, Vector3};

use crate::error::{HumanError, Result, missing};
use crate::maps::{self, DepthMap, Mask};
use crate::opencv::camera_from_opencv;
use crate::readlog::{ReadKind, ReadLog};
use crate::source::{MultiView, check_index, check_joints_inside};
use undistort::{UndistortMap, distortion_from_opencv};

/// Millimetres per metre: `annots.npy` stores `T` in millimetres.
const MM_PER_M: f64 = 1000.0;

/// SMPL parameters of one frame (`params/<n>.npy`), as stored: axis-angle `poses` (72),
/// global rotation `Rh` and translation `Th` (metres), and `shapes` (10 betas).
#[derive(Clone, Debug, PartialEq)]
pub struct SmplParams {
    pub poses: Vec<f64>,
    pub rh: [f64; 3],
    pub th: [f64; 3],
    pub shapes: Vec<f64>,
}

/// One ZJU-MoCap capture, opened and checked.
#[derive(Debug)]
pub struct ZjuDataset {
    root: PathBuf,
    cameras: Vec<Camera>,
    names: Vec<String>,
    intrinsics_cv: Vec<Matrix3<f64>>,
    distortion: Vec<Distortion>,
    images: Vec<Vec<String>>,
    mask_dir: PathBuf,
    frame_ids: Vec<Option<u64>>,
    log: ReadLog,
}

impl ZjuDataset {
    /// Opens the capture in `root`: reads `annots.npy`, each camera's image size (from its first
    /// image's header), and checks that every listed image and its mask exist (the error names
    /// the first missing file).
    pub fn open(root: &Path) -> Result<Self> {
        let annots_path = root.join("annots.npy");
        let annots = annots::read_annots(&annots_path)?;
        let mask_dir = [root.join("mask"), root.join("mask_cihp")]
            .into_iter()
            .find(|d| d.is_dir())
            .ok_or_else(|| missing(&root.join("mask"), "masks go in mask/ or mask_cihp/"))?;
        let log = ReadLog::default();
        let mut cameras = Vec::new();
        let mut names = Vec::new();
        let mut intrinsics_cv = Vec::new();
        let mut distortion = Vec::new();
        for (c, p) in annots.cameras.iter().enumerate() {
            let first = root.join(&annots.images[0][c]);
            let size = image_size(&first, &log)?;
            let k = Matrix3::from_row_slice(&p.k);
            let r = Matrix3::from_row_slice(&p.r);
            let t = Vector3::from(p.t_mm) / MM_PER_M;
            let name = camera_name(&annots.images[0][c]);
            cameras.push(camera_from_opencv(&k, &r, &t, size, &annots_path, &name)?);
            distortion.push(distortion_of(&p.d, &annots_path, &name)?);
            names.push(name);
            intrinsics_cv.push(k);
        }
        let frame_ids = annots.images.iter().map(|f| frame_id(&f[0])).collect();
        let data = Self {
            root: root.to_path_buf(),
            cameras,
            names,
            intrinsics_cv,
            distortion,
            images: annots.images,
            mask_dir,
            frame_ids,
            log,
        };
        data.check_files()?;
        Ok(data)
    }

    pub fn image_path(&self, camera: usize, frame: usize) -> PathBuf {
        self.root.join(&self.images[frame][camera])
    }

    pub fn mask_path(&self, camera: usize, frame: usize) -> PathBuf {
        self.mask_dir
            .join(&self.images[frame][camera])
            .with_extension("png")
    }

    /// The distortion of a camera as calibrated (its images are returned undistorted).
    pub fn distortion(&self, camera: usize) -> Option<&Distortion> {
        self.distortion.get(camera)
    }

    /// The SMPL parameters of a frame, from `params/<n>.npy` (or `new_params/`).
    pub fn smpl_params(&self, frame: usize) -> Result<SmplParams> {
        let dir = ["params", "new_params"]
            .iter()
            .map(|d| self.root.join(d))
            .find(|d| d.is_dir())
            .ok_or_else(|| {
                missing(
                    &self.root.join("params"),
                    "no params/ or new_params/ folder",
                )
            })?;
        let path = dir.join(format!("{}.npy", self.frame_id_of(frame)?));
        self.access(&path, None, frame)?;
        read_smpl(&path)
    }

    fn frame_id_of(&self, frame: usize) -> Result<u64> {
        check_index(
            &self.root,
            None,
            self.cameras.len(),
            frame,
            self.images.len(),
        )?;
        self.frame_ids[frame].ok_or_else(|| {
            let msg = format!(
                "frame {frame}: image name {:?} holds no frame number",
                self.images[frame][0]
            );
            HumanError::invalid(self.root.join("annots.npy"), msg)
        })
    }

    fn check_files(&self) -> Result<()> {
        for f in 0..self.images.len() {
            for c in 0..self.cameras.len() {
                for path in [self.image_path(c, f), self.mask_path(c, f)] {
                    if !path.is_file() {
                        return Err(missing(
                            &path,
                            &format!("listed in annots.npy for frame {f}"),
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    fn access(&self, path: &Path, camera: Option<usize>, frame: usize) -> Result<()> {
        check_index(
            &self.root,
            camera,
            self.cameras.len(),
            frame,
            self.images.len(),
        )?;
        self.log
            .record(path, ReadKind::Content, camera, Some(frame));
        Ok(())
    }

    /// The undistortion map of `camera`, or `None` without distortion.
    fn map(&self, camera: usize) -> Option<UndistortMap> {
        let d = &self.distortion[camera];
        let (width, height) = self.size(camera);
        (!d.is_identity()).then(|| UndistortMap::new(&self.intrinsics_cv[camera], d, width, height))
    }

    fn size(&self, camera: usize) -> (usize, usize) {
        let k = &self.cameras[camera].intrinsics;
        (k.width as usize, k.height as usize)
    }
}

impl MultiView for ZjuDataset {
    fn root(&self) -> &Path {
        &self.root
    }

    fn cameras(&self) -> &[Camera] {
        &self.cameras
    }

    fn camera_names(&self) -> &[String] {
        &self.names
    }

    fn frame_count(&self) -> usize {
        self.images.len()
    }

    fn joint_names(&self) -> &[String] {
        &[]
    }

    fn image(&self, camera: usize, frame: usize) -> Result<Image> {
        check_index(
            &self.root,
            Some(camera),
            self.cameras.len(),
            frame,
            self.images.len(),
        )?;
        let path = self.image_path(camera, frame);
        self.access(&path, Some(camera), frame)?;
        let img = maps::load_rgb(&path)?;
        maps::check_size(&path, (img.width, img.height), self.size(camera))?;
        Ok(match self.map(camera) {
            Some(map) => map.remap_bilinear(&img),
            None => img,
        })
    }

    fn mask(&self, camera: usize, frame: usize) -> Result<Mask> {
        check_index(
            &self.root,
            Some(camera),
            self.cameras.len(),
            frame,
            self.images.len(),
        )?;
        let path = self.mask_path(camera, frame);
        self.access(&path, Some(camera), frame)?;
        let mask = Mask::load(&path, 1)?;
        maps::check_size(&path, (mask.width, mask.height), self.size(camera))?;
        Ok(match self.map(camera) {
            Some(map) => map.remap_nearest(&mask),
            None => mask,
        })
    }

    fn has_depth(&self) -> bool {
        false
    }

    fn depth(&self, _camera: usize, _frame: usize) -> Result<DepthMap> {
        Err(HumanError::invalid(
            &self.root,
            "the ZJU-MoCap layout has no depth maps",
        ))
    }

    fn joints2d(&self, camera: usize, frame: usize) -> Result<Vec<[f64; 2]>> {
        check_index(
            &self.root,
            Some(camera),
            self.cameras.len(),
            frame,
            self.images.len(),
        )?;
        let joints = self.joints3d(frame)?;
        let cam = &self.cameras[camera];
        let path = self.root.join("joints3d");
        let mut out = Vec::with_capacity(joints.len());
        for (j, p) in joints.iter().enumerate() {
            let Some((u, v, _)) = cam.project(&Vector3::from(*p)) else {
                let msg = format!(
                    "camera {}, frame {frame}: joint {j} is behind the camera",
                    self.names[camera]
                );
                return Err(HumanError::invalid(&path, msg));
            };
            out.push([u, v]);
        }
        check_joints_inside(
            &path,
            &self.names[camera],
            frame,
            &out,
            (cam.width(), cam.height()),
        )?;
        Ok(out)
    }

    fn joints3d(&self, frame: usize) -> Result<Vec<[f64; 3]>> {
        let path = self
            .root
            .join("joints3d")
            .join(format!("{}.npy", self.frame_id_of(frame)?));
        self.access(&path, None, frame)?;
        let array = fewview_scene::numpy::read_npy(&path)?;
        if array.shape.len() != 2 || array.shape[1] != 3 {
            let msg = format!("shape {:?}, expected (joints, 3)", array.shape);
            return Err(HumanError::invalid(&path, msg));
        }
        Ok(array
            .data
            .chunks_exact(3)
            .map(|p| [p[0], p[1], p[2]])
            .collect())
    }

    fn joint_parents(&self) -> Result<Vec<i64>> {
        let joints = self.joints3d(0)?.len();
        let listed = self.root.join("joints3d").join(PARENTS_FILE);
        if listed.is_file() {
            let parents = read_parents(&listed)?;
            if parents.len() != joints {
                let msg = format!("{} parents for {joints} joints", parents.len());
                return Err(HumanError::invalid(&listed, msg));
            }
            return Ok(parents);
        }
        if joints == SMPL_PARENTS.len() {
            return Ok(SMPL_PARENTS.to_vec());
        }
        let msg = format!(
            "{joints} joints per frame: SMPL's {} have a known skeleton; for others list each \
             joint's parent (-1 for the root) in joints3d/{PARENTS_FILE}",
            SMPL_PARENTS.len()
        );
        Err(HumanError::invalid(self.root.join("joints3d"), msg))
    }

    fn read_log(&self) -> &ReadLog {
        &self.log
    }
}

/// The file naming each joint's parent, for joints other than SMPL's 24: a JSON list of
/// integers, `-1` for the root.
pub const PARENTS_FILE: &str = "parents.json";

/// The parents of SMPL's 24 joints (pelvis, hips, spine, knees, …), the kinematic tree of the
/// SMPL body model.
pub const SMPL_PARENTS: [i64; 24] = [
    -1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21,
];

/// A parents list, checked to be a tree whose parents come before their children.
fn read_parents(path: &Path) -> Result<Vec<i64>> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| HumanError::format(path, format!("cannot read ({e})")))?;
    let parents: Vec<i64> = serde_json::from_str(&text)
        .map_err(|e| HumanError::format(path, format!("expected a list of integers ({e})")))?;
    for (j, &p) in parents.iter().enumerate() {
        if p >= j as i64 || p < -1 || (p == -1) != (j == 0) {
            let msg = format!(
                "joint {j} has parent {p}: the root (joint 0) has -1, every other joint an \
                 earlier one"
            );
            return Err(HumanError::invalid(path, msg));
        }
    }
    Ok(parents)
}

/// A camera's `D`: none (no distortion), or OpenCV's 4 or 5 coefficients.
fn distortion_of(d: &[f64], annots: &Path, camera: &str) -> Result<Distortion> {
    if d.is_empty() {
        return Ok(Distortion::opencv(&[]));
    }
    distortion_from_opencv(d).ok_or_else(|| {
        let msg = format!(
            "camera {camera}: D has {} coefficients, expected 4 or 5 (k1, k2, p1, p2[, k3])",
            d.len()
        );
        HumanError::invalid(annots, msg)
    })
}

/// The image size from the file's header (recorded as a header read).
fn image_size(path: &Path, log: &ReadLog) -> Result<(u32, u32)> {
    if !path.is_file() {
        return Err(missing(path, "listed in annots.npy"));
    }
    log.record(path, ReadKind::Header, None, None);
    image::image_dimensions(path)
        .map_err(|e| HumanError::format(path, format!("cannot read the image size ({e})")))
}

/// The camera's folder in an image path (`Camera_B1/000000.jpg` → `Camera_B1`).
fn camera_name(rel: &str) -> String {
    let path = Path::new(rel);
    let folder = path.parent().and_then(|p| p.file_name());
    folder
        .unwrap_or(path.as_os_str())
        .to_string_lossy()
        .into_owned()
}

/// The frame number in an image name: the digits of its stem (`000123.jpg` → 123).
fn frame_id(rel: &str) -> Option<u64> {
    let stem = Path::new(rel).file_stem()?.to_string_lossy();
    let digits: String = stem.chars().filter(char::is_ascii_digit).collect();
    digits.parse().ok()
}

/// Reads one frame's SMPL parameters.
fn read_smpl(path: &Path) -> Result<SmplParams> {
    let value = numpy::read_object_npy(path)?;
    let get = |key: &str, len: Option<usize>| -> Result<Vec<f64>> {
        let v = value.get(key).and_then(numpy::Value::numbers);
        let v = v.ok_or_else(|| HumanError::format(path, format!("no numeric '{key}' entry")))?;
        match len {
            Some(n) if v.len() != n => Err(HumanError::format(
                path,
                format!("'{key}' has {} values, expected {n}", v.len()),
            )),
            _ => Ok(v),
        }
    };
    let three = |v: Vec<f64>| [v[0], v[1], v[2]];
    Ok(SmplParams {
        poses: get("poses", None)?,
        rh: three(get("Rh", Some(3))?),
        th: three(get("Th", Some(3))?),
        shapes: get("shapes", None)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distortion_needs_none_four_or_five_coefficients() {
        let at = Path::new("annots.npy");
        assert!(distortion_of(&[], at, "B1").unwrap().is_identity());
        let d = distortion_of(&[0.1, -0.2, 0.01, 0.02], at, "B1").unwrap();
        assert_eq!(d, Distortion::opencv(&[0.1, -0.2, 0.01, 0.02, 0.0]));
        let err = distortion_of(&[0.1, 0.2, 0.3], at, "B1")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("annots.npy") && err.contains("3 coefficients"),
            "{err}"
        );
    }
}
