//! Sparse-view training of 3D Gaussians.
//!
//! [`Trainer`] runs the loop ([`trainer`]: render, loss, backward; `update`: densification and
//! Adam). What it trains on is a [`TrainView`] each ([`view`]); what it reports and saves is in
//! [`state`]; an extra loss is one [`LossTerm`] ([`term`]).

/// Adam lives in `fewview-optim`, shared with the surface trainer.
pub use fewview_optim::adam;
pub mod appearance;
pub mod co_prune;
pub mod config;
pub mod densify;
pub mod dropout;
pub mod pair;
pub mod pseudo;
mod resident;
pub mod state;
pub mod term;
pub mod trainer;
mod update;
pub mod view;

pub use appearance::{AppearanceConfig, AppearanceModel, AppearanceState};
pub use config::{DensifyConfig, LearningRates, TrainConfig};
pub use state::{Progress, TrainError, TrainState};
pub use term::{LossContext, LossTerm};
pub use trainer::Trainer;
pub use view::{AlphaImage, TrainView};
