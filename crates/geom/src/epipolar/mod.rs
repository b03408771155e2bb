//! Two-view and multi-view geometry of calibrated cameras without poses: the five-point
//! essential matrix ([`five_point()`](five_point::five_point)), the relative pose of a pair by RANSAC and refinement
//! ([`relative_pose`]), and the absolute rotations and centres those pairs imply
//! ([`average_rotations`], [`centres_from_baselines`]) — a global start for the poses before
//! any local refinement (the surface paper's Table 1 protocol on DTU).

pub mod averaging;
pub mod five_point;
pub mod relative;

pub use averaging::{
    Baseline, RelativeRotation, average_rotations, centres_from_baselines, project_to_rotation,
};
pub use five_point::five_point;
pub use relative::{RelativePose, RelativePoseOptions, relative_pose};
