//! Errors of scene loading: each names the file and the problem in one line.
//!
//! The project's errors carry their cause in their own message and do not also return it from
//! `source()`, so a printer that walks the chain (anyhow's `{:#}`) says each cause once.

use std::path::PathBuf;

/// A file that could not be opened, read or written: its path and the I/O error, in one line
/// (`path: error`). Every crate's error enum holds this as its `Io` variant.
#[derive(Debug, thiserror::Error)]
#[error("{}: {error}", path.display())]
pub struct FileIoError {
    pub path: PathBuf,
    /// In the message, not returned from `source()`.
    pub error: std::io::Error,
}

impl FileIoError {
    pub fn new(path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        Self {
            path: path.into(),
            error,
        }
    }
}

/// An error while reading or validating scene input.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// A file could not be opened or read.
    #[error(transparent)]
    Io(FileIoError),
    /// A file was read but its contents are not what the format requires.
    #[error("{path}: {message}")]
    Format { path: PathBuf, message: String },
    /// Input that is well-formed but unusable (NaN, size mismatch, index out of range, ...).
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
}

impl SceneError {
    pub fn io(path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        Self::Io(FileIoError::new(path, error))
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

#[cfg(test)]
mod tests {
    use std::error::Error;

    use super::SceneError;

    #[test]
    fn an_io_error_names_the_file_and_the_cause_once() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "no such dataset folder");
        let err = SceneError::io("/nope", io);
        assert_eq!(err.to_string(), "/nope: no such dataset folder");
        assert!(
            err.source().is_none(),
            "the cause is in the message already"
        );
    }
}
