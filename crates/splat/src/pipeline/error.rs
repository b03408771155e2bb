//! The errors of a run.

use std::path::PathBuf;

use fewview_scene::SceneError;

use crate::device::DeviceError;
use crate::train::TrainError;

/// Errors of a run, each naming what failed.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Train(#[from] TrainError),
    #[error("{path}: {message}")]
    Checkpoint { path: PathBuf, message: String },
    #[error("initialisation: {0}")]
    Init(String),
    #[error("surface start: {0}")]
    SurfaceStart(#[from] crate::surface_start::SurfaceStartError),
    #[error("evaluation: {0}")]
    Eval(String),
    #[error(transparent)]
    Device(#[from] DeviceError),
}
