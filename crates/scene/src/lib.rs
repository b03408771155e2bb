#![doc = include_str!("../README.md")]
//! Cameras, poses, images and datasets in one internal convention.
//!
//! **Convention** (see `docs/ARCHITECTURE.md`): OpenCV camera axes (x right, y down, z forward),
//! world-to-camera `[R|t]`, pinhole intrinsics in pixels. Pixel `(i, j)` covers the continuous
//! square `[i, i+1) × [j, j+1)`, so its centre is at `(i + 0.5, j + 0.5)` and a principal point of
//! `(W/2, H/2)` is the exact image centre. Every loader converts to this at the border.
//!
//! Images are `f32` sRGB in `[0, 1]`, stored H×W×C row-major.
//!
//! **Datasets**: [`load_dataset`] detects and loads LLFF ([`llff`]), NeRF-synthetic and
//! nerfstudio `transforms` files ([`transforms`]), IDR/NeuS DTU ([`dtu`]) and COLMAP models
//! ([`colmap`]), with each format's standard sparse-view split ([`split`]) unless
//! [`LoadOptions`] names the views.

pub mod atomic;
pub mod axes;
pub mod camera;
pub mod colmap;
pub mod cpu;
pub mod cputime;
pub mod dataset;
pub mod demo_capture;
pub mod distortion;
pub mod dtu;
pub mod error;
pub mod image;
pub mod llff;
pub mod load;
mod load_options;
mod load_report;
pub mod memory;
pub mod numpy;
pub mod photometric;
pub mod ply;
pub mod ply_scalar;
pub mod pose_export;
pub mod sealed;
pub mod split;
pub mod synthetic;
pub mod transforms;
mod view_files;

pub use camera::{Camera, Intrinsics, Se3, axes_meeting_point, camera_path};
pub use dataset::{Dataset, PointCloud, View};
pub use error::{FileIoError, SceneError};
pub use image::Image;
pub use load::{
    DatasetFormat, LoadOptions, LoadReport, UndistortMode, detect_format, load_dataset,
    load_dataset_with_report,
};
pub use view_files::stem as file_stem;
