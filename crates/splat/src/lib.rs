#![doc = include_str!("../README.md")]
//! 3D Gaussian splatting (Kerbl et al. 2023): the Gaussian model, a differentiable tile rasterizer
//! exposed as a Burn custom autodiff op (CPU kernels in [`raster`]; with the feature `gpu`, CubeCL
//! kernels in `gpu` behind the same op, chosen by [`ComputeDevice`]), SH colour, the Inria PLY
//! format and sparse-view training.

pub mod bench;
#[cfg(feature = "gpu")]
pub mod bench_gpu;
pub mod benchmark;
pub use fewview_scene::cputime;
pub mod device;
pub mod eval;
pub mod floaters;
#[cfg(feature = "gpu")]
pub mod gpu;
pub mod init;
pub mod loss;
pub mod model;
pub mod op;
pub mod pipeline;
pub mod ply;
pub mod pseudo_depth;
pub mod raster;
pub mod real;
pub mod sh;
pub mod sky_shell;
pub mod stereo_depth;
pub mod stereo_pair;
pub mod stereo_pair_check;
pub mod stereo_start;
pub mod surface_start;
pub mod train;

pub use device::{ComputeDevice, DeviceError};
pub use model::GaussianModel;
pub use op::{GaussianTensors, PairCountCheck, RenderTensors, RenderView, render, render_deferred};
pub use pipeline::{RunConfig, render_path, train_run};
pub use ply::{read_ply, write_ply};
pub use train::{TrainConfig, Trainer};
