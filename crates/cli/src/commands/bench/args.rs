//! The `bench` command's flags.

use std::path::PathBuf;

use clap::Args as ClapArgs;
use fewview_splat::pipeline::MAX_INIT_POINTS;

use crate::commands::number_args::{count_in, positive_count};

/// Measure speed and memory, beside references measured in the same run.
///
/// Measures the rasterizer (forward and backward splat–pixel pairs per CPU-second at 100k
/// Gaussians and 504×378, beside a plain single-threaded blend loop), training iterations per
/// second (the demo scene, and LLFF fern 3-view when the data is available), surface training
/// iterations per second on DTU scan65 3-view (hash grid, beside the NeuS MLP; with the poses
/// refined and with them held, as the CPU schedule holds them), the SSIM loss,
/// the occlusion-aware Poisson blend at 1024², Semi-Global Matching on fern's rectified pair
/// (1, 10) cropped to 504×378 with 64 disparities (beside the same on one thread; the whole
/// stereo pair at its own size too), PoseGaussian inference per frame for both presets (by
/// stage, beside a matrix product's multiply-add rate), and peak memory. Prints a table and writes JSON.
///
/// Throughput is reported per CPU-second (CPU time summed over threads), which does not change
/// much when other programs load the machine; wall-clock seconds are reported too. The
/// rasterizer's per-core figures run on one thread (like the plain loop they are compared
/// with); its all-threads figures are printed beside them.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Where to write the JSON report.
    #[arg(long, default_value = "runs/bench.json", value_name = "FILE")]
    pub json: PathBuf,
    /// LLFF fern folder (default: in `$FEWVIEW_DATA`).
    ///
    /// LLFF fern folder for the training-step figure (default: `$FEWVIEW_DATA/llff/fern`).
    #[arg(long, value_name = "DIR")]
    pub fern: Option<PathBuf>,
    /// Gaussians in the rasterizer benchmark.
    ///
    /// 1 to 10,000,000, the `--init-points` limit.
    #[arg(long, default_value_t = 100_000, value_parser = gaussian_count)]
    pub gaussians: usize,
    /// Training steps timed per dataset (at least 1).
    #[arg(long, default_value_t = 20, value_parser = positive_count)]
    pub train_steps: usize,
    /// DTU scan65 folder (default: in `$FEWVIEW_DATA`).
    ///
    /// DTU scan65 folder for the surface training-step figure (default:
    /// `$FEWVIEW_DATA/dtu/scan65`; views 22, 25, 28 at 400×300).
    #[arg(long, value_name = "DIR")]
    pub dtu: Option<PathBuf>,
    /// Surface training steps timed.
    ///
    /// The NeuS-MLP reference runs one.
    #[arg(long, default_value_t = 10)]
    pub surface_steps: usize,
    /// PoseGaussian inference frames and training steps timed.
    ///
    /// Frames timed for PoseGaussian inference with the CPU preset (the paper preset times one),
    /// and the network's training steps timed per preset.
    #[arg(long, default_value_t = 3, value_parser = positive_count)]
    pub human_frames: usize,
    /// Repetitions of each rasterizer measurement.
    ///
    /// The median is reported; at least 1.
    #[arg(long, default_value_t = 5, value_parser = positive_count)]
    pub runs: usize,
    /// Where the rasterizer and training steps run.
    ///
    /// `cpu`, or `gpu` (builds with `--features gpu`; the rasterizer's CPU figures are then
    /// measured on the same scene as the yardstick, and PoseGaussian's inference, which runs on
    /// the CPU, is left out).
    #[arg(long, value_enum, default_value_t)]
    pub device: fewview_splat::ComputeDevice,
    /// Image size of the rasterizer benchmark, `WIDTHxHEIGHT`.
    #[arg(long, default_value = "504x378", value_parser = parse_size, value_name = "WxH")]
    pub raster_size: (usize, usize),
    /// Also write the rasterizer's scene into DIR.
    ///
    /// Also write the rasterizer benchmark's scene as `DIR/scene.ply` and `DIR/cameras.json`
    /// (for timing other rasterizers on the same Gaussians).
    #[arg(long, value_name = "DIR")]
    pub write_scene: Option<PathBuf>,
    /// Measure only these sections.
    ///
    /// E.g. `--only human,ssim` (default: all).
    #[arg(long, value_enum, value_delimiter = ',', value_name = "SECTION")]
    pub only: Vec<Section>,
}

/// A part of the benchmark that `--only` can pick.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Section {
    /// The rasterizer's forward and backward passes.
    Raster,
    /// Training steps on the demo scene and LLFF fern.
    Train,
    /// Demo training steps with the gradient-domain fusion term.
    Fusion,
    /// Demo training steps with a per-photo affine colour transform.
    Appearance,
    /// Surface training steps on DTU scan65.
    Surface,
    /// The SSIM loss.
    Ssim,
    /// The Poisson blend.
    Blend,
    /// Semi-Global Matching.
    Stereo,
    /// PoseGaussian: inference per frame, both presets, on the CPU; the network's training
    /// steps on the device (on a GPU, both presets).
    Human,
    /// The learned matchers (XFeat, XFeat*, LighterGlue) on a 400×300 fern pair.
    Match,
}

impl Args {
    pub(super) fn wants(&self, section: Section) -> bool {
        self.only.is_empty() || self.only.contains(&section)
    }
}

/// `--raster-size`: `WIDTHxHEIGHT`, each 1 to 16384.
fn parse_size(s: &str) -> Result<(usize, usize), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("`{s}`: expected WIDTHxHEIGHT, e.g. 1024x1024"))?;
    Ok((count_in(w, 1, 16384)?, count_in(h, 1, 16384)?))
}

/// `--gaussians`: at least one, and no more than training may start from
/// ([`MAX_INIT_POINTS`], about 1 KB each): 10¹² aborted on allocation.
fn gaussian_count(s: &str) -> Result<usize, String> {
    count_in(s, 1, MAX_INIT_POINTS)
}
