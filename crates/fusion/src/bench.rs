//! What the fusion term costs: training steps with and without it, same scene, same start.

use fewview_scene::Dataset;
use fewview_splat::bench::{TrainStepBench, train_step_bench_with};
use fewview_splat::pipeline::RunConfig;
use fewview_splat::train::TrainConfig;
use serde::Serialize;

use crate::error::FusionError;
use crate::run::{fusion_terms, training_pairs};
use crate::variant::FusionConfig;

/// Training steps of plain training and of training with the fusion term on every step.
#[derive(Clone, Debug, Serialize)]
pub struct FusionStepBench {
    pub plain: TrainStepBench,
    pub fusion: TrainStepBench,
    /// Share of a fusion step spent on the term: `1 − t_plain / t_fusion` (wall time).
    pub term_share: f64,
}

/// Times `iterations` steps of `ds`'s default run without and with the gradient-domain fusion
/// term, the term taken on every step (from the first) so that each timed step pays for it.
/// The meshes are built once in the warm-up steps (as a run rebuilds them every 500 steps).
pub fn fusion_step_bench(ds: &Dataset, iterations: usize) -> Result<FusionStepBench, FusionError> {
    let mut cfg = RunConfig::new(TrainConfig::sparse_view(3000));
    cfg.train.background = ds.background;
    let plain = train_step_bench_with(ds, &cfg, Vec::new(), iterations)?;
    let fusion_config = FusionConfig {
        start_fraction: 0.0,
        every: 1,
        ..FusionConfig::default()
    };
    let pairs = training_pairs(ds)?;
    let (terms, _) = fusion_terms(ds, &cfg, &fusion_config, &pairs);
    let fusion = train_step_bench_with(ds, &cfg, terms, iterations)?;
    Ok(FusionStepBench {
        term_share: 1.0 - plain.seconds / fusion.seconds,
        plain,
        fusion,
    })
}
