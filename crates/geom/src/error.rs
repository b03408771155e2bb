//! Errors of the geometry toolbox: each names the input (a file, or the argument) and the problem
//! in one line, so a person can act on it.

use std::path::PathBuf;

use fewview_scene::FileIoError;

/// An error of a geometry operation or of mesh/point I/O.
#[derive(Debug, thiserror::Error)]
pub enum GeomError {
    /// A file could not be opened, read or written.
    #[error(transparent)]
    Io(FileIoError),
    /// A file was read but its contents do not follow the format.
    #[error("{path}: {message}")]
    Format { path: PathBuf, message: String },
    /// Well-formed input that the operation cannot use (NaN, size mismatch, empty mask, ...).
    /// `what` names the argument or file.
    #[error("{what}: {message}")]
    Invalid { what: String, message: String },
    /// A numerical step failed (singular system, degenerate point set, ...).
    #[error("{0}")]
    Numerical(String),
}

impl GeomError {
    pub fn io(path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        Self::Io(FileIoError::new(path, error))
    }
    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self::Format {
            path: path.into(),
            message: message.into(),
        }
    }
    pub fn invalid(what: impl Into<String>, message: impl Into<String>) -> Self {
        Self::Invalid {
            what: what.into(),
            message: message.into(),
        }
    }
    pub fn numerical(message: impl Into<String>) -> Self {
        Self::Numerical(message.into())
    }
}

impl From<fewview_scene::SceneError> for GeomError {
    fn from(e: fewview_scene::SceneError) -> Self {
        match e {
            fewview_scene::SceneError::Io(e) => Self::Io(e),
            fewview_scene::SceneError::Format { path, message } => Self::Format { path, message },
            fewview_scene::SceneError::Invalid { path, message } => Self::Invalid {
                what: path.display().to_string(),
                message,
            },
        }
    }
}

pub type Result<T, E = GeomError> = std::result::Result<T, E>;
