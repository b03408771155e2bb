//! The whole network of "PoseGaussian: Pose-Driven Novel View Synthesis for Robust 3D Human
//! Reconstruction" (appendix, Fig. 5): three encoders of identical structure for a source view's
//! image, pose map and depth, one U-Net decoder over their concatenated features, and the
//! SR-Opacity, depth and uncertainty heads.

use burn::module::Module;
use burn::tensor::{Device, Tensor};

use super::config::NetConfig;
use super::decoder::Decoder;
use super::encoder::Encoder;
use super::heads::{HeadOutputs, Heads};
use crate::error::{HumanError, Result};

/// What one source view gives the network, each `[N, C, H, W]` of one size.
#[derive(Clone, Debug)]
pub struct NetInput {
    /// sRGB in `[0, 1]`, 3 channels.
    pub image: Tensor<4>,
    /// The pose map ([`super::posemap::pose_map`]), `pose_channels` channels.
    pub pose: Tensor<4>,
    /// Depth normalised to `[-1, 1]` over the near/far range, as the depth head predicts it.
    pub depth: Tensor<4>,
}

/// PoseGaussian's network, parameters and the configuration that shaped them.
/// Seconds spent in each part of one forward pass.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ForwardTimes {
    pub image_encoder: f64,
    pub pose_encoder: f64,
    pub depth_encoder: f64,
    pub decoder_and_heads: f64,
}

#[derive(Module, Debug)]
pub struct PoseGaussianNet {
    pub(crate) image: Encoder,
    pub(crate) pose: Encoder,
    pub(crate) depth: Encoder,
    pub(crate) decoder: Decoder,
    pub(crate) heads: Heads,
    #[module(skip)]
    pub(crate) config: NetConfig,
}

impl PoseGaussianNet {
    /// A freshly initialised network (Burn's default initialisers, drawn lazily from the
    /// device's generator; seed it with `device.seed` for a reproducible start).
    pub fn new(config: &NetConfig, device: &Device) -> Result<Self> {
        config.validate()?;
        let [ci, cp, cd] = config.encoder_inputs();
        Ok(Self {
            image: Encoder::new(ci, config, device),
            pose: Encoder::new(cp, config, device),
            depth: Encoder::new(cd, config, device),
            decoder: Decoder::new(config, device),
            heads: Heads::new(config.widths[0], config.scale_softplus_beta, device),
            config: config.clone(),
        })
    }

    pub fn config(&self) -> &NetConfig {
        &self.config
    }

    /// The heads' outputs for a batch of source views; an error naming the input whose shape
    /// does not fit (an empty image, a channel count, or a size that differs from the image's).
    pub fn forward(&self, input: NetInput) -> Result<HeadOutputs> {
        self.check(&input)?;
        let features = [
            self.image.forward(input.image),
            self.pose.forward(input.pose),
            self.depth.forward(input.depth),
        ];
        Ok(self.heads.forward(self.decoder.forward(features)))
    }

    /// [`PoseGaussianNet::forward`] with the wall time of each part (the CPU backend runs
    /// eagerly, so each part's time is its own): the image, pose and depth encoders, then the
    /// decoder with the heads.
    pub fn forward_timed(&self, input: NetInput) -> Result<(HeadOutputs, ForwardTimes)> {
        self.check(&input)?;
        let clock = std::time::Instant::now();
        let image = self.image.forward(input.image);
        let t_image = clock.elapsed().as_secs_f64();
        let pose = self.pose.forward(input.pose);
        let t_pose = clock.elapsed().as_secs_f64();
        let depth = self.depth.forward(input.depth);
        let t_depth = clock.elapsed().as_secs_f64();
        let heads = self
            .heads
            .forward(self.decoder.forward([image, pose, depth]));
        let t_all = clock.elapsed().as_secs_f64();
        let times = ForwardTimes {
            image_encoder: t_image,
            pose_encoder: t_pose - t_image,
            depth_encoder: t_depth - t_pose,
            decoder_and_heads: t_all - t_depth,
        };
        Ok((heads, times))
    }

    fn check(&self, input: &NetInput) -> Result<()> {
        let [n, _, h, w] = input.image.dims();
        if n * h * w == 0 {
            let m = format!("empty image {:?} (N, C, H, W)", input.image.dims());
            return Err(HumanError::argument("network input", m));
        }
        let named = [
            ("image", &input.image),
            ("pose map", &input.pose),
            ("depth", &input.depth),
        ];
        for ((name, t), c) in named.into_iter().zip(self.config.encoder_inputs()) {
            let want = [n, c, h, w];
            if t.dims() != want {
                return Err(HumanError::argument(
                    "network input",
                    format!("{name} is {:?}, expected {want:?} (N, C, H, W)", t.dims()),
                ));
            }
        }
        Ok(())
    }
}
