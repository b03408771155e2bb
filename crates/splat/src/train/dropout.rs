//! Opacity dropout of "DropGaussian: Structural Regularization for Sparse-view Gaussian
//! Splatting" (Park, Ryu and Kim, CVPR 2025): each iteration's photometric render leaves out a
//! random share `r` of the Gaussians and multiplies the opacity of the rest by `1 / (1 − r)`, so
//! that the image is unchanged in expectation wherever Gaussians do not overlap. The Gaussians
//! left in see larger gradients and cannot lean on the ones behind them, which is what overfits
//! a few training views. Held-out renders and extra loss terms use every Gaussian.
//!
//! The rate grows linearly over the run, `r_t = γ · t / T` (the paper's progressive schedule,
//! γ = 0.2 there); [`TrainConfig::dropout`](super::TrainConfig::dropout) is γ.
//!
//! The rasterizer takes opacity logits and clamps `α = min(0.99, o·G)`. A compensated opacity
//! `o / (1 − r)` above 1 has no logit, so it is clamped to [`MAX_COMPENSATED_OPACITY`] first:
//! the image differs from the reference code's only where such a Gaussian's `o·G` lies between
//! that and its own clamp, near the rim of an already opaque splat.

use burn::tensor::{Bool, Tensor, TensorData};
use rand::RngExt;
use rand::rngs::StdRng;

use crate::op::GaussianTensors;

/// The largest opacity a compensated Gaussian keeps (its logit is finite in `f32`).
pub const MAX_COMPENSATED_OPACITY: f32 = 1.0 - 1e-6;

/// The logit given to a dropped Gaussian: its opacity, `σ(−30) ≈ 10⁻¹³`, is far below the
/// rasterizer's skip threshold of 1/255, so it reaches no pixel.
const DROPPED_LOGIT: f32 = -30.0;

/// The drop rate at 1-based `iteration` of `iterations` when the largest is `gamma`.
pub fn rate_at(gamma: f32, iteration: usize, iterations: usize) -> f32 {
    gamma * (iteration as f32 / iterations.max(1) as f32).min(1.0)
}

/// Which of `n` Gaussians an iteration keeps at drop rate `rate` (each independently).
pub fn keep_mask(n: usize, rate: f32, rng: &mut StdRng) -> Vec<bool> {
    (0..n).map(|_| rng.random::<f32>() >= rate).collect()
}

/// `gaussians` with the dropped ones made invisible and the kept ones' opacity multiplied by
/// `1 / (1 − rate)` (clamped to [`MAX_COMPENSATED_OPACITY`]). The result is tracked: the kept
/// Gaussians' gradients reach the parameters through the compensation, the dropped ones get
/// none.
pub fn drop_gaussians(gaussians: &GaussianTensors, keep: &[bool], rate: f32) -> GaussianTensors {
    let logits = gaussians.opacity_logits.clone();
    let n = logits.dims()[0];
    assert_eq!(keep.len(), n, "one keep flag per Gaussian");
    assert!(
        (0.0..1.0).contains(&rate),
        "drop rate {rate} outside [0, 1)"
    );
    let device = logits.device();
    let opacity = burn::tensor::activation::sigmoid(logits) / (1.0 - rate);
    let opacity = opacity.clamp_max(MAX_COMPENSATED_OPACITY);
    let compensated = opacity.clone().log() - (opacity.neg() + 1.0).log();
    let dropped: Vec<bool> = keep.iter().map(|k| !k).collect();
    let dropped = Tensor::<1, Bool>::from_data(TensorData::new(dropped, [n]), &device);
    GaussianTensors {
        means: gaussians.means.clone(),
        log_scales: gaussians.log_scales.clone(),
        quats: gaussians.quats.clone(),
        opacity_logits: compensated.mask_fill(dropped, DROPPED_LOGIT),
        sh: gaussians.sh.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::GaussianModel;
    use burn::tensor::Device;
    use rand::SeedableRng;

    /// Three flat splats side by side, apart enough not to overlap, in front of `camera()`.
    fn three_splats(opacities: [f32; 3]) -> GaussianModel {
        let mut m = GaussianModel::new(0);
        for (k, o) in opacities.iter().enumerate() {
            let x = (k as f32 - 1.0) * 0.6;
            m.push_isotropic([x, 0.0, 3.0], 0.08, [0.9, 0.2 + 0.3 * k as f32, 0.1], *o);
        }
        m
    }

    fn image_of(g: &GaussianTensors) -> Vec<f32> {
        let out = crate::raster::tests::render_from_camera(g);
        let [h, w, _] = out.image.dims();
        let rgb = out.image.slice([0..h, 0..w, 0..3]);
        rgb.into_data().try_to_vec::<f32>().unwrap()
    }

    /// The dropped model renders as the model without the dropped Gaussians and with the kept
    /// ones' opacity scaled by hand, and over all eight keep patterns, weighted by their
    /// probability, the image is the undropped one: splats that do not overlap blend linearly in
    /// their opacity, up to the rasterizer skipping `α < 1/255` (a compensated rim pixel may
    /// pass the threshold that its undropped self does not).
    #[test]
    fn compensation_keeps_the_expected_image() {
        let device = Device::flex();
        let base = [0.3f32, 0.5, 0.7];
        let rate = 0.25f32;
        let full = image_of(&three_splats(base).to_tensors(&device, false));
        let mut expected = vec![0.0f64; full.len()];
        for pattern in 0..8u32 {
            let keep: Vec<bool> = (0..3).map(|k| pattern >> k & 1 == 1).collect();
            let g = three_splats(base).to_tensors(&device, false);
            let got = image_of(&drop_gaussians(&g, &keep, rate));
            // The naive reference: dropped splats removed, kept ones at o / (1 − r).
            let kept: Vec<f32> = (0..3)
                .map(|k| {
                    if keep[k] {
                        base[k] / (1.0 - rate)
                    } else {
                        1e-12
                    }
                })
                .collect();
            let by_hand = three_splats([kept[0], kept[1], kept[2]]);
            let reference = image_of(&by_hand.to_tensors(&device, false));
            for (a, b) in got.iter().zip(&reference) {
                assert!((a - b).abs() < 1e-5, "pattern {pattern}: {a} vs {b}");
            }
            let p: f64 = keep
                .iter()
                .map(|k| if *k { 1.0 - rate as f64 } else { rate as f64 })
                .product();
            for (e, v) in expected.iter_mut().zip(&got) {
                *e += p * *v as f64;
            }
        }
        assert!(full.iter().any(|v| *v > 0.05), "the splats are in view");
        let skip = crate::raster::ALPHA_MIN / (1.0 - rate as f64);
        for (e, f) in expected.iter().zip(&full) {
            assert!((e - *f as f64).abs() < skip, "{e} vs {f}");
        }
        let (e, f): (f64, f64) = (expected.iter().sum(), full.iter().map(|v| *v as f64).sum());
        // Without the compensation the expected light would be a quarter (the rate) lower.
        assert!((e - f).abs() < 0.01 * f, "total light {e} vs {f}");
    }

    #[test]
    fn dropped_gaussians_get_no_gradient_and_kept_ones_do() {
        let device = Device::flex().autodiff();
        let g = three_splats([0.3, 0.5, 0.7]).to_tensors(&device, true);
        let dropped = drop_gaussians(&g, &[true, false, true], 0.2);
        let out = crate::raster::tests::render_from_camera(&dropped);
        let grads = out.image.sum().backward();
        let grad = g.opacity_logits.grad(&grads).unwrap();
        let grad = grad.into_data().try_to_vec::<f32>().unwrap();
        assert_eq!(grad[1], 0.0);
        assert!(grad[0] > 0.0 && grad[2] > 0.0, "{grad:?}");
    }

    #[test]
    fn the_rate_grows_to_gamma_and_the_mask_keeps_its_share() {
        assert_eq!(rate_at(0.2, 500, 1000), 0.1);
        assert_eq!(rate_at(0.2, 1000, 1000), 0.2);
        let keep = keep_mask(100_000, 0.2, &mut StdRng::seed_from_u64(7));
        let share = keep.iter().filter(|k| **k).count() as f64 / keep.len() as f64;
        assert!((share - 0.8).abs() < 0.005, "{share}");
        assert_eq!(keep, keep_mask(100_000, 0.2, &mut StdRng::seed_from_u64(7)));
    }
}
