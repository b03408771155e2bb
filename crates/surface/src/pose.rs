//! Camera poses: the BARF/SPARF synthetic perturbation and SPARF's pose parameterisation.
//!
//! **Perturbation** (BARF, SPARF; the surface paper §4.1): `ξ ~ N(0, σ²)` in se(3) (rotation part
//! first), `P_noisy = P_w2c ∘ exp(ξ)` — BARF's `pose.compose([pose_noise, pose])`, i.e. the noise
//! acts in world coordinates before the world-to-camera transform.
//!
//! **Parameterisation** (SPARF `FirstTwoColunmnsPoseParameters`, the surface paper §B.1): each
//! world-to-camera pose is 9 numbers, the translation `t` and the first two *rows* of `R`
//! (Zhou et al.'s 6D representation), mapped back to a rotation by Gram–Schmidt. The parameters
//! start at the initial (noisy) pose and are optimised directly with their own Adam.

use burn::tensor::Tensor;
use fewview_scene::Se3;
use nalgebra::{Matrix3, Rotation3, Vector3};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

pub use fewview_sfm::se3::{into_frame_of, se3_exp};

/// Perturbs world-to-camera poses with se(3) noise `N(0, σ²)` drawn from `seed` (one 6-vector
/// per pose, in order).
pub fn perturb_poses(gt: &[Se3], sigma: f64, seed: u64) -> Vec<Se3> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    gt.iter()
        .map(|p| {
            let xi: [f64; 6] = std::array::from_fn(|_| {
                let z: f64 = StandardNormal.sample(&mut rng);
                z * sigma
            });
            p.compose(&se3_exp(&xi))
        })
        .collect()
}

/// SPARF's 9 numbers of a world-to-camera pose: `t`, then rows 0 and 1 of `R`.
pub fn pose_to_d9(p: &Se3) -> [f64; 9] {
    let r = &p.rotation;
    [
        p.translation.x,
        p.translation.y,
        p.translation.z,
        r[(0, 0)],
        r[(0, 1)],
        r[(0, 2)],
        r[(1, 0)],
        r[(1, 1)],
        r[(1, 2)],
    ]
}

/// The pose of 9 numbers (Gram–Schmidt on the two rows, third row by the cross product).
pub fn d9_to_pose(d: &[f64]) -> Se3 {
    let a1 = Vector3::new(d[3], d[4], d[5]);
    let a2 = Vector3::new(d[6], d[7], d[8]);
    let b1 = a1.normalize();
    let b2 = (a2 - b1 * b1.dot(&a2)).normalize();
    let b3 = b1.cross(&b2);
    let r = Matrix3::from_rows(&[b1.transpose(), b2.transpose(), b3.transpose()]);
    Se3::new(r, Vector3::new(d[0], d[1], d[2]))
}

/// Rotation angle between two rotations, degrees.
pub fn rotation_angle_deg(a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
    Rotation3::from_matrix(&(a * b.transpose()))
        .angle()
        .to_degrees()
}

/// Differentiable world-to-camera matrices from the `[V, 9]` parameters: `[V, 12]` holding the
/// rows `r₀, r₁, r₂` of `R` and `t` (in that order).
pub fn d9_to_rows(d9: Tensor<2>) -> Tensor<2> {
    let [v, _] = d9.dims();
    let t = d9.clone().slice([0..v, 0..3]);
    let a1 = d9.clone().slice([0..v, 3..6]);
    let a2 = d9.slice([0..v, 6..9]);
    let b1 = normalize_rows(a1);
    let proj = (b1.clone() * a2.clone()).sum_dim(1);
    let b2 = normalize_rows(a2 - b1.clone() * proj);
    let b3 = cross_rows(b1.clone(), b2.clone());
    Tensor::cat(vec![b1, b2, b3, t], 1)
}

/// Rows scaled to unit length.
pub fn normalize_rows(x: Tensor<2>) -> Tensor<2> {
    let n = (x.clone() * x.clone()).sum_dim(1).sqrt().clamp_min(1e-12);
    x / n
}

/// Row-wise cross products of two `[N, 3]` tensors.
pub fn cross_rows(a: Tensor<2>, b: Tensor<2>) -> Tensor<2> {
    let [n, _] = a.dims();
    let c = |t: &Tensor<2>, i: usize| t.clone().slice([0..n, i..i + 1]);
    let (a0, a1, a2) = (c(&a, 0), c(&a, 1), c(&a, 2));
    let (b0, b1, b2) = (c(&b, 0), c(&b, 1), c(&b, 2));
    Tensor::cat(
        vec![
            a1.clone() * b2.clone() - a2.clone() * b1.clone(),
            a2 * b0.clone() - a0.clone() * b2,
            a0 * b1 - a1 * b0,
        ],
        1,
    )
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Device, TensorData};

    use super::*;

    #[test]
    fn perturbation_has_the_requested_spread() {
        let gt = vec![Se3::identity(); 4000];
        let noisy = perturb_poses(&gt, 0.15, 7);
        assert_eq!(noisy, perturb_poses(&gt, 0.15, 7));
        // The rotation angle of exp(w) is |w|, |w| ~ 0.15·χ₃: mean 0.15·2√2/√π ≈ 0.2394.
        let mean_angle: f64 = noisy
            .iter()
            .map(|p| Rotation3::from_matrix(&p.rotation).angle())
            .sum::<f64>()
            / gt.len() as f64;
        assert!((mean_angle - 0.2394).abs() < 0.006, "{mean_angle}");
    }

    #[test]
    fn d9_roundtrip_and_tensor_version() {
        let p = se3_exp(&[0.3, -0.2, 0.5, 0.7, 0.1, -0.4]);
        let d = pose_to_d9(&p);
        let q = d9_to_pose(&d);
        assert!((p.to_matrix4() - q.to_matrix4()).norm() < 1e-12);
        // Non-orthonormal rows are orthonormalised the same way in both versions.
        let raw = [0.1, 0.2, 0.3, 1.1, 0.2, -0.1, 0.3, 0.9, 0.2];
        let host = d9_to_pose(&raw);
        let dev = Device::flex();
        let t = Tensor::<2>::from_data(
            TensorData::new(raw.iter().map(|v| *v as f32).collect::<Vec<_>>(), [1, 9]),
            &dev,
        );
        let rows = d9_to_rows(t).into_data().try_to_vec::<f32>().unwrap();
        for r in 0..3 {
            for c in 0..3 {
                assert!((rows[r * 3 + c] as f64 - host.rotation[(r, c)]).abs() < 1e-6);
            }
        }
        assert!((rows[9] - 0.1).abs() < 1e-7 && (rows[11] - 0.3).abs() < 1e-7);
    }
}
