//! The XFeat network ("XFeat: Accelerated Features for Lightweight Image Matching", CVPR 2024,
//! Fig. 3) in Burn, for inference, with the layer names of the reference's `XFeatModel` so that
//! its state dict loads as is.
//!
//! Backbone: six blocks of 3×3 convolutions (`BasicLayer`: convolution without bias, BatchNorm
//! without affine parameters, ReLU) down to 1/32 of the image, plus a 4×4 average-pool skip of
//! the input into the second block; the 1/8, 1/16 and 1/32 maps are upsampled bilinearly to 1/8,
//! summed and fused into 64-channel dense descriptors. Heads: a reliability map (sigmoid) from
//! the descriptors, and 65 keypoint logits per 8×8 cell (64 positions and a "no keypoint" bin)
//! from the normalised input unfolded into 8×8 cells. The fine matcher of XFeat* is a five-layer
//! MLP on a pair of descriptors that predicts an 8×8 offset distribution.

use burn::tensor::activation::{relu, sigmoid};
use burn::tensor::module::{avg_pool2d, conv2d, interpolate};
use burn::tensor::ops::{AvgPoolOptions, ConvOptions, InterpolateMode, InterpolateOptions};
use burn::tensor::{Device, Tensor, TensorData};

use crate::error::Result;
use crate::weights::StateDict;

/// BatchNorm's ε (PyTorch's default, which XFeat keeps).
const BN_EPS: f64 = 1e-5;

/// One `BasicLayer` (or a plain convolution with bias when `norm` is `None`).
struct Conv {
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    /// BatchNorm in inference form, `x · α + β` per channel (α = 1/√(var + ε), β = −mean · α).
    norm: Option<(Tensor<4>, Tensor<4>)>,
    stride: usize,
    pad: usize,
}

impl Conv {
    /// `BasicLayer(cin, cout, k, stride)` at `{prefix}.layer.{0,1}`; padding k/2 as the reference.
    fn basic(
        w: &StateDict,
        prefix: &str,
        shape: [usize; 4],
        stride: usize,
        dev: &Device,
    ) -> Result<Self> {
        let weight = w.tensor(&format!("{prefix}.layer.0.weight"), shape, dev)?;
        let norm = batch_norm(w, &format!("{prefix}.layer.1"), shape[0])?;
        let norm = Some((
            Tensor::<1>::from_data(TensorData::new(norm.0, [shape[0]]), dev)
                .reshape([1, shape[0], 1, 1]),
            Tensor::<1>::from_data(TensorData::new(norm.1, [shape[0]]), dev)
                .reshape([1, shape[0], 1, 1]),
        ));
        Ok(Self {
            weight,
            bias: None,
            norm,
            stride,
            pad: shape[3] / 2,
        })
    }

    /// A 1×1 `nn.Conv2d` with bias at `prefix`.
    fn pointwise(
        w: &StateDict,
        prefix: &str,
        cin: usize,
        cout: usize,
        dev: &Device,
    ) -> Result<Self> {
        Ok(Self {
            weight: w.tensor(&format!("{prefix}.weight"), [cout, cin, 1, 1], dev)?,
            bias: Some(w.tensor(&format!("{prefix}.bias"), [cout], dev)?),
            norm: None,
            stride: 1,
            pad: 0,
        })
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let options = ConvOptions::new([self.stride; 2], [self.pad; 2], [1, 1], 1);
        let y = conv2d(x, self.weight.clone(), self.bias.clone(), options);
        match &self.norm {
            Some((alpha, beta)) => relu(y * alpha.clone() + beta.clone()),
            None => y,
        }
    }
}

/// BatchNorm (no affine parameters) at `prefix` as per-channel `(α, β)`.
pub(super) fn batch_norm(
    w: &StateDict,
    prefix: &str,
    channels: usize,
) -> Result<(Vec<f32>, Vec<f32>)> {
    let mean = &w.get(&format!("{prefix}.running_mean"), &[channels])?.data;
    let var = &w.get(&format!("{prefix}.running_var"), &[channels])?.data;
    let alpha: Vec<f32> = var
        .iter()
        .map(|&v| (1.0 / (v as f64 + BN_EPS).sqrt()) as f32)
        .collect();
    let beta = mean.iter().zip(&alpha).map(|(&m, &a)| -m * a).collect();
    Ok((alpha, beta))
}

/// A `Sequential` of layers.
struct Block(Vec<Conv>);

impl Block {
    /// `BasicLayer`s `prefix.0 ..` given as `(cin, cout, kernel, stride)`.
    fn basic(
        w: &StateDict,
        prefix: &str,
        layers: &[(usize, usize, usize, usize)],
        dev: &Device,
    ) -> Result<Self> {
        let convs = layers
            .iter()
            .enumerate()
            .map(|(i, &(cin, cout, k, stride))| {
                Conv::basic(w, &format!("{prefix}.{i}"), [cout, cin, k, k], stride, dev)
            })
            .collect::<Result<_>>()?;
        Ok(Self(convs))
    }

    fn forward(&self, mut x: Tensor<4>) -> Tensor<4> {
        for conv in &self.0 {
            x = conv.forward(x);
        }
        x
    }
}

/// The dense outputs of the network for one image whose sides are multiples of 32.
pub struct NetworkOutput {
    /// Dense descriptors `[1, 64, H/8, W/8]` (not normalised).
    pub descriptors: Tensor<4>,
    /// Keypoint logits `[1, 65, H/8, W/8]`.
    pub keypoint_logits: Tensor<4>,
    /// Reliability `[1, 1, H/8, W/8]` in (0, 1).
    pub reliability: Tensor<4>,
}

/// XFeat's convolutional network with its weights.
pub struct Network {
    skip1: Conv,
    block1: Block,
    block2: Block,
    block3: Block,
    block4: Block,
    block5: Block,
    fusion: Block,
    heatmap_head: Block,
    keypoint_head: Block,
    device: Device,
}

impl Network {
    /// Builds the network from the reference's state dict, checking every tensor's shape.
    pub fn new(w: &StateDict, dev: &Device) -> Result<Self> {
        let mut fusion = Block::basic(w, "block_fusion", &[(64, 64, 3, 1), (64, 64, 3, 1)], dev)?;
        fusion
            .0
            .push(Conv::pointwise(w, "block_fusion.2", 64, 64, dev)?);
        let mut heatmap_head = Block::basic(w, "heatmap_head", &[(64, 64, 1, 1); 2], dev)?;
        heatmap_head
            .0
            .push(Conv::pointwise(w, "heatmap_head.2", 64, 1, dev)?);
        let mut keypoint_head = Block::basic(w, "keypoint_head", &[(64, 64, 1, 1); 3], dev)?;
        keypoint_head
            .0
            .push(Conv::pointwise(w, "keypoint_head.3", 64, 65, dev)?);
        Ok(Self {
            skip1: Conv::pointwise(w, "skip1.1", 1, 24, dev)?,
            block1: Block::basic(
                w,
                "block1",
                &[(1, 4, 3, 1), (4, 8, 3, 2), (8, 8, 3, 1), (8, 24, 3, 2)],
                dev,
            )?,
            block2: Block::basic(w, "block2", &[(24, 24, 3, 1), (24, 24, 3, 1)], dev)?,
            block3: Block::basic(
                w,
                "block3",
                &[(24, 64, 3, 2), (64, 64, 3, 1), (64, 64, 1, 1)],
                dev,
            )?,
            block4: Block::basic(
                w,
                "block4",
                &[(64, 64, 3, 2), (64, 64, 3, 1), (64, 64, 3, 1)],
                dev,
            )?,
            block5: Block::basic(
                w,
                "block5",
                &[
                    (64, 128, 3, 2),
                    (128, 128, 3, 1),
                    (128, 128, 3, 1),
                    (128, 64, 1, 1),
                ],
                dev,
            )?,
            fusion,
            heatmap_head,
            keypoint_head,
            device: dev.clone(),
        })
    }

    /// Runs the network on an instance-normalised grey image (`height × width`, row-major, both
    /// multiples of 32).
    pub fn forward(&self, gray: &[f32], width: usize, height: usize) -> NetworkOutput {
        debug_assert!(width.is_multiple_of(32) && height.is_multiple_of(32));
        let x = Tensor::<4>::from_data(
            TensorData::new(gray.to_vec(), [1, 1, height, width]),
            &self.device,
        );
        let pooled = avg_pool2d(x.clone(), AvgPoolOptions::new([4, 4]).with_stride([4, 4]));
        let x1 = self.block1.forward(x.clone());
        let x2 = self.block2.forward(x1 + self.skip1.forward(pooled));
        let x3 = self.block3.forward(x2);
        let x4 = self.block4.forward(x3.clone());
        let x5 = self.block5.forward(x4.clone());
        let size = [height / 8, width / 8];
        let up = |t: Tensor<4>| {
            let options = InterpolateOptions::new(InterpolateMode::Bilinear)
                .with_align_corners(false)
                .with_output_size(size);
            interpolate(t, options)
        };
        let descriptors = self.fusion.forward(x3 + up(x4) + up(x5));
        let reliability = sigmoid(self.heatmap_head.forward(descriptors.clone()));
        let keypoint_logits = self.keypoint_head.forward(space_to_depth8(x));
        NetworkOutput {
            descriptors,
            keypoint_logits,
            reliability,
        }
    }
}

/// The reference's `_unfold2d(x, ws=8)` on a one-channel map: `[1, 1, H, W]` →
/// `[1, 64, H/8, W/8]` with channel `8·dy + dx` holding pixel `(8y + dy, 8x + dx)`.
fn space_to_depth8(x: Tensor<4>) -> Tensor<4> {
    let [_, _, h, w] = x.dims();
    x.reshape([1, h / 8, 8, w / 8, 8])
        .permute([0, 2, 4, 1, 3])
        .reshape([1, 64, h / 8, w / 8])
}
