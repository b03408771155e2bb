//! What training reports and keeps: each iteration's [`Progress`], the state a checkpoint
//! saves ([`TrainState`]) and why training stops early ([`TrainError`]).

use fewview_optim::ReadbackError;
use serde::{Deserialize, Serialize};

use super::appearance::AppearanceState;
use super::densify::{DensifyReport, DensifyStats, ModelAdam};
use crate::model::GaussianModel;

/// Progress of one iteration, for progress bars and logs.
#[derive(Clone, Debug, Serialize)]
pub struct Progress {
    pub iteration: usize,
    pub iterations: usize,
    pub loss: f32,
    pub gaussians: usize,
    pub densified: Option<DensifyReport>,
}

/// Why training stopped early.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error("training diverged at iteration {iteration}: loss is {loss}")]
    Diverged { iteration: usize, loss: f32 },
    #[error("invalid training setup: {0}")]
    Invalid(String),
    /// Densification and pruning removed every Gaussian: there is nothing left to train or save.
    #[error(
        "densification/pruning at iteration {iteration} removed every Gaussian ({before} before, 0 left); start from more points (e.g. a larger --init-points) or prune less"
    )]
    NoGaussiansLeft { iteration: usize, before: usize },
    /// A loss, gradient or render output whose values could not be read back (a defect).
    #[error(transparent)]
    Readback(#[from] ReadbackError),
}

/// Everything that changes during training; saved in checkpoints.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainState {
    /// Iterations completed.
    pub iteration: usize,
    pub model: GaussianModel,
    pub adam: ModelAdam,
    pub stats: DensifyStats,
    /// The training photos' colour transforms (empty without an appearance model).
    pub appearance: AppearanceState,
}
