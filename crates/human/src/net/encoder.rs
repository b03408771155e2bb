//! One of PoseGaussian's three parallel encoders ("PoseGaussian: Pose-Driven Novel View
//! Synthesis for Robust 3D Human Reconstruction", appendix: "the three parallel encoders share an
//! identical structure: an initial 3×3 convolutional layer with 32 channels, followed by six
//! residual units with progressively increasing channel dimensions").
//!
//! The stem is a convolution (5×5 in config 1) followed by a ReLU, at stride 1, so that the
//! decoder has a full-resolution feature of every modality to skip to before the per-pixel heads
//! (GPS-Gaussian's stem strides by 2 instead, and sees full resolution again only in its output
//! convolution). The stages follow [`NetConfig::stages`].

use burn::module::Module;
use burn::nn::conv::Conv2d;
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor};

use super::config::NetConfig;
use super::residual::{Stage, conv};

/// Stem and stages for one input modality.
#[derive(Module, Debug)]
pub struct Encoder {
    pub(crate) stem: Conv2d,
    pub(crate) stages: Vec<Stage>,
}

impl Encoder {
    /// An encoder of `input` channels shaped by `config`.
    pub fn new(input: usize, config: &NetConfig, device: &Device) -> Self {
        let v = config.variant;
        let mut width = config.widths[0];
        let stem = conv(input, width, v.stem_kernel(), 1, device);
        let stages = config
            .stages()
            .into_iter()
            .map(|s| {
                let stage = Stage::new(width, s.width, s.units, s.stride, v, device);
                width = s.width;
                stage
            })
            .collect();
        Self { stem, stages }
    }

    /// The features the decoder skips to: the stem's, then each stage's (finest first).
    pub fn forward(&self, x: Tensor<4>) -> Vec<Tensor<4>> {
        let mut features = vec![relu(super::conv::apply(&self.stem, x))];
        for stage in &self.stages {
            let last = features.last().expect("the stem's feature").clone();
            features.push(stage.forward(last));
        }
        features
    }
}
