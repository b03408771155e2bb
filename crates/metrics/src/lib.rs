//! Metrics the papers report: see the modules.

pub mod pose_error;
