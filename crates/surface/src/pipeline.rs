//! The whole method on a dataset, as the CLI runs it: training views and their ground-truth
//! poses → perturbed initial poses (BARF/SPARF protocol) → correspondences → joint training
//! with checkpoints → refined poses, mesh, renders and metrics in one run directory.
//!
//! Run directory:
//! - `config.json` — the resolved configuration;
//! - `checkpoint.bin` — the training state (resume with the same configuration);
//! - `matches.json` — the correspondences (pixel coordinates, training-view indices,
//!   confidences), their count and precision against the true poses;
//! - `poses_initial.json`, `poses_refined.json` — cameras (intrinsics + world-to-camera), and
//!   the input's camera file with the refined poses mapped into the input's frame by the Alg. 1
//!   alignment (`cameras_sphere_refined.npz`, `poses_bounds_refined.npy`,
//!   `transforms_refined.json`, `sparse_refined/`, …; see [`fewview_scene::pose_export`]) when
//!   the dataset came from a folder;
//! - `mesh.ply` — marching cubes of the SDF, culled by the training masks, coloured, in the
//!   reconstruction's frame (that of `poses_refined.json`); `mesh_input_frame.ply` — the same
//!   mesh in the input's own world, the frame of the refined camera file (DTU: millimetres);
//! - `renders/` — colour, depth and normals of the test views (ground-truth cameras mapped into
//!   the reconstruction's frame by the Alg. 1 alignment): PNGs to look at, and `NNN_depth.npy`,
//!   depth along the optical axis in the input world's units (0 on the background);
//! - `metrics.json` — pose errors (Alg. 1/2) before and after, masked PSNR/SSIM of the test
//!   views, Chamfer of the mesh against a reference surface (Alg. 3) when one is given.

use std::path::{Path, PathBuf};

use fewview_geom::Mesh;
use fewview_geom::Similarity;
use fewview_metrics::pose_error::{
    PoseError, PoseErrorOptions, SPARF_CODE_EPS, pose_error_pairwise,
};
use fewview_scene::numpy::Array as NpyArray;
use fewview_scene::pose_export::{PoseSource, write_refined_poses};
use fewview_scene::{Camera, Dataset, Image, Intrinsics, Se3};
use serde::{Deserialize, Serialize};

use crate::bundle::{BundleOptions, BundleReport, bundle_adjust};
use crate::checkpoint;
use crate::error::{Result, SurfaceError};
use crate::extract::{MeshOptions, final_mesh, render_view};
use crate::global_start::PairPose;
use crate::matching::dense::{DenseOptions, dense_matches};
use crate::matching::densify::{DensifyOptions, densify_matches};
use crate::matching::refine::{AffineRefineOptions, refine_matches};
use crate::matching::sift::{SiftMatcher, SiftOptions};
use crate::matching::{
    Match, MatchInput, MatchPrecision, covisible_pairs, epipolar_precision, match_pairs,
};
use crate::patch_adjustment::{PatchAdjustmentOptions, PatchAdjustmentReport, adjust_patches};
use crate::pose::perturb_poses;
use crate::schedule::PoseTiming;
use crate::train::{StepStats, TrainConfig, TrainView, Trainer};
use crate::warmup::{WarmupOptions, WarmupReport, epipolar_warmup, matches_tie_the_views};

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

/// Everything about a run besides the dataset.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunConfig {
    pub train: TrainConfig,
    pub initial_poses: InitialPoses,
    /// `None`: no correspondences (colour-only joint optimisation, BARF-like).
    pub matcher: Option<SiftOptions>,
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
    /// many degrees apart ([`covisible_pairs`]). Paper 001 matches every pair of its three
    /// views; on rings of views the default drops the opposite ones. On DTU's wide triplet
    /// σ = 0.15 noise can push the outer pair past it (seed 1: 89.7° under the noisy poses):
    /// pass 180 there to match every pair as the paper does, or let dense matching compose
    /// that pair through the middle view (`DensifyOptions::compose_unmatched_pairs`, as
    /// [`crate::schedule::Schedule::Cpu`] does).
    #[serde(default = "default_max_pair_angle")]
    pub max_pair_angle_deg: f64,
    /// Deviation, on by default: refine each match's second end to sub-pixel precision by
    /// affine Lucas–Kanade ([`refine_matches`]). `None` keeps the matcher's output (the
    /// behaviour of configurations written before the option existed).
    #[serde(default)]
    pub match_refinement: Option<AffineRefineOptions>,
    /// Deviation, off by default: grow dense matches from the (refined) sparse ones by affine
    /// Lucas–Kanade with forward–backward checks ([`densify_matches`]), standing in for the
    /// density of paper 001's PDC-Net matches.
    #[serde(default)]
    pub densify: Option<DensifyOptions>,
    /// Deviation, used by [`crate::schedule::Schedule::Cpu`]: when [`Self::densify`] is off,
    /// the warm-up is on, and the refined sparse matches cannot tie the views together for it
    /// ([`crate::warmup::matches_tie_the_views`]; e.g. DTU's wide triplet, whose outer pair
    /// shares 2 of them), grow dense matches with these options all the same. The narrow
    /// triplet's sparse matches suffice, and there the dense ones do not help (crate README).
    #[serde(default)]
    pub densify_if_needed: Option<DensifyOptions>,
    /// The pose timing the training uses instead of `train`'s when [`Self::pose_warmup`] is
    /// asked for but declines (too few matches to tie the views together): a late release at
    /// a low rate assumes warmed-up poses ([`crate::schedule::Schedule::Cpu`]). `None` keeps
    /// `train`'s.
    #[serde(default)]
    pub pose_timing_without_warmup: Option<PoseTiming>,
    /// Deviation, used by [`crate::schedule::Schedule::Cpu`]: after an epipolar warm-up, adjust
    /// the poses and the matches' tracks on their reprojection errors ([`crate::bundle`]).
    #[serde(default)]
    pub bundle_adjustment: Option<BundleOptions>,
    /// Deviation, used by [`crate::schedule::Schedule::Cpu`]: after an epipolar warm-up that
    /// ran on dense matches, refine the poses photometrically on small planes seeded by the
    /// matches ([`crate::patch_adjustment`]).
    #[serde(default)]
    pub patch_adjustment: Option<PatchAdjustmentOptions>,
    /// Deviation, used by [`crate::schedule::Schedule::Cpu`]: when the patch adjustment ran,
    /// keep its poses for the whole training (`pose_start` 1). Released at 75 %, the field's
    /// gradients moved them away on every wide DTU seed measured (crate README).
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

/// Training inputs derived from a dataset.
pub struct Prepared {
    pub views: Vec<TrainView>,
    /// Indices of the training views in the dataset.
    pub view_indices: Vec<usize>,
    pub ground_truth: Vec<Se3>,
    /// The initial (noisy) poses: the "initial" of the reported pose errors.
    pub initial: Vec<Se3>,
    /// The poses the joint optimisation starts from: `initial`, or `initial` after the
    /// epipolar warm-up.
    pub start: Vec<Se3>,
    pub warmup: Option<WarmupReport>,
    /// The poses after the epipolar warm-up (`initial` when it did not run).
    pub warmup_poses: Vec<Se3>,
    /// The bundle adjustment's report and the poses it gave, when it ran
    /// ([`RunConfig::bundle_adjustment`]).
    pub bundle_adjustment: Option<(BundleReport, Vec<Se3>)>,
    /// The photometric patch adjustment's report, when it ran ([`RunConfig::patch_adjustment`]);
    /// its poses are `start`.
    pub patch_adjustment: Option<PatchAdjustmentReport>,
    pub matches: Vec<Match>,
    pub match_precision: Option<MatchPrecision>,
    /// Why dense matches were grown under [`RunConfig::densify_if_needed`] (the warm-up's
    /// verdict on the sparse ones), when they were.
    pub densified_because: Option<String>,
}

/// Builds the training inputs: views, ground-truth and initial poses, correspondences.
/// `truth` holds the ground-truth cameras of the same views when `dataset` carries other
/// (initial) poses.
pub fn prepare(dataset: &Dataset, truth: Option<&Dataset>, config: &RunConfig) -> Result<Prepared> {
    prepare_with_matching(dataset, truth, None, config)
}

/// Masks that would spoil a run unnoticed. An empty mask on a training view (no pixel above
/// 0.5) leaves the matcher and the masked losses nothing: an error before anything is written.
/// Masks covering every pixel of every training view change nothing: the run goes on, and the
/// returned notice says so.
fn check_masks(dataset: &Dataset, use_masks: bool) -> Result<Option<String>> {
    if !use_masks {
        return Ok(None);
    }
    let mut with_mask = 0;
    let mut full = 0;
    for (&index, view) in dataset.train.iter().zip(dataset.train_views()) {
        let Some(mask) = &view.mask else { continue };
        with_mask += 1;
        let mut pixels = mask.data.iter().step_by(mask.channels.max(1));
        if !pixels.clone().any(|&v| v > 0.5) {
            return Err(SurfaceError::invalid(
                format!("mask of view {index} ({})", view.name),
                "is empty (no pixel above 0.5): fix the masks or pass --no-masks",
            ));
        }
        full += pixels.all(|&v| v > 0.5) as usize;
    }
    Ok((with_mask > 0 && full == with_mask).then(|| {
        format!(
            "the masks of all {with_mask} training views cover every pixel: they change nothing \
             (the run goes on as with --no-masks)"
        )
    }))
}

/// Two views at least: one view fixes no relative pose and no correspondence.
fn check_view_count(dataset: &Dataset) -> Result<()> {
    if dataset.train.len() < 2 {
        return Err(SurfaceError::invalid(
            "training views",
            format!("{} training views; need at least 2", dataset.train.len()),
        ));
    }
    Ok(())
}

/// [`prepare`], matching on `matching`: the same views at a finer resolution (an integer
/// multiple of the training size). The matcher and the warm-up then work on the finer pixels —
/// on DTU scan65 matching at 800 × 600 instead of 400 × 300 halves the warm-up's pose error
/// (crate README) — and the matches are scaled down to the training pixels for the losses.
pub fn prepare_with_matching(
    dataset: &Dataset,
    truth: Option<&Dataset>,
    matching: Option<&Dataset>,
    config: &RunConfig,
) -> Result<Prepared> {
    check_view_count(dataset)?;
    let views: Vec<TrainView> = dataset.train_views().map(TrainView::of).collect();
    let gt_source = truth.unwrap_or(dataset);
    let ground_truth: Vec<Se3> = dataset
        .train
        .iter()
        .map(|&i| {
            gt_source
                .views
                .get(i)
                .map(|v| v.camera.world_to_camera)
                .ok_or_else(|| SurfaceError::invalid("ground truth", format!("has no view {i}")))
        })
        .collect::<Result<_>>()?;
    let initial = match &config.initial_poses {
        InitialPoses::NoisyGroundTruth { sigma } => {
            if !(sigma.is_finite() && *sigma >= 0.0) {
                return Err(SurfaceError::invalid(
                    "pose noise",
                    format!("σ = {sigma} must be ≥ 0"),
                ));
            }
            perturb_poses(&ground_truth, *sigma, config.train.seed)
        }
        InitialPoses::AsLoaded => dataset
            .train_views()
            .map(|v| v.camera.world_to_camera)
            .collect(),
    };
    let matching = matching.unwrap_or(dataset);
    let scale = matching_scale(dataset, matching)?;
    let match_intrinsics: Vec<Intrinsics> = matching
        .train_views()
        .map(|v| v.camera.intrinsics)
        .collect();
    let (fine_matches, match_precision, densified_because) = match &config.matcher {
        None => (Vec::new(), None, None),
        Some(opts) => {
            let pairs = covisible_pairs(&initial, config.max_pair_angle_deg);
            let c = correspondences(
                matching,
                &pairs,
                &match_intrinsics,
                &ground_truth,
                opts,
                config,
            );
            (c.matches, Some(c.precision), c.densified_because)
        }
    };
    let (start, warmup) = match &config.pose_warmup {
        None => (initial.clone(), None),
        Some(opts) => {
            let (poses, report) = epipolar_warmup(&initial, &match_intrinsics, &fine_matches, opts);
            (poses, Some(report))
        }
    };
    let dense = densified_because.is_some() || config.densify.is_some();
    let warmed_up = warmup.as_ref().is_some_and(|w| w.skipped.is_none());
    let warmup_poses = start.clone();
    let (start, bundle_adjustment) = match &config.bundle_adjustment {
        Some(opts) if warmed_up => {
            let (poses, report) = bundle_adjust(&match_intrinsics, &start, &fine_matches, opts);
            (poses.clone(), Some((report, poses)))
        }
        _ => (start, None),
    };
    let (start, patch_adjustment) = match &config.patch_adjustment {
        Some(opts) if dense && warmed_up => {
            let images: Vec<&Image> = matching.train_views().map(|v| &v.image).collect();
            let masks: Vec<Option<&Image>> = matching
                .train_views()
                .map(|v| v.mask.as_ref().filter(|_| config.train.use_masks))
                .collect();
            let (poses, report) = adjust_patches(
                &images,
                &masks,
                &match_intrinsics,
                &start,
                &fine_matches,
                opts,
            );
            (poses, Some(report))
        }
        _ => (start, None),
    };
    let matches = fine_matches
        .iter()
        .map(|m| Match {
            a: m.a.map(|x| x / scale as f32),
            b: m.b.map(|x| x / scale as f32),
            ..*m
        })
        .collect();
    Ok(Prepared {
        views,
        view_indices: dataset.train.clone(),
        ground_truth,
        initial,
        start,
        warmup,
        warmup_poses,
        bundle_adjustment,
        patch_adjustment,
        matches,
        match_precision,
        densified_because,
    })
}

/// The integer factor between the matching images and the training images (1 when they are
/// the same), or an error when `matching` is not the training views at a multiple of their size.
fn matching_scale(dataset: &Dataset, matching: &Dataset) -> Result<usize> {
    if matching.train != dataset.train {
        return Err(SurfaceError::invalid(
            "matching images",
            format!(
                "training views {:?} differ from the matcher's {:?}",
                dataset.train, matching.train
            ),
        ));
    }
    let mut scale = None;
    for (t, m) in dataset.train_views().zip(matching.train_views()) {
        let (tw, th) = (t.image.width, t.image.height);
        let (mw, mh) = (m.image.width, m.image.height);
        let k = mw / tw.max(1);
        if k == 0 || mw != k * tw || mh != k * th || scale.is_some_and(|s| s != k) {
            return Err(SurfaceError::invalid(
                "matching images",
                format!("{mw}×{mh} is not one integer multiple of the training size {tw}×{th}"),
            ));
        }
        scale = Some(k);
    }
    Ok(scale.unwrap_or(1))
}

/// What [`correspondences`] found.
struct Correspondences {
    matches: Vec<Match>,
    precision: MatchPrecision,
    densified_because: Option<String>,
}

/// SIFT correspondences between the given pairs of training views of `dataset` (in its
/// pixels), refined and densified as `config` asks (or, under
/// [`RunConfig::densify_if_needed`], as the warm-up needs), and their precision against the
/// ground-truth poses.
fn correspondences(
    dataset: &Dataset,
    pairs: &[(usize, usize)],
    intrinsics: &[Intrinsics],
    ground_truth: &[Se3],
    options: &SiftOptions,
    config: &RunConfig,
) -> Correspondences {
    let (use_masks, refinement) = (config.train.use_masks, config.match_refinement.as_ref());
    let inputs: Vec<MatchInput> = dataset
        .train_views()
        .map(|v| MatchInput {
            image: &v.image,
            mask: if use_masks { v.mask.as_ref() } else { None },
        })
        .collect();
    let matches = match_pairs(
        &SiftMatcher {
            options: options.clone(),
        },
        &inputs,
        pairs,
    );
    let images: Vec<&Image> = inputs.iter().map(|i| i.image).collect();
    let mut matches = match refinement {
        Some(o) => refine_matches(&images, &matches, o),
        None => matches,
    };
    let mut densified_because = None;
    let densify = match (
        &config.densify,
        &config.densify_if_needed,
        &config.pose_warmup,
    ) {
        (Some(o), _, _) => Some(o),
        (None, Some(o), Some(warmup)) => {
            match matches_tie_the_views(inputs.len(), &matches, warmup) {
                Ok(()) => None,
                Err(why) => {
                    densified_because = Some(why);
                    Some(o)
                }
            }
        }
        _ => None,
    };
    if let Some(o) = densify {
        let masks: Vec<Option<&Image>> = inputs.iter().map(|i| i.mask).collect();
        let window = refinement.cloned().unwrap_or_default();
        let dense = densify_matches(&images, &masks, &matches, pairs, &window, o);
        matches.extend(dense);
        if let Some(warmup) = &config.pose_warmup
            && let Err(why) = matches_tie_the_views(inputs.len(), &matches, warmup)
        {
            // Growth from the sparse seeds did not reach every pair: seed it again from the
            // dense matcher, which needs no seeds, and grow and compose once more.
            let seeded = standalone_dense_matches(&inputs, pairs, options.seed);
            let seeds: Vec<Match> = matches.iter().chain(&seeded).copied().collect();
            let regrown = densify_matches(&images, &masks, &seeds, pairs, &window, o);
            matches.extend(seeded);
            matches.extend(regrown);
            let again = format!("grown, still {why}; the dense matcher seeded the growth again");
            densified_because = Some(match densified_because {
                Some(first) => format!("{first}; {again}"),
                None => again,
            });
        }
    }
    let cams: Vec<Camera> = intrinsics
        .iter()
        .zip(ground_truth)
        .map(|(k, p)| Camera::new(*k, *p))
        .collect();
    let precision = epipolar_precision(&matches, &cams);
    Correspondences {
        matches,
        precision,
        densified_because,
    }
}

/// The dense matcher's correspondences ([`crate::matching::dense`]) of every pair in `pairs`.
fn standalone_dense_matches(
    inputs: &[MatchInput],
    pairs: &[(usize, usize)],
    seed: u64,
) -> Vec<Match> {
    let options = DenseOptions {
        seed,
        ..DenseOptions::default()
    };
    pairs
        .iter()
        .flat_map(|&(a, b)| dense_matches(&inputs[a], &inputs[b], a, b, &options))
        .collect()
}

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
    pub match_precision: Option<MatchPrecision>,
    /// Why dense matches were grown under [`RunConfig::densify_if_needed`], when they were.
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
    /// Whether that is [`RunConfig::pose_timing_without_warmup`] because the warm-up declined.
    pub pose_timing_fell_back: bool,
    pub final_pose_error: PoseError,
    /// The rotation errors again at the ε of SPARF's code, the convention of paper 001
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

/// Rotation errors by Alg. 1/2 with ε = 10⁻⁷ ([`SPARF_CODE_EPS`]) instead of the printed 10⁻⁶.
/// A view aligned exactly (Alg. 1's anchor always is) scores arccos(1 − ε): 0.081° at 10⁻⁶,
/// 0.026° here, which is the floor behind the 0.03° of paper 001 Table 1; the mean over three
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
        precision: Option<&'a MatchPrecision>,
        /// Why dense matches were grown although not asked for ([`Prepared::densified_because`]).
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
    /// [`RunConfig::pose_timing_without_warmup`], this timing.
    PoseTimingFallback(&'a PoseTiming),
    Stage(&'static str),
    /// Something about the input the user should know, the run going on regardless.
    Notice(String),
}

/// The angle (degrees) between each pair's relative rotation and the true one, `R_b R_aᵀ` of
/// the true world-to-camera rotations.
fn pair_rotation_errors(pairs: &[PairPose], truth: &[Se3]) -> Vec<f64> {
    pairs
        .iter()
        .filter_map(|p| {
            let (a, b) = (truth.get(p.view_a)?, truth.get(p.view_b)?);
            let found = nalgebra::Matrix3::from_fn(|i, j| p.rotation[i][j]);
            let true_rel = b.rotation * a.rotation.transpose();
            Some(crate::pose::rotation_angle_deg(&found, &true_rel))
        })
        .collect()
}

fn pose_error(est: &[Se3], gt: &[Se3]) -> Result<PoseError> {
    pose_error_at_eps(est, gt, fewview_metrics::pose_error::EPS)
}

fn pose_error_at_eps(est: &[Se3], gt: &[Se3], eps: f64) -> Result<PoseError> {
    let options = PoseErrorOptions {
        eps,
        ..Default::default()
    };
    pose_error_pairwise(est, gt, &options)
        .map_err(|e| SurfaceError::invalid("pose error", e.to_string()))
}

fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| SurfaceError::invalid("json", e.to_string()))?;
    fewview_scene::atomic::write_bytes(path, text.as_bytes()).map_err(SurfaceError::Scene)
}

/// The cameras of `gt` mapped into the reconstruction's world by the inverse of the Alg. 1
/// alignment `x_gt = s R x_est + t`.
pub fn camera_in_estimate_frame(gt: &Camera, alignment: &Similarity) -> Camera {
    Camera::new(
        gt.intrinsics,
        alignment.inverse().apply_to_pose(&gt.world_to_camera),
    )
}

/// What a run reads.
#[derive(Clone, Copy)]
pub struct RunInputs<'a> {
    /// Training and test views with the poses to start from.
    pub dataset: &'a Dataset,
    /// Ground-truth cameras of the same views when `dataset` carries other poses.
    pub truth: Option<&'a Dataset>,
    /// The same views at a finer resolution for the matcher ([`prepare_with_matching`]).
    pub matching: Option<&'a Dataset>,
    /// A surface in the dataset's (normalised) frame for Chamfer.
    pub reference: Option<&'a Mesh>,
    /// For each face of `reference`, whether a training view sees it: Chamfer is then also
    /// scored on the observed part (`RunReport::chamfer_observed`), as DTU's protocol does.
    pub reference_observed: Option<&'a [bool]>,
    /// The folder `dataset` was loaded from, to write the refined poses back in its format.
    pub source: Option<PoseSource<'a>>,
}

/// A reference surface Chamfer can score against: faces with some area, on which Chamfer
/// samples its points. An empty, line-only or degenerate mesh used to be found out only after
/// training, as "not scored".
pub fn check_reference(reference: &Mesh) -> Result<()> {
    let what = "reference surface";
    if reference.faces.is_empty() {
        return Err(SurfaceError::invalid(
            what,
            format!(
                "has no faces ({} vertices): Chamfer samples points on a surface",
                reference.vertices.len()
            ),
        ));
    }
    let area = reference.area();
    if !(area.is_finite() && area > 0.0) {
        return Err(SurfaceError::invalid(
            what,
            format!("none of its {} faces has any area", reference.faces.len()),
        ));
    }
    Ok(())
}

/// What a checkpoint of this run must match for `--resume` to continue it
/// ([`checkpoint::RunIdentity`]): the data and the whole configuration except the settings a
/// resume may change — the iteration count, the checkpoint interval and the outputs (mesh
/// resolution, evaluated views and their scale).
pub fn run_identity(
    dataset: &Dataset,
    truth: Option<&Dataset>,
    matching: Option<&Dataset>,
    config: &RunConfig,
) -> Result<checkpoint::RunIdentity> {
    let cameras = |ds: &Dataset| -> Vec<checkpoint::CameraRecord> {
        ds.train_views()
            .map(|v| checkpoint::camera_record(&v.camera))
            .collect()
    };
    let sizes = |ds: &Dataset| -> Vec<[usize; 2]> {
        ds.train_views()
            .map(|v| [v.image.width, v.image.height])
            .collect()
    };
    let mut settings = serde_json::to_value(config)
        .map_err(|e| SurfaceError::invalid("configuration", e.to_string()))?;
    if let Some(all) = settings.as_object_mut() {
        for resumable in [
            "checkpoint_every",
            "mesh_resolution",
            "eval_views",
            "eval_scale",
        ] {
            all.remove(resumable);
        }
        if let Some(train) = all.get_mut("train").and_then(|t| t.as_object_mut()) {
            train.remove("iterations");
        }
    }
    Ok(checkpoint::RunIdentity {
        dataset: dataset.name.clone(),
        train_views: dataset.train_views().map(|v| v.name.clone()).collect(),
        image_sizes: sizes(dataset),
        matching_sizes: matching.map(sizes),
        cameras: cameras(dataset),
        truth_cameras: truth.map(cameras),
        settings_json: settings.to_string(),
    })
}

/// Runs everything and writes the run directory. `resume` continues from `checkpoint.bin`
/// when it exists.
pub fn run(
    inputs: RunInputs,
    config: &RunConfig,
    out: &Path,
    resume: bool,
    on_event: &mut dyn FnMut(Event),
) -> Result<RunReport> {
    let RunInputs {
        dataset,
        truth,
        matching,
        reference,
        reference_observed,
        source,
    } = inputs;
    let started = std::time::Instant::now();
    // Refuse what is wrong before the run folder is touched: no half-written output.
    config.train.validate()?;
    check_view_count(dataset)?;
    if let Some(reference) = reference {
        check_reference(reference)?;
    }
    if let Some(notice) = check_masks(dataset, config.train.use_masks)? {
        on_event(Event::Notice(notice));
    }
    let identity = run_identity(dataset, truth, matching, config)?;
    let ckpt = checkpoint_path(out);
    let saved = if resume && ckpt.exists() {
        let saved = checkpoint::read(&ckpt)?;
        saved.check_run(&ckpt, &identity, config.train.iterations)?;
        Some(saved)
    } else {
        None
    };
    std::fs::create_dir_all(out).map_err(|e| SurfaceError::io(out, e))?;
    write_json(&out.join("config.json"), config)?;
    on_event(Event::Stage("matching"));
    let prep = prepare_with_matching(dataset, truth, matching, config)?;
    on_event(Event::Matched {
        matches: prep.matches.len(),
        precision: prep.match_precision.as_ref(),
        densified_because: prep.densified_because.as_deref(),
    });
    write_json(
        &out.join("matches.json"),
        &serde_json::json!({
            "matches": prep.matches.len(),
            "precision": prep.match_precision,
            "views": prep.view_indices,
            "correspondences": prep.matches,
        }),
    )?;
    let cams = |poses: &[Se3]| -> Vec<Camera> {
        prep.views
            .iter()
            .zip(poses)
            .map(|(v, p)| Camera::new(v.intrinsics, *p))
            .collect()
    };
    fewview_geom::io::cameras::write_cameras(
        &out.join("poses_initial.json"),
        &cams(&prep.initial),
    )?;
    let epipolar_poses = &prep.warmup_poses;
    let global_start_rotation_errors_deg = prep
        .warmup
        .as_ref()
        .map(|w| pair_rotation_errors(&w.global_start, &prep.ground_truth))
        .unwrap_or_default();
    let warmup_pose_error = match &prep.warmup {
        Some(report) => {
            let err = pose_error(epipolar_poses, &prep.ground_truth)?;
            on_event(Event::WarmedUp {
                report,
                pose_error: &err,
                pair_errors_deg: &global_start_rotation_errors_deg,
            });
            Some(err)
        }
        None => None,
    };
    let bundle_adjustment_pose_error = match &prep.bundle_adjustment {
        Some((report, poses)) => {
            let err = pose_error(poses, &prep.ground_truth)?;
            on_event(Event::BundleAdjusted {
                report,
                pose_error: &err,
            });
            Some(err)
        }
        None => None,
    };
    let patch_adjustment_pose_error = match &prep.patch_adjustment {
        Some(report) => {
            let err = pose_error(&prep.start, &prep.ground_truth)?;
            on_event(Event::PatchesAdjusted {
                report,
                pose_error: &err,
            });
            Some(err)
        }
        None => None,
    };
    let patches_adjusted = prep
        .patch_adjustment
        .as_ref()
        .is_some_and(|report| report.skipped.is_none());
    let (train_config, fell_back) = config.effective_train(prep.warmup.as_ref(), patches_adjusted);
    let pose_timing = PoseTiming::of(&train_config);
    if fell_back {
        on_event(Event::PoseTimingFallback(&pose_timing));
    }
    let mut trainer = Trainer::new(
        train_config.clone(),
        prep.views.clone(),
        &prep.start,
        prep.matches.clone(),
    )?;
    if let Some(saved) = saved {
        trainer.restore(saved.into_state(&ckpt, &train_config)?)?;
        trainer.sync_progress();
    }
    on_event(Event::Stage("training"));
    let wall = std::time::Instant::now();
    let cpu = crate::cputime::process_cpu_seconds();
    let start_it = trainer.state.iteration;
    let mut last = StepStats::default();
    let mut pose_steps_skipped = 0;
    let mut history = Vec::new();
    while trainer.state.iteration < train_config.iterations {
        last = trainer.step()?;
        pose_steps_skipped += usize::from(last.pose_step_skipped);
        on_event(Event::Step(&last));
        let it = trainer.state.iteration;
        if config.checkpoint_every > 0
            && (it % config.checkpoint_every == 0 || it == train_config.iterations)
        {
            checkpoint::save(&ckpt, &identity, &train_config, &trainer.state)?;
            let err = pose_error(&trainer.poses(), &prep.ground_truth)?;
            history.push(PoseErrorAt {
                iteration: it,
                rotation_deg: err.rotation_deg,
                translation: err.translation,
            });
            on_event(Event::Checkpoint {
                iteration: it,
                pose_error: &err,
            });
        }
    }
    let train_wall = wall.elapsed().as_secs_f64();
    let train_cpu = crate::cputime::process_cpu_seconds() - cpu;
    let done = trainer.state.iteration - start_it;

    on_event(Event::Stage("evaluating"));
    let refined = trainer.poses();
    let initial_err = pose_error(&prep.initial, &prep.ground_truth)?;
    let final_err = pose_error(&refined, &prep.ground_truth)?;
    let at_sparf_eps = |poses: &[Se3]| pose_error_at_eps(poses, &prep.ground_truth, SPARF_CODE_EPS);
    let final_at_sparf_eps = at_sparf_eps(&refined)?;
    let rotation_at_sparf_eps = SparfEpsRotation {
        eps: SPARF_CODE_EPS,
        initial_deg: at_sparf_eps(&prep.initial)?.rotation_deg,
        warmup_deg: match &warmup_pose_error {
            Some(_) => Some(at_sparf_eps(epipolar_poses)?.rotation_deg),
            None => None,
        },
        bundle_adjustment_deg: match &prep.bundle_adjustment {
            Some((_, poses)) => Some(at_sparf_eps(poses)?.rotation_deg),
            None => None,
        },
        patch_adjustment_deg: match &patch_adjustment_pose_error {
            Some(_) => Some(at_sparf_eps(&prep.start)?.rotation_deg),
            None => None,
        },
        final_deg: final_at_sparf_eps.rotation_deg,
        final_per_view_deg: final_at_sparf_eps.per_view_rotation_deg,
    };
    let refined_cams = cams(&refined);
    fewview_geom::io::cameras::write_cameras(&out.join("poses_refined.json"), &refined_cams)?;
    // The cameras the poses are scored against, and whose file frame the outputs go back to.
    let scored = truth.unwrap_or(dataset);
    // Written back in the input's frame: the estimate's gauge is wherever the anchor view's
    // initial pose put it (with σ = 0.15 noise, some 10–20° and a translation away from the
    // input's cameras), so its poses are first mapped by the Alg. 1 alignment onto the cameras
    // they are scored against, which keeps them consistent with the file's untouched views.
    // Those are `truth`'s when given: its normalised frame (DTU: its own `scale_mat`, which
    // differs between scan65's `cameras_sphere.npz` and `cameras_linear_init.npz`) is the one
    // that maps the aligned poses back to the file's world.
    let refined_pose_files = match source {
        Some(source) => {
            let poses: Vec<(usize, Se3)> = prep
                .view_indices
                .iter()
                .copied()
                .zip(final_err.aligned_world_to_camera.iter().copied())
                .collect();
            write_refined_poses(source, scored, &poses, out)?
                .iter()
                .map(|p| p.strip_prefix(out).unwrap_or(p).display().to_string())
                .collect()
        }
        None => Vec::new(),
    };
    let (field, params) = trainer.field_params();
    let masks: Option<Vec<Image>> = prep.views.iter().map(|v| v.mask.clone()).collect();
    let mesh = final_mesh(
        field,
        params,
        &MeshOptions {
            resolution: config.mesh_resolution,
            chunk: 32,
        },
        masks
            .as_ref()
            .filter(|_| config.train.use_masks)
            .map(|m| (refined_cams.as_slice(), m.as_slice())),
    )?;
    fewview_geom::io::write_mesh(&out.join("mesh.ply"), &mesh)?;
    let to_input = input_world(scored, &final_err.alignment)?;
    fewview_geom::io::write_mesh(
        &out.join("mesh_input_frame.ply"),
        &to_input.apply_to_mesh(&mesh),
    )?;

    // Test views.
    let renders = out.join("renders");
    std::fs::create_dir_all(&renders).map_err(|e| SurfaceError::io(&renders, e))?;
    let mut test_metrics = Vec::new();
    for &vi in dataset.test.iter().take(config.eval_views) {
        let gt_view = &scored.views[vi];
        let mut cam = camera_in_estimate_frame(&gt_view.camera, &final_err.alignment);
        let (mut image, mut mask) = (gt_view.image.clone(), gt_view.mask.clone());
        if config.eval_scale > 1 {
            let k = config.eval_scale as usize;
            image = image.downscale(k);
            mask = mask.map(|m| m.downscale(k));
            cam = cam.resized(image.width as u32, image.height as u32);
        }
        let r = render_view(
            field,
            params,
            &cam,
            &config.train.sample,
            config.train.background,
            4096,
        )?;
        let name = |s: &str| renders.join(format!("{:03}_{s}.png", vi));
        r.rgb.save_png(&name("rgb"))?;
        r.depth.scaled_to_unit_max().save_png(&name("depth"))?;
        let depth_npy = renders.join(format!("{vi:03}_depth.npy"));
        fewview_scene::numpy::save_npy(&depth_npy, &z_depth(&r, &cam, to_input.scale))?;
        r.normal.save_png(&name("normal"))?;
        let full = fewview_metrics::psnr::psnr(&r.rgb, &image).unwrap_or(f64::NAN);
        let (pm, sm) = match &mask {
            Some(m) => (
                fewview_metrics::psnr::psnr_masked(&r.rgb, &image, m).unwrap_or(f64::NAN),
                fewview_metrics::ssim::ssim_masked(&r.rgb, &image, m, &Default::default())
                    .unwrap_or(f64::NAN),
            ),
            None => (
                full,
                fewview_metrics::ssim::ssim(&r.rgb, &image).unwrap_or(f64::NAN),
            ),
        };
        test_metrics.push(TestViewMetrics {
            view: vi,
            psnr_masked: pm,
            ssim_masked: sm,
            psnr: full,
        });
    }
    let mean = |f: &dyn Fn(&TestViewMetrics) -> f64| {
        (!test_metrics.is_empty())
            .then(|| test_metrics.iter().map(f).sum::<f64>() / test_metrics.len() as f64)
    };
    let scores =
        reference.map(|gt| reference_scores(&mesh, gt, reference_observed, &final_err.alignment));
    let (chamfer, chamfer_observed, chamfer_error) = scores.unwrap_or_default();
    let first = dataset.train_views().next();
    let report = RunReport {
        dataset: dataset.name.clone(),
        train_views: dataset.train_views().map(|v| v.source_index).collect(),
        image_size: first.map_or([0, 0], |v| [v.image.width, v.image.height]),
        seed: config.train.seed,
        run_seconds_wall: started.elapsed().as_secs_f64(),
        iterations: trainer.state.iteration,
        train_seconds_wall: train_wall,
        train_seconds_cpu: train_cpu,
        iterations_per_second_wall: if train_wall > 0.0 {
            done as f64 / train_wall
        } else {
            0.0
        },
        matches: prep.matches.len(),
        match_precision: prep.match_precision.clone(),
        densified_because: prep.densified_because.clone(),
        initial_pose_error: initial_err,
        warmup: prep.warmup.clone(),
        warmup_pose_error,
        global_start_rotation_errors_deg,
        bundle_adjustment: prep.bundle_adjustment.as_ref().map(|(r, _)| r.clone()),
        bundle_adjustment_pose_error,
        patch_adjustment: prep.patch_adjustment.clone(),
        patch_adjustment_pose_error,
        pose_timing,
        pose_timing_fell_back: fell_back,
        final_pose_error: final_err,
        rotation_at_sparf_eps,
        last_step: last,
        pose_steps_skipped,
        pose_error_history: history,
        mean_psnr_masked: mean(&|m| m.psnr_masked),
        mean_ssim_masked: mean(&|m| m.ssim_masked),
        test_views: test_metrics,
        chamfer,
        chamfer_observed,
        chamfer_error,
        mesh_vertices: mesh.vertices.len(),
        mesh_faces: mesh.faces.len(),
        refined_pose_files,
    };
    write_json(&out.join("metrics.json"), &report)?;
    Ok(report)
}

/// Chamfer of `mesh` against `reference` on the whole reference and, given per-face flags, on
/// its observed part, after registering it ([`register_to_reference`]); what cannot be scored
/// is `None`, with the reasons.
fn reference_scores(
    mesh: &Mesh,
    reference: &Mesh,
    observed: Option<&[bool]>,
    alignment: &Similarity,
) -> (Option<ChamferReport>, Option<ChamferReport>, Option<String>) {
    if mesh.faces.is_empty() {
        return (None, None, Some("the extracted mesh is empty".into()));
    }
    let aligned = match register_to_reference(mesh, reference, alignment) {
        Ok(m) => m,
        Err(e) => return (None, None, Some(format!("registration: {e}"))),
    };
    let mut errors = Vec::new();
    let mut score = |flags: Option<&[bool]>, what: &str| {
        chamfer_of(&aligned, reference, flags)
            .map_err(|e| errors.push(format!("{what}: {e}")))
            .ok()
    };
    let whole = score(None, "whole surface");
    let seen = observed.and_then(|flags| score(Some(flags), "observed part"));
    let why = (!errors.is_empty()).then(|| errors.join("; "));
    (whole, seen, why)
}

/// The map from the reconstruction's frame to the input's own world, the frame of the refined
/// camera file: the Alg. 1 alignment onto the cameras the poses are scored against (`scored`,
/// the truth's when given), then that dataset's map back to its file's frame (DTU: `scale_mat`,
/// to the millimetres of DTU's reference point clouds; LLFF: NeRF's normalisation undone).
/// `mesh_input_frame.ply` and the raw depth maps are in this world, so they overlay the
/// refined cameras in the tools that read the input's format.
fn input_world(scored: &Dataset, alignment: &Similarity) -> Result<Similarity> {
    match &scored.to_source_world {
        None => Ok(*alignment),
        Some(m) => Ok(Similarity::from_matrix4(m)?.compose(alignment)),
    }
}

/// The rendered depth as a `height × width` array of depths along the optical axis (the
/// convention of COLMAP's and MVSNet's depth maps, not the distance along the ray that NeuS
/// renders), times `units` (the scale of the map to the input's world); 0 where the rendered
/// opacity is under one half (background). The weights' expected distance is divided by their
/// sum first, so that partly covered pixels are not pulled towards the camera.
fn z_depth(render: &crate::extract::ViewRender, camera: &Camera, units: f64) -> NpyArray {
    let (w, h) = (render.depth.width, render.depth.height);
    let axis = camera.world_to_camera.rotation.row(2).transpose();
    let data = (0..w * h)
        .map(|i| {
            let alpha = f64::from(render.alpha.data[i]);
            if alpha < 0.5 {
                return 0.0;
            }
            let (x, y) = ((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
            let (_, direction) = camera.ray(x, y);
            f64::from(render.depth.data[i]) / alpha * direction.dot(&axis) * units
        })
        .collect();
    NpyArray {
        shape: vec![h, w],
        data,
    }
}

/// Paper 001 Alg. 3: the mesh pre-aligned with the pose-evaluation similarity, then
/// registered to the reference by FPFH + RANSAC and point-to-point ICP (ICP also from the
/// pre-alignment, see `fewview_geom::registration::IcpStarts`).
pub fn register_to_reference(
    mesh: &Mesh,
    reference: &Mesh,
    alignment: &Similarity,
) -> Result<Mesh> {
    use fewview_geom::registration::{RegistrationOptions, register};
    let voxel = fewview_geom::mesh::bbox_diagonal(&reference.vertices) / 100.0;
    let src = fewview_geom::Points::from_positions(mesh.vertices.clone());
    let dst = fewview_geom::Points::from_positions(reference.vertices.clone());
    let reg = register(
        &src,
        &dst,
        Some(alignment),
        &RegistrationOptions::for_voxel(voxel),
    )?;
    Ok(Mesh {
        vertices: reg.transformation.apply_points(&mesh.vertices),
        ..mesh.clone()
    })
}

/// Chamfer-L1 of a registered mesh to the reference from uniform surface samples, on the whole
/// reference or, given per-face flags, on its observed part.
pub fn chamfer_of(
    aligned: &Mesh,
    reference: &Mesh,
    observed: Option<&[bool]>,
) -> Result<ChamferReport> {
    use fewview_geom::chamfer::{surface_metrics, surface_metrics_observed};
    let diag = fewview_geom::mesh::bbox_diagonal(&reference.vertices);
    let (n, taus) = (200_000, [0.01 * diag]);
    let m = match observed {
        Some(flags) => surface_metrics_observed(aligned, reference, flags, n, &taus, 0)?,
        None => surface_metrics(aligned, reference, n, &taus, 0)?,
    };
    Ok(ChamferReport {
        chamfer_l1: m.chamfer_l1,
        accuracy: m.accuracy,
        completeness: m.completeness,
        bbox_diagonal: diag,
        relative: m.chamfer_l1 / diag,
        fscore_1pct: m.fscore.first().map(|f| f.fscore).unwrap_or(f64::NAN),
    })
}

/// The run directory's checkpoint path.
pub fn checkpoint_path(out: &Path) -> PathBuf {
    out.join("checkpoint.bin")
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// An empty training mask stops the run before its folder exists; masks covering every
    /// pixel let it go on with a notice; ordinary masks, and no masks asked for, say nothing.
    #[test]
    fn empty_masks_stop_the_run_and_full_ones_are_noticed() {
        let mut ds = crate::sdf_scene::sdf_dataset(&crate::sdf_scene::SdfSceneOptions {
            width: 32,
            height: 24,
            views: 4,
            train: vec![0, 1, 2],
            supersample: 1,
            ..Default::default()
        });
        assert_eq!(check_masks(&ds, true).unwrap(), None);
        let fill = |ds: &mut Dataset, view: usize, value: f32| {
            if let Some(m) = ds.views[view].mask.as_mut() {
                m.data.iter_mut().for_each(|v| *v = value);
            }
        };
        for v in 0..3 {
            fill(&mut ds, v, 1.0);
        }
        let notice = check_masks(&ds, true).unwrap().expect("a notice");
        assert!(notice.contains("cover every pixel"), "{notice}");
        fill(&mut ds, 1, 0.0);
        let err = check_masks(&ds, true).unwrap_err().to_string();
        assert!(err.contains("view 1") && err.contains("empty"), "{err}");
        assert_eq!(check_masks(&ds, false).unwrap(), None, "--no-masks");
        let out = tempfile::tempdir().unwrap().path().join("run");
        let inputs = RunInputs {
            dataset: &ds,
            truth: None,
            matching: None,
            reference: None,
            reference_observed: None,
            source: None,
        };
        assert!(run(inputs, &RunConfig::default(), &out, false, &mut |_| {}).is_err());
        assert!(!out.exists(), "nothing written");
    }

    /// A tilted plane seen by a turned camera: where a pixel's opacity reaches one half, the
    /// written depth is the hit point's camera-frame z (computed by transforming the point, not
    /// by the projection onto the axis the function uses) times the units, also when the
    /// opacity is 0.8 and the rendered depth is the weights' unnormalised sum; below one half,
    /// 0.
    #[test]
    fn depth_maps_hold_z_along_the_optical_axis_in_the_input_units() {
        let (w, h) = (12usize, 9usize);
        let camera = Camera::look_at(
            Intrinsics::centered(10.0, w as u32, h as u32),
            Vector3::new(0.4, -0.3, 3.0),
            Vector3::new(0.1, 0.2, 0.0),
            Vector3::new(0.0, 0.0, 1.0),
        );
        let (normal, offset) = (Vector3::new(0.2, -0.1, 1.0).normalize(), -0.05);
        let opacity = |i: usize| [1.0f32, 0.8, 0.3][i % 3];
        let mut depth = Vec::new();
        let mut expected = Vec::new();
        for i in 0..w * h {
            let (o, d) = camera.ray((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
            let t = (offset - normal.dot(&o)) / normal.dot(&d);
            assert!(t > 0.0);
            depth.push(opacity(i) * t as f32);
            let z = camera.world_to_camera.transform_point(&(o + t * d)).z;
            expected.push(if opacity(i) >= 0.5 { 2.5 * z } else { 0.0 });
        }
        let blank = |c: usize| Image::from_vec(w, h, c, vec![0.0; w * h * c]);
        let render = crate::extract::ViewRender {
            rgb: blank(3),
            depth: Image::from_vec(w, h, 1, depth),
            normal: blank(3),
            alpha: Image::from_vec(w, h, 1, (0..w * h).map(opacity).collect()),
        };
        let got = z_depth(&render, &camera, 2.5);
        assert_eq!(got.shape, [h, w]);
        for (i, (g, e)) in got.data.iter().zip(&expected).enumerate() {
            assert!(
                (g - e).abs() < 1e-5 * e.abs().max(1.0),
                "pixel {i}: {g} vs {e}"
            );
        }
        assert!(expected.iter().filter(|&&e| e > 0.0).count() >= 2 * w * h / 3);
    }
}
