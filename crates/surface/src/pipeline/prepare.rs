//! The training inputs of a run ([`Prepared`]): views, ground-truth and initial poses,
//! correspondences, and the poses after the warm-up and the adjustments that follow it.

use fewview_scene::{Camera, Dataset, Image, Intrinsics, Se3};

use crate::config::{InitialPoses, RunConfig};
use crate::error::{Result, SurfaceError};
use crate::matching::dense::{DenseOptions, dense_matches};
use crate::matching::densify::densify_matches;
use crate::matching::learned::matcher_for;
use crate::matching::refine::refine_matches;
use crate::matching::sift::SiftOptions;
use crate::matching::{
    Match, MatchInput, MatchPrecision, covisible_pairs, epipolar_precision, match_pairs,
};
use crate::patch_adjustment::{PatchAdjustmentReport, adjust_patches};
use crate::pose::perturb_poses;
use crate::train::state::TrainView;
use crate::warmup::{WarmupReport, epipolar_warmup, matches_tie_the_views};
use fewview_sfm::bundle::{BundleReport, bundle_adjust};

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
    /// The matcher that ran ([`crate::matching::Matcher::name`]), when one did.
    pub matcher: Option<String>,
    /// Why the configured matcher could not run and the classical one ran instead.
    pub matcher_fallback: Option<String>,
}

impl Prepared {
    /// The training views' cameras with these poses.
    pub fn cameras(&self, poses: &[Se3]) -> Vec<Camera> {
        self.views
            .iter()
            .zip(poses)
            .map(|(v, p)| Camera::new(v.intrinsics, *p))
            .collect()
    }
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
pub(super) fn check_masks(dataset: &Dataset, use_masks: bool) -> Result<Option<String>> {
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
pub(super) fn check_view_count(dataset: &Dataset) -> Result<()> {
    if dataset.train.len() < 2 {
        return Err(SurfaceError::invalid(
            "training views",
            format!("{} training views; need at least 2", dataset.train.len()),
        ));
    }
    Ok(())
}

/// [`prepare`], matching on `matching`: the same views at a finer resolution (an integer
/// multiple of the training size). The matcher and the warm-up then work on the finer pixels,
/// where the matches are more precise, and the matches are scaled down to the training pixels
/// for the losses.
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
    let (fine_matches, match_precision, densified_because, matcher, matcher_fallback) =
        match &config.matcher {
            None => (Vec::new(), None, None, None, None),
            Some(opts) => {
                let pairs = covisible_pairs(&initial, config.max_pair_angle_deg);
                let c = correspondences(
                    matching,
                    &pairs,
                    &match_intrinsics,
                    &ground_truth,
                    opts,
                    config,
                )?;
                (
                    c.matches,
                    Some(c.precision),
                    c.densified_because,
                    Some(c.matcher),
                    c.fallback,
                )
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
        matcher,
        matcher_fallback,
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
    /// The matcher that ran.
    matcher: String,
    /// Why the configured matcher could not run.
    fallback: Option<String>,
}

/// SIFT correspondences between the given pairs of training views of `dataset` (in its
/// pixels), refined and densified as `config` asks (or, under
/// [`RunConfig::densify_if_needed`], as the warm-up needs), and their precision against the
/// ground-truth poses. Weight files of a learned matcher that exist but cannot be loaded are an
/// error.
fn correspondences(
    dataset: &Dataset,
    pairs: &[(usize, usize)],
    intrinsics: &[Intrinsics],
    ground_truth: &[Se3],
    options: &SiftOptions,
    config: &RunConfig,
) -> Result<Correspondences> {
    let (use_masks, refinement) = (config.train.use_masks, config.match_refinement.as_ref());
    let inputs: Vec<MatchInput> = dataset
        .train_views()
        .map(|v| MatchInput {
            image: &v.image,
            mask: if use_masks { v.mask.as_ref() } else { None },
        })
        .collect();
    let (matcher, fallback) = matcher_for(config.matcher_kind, options, &inputs)
        .map_err(|e| SurfaceError::invalid("--matcher", e.to_string()))?;
    let matches = match_pairs(matcher.as_ref(), &inputs, pairs);
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
    Ok(Correspondences {
        matches,
        precision,
        densified_because,
        matcher: matcher.name().to_string(),
        fallback,
    })
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
