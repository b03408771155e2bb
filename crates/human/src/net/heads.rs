//! The three output heads "attached at the final decoder stage" ("PoseGaussian: Pose-Driven
//! Novel View Synthesis for Robust 3D Human Reconstruction", appendix):
//!
//! - SR-Opacity, Conv3×3(8): 3 channels of scale (Softplus), 3 of rotation ("normalization"),
//!   2 of opacity (Sigmoid);
//! - depth, Conv3×3(1) + Tanh: depth normalised to `[-1, 1]` over the scene's near/far range;
//! - uncertainty, Conv3×3(2) + Sigmoid: depth confidence, then SR-Opacity confidence.
//!
//! Two choices the paper leaves open:
//!
//! - **Rotation from three numbers.** They are read as a Gibbs (Rodrigues) vector
//!   `g = tan(θ/2)·axis`, and the rotation is the unit quaternion `(1, g) / √(1 + |g|²)`
//!   (w first, the layout of the Inria 3DGS files). This is the "normalization": every `g` gives
//!   a valid rotation, `g = 0` is the identity, and unlike axis-angle it is smooth everywhere
//!   (no `|g|` with an undefined gradient at zero); only the half-turns lie at infinity.
//! - **Two opacity channels.** Channel 0 is the Gaussian's opacity α, channel 1 the probability
//!   that the pixel belongs to the person (its silhouette, which the dataset's masks supervise).
//!   The opacity a Gaussian is rendered with is their product ([`HeadOutputs::render_opacity`]),
//!   so that background pixels spawn no visible Gaussians.

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::tensor::activation::{sigmoid, softplus, tanh};
use burn::tensor::{Device, Tensor};

use super::residual::conv;

/// The heads' convolutions.
#[derive(Module, Debug)]
pub struct Heads {
    pub(crate) sr_opacity: Conv2d,
    pub(crate) depth: Conv2d,
    pub(crate) uncertainty: Conv2d,
    pub(crate) scale_beta: f64,
}

/// Per-pixel outputs, each `[N, C, H, W]` at the input's resolution.
#[derive(Clone, Debug)]
pub struct HeadOutputs {
    /// Per-axis scale, positive, 3 channels.
    pub scale: Tensor<4>,
    /// Unit quaternion, w first, 4 channels.
    pub rotation: Tensor<4>,
    /// α and foreground probability in `(0, 1)`, 2 channels.
    pub opacity: Tensor<4>,
    /// Depth normalised to `(-1, 1)` ([`HeadOutputs::metric_depth`]), 1 channel.
    pub depth: Tensor<4>,
    /// Depth confidence and SR-Opacity confidence in `(0, 1)`, 2 channels.
    pub uncertainty: Tensor<4>,
}

impl Heads {
    /// Heads on `features` channels; `scale_beta` is the scale Softplus's β.
    pub fn new(features: usize, scale_beta: f64, device: &Device) -> Self {
        Self {
            sr_opacity: conv(features, 8, 3, 1, device),
            depth: conv(features, 1, 3, 1, device),
            uncertainty: conv(features, 2, 3, 1, device),
            scale_beta,
        }
    }

    pub fn forward(&self, features: Tensor<4>) -> HeadOutputs {
        let sr = super::conv::apply(&self.sr_opacity, features.clone());
        HeadOutputs {
            scale: softplus(sr.clone().narrow(1, 0, 3), self.scale_beta),
            rotation: quaternion_from_gibbs(sr.clone().narrow(1, 3, 3)),
            opacity: sigmoid(sr.narrow(1, 6, 2)),
            depth: tanh(super::conv::apply(&self.depth, features.clone())),
            uncertainty: sigmoid(super::conv::apply(&self.uncertainty, features)),
        }
    }
}

/// `(1, g) / √(1 + |g|²)` per pixel: `[N, 3, H, W]` Gibbs vectors to `[N, 4, H, W]` unit
/// quaternions, w first.
pub fn quaternion_from_gibbs(g: Tensor<4>) -> Tensor<4> {
    let [n, _, h, w] = g.dims();
    let one = Tensor::<4>::ones([n, 1, h, w], &g.device());
    let norm = g.clone().square().sum_dim(1).add_scalar(1.0).sqrt();
    Tensor::cat(vec![one, g], 1) / norm
}

impl HeadOutputs {
    /// The opacity a Gaussian is rendered with: α times the foreground probability.
    pub fn render_opacity(&self) -> Tensor<4> {
        self.opacity.clone().narrow(1, 0, 1) * self.opacity.clone().narrow(1, 1, 1)
    }

    /// Depth in the scene's units: `near + (d + 1) / 2 · (far − near)`, inside `(near, far)`.
    pub fn metric_depth(&self, near: f32, far: f32) -> Tensor<4> {
        self.depth
            .clone()
            .add_scalar(1.0)
            .mul_scalar(0.5 * (far - near))
            .add_scalar(near)
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::TensorData;

    use super::*;

    /// A rotation of θ about the unit axis a has Gibbs vector tan(θ/2)·a and quaternion
    /// (cos θ/2, sin θ/2 · a).
    #[test]
    fn gibbs_vector_gives_the_quaternion_of_its_rotation() {
        let device = Device::flex();
        let (theta, axis) = (2.0f32, [0.6f32, 0.0, 0.8]);
        let t = (theta / 2.0).tan();
        let g: Vec<f32> = axis.iter().map(|a| a * t).collect();
        let q = quaternion_from_gibbs(Tensor::from_data(TensorData::new(g, [1, 3, 1, 1]), &device));
        let q: Vec<f32> = q.into_data().try_to_vec::<f32>().unwrap();
        let (c, s) = ((theta / 2.0).cos(), (theta / 2.0).sin());
        let want = [c, s * axis[0], s * axis[1], s * axis[2]];
        for (a, b) in q.iter().zip(want) {
            assert!((a - b).abs() < 1e-6, "{q:?} vs {want:?}");
        }
    }
}
