//! Blending two images with two validity masks (the fusion paper §4, Fig. 2 and Fig. 9): the
//! occlusion-aware Poisson blend of Eq. (3), standard Poisson blending (Pérez et al. 2003),
//! Laplacian-pyramid blending (Burt & Adelson 1983) and Gaussian feathering.
//!
//! Images are H×W×C `f32` ([`fewview_scene::Image`]) of equal size and channel count; masks are
//! `W·H` booleans, row-major (`true` = the image is valid there). Pixels valid in neither image
//! come out 0.

mod feather;
mod inputs;
mod poisson;
mod pyramid;
pub mod solver;

pub use feather::{gaussian_blur, gaussian_feather_blend};
pub use inputs::{Weights, mask_from_image};
pub use poisson::{
    PoissonOptions, PoissonStats, occlusion_aware_poisson, occlusion_aware_poisson_with,
    overlap_size, poisson_blend,
};
pub use pyramid::laplacian_pyramid_blend;
pub use solver::{SolveStats, Solver};

/// The blending methods of Fig. 9.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlendMethod {
    OcclusionAwarePoisson,
    Poisson,
    LaplacianPyramid,
    GaussianFeather,
}

#[cfg(test)]
mod tests;
