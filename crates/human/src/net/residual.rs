//! The residual unit of PoseGaussian's encoders and decoder ("PoseGaussian: Pose-Driven Novel
//! View Synthesis for Robust 3D Human Reconstruction", appendix), in the four forms of its
//! configuration variants.
//!
//! The paper names the parts (3×3 convolutions, a skip connection, an SE block, batch norm and
//! ReLU in config 3) but not their order. The order here is SE-ResNet's (Hu et al.,
//! "Squeeze-and-Excitation Networks"), on the two-convolution block of the RAFT/GPS-Gaussian
//! encoders the paper builds on:
//!
//! ```text
//! config 1:    y = conv(x)
//! config 2:    y = conv₂(conv₁(x))
//! config 3, 4: y = bn₂(conv₂(relu(bn₁(conv₁(x)))))
//! out = relu(shortcut(x) + se(y))
//! ```
//!
//! The first convolution carries the unit's stride. The shortcut is the identity, or, where the
//! width or the resolution changes, a strided 1×1 convolution (followed by batch norm in
//! configs 3 and 4), as in RAFT's residual block.

use burn::module::Module;
use burn::nn::conv::{Conv2d, Conv2dConfig};
use burn::nn::{BatchNorm, BatchNormConfig, PaddingConfig2d};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor};

use super::config::Variant;
use super::se::SqueezeExcitation;

/// A `kernel`×`kernel` convolution with `kernel / 2` zero padding (so stride 1 keeps the size)
/// and a bias.
pub fn conv(input: usize, output: usize, kernel: usize, stride: usize, device: &Device) -> Conv2d {
    let p = kernel / 2;
    Conv2dConfig::new([input, output], [kernel, kernel])
        .with_stride([stride, stride])
        .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
        .init(device)
}

/// The projection on the skip path when a unit changes width or resolution.
#[derive(Module, Debug)]
pub struct Projection {
    pub(crate) conv: Conv2d,
    pub(crate) norm: Option<BatchNorm>,
}

impl Projection {
    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let y = super::conv::apply(&self.conv, x);
        match &self.norm {
            Some(bn) => bn.forward(y),
            None => y,
        }
    }
}

/// One residual unit with its SE block; see the module documentation for the formula.
#[derive(Module, Debug)]
pub struct ResidualUnit {
    pub(crate) conv1: Conv2d,
    pub(crate) norm1: Option<BatchNorm>,
    pub(crate) conv2: Option<Conv2d>,
    pub(crate) norm2: Option<BatchNorm>,
    pub(crate) shortcut: Option<Projection>,
    pub(crate) se: SqueezeExcitation,
}

impl ResidualUnit {
    /// A unit from `input` to `output` channels whose first convolution has `stride`, in the
    /// form `variant` prescribes.
    pub fn new(
        input: usize,
        output: usize,
        stride: usize,
        variant: Variant,
        device: &Device,
    ) -> Self {
        let bn = |c: usize| {
            variant
                .batch_norm()
                .then(|| BatchNormConfig::new(c).init(device))
        };
        let two = variant.convs_per_unit() == 2;
        let shortcut = (input != output || stride != 1).then(|| Projection {
            conv: conv(input, output, 1, stride, device),
            norm: bn(output),
        });
        Self {
            conv1: conv(input, output, 3, stride, device),
            norm1: bn(output),
            conv2: two.then(|| conv(output, output, 3, 1, device)),
            norm2: if two { bn(output) } else { None },
            shortcut,
            se: SqueezeExcitation::new(output, device),
        }
    }

    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let mut y = super::conv::apply(&self.conv1, x.clone());
        if let Some(bn) = &self.norm1 {
            y = relu(bn.forward(y));
        }
        if let Some(conv2) = &self.conv2 {
            y = super::conv::apply(conv2, y);
        }
        if let Some(bn) = &self.norm2 {
            y = bn.forward(y);
        }
        let skip = match &self.shortcut {
            Some(p) => p.forward(x),
            None => x,
        };
        relu(skip + self.se.forward(y))
    }
}

/// Residual units applied one after the other: one stage of an encoder or the decoder.
#[derive(Module, Debug)]
pub struct Stage {
    pub(crate) units: Vec<ResidualUnit>,
}

impl Stage {
    /// `units` units from `input` to `output` channels; only the first strides and projects.
    pub fn new(
        input: usize,
        output: usize,
        units: usize,
        stride: usize,
        variant: Variant,
        device: &Device,
    ) -> Self {
        let units = (0..units)
            .map(|i| match i {
                0 => ResidualUnit::new(input, output, stride, variant, device),
                _ => ResidualUnit::new(output, output, 1, variant, device),
            })
            .collect();
        Self { units }
    }

    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        self.units.iter().fold(x, |x, u| u.forward(x))
    }
}

#[cfg(test)]
mod tests {
    use burn::module::RunningState;
    use burn::tensor::{Distribution, TensorData};

    use super::*;
    use crate::net::reference::{Host, residual_unit};
    use crate::net::seed::seeded;

    fn random(shape: [usize; 4], device: &Device) -> Tensor<4> {
        Tensor::random(shape, Distribution::Uniform(-1.0, 1.0), device)
    }

    /// Non-trivial batch-norm statistics and affine parameters, so that inference-mode batch
    /// norm is not the identity.
    fn perturb(bn: &mut BatchNorm, device: &Device) {
        let c = bn.gamma.dims()[0];
        let r = |lo, hi| Tensor::<1>::random([c], Distribution::Uniform(lo, hi), device);
        bn.gamma = burn::module::Param::from_tensor(r(0.5, 1.5));
        bn.beta = burn::module::Param::from_tensor(r(-0.5, 0.5));
        bn.running_mean = RunningState::new(r(-0.3, 0.3));
        bn.running_var = RunningState::new(r(0.5, 2.0));
    }

    fn check(variant: Variant, input: usize, output: usize, stride: usize) {
        let _rng = seeded(3);
        let device = Device::flex();
        let mut unit = ResidualUnit::new(input, output, stride, variant, &device);
        for bn in [&mut unit.norm1, &mut unit.norm2].into_iter().flatten() {
            perturb(bn, &device);
        }
        if let Some(bn) = unit.shortcut.as_mut().and_then(|p| p.norm.as_mut()) {
            perturb(bn, &device);
        }
        let x = random([2, input, 5, 6], &device);
        let want = residual_unit(&Host::from_tensor(x.clone()), &unit);
        let got = Host::from_tensor(unit.forward(x));
        assert_eq!(got.shape, want.shape, "{variant:?}");
        for (i, (g, w)) in got.data.iter().zip(&want.data).enumerate() {
            assert!((g - w).abs() < 1e-5, "{variant:?} {i}: {g} vs {w}");
        }
    }

    #[test]
    fn residual_unit_matches_a_loop_reference_in_every_variant() {
        check(Variant::Simplified, 3, 3, 1);
        check(Variant::Simplified, 2, 3, 1);
        check(Variant::DeepResidual, 3, 3, 1);
        check(Variant::DeepResidual, 2, 4, 2);
        check(Variant::Normalized, 3, 3, 1);
        check(Variant::Normalized, 2, 4, 2);
        check(Variant::FullResolution, 2, 3, 1);
    }

    #[test]
    fn strided_unit_halves_odd_sizes_rounding_up() {
        let device = Device::flex();
        let unit = ResidualUnit::new(2, 3, 2, Variant::DeepResidual, &device);
        let x = Tensor::<4>::from_data(TensorData::zeros::<f32, _>([1, 2, 7, 5]), &device);
        assert_eq!(unit.forward(x).dims(), [1, 3, 4, 3]);
    }
}
