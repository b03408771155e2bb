//! Errors of the matching crate: one line each, naming the input and the problem.

use std::path::PathBuf;

/// An error while loading a matcher or matching images.
#[derive(Debug, thiserror::Error)]
pub enum MatchError {
    /// Input that is well-formed but unusable (too small, empty, NaN, ...).
    #[error("invalid input: {0}")]
    Invalid(String),
    /// A weight file was read but is not what the network needs (missing tensor, wrong shape).
    #[error("{path}: {message}")]
    Weights { path: PathBuf, message: String },
}

impl MatchError {
    pub fn invalid(message: impl Into<String>) -> Self {
        Self::Invalid(message.into())
    }
    pub fn weights(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self::Weights {
            path: path.into(),
            message: message.into(),
        }
    }
}

pub type Result<T, E = MatchError> = std::result::Result<T, E>;
