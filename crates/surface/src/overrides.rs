//! The user's settings of a run on top of a [`Schedule`]: [`Overrides`] holds them typed (the
//! `fewview surface` flags), and [`RunConfig::resolve`] turns them into the one configuration a
//! run uses, before any data is loaded, so that a contradiction fails at once.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::config::{InitialPoses, RunConfig};
use crate::error::{Result, SurfaceError};
use crate::field::{EncoderKind, FdScheme};
use crate::matching::densify::DensifyOptions;
use crate::matching::learned::MatcherKind;
use crate::matching::refine::{AffineRefineOptions, WarpModel};
use crate::matching::sift::SiftOptions;
use crate::patch_adjustment::PatchAdjustmentOptions;
use crate::schedule::Schedule;
use crate::warmup::{Connectivity, WarmupOptions};
use fewview_optim::ExpSchedule;
use fewview_sfm::bundle::BundleOptions;

/// Whether and how dense matches are grown from the sparse ones
/// ([`RunConfig::densify`], [`RunConfig::densify_if_needed`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Densify {
    /// As the schedule says: with [`Schedule::Cpu`], only when the sparse matches cannot tie
    /// the views together for the warm-up.
    #[default]
    Auto,
    /// Sparse matches only.
    Off,
    /// Always, on a grid of this spacing (pixels of the matching images).
    Spacing(usize),
}

impl FromStr for Densify {
    type Err = String;

    /// `auto`, `off` (or `0`), or a grid spacing in pixels.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "auto" => Ok(Self::Auto),
            "off" | "0" => Ok(Self::Off),
            px => px
                .parse()
                .map(Self::Spacing)
                .map_err(|_| format!("{px:?}: expected a grid spacing in pixels, auto or off")),
        }
    }
}

impl fmt::Display for Densify {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Auto => f.write_str("auto"),
            Self::Off => f.write_str("off"),
            Self::Spacing(px) => write!(f, "{px}"),
        }
    }
}

/// The loss terms a run may switch off (ablations); all on by default.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LossSwitches {
    pub matching: bool,
    pub ncc: bool,
    pub geometric_consistency: bool,
    pub uncertainty: bool,
    pub psdf: bool,
    pub eikonal: bool,
}

impl Default for LossSwitches {
    fn default() -> Self {
        Self {
            matching: true,
            ncc: true,
            geometric_consistency: true,
            uncertainty: true,
            psdf: true,
            eikonal: true,
        }
    }
}

/// Loss weights that replace the defaults of [`crate::train::LossConfig`] when given.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LossWeights {
    pub mc: Option<f32>,
    pub u: Option<f32>,
    pub gc: Option<f32>,
    pub geo: Option<f32>,
    pub psdf: Option<f32>,
}

/// σ of the se(3) noise on the ground-truth poses a run starts from by default (the surface
/// paper's noisy-pose setting).
pub const DEFAULT_POSE_NOISE: f64 = 0.15;

/// A run's settings as the user gives them. `None` and [`Densify::Auto`] leave the choice to
/// the [`Schedule`]; an explicit value wins over it. The defaults are `fewview surface`'s.
#[derive(Clone, Debug, PartialEq)]
pub struct Overrides {
    pub iterations: usize,
    pub rays_per_batch: usize,
    pub matches_per_batch: usize,
    /// Seed of the noise, sampling, initialisation and the matcher's RANSAC.
    pub seed: u64,
    pub initial_poses: InitialPoses,
    /// Replaces the schedule's pose learning rate (and its fallback timing).
    pub pose_lr: Option<ExpSchedule>,
    /// Replaces the schedule's pose start (and its fallback timing), in [0, 1].
    pub pose_start: Option<f64>,
    pub refine_poses: bool,
    /// In (0, 180] degrees ([`RunConfig::max_pair_angle_deg`]).
    pub max_pair_angle_deg: f64,
    /// Which matcher finds the correspondences.
    pub matcher: MatcherKind,
    /// The sub-pixel refinement's warp; `None` keeps the matcher's output.
    pub match_refine: Option<WarpModel>,
    /// With [`WarpModel::Quadratic`] only ([`AffineRefineOptions::max_bend_px`]).
    pub match_max_bend_px: Option<f64>,
    pub densify: Densify,
    /// The epipolar warm-up on or off; `None`: as the schedule says.
    pub pose_warmup: Option<bool>,
    pub warmup_min_matches: usize,
    pub warmup_cauchy_px: f64,
    pub warmup_connectivity: Connectivity,
    /// The warm-up's covariance polish on or off; `None`: as the schedule says.
    pub warmup_covariance: Option<bool>,
    pub global_start: bool,
    /// The bundle adjustment on or off; `None`: as the schedule says.
    pub bundle_adjustment: Option<bool>,
    /// The patch adjustment on or off; `None`: as the schedule says.
    pub patch_adjustment: Option<bool>,
    pub encoder: EncoderKind,
    pub fd_scheme: FdScheme,
    pub n_coarse: usize,
    pub n_importance: usize,
    pub losses: LossSwitches,
    pub weights: LossWeights,
    pub use_masks: bool,
    /// The coarse-to-fine window (α₁, α₂) as fractions of the iterations.
    pub c2f: Option<(f64, f64)>,
    pub mesh_resolution: usize,
    pub eval_views: usize,
    pub eval_scale: u32,
    pub checkpoint_every: usize,
}

impl Default for Overrides {
    fn default() -> Self {
        Self {
            iterations: 2000,
            rays_per_batch: 512,
            matches_per_batch: 128,
            seed: 0,
            initial_poses: InitialPoses::NoisyGroundTruth {
                sigma: DEFAULT_POSE_NOISE,
            },
            pose_lr: None,
            pose_start: None,
            refine_poses: true,
            max_pair_angle_deg: 80.0,
            matcher: MatcherKind::Classical,
            match_refine: Some(WarpModel::Affine),
            match_max_bend_px: None,
            densify: Densify::Auto,
            pose_warmup: None,
            warmup_min_matches: 40,
            warmup_cauchy_px: WarmupOptions::default().cauchy_px,
            warmup_connectivity: Connectivity::Rigid,
            warmup_covariance: None,
            global_start: true,
            bundle_adjustment: None,
            patch_adjustment: None,
            encoder: EncoderKind::HashGrid,
            fd_scheme: FdScheme::Tetrahedron,
            n_coarse: 32,
            n_importance: 32,
            losses: LossSwitches::default(),
            weights: LossWeights::default(),
            use_masks: true,
            c2f: None,
            mesh_resolution: 256,
            eval_views: 5,
            eval_scale: 1,
            checkpoint_every: 250,
        }
    }
}

impl RunConfig {
    /// The configuration of a run: `schedule`'s settings with `overrides` on top. An explicit
    /// pose start or learning rate is what the user asked for, warm-up or not, so it also
    /// clears the schedule's fallback timing and its hold after the patch adjustment.
    pub fn resolve(schedule: Schedule, overrides: &Overrides) -> Result<Self> {
        let o = overrides;
        let mut c = RunConfig::default();
        schedule.apply(&mut c);
        c.resolve_pose_timing(o)?;
        c.resolve_training(o);
        c.initial_poses = o.initial_poses.clone();
        c.resolve_pose_stages(o);
        let needs_matches = c.pose_warmup.is_some()
            || o.losses.matching
            || o.losses.ncc
            || o.losses.geometric_consistency;
        c.matcher = needs_matches.then(|| SiftOptions {
            seed: o.seed,
            ..Default::default()
        });
        c.resolve_matching(o)?;
        c.mesh_resolution = o.mesh_resolution;
        c.eval_views = o.eval_views;
        c.eval_scale = o.eval_scale;
        c.checkpoint_every = o.checkpoint_every;
        Ok(c)
    }

    fn resolve_pose_timing(&mut self, o: &Overrides) -> Result<()> {
        if let Some(start) = o.pose_start {
            if !(0.0..=1.0).contains(&start) {
                return Err(SurfaceError::invalid(
                    format!("--pose-start {start}"),
                    "expected a fraction in [0, 1]",
                ));
            }
            self.train.pose_start = start;
            self.pose_timing_without_warmup = None;
            self.hold_poses_after_patch_adjustment = false;
        }
        if let Some(lr) = o.pose_lr {
            self.train.pose_lr = lr;
            self.pose_timing_without_warmup = None;
            self.hold_poses_after_patch_adjustment = false;
        }
        Ok(())
    }

    fn resolve_training(&mut self, o: &Overrides) {
        let t = &mut self.train;
        t.iterations = o.iterations;
        t.rays_per_batch = o.rays_per_batch;
        t.matches_per_batch = o.matches_per_batch;
        t.seed = o.seed;
        t.refine_poses = o.refine_poses;
        t.use_masks = o.use_masks;
        t.sample.n_coarse = o.n_coarse;
        t.sample.n_importance = o.n_importance;
        t.field.encoder = o.encoder;
        t.field.fd_scheme = o.fd_scheme;
        if let Some(c2f) = o.c2f {
            t.c2f = c2f;
        }
        let l = &mut t.losses;
        l.matching = o.losses.matching;
        l.ncc = o.losses.ncc;
        l.geometric_consistency = o.losses.geometric_consistency;
        l.uncertainty = o.losses.uncertainty;
        l.psdf = o.losses.psdf;
        l.eikonal = o.losses.eikonal;
        let w = &o.weights;
        for (weight, given) in [
            (&mut l.lambda_mc, w.mc),
            (&mut l.lambda_u, w.u),
            (&mut l.lambda_gc, w.gc),
            (&mut l.lambda_geo, w.geo),
            (&mut l.lambda_psdf, w.psdf),
        ] {
            if let Some(v) = given {
                *weight = v;
            }
        }
    }

    /// The warm-up, its covariance polish, and the bundle and patch adjustments after it: each
    /// as the schedule says unless `o` switches it. Poses held fixed (`refine_poses` off) hold
    /// before training too: the three stages are off unless `o` switches one on.
    fn resolve_pose_stages(&mut self, o: &Overrides) {
        let scheduled = self.pose_warmup.filter(|_| o.refine_poses);
        let warm_up = o.pose_warmup.unwrap_or(scheduled.is_some());
        let covariance_polish = o
            .warmup_covariance
            .unwrap_or(scheduled.is_some_and(|w| w.covariance_polish));
        let patch_adjustment = o
            .patch_adjustment
            .unwrap_or(self.patch_adjustment.is_some() && o.refine_poses);
        self.patch_adjustment = patch_adjustment.then(PatchAdjustmentOptions::default);
        match o.bundle_adjustment {
            Some(false) => self.bundle_adjustment = None,
            Some(true) => {
                self.bundle_adjustment = self.bundle_adjustment.or(Some(BundleOptions::default()));
            }
            None if !o.refine_poses => self.bundle_adjustment = None,
            None => {}
        }
        self.pose_warmup = warm_up.then(|| WarmupOptions {
            min_matches_per_pair: o.warmup_min_matches,
            connectivity: o.warmup_connectivity,
            cauchy_px: o.warmup_cauchy_px,
            covariance_polish,
            global_start: o.global_start,
            ..Default::default()
        });
    }

    fn resolve_matching(&mut self, o: &Overrides) -> Result<()> {
        let angle = o.max_pair_angle_deg;
        if !(angle > 0.0 && angle <= 180.0) {
            return Err(SurfaceError::invalid(
                format!("--max-pair-angle {angle}"),
                "expected degrees in (0, 180]",
            ));
        }
        self.max_pair_angle_deg = angle;
        self.matcher_kind = o.matcher;
        if o.match_max_bend_px.is_some() && o.match_refine != Some(WarpModel::Quadratic) {
            return Err(SurfaceError::invalid(
                "--match-max-bend",
                "applies to --match-refine quadratic only",
            ));
        }
        self.match_refinement = o.match_refine.map(|warp| AffineRefineOptions {
            warp,
            max_bend_px: o.match_max_bend_px,
            ..Default::default()
        });
        match o.densify {
            Densify::Auto => {}
            Densify::Off | Densify::Spacing(0) => self.densify_if_needed = None,
            Densify::Spacing(spacing_px) => {
                self.densify = Some(DensifyOptions {
                    spacing_px,
                    ..Default::default()
                });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Held poses hold before training too: a run on exact poses once had the CPU schedule's
    /// warm-up replace them from wrong matches, with `--no-pose-refinement` given.
    #[test]
    fn held_poses_switch_the_pose_stages_off_unless_asked() {
        let held = Overrides {
            refine_poses: false,
            ..Overrides::default()
        };
        let c = RunConfig::resolve(Schedule::Cpu, &held).unwrap();
        assert!(!c.train.refine_poses);
        assert!(c.pose_warmup.is_none());
        assert!(c.bundle_adjustment.is_none() && c.patch_adjustment.is_none());
        // Switched on explicitly, a stage still runs.
        let asked = Overrides {
            pose_warmup: Some(true),
            bundle_adjustment: Some(true),
            ..held
        };
        let c = RunConfig::resolve(Schedule::Cpu, &asked).unwrap();
        assert!(c.pose_warmup.is_some() && c.bundle_adjustment.is_some());
        assert!(c.patch_adjustment.is_none());
        // Refined poses keep the schedule's stages.
        let c = RunConfig::resolve(Schedule::Cpu, &Overrides::default()).unwrap();
        assert!(c.pose_warmup.is_some() && c.bundle_adjustment.is_some());
        assert!(c.patch_adjustment.is_some());
    }
}
