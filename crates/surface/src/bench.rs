//! Speed of a training step, beside a reference measured in the same run: the same step with
//! the paper's NeuS MLP (8 × 256, positional encoding) as the geometry encoder instead of the
//! hash grid's custom CPU op. Everything else (batch, sampling, losses, pose refinement,
//! correspondences) is the default run's. A second hash-grid figure times the step with the
//! poses held, as the CPU schedule holds them for most of a run: held poses are not tracked by
//! autodiff, so the step skips the gradient with respect to the sample positions.

use fewview_scene::Dataset;
use serde::Serialize;

use crate::config::RunConfig;
use crate::error::Result;
use crate::field::EncoderKind;
use crate::pipeline::prepare;
use crate::train::trainer::Trainer;
use fewview_scene::cputime::measure;

/// Iterations per second of one configuration.
#[derive(Clone, Debug, Serialize)]
pub struct StepRate {
    pub encoder: String,
    pub iterations: usize,
    pub seconds: f64,
    pub cpu_seconds: f64,
    pub iterations_per_second: f64,
    /// Iterations per CPU-second (summed over threads; insensitive to other load).
    pub iterations_per_cpu_second: f64,
}

/// The training-step figures of a dataset.
#[derive(Clone, Debug, Serialize)]
pub struct SurfaceStepBench {
    pub dataset: String,
    pub width: usize,
    pub height: usize,
    pub train_views: usize,
    pub correspondences: usize,
    /// Rays rendered per iteration (random pixels + two per correspondence).
    pub rays_per_iteration: usize,
    pub samples_per_ray: usize,
    /// The default run (hash grid), poses refined in every step.
    pub hash_grid: StepRate,
    /// The same step with the poses held (`pose_start` 1), as in the CPU schedule's held part.
    pub hash_grid_poses_held: StepRate,
    /// `hash_grid_poses_held.iterations_per_cpu_second / hash_grid.iterations_per_cpu_second`.
    pub held_speedup: f64,
    /// The reference: the same step with the NeuS MLP encoder.
    pub reference_neus_mlp: StepRate,
    /// `hash_grid.iterations_per_cpu_second / reference_neus_mlp.iterations_per_cpu_second`.
    pub speedup_vs_reference: f64,
}

fn rate(
    config: &RunConfig,
    prep: &crate::pipeline::Prepared,
    iterations: usize,
) -> Result<StepRate> {
    let mut trainer = Trainer::new(
        config.train.clone(),
        prep.views.clone(),
        &prep.initial,
        prep.matches.clone(),
    )?;
    trainer.step()?;
    let (result, seconds, cpu_seconds) = measure(|| {
        for _ in 0..iterations {
            trainer.step()?;
        }
        Ok::<(), crate::error::SurfaceError>(())
    });
    result?;
    Ok(StepRate {
        encoder: format!("{:?}", config.train.field.encoder),
        iterations,
        seconds,
        cpu_seconds,
        iterations_per_second: iterations as f64 / seconds,
        iterations_per_cpu_second: iterations as f64 / cpu_seconds,
    })
}

/// Times `iterations` steps (after one warm-up step) of the default run on `dataset` (e.g. DTU
/// scan65, views 22, 25, 28, 400 × 300), then `reference_iterations` steps of the same run with
/// the NeuS MLP encoder. Correspondences are computed once and shared.
pub fn train_step_bench(
    dataset: &Dataset,
    iterations: usize,
    reference_iterations: usize,
) -> Result<SurfaceStepBench> {
    train_step_bench_with(
        dataset,
        &RunConfig::default(),
        iterations,
        reference_iterations,
    )
}

/// [`train_step_bench`] with another configuration (its encoder is replaced by the NeuS MLP for
/// the reference).
pub fn train_step_bench_with(
    dataset: &Dataset,
    config: &RunConfig,
    iterations: usize,
    reference_iterations: usize,
) -> Result<SurfaceStepBench> {
    let config = config.clone();
    let prep = prepare(dataset, None, &config)?;
    let hash_grid = rate(&config, &prep, iterations.max(1))?;
    let mut held = config.clone();
    held.train.pose_start = 1.0;
    let hash_grid_poses_held = rate(&held, &prep, iterations.max(1))?;
    let mut reference = config.clone();
    reference.train.field.encoder = EncoderKind::NeusMlp;
    let reference_neus_mlp = rate(&reference, &prep, reference_iterations.max(1))?;
    let first = &prep.views[0].image;
    Ok(SurfaceStepBench {
        dataset: dataset.name.clone(),
        width: first.width,
        height: first.height,
        train_views: prep.views.len(),
        correspondences: prep.matches.len(),
        rays_per_iteration: config.train.rays_per_batch + 2 * config.train.matches_per_batch,
        samples_per_ray: config.train.sample.samples_per_ray(),
        speedup_vs_reference: hash_grid.iterations_per_cpu_second
            / reference_neus_mlp.iterations_per_cpu_second,
        held_speedup: hash_grid_poses_held.iterations_per_cpu_second
            / hash_grid.iterations_per_cpu_second,
        hash_grid,
        hash_grid_poses_held,
        reference_neus_mlp,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sdf_scene::{SdfSceneOptions, sdf_dataset};

    /// The bench runs end to end on a tiny scene and reports consistent figures.
    #[test]
    fn bench_reports_consistent_rates() {
        let ds = sdf_dataset(&SdfSceneOptions {
            width: 48,
            height: 36,
            views: 4,
            train: vec![0, 1, 2],
            supersample: 1,
            ..Default::default()
        });
        let mut config = RunConfig::default();
        config.train.rays_per_batch = 32;
        config.train.matches_per_batch = 8;
        config.train.sample.n_coarse = 8;
        config.train.sample.n_importance = 8;
        let b = train_step_bench_with(&ds, &config, 2, 1).unwrap();
        assert_eq!(b.rays_per_iteration, 32 + 2 * 8);
        assert_eq!(b.train_views, 3);
        assert_eq!((b.width, b.height), (48, 36));
        assert_eq!(b.hash_grid.iterations, 2);
        assert!(b.hash_grid.iterations_per_second > 0.0 && b.hash_grid.seconds > 0.0);
        let ratio =
            b.hash_grid.iterations_per_cpu_second / b.reference_neus_mlp.iterations_per_cpu_second;
        assert!((b.speedup_vs_reference - ratio).abs() < 1e-12);
        assert_eq!(b.hash_grid_poses_held.iterations, 2);
        let held = b.hash_grid_poses_held.iterations_per_cpu_second
            / b.hash_grid.iterations_per_cpu_second;
        assert!((b.held_speedup - held).abs() < 1e-12);
    }
}
