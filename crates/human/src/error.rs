//! Errors of the human crate: each is one line naming the file (or the argument) and the problem,
//! so a person can act on it. Library code never panics on bad input; it returns these.

use std::path::{Path, PathBuf};

use fewview_geom::GeomError;
use fewview_scene::SceneError;

/// An error while reading a capture, splitting it or carving its visual hull.
#[derive(Debug, thiserror::Error)]
pub enum HumanError {
    /// A file could not be opened or read.
    #[error(transparent)]
    Io(fewview_scene::FileIoError),
    /// A file was read but its contents do not follow the format.
    #[error("{path}: {message}")]
    Format { path: PathBuf, message: String },
    /// Well-formed input that cannot be used: a missing file, a size or count mismatch, a joint
    /// outside its image, an index out of range.
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    /// An argument (not a file) that cannot be used; `what` names it.
    #[error("{what}: {message}")]
    Argument { what: String, message: String },
    /// Data a [`crate::split::TrainingView`] refuses to open; `what` names the camera and frame.
    #[error(
        "{dataset}: {what} is outside the training split (input cameras {cameras}, training frames {frames})"
    )]
    OutsideTraining {
        dataset: PathBuf,
        what: String,
        cameras: String,
        frames: String,
    },
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Geom(#[from] GeomError),
}

impl HumanError {
    pub fn io(path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        Self::Io(fewview_scene::FileIoError::new(path, error))
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
    pub fn argument(what: impl Into<String>, message: impl Into<String>) -> Self {
        Self::Argument {
            what: what.into(),
            message: message.into(),
        }
    }
}

/// An error for a required file that is not there.
pub(crate) fn missing(path: &Path, why: &str) -> HumanError {
    HumanError::invalid(path, format!("missing ({why})"))
}

pub type Result<T, E = HumanError> = std::result::Result<T, E>;
