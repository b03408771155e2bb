//! The synthetic multi-view video of a person (`$FEWVIEW_DATA/human`, see its README): 12 fixed
//! cameras, per camera and frame an sRGB JPEG on black, a mask and exact z-depth, and 17 joints
//! per frame in 3D and in every camera. It stands in for ZJU-MoCap, the benchmark of
//! "PoseGaussian: Pose-Driven Novel View Synthesis for Robust 3D Human Reconstruction".
//!
//! Layout: `cameras.json`, `joints.json`, and per sequence `images/cam_XX/frame_YYYY.jpg`,
//! `masks/cam_XX/frame_YYYY.png` (0 / 255), `depth/cam_XX/frame_YYYY.png` (16-bit millimetres,
//! 0 = none), `joints3d.npy` (T, 17, 3) and `joints2d/cam_XX.npy` (T, 17, 2).
//!
//! **Conventions.** `cameras.json` is OpenCV's with pixel centres at *integer* coordinates; the
//! cameras are converted to fewview-scene's half-integer centres by [`crate::opencv`] (principal
//! point 255.5 → 256.0), and the 2D joints move by the same half pixel, so
//! `camera.project(joint3d)` equals the returned 2D joint. Depth keeps its meaning: the z of the
//! surface through each pixel centre, now in metres.
//!
//! **Checks on open** (each a one-line error naming the file): every camera of `cameras.json`
//! has an image folder and there are no others; every camera has every frame's image and mask
//! (the frame count is the first camera's number of images); `joints3d.npy` and each
//! `joints2d/cam_XX.npy` have that many frames and `joints.json`'s joints. Opening reads only
//! headers; pixels and joints are read on access, one `(camera, frame)` at a time.

use std::path::{Path, PathBuf};

use fewview_scene::{Camera, Image};
use nalgebra::{Matrix3, Vector3};
use serde::Deserialize;

use crate::error::{HumanError, Result, missing};
use crate::maps::{self, DepthMap, Mask};
use crate::npy_rows;
use crate::opencv::{camera_from_opencv, pixel_from_opencv};
use crate::readlog::{ReadKind, ReadLog};
use crate::source::{MultiView, check_index, check_joints_inside};

/// Mask pixels at or above this 8-bit value are foreground (the files hold 0 and 255).
const MASK_THRESHOLD: u8 = 128;

#[derive(Deserialize)]
struct CamerasFile {
    cameras: Vec<CameraEntry>,
}

#[derive(Deserialize)]
struct CameraEntry {
    name: String,
    width: u32,
    height: u32,
    #[serde(rename = "K")]
    k: [[f64; 3]; 3],
    #[serde(rename = "R")]
    r: [[f64; 3]; 3],
    t: [f64; 3],
    #[serde(default)]
    dist: Vec<f64>,
}

#[derive(Deserialize)]
struct JointsFile {
    names: Vec<String>,
    parents: Vec<i64>,
}

/// One sequence of the synthetic capture, opened and checked.
#[derive(Debug)]
pub struct HumanDataset {
    root: PathBuf,
    sequence: PathBuf,
    cameras: Vec<Camera>,
    names: Vec<String>,
    frames: usize,
    joint_names: Vec<String>,
    joint_parents: Vec<i64>,
    log: ReadLog,
}

impl HumanDataset {
    /// Opens sequence `sequence` (e.g. `seq_a`) of the capture in `root` and checks it (module
    /// docs).
    pub fn open(root: &Path, sequence: &str) -> Result<Self> {
        let (cameras, names) = read_cameras(&root.join("cameras.json"))?;
        let (joint_names, joint_parents) = read_joints(&root.join("joints.json"))?;
        let mut data = Self {
            root: root.to_path_buf(),
            sequence: root.join(sequence),
            cameras,
            names,
            frames: 0,
            joint_names,
            joint_parents,
            log: ReadLog::default(),
        };
        data.check_camera_folders()?;
        data.frames = data.count_frames()?;
        data.check_frames_present()?;
        data.check_joint_arrays()?;
        Ok(data)
    }

    pub fn image_path(&self, camera: usize, frame: usize) -> PathBuf {
        self.per_view("images", camera, frame, "jpg")
    }

    pub fn mask_path(&self, camera: usize, frame: usize) -> PathBuf {
        self.per_view("masks", camera, frame, "png")
    }

    pub fn depth_path(&self, camera: usize, frame: usize) -> PathBuf {
        self.per_view("depth", camera, frame, "png")
    }

    fn per_view(&self, kind: &str, camera: usize, frame: usize, ext: &str) -> PathBuf {
        let name = self.names.get(camera).map_or("?", String::as_str);
        self.sequence
            .join(kind)
            .join(name)
            .join(format!("frame_{frame:04}.{ext}"))
    }

    fn joints2d_path(&self, camera: usize) -> PathBuf {
        let name = &self.names[camera];
        self.sequence.join("joints2d").join(format!("{name}.npy"))
    }

    fn joints3d_path(&self) -> PathBuf {
        self.sequence.join("joints3d.npy")
    }

    /// The image folders are exactly the cameras of `cameras.json`.
    fn check_camera_folders(&self) -> Result<()> {
        let dir = self.sequence.join("images");
        let entries = std::fs::read_dir(&dir).map_err(|e| HumanError::io(&dir, e))?;
        let mut folders = Vec::new();
        for entry in entries {
            let entry = entry.map_err(|e| HumanError::io(&dir, e))?;
            if entry.path().is_dir() {
                folders.push(entry.file_name().to_string_lossy().into_owned());
            }
        }
        if folders.len() != self.names.len() {
            return Err(HumanError::invalid(
                &dir,
                format!(
                    "{} camera folders but cameras.json has {} cameras",
                    folders.len(),
                    self.names.len()
                ),
            ));
        }
        Ok(())
    }

    /// The number of frames: the first camera's images `frame_0000.jpg`, `frame_0001.jpg`, ...
    fn count_frames(&self) -> Result<usize> {
        let first = self.image_path(0, 0);
        if !first.is_file() {
            return Err(missing(&first, "every camera needs frame 0000"));
        }
        let mut n = 1;
        while self.image_path(0, n).is_file() {
            n += 1;
        }
        Ok(n)
    }

    /// Every camera has every frame's image and mask; the error names the first missing file.
    fn check_frames_present(&self) -> Result<()> {
        let last = self.frames - 1;
        for c in 0..self.cameras.len() {
            for f in 0..self.frames {
                for path in [self.image_path(c, f), self.mask_path(c, f)] {
                    if !path.is_file() {
                        let why = format!("every camera needs frames 0000 to {last:04}");
                        return Err(missing(&path, &why));
                    }
                }
            }
        }
        Ok(())
    }

    /// `joints3d.npy` is (T, J, 3) and every `joints2d/cam_XX.npy` (T, J, 2).
    fn check_joint_arrays(&self) -> Result<()> {
        let j = self.joint_names.len();
        self.check_shape(&self.joints3d_path(), [self.frames, j, 3])?;
        for c in 0..self.cameras.len() {
            self.check_shape(&self.joints2d_path(c), [self.frames, j, 2])?;
        }
        Ok(())
    }

    fn check_shape(&self, path: &Path, want: [usize; 3]) -> Result<()> {
        self.log.record(path, ReadKind::Header, None, None);
        let shape = npy_rows::shape(path)?;
        if shape != want {
            return Err(HumanError::invalid(
                path,
                format!(
                    "shape {shape:?}, expected {want:?} ({} frames of images, {} joints in joints.json)",
                    want[0], want[1]
                ),
            ));
        }
        Ok(())
    }

    fn size(&self, camera: usize) -> (usize, usize) {
        let k = &self.cameras[camera].intrinsics;
        (k.width as usize, k.height as usize)
    }

    /// Checks the indices and records a content read of `path`.
    fn access(&self, path: &Path, camera: Option<usize>, frame: usize) -> Result<()> {
        check_index(&self.root, camera, self.cameras.len(), frame, self.frames)?;
        self.log
            .record(path, ReadKind::Content, camera, Some(frame));
        Ok(())
    }
}

impl MultiView for HumanDataset {
    fn joint_parents(&self) -> Result<Vec<i64>> {
        Ok(self.joint_parents.clone())
    }

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
        self.frames
    }

    fn joint_names(&self) -> &[String] {
        &self.joint_names
    }

    fn image(&self, camera: usize, frame: usize) -> Result<Image> {
        let path = self.image_path(camera, frame);
        self.access(&path, Some(camera), frame)?;
        let img = maps::load_rgb(&path)?;
        maps::check_size(&path, (img.width, img.height), self.size(camera))?;
        Ok(img)
    }

    fn mask(&self, camera: usize, frame: usize) -> Result<Mask> {
        let path = self.mask_path(camera, frame);
        self.access(&path, Some(camera), frame)?;
        let mask = Mask::load(&path, MASK_THRESHOLD)?;
        maps::check_size(&path, (mask.width, mask.height), self.size(camera))?;
        Ok(mask)
    }

    /// A capture without a `depth/` folder has none; a missing or broken file inside one is
    /// an error of [`MultiView::depth`].
    fn has_depth(&self) -> bool {
        self.sequence.join("depth").is_dir()
    }

    fn depth(&self, camera: usize, frame: usize) -> Result<DepthMap> {
        let path = self.depth_path(camera, frame);
        self.access(&path, Some(camera), frame)?;
        let depth = DepthMap::load_millimetres(&path)?;
        maps::check_size(&path, (depth.width, depth.height), self.size(camera))?;
        Ok(depth)
    }

    fn joints2d(&self, camera: usize, frame: usize) -> Result<Vec<[f64; 2]>> {
        check_index(
            &self.root,
            Some(camera),
            self.cameras.len(),
            frame,
            self.frames,
        )?;
        let path = self.joints2d_path(camera);
        self.access(&path, Some(camera), frame)?;
        let row = npy_rows::read_row(&path, frame)?;
        let joints: Vec<[f64; 2]> = row
            .chunks_exact(2)
            .map(|p| pixel_from_opencv([p[0], p[1]]))
            .collect();
        let k = &self.cameras[camera].intrinsics;
        check_joints_inside(
            &path,
            &self.names[camera],
            frame,
            &joints,
            (k.width, k.height),
        )?;
        Ok(joints)
    }

    fn joints3d(&self, frame: usize) -> Result<Vec<[f64; 3]>> {
        let path = self.joints3d_path();
        self.access(&path, None, frame)?;
        let row = npy_rows::read_row(&path, frame)?;
        Ok(row.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect())
    }

    fn read_log(&self) -> &ReadLog {
        &self.log
    }
}

/// Reads `cameras.json` into cameras (fewview-scene's convention) and their names.
fn read_cameras(path: &Path) -> Result<(Vec<Camera>, Vec<String>)> {
    let text = std::fs::read_to_string(path).map_err(|e| HumanError::io(path, e))?;
    let file: CamerasFile = serde_json::from_str(&text)
        .map_err(|e| HumanError::format(path, format!("not a camera file ({e})")))?;
    if file.cameras.is_empty() {
        return Err(HumanError::invalid(path, "no cameras"));
    }
    let mut cameras = Vec::with_capacity(file.cameras.len());
    let mut names = Vec::with_capacity(file.cameras.len());
    for entry in file.cameras {
        if entry.dist.iter().any(|&d| d != 0.0) {
            let msg = format!(
                "{}: non-zero distortion {:?} is not supported",
                entry.name, entry.dist
            );
            return Err(HumanError::invalid(path, msg));
        }
        let k = Matrix3::from_fn(|i, j| entry.k[i][j]);
        let r = Matrix3::from_fn(|i, j| entry.r[i][j]);
        let t = Vector3::from(entry.t);
        let size = (entry.width, entry.height);
        cameras.push(camera_from_opencv(&k, &r, &t, size, path, &entry.name)?);
        names.push(entry.name);
    }
    Ok((cameras, names))
}

/// Reads `joints.json`: joint names and parent indices.
fn read_joints(path: &Path) -> Result<(Vec<String>, Vec<i64>)> {
    let text = std::fs::read_to_string(path).map_err(|e| HumanError::io(path, e))?;
    let file: JointsFile = serde_json::from_str(&text)
        .map_err(|e| HumanError::format(path, format!("not a joint list ({e})")))?;
    let n = file.names.len() as i64;
    if file.parents.len() != file.names.len() || file.parents.iter().any(|&p| p < -1 || p >= n) {
        return Err(HumanError::invalid(
            path,
            format!(
                "{} names but parents {:?} (one index in -1..{} per joint)",
                file.names.len(),
                file.parents,
                n
            ),
        ));
    }
    Ok((file.names, file.parents))
}
