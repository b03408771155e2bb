//! The network of "PoseGaussian: Pose-Driven Novel View Synthesis for Robust 3D Human
//! Reconstruction" (appendix, "Implementation Details" and Fig. 5), as Burn modules on whatever
//! device the caller passes (`Device::flex()` on the CPU, `.autodiff()` to train).
//!
//! - [`config`]: the four configuration variants, the `paper` and `cpu` presets, the stage plan.
//! - [`posemap`]: 2D joints → the pose map the pose encoder reads.
//! - [`se`], [`residual`], [`encoder`], [`decoder`], [`heads`]: the blocks, each documenting
//!   what the paper says and what was chosen where it is silent.
//! - [`model`]: [`PoseGaussianNet`], three encoders + decoder + heads.
//! - [`conv`]: the convolutions as one matrix product per kernel tap on the CPU (cheap
//!   gradients).
//! - [`flops`]: multiply-adds of one forward pass, from the configuration alone.
//! - [`checkpoint`]: weights on disk with their configuration, refused by any other network.

pub mod checkpoint;
pub mod config;
pub mod conv;
mod conv_taps;
pub mod decoder;
pub mod encoder;
pub mod flops;
pub mod heads;
pub mod model;
pub mod posemap;
pub mod residual;
pub mod resize;
pub mod se;
pub mod seed;

#[cfg(test)]
pub(crate) mod reference;
#[cfg(test)]
mod tests;

pub use config::{NetConfig, SKELETON_POSE_CHANNELS, StagePlan, Variant};
pub use flops::forward_macs;
pub use heads::HeadOutputs;
pub use model::{ForwardTimes, NetInput, PoseGaussianNet};
pub use posemap::{PoseMapConfig, PoseMapStyle, pose_map, pose_map_channels};
