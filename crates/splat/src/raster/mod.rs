//! The differentiable 3D Gaussian splatting rasterizer (Kerbl et al. 2023), on the CPU.
//!
//! Stages, each in its own module, as in the reference CUDA rasterizer:
//! 1. [`project`]: per Gaussian, camera transform, EWA projection of the 3D covariance with the
//!    +0.3 px low-pass dilation, conic, SH colour, sigmoid opacity, screen bounding box.
//! 2. [`tiles`]: 16×16 tile binning and front-to-back depth ordering.
//! 3. [`blend`]: per tile, front-to-back alpha blending (α ≤ 0.99, skip α < 1/255, stop before
//!    the transmittance would fall below 1e-4); outputs RGB (+ background), expected depth
//!    `Σ wᵢ zᵢ` and alpha `1 − T`; [`kernels`] picks the build of its loops the CPU runs best
//!    (AVX-512, AVX2 + FMA, or portable).
//!
//! The backward pass runs the same stages in reverse with exact gradients (see
//! [`backward`]). Every function is generic over [`Real`](crate::real::Real) so the `f64`
//! instantiation checks the `f32` code path against finite differences.
//! [`reference`](mod@reference) is an independent naive per-pixel renderer used as the forward
//! test oracle and as the benchmark yardstick.
//!
//! **Screen bounding box.** Instead of the 3σ square of the reference code, a Gaussian is binned
//! to the tiles its `α ≥ 1/255` ellipse touches (half-widths `sqrt(2 ln(255 o) Σ₂ᴰ_xx)`, etc.).
//! Every pixel outside it would be skipped by the α test anyway, so the image is exactly the
//! per-pixel definition above, independent of tiling (the reference code's 3σ square can drop a
//! few pixels of opaque Gaussians at tile edges); it also bins low-opacity Gaussians to fewer tiles.

pub mod blend;
pub mod inputs;
pub mod kernels;
pub mod project;
pub mod reference;
pub mod render;
pub mod tiles;

pub use inputs::{
    ALPHA_MAX, ALPHA_MIN, DILATION, FOV_CLAMP, GaussianRefs, RenderCamera, RenderSettings, T_MIN,
    TILE, sh_degree_of,
};
pub use render::{ForwardContext, ForwardOutput, ParamGradients, backward, forward};

#[cfg(test)]
pub(crate) mod tests;
