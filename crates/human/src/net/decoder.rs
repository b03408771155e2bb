//! The decoder that "mirrors the encoder structure to complete the U-Net architecture,
//! progressively upsampling and refining the feature maps", with skip connections "formed by
//! concatenating intermediate encoder features at corresponding layer indices" ("PoseGaussian:
//! Pose-Driven Novel View Synthesis for Robust 3D Human Reconstruction", appendix).
//!
//! Where the paper is silent, as GPS-Gaussian's decoder does it: from the coarsest level up, each
//! decoder stage takes the previous stage's output, upsampled bilinearly (half-pixel centres) to
//! the skip's size, concatenated with the three encoders' features of its level, and has as many
//! residual units as the encoder stage it mirrors. The stem is mirrored by a 3×3 convolution and
//! a ReLU at full resolution over the upsampled features and the three stems' features.

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor};

use super::config::NetConfig;
use super::residual::{Stage, conv};
use super::resize::resize;

/// Decoder stages, finest level first, and the full-resolution fusion convolution.
#[derive(Module, Debug)]
pub struct Decoder {
    pub(crate) stages: Vec<Stage>,
    pub(crate) fuse: Conv2d,
}

/// Input channels of decoder stage `i` (0-based, finest first): three encoders' features plus,
/// below the coarsest, the coarser decoder stage's output.
pub fn stage_input(config: &NetConfig, i: usize) -> usize {
    let plan = config.stages();
    let coarser = plan.get(i + 1).map_or(0, |s| s.width);
    3 * plan[i].width + coarser
}

/// Input channels of the fusion convolution.
pub fn fuse_input(config: &NetConfig) -> usize {
    3 * config.widths[0] + config.stages()[0].width
}

impl Decoder {
    pub fn new(config: &NetConfig, device: &Device) -> Self {
        let v = config.variant;
        let stages = config
            .stages()
            .iter()
            .enumerate()
            .map(|(i, s)| Stage::new(stage_input(config, i), s.width, s.units, 1, v, device))
            .collect();
        let fuse = conv(fuse_input(config), config.widths[0], 3, 1, device);
        Self { stages, fuse }
    }

    /// Full-resolution features, `widths[0]` channels, from the three encoders' outputs
    /// (image, pose, depth; each finest first as [`super::encoder::Encoder::forward`] gives).
    pub fn forward(&self, features: [Vec<Tensor<4>>; 3]) -> Tensor<4> {
        let level = |l: usize| features.iter().map(move |f| f[l].clone());
        let mut up: Option<Tensor<4>> = None;
        for (i, stage) in self.stages.iter().enumerate().rev() {
            let parts = join(up.take(), level(i + 1));
            up = Some(stage.forward(Tensor::cat(parts, 1)));
        }
        relu(super::conv::apply(
            &self.fuse,
            Tensor::cat(join(up, level(0)), 1),
        ))
    }
}

/// `coarse` upsampled to the size of the skips, then the skips.
fn join(coarse: Option<Tensor<4>>, skips: impl Iterator<Item = Tensor<4>>) -> Vec<Tensor<4>> {
    let skips: Vec<Tensor<4>> = skips.collect();
    let [_, _, h, w] = skips[0].dims();
    let mut parts: Vec<Tensor<4>> = coarse.map(|c| resize(c, [h, w])).into_iter().collect();
    parts.extend(skips);
    parts
}
