//! The patch adjustment's settings.

use serde::{Deserialize, Serialize};

/// Options of [`super::adjust_patches`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PatchAdjustmentOptions {
    /// Half-size `h` of the `(2h + 1)²` window, pixels of the matching images (the Lucas–Kanade
    /// refinement's).
    pub half_window: usize,
    /// σ (pixels) of the Gaussian blur applied to the images first (the refinement's).
    pub blur_sigma: f32,
    /// A match seeds a patch only when its window lies inside the reference view's mask and,
    /// at the start, correlates with its second view by at least this (NCC).
    pub min_ncc: f64,
    /// A further view joins a patch when the patch's warped window correlates by at least this.
    pub join_ncc: f64,
    /// Iterations before further views are tried.
    pub join_after: usize,
    /// Matches of the same pair whose triangulated points the starting normal is fitted to.
    pub neighbours: usize,
    /// Scale of the Cauchy weights, in robust standard deviations of the residuals.
    pub cauchy_sigmas: f64,
    /// Levenberg–Marquardt iterations.
    pub max_iterations: usize,
    /// Stop when an accepted step lowers the robust cost by less than this fraction.
    pub tolerance: f64,
}

impl Default for PatchAdjustmentOptions {
    /// The settings the CPU schedule runs with.
    fn default() -> Self {
        Self {
            half_window: 10,
            blur_sigma: 0.7,
            min_ncc: 0.9,
            join_ncc: 0.85,
            join_after: 3,
            neighbours: 12,
            cauchy_sigmas: 2.0,
            max_iterations: 40,
            tolerance: 1e-5,
        }
    }
}
