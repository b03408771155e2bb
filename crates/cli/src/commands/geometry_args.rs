//! The few-view geometry regularisers' flags, shared by every command that trains.

use clap::Args;
use fewview_splat::TrainConfig;
use fewview_splat::pipeline::RunConfig;
use fewview_splat::train::pair::CoRegConfig;

/// Regularisers of the geometry that a few views leave (each off by default).
#[derive(Debug, Clone, Args)]
pub struct GeometryArgs {
    /// Weight of the stereo start's depth as a loss, 0: off.
    ///
    /// Weight of the stereo start's depth as a training loss: each training render's depth is
    /// pulled to the depth stereo accepted at its pixels (R^c fully, R^o half, R^s not), as a
    /// relative L1. Only with the stereo start.
    #[arg(long, value_name = "W", default_value_t = RunConfig::new(TrainConfig::sparse_view(1)).stereo_depth_weight,
          value_parser = super::number_args::non_negative_f32)]
    pub stereo_depth_weight: f32,
    /// Weight of the stereo depth seen from pseudo views, 0: off [default: 0; benchmark
    /// --protocol dtu: 0.1].
    ///
    /// Weight of the stereo start's depth reprojected into a view between two training cameras
    /// at each iteration: that view's render is pulled to it (R^c fully, R^o half, R^s not, as a
    /// relative L1), which constrains the depth of Gaussians that the training views alone leave
    /// free. One extra render per iteration. Only with the stereo start. Default: off
    /// (`RunConfig`'s), but under `benchmark --protocol dtu` (`Protocol::pseudo_depth_weight`).
    #[arg(long, value_name = "W", value_parser = super::number_args::non_negative_f32)]
    pub pseudo_depth_weight: Option<f32>,
    /// Weight of the floater loss, 0: off.
    ///
    /// Weight of the floater loss: a Gaussian that one training view sees alone, in front of
    /// the depth stereo confirmed there, has its opacity pulled down until densification prunes
    /// it. Only with the stereo start.
    #[arg(long, value_name = "W", default_value_t = RunConfig::new(TrainConfig::sparse_view(1)).floater_weight,
          value_parser = super::number_args::non_negative_f32)]
    pub floater_weight: f32,
    /// CoR-GS: two fields regularised by their disagreement.
    ///
    /// CoR-GS's co-regularisation: a second field trains beside the first from the same start
    /// with other random draws; Gaussians without a counterpart in the other field within
    /// `--co-reg-tau` are pruned every 5 densification steps, and each field's render of a view
    /// between the training cameras is pulled to the other's. Doubles the training time or more.
    #[arg(long)]
    pub co_reg: bool,
    /// CoR-GS co-pruning distance, a fraction of the scene's depth scale.
    ///
    /// CoR-GS's co-pruning distance τ as a fraction of the scene's depth scale (the median
    /// distance of the Gaussians to their nearest training camera).
    #[arg(long, value_name = "F", default_value_t = CoRegConfig::default().tau,
          requires = "co_reg", value_parser = super::number_args::non_negative_f32)]
    pub co_reg_tau: f32,
    /// CoR-GS pseudo-view weight λ_p (0: co-pruning only).
    #[arg(long, value_name = "W", default_value_t = CoRegConfig::default().pseudo_weight,
          requires = "co_reg", value_parser = super::number_args::non_negative_f32)]
    pub co_reg_pseudo_weight: f32,
}

impl GeometryArgs {
    /// CoR-GS's configuration, when `--co-reg` asks for the pair.
    pub fn co_reg(&self) -> Option<CoRegConfig> {
        self.co_reg.then_some(CoRegConfig {
            tau: self.co_reg_tau,
            pseudo_weight: self.co_reg_pseudo_weight,
            ..CoRegConfig::default()
        })
    }
}
