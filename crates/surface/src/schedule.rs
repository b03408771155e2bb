//! Pose schedules: when the camera poses start to move and how fast, before and after the
//! epipolar warm-up.
//!
//! The surface paper §B.1 refines the poses from the first iteration with their own Adam,
//! 10⁻³ → 10⁻⁴, over 100k GPU iterations, from PDC-Net's dense matches. On a CPU budget of
//! about 2000 iterations that schedule does not converge: while the field is young its colour
//! and correspondence gradients pull the poses away. The schedule that converges here
//! ([`Schedule::Cpu`]; figures in `docs/experiments.md`) first refines the poses on the
//! matches' epipolar constraints alone ([`crate::warmup`]), then holds them while the field forms and releases
//! them for the last quarter at a tenth of the paper's rate. All three are deviations from the
//! paper; [`Schedule::Paper`] keeps the paper's.

use serde::{Deserialize, Serialize};

use crate::train::config::TrainConfig;
use fewview_optim::ExpSchedule;

/// When the poses start to move (a fraction of the iterations) and their learning rate: the
/// two fields of [`TrainConfig`] a schedule sets.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseTiming {
    /// [`TrainConfig::pose_start`].
    pub start: f64,
    /// [`TrainConfig::pose_lr`].
    pub lr: ExpSchedule,
}

impl PoseTiming {
    /// The surface paper §B.1: refined from the first iteration, 10⁻³ → 10⁻⁴.
    pub const PAPER: Self = Self {
        start: 0.0,
        lr: ExpSchedule {
            start: 1e-3,
            end: 1e-4,
        },
    };

    /// After the warm-up (a deviation): held for the first 75 % of the iterations, then
    /// refined at a tenth of the paper's rate. Released earlier, a young field's gradients
    /// pull warmed-up poses away; released late, they improve them.
    pub const LATE_RELEASE: Self = Self {
        start: 0.75,
        lr: ExpSchedule {
            start: 1e-4,
            end: 1e-5,
        },
    };

    /// The timing `train` carries.
    pub fn of(train: &TrainConfig) -> Self {
        Self {
            start: train.pose_start,
            lr: train.pose_lr,
        }
    }

    /// Sets `train`'s pose start and learning rate.
    pub fn apply_to(&self, train: &mut TrainConfig) {
        train.pose_start = self.start;
        train.pose_lr = self.lr;
    }
}

/// A named set of pose-schedule settings for [`crate::config::RunConfig`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Schedule {
    /// The surface paper: no warm-up, poses refined from the first iteration at 10⁻³ → 10⁻⁴.
    Paper,
    /// The CPU schedule that converges (the module docs): the epipolar warm-up, then
    /// [`PoseTiming::LATE_RELEASE`]. When the sparse matches cannot tie the views together for
    /// the warm-up, dense ones are grown on a 4-pixel grid first
    /// ([`crate::config::RunConfig::densify_if_needed`]), and the warm-up ends with the covariance polish
    /// ([`crate::warmup::WarmupOptions::covariance_polish`]), followed by the bundle adjustment of the
    /// matches' tracks ([`crate::config::RunConfig::bundle_adjustment`]) and, on dense matches, the
    /// photometric patch adjustment ([`crate::config::RunConfig::patch_adjustment`]), whose poses are then
    /// kept for the whole run ([`crate::config::RunConfig::hold_poses_after_patch_adjustment`]). When the
    /// warm-up still declines (e.g. a ring of views whose neighbours alone are matched),
    /// holding the unrefined noisy poses for most of the run would waste it, so the run falls
    /// back to [`PoseTiming::PAPER`] ([`crate::config::RunConfig::pose_timing_without_warmup`]).
    #[default]
    #[cfg_attr(
        feature = "cli",
        value(help = "The epipolar warm-up and adjustments, then a late release of the poses")
    )]
    Cpu,
}
