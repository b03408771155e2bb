//! Cameras, poses, images and datasets in one internal convention.
//!
//! **Convention** (see `ARCHITECTURE.md`): OpenCV camera axes (x right, y down, z forward),
//! world-to-camera `[R|t]`, pinhole intrinsics in pixels. Pixel `(i, j)` covers the continuous
//! square `[i, i+1) × [j, j+1)`, so its centre is at `(i + 0.5, j + 0.5)` and a principal point of
//! `(W/2, H/2)` is the exact image centre. Every loader converts to this at the border.
//!
//! Images are `f32` sRGB in `[0, 1]`, stored H×W×C row-major.

pub mod atomic;
pub mod camera;
pub mod dataset;
pub mod error;
pub mod image;
pub mod video;

pub use camera::{Camera, Intrinsics, Se3, camera_path};
pub use dataset::{Dataset, PointCloud, View};
pub use error::SceneError;
pub use image::Image;
