//! The damped normal equations of a bundle adjustment whose unknowns are the poses of the
//! cameras (6 each, camera 0 held) and many small blocks of 3 (a 3D point, or a patch's depth
//! and tilts), each block seen by a few cameras: the Schur complement eliminates the blocks, so
//! a Levenberg–Marquardt step solves only the `6(n − 1)` camera system, then back-substitutes
//! every block. Shared by [`crate::bundle`] and the surface method's patch adjustment.

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

use fewview_scene::Se3;

use crate::se3::se3_exp;

/// One block's share of the weighted normal equations `Jᵀ J δ = −Jᵀ r`.
pub struct BlockSystem {
    /// `J_bᵀ J_b` and `J_bᵀ r` of the block's own 3 unknowns.
    pub v: Matrix3<f64>,
    pub g: Vector3<f64>,
    /// Indices of the camera parameters this block's residuals depend on.
    pub columns: Vec<usize>,
    /// `J_cᵀ J_b`, one row per entry of `columns`.
    pub w: Vec<Vector3<f64>>,
    /// `J_cᵀ J_c` (row-major, `columns.len()` square) and `J_cᵀ r`.
    pub u: Vec<f64>,
    pub gc: Vec<f64>,
}

/// A damped Gauss–Newton step: the free cameras' twists (6 each) and each block's step
/// (`None` for a block whose damped 3 × 3 system is singular; it stays where it is).
pub struct SchurStep {
    pub cameras: DVector<f64>,
    pub blocks: Vec<Option<Vector3<f64>>>,
}

/// The camera part `U`, `g_c` of the normal equations, summed over the blocks.
pub struct CameraSystem {
    u: DMatrix<f64>,
    gc: DVector<f64>,
}

impl CameraSystem {
    /// Sums the blocks' camera terms for `free` camera parameters.
    pub fn new(free: usize, systems: &[BlockSystem]) -> Self {
        let mut u = DMatrix::<f64>::zeros(free, free);
        let mut gc = DVector::<f64>::zeros(free);
        for s in systems {
            let n = s.columns.len();
            for (i, &ci) in s.columns.iter().enumerate() {
                gc[ci] += s.gc[i];
                for (j, &cj) in s.columns.iter().enumerate() {
                    u[(ci, cj)] += s.u[i * n + j];
                }
            }
        }
        Self { u, gc }
    }

    /// Adds a residual `r` on camera parameter `column` alone, with derivative `jacobian` (a
    /// prior on a shared parameter).
    pub fn add_prior(&mut self, column: usize, jacobian: f64, r: f64) {
        self.u[(column, column)] += jacobian * jacobian;
        self.gc[column] += jacobian * r;
    }

    /// The step at Marquardt damping `lambda` (each diagonal entry raised by `lambda` times
    /// itself); `None` when the reduced camera system is not positive definite.
    pub fn step(&self, systems: &[BlockSystem], lambda: f64) -> Option<SchurStep> {
        let damp3 = |v: &Matrix3<f64>| {
            let mut d = *v;
            for i in 0..3 {
                d[(i, i)] += lambda * v[(i, i)] + 1e-12;
            }
            d
        };
        let inverses: Vec<Option<Matrix3<f64>>> =
            systems.iter().map(|s| damp3(&s.v).try_inverse()).collect();
        let free = self.gc.len();
        let mut schur = self.u.clone();
        for i in 0..free {
            schur[(i, i)] += lambda * self.u[(i, i)] + 1e-12;
        }
        let mut rhs = -self.gc.clone();
        for (s, inv) in systems.iter().zip(&inverses) {
            let Some(inv) = inv else { continue };
            // Rows of W V⁻¹ for this block's columns.
            let w_inv: Vec<Vector3<f64>> = s.w.iter().map(|w| inv.transpose() * w).collect();
            for (i, &ci) in s.columns.iter().enumerate() {
                rhs[ci] += w_inv[i].dot(&s.g);
                for (j, &cj) in s.columns.iter().enumerate() {
                    schur[(ci, cj)] -= w_inv[i].dot(&s.w[j]);
                }
            }
        }
        let camera_step = schur.cholesky()?.solve(&rhs);
        let blocks = systems
            .iter()
            .zip(&inverses)
            .map(|(s, inv)| {
                let inv = inv.as_ref()?;
                let coupled: Vector3<f64> = s
                    .columns
                    .iter()
                    .zip(&s.w)
                    .map(|(&c, w)| w * camera_step[c])
                    .sum();
                Some(inv * (-s.g - coupled))
            })
            .collect();
        Some(SchurStep {
            cameras: camera_step,
            blocks,
        })
    }
}

/// What one Levenberg–Marquardt iteration did: the weighted cost before and after (under the
/// iteration's weights) and, when a step lowered it, the new poses and block states, and the
/// whole camera step (its entries past the poses' are the caller's shared parameters).
pub struct LmStep<T> {
    pub cost_before: f64,
    pub cost_after: f64,
    pub accepted: Option<(Vec<Se3>, Vec<T>)>,
    pub camera_step: Option<DVector<f64>>,
}

/// Damped steps from `poses` and the blocks' `states` until one lowers `cost_before` (the
/// damping then falls three-fold, to `min_lambda` at the least) or the damping exceeds 10⁶ (it
/// rises ten-fold after each failed step). `moved` applies a block's step to its state; `cost`
/// is the weighted cost of new poses and states, given the whole camera step too (for
/// parameters beyond the poses' `6(n − 1)`).
pub fn damped_step<T: Copy>(
    cameras: &CameraSystem,
    systems: &[BlockSystem],
    (poses, states): (&[Se3], &[T]),
    cost_before: f64,
    (lambda, min_lambda): (&mut f64, f64),
    moved: impl Fn(&T, &Vector3<f64>) -> T,
    cost: impl Fn(&[Se3], &[T], &DVector<f64>) -> f64,
) -> LmStep<T> {
    while *lambda <= 1e6 {
        let Some(step) = cameras.step(systems, *lambda) else {
            *lambda *= 10.0;
            continue;
        };
        let new_states: Vec<T> = states
            .iter()
            .zip(&step.blocks)
            .map(|(state, block)| block.as_ref().map_or(*state, |b| moved(state, b)))
            .collect();
        let new_poses = updated(poses, &step.cameras);
        let cost_after = cost(&new_poses, &new_states, &step.cameras);
        if cost_after.is_finite() && cost_after < cost_before {
            *lambda = (*lambda / 3.0).max(min_lambda);
            return LmStep {
                cost_before,
                cost_after,
                accepted: Some((new_poses, new_states)),
                camera_step: Some(step.cameras),
            };
        }
        *lambda *= 10.0;
    }
    LmStep {
        cost_before,
        cost_after: cost_before,
        accepted: None,
        camera_step: None,
    }
}

/// Poses after the left update by `xi` (6 per free camera, rotation first; camera 0 held).
pub fn updated(poses: &[Se3], xi: &DVector<f64>) -> Vec<Se3> {
    poses
        .iter()
        .enumerate()
        .map(|(c, p)| {
            if c == 0 {
                return *p;
            }
            let d: [f64; 6] = std::array::from_fn(|k| xi[6 * (c - 1) + k]);
            se3_exp(&d).compose(p)
        })
        .collect()
}

/// `adjusted` with the camera centres scaled about view 0's so that their summed distance from
/// it is that of `start`: images cannot see a common scale, and the step along it is undone.
pub fn keep_scale(start: &[Se3], adjusted: &[Se3]) -> Vec<Se3> {
    let spread = |poses: &[Se3]| {
        let origin = poses[0].inverse().translation;
        poses[1..]
            .iter()
            .map(|p| (p.inverse().translation - origin).norm())
            .sum::<f64>()
    };
    let (before, after) = (spread(start), spread(adjusted));
    if !(before > 0.0 && after > 0.0) {
        return adjusted.to_vec();
    }
    let s = before / after;
    let origin = adjusted[0].inverse().translation;
    adjusted
        .iter()
        .map(|p| {
            let centre = origin + s * (p.inverse().translation - origin);
            Se3::new(p.rotation, -(p.rotation * centre))
        })
        .collect()
}

/// The robust scale of residuals: 1.4826 × their median magnitude (the standard deviation of
/// a normal distribution with that median absolute value).
pub fn robust_sigma(residuals: impl Iterator<Item = f64>) -> f64 {
    let mut magnitudes: Vec<f64> = residuals.map(f64::abs).collect();
    if magnitudes.is_empty() {
        return 0.0;
    }
    let middle = magnitudes.len() / 2;
    1.4826 * *magnitudes.select_nth_unstable_by(middle, f64::total_cmp).1
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A linear least-squares problem with one camera parameter block and two 3-blocks: the
    /// Schur step at zero damping is the dense normal-equations solution.
    #[test]
    fn the_undamped_schur_step_solves_the_full_normal_equations() {
        // Unknowns: 6 camera parameters, then two blocks of 3 (12 in all).
        let rows = 20;
        let j = DMatrix::<f64>::from_fn(rows, 12, |r, c| {
            let block_of_row = r % 2; // even rows see block 0, odd rows block 1
            let in_block = c >= 6 && (c - 6) / 3 == block_of_row;
            if c < 6 || in_block {
                ((r * 31 + c * 17) % 13) as f64 / 7.0 - 0.8
            } else {
                0.0
            }
        });
        let r = DVector::<f64>::from_fn(rows, |i, _| ((i * 7) % 5) as f64 - 2.0);
        let full = (j.transpose() * &j)
            .cholesky()
            .unwrap()
            .solve(&(-(j.transpose() * &r)));
        let systems: Vec<BlockSystem> = (0..2)
            .map(|b| {
                let jb = j.columns(6 + 3 * b, 3);
                let jc = j.columns(0, 6);
                let v = Matrix3::from_fn(|x, y| jb.column(x).dot(&jb.column(y)));
                let g = Vector3::from_fn(|x, _| jb.column(x).dot(&r));
                BlockSystem {
                    v,
                    g,
                    columns: (0..6).collect(),
                    w: (0..6)
                        .map(|c| Vector3::from_fn(|x, _| jc.column(c).dot(&jb.column(x))))
                        .collect(),
                    // Block 0 carries the whole camera system; block 1 adds nothing to it.
                    u: (0..36)
                        .map(|k| {
                            if b == 0 {
                                jc.column(k / 6).dot(&jc.column(k % 6))
                            } else {
                                0.0
                            }
                        })
                        .collect(),
                    gc: (0..6)
                        .map(|c| if b == 0 { jc.column(c).dot(&r) } else { 0.0 })
                        .collect(),
                }
            })
            .collect();
        let SchurStep {
            cameras: camera,
            blocks,
        } = CameraSystem::new(6, &systems).step(&systems, 0.0).unwrap();
        for i in 0..6 {
            assert!(
                (camera[i] - full[i]).abs() < 1e-8,
                "{} vs {}",
                camera[i],
                full[i]
            );
        }
        for (b, step) in blocks.iter().enumerate() {
            let step = step.unwrap();
            for x in 0..3 {
                assert!((step[x] - full[6 + 3 * b + x]).abs() < 1e-8);
            }
        }
    }
}
