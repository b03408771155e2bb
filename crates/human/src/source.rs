//! The one interface every multi-view video capture offers the rest of the crate: fixed
//! calibrated cameras and, per `(camera, frame)`, an image, a mask and the body joints.
//!
//! Implemented by the synthetic capture ([`crate::dataset::HumanDataset`]) and the ZJU-MoCap
//! layout ([`crate::zju::ZjuDataset`]); [`crate::split::TrainingView`] wraps any of them.
//! Cameras are in fewview-scene's convention (OpenCV axes, world-to-camera, pixel centres at
//! half-integers) and 2D joints in the same pixel coordinates, so `camera.project(joint3d)`
//! lands on the matching 2D joint.

use std::path::Path;

use fewview_scene::{Camera, Image};

use crate::error::Result;
use crate::maps::{DepthMap, Mask};
use crate::readlog::ReadLog;

/// A synchronized multi-view video with fixed cameras. Accessors read lazily, one
/// `(camera, frame)` at a time, and record what they read in [`MultiView::read_log`].
pub trait MultiView: Sync {
    /// The capture's folder (named in errors).
    fn root(&self) -> &Path;
    /// The cameras, fixed for all frames.
    fn cameras(&self) -> &[Camera];
    /// A name per camera, as the capture calls it (`cam_03`, `Camera_B4`).
    fn camera_names(&self) -> &[String];
    /// Number of frames.
    fn frame_count(&self) -> usize;
    /// The joints' names (empty when the capture does not name them).
    fn joint_names(&self) -> &[String];
    /// sRGB colour in `[0, 1]`, H×W×3.
    fn image(&self, camera: usize, frame: usize) -> Result<Image>;
    /// The person's mask.
    fn mask(&self, camera: usize, frame: usize) -> Result<Mask>;
    /// Whether the capture has depth maps ([`MultiView::depth`]).
    fn has_depth(&self) -> bool;
    /// Metric z-depth, where the capture has it (an error otherwise).
    fn depth(&self, camera: usize, frame: usize) -> Result<DepthMap>;
    /// The joints' pixel positions `(u, v)` in this camera; an error if one lies outside the image.
    fn joints2d(&self, camera: usize, frame: usize) -> Result<Vec<[f64; 2]>>;
    /// The joints' world positions, metres.
    fn joints3d(&self, frame: usize) -> Result<Vec<[f64; 3]>>;
    /// Each joint's parent in the skeleton (`-1` for the root), which the pose maps draw limbs
    /// along.
    fn joint_parents(&self) -> Result<Vec<i64>>;
    /// Every file read so far.
    fn read_log(&self) -> &ReadLog;
}

/// An error unless `camera < count` and `frame < frames`, naming the capture.
pub(crate) fn check_index(
    root: &Path,
    camera: Option<usize>,
    cameras: usize,
    frame: usize,
    frames: usize,
) -> Result<()> {
    if let Some(c) = camera.filter(|&c| c >= cameras) {
        return Err(crate::error::HumanError::invalid(
            root,
            format!("camera {c} out of range (the capture has {cameras} cameras)"),
        ));
    }
    if frame >= frames {
        return Err(crate::error::HumanError::invalid(
            root,
            format!("frame {frame} out of range (the capture has {frames} frames)"),
        ));
    }
    Ok(())
}

/// An error naming `path`, camera and frame unless every joint lies inside the `width × height`
/// image (pixel coordinates in `[0, width] × [0, height]`).
pub(crate) fn check_joints_inside(
    path: &Path,
    camera: &str,
    frame: usize,
    joints: &[[f64; 2]],
    size: (u32, u32),
) -> Result<()> {
    let (w, h) = (size.0 as f64, size.1 as f64);
    for (j, p) in joints.iter().enumerate() {
        let inside = p.iter().all(|v| v.is_finite())
            && (0.0..=w).contains(&p[0])
            && (0.0..=h).contains(&p[1]);
        if !inside {
            return Err(crate::error::HumanError::invalid(
                path,
                format!(
                    "camera {camera}, frame {frame}: joint {j} at ({:.2}, {:.2}) is outside the {}×{} image",
                    p[0], p[1], size.0, size.1
                ),
            ));
        }
    }
    Ok(())
}
