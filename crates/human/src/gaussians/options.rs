//! The choices of the per-pixel Gaussians and their source views.

use super::select::Nearness;

/// Choices of the per-pixel Gaussians and their source views that the paper leaves open.
#[derive(Clone, Debug, PartialEq)]
pub struct GaussianOptions {
    /// How many source views render a target (2: the paper builds on GPS-Gaussian's pair of
    /// views nearest the target).
    pub source_views: usize,
    /// How "nearest" is measured ([`Nearness`]).
    pub nearness: Nearness,
    /// Upper bound on a Gaussian's standard deviation, metres; `None` for none. GPS-Gaussian
    /// clamps its scale head at 0.01; the clamp also stops a Gaussian from smearing one pixel's
    /// colour over the body before the heads are trained.
    pub max_scale: Option<f32>,
}

impl Default for GaussianOptions {
    fn default() -> Self {
        Self {
            source_views: 2,
            nearness: Nearness::ViewDirection,
            max_scale: Some(0.01),
        }
    }
}
