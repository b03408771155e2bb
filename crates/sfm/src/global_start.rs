//! A global start for the epipolar warm-up, as structure from motion starts: for every pair of
//! views with enough matches, the relative pose from the matches alone (five-point RANSAC on
//! the essential matrix, then a robust refinement: [`fewview_geom::epipolar::relative_pose`]);
//! then the absolute rotations by rotation averaging over the pairs, the camera centres from the
//! baseline directions with each baseline's length taken from the initial poses where the
//! directions leave it free, and the whole set moved onto the initial poses by a similarity.
//!
//! Why: the warm-up's Levenberg–Marquardt is local: from noisy poses it can settle in a basin
//! where the matches still sit well off their epipolar lines and the rotations stay far off.
//! The relative poses need no initial poses at all, so they cannot inherit that basin.

use std::collections::HashMap;

use fewview_geom::epipolar::averaging::LENGTH_PRIOR_WEIGHT;
use fewview_geom::epipolar::{
    Baseline, RelativePoseOptions, RelativeRotation, average_rotations, centres_from_baselines,
    project_to_rotation, relative_pose,
};
use fewview_scene::{Intrinsics, Se3};
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use crate::baseline_lengths::{PairPixels, baseline_lengths};
use fewview_match::Match;

/// One pair's relative pose as the five-point step found it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PairPose {
    pub view_a: usize,
    pub view_b: usize,
    pub matches: usize,
    pub inliers: usize,
    /// Median Sampson distance of the inliers (pixels).
    pub median_px: f64,
    /// `R_b R_aᵀ` of the world-to-camera rotations, row-major.
    pub rotation: [[f64; 3]; 3],
    /// Unit translation `t` of `x_b = R x_a + t`.
    pub translation: [f64; 3],
}

/// The global start and the pairs it came from.
#[derive(Clone, Debug)]
pub struct GlobalStart {
    pub poses: Vec<Se3>,
    pub pairs: Vec<PairPose>,
}

/// The RANSAC inlier threshold for images of this size: 1 px per 400 px of the diagonal's
/// 500 (0.25 % of the diagonal), at least 1 px, so that 400 × 300 and 1600 × 1200 views
/// accept the same fraction of a matcher's errors.
pub fn inlier_threshold_px(intrinsics: &[Intrinsics]) -> f64 {
    let diagonal = intrinsics
        .iter()
        .map(|k| (k.width as f64).hypot(k.height as f64))
        .fold(0.0, f64::max);
    (0.0025 * diagonal).max(1.0)
}

/// The pixel positions of one pair's matches: views `a < b`, the points in each.
struct PairMatches {
    a: usize,
    b: usize,
    in_a: Vec<[f64; 2]>,
    in_b: Vec<[f64; 2]>,
}

/// The matches of each pair of views with at least `min_per_pair` of them.
fn pairs_of(matches: &[Match], n: usize, min_per_pair: usize) -> Vec<PairMatches> {
    let mut out = Vec::new();
    for a in 0..n {
        for b in a + 1..n {
            let (mut pa, mut pb) = (Vec::new(), Vec::new());
            for m in matches {
                let (x, y) = match (m.view_a, m.view_b) {
                    (va, vb) if va == a && vb == b => (m.a, m.b),
                    (va, vb) if va == b && vb == a => (m.b, m.a),
                    _ => continue,
                };
                pa.push([x[0] as f64, x[1] as f64]);
                pb.push([y[0] as f64, y[1] as f64]);
            }
            if pa.len() >= min_per_pair.max(5) {
                out.push(PairMatches {
                    a,
                    b,
                    in_a: pa,
                    in_b: pb,
                });
            }
        }
    }
    out
}

/// The poses the matches imply on their own, placed where `initial` is (one pose per view,
/// `intrinsics` alike), or why there are none: fewer than two usable pairs' worth of views, a
/// pair without a model, or pairs that do not connect the views.
pub fn global_start(
    initial: &[Se3],
    intrinsics: &[Intrinsics],
    matches: &[Match],
    min_per_pair: usize,
    seed: u64,
) -> Result<GlobalStart, String> {
    let n = initial.len();
    let mut pairs = Vec::new();
    for pair in pairs_of(matches, n, min_per_pair) {
        let (a, b, count) = (pair.a, pair.b, pair.in_a.len());
        let pose = pair_pose(&pair, intrinsics, seed)
            .ok_or_else(|| format!("no relative pose for views {a} and {b} ({count} matches)"))?;
        pairs.push(pose);
    }
    let rotations = averaged_rotations(n, &pairs)?;
    // The world rotation the averaging leaves free: the one nearest the initial rotations.
    let g = project_to_rotation(
        &rotations
            .iter()
            .zip(initial)
            .map(|(r, p)| r.transpose() * p.rotation)
            .sum::<Matrix3<f64>>(),
    );
    let rotations: Vec<Matrix3<f64>> = rotations.iter().map(|r| r * g).collect();
    let initial_centres: Vec<Vector3<f64>> =
        initial.iter().map(|p| p.inverse().translation).collect();
    let prior = |k: usize| {
        let (i, j) = (pairs[k].view_a, pairs[k].view_b);
        let length = (initial_centres[j] - initial_centres[i]).norm();
        (length, LENGTH_PRIOR_WEIGHT)
    };
    let poses = poses_from_baselines(n, &pairs, &rotations, prior)?;
    Ok(GlobalStart {
        poses: crate::se3::into_frame_of(&poses, initial),
        pairs,
    })
}

/// The poses the matches imply with no poses to start from, as structure from motion starts:
/// view 0 at the origin with the identity rotation; the baselines of wide triangles of pairs
/// as their directions fix them, the others (flat triangles, as a walk forward makes, or no
/// triangle) as long as the points they share with other pairs measure them
/// ([`crate::baseline_lengths`]), and one unit where nothing measures them. Pairs whose
/// matches give no relative pose, or whose rotation disagrees with the averaged ones by more
/// than [`MAX_PAIR_DISAGREEMENT_DEG`] (dropped worst first while the rest connect the views),
/// are left out; `Err` says why there is no start when the
/// remaining pairs do not connect the `n` views.
pub fn relative_start(
    n: usize,
    intrinsics: &[Intrinsics],
    matches: &[Match],
    min_per_pair: usize,
    seed: u64,
) -> Result<GlobalStart, String> {
    relative_start_with(n, intrinsics, matches, (min_per_pair, seed), |_, _| {})
}

/// [`relative_start`], telling `on_pair(done, total)` after each pair's relative pose.
pub fn relative_start_with(
    n: usize,
    intrinsics: &[Intrinsics],
    matches: &[Match],
    (min_per_pair, seed): (usize, u64),
    on_pair: impl Fn(usize, usize),
) -> Result<GlobalStart, String> {
    let overlapping = pairs_of(matches, n, min_per_pair);
    let mut pairs: Vec<PairPose> = overlapping
        .iter()
        .enumerate()
        .filter_map(|(i, pair)| {
            let pose = pair_pose(pair, intrinsics, seed);
            on_pair(i + 1, overlapping.len());
            pose
        })
        .collect();
    let mut rotations = averaged_rotations(n, &pairs)?;
    // A pair whose relative rotation disagrees with the others (a wrong model from few or
    // look-alike matches) is dropped while the rest still connect the views.
    while let Some(worst) = worst_disagreeing_pair(&pairs, &rotations) {
        let mut fewer = pairs.clone();
        fewer.remove(worst);
        let Ok(again) = averaged_rotations(n, &fewer) else {
            break;
        };
        (pairs, rotations) = (fewer, again);
    }
    let g = rotations[0].transpose();
    let rotations: Vec<Matrix3<f64>> = rotations.iter().map(|r| r * g).collect();
    let fixed = fixed_by_directions(&pairs, &rotations);
    let lengths: Vec<Option<f64>> = if fixed.iter().all(|&f| f) {
        vec![None; pairs.len()]
    } else {
        let measured = measured_lengths(&pairs, &overlapping, intrinsics);
        measured
            .into_iter()
            .zip(&fixed)
            .map(|(length, &fixed)| length.filter(|_| !fixed))
            .collect()
    };
    let poses = poses_from_baselines(n, &pairs, &rotations, |k| match lengths[k] {
        Some(length) => (length, MEASURED_LENGTH_WEIGHT),
        None => (1.0, LENGTH_PRIOR_WEIGHT),
    })?;
    Ok(GlobalStart { poses, pairs })
}

/// How much a baseline length measured by shared points counts beside the baseline's
/// direction: as much (a guessed length counts [`LENGTH_PRIOR_WEIGHT`]).
pub const MEASURED_LENGTH_WEIGHT: f64 = 1.0;

/// A triangle of pairs fixes its baselines' lengths when each of its angles is at least this
/// many degrees.
pub const FLAT_TRIANGLE_DEG: f64 = 10.0;

/// Per pair, whether the baseline directions fix its length: it belongs to a triangle of
/// pairs whose angles are all at least [`FLAT_TRIANGLE_DEG`]. A walk forward or along a row
/// makes every triangle flat, and a pair outside any triangle is free; their lengths are
/// better measured by the shared points. Elsewhere the directions fix them better than the
/// points measure them (the points carry each pair's own pose error).
fn fixed_by_directions(pairs: &[PairPose], rotations: &[Matrix3<f64>]) -> Vec<bool> {
    // c_b − c_a of each pair's views (a, b), found either way round.
    let directions: HashMap<(usize, usize), Vector3<f64>> = pairs
        .iter()
        .map(|p| {
            let d = -(rotations[p.view_b].transpose() * Vector3::from(p.translation));
            ((p.view_a, p.view_b), d)
        })
        .collect();
    let baseline = |a: usize, b: usize| {
        (directions.get(&(a, b)).copied()).or_else(|| directions.get(&(b, a)).map(|d| -d))
    };
    let wide = |i: usize, j: usize, m: usize| {
        let (Some(ij), Some(im), Some(jm)) = (baseline(i, j), baseline(i, m), baseline(j, m))
        else {
            return false;
        };
        [ij.angle(&im), (-ij).angle(&jm), im.angle(&jm)]
            .iter()
            .all(|a| a.to_degrees() >= FLAT_TRIANGLE_DEG)
    };
    pairs
        .iter()
        .map(|p| {
            let (i, j) = (p.view_a, p.view_b);
            (0..rotations.len()).any(|m| m != i && m != j && wide(i, j, m))
        })
        .collect()
}

/// The length of each pair's baseline measured by the points it shares with other pairs
/// ([`crate::baseline_lengths`]), `None` where nothing measures it.
fn measured_lengths(
    pairs: &[PairPose],
    matches: &[PairMatches],
    intrinsics: &[Intrinsics],
) -> Vec<Option<f64>> {
    let pixels: Vec<PairPixels<'_>> = pairs
        .iter()
        .filter_map(|pose| {
            let m = matches
                .iter()
                .find(|m| (m.a, m.b) == (pose.view_a, pose.view_b))?;
            Some(PairPixels {
                views: (pose.view_a, pose.view_b),
                rotation: Matrix3::from_fn(|i, j| pose.rotation[i][j]),
                translation: Vector3::from(pose.translation),
                in_a: &m.in_a,
                in_b: &m.in_b,
            })
        })
        .collect();
    if pixels.len() != pairs.len() {
        return vec![None; pairs.len()];
    }
    baseline_lengths(&pixels, intrinsics)
}

/// A pair's relative rotation may disagree with the averaged rotations by at most this many
/// degrees before [`relative_start`] drops it.
pub const MAX_PAIR_DISAGREEMENT_DEG: f64 = 2.0;

/// The pair whose relative rotation disagrees most with `rotations`, when that is beyond
/// [`MAX_PAIR_DISAGREEMENT_DEG`].
fn worst_disagreeing_pair(pairs: &[PairPose], rotations: &[Matrix3<f64>]) -> Option<usize> {
    pairs
        .iter()
        .map(|p| {
            let r = Matrix3::from_fn(|i, j| p.rotation[i][j]);
            let implied = rotations[p.view_b] * rotations[p.view_a].transpose();
            fewview_geom::similarity::rotation_angle_deg(&(r * implied.transpose()))
        })
        .enumerate()
        .filter(|(_, deg)| *deg > MAX_PAIR_DISAGREEMENT_DEG)
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i)
}

/// One pair's relative pose from its matches (five-point RANSAC, then the robust refinement),
/// `None` when the matches give no model.
fn pair_pose(pair: &PairMatches, intrinsics: &[Intrinsics], seed: u64) -> Option<PairPose> {
    let (a, b) = (pair.a, pair.b);
    let options = RelativePoseOptions {
        threshold_px: inlier_threshold_px(intrinsics),
        seed,
        ..RelativePoseOptions::default()
    };
    let (ka, kb) = (intrinsics[a].matrix(), intrinsics[b].matrix());
    let pose = relative_pose(&pair.in_a, &pair.in_b, &ka, &kb, &options)?;
    let r = pose.rotation;
    Some(PairPose {
        view_a: a,
        view_b: b,
        matches: pair.in_a.len(),
        inliers: pose.inliers.iter().filter(|i| **i).count(),
        median_px: pose.median_px,
        rotation: std::array::from_fn(|i| std::array::from_fn(|j| r[(i, j)])),
        translation: pose.translation.into(),
    })
}

/// World-to-camera rotations of `n` views averaged over the pairs' relative rotations (weighted
/// by their inliers), up to a common rotation.
fn averaged_rotations(n: usize, pairs: &[PairPose]) -> Result<Vec<Matrix3<f64>>, String> {
    let edges: Vec<RelativeRotation> = pairs
        .iter()
        .map(|p| RelativeRotation {
            i: p.view_a,
            j: p.view_b,
            rotation: Matrix3::from_fn(|i, j| p.rotation[i][j]),
            weight: p.inliers as f64,
        })
        .collect();
    average_rotations(n, &edges)
        .ok_or_else(|| "the pairs with enough matches do not connect all views".to_string())
}

/// Poses from the `rotations` and the camera centres the pairs' baseline directions give,
/// the `k`-th pair's baseline with the prior length and weight `prior(k)`.
fn poses_from_baselines(
    n: usize,
    pairs: &[PairPose],
    rotations: &[Matrix3<f64>],
    prior: impl Fn(usize) -> (f64, f64),
) -> Result<Vec<Se3>, String> {
    let baselines: Vec<Baseline> = pairs
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let t = Vector3::from(p.translation);
            let (prior_length, prior_weight) = prior(k);
            Baseline {
                i: p.view_a,
                j: p.view_b,
                // x_b = R x_a + t with t = −R_b (c_b − c_a).
                direction: -(rotations[p.view_b].transpose() * t),
                prior_length,
                weight: p.inliers as f64,
                prior_weight,
            }
        })
        .collect();
    let centres = centres_from_baselines(n, &baselines)
        .ok_or_else(|| "the pairs with enough matches do not connect all views".to_string())?;
    Ok(rotations
        .iter()
        .zip(&centres)
        .map(|(r, c)| Se3::new(*r, -(r * c)))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use fewview_geom::similarity::rotation_angle_deg as angle_deg;
    use fewview_scene::Camera;

    /// The exact matches of point `p` between every two of the three cameras that see it.
    fn exact_matches_of(truth: &[Camera], p: &Vector3<f64>) -> Vec<Match> {
        [(0, 1), (1, 2), (0, 2)]
            .into_iter()
            .filter_map(|(a, b)| {
                let (pa, pb) = (truth[a].project(p)?, truth[b].project(p)?);
                Some(Match {
                    view_a: a,
                    view_b: b,
                    a: [pa.0 as f32, pa.1 as f32],
                    b: [pb.0 as f32, pb.1 as f32],
                    confidence: 1.0,
                    b_covariance: None,
                })
            })
            .collect()
    }

    /// Three cameras around the origin with exact matches: the start equals the true poses
    /// up to the similarity it was placed with, from initial poses 10° and 30 % off.
    #[test]
    fn exact_matches_give_the_true_relative_poses() {
        let k = Intrinsics::centered(500.0, 400, 300);
        let truth: Vec<Camera> = [(3.0, 0.5, 1.0), (2.2, 2.0, 0.8), (0.6, 3.0, 1.2)]
            .iter()
            .map(|&(x, y, z)| {
                Camera::look_at(k, Vector3::new(x, y, z), Vector3::zeros(), Vector3::z())
            })
            .collect();
        let mut matches = Vec::new();
        for s in 0..400 {
            let f = s as f64;
            let p = Vector3::new((0.37 * f).sin(), (0.71 * f).cos(), (0.13 * f).sin()) * 0.6;
            matches.extend(exact_matches_of(&truth, &p));
        }
        let initial: Vec<Se3> = truth
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let w = Vector3::new(0.1, -0.12, 0.08) * (i as f64 + 1.0);
                let noise = Se3::new(
                    nalgebra::Rotation3::new(w).into_inner(),
                    Vector3::new(0.3, 0.0, -0.2),
                );
                noise.compose(&c.world_to_camera)
            })
            .collect();
        let start = global_start(&initial, &[k; 3], &matches, 20, 0).unwrap();
        assert_eq!(start.pairs.len(), 3);
        for (a, b) in [(0, 1), (1, 2), (0, 2)] {
            let (ta, tb) = (&truth[a].world_to_camera, &truth[b].world_to_camera);
            let (sa, sb) = (&start.poses[a], &start.poses[b]);
            let true_rel = tb.rotation * ta.rotation.transpose();
            let rel = sb.rotation * sa.rotation.transpose();
            let err = angle_deg(&(rel * true_rel.transpose()));
            assert!(err < 0.01, "views {a}, {b}: {err}°");
            // The baseline seen from camera a: no choice of world frame changes it.
            let dir = |p: &Se3, q: &Se3| {
                (p.rotation * (q.inverse().translation - p.inverse().translation)).normalize()
            };
            let dir_err = dir(sa, sb).angle(&dir(ta, tb)).to_degrees();
            assert!(dir_err < 0.05, "views {a}, {b}: baseline {dir_err}°");
        }
    }

    /// A camera walking forward: three centres on one line, 1 and then 3 units apart. The
    /// directions alone leave the spacing free; the shared points measure it.
    #[test]
    fn a_walk_forward_keeps_its_spacing() {
        let k = Intrinsics::centered(500.0, 400, 300);
        let truth: Vec<Camera> = [0.0, 1.0, 4.0]
            .iter()
            .map(|&z| {
                let centre = Vector3::new(0.02 * z, 0.0, z);
                Camera::look_at(k, centre, Vector3::new(0.0, 0.0, 100.0), -Vector3::y())
            })
            .collect();
        let mut matches = Vec::new();
        for s in 0..300 {
            let f = s as f64;
            let p = Vector3::new(
                3.0 * (0.37 * f).sin(),
                2.0 * (0.71 * f).cos(),
                10.0 + 10.0 * (1.0 + (0.13 * f).sin()),
            );
            matches.extend(exact_matches_of(&truth, &p));
        }
        let start = relative_start(3, &[k; 3], &matches, 20, 0).unwrap();
        let centre = |p: &Se3| p.inverse().translation;
        let (c0, c1, c2) = (
            centre(&start.poses[0]),
            centre(&start.poses[1]),
            centre(&start.poses[2]),
        );
        let ratio = (c2 - c1).norm() / (c1 - c0).norm();
        assert!((ratio - 3.0).abs() < 0.01, "spacing ratio {ratio}");
        assert!((c2 - c1).dot(&(c1 - c0)) > 0.0, "view 1 between 0 and 2");
    }
}
