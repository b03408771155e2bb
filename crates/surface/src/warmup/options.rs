//! What the epipolar warm-up is asked ([`WarmupOptions`], [`Connectivity`]) and what it did
//! ([`WarmupReport`]).

use serde::{Deserialize, Serialize};

use fewview_sfm::global_start::PairPose;

/// Options of [`super::epipolar_warmup`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WarmupOptions {
    /// Final scale of the Cauchy loss of the Sampson distance (pixels).
    pub cauchy_px: f64,
    /// Smallest starting scale (pixels): the scale starts at twice the initial median distance
    /// or this, whichever is larger. Noisy poses can put matches only a few pixels off their
    /// lines while the rotation is far off (translation compensating); starting that narrow,
    /// the solver can settle in a worse minimum.
    pub start_px: f64,
    /// Levenberg–Marquardt iterations per scale.
    pub max_iterations: usize,
    /// Stop when the relative decrease of the robust cost falls below this.
    pub tolerance: f64,
    /// Skip the warm-up when some pair of views has fewer matches: with few matches and a
    /// quarter of them wrong, the poses overfit the outliers.
    pub min_matches_per_pair: usize,
    /// Which graphs of matched pairs the warm-up runs on ([`Connectivity`]).
    #[serde(default)]
    pub connectivity: Connectivity,
    /// After the annealing, one more Levenberg–Marquardt run at the final Cauchy scale with
    /// each match's distance divided by its standard deviation across its epipolar line, from
    /// the Lucas–Kanade covariance of its second end ([`Match::b_covariance`](crate::matching::Match::b_covariance), dense matches
    /// only), relative to the median one (`covariance_scaled`). Off by default.
    #[serde(default)]
    pub covariance_polish: bool,
    /// Also start one annealing run from the poses the matches imply on their own
    /// ([`mod@crate::global_start`]: five-point relative poses, rotation averaging, baseline
    /// directions). On by default; off, the runs start from the initial poses only.
    #[serde(default = "yes")]
    pub global_start: bool,
}

fn yes() -> bool {
    true
}

/// What the pairs of views with enough matches must form for the warm-up to run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Connectivity {
    /// The baseline directions of the pairs fix every camera centre up to one translation and
    /// one scale (parallel rigidity; e.g. triangles chained through shared edges): every
    /// baseline's length is tied to the others, so the whole camera set is fixed up to a
    /// similarity. (`rigid-triangles`, the name of the triangle-chain test this generalises,
    /// still reads.)
    #[default]
    #[serde(alias = "rigid-triangles")]
    #[cfg_attr(
        feature = "cli",
        value(
            alias = "triangles",
            help = "Baseline lengths tied together (e.g. chained triangles)"
        )
    )]
    Rigid,
    /// Any connected graph (a chain of three views, a ring). The relative rotations and the
    /// baseline directions are still fixed, but the lengths of baselines outside triangles are
    /// not: they keep the initial poses' values (the damped solver does not move along
    /// directions the cost cannot see) for the joint optimisation to correct. On the wide DTU
    /// triplet, whose outer pair shares almost no matches, this is the only way to run.
    #[cfg_attr(feature = "cli", value(help = "Any connected graph of pairs"))]
    Connected,
}

impl Default for WarmupOptions {
    fn default() -> Self {
        Self {
            cauchy_px: 1.0,
            start_px: 128.0,
            max_iterations: 50,
            tolerance: 1e-10,
            min_matches_per_pair: 40,
            connectivity: Connectivity::Rigid,
            covariance_polish: false,
            global_start: true,
        }
    }
}

/// What the warm-up did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WarmupReport {
    /// Why the poses were left as they were, when they were.
    pub skipped: Option<String>,
    pub iterations: usize,
    /// Scales of the Cauchy loss of the chosen run, in the order used.
    pub scales_px: Vec<f64>,
    /// Fraction of the matches whose rays meet in front of both cameras, for the result.
    pub in_front: f64,
    /// Median absolute Sampson distance (pixels) before and after.
    pub initial_median_px: f64,
    pub final_median_px: f64,
    /// Matches whose distances the covariance polish weighed (0 when it did not run).
    #[serde(default)]
    pub covariance_weighted: usize,
    /// The pairs' relative poses of the global start, when it ran.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub global_start: Vec<PairPose>,
    /// Why the global start was not used, when it was asked for and failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub global_start_failed: Option<String>,
    /// Which start the chosen result came from (`initial, wide`, `initial, narrow`, `global`).
    #[serde(default)]
    pub chosen_start: String,
    /// Robust epipolar cost (final Cauchy scale, confidence-weighted) of the initial poses and
    /// of the result.
    #[serde(default)]
    pub initial_cost: f64,
    #[serde(default)]
    pub final_cost: f64,
}

impl WarmupReport {
    /// The report of a warm-up that has not run yet: no iterations, no distances, no costs.
    pub fn unstarted() -> Self {
        Self {
            skipped: None,
            iterations: 0,
            scales_px: Vec::new(),
            in_front: 0.0,
            initial_median_px: f64::NAN,
            final_median_px: f64::NAN,
            covariance_weighted: 0,
            global_start: Vec::new(),
            global_start_failed: None,
            chosen_start: String::new(),
            initial_cost: f64::NAN,
            final_cost: f64::NAN,
        }
    }
}
