//! Training hyper-parameters: the learning rates of the fusion paper §3 (= the Inria 3DGS defaults) and
//! a densification schedule rescaled for short sparse-view runs.

use serde::{Deserialize, Serialize};

use super::appearance::AppearanceConfig;
use fewview_optim::adam::AdamConfig;

/// Learning rates (the fusion paper §3; Kerbl et al. 2023).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LearningRates {
    /// Position learning rate at the first iteration, times the scene extent.
    pub position_init: f32,
    /// Position learning rate at iteration `position_decay_steps`, times the scene extent
    /// (exponential decay in between, constant after).
    pub position_final: f32,
    /// Length of the position learning-rate decay (Inria's `position_lr_max_steps`, 30k). It is
    /// not tied to the run length: a short run keeps the larger early learning rates, so
    /// Gaussians initialised at random still travel to the surface.
    pub position_decay_steps: usize,
    /// Diffuse colour (SH degree 0).
    pub f_dc: f32,
    /// Higher SH coefficients.
    pub f_rest: f32,
    pub opacity: f32,
    pub scaling: f32,
    pub rotation: f32,
}

impl Default for LearningRates {
    fn default() -> Self {
        Self {
            position_init: 1.6e-4,
            position_final: 1.6e-6,
            position_decay_steps: 30_000,
            f_dc: 0.0025,
            f_rest: 0.000125,
            opacity: 0.05,
            scaling: 0.005,
            rotation: 0.001,
        }
    }
}

/// Adaptive density control (3DGS §5.2).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DensifyConfig {
    /// First iteration after which densification runs.
    pub from_iter: usize,
    /// Densification stops at this iteration.
    pub until_iter: usize,
    pub interval: usize,
    /// Threshold on the average NDC-space positional gradient norm.
    pub grad_threshold: f32,
    /// Gaussians larger than this fraction of the scene extent are split, smaller ones cloned.
    pub percent_dense: f32,
    /// Gaussians below this opacity are pruned.
    pub min_opacity: f32,
    /// After the first opacity reset, Gaussians wider than this on screen (px) are pruned.
    pub max_screen_size: f32,
    /// ... and those larger than this fraction of the extent in world space.
    pub max_world_size: f32,
    /// Opacities are reset to at most 0.01 every this many iterations (while densifying).
    pub opacity_reset_interval: usize,
}

/// The largest dropout rate of [`TrainConfig::sparse_view`]: DropGaussian's γ.
pub const SPARSE_VIEW_DROPOUT: f32 = 0.2;

/// Everything a training run needs besides the data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    pub iterations: usize,
    /// Largest SH degree (coefficients are allocated for it).
    pub sh_degree: usize,
    /// The active SH degree grows by one every this many iterations.
    pub sh_increase_interval: usize,
    pub lr: LearningRates,
    pub adam: AdamConfig,
    /// λ of `(1 − λ) L1 + λ (1 − SSIM)`.
    pub lambda_dssim: f32,
    pub densify: DensifyConfig,
    pub seed: u64,
    /// Background colour composited behind the Gaussians during training and rendering.
    pub background: [f32; 3],
    /// Train each iteration over a random background colour, with the target image
    /// re-composited over the same colour, on views whose images have alpha (NeRF-synthetic
    /// RGBA). Gaussians must then match the alpha as well as the colour, so floaters that
    /// blend into a fixed white background are pruned. nerfstudio's splatfacto default for
    /// RGBA data, and [`TrainConfig::sparse_view`]'s; not in the fusion paper or Inria's 3DGS
    /// (whose `--random_background` leaves the targets composited over the fixed colour), so
    /// [`TrainConfig::inria`] leaves it off.
    #[serde(default)]
    pub random_background: bool,
    /// Gaussians closer than this to a camera (camera z) are culled.
    pub near_plane: f64,
    /// Save a checkpoint every this many iterations (0: only at the end).
    pub checkpoint_interval: usize,
    /// A learned colour transform per training photo (off by default; see
    /// [`super::appearance`]).
    #[serde(default)]
    pub appearance: AppearanceConfig,
    /// Largest opacity-dropout rate γ of DropGaussian ([`super::dropout`]), reached at the last
    /// iteration; 0: off.
    #[serde(default)]
    pub dropout: f32,
}

impl TrainConfig {
    /// The Inria schedule for 30k iterations (densify 500–15k every 100, opacity reset every
    /// 3000, SH degree up every 1000).
    pub fn inria() -> Self {
        Self {
            iterations: 30_000,
            sh_degree: 3,
            sh_increase_interval: 1000,
            lr: LearningRates::default(),
            adam: AdamConfig::inria_3dgs(),
            lambda_dssim: 0.2,
            densify: DensifyConfig {
                from_iter: 500,
                until_iter: 15_000,
                interval: 100,
                grad_threshold: 0.0002,
                percent_dense: 0.01,
                min_opacity: 0.005,
                max_screen_size: 20.0,
                max_world_size: 0.1,
                opacity_reset_interval: 3000,
            },
            seed: 0,
            background: [0.0; 3],
            random_background: false,
            near_plane: 0.2,
            checkpoint_interval: 1000,
            appearance: AppearanceConfig::default(),
            dropout: 0.0,
        }
    }

    /// The schedule for a short sparse-view run of `iterations` steps.
    ///
    /// With 3–8 views, each view is seen hundreds of times in a thousand iterations, and longer
    /// runs overfit: on fern 3-view the held-out PSNR peaks near iteration 500 and drifts down
    /// slowly after (`docs/guide/splatting.md`, "Schedule for short sparse-view runs"). So the Inria schedule is
    /// compressed: densification (clone/split every 100 iterations, as Inria) runs from 20% to
    /// 60% of the run instead of from iteration 500 to 15k of 30k; the opacity reset (Inria:
    /// every 3000) happens every `max(iterations / 3, 1000)` iterations while densifying, so not
    /// at all in runs of up to 1500 iterations; the SH degree grows every `iterations / 10`
    /// iterations (Inria reaches degree 3 at 10% of its run too); the position learning rate
    /// decays over the whole run. Learning rates and thresholds are Inria's. Views with alpha
    /// train over a random background ([`TrainConfig::random_background`]), and the photometric
    /// render drops Gaussians as DropGaussian does, up to its γ = 0.2 ([`super::dropout`]).
    pub fn sparse_view(iterations: usize) -> Self {
        let mut c = Self::inria();
        c.random_background = true;
        c.dropout = SPARSE_VIEW_DROPOUT;
        c.iterations = iterations;
        c.densify.from_iter = iterations / 5;
        c.densify.until_iter = iterations * 3 / 5;
        c.densify.opacity_reset_interval = (iterations / 3).max(1000);
        c.sh_increase_interval = (iterations / 10).max(1);
        c
    }

    /// Position learning rate at `iteration` (1-based), already scaled by the scene extent:
    /// log-linear from `position_init` to `position_final` over `position_decay_steps` (Inria's
    /// `get_expon_lr_func` with no warm-up delay).
    pub fn position_lr(&self, iteration: usize, extent: f32) -> f32 {
        let steps = self.lr.position_decay_steps.max(1) as f64;
        let t = (iteration as f64 / steps).clamp(0.0, 1.0);
        let (a, b) = (self.lr.position_init as f64, self.lr.position_final as f64);
        ((a.ln() * (1.0 - t) + b.ln() * t).exp() * extent as f64) as f32
    }

    /// The SH degree in use at `iteration` (1-based).
    pub fn active_sh_degree(&self, iteration: usize) -> usize {
        (iteration / self.sh_increase_interval.max(1)).min(self.sh_degree)
    }

    /// Checks the values make sense; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        if self.iterations == 0 {
            return Err("iterations must be at least 1".into());
        }
        if self.sh_degree > 3 {
            return Err(format!("sh_degree {} is above 3", self.sh_degree));
        }
        let lrs = [
            self.lr.position_init,
            self.lr.position_final,
            self.lr.f_dc,
            self.lr.f_rest,
            self.lr.opacity,
            self.lr.scaling,
            self.lr.rotation,
        ];
        if lrs.iter().any(|v| !v.is_finite() || *v < 0.0) {
            return Err("learning rates must be finite and non-negative".into());
        }
        if !(0.0..=1.0).contains(&self.lambda_dssim) {
            return Err(format!(
                "lambda_dssim {} is outside [0, 1]",
                self.lambda_dssim
            ));
        }
        if !(0.0..1.0).contains(&self.dropout) {
            return Err(format!("dropout rate {} is outside [0, 1)", self.dropout));
        }
        if self.densify.interval == 0 {
            return Err("densify interval must be at least 1".into());
        }
        self.appearance.validate()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn position_lr_decays_log_linearly() {
        let mut c = TrainConfig::sparse_view(1000);
        c.lr.position_decay_steps = 1000;
        assert!((c.position_lr(0, 2.0) - 3.2e-4).abs() < 1e-9);
        assert!((c.position_lr(1000, 2.0) - 3.2e-6).abs() < 1e-11);
        // Geometric mean at the midpoint; constant after the decay.
        assert!((c.position_lr(500, 1.0) - 1.6e-5).abs() < 1e-9);
        assert!((c.position_lr(5000, 1.0) - 1.6e-6).abs() < 1e-11);
    }

    #[test]
    fn sh_degree_grows_to_the_maximum() {
        let c = TrainConfig::sparse_view(3000);
        assert_eq!(c.active_sh_degree(1), 0);
        assert_eq!(c.active_sh_degree(300), 1);
        assert_eq!(c.active_sh_degree(2999), 3);
    }
}
