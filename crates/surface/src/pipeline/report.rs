//! What a run reports: [`RunReport`] (written as `metrics.json`) and the progress [`Event`]s.

use fewview_metrics::pose_error::PoseError;
use serde::Serialize;

use crate::matching::MatchPrecision;
use crate::patch_adjustment::PatchAdjustmentReport;
use crate::schedule::PoseTiming;
use crate::train::state::StepStats;
use crate::warmup::WarmupReport;
use fewview_sfm::bundle::BundleReport;

/// What a run reports.
#[derive(Clone, Debug, Serialize)]
pub struct RunReport {
    /// The dataset's name (its folder), the training views' indices in the source (DTU's
    /// camera numbers), their size in pixels and the seed: what a results table groups by.
    #[serde(default)]
    pub dataset: String,
    #[serde(default)]
    pub train_views: Vec<usize>,
    #[serde(default)]
    pub image_size: [usize; 2],
    #[serde(default)]
    pub seed: u64,
    /// Wall time of the whole invocation: matching, warm-up, training, meshing and evaluation.
    #[serde(default)]
    pub run_seconds_wall: f64,
    pub iterations: usize,
    pub train_seconds_wall: f64,
    pub train_seconds_cpu: f64,
    pub iterations_per_second_wall: f64,
    pub matches: usize,
    /// The matcher that ran (`classical`, `xfeat`, `xfeat-star`, `lighterglue`); absent in runs
    /// written before the choice existed (classical) and in runs without matches.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub matcher: Option<String>,
    /// Why the configured matcher could not run and the classical one ran instead.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub matcher_fallback: Option<String>,
    pub match_precision: Option<MatchPrecision>,
    /// Why dense matches were grown under [`crate::config::RunConfig::densify_if_needed`], when they were.
    pub densified_because: Option<String>,
    pub initial_pose_error: PoseError,
    /// After the epipolar warm-up, when it ran.
    pub warmup: Option<WarmupReport>,
    /// After the epipolar warm-up (before the patch adjustment, when that ran).
    pub warmup_pose_error: Option<PoseError>,
    /// The error (degrees) of each relative rotation the global start's five-point step found
    /// (in the order of [`WarmupReport::global_start`]) against the true poses.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub global_start_rotation_errors_deg: Vec<f64>,
    /// The bundle adjustment after the warm-up, when it ran, and the pose error of its poses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bundle_adjustment: Option<BundleReport>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bundle_adjustment_pose_error: Option<PoseError>,
    /// The photometric patch adjustment after the warm-up, when it ran, and the pose error of
    /// the poses it gave the training.
    pub patch_adjustment: Option<PatchAdjustmentReport>,
    pub patch_adjustment_pose_error: Option<PoseError>,
    /// When the poses were released and their learning rate, as the training used them.
    pub pose_timing: PoseTiming,
    /// Whether that is [`crate::config::RunConfig::pose_timing_without_warmup`] because the warm-up declined.
    pub pose_timing_fell_back: bool,
    pub final_pose_error: PoseError,
    /// The rotation errors again at the ε of SPARF's code, the convention of the surface paper
    /// Table 1's figures ([`SparfEpsRotation`]).
    pub rotation_at_sparf_eps: SparfEpsRotation,
    pub last_step: StepStats,
    /// Iterations of this invocation whose pose gradient was not finite, so the poses held
    /// still while the field stepped ([`StepStats::pose_step_skipped`]).
    pub pose_steps_skipped: usize,
    /// Pose errors at the checkpoints of this invocation (a resumed run lists only its own).
    pub pose_error_history: Vec<PoseErrorAt>,
    pub test_views: Vec<TestViewMetrics>,
    pub mean_psnr_masked: Option<f64>,
    pub mean_ssim_masked: Option<f64>,
    pub chamfer: Option<ChamferReport>,
    /// Chamfer on the part of the reference the training views see, when known.
    pub chamfer_observed: Option<ChamferReport>,
    /// Why a Chamfer score asked for (a reference given) is missing: an empty mesh, a failed
    /// registration, or no part of the mesh near the observed reference (e.g. a run too short
    /// to form a surface). The run's other outputs are kept.
    pub chamfer_error: Option<String>,
    pub mesh_vertices: usize,
    pub mesh_faces: usize,
    /// The input's camera file(s) with the refined poses (mapped into the input's frame by the
    /// Alg. 1 alignment), relative to the run folder ([`fewview_scene::pose_export`]); empty
    /// for in-process scenes.
    pub refined_pose_files: Vec<String>,
}

/// Rotation errors by Alg. 1/2 with ε = 10⁻⁷ ([`fewview_metrics::pose_error::SPARF_CODE_EPS`]) instead of the printed 10⁻⁶.
/// A view aligned exactly (Alg. 1's anchor always is) scores arccos(1 − ε): 0.081° at 10⁻⁶,
/// 0.026° here, which is the floor behind the 0.03° of the surface paper Table 1; the mean over three
/// views at 10⁻⁶ carries 0.027° of floor from the anchor alone. Translation errors do not
/// depend on ε (beyond which alignment Alg. 1 picks).
#[derive(Clone, Debug, Serialize)]
pub struct SparfEpsRotation {
    pub eps: f64,
    pub initial_deg: f64,
    pub warmup_deg: Option<f64>,
    /// After the bundle adjustment, when it ran.
    pub bundle_adjustment_deg: Option<f64>,
    /// After the patch adjustment, when it ran.
    pub patch_adjustment_deg: Option<f64>,
    pub final_deg: f64,
    pub final_per_view_deg: Vec<f64>,
}

/// The pose error at one iteration.
#[derive(Clone, Debug, Serialize)]
pub struct PoseErrorAt {
    pub iteration: usize,
    pub rotation_deg: f64,
    pub translation: f64,
}

/// Metrics of one rendered test view.
#[derive(Clone, Debug, Serialize)]
pub struct TestViewMetrics {
    pub view: usize,
    pub psnr_masked: f64,
    pub ssim_masked: f64,
    pub psnr: f64,
}

/// Chamfer distance of the mesh to a reference surface after Alg. 3.
#[derive(Clone, Debug, Serialize)]
pub struct ChamferReport {
    pub chamfer_l1: f64,
    pub accuracy: f64,
    pub completeness: f64,
    pub bbox_diagonal: f64,
    /// `chamfer_l1 / bbox_diagonal`.
    pub relative: f64,
    pub fscore_1pct: f64,
}

/// Progress callback events.
pub enum Event<'a> {
    Matched {
        matches: usize,
        /// The matcher that ran, and why it is not the configured one when it is not.
        matcher: Option<&'a str>,
        fallback: Option<&'a str>,
        precision: Option<&'a MatchPrecision>,
        /// Why dense matches were grown although not asked for ([`crate::pipeline::Prepared::densified_because`]).
        densified_because: Option<&'a str>,
    },
    /// The epipolar warm-up finished; the pose error of its poses.
    WarmedUp {
        report: &'a WarmupReport,
        pose_error: &'a PoseError,
        /// [`RunReport::global_start_rotation_errors_deg`].
        pair_errors_deg: &'a [f64],
    },
    /// The bundle adjustment finished; the pose error of its poses.
    BundleAdjusted {
        report: &'a BundleReport,
        pose_error: &'a PoseError,
    },
    /// The photometric patch adjustment finished; the pose error of its poses.
    PatchesAdjusted {
        report: &'a PatchAdjustmentReport,
        pose_error: &'a PoseError,
    },
    Step(&'a StepStats),
    /// A checkpoint was written; the pose error of the current poses (Alg. 1/2).
    Checkpoint {
        iteration: usize,
        pose_error: &'a PoseError,
    },
    /// The warm-up declined, so the training refines the poses with
    /// [`crate::config::RunConfig::pose_timing_without_warmup`], this timing.
    PoseTimingFallback(&'a PoseTiming),
    Stage(&'static str),
    /// Something about the input the user should know, the run going on regardless.
    Notice(String),
}
