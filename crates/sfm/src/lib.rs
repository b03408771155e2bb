#![doc = include_str!("../README.md")]

pub mod bundle;
pub mod global_start;
pub mod schur;
pub mod se3;

pub use bundle::{BundleOptions, BundleReport, bundle_adjust};
pub use global_start::{GlobalStart, PairPose, global_start};
