//! Squeeze-and-Excitation: each residual unit of PoseGaussian's encoders "includes a
//! Squeeze-and-Excitation (SE) block" that recalibrates its channels ("PoseGaussian: Pose-Driven
//! Novel View Synthesis for Robust 3D Human Reconstruction", appendix). The paper gives no
//! details, so this is the block of Hu et al., "Squeeze-and-Excitation Networks": global average
//! pool → fully connected to `hidden` → ReLU → fully connected back to `C` → sigmoid, and the
//! input's channels multiplied by the result.

use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::activation::{relu, sigmoid};
use burn::tensor::{Device, Tensor};

use super::config::se_hidden;

/// The SE gate on `C` channels (both fully connected layers with a bias, as in Hu et al.).
#[derive(Module, Debug)]
pub struct SqueezeExcitation {
    pub(crate) reduce: Linear,
    pub(crate) expand: Linear,
}

impl SqueezeExcitation {
    /// A block for `channels` channels with [`se_hidden`] hidden units.
    pub fn new(channels: usize, device: &Device) -> Self {
        let hidden = se_hidden(channels);
        Self {
            reduce: LinearConfig::new(channels, hidden).init(device),
            expand: LinearConfig::new(hidden, channels).init(device),
        }
    }

    /// The per-channel gate in `(0, 1)`, `[N, C]`.
    pub fn gate(&self, x: Tensor<4>) -> Tensor<2> {
        let [n, c, _, _] = x.dims();
        let squeezed = x.mean_dim(3).mean_dim(2).reshape([n, c]);
        sigmoid(self.expand.forward(relu(self.reduce.forward(squeezed))))
    }

    /// `x` with each channel scaled by its gate.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let [n, c, _, _] = x.dims();
        let gate = self.gate(x.clone()).reshape([n, c, 1, 1]);
        x * gate
    }
}

#[cfg(test)]
mod tests {
    use burn::module::Param;
    use burn::tensor::TensorData;

    use super::*;

    fn linear(weight: [[f32; 2]; 2], bias: [f32; 2], device: &Device) -> Linear {
        // Burn's Linear stores the weight as `[d_input, d_output]`.
        let w: Vec<f32> = weight.iter().flatten().copied().collect();
        Linear {
            weight: Param::from_tensor(Tensor::from_data(TensorData::new(w, [2, 2]), device)),
            bias: Some(Param::from_tensor(Tensor::from_data(
                TensorData::new(bias.to_vec(), [2]),
                device,
            ))),
        }
    }

    /// Two channels of 2×2 pixels, weights by hand:
    /// means (2.5, -1); hidden = relu((2.5·1 + (-1)·0 + 0.5, 2.5·(-1) + (-1)·2 + 0)) = (3, 0);
    /// logits = (3·0.5 + 0·1 + 0, 3·(-1) + 0·4 + 1) = (1.5, -2);
    /// gates = (σ(1.5), σ(-2)) = (0.8175745, 0.1192029).
    #[test]
    fn se_block_matches_a_hand_computation() {
        let device = Device::flex();
        let se = SqueezeExcitation {
            reduce: linear([[1.0, -1.0], [0.0, 2.0]], [0.5, 0.0], &device),
            expand: linear([[0.5, -1.0], [1.0, 4.0]], [0.0, 1.0], &device),
        };
        let x = [1.0f32, 2.0, 3.0, 4.0, -2.0, 0.0, -1.0, -1.0];
        let input = Tensor::<4>::from_data(TensorData::new(x.to_vec(), [1, 2, 2, 2]), &device);
        let out: Vec<f32> = se.forward(input).into_data().try_to_vec::<f32>().unwrap();
        let gates = [0.817_574_5f32, 0.119_202_92];
        for (i, (&o, &xi)) in out.iter().zip(&x).enumerate() {
            let want = xi * gates[i / 4];
            assert!((o - want).abs() < 1e-6, "{i}: {o} vs {want}");
        }
    }
}
