#![doc = include_str!("../README.md")]
//! Neural implicit surfaces from sparse, noisy poses (the surface paper): a NeuS renderer over a signed
//! distance field (hash grid or NeuS MLP), per-camera pose refinement with SPARF's
//! parameterisation, correspondence-based losses with the paper's uncertainty-aware photometric
//! and geometric consistency (Eqs. 5–7), and the progressive SDF loss (Eqs. 8, 9, 12, 13).
//!
//! A run in three calls: [`RunConfig::resolve`] turns a [`Schedule`] and the user's
//! [`Overrides`] into the run's configuration, [`LoadedInputs::load`] reads the views of a
//! dataset folder or of the built-in analytic scene ([`Scene`]), and [`run`] trains, refines
//! the poses and writes the run directory, returning a [`RunReport`].

// Numeric kernels index several parallel arrays with one loop variable.
#![allow(clippy::needless_range_loop)]

/// Adam and the learning-rate schedule live in `fewview-optim`, shared with the Gaussian trainer.
pub use fewview_optim as adam;
pub mod bench;
pub use fewview_sfm::bundle;
pub mod checkpoint;
pub mod config;
pub use fewview_scene::cputime;
pub mod error;
pub mod extract;
pub mod field;
#[doc(hidden)]
pub use fewview_sfm::global_start;
#[doc(hidden)]
pub mod hashgrid;
pub mod inputs;
#[doc(hidden)]
pub mod losses;
/// Correspondences between the training views: the matchers of `fewview-match` under the
/// paths the surface method has always used.
pub mod matching {
    pub use fewview_match::correspondence::*;
    pub use fewview_match::{dense, densify, fundamental, learned, refine, report, sift};
}
#[doc(hidden)]
pub mod mlp;
pub mod overrides;
pub mod patch_adjustment;
pub mod pipeline;
#[doc(hidden)]
pub mod pose;
#[doc(hidden)]
pub mod rays;
#[doc(hidden)]
pub mod render;
pub mod schedule;
pub mod sdf_scene;
pub mod table1;
pub mod train;
pub mod warmup;

pub use config::{InitialPoses, RunConfig};
pub use error::{Result, SurfaceError};
pub use inputs::{LoadedInputs, Scene};
pub use overrides::{DEFAULT_POSE_NOISE, Densify, LossSwitches, LossWeights, Overrides};
pub use pipeline::{Event, RunInputs, RunReport, run};
pub use schedule::Schedule;
