//! Co-pruning of "CoR-GS: Sparse-View 3D Gaussian Splatting via Co-Regularization" (Zhang et
//! al., ECCV 2024), §4.1: two fields trained side by side from the same start disagree where
//! densification placed Gaussians blindly; a Gaussian whose nearest Gaussian in the other field
//! is farther than τ (Eq. 6–7) sits where the views do not pin it down, and is pruned, in both
//! fields alike, every few densification steps.
//!
//! The paper's τ = 5 is in its datasets' own units, where it leaves all but far outliers; here
//! τ is a fraction of the scene's depth scale ([`depth_scale`]: the median distance of the
//! Gaussians to their nearest training camera), so that one value serves scenes of any scale.
//! The cameras' spread (3DGS's extent) would not: a forward-facing capture's cameras lie close
//! together in front of a deep scene.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

use super::densify::DensifyStats;
use super::state::TrainState;

/// Per Gaussian of `from` (centres, `N×3`), whether a centre of `other` lies within `tau`
/// (Eq. 7's `M = 0`). Every Gaussian is non-matching when `other` is empty.
pub fn matching(from: &[f32], other: &[f32], tau: f32) -> Vec<bool> {
    let points =
        |m: &[f32]| -> Vec<[f32; 3]> { m.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect() };
    let (from, other) = (points(from), points(other));
    if other.is_empty() {
        return vec![false; from.len()];
    }
    let tree: ImmutableKdTree<f32, 3> = ImmutableKdTree::new_from_slice(&other).expect("non-empty");
    let one = std::num::NonZero::new(1).expect("1 > 0");
    from.par_iter()
        .map(|p| {
            let nearest = tree
                .query(p)
                .nearest_n::<SquaredEuclidean<f32>>(one)
                .execute();
            nearest.first().is_some_and(|n| n.distance <= tau * tau)
        })
        .collect()
}

/// The median distance of `means`' Gaussians to the nearest of `centres` (camera centres);
/// 1 when there are none.
pub fn depth_scale(means: &[f32], centres: &[[f64; 3]]) -> f32 {
    let mut d: Vec<f64> = means
        .chunks_exact(3)
        .filter_map(|p| {
            centres
                .iter()
                .map(|c| (0..3).map(|a| (p[a] as f64 - c[a]).powi(2)).sum::<f64>())
                .min_by(f64::total_cmp)
        })
        .collect();
    if d.is_empty() {
        return 1.0;
    }
    let mid = d.len() / 2;
    d.select_nth_unstable_by(mid, f64::total_cmp);
    d[mid].sqrt() as f32
}

/// Prunes the non-matching Gaussians of both states (parameters, Adam moments and
/// densification statistics alike) and returns how many each lost.
pub fn co_prune(a: &mut TrainState, b: &mut TrainState, tau: f32) -> (usize, usize) {
    let keep_a = matching(&a.model.means, &b.model.means, tau);
    let keep_b = matching(&b.model.means, &a.model.means, tau);
    (retain(a, &keep_a), retain(b, &keep_b))
}

/// Keeps the Gaussians of `state` that `keep` marks; returns how many went.
fn retain(state: &mut TrainState, keep: &[bool]) -> usize {
    let gone = keep.iter().filter(|k| !**k).count();
    if gone > 0 {
        state.model.retain(keep);
        state.adam.retain(keep);
        retain_stats(&mut state.stats, keep);
    }
    gone
}

fn retain_stats(stats: &mut DensifyStats, keep: &[bool]) {
    for v in [
        &mut stats.grad_accum,
        &mut stats.denom,
        &mut stats.max_radii,
    ] {
        fewview_optim::retain_rows(v, 1, keep);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::GaussianModel;
    use crate::train::AppearanceState;
    use crate::train::densify::ModelAdam;
    use rand::rngs::StdRng;
    use rand::{RngExt, SeedableRng};

    fn state(points: &[[f32; 3]]) -> TrainState {
        let mut model = GaussianModel::new(0);
        for p in points {
            model.push_isotropic(*p, 0.01, [0.5; 3], 0.5);
        }
        TrainState {
            iteration: 0,
            adam: ModelAdam::new(&model),
            stats: DensifyStats::new(model.len()),
            appearance: AppearanceState::default(),
            model,
        }
    }

    /// Two fields sampling one surface with their own jitter, each with outliers planted
    /// farther than τ from the other field: exactly the outliers go, and the rows that stay
    /// keep their statistics.
    #[test]
    fn co_pruning_removes_exactly_the_far_outliers() {
        let mut rng = StdRng::seed_from_u64(5);
        let surface = |rng: &mut StdRng| -> Vec<[f32; 3]> {
            (0..400)
                .map(|_| {
                    [
                        rng.random::<f32>(),
                        rng.random::<f32>(),
                        0.01 * rng.random::<f32>(),
                    ]
                })
                .collect()
        };
        let mut a_points = surface(&mut rng);
        let mut b_points = surface(&mut rng);
        let a_outliers = [[0.5, 0.5, 0.8], [2.0, 0.0, 0.0]];
        let b_outliers = [[0.2, 0.7, -0.6], [0.5, -1.5, 0.3], [3.0, 3.0, 3.0]];
        a_points.splice(100..100, a_outliers);
        b_points.extend(b_outliers);
        let (mut a, mut b) = (state(&a_points), state(&b_points));
        a.stats.denom = (0..a.model.len()).map(|i| i as f32).collect();
        let tau = 0.2;
        assert_eq!(co_prune(&mut a, &mut b, tau), (2, 3));
        assert_eq!(a.model.len(), 400);
        assert_eq!(b.model.len(), 400);
        assert!(a.model.means.chunks(3).all(|p| p[2] < 0.02));
        assert!(b.model.means.chunks(3).all(|p| p[2] < 0.02));
        // Rows 100 and 101 went; the statistics of the rest moved with them.
        assert_eq!(a.stats.denom[99], 99.0);
        assert_eq!(a.stats.denom[100], 102.0);
        assert_eq!(a.adam.means.m.len(), a.model.means.len());
        // Once pruned, the fields match everywhere.
        assert_eq!(co_prune(&mut a, &mut b, tau), (0, 0));
    }

    #[test]
    fn the_depth_scale_is_the_median_distance_to_the_nearest_camera() {
        let means = [0.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0, 7.0, 5.0, 0.0, 0.0];
        let centres = [[0.0, 0.0, 0.0], [5.0, 0.0, 1.0]];
        // Distances 1, 2, 7 to the first centre and 1 to the second: median of 1, 1, 2, 7.
        assert_eq!(depth_scale(&means, &centres), 2.0);
        assert_eq!(depth_scale(&[], &centres), 1.0);
    }

    #[test]
    fn against_an_empty_field_nothing_matches() {
        assert_eq!(matching(&[0.0, 0.0, 0.0], &[], 1.0), vec![false]);
    }
}
