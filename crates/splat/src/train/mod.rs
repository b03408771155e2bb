//! Sparse-view training of 3D Gaussians.

pub mod adam;
pub mod config;
pub mod densify;
pub mod trainer;

pub use config::{DensifyConfig, LearningRates, TrainConfig};
pub use trainer::{LossContext, LossTerm, Progress, TrainError, TrainState, TrainView, Trainer};
