//! Sparse-view training of 3D Gaussians.

/// Adam lives in `fewview-optim`, shared with the surface trainer.
pub use fewview_optim::adam;
pub mod appearance;
pub mod config;
pub mod densify;
mod resident;
pub mod trainer;

pub use appearance::{AppearanceConfig, AppearanceModel, AppearanceState};
pub use config::{DensifyConfig, LearningRates, TrainConfig};
pub use trainer::{
    AlphaImage, LossContext, LossTerm, Progress, TrainError, TrainState, TrainView, Trainer,
};
