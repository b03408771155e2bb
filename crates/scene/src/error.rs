//! Errors of scene loading: each names the file and the problem in one line.

use std::path::PathBuf;

/// An error while reading or validating scene input.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// A file could not be opened or read.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A file was read but its contents are not what the format requires.
    #[error("{path}: {message}")]
    Format { path: PathBuf, message: String },
    /// Input that is well-formed but unusable (NaN, size mismatch, index out of range, ...).
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
}

impl SceneError {
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }
    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self::Format {
            path: path.into(),
            message: message.into(),
        }
    }
    pub fn invalid(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self::Invalid {
            path: path.into(),
            message: message.into(),
        }
    }
}

pub type Result<T, E = SceneError> = std::result::Result<T, E>;
