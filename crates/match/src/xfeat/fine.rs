//! XFeat*'s fine matcher: an MLP on a concatenated pair of coarse descriptors that predicts,
//! for the first keypoint, a distribution over the 8×8 pixels of its cell; the match moves by
//! the distribution's soft-argmax (`refine_matches`, `subpix_softmax2d`).

use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor, TensorData};

use super::network::batch_norm;
use crate::error::Result;
use crate::weights::StateDict;

/// One `Linear` (weight stored transposed, `[in, out]`), with BatchNorm1d and ReLU after it
/// unless it is the last layer.
struct Layer {
    weight_t: Tensor<2>,
    bias: Tensor<2>,
    norm: Option<(Tensor<2>, Tensor<2>)>,
}

/// The five-layer `fine_matcher` of the reference (128 → 512 → 512 → 512 → 512 → 64).
pub struct FineMatcher {
    layers: Vec<Layer>,
}

impl FineMatcher {
    pub fn new(w: &StateDict, dev: &Device) -> Result<Self> {
        let dims = [128, 512, 512, 512, 512, 64];
        let row = |v: Vec<f32>, n: usize| Tensor::<2>::from_data(TensorData::new(v, [1, n]), dev);
        let mut layers = Vec::new();
        for (i, pair) in dims.windows(2).enumerate() {
            let (cin, cout) = (pair[0], pair[1]);
            let key = 3 * i; // Linear, BatchNorm1d, ReLU per block
            let weight: Tensor<2> =
                w.tensor(&format!("fine_matcher.{key}.weight"), [cout, cin], dev)?;
            let bias = w
                .get(&format!("fine_matcher.{key}.bias"), &[cout])?
                .data
                .clone();
            let norm = if i + 2 < dims.len() {
                let (alpha, beta) = batch_norm(w, &format!("fine_matcher.{}", key + 1), cout)?;
                Some((row(alpha, cout), row(beta, cout)))
            } else {
                None
            };
            layers.push(Layer {
                weight_t: weight.transpose(),
                bias: row(bias, cout),
                norm,
            });
        }
        Ok(Self { layers })
    }

    /// Logits `[N, 64]` of the offsets of `pairs` `[N, 128]`.
    pub fn forward(&self, mut x: Tensor<2>) -> Tensor<2> {
        for layer in &self.layers {
            x = x.matmul(layer.weight_t.clone()) + layer.bias.clone();
            if let Some((alpha, beta)) = &layer.norm {
                x = relu(x * alpha.clone() + beta.clone());
            }
        }
        x
    }
}

/// The confidence (largest probability of `softmax(3·logits)`) and the soft-argmax offset
/// `(x, y)` in pixels from the cell's centre, with the same temperature of 3.
pub fn offset(logits: &[f32]) -> (f32, [f32; 2]) {
    let max = logits.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let e: Vec<f32> = logits.iter().map(|&l| (3.0 * (l - max)).exp()).collect();
    let sum: f32 = e.iter().sum();
    let confidence = e.iter().copied().fold(0.0f32, f32::max) / sum;
    let mut xy = [0.0f32; 2];
    for (k, &p) in e.iter().enumerate() {
        let p = p / sum;
        xy[0] += ((k % 8) as f32 - 4.0) * p;
        xy[1] += ((k / 8) as f32 - 4.0) * p;
    }
    (confidence, xy)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_peaked_distribution_points_at_its_pixel() {
        let mut logits = [0.0f32; 64];
        logits[8 * 6 + 1] = 20.0; // pixel (1, 6): offset (−3, +2) from the centre (4, 4)
        let (confidence, [x, y]) = offset(&logits);
        assert!(confidence > 0.999);
        assert!(
            (x + 3.0).abs() < 1e-3 && (y - 2.0).abs() < 1e-3,
            "({x}, {y})"
        );
        // Uniform: confidence 1/64, mean offset (−½, −½) of the pixels −4..=3.
        let (confidence, [x, y]) = offset(&[0.0; 64]);
        assert!((confidence - 1.0 / 64.0).abs() < 1e-7);
        assert!((x + 0.5).abs() < 1e-6 && (y + 0.5).abs() < 1e-6);
    }
}
