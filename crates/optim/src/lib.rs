#![doc = include_str!("../README.md")]
//! Optimisation shared by the Gaussian and surface trainers: Adam on host parameter arrays,
//! learning-rate schedules, and the read-back of tensors (gradients and the values host steps
//! need) to those arrays.

pub mod adam;
pub mod host;
pub mod rows;
pub mod schedule;

pub use adam::{AdamConfig, AdamState};
pub use host::{ReadbackError, f32_values, flex_f32, note_read_back, read_backs};
pub use rows::retain_rows;
pub use schedule::ExpSchedule;
