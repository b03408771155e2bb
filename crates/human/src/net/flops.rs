//! Multiply-adds of one forward pass, counted from the configuration alone (no weights are
//! built), by walking the same stage plan ([`NetConfig::stages`]) the modules are built from.
//!
//! Counted: every convolution (`H_out·W_out·C_out·C_in·k²`) and the SE blocks' fully connected
//! layers (`2·C·hidden` per image). Not counted: biases, batch norm, activations, pooling,
//! bilinear upsampling and concatenation, which are elementwise or memory moves, a few percent
//! at most. One multiply-add is two floating-point operations.

use super::config::{NetConfig, Variant, se_hidden};
use super::decoder::{fuse_input, stage_input};

/// Output side of a `k`×`k` convolution with `k / 2` padding at `stride`.
fn strided(side: usize, stride: usize) -> usize {
    (side - 1) / stride + 1
}

/// Multiply-adds of a convolution producing `size` from `input` to `output` channels.
fn conv_macs(size: [usize; 2], input: usize, output: usize, kernel: usize) -> u64 {
    (size[0] * size[1] * output * input * kernel * kernel) as u64
}

/// Multiply-adds of one residual unit on an input of `size`, and its output size.
fn unit_macs(
    size: [usize; 2],
    input: usize,
    output: usize,
    stride: usize,
    variant: Variant,
) -> (u64, [usize; 2]) {
    let out = [strided(size[0], stride), strided(size[1], stride)];
    let mut macs = conv_macs(out, input, output, 3);
    if variant.convs_per_unit() == 2 {
        macs += conv_macs(out, output, output, 3);
    }
    if input != output || stride != 1 {
        macs += conv_macs(out, input, output, 1);
    }
    macs += (2 * output * se_hidden(output)) as u64;
    (macs, out)
}

/// Multiply-adds of a stage, and its output size.
fn stage_macs(
    size: [usize; 2],
    input: usize,
    output: usize,
    units: usize,
    stride: usize,
    variant: Variant,
) -> (u64, [usize; 2]) {
    let (mut total, mut size) = unit_macs(size, input, output, stride, variant);
    for _ in 1..units {
        let (m, s) = unit_macs(size, output, output, 1, variant);
        total += m;
        size = s;
    }
    (total, size)
}

/// Multiply-adds of one encoder of `input` channels, and the size of each level's features.
fn encoder_macs(config: &NetConfig, input: usize, size: [usize; 2]) -> (u64, Vec<[usize; 2]>) {
    let v = config.variant;
    let mut total = conv_macs(size, input, config.widths[0], v.stem_kernel());
    let (mut sizes, mut width) = (vec![size], config.widths[0]);
    for s in config.stages() {
        let (m, next) = stage_macs(
            *sizes.last().expect("stem"),
            width,
            s.width,
            s.units,
            s.stride,
            v,
        );
        total += m;
        sizes.push(next);
        width = s.width;
    }
    (total, sizes)
}

/// Multiply-adds of one forward pass of the network `config` on one `height`×`width` view
/// (a batch of N costs N times as much).
pub fn forward_macs(config: &NetConfig, height: usize, width: usize) -> u64 {
    let size = [height.max(1), width.max(1)];
    let mut total = 0;
    let mut sizes = Vec::new();
    for input in config.encoder_inputs() {
        let (m, s) = encoder_macs(config, input, size);
        total += m;
        sizes = s;
    }
    let v = config.variant;
    for (i, s) in config.stages().iter().enumerate() {
        let input = stage_input(config, i);
        total += stage_macs(sizes[i + 1], input, s.width, s.units, 1, v).0;
    }
    let w0 = config.widths[0];
    total += conv_macs(size, fuse_input(config), w0, 3);
    total + conv_macs(size, w0, 8 + 1 + 2, 3)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiny(variant: Variant) -> NetConfig {
        NetConfig {
            widths: [2, 3, 4, 5],
            pose_channels: 2,
            ..NetConfig::cpu(variant)
        }
    }

    /// Config 1 on a 4×6 view (24 pixels), written out layer by layer.
    #[test]
    fn config_1_count_matches_a_hand_count() {
        let stems = 24 * 2 * (3 + 2 + 1) * 25; // 5×5 to 2 channels from 3, 2, 1 channels
        let enc_unit = 24 * 2 * 2 * 9 + 2 * 2 * 2; // one 3×3 conv 2→2, SE with 2 hidden
        let dec_unit = 24 * 2 * 6 * 9 + 24 * 2 * 6 + 2 * 2 * 2; // 3×3 6→2, 1×1 shortcut, SE
        let fuse = 24 * 2 * 8 * 9; // (2 decoded + 3·2 stems) → 2
        let heads = 24 * 2 * 9 * 11; // 8 + 1 + 2 outputs
        let want = stems + 3 * enc_unit + dec_unit + fuse + heads;
        assert_eq!(want, 20_912);
        assert_eq!(forward_macs(&tiny(Variant::Simplified), 4, 6), want);
    }

    /// Config 2 on an 8×8 view: levels of 8×8, 4×4, 2×2, 1×1 (64, 16, 4, 1 pixels).
    #[test]
    fn config_2_count_matches_a_hand_count() {
        let stems = 64 * 2 * (3 + 2 + 1) * 9;
        // Encoder stage 1: 2→3 at 16 px (two 3×3, 1×1 shortcut, SE 3·3·2), then 3→3.
        let e1 = (16 * 3 * 2 * 9 + 16 * 3 * 3 * 9 + 16 * 3 * 2 + 18) + (2 * 16 * 3 * 3 * 9 + 18);
        // Stage 2: 3→4 at 4 px, SE 4·4·2; stage 3: 4→5 at 1 px, SE 5·5·2.
        let e2 = (4 * 4 * 3 * 9 + 4 * 4 * 4 * 9 + 4 * 4 * 3 + 32) + (2 * 4 * 4 * 4 * 9 + 32);
        let e3 = (5 * 4 * 9 + 5 * 5 * 9 + 5 * 4 + 50) + (2 * 5 * 5 * 9 + 50);
        // Decoder: 15→5 at 1 px, (3·4 + 5 = 17)→4 at 4 px, (3·3 + 4 = 13)→3 at 16 px.
        let d3 = (5 * 15 * 9 + 5 * 5 * 9 + 5 * 15 + 50) + (2 * 5 * 5 * 9 + 50);
        let d2 = (4 * 4 * 17 * 9 + 4 * 4 * 4 * 9 + 4 * 4 * 17 + 32) + (2 * 4 * 4 * 4 * 9 + 32);
        let d1 = (16 * 3 * 13 * 9 + 16 * 3 * 3 * 9 + 16 * 3 * 13 + 18) + (2 * 16 * 3 * 3 * 9 + 18);
        let fuse = 64 * 2 * (3 * 2 + 3) * 9;
        let heads = 64 * 2 * 9 * 11;
        let want = stems + 3 * (e1 + e2 + e3) + d3 + d2 + d1 + fuse + heads;
        assert_eq!(want, 70_546);
        assert_eq!(forward_macs(&tiny(Variant::DeepResidual), 8, 8), want);
    }

    /// Config 3 counts what config 2 does (batch norm is not counted); config 4 more, since
    /// nothing is downsampled.
    #[test]
    fn variants_compare_as_expected() {
        let m = |v| forward_macs(&NetConfig::paper(v), 512, 512);
        assert_eq!(m(Variant::DeepResidual), m(Variant::Normalized));
        assert!(m(Variant::FullResolution) > 4 * m(Variant::Normalized));
        assert!(m(Variant::Simplified) < m(Variant::Normalized));
    }
}
