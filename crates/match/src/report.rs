//! How well a matcher does on views with known cameras (`fewview match`): the matches of every
//! pair of training views and their symmetric epipolar distances under the true cameras, as
//! they leave the matcher and after the Lucas–Kanade refinement the surface method applies.

use std::time::Instant;

use fewview_scene::{Camera, Dataset};
use serde::Serialize;

use super::learned::{MatcherKind, matcher_for};
use super::refine::{AffineRefineOptions, refine_matches};
use super::sift::SiftOptions;
use crate::correspondence::{
    Match, MatchInput, MatchPrecision, epipolar_precision, match_pairs, unordered_pairs,
};

/// One pair of views.
#[derive(Clone, Debug, Serialize)]
pub struct PairReport {
    /// The dataset's view indices.
    pub views: [usize; 2],
    /// As the matcher gives them (after its RANSAC filter).
    pub raw: MatchPrecision,
    /// After the affine Lucas–Kanade refinement of the second ends.
    pub refined: MatchPrecision,
}

/// Every pair of a dataset's training views.
#[derive(Clone, Debug, Serialize)]
pub struct MatchReport {
    pub dataset: String,
    /// The matcher that ran.
    pub matcher: String,
    /// Why the requested matcher could not run, when the classical one ran instead.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fallback: Option<String>,
    pub pairs: Vec<PairReport>,
    /// Wall seconds of the matching alone (without the refinement).
    pub matching_seconds: f64,
    /// The refined matches, with the training-view indices of their pair.
    #[serde(skip)]
    pub matches: Vec<Match>,
}

/// Matches every pair of `dataset`'s training views with `kind` and scores them against the
/// dataset's cameras. Masks restrict the matches when `use_masks`. Weight files that exist but
/// cannot be loaded are an error ([`matcher_for`]).
pub fn match_report(
    dataset: &Dataset,
    kind: MatcherKind,
    use_masks: bool,
) -> Result<MatchReport, crate::error::MatchError> {
    let views: Vec<_> = dataset.train_views().collect();
    let inputs: Vec<MatchInput> = views
        .iter()
        .map(|v| MatchInput {
            image: &v.image,
            mask: v.mask.as_ref().filter(|_| use_masks),
        })
        .collect();
    let cameras: Vec<Camera> = views.iter().map(|v| v.camera.clone()).collect();
    let (matcher, fallback) = matcher_for(kind, &SiftOptions::default(), &inputs)?;
    let pairs: Vec<(usize, usize)> = unordered_pairs(inputs.len()).collect();
    let started = Instant::now();
    let raw = match_pairs(matcher.as_ref(), &inputs, &pairs);
    let matching_seconds = started.elapsed().as_secs_f64();
    let images: Vec<_> = inputs.iter().map(|i| i.image).collect();
    let refined = refine_matches(&images, &raw, &AffineRefineOptions::default());
    let of_pair = |all: &[Match], (i, j): (usize, usize)| -> Vec<Match> {
        all.iter()
            .filter(|m| m.view_a == i && m.view_b == j)
            .copied()
            .collect()
    };
    let pairs = pairs
        .iter()
        .map(|&p| PairReport {
            views: [dataset.train[p.0], dataset.train[p.1]],
            raw: epipolar_precision(&of_pair(&raw, p), &cameras),
            refined: epipolar_precision(&of_pair(&refined, p), &cameras),
        })
        .collect();
    Ok(MatchReport {
        dataset: dataset.name.clone(),
        matcher: matcher.name().to_string(),
        fallback,
        pairs,
        matching_seconds,
        matches: refined,
    })
}
