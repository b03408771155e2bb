//! The adjustment's Levenberg–Marquardt iterations: forward-difference Jacobians of the
//! patches and the cameras, and the Schur-complement system over the cameras.

use fewview_scene::Se3;
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use crate::pose::se3_exp;
use fewview_sfm::schur::{BlockSystem, CameraSystem, LmStep, damped_step, robust_sigma};

use super::options::PatchAdjustmentOptions;
use super::residual::{Patch, PatchState, Views};

/// Forward-difference steps: log depth, normal tilts (radians), camera twists.
pub(super) const DEPTH_STEP: f64 = 1e-6;
pub(super) const TILT_STEP: f64 = 1e-4;
pub(super) const POSE_STEP: f64 = 1e-6;

/// One patch's part of the weighted normal equations, from its residuals `r`, the 3 columns
/// `J_p` of its own unknowns and the columns `J_c` of the camera parameters it depends on (6
/// for each free camera that sees it; a patch in 3 of 24 views touches 18 of 138).
/// A Jacobian column that is zero outside `offset .. offset + values.len()`.
pub(super) struct SparseColumn {
    pub(super) offset: usize,
    pub(super) values: Vec<f64>,
}

impl SparseColumn {
    pub(super) fn end(&self) -> usize {
        self.offset + self.values.len()
    }

    pub(super) fn dot(&self, other: &SparseColumn) -> f64 {
        let (start, end) = (self.offset.max(other.offset), self.end().min(other.end()));
        (start..end)
            .map(|i| self.values[i - self.offset] * other.values[i - other.offset])
            .sum()
    }

    /// The dot product with a dense column.
    pub(super) fn dot_full(&self, full: &[f64]) -> f64 {
        self.values
            .iter()
            .zip(&full[self.offset..self.end()])
            .map(|(a, b)| a * b)
            .sum()
    }
}

/// The forward-difference twist along axis `k` (rotation first).
pub(super) fn unit_twist(k: usize) -> [f64; 6] {
    let mut xi = [0.0; 6];
    xi[k] = POSE_STEP;
    xi
}

/// One iteration: residuals and weights at the current estimate, the patch systems, then
/// damped steps until one lowers the robust cost (raising the damping ten-fold each time it
/// does not) or the damping exceeds 10⁶.
pub(super) fn iterate(
    views: &Views,
    patches: &[Patch],
    states: &[PatchState],
    poses: &[Se3],
    options: &PatchAdjustmentOptions,
    lambda: &mut f64,
) -> LmStep<PatchState> {
    let residuals: Vec<Vec<f64>> = patches
        .par_iter()
        .zip(states)
        .map(|(p, s)| views.residuals(p, s, poses))
        .collect();
    let sigma = robust_sigma(residuals.iter().flatten().copied());
    let scale = (options.cauchy_sigmas * sigma).max(1e-12);
    let weights: Vec<Vec<f64>> = residuals
        .iter()
        .map(|r| {
            r.iter()
                .map(|x| 1.0 / (1.0 + (x / scale).powi(2)))
                .collect()
        })
        .collect();
    let cost_of = |r: &[f64], w: &[f64]| r.iter().zip(w).map(|(r, w)| w * r * r).sum::<f64>();
    let cost_before: f64 = residuals
        .iter()
        .zip(&weights)
        .map(|(r, w)| cost_of(r, w))
        .sum();
    let free = 6 * (poses.len() - 1);
    let systems: Vec<BlockSystem> = patches
        .par_iter()
        .zip(states)
        .zip(residuals.par_iter().zip(&weights))
        .map(|((p, s), (r, w))| patch_system(views, p, s, poses, r, w))
        .collect();
    let cameras = CameraSystem::new(free, &systems);
    damped_step(
        &cameras,
        &systems,
        (poses, states),
        cost_before,
        (lambda, 1e-7),
        |state, step| state.moved(&[step.x, step.y, step.z]),
        |new_poses, new_states, _| {
            // Summed in order after the parallel part, so that a run repeats bit for bit.
            let costs: Vec<f64> = patches
                .par_iter()
                .zip(new_states)
                .zip(&weights)
                .map(|((p, s), w)| cost_of(&views.residuals(p, s, new_poses), w))
                .collect();
            costs.iter().sum()
        },
    )
}

/// The weighted normal equations of one patch (forward differences around `r`).
pub(super) fn patch_system(
    views: &Views,
    patch: &Patch,
    state: &PatchState,
    poses: &[Se3],
    r: &[f64],
    weights: &[f64],
) -> BlockSystem {
    let sw: Vec<f64> = weights.iter().map(|w| w.sqrt()).collect();
    let column = |perturbed: Vec<f64>, step: f64| -> Vec<f64> {
        perturbed
            .iter()
            .zip(r)
            .zip(&sw)
            .map(|((p, r), s)| s * (p - r) / step)
            .collect()
    };
    let patch_columns: Vec<Vec<f64>> = [
        ([DEPTH_STEP, 0.0, 0.0], DEPTH_STEP),
        ([0.0, TILT_STEP, 0.0], TILT_STEP),
        ([0.0, 0.0, TILT_STEP], TILT_STEP),
    ]
    .into_iter()
    .map(|(step, h)| column(views.residuals(patch, &state.moved(&step), poses), h))
    .collect();
    // Camera columns: the reference camera moves every view's window (a full column); any
    // other camera only its own view's block, so its column is that block at its offset.
    let block = views.window.offsets.len();
    let mut camera_columns: Vec<(usize, SparseColumn)> = Vec::new();
    if patch.reference != 0 {
        for k in 0..6 {
            let mut moved = poses.to_vec();
            moved[patch.reference] = se3_exp(&unit_twist(k)).compose(&poses[patch.reference]);
            let values = column(views.residuals(patch, state, &moved), POSE_STEP);
            let index = 6 * (patch.reference - 1) + k;
            camera_columns.push((index, SparseColumn { offset: 0, values }));
        }
    }
    for (position, &c) in patch.views.iter().enumerate() {
        if c == 0 {
            continue;
        }
        let offset = position * block;
        let (r_block, sw_block) = (&r[offset..offset + block], &sw[offset..offset + block]);
        for k in 0..6 {
            let mut moved = poses.to_vec();
            moved[c] = se3_exp(&unit_twist(k)).compose(&poses[c]);
            let mut perturbed = Vec::with_capacity(block);
            views.push_view_residuals(patch, state, &moved, c, &mut perturbed);
            let values = perturbed
                .iter()
                .zip(r_block)
                .zip(sw_block)
                .map(|((p, r), s)| s * (p - r) / POSE_STEP)
                .collect();
            camera_columns.push((6 * (c - 1) + k, SparseColumn { offset, values }));
        }
    }
    let weighted_r: Vec<f64> = r.iter().zip(&sw).map(|(r, s)| r * s).collect();
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let v = Matrix3::from_fn(|i, j| dot(&patch_columns[i], &patch_columns[j]));
    let g = Vector3::from_fn(|i, _| dot(&patch_columns[i], &weighted_r));
    let n = camera_columns.len();
    let mut u = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let value = camera_columns[i].1.dot(&camera_columns[j].1);
            u[i * n + j] = value;
            u[j * n + i] = value;
        }
    }
    BlockSystem {
        v,
        g,
        columns: camera_columns.iter().map(|(c, _)| *c).collect(),
        w: camera_columns
            .iter()
            .map(|(_, c)| Vector3::from_fn(|j, _| c.dot_full(&patch_columns[j])))
            .collect(),
        u,
        gc: camera_columns
            .iter()
            .map(|(_, c)| c.dot_full(&weighted_r))
            .collect(),
    }
}
