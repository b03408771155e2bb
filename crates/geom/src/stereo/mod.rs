//! Calibrated two-view stereo (paper 000 §2): rectification, Semi-Global Matching, and the
//! confidence-based hierarchical point cloud built from the disparities.

pub mod hierarchy;
pub mod pairs;
pub mod rectify;
pub mod refine;
pub mod sgm;
pub mod source;
