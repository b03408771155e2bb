//! Camera poses from a few photos, as structure from motion finds them: SIFT matches between
//! every pair of photos (with dense matches added where SIFT finds few, as the surface method
//! grows them, and every match refined by affine Lucas–Kanade), the relative start (five-point pair poses, rotation averaging,
//! centres from the baseline directions), and the bundle adjustment of poses and tracks.
//!
//! **Gauge.** A model from photos alone is fixed up to a similarity. The first registered photo
//! is the world: its camera sits at the origin with the identity rotation, and the scale puts
//! the median depth of the tracks' points, over all their observations, at 1.
//!
//! **Intrinsics** start from EXIF or an assumed field of view ([`crate::photos`]). When all
//! photos share one camera, the bundle adjustment refines their common focal length (one
//! factor on every `fx`, `fy`), held near an EXIF focal by a prior as OpenSfM holds it
//! ([`PoseOptions::exif_focal_sd`]); the principal point stays at the centre unless asked.

use std::collections::HashMap;
use std::sync::atomic::{AtomicUsize, Ordering};

use fewview_match::dense::{DenseOptions, dense_matches};
use fewview_match::learned::{MatcherKind, matcher_for};
use fewview_match::refine::{AffineRefineOptions, refine_matches};
use fewview_match::retrieval::{RetrievalOptions, retrieval_pairs};
use fewview_match::sift::{SiftFeatures, SiftMatcher, SiftOptions};
use fewview_match::{Match, MatchInput, Matcher};
use fewview_scene::{Camera, Image, Intrinsics, Se3};
use rayon::prelude::*;
use serde::Serialize;

use crate::bundle::{
    BundleOptions, BundleReport, adjusted_intrinsics, bundle_adjust_with, triangulated_tracks,
};
use crate::error::{Result, SfmError};
use crate::global_start::{PairPose, relative_start_with};
use crate::photos::{FocalSource, Photo};

/// Options of [`estimate_poses`].
#[derive(Clone, Debug, PartialEq)]
pub struct PoseOptions {
    /// Fewest matches for a pair of photos to count as overlapping.
    pub min_matches: usize,
    /// Pairs with fewer SIFT matches than this also get the dense matcher's (`0`: never)...
    pub dense_below: usize,
    /// ...when there are at most this many photos (a pair of photos costs the dense matcher
    /// seconds; with many photos SIFT alone ties them together, as in COLMAP).
    pub dense_max_photos: usize,
    /// Spacing of the dense matcher's grid, as a fraction of the photos' long side (the
    /// surface method's dense matches: 0.01; poses need fewer tracks than a surface, and the
    /// grid's cost falls with the square of its spacing).
    pub dense_spacing: f64,
    /// Tracks whose reprojection error exceeds this (pixels of the working images) after the
    /// adjustment are left out of the model's points.
    pub max_error_px: f64,
    pub sift: SiftOptions,
    /// The matcher of the sparse correspondences: SIFT (`Classical`) or a learned one, which
    /// falls back to SIFT, and says so in the report, without its weights.
    pub matcher: MatcherKind,
    /// The bundle adjustment's options; its focal refinement is switched on when all photos
    /// share one camera (the same size and starting focal length), off otherwise, and so is
    /// its radial coefficient when [`BundleOptions::refine_radial`] asks for it.
    pub bundle: BundleOptions,
    /// When every photo's focal length comes from EXIF: the standard deviation (log scale) of
    /// the bundle's prior holding the shared focal near it ([`BundleOptions::focal_prior_sd`];
    /// `None`: free). Photos without an EXIF focal start from a guess and refine it freely.
    pub exif_focal_sd: Option<f64>,
    /// With more photos than this, each is matched only with the photos most like it
    /// ([`fewview_match::retrieval`]); up to this many, or with
    /// [`RetrievalOptions::neighbours`] 0, every pair is matched.
    pub retrieval_above: usize,
    /// How the photos most like each other are found (its seed is [`PoseOptions::seed`]).
    pub retrieval: RetrievalOptions,
    /// Seed of RANSAC and of the retrieval's vocabulary.
    pub seed: u64,
}

/// OpenSfM's standard deviation of an EXIF focal length in log scale (`exif_focal_sd`): the
/// default of [`PoseOptions::exif_focal_sd`].
pub const EXIF_FOCAL_SD: f64 = 0.01;

impl Default for PoseOptions {
    fn default() -> Self {
        Self {
            min_matches: 20,
            dense_below: 200,
            dense_max_photos: 10,
            dense_spacing: 0.0125,
            max_error_px: 4.0,
            sift: SiftOptions::default(),
            matcher: MatcherKind::Classical,
            bundle: BundleOptions::default(),
            exif_focal_sd: Some(EXIF_FOCAL_SD),
            retrieval_above: 20,
            retrieval: RetrievalOptions::default(),
            seed: 0,
        }
    }
}

/// A photo with its estimated camera.
#[derive(Clone, Debug)]
pub struct RegisteredPhoto {
    pub name: String,
    /// At the resolution of the photo's file.
    pub camera: Camera,
    pub focal_from: FocalSource,
}

/// A photo left out of the model, and why.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Unregistered {
    pub name: String,
    pub reason: String,
}

/// A triangulated track: its point, colour and where the photos see it.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelPoint {
    pub xyz: [f64; 3],
    pub rgb: [u8; 3],
    /// (index into [`PoseModel::photos`], pixel of the photo's file; centres at half-integers).
    pub observations: Vec<(usize, [f64; 2])>,
    /// Mean reprojection error (pixels of the working images).
    pub error_px: f64,
}

/// What [`estimate_poses`] measured on the way.
#[derive(Clone, Debug, Default, Serialize)]
pub struct PoseReport {
    pub photos: usize,
    pub registered: usize,
    /// Pairs of photos with at least `min_matches` matches, and those that gave a relative pose.
    pub overlapping_pairs: usize,
    pub pairs: Vec<PairPose>,
    /// The pairs of photos that were matched.
    pub matched_pairs: MatchedPairs,
    pub matches: usize,
    /// The matcher that ran, and why it is not the one asked for when it is not.
    pub matcher: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub matcher_fallback: Option<String>,
    pub bundle: BundleReport,
    pub points: usize,
    /// Median reprojection error of the model's points (pixels of the working images).
    pub median_error_px: f64,
}

/// How many pairs of photos were matched, and whether they were chosen by retrieval
/// ([`PoseOptions::retrieval_above`]) or were every pair.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct MatchedPairs {
    pub pairs: usize,
    pub chosen_by_retrieval: bool,
}

/// The estimated model.
#[derive(Clone, Debug)]
pub struct PoseModel {
    pub photos: Vec<RegisteredPhoto>,
    pub unregistered: Vec<Unregistered>,
    pub points: Vec<ModelPoint>,
    pub report: PoseReport,
}

/// Cameras for `photos` (module docs). Photos that share too little with the largest group of
/// overlapping photos are listed in [`PoseModel::unregistered`] with the reason; fewer than two
/// registered photos is an error.
pub fn estimate_poses(photos: &[Photo], options: &PoseOptions) -> Result<PoseModel> {
    estimate_poses_with(photos, options, |_| {})
}

/// [`estimate_poses`], reporting the progress of its long stages to `on_progress`.
pub fn estimate_poses_with(
    photos: &[Photo],
    options: &PoseOptions,
    on_progress: impl Fn(&PoseProgress) + Sync,
) -> Result<PoseModel> {
    if photos.len() < 2 {
        return Err(SfmError::NoModel(format!(
            "{} photo(s): poses need at least two photos that overlap",
            photos.len()
        )));
    }
    let inputs: Vec<MatchInput> = photos
        .iter()
        .map(|p| MatchInput {
            image: &p.image,
            mask: None,
        })
        .collect();
    let sift = SiftMatcher {
        options: SiftOptions {
            seed: options.seed,
            ..options.sift.clone()
        },
    };
    // A learned matcher when asked and its weights load; SIFT (with the reason) otherwise.
    let (learned, fallback) = match options.matcher {
        MatcherKind::Classical => (None, None),
        kind => {
            let (matcher, fallback) = matcher_for(kind, &sift.options, &inputs)
                .map_err(|e| SfmError::Matcher(e.to_string()))?;
            (fallback.is_none().then_some(matcher), fallback)
        }
    };
    let (matches, matched_pairs) =
        correspondences(&inputs, (&sift, learned.as_deref()), options, &on_progress);
    let (group, unregistered) = largest_group(photos, &matches, options.min_matches);
    if group.len() < 2 {
        return Err(SfmError::NoModel(format!(
            "no two of the {} photos share {} matches or more",
            photos.len(),
            options.min_matches
        )));
    }
    let (intrinsics, matches) = restricted(photos, &matches, &group);
    let start = relative_start_with(
        group.len(),
        &intrinsics,
        &matches,
        (options.min_matches, options.seed),
        |done, total| {
            on_progress(&PoseProgress {
                stage: PoseStage::RelativePoses,
                done,
                total,
            });
        },
    )
    .map_err(SfmError::NoModel)?;
    let one_camera = intrinsics.iter().all(|k| *k == intrinsics[0]);
    let focal_from_exif = group
        .iter()
        .all(|&i| photos[i].focal_from == FocalSource::Exif35mm);
    let bundle_options = BundleOptions {
        refine_focal: one_camera,
        focal_prior_sd: options.exif_focal_sd.filter(|_| focal_from_exif),
        refine_radial: one_camera && options.bundle.refine_radial,
        refine_principal_point: one_camera && options.bundle.refine_principal_point,
        ..options.bundle
    };
    let on_iteration = |done| {
        on_progress(&PoseProgress {
            stage: PoseStage::Adjustment,
            done,
            total: bundle_options.max_iterations,
        });
    };
    let (poses, bundle) = bundle_adjust_with(
        &intrinsics,
        &start.poses,
        &matches,
        &bundle_options,
        on_iteration,
    );
    let intrinsics = adjusted_intrinsics(&intrinsics, &bundle);
    let k1 = bundle.radial_k1.unwrap_or(0.0);
    let (poses, points) =
        scaled_model(photos, &group, (&intrinsics, k1), &poses, &matches, options);
    let mut errors: Vec<f64> = points.iter().map(|p| p.error_px).collect();
    errors.sort_by(f64::total_cmp);
    let report = PoseReport {
        photos: photos.len(),
        registered: group.len(),
        overlapping_pairs: overlapping_pairs(&matches, group.len(), options.min_matches),
        pairs: start.pairs,
        matched_pairs,
        matches: matches.len(),
        matcher: match (&learned, &fallback) {
            (Some(_), _) => options.matcher.name().to_string(),
            _ => MatcherKind::Classical.name().to_string(),
        },
        matcher_fallback: fallback,
        bundle,
        points: points.len(),
        median_error_px: errors.get(errors.len() / 2).copied().unwrap_or(f64::NAN),
    };
    let photos = group
        .iter()
        .zip(&poses)
        .zip(&intrinsics)
        .map(|((&i, pose), k)| RegisteredPhoto {
            name: photos[i].name.clone(),
            camera: Camera::new(full_intrinsics(&photos[i], k), *pose),
            focal_from: photos[i].focal_from,
        })
        .collect();
    Ok(PoseModel {
        photos,
        unregistered,
        points,
        report,
    })
}

/// How far [`estimate_poses_with`] is: `done` of `total` steps of `stage`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PoseProgress {
    pub stage: PoseStage,
    pub done: usize,
    pub total: usize,
}

/// The long stages of pose estimation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PoseStage {
    /// SIFT features, one photo at a time.
    Features,
    /// Matching the features of every pair.
    Matching,
    /// The dense matcher on the pairs where SIFT found few matches.
    DenseMatching,
    /// Every match refined by affine Lucas–Kanade (one step: no finer progress is told).
    Refinement,
    /// The five-point relative pose of every overlapping pair.
    RelativePoses,
    /// The bundle adjustment's iterations (up to its most; it usually stops before).
    Adjustment,
}

impl PoseStage {
    pub fn name(self) -> &'static str {
        match self {
            Self::Features => "features",
            Self::Matching => "matching",
            Self::DenseMatching => "dense matching",
            Self::Refinement => "refining matches",
            Self::RelativePoses => "relative poses",
            Self::Adjustment => "bundle adjustment",
        }
    }
}

/// SIFT matches of every pair (each photo's features computed once; with more than
/// [`PoseOptions::retrieval_above`] photos, of the pairs [`pairs_to_match`] chooses), dense
/// ones added to pairs with few, all refined by affine Lucas–Kanade (the refinement drops the
/// matches whose windows do not agree).
fn correspondences(
    inputs: &[MatchInput],
    (sift, learned): (&SiftMatcher, Option<&dyn Matcher>),
    options: &PoseOptions,
    on_progress: &(impl Fn(&PoseProgress) + Sync),
) -> (Vec<Match>, MatchedPairs) {
    let n = inputs.len();
    let counter = AtomicUsize::new(0);
    let step = |stage: PoseStage, total: usize| {
        let done = counter.fetch_add(1, Ordering::Relaxed) + 1;
        on_progress(&PoseProgress { stage, done, total });
    };
    // SIFT features: the classical matcher's, and the global descriptors' when there are too
    // many photos to match every pair.
    let retrieve = n > options.retrieval_above && options.retrieval.neighbours > 0;
    let features: Vec<SiftFeatures> = if learned.is_none() || retrieve {
        let features = inputs
            .par_iter()
            .map(|input| {
                let f = sift.features(input);
                step(PoseStage::Features, n);
                f
            })
            .collect();
        counter.store(0, Ordering::Relaxed);
        features
    } else {
        Vec::new()
    };
    let (pairs, matched) = pairs_to_match(n, retrieve.then_some(features.as_slice()), options);
    let with_views = |(a, b): (usize, usize), found: Vec<Match>| {
        found.into_iter().map(move |m| Match {
            view_a: a,
            view_b: b,
            ..m
        })
    };
    let mut matches: Vec<Match> = match learned {
        // A learned matcher runs its network on its own threads: one pair at a time.
        Some(matcher) => pairs
            .iter()
            .flat_map(|&(a, b)| {
                let found = matcher.match_pair(&inputs[a], &inputs[b]);
                step(PoseStage::Matching, pairs.len());
                with_views((a, b), found)
            })
            .collect(),
        None => pairs
            .par_iter()
            .flat_map_iter(|&(a, b)| {
                let found = sift.match_features(&features[a], &features[b]);
                step(PoseStage::Matching, pairs.len());
                with_views((a, b), found)
            })
            .collect(),
    };
    let counts = match_counts(&matches, n);
    let long_side = inputs
        .iter()
        .map(|i| i.image.width.max(i.image.height))
        .max()
        .unwrap_or(0) as f64;
    let dense = DenseOptions {
        spacing_px: Some(options.dense_spacing * long_side),
        seed: options.seed,
        ..DenseOptions::default()
    };
    let sparse_pairs: Vec<(usize, usize)> = pairs
        .into_iter()
        .filter(|&(a, b)| counts[a][b] < options.dense_below && n <= options.dense_max_photos)
        .collect();
    counter.store(0, Ordering::Relaxed);
    for &(a, b) in &sparse_pairs {
        matches.extend(dense_matches(&inputs[a], &inputs[b], a, b, &dense));
        step(PoseStage::DenseMatching, sparse_pairs.len());
    }
    let images: Vec<&Image> = inputs.iter().map(|i| i.image).collect();
    let refinement = |done| {
        on_progress(&PoseProgress {
            stage: PoseStage::Refinement,
            done,
            total: 1,
        });
    };
    refinement(0);
    let refined = refine_matches(&images, &matches, &AffineRefineOptions::default());
    refinement(1);
    (shared_ends(&matches, refined), matched)
}

/// The pairs `(a, b)`, `a < b`, of `n` photos to match: those [`retrieval_pairs`] chooses from
/// the photos' SIFT `features` when given, else every pair.
fn pairs_to_match(
    n: usize,
    features: Option<&[SiftFeatures]>,
    options: &PoseOptions,
) -> (Vec<(usize, usize)>, MatchedPairs) {
    let pairs: Vec<(usize, usize)> = match features {
        Some(features) => {
            let descriptors: Vec<&[[f32; 128]]> =
                features.iter().map(SiftFeatures::descriptors).collect();
            let retrieval = RetrievalOptions {
                seed: options.seed,
                ..options.retrieval
            };
            retrieval_pairs(&descriptors, &retrieval)
        }
        None => (0..n)
            .flat_map(|a| (a + 1..n).map(move |b| (a, b)))
            .collect(),
    };
    let matched = MatchedPairs {
        pairs: pairs.len(),
        chosen_by_retrieval: features.is_some(),
    };
    (pairs, matched)
}

/// The refined matches with every end that was one pixel before the refinement one pixel
/// again. The refinement moves each match's second end on its own, so a keypoint matched from
/// two views lands on two nearby positions and the tracks of the bundle adjustment (matches
/// that share a view and a pixel) fall apart into pairs; here each (view, keypoint) takes the
/// position its first refinement gave it, in both roles.
fn shared_ends(raw: &[Match], refined: Vec<Match>) -> Vec<Match> {
    type Key = (usize, u32, u32);
    let key = |view: usize, p: [f32; 2]| (view, p[0].to_bits(), p[1].to_bits());
    // The refinement keeps each match's first end: it identifies the raw match of its pair.
    let raw_b: HashMap<(usize, usize, u32, u32), [f32; 2]> = raw
        .iter()
        .map(|m| {
            (
                (m.view_a, m.view_b, m.a[0].to_bits(), m.a[1].to_bits()),
                m.b,
            )
        })
        .collect();
    let original_b = |m: &Match| {
        raw_b
            .get(&(m.view_a, m.view_b, m.a[0].to_bits(), m.a[1].to_bits()))
            .copied()
    };
    let mut position: HashMap<Key, [f32; 2]> = HashMap::new();
    for m in &refined {
        if let Some(b) = original_b(m) {
            position.entry(key(m.view_b, b)).or_insert(m.b);
        }
    }
    refined
        .iter()
        .map(|m| {
            let b = original_b(m)
                .and_then(|b| position.get(&key(m.view_b, b)))
                .copied()
                .unwrap_or(m.b);
            let a = position.get(&key(m.view_a, m.a)).copied().unwrap_or(m.a);
            Match { a, b, ..*m }
        })
        .collect()
}

/// Number of matches between photos `i` and `j` of `n`, as a symmetric table.
fn match_counts(matches: &[Match], n: usize) -> Vec<Vec<usize>> {
    let mut counts = vec![vec![0; n]; n];
    for m in matches {
        counts[m.view_a][m.view_b] += 1;
        counts[m.view_b][m.view_a] += 1;
    }
    counts
}

fn overlapping_pairs(matches: &[Match], n: usize, min_matches: usize) -> usize {
    let counts = match_counts(matches, n);
    (0..n)
        .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
        .filter(|&(i, j)| counts[i][j] >= min_matches)
        .count()
}

/// The largest set of photos connected by pairs with at least `min_matches` matches (ties: the
/// one with the first photo), and the others with their reason.
fn largest_group(
    photos: &[Photo],
    matches: &[Match],
    min_matches: usize,
) -> (Vec<usize>, Vec<Unregistered>) {
    let n = photos.len();
    let counts = match_counts(matches, n);
    let mut component = vec![usize::MAX; n];
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for seed in 0..n {
        if component[seed] != usize::MAX {
            continue;
        }
        let id = groups.len();
        let mut group = vec![seed];
        component[seed] = id;
        let mut next = 0;
        while next < group.len() {
            let i = group[next];
            next += 1;
            for j in 0..n {
                if component[j] == usize::MAX && counts[i][j] >= min_matches {
                    component[j] = id;
                    group.push(j);
                }
            }
        }
        group.sort_unstable();
        groups.push(group);
    }
    let best = groups
        .iter()
        .enumerate()
        .max_by_key(|(id, g)| (g.len(), std::cmp::Reverse(*id)))
        .map(|(id, _)| id)
        .unwrap_or(0);
    let unregistered = (0..n)
        .filter(|&i| component[i] != best)
        .map(|i| {
            let most = groups[best]
                .iter()
                .map(|&j| counts[i][j])
                .max()
                .unwrap_or(0);
            Unregistered {
                name: photos[i].name.clone(),
                reason: format!(
                    "shares at most {most} matches with a registered photo (needs {min_matches})"
                ),
            }
        })
        .collect();
    (groups.swap_remove(best), unregistered)
}

/// The intrinsics of the `group`'s photos and their matches, with views renumbered in it.
fn restricted(
    photos: &[Photo],
    matches: &[Match],
    group: &[usize],
) -> (Vec<Intrinsics>, Vec<Match>) {
    let index = |v: usize| group.iter().position(|&g| g == v);
    let intrinsics = group.iter().map(|&i| photos[i].intrinsics).collect();
    let matches = matches
        .iter()
        .filter_map(|m| {
            Some(Match {
                view_a: index(m.view_a)?,
                view_b: index(m.view_b)?,
                ..*m
            })
        })
        .collect();
    (intrinsics, matches)
}

/// The intrinsics `k` of a photo's working image at the resolution of its file.
fn full_intrinsics(photo: &Photo, k: &Intrinsics) -> Intrinsics {
    let (w, h) = photo.full_size;
    let (sx, sy) = (w as f64 / k.width as f64, h as f64 / k.height as f64);
    Intrinsics {
        fx: k.fx * sx,
        fy: k.fy * sy,
        cx: k.cx * sx,
        cy: k.cy * sy,
        width: w as u32,
        height: h as u32,
    }
}

/// The adjusted poses and the tracks' points in the gauge of the module docs: the first photo
/// at the origin, the median depth 1.
fn scaled_model(
    photos: &[Photo],
    group: &[usize],
    (intrinsics, k1): (&[Intrinsics], f64),
    poses: &[Se3],
    matches: &[Match],
    options: &PoseOptions,
) -> (Vec<Se3>, Vec<ModelPoint>) {
    let to_first = poses[0].inverse();
    let poses: Vec<Se3> = poses.iter().map(|p| p.compose(&to_first)).collect();
    let tracks: Vec<_> = triangulated_tracks(intrinsics, k1, &poses, matches)
        .into_iter()
        .filter(|t| t.errors_px.iter().all(|e| *e <= options.max_error_px))
        .collect();
    let mut depths: Vec<f64> = tracks
        .iter()
        .flat_map(|t| {
            t.track
                .observations
                .iter()
                .map(|(v, _)| (poses[*v].rotation * t.point + poses[*v].translation).z)
                .collect::<Vec<_>>()
        })
        .collect();
    depths.sort_by(f64::total_cmp);
    let median = depths.get(depths.len() / 2).copied().unwrap_or(1.0);
    let s = if median > 0.0 { 1.0 / median } else { 1.0 };
    let poses: Vec<Se3> = poses
        .iter()
        .map(|p| Se3::new(p.rotation, p.translation * s))
        .collect();
    let points = tracks
        .iter()
        .map(|t| {
            let (v0, p0) = t.track.observations[0];
            let photo = &photos[group[v0]];
            let rgb = colour_at(&photo.image, p0.x, p0.y);
            let observations = t
                .track
                .observations
                .iter()
                .map(|(v, p)| {
                    let photo = &photos[group[*v]];
                    let sx = photo.full_size.0 as f64 / photo.image.width as f64;
                    let sy = photo.full_size.1 as f64 / photo.image.height as f64;
                    (*v, [p.x * sx, p.y * sy])
                })
                .collect();
            let x = t.point * s;
            ModelPoint {
                xyz: [x.x, x.y, x.z],
                rgb,
                observations,
                error_px: t.errors_px.iter().sum::<f64>() / t.errors_px.len() as f64,
            }
        })
        .collect();
    (poses, points)
}

/// The 8-bit colour of the pixel under `(x, y)` (centres at half-integers).
fn colour_at(image: &fewview_scene::Image, x: f64, y: f64) -> [u8; 3] {
    let (px, py) = (
        (x.floor().max(0.0) as usize).min(image.width - 1),
        (y.floor().max(0.0) as usize).min(image.height - 1),
    );
    let p = image.pixel(px, py);
    let c = |k: usize| (p[k.min(p.len() - 1)].clamp(0.0, 1.0) * 255.0).round() as u8;
    [c(0), c(1), c(2)]
}
