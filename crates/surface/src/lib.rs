#![doc = include_str!("../README.md")]
//! Neural implicit surfaces from sparse, noisy poses (paper 001): a NeuS renderer over a signed
//! distance field (hash grid or NeuS MLP), per-camera pose refinement with SPARF's
//! parameterisation, correspondence-based losses with the paper's uncertainty-aware photometric
//! and geometric consistency (Eqs. 5–7), and the progressive SDF loss (Eqs. 8, 9, 12, 13).

// Numeric kernels index several parallel arrays with one loop variable.
#![allow(clippy::needless_range_loop)]

/// Adam and the learning-rate schedule live in `fewview-optim`, shared with the Gaussian trainer.
pub use fewview_optim as adam;
pub mod bench;
pub mod bundle;
pub mod checkpoint;
pub use fewview_scene::cputime;
pub mod error;
pub mod extract;
pub mod field;
pub mod global_start;
pub mod hashgrid;
pub mod losses;
pub mod matching;
pub mod mlp;
pub mod patch_adjustment;
pub mod pipeline;
pub mod pose;
pub mod rays;
pub mod render;
pub mod schedule;
mod schur;
pub mod sdf_scene;
pub mod table1;
pub mod train;
pub mod warmup;

pub use error::{Result, SurfaceError};
