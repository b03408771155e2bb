#![doc = include_str!("../README.md")]
//! Metrics the papers report: image quality (PSNR, SSIM, and LPIPS with the default `lpips`
//! feature), temporal and transition metrics, and camera pose error.

pub mod bench;
pub mod error;
pub mod flow;
pub mod gain;
#[cfg(feature = "lpips")]
pub mod lpips;
pub mod popping;
pub mod pose_error;
pub mod psnr;
pub mod relative_pose;
pub mod ssim;
pub mod temporal;

pub use error::MetricsError;
pub use flow::{flow_between, path_flows};
pub use gain::{gain_fit, gain_matched};
pub use popping::{Popping, local_popping};
pub use psnr::{mse, psnr, psnr_from_mse, psnr_masked};
pub use ssim::{
    SsimBorder, SsimOptions, SsimWorkspace, ssim, ssim_masked, ssim_masked_with_grad, ssim_with,
    ssim_with_grad, ssim_with_grad_f64,
};
