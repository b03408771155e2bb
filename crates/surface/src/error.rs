//! Errors of the surface pipeline: one line naming the input and the problem.

use std::path::PathBuf;

/// Result with [`SurfaceError`].
pub type Result<T> = std::result::Result<T, SurfaceError>;

#[derive(Debug, thiserror::Error)]
pub enum SurfaceError {
    /// A configuration or argument that cannot work.
    #[error("{what}: {message}")]
    Invalid { what: String, message: String },
    /// A file that cannot be read or written.
    #[error(transparent)]
    Io(fewview_scene::FileIoError),
    /// A file whose contents are not what they should be.
    #[error("{}: {message}", path.display())]
    Format { path: PathBuf, message: String },
    /// An error of the scene crate (datasets, images).
    #[error(transparent)]
    Scene(#[from] fewview_scene::SceneError),
    /// An error of the geometry crate (meshes, registration).
    #[error(transparent)]
    Geom(#[from] fewview_geom::GeomError),
    /// A tensor whose values could not be read back to the host (a defect, not bad input).
    #[error(transparent)]
    Readback(#[from] fewview_optim::ReadbackError),
    /// An input that could not be loaded: `what` says which, `source` why.
    #[error("{what}")]
    Input {
        what: String,
        #[source]
        source: Box<SurfaceError>,
    },
    /// Training diverged (NaN loss or parameters).
    #[error("training diverged at iteration {iteration}: {message}")]
    Diverged { iteration: usize, message: String },
}

impl SurfaceError {
    pub fn invalid(what: impl Into<String>, message: impl Into<String>) -> Self {
        Self::Invalid {
            what: what.into(),
            message: message.into(),
        }
    }

    pub fn io(path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        Self::Io(fewview_scene::FileIoError::new(path, error))
    }

    pub fn input(what: impl Into<String>, source: SurfaceError) -> Self {
        Self::Input {
            what: what.into(),
            source: Box::new(source),
        }
    }

    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self::Format {
            path: path.into(),
            message: message.into(),
        }
    }
}
