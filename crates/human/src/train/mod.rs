//! Training the PoseGaussian network (the PoseGaussian paper) on the input cameras of the training frames:
//! each step renders one input camera of one frame from its nearest other input cameras and
//! compares it with that camera's image ([`loss`]).
//!
//! - [`crop`]: the fixed per-camera crops around the person.
//! - [`prepare`]: a frame's cropped views with their visual-hull depth, and [`prepare::InputViews`],
//!   through which training reads only its own cameras and frames.
//! - [`forward`]: network → per-pixel Gaussians → render, the same for training and inference.
//! - [`loss`]: L1 + D-SSIM with the confidence-weighted depth and silhouette terms.
//! - [`trainer`]: Adam steps, checkpoints and resume.

pub mod crop;
pub mod forward;
pub mod loss;
pub mod prepare;
pub mod trainer;

pub use forward::{DepthBracket, ForwardSettings, Prediction, predict, render_prediction};
pub use loss::{LossParts, LossWeights};
pub use prepare::{Framing, InferenceInputs, InputViews, PreparedFrame, PreparedView};
pub use trainer::{Preset, StepStats, TrainConfig, Trainer, default_device};
