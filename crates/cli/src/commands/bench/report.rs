//! The `bench` command's JSON report.

use serde::Serialize;

/// The figures measured; a section left out by `--only` (or lacking its data) is absent.
#[derive(Serialize)]
pub(super) struct Report {
    pub(super) machine: Machine,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) raster: Option<fewview_splat::bench::RasterBench>,
    #[cfg(feature = "gpu")]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) raster_gpu: Option<fewview_splat::bench_gpu::GpuRasterBench>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) train_demo: Option<fewview_splat::bench::TrainStepBench>,
    /// Demo training steps with the gradient-domain fusion term on every step.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) fusion_demo: Option<fewview_fusion::bench::FusionStepBench>,
    /// Demo training steps with a per-photo affine colour transform.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) appearance_demo: Option<fewview_splat::bench::AppearanceStepBench>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) train_fern: Option<fewview_splat::bench::TrainStepBench>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) train_surface: Option<fewview_surface::bench::SurfaceStepBench>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) ssim: Option<fewview_metrics::bench::SsimBench>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) blend: Option<fewview_geom::bench::BlendBench>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) stereo: Option<fewview_geom::bench::StereoBench>,
    /// PoseGaussian inference per frame, both presets (synthetic frame, random weights).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub(super) human_inference: Vec<fewview_human::bench::InferenceBench>,
    /// PoseGaussian training steps (the network's forward and backward): the CPU preset, and
    /// on a GPU the paper's as well.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub(super) human_training: Vec<fewview_human::bench::TrainingBench>,
    /// The learned matchers on one 400×300 pair (fern images 0 and 4, central crops).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(super) matching: Option<fewview_match::bench::MatchBench>,
    pub(super) peak_memory_mib: Option<f64>,
}

#[derive(Serialize)]
pub(super) struct Machine {
    pub(super) threads: usize,
    pub(super) avx2_fma: bool,
    /// The build of the rasterizer's tile kernels this CPU runs (`Avx512`, `Avx2`, `Portable`).
    pub(super) raster_kernels: String,
}

/// Peak resident memory of this process (VmHWM), in MiB.
pub(super) fn peak_memory_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}
