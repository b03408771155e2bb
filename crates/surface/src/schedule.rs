//! Pose schedules: when the camera poses start to move and how fast, before and after the
//! epipolar warm-up.
//!
//! Paper 001 §B.1 refines the poses from the first iteration with their own Adam,
//! 10⁻³ → 10⁻⁴, over 100k GPU iterations, from PDC-Net's dense matches. On a CPU budget of
//! about 2000 iterations that schedule does not converge: while the field is young its colour
//! and correspondence gradients pull the poses away (crate README, "Measured"). The schedule
//! that converges here ([`Schedule::Cpu`], measured on DTU scan65's narrow triplet:
//! 12° → 0.083–0.092°, t×100 0.34–0.42) first refines the poses on the matches' epipolar
//! constraints alone ([`crate::warmup`]), then holds them while the field forms and releases
//! them for the last quarter at a tenth of the paper's rate. All three are deviations from the
//! paper; [`Schedule::Paper`] keeps the paper's.

use serde::{Deserialize, Serialize};

use crate::adam::ExpSchedule;
use crate::bundle::BundleOptions;
use crate::matching::densify::DensifyOptions;
use crate::patch_adjustment::PatchAdjustmentOptions;
use crate::pipeline::RunConfig;
use crate::train::TrainConfig;
use crate::warmup::WarmupOptions;

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
    /// Paper 001 §B.1: refined from the first iteration, 10⁻³ → 10⁻⁴.
    pub const PAPER: Self = Self {
        start: 0.0,
        lr: ExpSchedule {
            start: 1e-3,
            end: 1e-4,
        },
    };

    /// After the warm-up (a deviation): held for the first 75 % of the iterations, then
    /// refined at a tenth of the paper's rate. Released earlier, a young field's gradients
    /// pull warmed-up poses away (seed 0 of the narrow DTU triplet: 0.106° → 0.343° after 500
    /// iterations released from the start); released late, they improve them
    /// (0.106° → 0.083°).
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

/// A named set of pose-schedule settings for [`RunConfig`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Schedule {
    /// Paper 001: no warm-up, poses refined from the first iteration at 10⁻³ → 10⁻⁴.
    Paper,
    /// The CPU schedule that converges (the module docs): the epipolar warm-up, then
    /// [`PoseTiming::LATE_RELEASE`]. When the sparse matches cannot tie the views together for
    /// the warm-up, dense ones are grown on a 4-pixel grid first
    /// ([`RunConfig::densify_if_needed`]), and the warm-up ends with the covariance polish
    /// ([`WarmupOptions::covariance_polish`]), followed by the bundle adjustment of the
    /// matches' tracks ([`RunConfig::bundle_adjustment`]) and, on dense matches, the
    /// photometric patch adjustment ([`RunConfig::patch_adjustment`]), whose poses are then
    /// kept for the whole run ([`RunConfig::hold_poses_after_patch_adjustment`]). When the
    /// warm-up still declines (e.g. a ring of views whose neighbours alone are matched),
    /// holding the unrefined noisy poses for most of the run would waste it, so the run falls
    /// back to [`PoseTiming::PAPER`] ([`RunConfig::pose_timing_without_warmup`]).
    #[default]
    Cpu,
}

impl Schedule {
    /// Sets the warm-up, the pose timing, the densification if needed and the fallback of
    /// `config` for this schedule.
    pub fn apply(self, config: &mut RunConfig) {
        match self {
            Schedule::Paper => {
                config.pose_warmup = None;
                PoseTiming::PAPER.apply_to(&mut config.train);
                config.densify_if_needed = None;
                config.pose_timing_without_warmup = None;
                config.bundle_adjustment = None;
                config.patch_adjustment = None;
                config.hold_poses_after_patch_adjustment = false;
            }
            Schedule::Cpu => {
                config.pose_warmup = Some(WarmupOptions {
                    covariance_polish: true,
                    ..Default::default()
                });
                PoseTiming::LATE_RELEASE.apply_to(&mut config.train);
                config.densify_if_needed = Some(DensifyOptions {
                    spacing_px: 4,
                    compose_unmatched_pairs: true,
                    ..Default::default()
                });
                config.pose_timing_without_warmup = Some(PoseTiming::PAPER);
                config.bundle_adjustment = Some(BundleOptions::default());
                config.patch_adjustment = Some(PatchAdjustmentOptions::default());
                config.hold_poses_after_patch_adjustment = true;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_schedule_is_the_library_default() {
        let mut c = RunConfig::default();
        Schedule::Paper.apply(&mut c);
        assert_eq!(c, RunConfig::default());
        assert_eq!(PoseTiming::of(&c.train), PoseTiming::PAPER);
    }

    #[test]
    fn cpu_schedule_warms_up_releases_late_and_falls_back_to_the_paper() {
        let mut c = RunConfig::default();
        Schedule::Cpu.apply(&mut c);
        assert_eq!(
            c.pose_warmup,
            Some(WarmupOptions {
                covariance_polish: true,
                ..Default::default()
            })
        );
        assert_eq!(c.train.pose_start, 0.75);
        assert_eq!((c.train.pose_lr.start, c.train.pose_lr.end), (1e-4, 1e-5));
        assert_eq!(c.pose_timing_without_warmup, Some(PoseTiming::PAPER));
        assert_eq!(c.densify, None);
        assert_eq!(c.densify_if_needed.as_ref().map(|d| d.spacing_px), Some(4));
        assert_eq!(c.bundle_adjustment, Some(BundleOptions::default()));
        assert_eq!(c.patch_adjustment, Some(PatchAdjustmentOptions::default()));
        assert!(c.hold_poses_after_patch_adjustment);
        // After a patch adjustment the poses are held for the whole run.
        let ran = warmup_report(None);
        let (held, fell_back) = c.effective_train(Some(&ran), true);
        assert_eq!((held.pose_start, fell_back), (1.0, false));
        assert_eq!(c.effective_train(Some(&ran), false).0.pose_start, 0.75);
        // Back to the paper's clears all of it.
        Schedule::Paper.apply(&mut c);
        assert_eq!(c, RunConfig::default());
    }

    fn warmup_report(skipped: Option<&str>) -> crate::warmup::WarmupReport {
        crate::warmup::WarmupReport {
            skipped: skipped.map(String::from),
            iterations: 0,
            scales_px: Vec::new(),
            in_front: 1.0,
            initial_median_px: 1.0,
            final_median_px: 1.0,
            ..crate::warmup::WarmupReport::unstarted()
        }
    }

    #[test]
    fn a_declined_warm_up_switches_to_the_fallback_timing_only() {
        let mut c = RunConfig::default();
        Schedule::Cpu.apply(&mut c);
        let ran = warmup_report(None);
        let declined = warmup_report(Some("too few matches"));
        let (train, fell_back) = c.effective_train(Some(&ran), false);
        assert_eq!((train, fell_back), (c.train.clone(), false));
        let (train, fell_back) = c.effective_train(Some(&declined), false);
        assert!(fell_back);
        assert_eq!(PoseTiming::of(&train), PoseTiming::PAPER);
        // Everything else is the configured training.
        let mut expected = c.train.clone();
        PoseTiming::PAPER.apply_to(&mut expected);
        assert_eq!(train, expected);
        // Without a fallback, or without a warm-up, the configuration is used as it is.
        c.pose_timing_without_warmup = None;
        assert_eq!(
            c.effective_train(Some(&declined), false),
            (c.train.clone(), false)
        );
        Schedule::Cpu.apply(&mut c);
        assert_eq!(c.effective_train(None, false), (c.train.clone(), false));
    }
}
