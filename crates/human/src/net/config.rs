//! What a network is: the appendix's configuration variant, the widths, the number of pose
//! channels and the nominal input size, and the stage plan that the modules and the
//! multiply-add count both read, so that the two cannot disagree.
//!
//! "PoseGaussian: Pose-Driven Novel View Synthesis for Robust 3D Human Reconstruction",
//! appendix "Implementation Details" and "Detailed Configuration Variants".

use std::fmt;

use serde::{Deserialize, Serialize};

use crate::error::{HumanError, Result};

/// Pose channels of the capture's 17-joint skeleton ([`crate::dataset`]'s `joints.json`): one
/// heatmap per joint and one limb per bone (16 joints have a parent); see [`super::posemap`].
pub const SKELETON_POSE_CHANNELS: usize = 17 + 16;

/// The four configuration variants of the appendix ("Detailed Configuration Variants and
/// Their Impact"). The paper describes each in one sentence; where it is silent:
///
/// - Every residual unit carries a Squeeze-and-Excitation block ("each residual unit includes a
///   Squeeze-and-Excitation (SE) block"), in all four variants.
/// - Config 2 is read literally: two stacked 3×3 convolutions with the skip around both and no
///   activation between them (config 3 is the one that "introduces ... ReLU activations within
///   the residual blocks"); the ReLU after the sum and the SE gate keep it nonlinear.
/// - Downsampling, where there is some, is a stride of 2 in the first unit of each encoder
///   stage, as in the RAFT/GPS-Gaussian residual encoders the paper builds on.
/// - Config 4 is config 3 without those strides (the paper compares it with configs 2 and 3).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Variant {
    /// Config 1: one 5×5 convolution to 32 channels, then one residual block (one 3×3
    /// convolution and the skip). A single resolution level.
    Simplified,
    /// Config 2: residual units of two 3×3 convolutions with a skip connection around them.
    DeepResidual,
    /// Config 3: config 2 plus batch normalisation after each convolution and a ReLU between
    /// the two convolutions. The default: the fullest variant the appendix describes.
    Normalized,
    /// Config 4: config 3 without downsampling; every level keeps the input resolution.
    FullResolution,
}

impl Variant {
    /// All four, in the paper's order.
    pub const ALL: [Variant; 4] = [
        Variant::Simplified,
        Variant::DeepResidual,
        Variant::Normalized,
        Variant::FullResolution,
    ];

    /// The paper's number (1 to 4).
    pub fn number(self) -> u8 {
        match self {
            Variant::Simplified => 1,
            Variant::DeepResidual => 2,
            Variant::Normalized => 3,
            Variant::FullResolution => 4,
        }
    }

    /// The variant the paper numbers `n`.
    pub fn from_number(n: u8) -> Result<Self> {
        Variant::ALL
            .into_iter()
            .find(|v| v.number() == n)
            .ok_or_else(|| HumanError::argument("variant", format!("{n} is not one of 1, 2, 3, 4")))
    }

    /// Kernel of the first convolution: 5×5 in config 1, 3×3 otherwise.
    pub fn stem_kernel(self) -> usize {
        if self == Variant::Simplified { 5 } else { 3 }
    }

    /// 3×3 convolutions in one residual unit.
    pub fn convs_per_unit(self) -> usize {
        if self == Variant::Simplified { 1 } else { 2 }
    }

    /// Whether residual units normalise (batch norm) and apply a ReLU between their convolutions.
    pub fn batch_norm(self) -> bool {
        matches!(self, Variant::Normalized | Variant::FullResolution)
    }

    /// Whether encoder stages halve the resolution.
    pub fn downsamples(self) -> bool {
        matches!(self, Variant::DeepResidual | Variant::Normalized)
    }
}

/// One encoder stage (mirrored by one decoder stage): its width, its residual units and the
/// stride of its first unit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StagePlan {
    pub width: usize,
    pub units: usize,
    pub stride: usize,
}

/// The whole network's shape. Two presets exist ([`NetConfig::paper`], [`NetConfig::cpu`]);
/// any other is allowed (tests build tiny ones). A checkpoint stores this beside its weights
/// and is refused by a network with any other value.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NetConfig {
    pub variant: Variant,
    /// Stem width, then the three stages' widths (the paper's 32/64/96/128).
    pub widths: [usize; 4],
    /// Channels of the pose map ([`super::posemap::pose_map_channels`]).
    pub pose_channels: usize,
    /// Nominal input `[height, width]` of the preset. The network is fully convolutional and
    /// takes any size; this only fixes what the preset (and its multiply-add count) means.
    pub input: [usize; 2],
    /// β of the scale head's Softplus, `log(1 + exp(βx)) / β`. The paper says "Softplus"; 100
    /// is what GPS-Gaussian's scale head uses, so that a zero pre-activation gives scales of
    /// ~7 mm rather than ~0.7 m.
    pub scale_softplus_beta: f64,
}

impl NetConfig {
    /// The paper's network: 512×512 inputs, widths 32/64/96/128.
    pub fn paper(variant: Variant) -> Self {
        Self {
            variant,
            widths: [32, 64, 96, 128],
            pose_channels: SKELETON_POSE_CHANNELS,
            input: [512, 512],
            scale_softplus_beta: 100.0,
        }
    }

    /// The CPU preset: 128×256 crops around the person (height × width = 256 × 128, a standing
    /// person's aspect) and the widths halved, 16/32/48/64.
    pub fn cpu(variant: Variant) -> Self {
        Self {
            widths: [16, 32, 48, 64],
            input: [256, 128],
            ..Self::paper(variant)
        }
    }

    /// The encoder stages after the stem. Config 1 has one stage of one unit at the stem's
    /// width; the others three stages of two units (six residual units, as the paper says)
    /// at the three larger widths, as GPS-Gaussian's encoder groups its six blocks.
    pub fn stages(&self) -> Vec<StagePlan> {
        if self.variant == Variant::Simplified {
            return vec![StagePlan {
                width: self.widths[0],
                units: 1,
                stride: 1,
            }];
        }
        let stride = if self.variant.downsamples() { 2 } else { 1 };
        self.widths[1..]
            .iter()
            .map(|&width| StagePlan {
                width,
                units: 2,
                stride,
            })
            .collect()
    }

    /// Input channels of the three encoders: image (RGB), pose map, depth.
    pub fn encoder_inputs(&self) -> [usize; 3] {
        [3, self.pose_channels, 1]
    }

    /// An error unless every width and the pose channel count are positive and β is positive.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(HumanError::argument("network config", m));
        if self.widths.contains(&0) || self.pose_channels == 0 {
            return bad(format!("zero width or channel count in {self}"));
        }
        if !(self.scale_softplus_beta > 0.0) {
            return bad(format!(
                "softplus β must be positive, not {}",
                self.scale_softplus_beta
            ));
        }
        Ok(())
    }

    /// The preset's name when this is one of the two presets.
    pub fn preset_name(&self) -> Option<&'static str> {
        let v = self.variant;
        [("paper", Self::paper(v)), ("cpu", Self::cpu(v))]
            .into_iter()
            .find(|(_, c)| c == self)
            .map(|(n, _)| n)
    }
}

impl fmt::Display for NetConfig {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(name) = self.preset_name() {
            write!(f, "preset {name}, ")?;
        }
        let [w0, w1, w2, w3] = self.widths;
        write!(
            f,
            "config {}, widths {w0}/{w1}/{w2}/{w3}, {} pose channels, input {}×{}, softplus β {}",
            self.variant.number(),
            self.pose_channels,
            self.input[0],
            self.input[1],
            self.scale_softplus_beta
        )
    }
}

/// Hidden units of the SE block on `channels` channels: `channels / 16` (the reduction ratio
/// r = 16 of Hu et al., "Squeeze-and-Excitation Networks"), but never fewer than
/// `min(8, channels)`, so that the narrow layers here (16 to 128 channels) keep a bottleneck
/// of a few units instead of one or two; r is then effectively 8 or smaller for them.
pub fn se_hidden(channels: usize) -> usize {
    (channels / 16).max(channels.min(8))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variants_round_trip_their_numbers() {
        for v in Variant::ALL {
            assert_eq!(Variant::from_number(v.number()).unwrap(), v);
        }
        let e = Variant::from_number(5).unwrap_err().to_string();
        assert_eq!(e, "variant: 5 is not one of 1, 2, 3, 4");
    }

    #[test]
    fn presets_have_six_units_and_name_themselves() {
        let paper = NetConfig::paper(Variant::Normalized);
        let units: usize = paper.stages().iter().map(|s| s.units).sum();
        assert_eq!(units, 6);
        assert_eq!(paper.stages()[2].width, 128);
        assert_eq!(paper.preset_name(), Some("paper"));
        let cpu = NetConfig::cpu(Variant::FullResolution);
        assert!(cpu.stages().iter().all(|s| s.stride == 1));
        assert!(
            cpu.to_string()
                .starts_with("preset cpu, config 4, widths 16/32/48/64")
        );
        assert_eq!(NetConfig::cpu(Variant::Simplified).stages().len(), 1);
    }

    #[test]
    fn se_hidden_follows_the_reduction_rule() {
        assert_eq!(se_hidden(256), 16);
        assert_eq!(se_hidden(128), 8);
        assert_eq!(se_hidden(32), 8);
        assert_eq!(se_hidden(4), 4);
    }
}
