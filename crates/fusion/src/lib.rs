#![doc = include_str!("../README.md")]
//! Sparse-view Gaussian splatting whose colours change smoothly while the camera moves between
//! the input views: the gradient-domain fusion of the fusion paper ("Splat-based Gradient-domain Fusion
//! for Seamless View Transition") on virtual views between adjacent training views, its
//! alternatives (supplement §4), and the transition videos and metrics it is judged by.
//!
//! Entry points: [`fusion_run`] trains one variant ([`Variant`], [`FusionConfig`]);
//! [`transition`] renders and scores the path through the training views; [`leave_one_out`]
//! scores a capture whose every photo trains.

pub mod bench;
pub mod budget;
pub mod error;
pub mod guidance;
pub mod leave_one_out;
pub mod losses;
pub mod reproject;
pub mod run;
pub mod study;
pub mod table;
pub mod terms;
pub mod transition;
pub mod variant;
pub mod virtual_view;

pub use error::FusionError;
pub use run::{FusionRecord, fusion_run};
pub use variant::{FUSION_DROPOUT, FusionConfig, Variant};
