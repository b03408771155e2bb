//! Per-pixel Gaussians of "PoseGaussian: Pose-Driven Novel View Synthesis for Robust 3D Human
//! Reconstruction" (appendix, "3D Gaussian Splatting Preliminary"): every foreground pixel of a
//! source view becomes one 3D Gaussian, and the Gaussians of the source views nearest a target
//! camera are rendered into it with fewview-splat's differentiable rasterizer.
//!
//! Per pixel `(x, y)` of a source view with camera `K, R, t` (world-to-camera):
//!
//! - **position** ("the estimated depth map through camera intrinsics"): the predicted z-depth
//!   `z` lifted through the pixel centre, `μ = C + z · Rᵀ K⁻¹ [x + ½, y + ½, 1]ᵀ` with `C` the
//!   camera centre. Pixel centres are at half-integers, the crate's convention (the loaders
//!   move the files' principal points by half a pixel, [`crate::opencv`]).
//! - **colour** ("directly retrieved as the mean colour value at each pixel"): the pixel's sRGB
//!   as the degree-0 SH coefficient of the Inria layout, `f_dc = (c − ½) / C0`, which the
//!   rasterizer turns back into `c` from every direction.
//! - **rotation**: the rotation head's unit quaternion, read in the source camera's frame and
//!   carried to the world by the camera-to-world rotation, `q_world = q_c2w ⊗ q`. The paper
//!   does not say in which frame; a network that sees one image can only predict orientations
//!   relative to its own camera consistently from every camera of the ring.
//! - **scale**: the scale head's values are standard deviations in the scene's units (metres),
//!   as in GPS-Gaussian, whose Softplus β = 100 our head copies
//!   ([`crate::net::NetConfig::scale_softplus_beta`]); they are capped at
//!   [`GaussianOptions::max_scale`] (GPS-Gaussian's 1 cm by default).
//! - **opacity**: [`crate::net::HeadOutputs::render_opacity`], α times the person probability.
//!
//! Only pixels inside the source view's mask spawn Gaussians. Everything from the maps onward is
//! Burn tensors on the maps' device, so gradients of a loss on the render reach the heads.
//!
//! - [`params`]: [`PixelMaps`], one view's parameter maps (from the heads, or given).
//! - [`pixels`]: [`pixel_gaussians`], one view's foreground pixels to Gaussians.
//! - [`select`]: [`nearest_sources`], the source cameras nearest a target.
//! - [`render`]: [`render_gaussians`] and [`novel_view`], the render into a target camera.

mod options;
pub mod params;
pub mod pixels;
pub mod render;
pub mod select;

#[cfg(test)]
mod tests;

pub use options::GaussianOptions;
pub use params::PixelMaps;
pub use pixels::{SourceView, pixel_gaussians};
pub use render::{Rendered, concat, novel_view, render_gaussians};
pub use select::{Nearness, nearest_sources};
