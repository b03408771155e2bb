//! Why a benchmark cannot run.

use std::path::PathBuf;

use crate::pipeline::PipelineError;

/// Why a benchmark cannot run, naming the scene folder or the run.
#[derive(Debug, thiserror::Error)]
pub enum BenchmarkError {
    #[error("{}: {message}", folder.display())]
    Scene { folder: PathBuf, message: String },
    #[error(transparent)]
    Pipeline(#[from] PipelineError),
    #[error("{}: {message}", run.display())]
    Run { run: PathBuf, message: String },
}
