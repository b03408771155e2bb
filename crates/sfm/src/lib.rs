#![doc = include_str!("../README.md")]

pub mod baseline_lengths;
pub mod bundle;
pub mod error;
pub mod export;
pub mod folder;
pub mod global_start;
pub mod photos;
pub mod poses;
pub mod schur;
pub mod se3;

pub use bundle::{BundleOptions, BundleReport, bundle_adjust, bundle_adjust_with};
pub use error::{Result, SfmError};
pub use export::{place_images, write_model};
pub use folder::{FolderOptions, poses_for_folder};
pub use global_start::{GlobalStart, PairPose, global_start};
pub use photos::{Photo, load_folder, load_photo, photo_files};
pub use poses::{
    EXIF_FOCAL_SD, MatchedPairs, PoseModel, PoseOptions, PoseProgress, PoseStage, estimate_poses,
    estimate_poses_with,
};
