//! Global registration by RANSAC over FPFH feature matches, with Open3D's semantics
//! (`registration_ransac_based_on_feature_matching`): each source point is matched to its
//! nearest target point in feature space (optionally only mutual nearest neighbours); each
//! iteration draws `ransac_n` matches, rejects them unless every pair of edges agrees in length
//! to `edge_length_ratio` (the edge-length checker), fits a rigid transform, rejects it unless
//! every drawn match lands within `distance_threshold` (the distance checker), and scores it by
//! fitness and inlier RMSE at `max_correspondence_distance`. The best result (higher fitness,
//! then lower RMSE) wins; the loop ends after `max_iteration` draws or once
//! `log(1 − confidence) / log(1 − fitnessⁿ)` draws have been made (`RANSACConvergenceCriteria`).

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::Vector3;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use serde::Serialize;

use super::features::FPFH_BINS;
use super::icp::{Evaluation, evaluate_with_tree};
use crate::error::{GeomError, Result};
use crate::knn::PointTree;
use crate::mesh::v3;
use crate::similarity::{Similarity, umeyama};

/// RANSAC parameters (Open3D's tutorial values by default, with `distance_threshold` and
/// `max_correspondence_distance` to be set from the voxel size).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RansacOptions {
    pub max_correspondence_distance: f64,
    pub distance_threshold: f64,
    pub edge_length_ratio: f64,
    pub ransac_n: usize,
    pub mutual_filter: bool,
    pub max_iteration: usize,
    pub confidence: f64,
    pub seed: u64,
}

impl Default for RansacOptions {
    fn default() -> Self {
        Self {
            max_correspondence_distance: 0.015,
            distance_threshold: 0.015,
            edge_length_ratio: 0.9,
            ransac_n: 3,
            mutual_filter: false,
            max_iteration: 100_000,
            confidence: 0.999,
            seed: 0,
        }
    }
}

/// Result of the global registration.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RansacResult {
    pub transformation: Similarity,
    pub evaluation: Evaluation,
    pub iterations: usize,
    pub matches: usize,
}

fn feature_matches(
    src: &[[f32; FPFH_BINS]],
    tgt: &[[f32; FPFH_BINS]],
    mutual: bool,
) -> Result<Vec<(usize, usize)>> {
    let build = |f: &[[f32; FPFH_BINS]]| {
        ImmutableKdTree::<f32, FPFH_BINS>::new_from_slice(f)
            .map_err(|e| GeomError::numerical(format!("feature tree: {e:?}")))
    };
    let t_tree = build(tgt)?;
    let nn = |tree: &ImmutableKdTree<f32, FPFH_BINS>, f: &[[f32; FPFH_BINS]]| -> Vec<usize> {
        f.par_iter()
            .map(|q| {
                tree.query(q)
                    .nearest_one::<SquaredEuclidean<f32>>()
                    .execute()
                    .item as usize
            })
            .collect()
    };
    let s2t = nn(&t_tree, src);
    if !mutual {
        return Ok(s2t.into_iter().enumerate().collect());
    }
    let s_tree = build(src)?;
    let t2s = nn(&s_tree, tgt);
    Ok(s2t
        .into_iter()
        .enumerate()
        .filter(|&(i, j)| t2s[j] == i)
        .collect())
}

/// RANSAC over feature matches from `source` to `target` (points and their FPFH features).
pub fn ransac_feature_matching(
    source: &[[f32; 3]],
    target: &[[f32; 3]],
    source_features: &[[f32; FPFH_BINS]],
    target_features: &[[f32; FPFH_BINS]],
    options: &RansacOptions,
) -> Result<RansacResult> {
    if source.len() != source_features.len() || target.len() != target_features.len() {
        return Err(GeomError::invalid(
            "RANSAC",
            "one feature per point is needed",
        ));
    }
    if source.len() < options.ransac_n || target.len() < options.ransac_n || options.ransac_n < 3 {
        return Err(GeomError::invalid(
            "RANSAC",
            format!(
                "too few points (source {}, target {}) for ransac_n = {}",
                source.len(),
                target.len(),
                options.ransac_n
            ),
        ));
    }
    let matches = feature_matches(source_features, target_features, options.mutual_filter)?;
    if matches.len() < options.ransac_n {
        return Err(GeomError::numerical("too few feature matches for RANSAC"));
    }
    let src: Vec<Vector3<f64>> = source.iter().map(v3).collect();
    let tgt: Vec<Vector3<f64>> = target.iter().map(v3).collect();
    let tree = PointTree::new(target);
    let mut rng = StdRng::seed_from_u64(options.seed);
    let mut best: Option<(Similarity, Evaluation)> = None;
    let mut est_k = options.max_iteration as f64;
    let mut it = 0;
    while it < options.max_iteration && (it as f64) < est_k {
        it += 1;
        let mut pick: Vec<usize> = Vec::with_capacity(options.ransac_n);
        while pick.len() < options.ransac_n {
            let k = rng.random_range(0..matches.len());
            if !pick.contains(&k) {
                pick.push(k);
            }
        }
        let a: Vec<Vector3<f64>> = pick.iter().map(|&k| src[matches[k].0]).collect();
        let b: Vec<Vector3<f64>> = pick.iter().map(|&k| tgt[matches[k].1]).collect();
        let mut edges_ok = true;
        'outer: for i in 0..a.len() {
            for j in i + 1..a.len() {
                let (ls, lt) = ((a[i] - a[j]).norm(), (b[i] - b[j]).norm());
                if ls < options.edge_length_ratio * lt || lt < options.edge_length_ratio * ls {
                    edges_ok = false;
                    break 'outer;
                }
            }
        }
        if !edges_ok {
            continue;
        }
        let Ok(t) = umeyama(&a, &b, false) else {
            continue;
        };
        if a.iter()
            .zip(&b)
            .any(|(p, q)| (t.apply(p) - q).norm() > options.distance_threshold)
        {
            continue;
        }
        let e = evaluate_with_tree(&src, &tree, options.max_correspondence_distance, &t);
        let better = match &best {
            None => true,
            Some((_, b)) => {
                e.fitness > b.fitness || (e.fitness == b.fitness && e.inlier_rmse < b.inlier_rmse)
            }
        };
        if better {
            if e.fitness > 0.0 {
                let p = e.fitness.powi(options.ransac_n as i32);
                est_k = if p >= 1.0 {
                    0.0
                } else {
                    (1.0 - options.confidence).ln() / (1.0 - p).ln()
                };
            }
            best = Some((t, e));
        }
    }
    let (transformation, evaluation) = best.ok_or_else(|| {
        GeomError::numerical("RANSAC found no transform that passes the checkers")
    })?;
    Ok(RansacResult {
        transformation,
        evaluation,
        iterations: it,
        matches: matches.len(),
    })
}
