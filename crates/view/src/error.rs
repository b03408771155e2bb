//! Errors of the viewer: one line each, naming the file and the problem.

use std::path::PathBuf;

/// An error while reading a run or serving it.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    /// A file or folder could not be opened or read.
    #[error(transparent)]
    Io(fewview_scene::FileIoError),
    /// A file was read but is not what the viewer can show.
    #[error("{}: {message}", path.display())]
    Format { path: PathBuf, message: String },
    /// A mesh or camera file of the run could not be read.
    #[error(transparent)]
    Geom(#[from] fewview_geom::GeomError),
    /// The dataset given for the run's cameras could not be read.
    #[error(transparent)]
    Scene(#[from] fewview_scene::SceneError),
    /// The web server could not start or stopped with an error.
    #[error("{0}")]
    Server(String),
}

impl ViewError {
    pub fn io(path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        Self::Io(fewview_scene::FileIoError::new(path, error))
    }
    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self::Format {
            path: path.into(),
            message: message.into(),
        }
    }
}

pub type Result<T, E = ViewError> = std::result::Result<T, E>;
