//! Errors of pose estimation: one line naming the file or the photos and the problem.

use std::path::{Path, PathBuf};

/// Why poses could not be estimated.
#[derive(Debug, thiserror::Error)]
pub enum SfmError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// A file that cannot be used as it is.
    #[error("{}: {message}", path.display())]
    Input { path: PathBuf, message: String },
    /// A photo that cannot be read, or an output that cannot be written (the message names
    /// the file).
    #[error(transparent)]
    Scene(#[from] fewview_scene::SceneError),
    /// A learned matcher's weights that exist but cannot be loaded (the message names the file).
    #[error("{0}")]
    Matcher(String),
    /// The photos do not give a model (too few, or nothing shared).
    #[error("{0}")]
    NoModel(String),
}

impl SfmError {
    pub fn io(path: &Path, source: std::io::Error) -> Self {
        Self::Io {
            path: path.to_path_buf(),
            source,
        }
    }

    pub fn input(path: &Path, message: impl Into<String>) -> Self {
        Self::Input {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }
}

pub type Result<T> = std::result::Result<T, SfmError>;
