//! Errors of the study crate: one line each, naming the input and the problem. As in the other
//! crates, a cause is part of the message and not also returned from `source()`, so a printer
//! that walks the chain (anyhow's `{:#}`) says it once.

use std::path::PathBuf;

/// An error while configuring, serving, storing or analysing a study.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    /// Input that is well-formed but unusable (too few answers, a bad setting, ...).
    #[error("invalid input: {0}")]
    Invalid(String),
    /// A file could not be opened, read or written.
    #[error(transparent)]
    Io(fewview_scene::FileIoError),
    /// A file was read but its contents are not what the format requires (a responses CSV, a
    /// `study.toml`).
    #[error("{}: {message}", path.display())]
    Format { path: PathBuf, message: String },
    /// The study's SQLite database could not be opened or set up.
    #[error("{}: {what}: {error}", path.display())]
    Database {
        path: PathBuf,
        what: &'static str,
        error: rusqlite::Error,
    },
    /// The web server could not start or stopped with an error.
    #[error("{0}")]
    Server(String),
    /// An output (PNG, CSV) could not be written.
    #[error(transparent)]
    Scene(#[from] fewview_scene::SceneError),
}

impl StudyError {
    pub fn invalid(message: impl Into<String>) -> Self {
        Self::Invalid(message.into())
    }
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

pub type Result<T, E = StudyError> = std::result::Result<T, E>;
