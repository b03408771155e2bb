//! A run's whole configuration, [`RunConfig`], and the named pose schedules it starts from
//! ([`Schedule::apply`]); [`crate::overrides`] resolves the user's settings on top of them.

use serde::{Deserialize, Serialize};

use crate::matching::densify::DensifyOptions;
use crate::matching::learned::MatcherKind;
use crate::matching::refine::AffineRefineOptions;
use crate::matching::sift::SiftOptions;
use crate::patch_adjustment::PatchAdjustmentOptions;
use crate::schedule::{PoseTiming, Schedule};
use crate::train::config::TrainConfig;
use crate::warmup::{WarmupOptions, WarmupReport};
use fewview_sfm::bundle::BundleOptions;

/// Where the initial poses come from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum InitialPoses {
    /// Ground truth perturbed by se(3) noise `N(0, σ²)` from the run's seed (BARF/SPARF).
    NoisyGroundTruth { sigma: f64 },
    /// The poses as loaded (e.g. DTU's `cameras_linear_init.npz`); the ground truth for the
    /// errors then comes from `ground_truth` (a dataset loaded with the true cameras).
    AsLoaded,
}

impl InitialPoses {
    /// The same start with noise `sigma` where the start is noisy ground truth.
    pub fn with_noise(self, sigma: f64) -> Self {
        match self {
            Self::NoisyGroundTruth { .. } => Self::NoisyGroundTruth { sigma },
            other => other,
        }
    }
}

/// The command line names the two starts; the noise σ is a flag of its own (see
/// [`InitialPoses::with_noise`]).
#[cfg(feature = "cli")]
impl clap::ValueEnum for InitialPoses {
    fn value_variants<'a>() -> &'a [Self] {
        &[Self::NoisyGroundTruth { sigma: 0.0 }, Self::AsLoaded]
    }

    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        use clap::builder::PossibleValue;
        Some(match self {
            Self::NoisyGroundTruth { .. } => {
                PossibleValue::new("noisy").help("the ground truth perturbed by --pose-noise")
            }
            Self::AsLoaded => PossibleValue::new("loaded").help("the dataset's poses as loaded"),
        })
    }
}

/// Everything about a run besides the dataset.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunConfig {
    pub train: TrainConfig,
    pub initial_poses: InitialPoses,
    /// `None`: no correspondences (colour-only joint optimisation, BARF-like). The SIFT
    /// settings; their RANSAC filter also applies to the learned matchers.
    pub matcher: Option<SiftOptions>,
    /// Which matcher finds the correspondences (runs written before the choice existed used
    /// the classical one).
    #[serde(default)]
    pub matcher_kind: MatcherKind,
    /// Iterations between checkpoints (0: none).
    pub checkpoint_every: usize,
    pub mesh_resolution: usize,
    /// Test views rendered and scored (the first ones of the dataset's test split).
    pub eval_views: usize,
    /// Render test views at this fraction of their size (1 = full).
    pub eval_scale: u32,
    /// Deviation, off by default: refine the initial poses on the matches' epipolar
    /// constraints alone before the joint optimisation ([`crate::warmup`]).
    #[serde(default)]
    pub pose_warmup: Option<WarmupOptions>,
    /// Match only pairs of views whose optical axes, under the initial poses, are at most this
    /// many degrees apart ([`crate::matching::covisible_pairs`]). The surface paper matches every pair
    /// of its three views; on rings of views the default drops the opposite ones. Noise can push
    /// a wide pair past it: pass 180 to match every pair as the paper does, or let dense
    /// matching compose that pair through a middle view (`DensifyOptions::compose_unmatched_pairs`, as
    /// [`Schedule::Cpu`] does).
    #[serde(default = "default_max_pair_angle")]
    pub max_pair_angle_deg: f64,
    /// Deviation, on by default: refine each match's second end to sub-pixel precision by
    /// affine Lucas–Kanade ([`crate::matching::refine::refine_matches`]). `None` keeps the matcher's output (the
    /// behaviour of configurations written before the option existed).
    #[serde(default)]
    pub match_refinement: Option<AffineRefineOptions>,
    /// Deviation, off by default: grow dense matches from the (refined) sparse ones by affine
    /// Lucas–Kanade with forward–backward checks ([`crate::matching::densify::densify_matches`]), standing in for the
    /// density of the surface paper's PDC-Net matches.
    #[serde(default)]
    pub densify: Option<DensifyOptions>,
    /// Deviation, used by [`Schedule::Cpu`]: when [`Self::densify`] is off,
    /// the warm-up is on, and the refined sparse matches cannot tie the views together for it
    /// ([`crate::warmup::matches_tie_the_views`]; e.g. DTU's wide triplet), grow dense matches
    /// with these options all the same. Where the sparse matches suffice the dense ones do not
    /// help.
    #[serde(default)]
    pub densify_if_needed: Option<DensifyOptions>,
    /// The pose timing the training uses instead of `train`'s when [`Self::pose_warmup`] is
    /// asked for but declines (too few matches to tie the views together): a late release at
    /// a low rate assumes warmed-up poses ([`Schedule::Cpu`]). `None` keeps
    /// `train`'s.
    #[serde(default)]
    pub pose_timing_without_warmup: Option<PoseTiming>,
    /// Deviation, used by [`Schedule::Cpu`]: after an epipolar warm-up, adjust
    /// the poses and the matches' tracks on their reprojection errors ([`crate::bundle`]).
    #[serde(default)]
    pub bundle_adjustment: Option<BundleOptions>,
    /// Deviation, used by [`Schedule::Cpu`]: after an epipolar warm-up that
    /// ran on dense matches, refine the poses photometrically on small planes seeded by the
    /// matches ([`crate::patch_adjustment`]).
    #[serde(default)]
    pub patch_adjustment: Option<PatchAdjustmentOptions>,
    /// Deviation, used by [`Schedule::Cpu`]: when the patch adjustment ran,
    /// keep its poses for the whole training (`pose_start` 1): released later in the run, the
    /// field's gradients move them away from the adjusted optimum.
    #[serde(default)]
    pub hold_poses_after_patch_adjustment: bool,
}

fn default_max_pair_angle() -> f64 {
    80.0
}

impl Default for RunConfig {
    fn default() -> Self {
        Self {
            train: TrainConfig::default(),
            initial_poses: InitialPoses::NoisyGroundTruth { sigma: 0.15 },
            matcher: Some(SiftOptions::default()),
            matcher_kind: MatcherKind::Classical,
            checkpoint_every: 500,
            mesh_resolution: 256,
            eval_views: 5,
            eval_scale: 1,
            pose_warmup: None,
            max_pair_angle_deg: default_max_pair_angle(),
            match_refinement: Some(AffineRefineOptions::default()),
            densify: None,
            densify_if_needed: None,
            pose_timing_without_warmup: None,
            bundle_adjustment: None,
            patch_adjustment: None,
            hold_poses_after_patch_adjustment: false,
        }
    }
}

impl RunConfig {
    /// The training configuration a run uses: `train`, with the pose timing replaced by
    /// [`Self::pose_timing_without_warmup`] when the warm-up was asked for and declined
    /// (`warmup` is its report). The flag says whether that happened.
    pub fn effective_train(
        &self,
        warmup: Option<&WarmupReport>,
        patches_adjusted: bool,
    ) -> (TrainConfig, bool) {
        let mut train = self.train.clone();
        if patches_adjusted && self.hold_poses_after_patch_adjustment {
            train.pose_start = 1.0;
        }
        let declined = warmup.is_some_and(|w| w.skipped.is_some());
        match self.pose_timing_without_warmup {
            Some(timing) if declined => {
                timing.apply_to(&mut train);
                (train, true)
            }
            _ => (train, false),
        }
    }
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
        // The poses are first placed by the warm-up (with its covariance polish), then the
        // tracks' bundle adjustment and, on dense matches, the patch adjustment.
        assert!(c.pose_warmup.as_ref().is_some_and(|w| w.covariance_polish));
        assert!(c.bundle_adjustment.is_some() && c.patch_adjustment.is_some());
        // Dense matches are grown only when the sparse ones cannot tie the views together.
        assert!(c.densify.is_none() && c.densify_if_needed.is_some());
        // The field then refines them later and more gently than the paper's schedule.
        let paper = PoseTiming::PAPER;
        assert!(c.train.pose_start > paper.start);
        assert!(c.train.pose_lr.start < paper.lr.start && c.train.pose_lr.end < paper.lr.end);
        // After a patch adjustment the poses are held for the whole run; otherwise released late.
        let ran = warmup_report(None);
        let (held, fell_back) = c.effective_train(Some(&ran), true);
        assert_eq!((held.pose_start, fell_back), (1.0, false));
        let (released, fell_back) = c.effective_train(Some(&ran), false);
        assert_eq!((released, fell_back), (c.train.clone(), false));
        // A declined warm-up falls back to the paper's timing.
        let declined = warmup_report(Some("too few matches"));
        let (train, fell_back) = c.effective_train(Some(&declined), false);
        assert!(fell_back);
        assert_eq!(PoseTiming::of(&train), paper);
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
