//! Errors of the metrics crate: one line each, naming the input and the problem.

use std::path::PathBuf;

/// An error while computing a metric or reading its inputs.
#[derive(Debug, thiserror::Error)]
pub enum MetricsError {
    /// Two inputs that must have the same shape do not.
    #[error("size mismatch: {0}")]
    ShapeMismatch(String),
    /// Input that is well-formed but unusable (NaN, too small, empty, out of range, ...).
    #[error("invalid input: {0}")]
    Invalid(String),
    /// A file could not be opened, read or written.
    #[error(transparent)]
    Io(fewview_scene::FileIoError),
    /// A file was read but its contents are not what the format requires.
    #[error("{path}: {message}")]
    Format { path: PathBuf, message: String },
    /// An image or other scene input could not be loaded.
    #[error(transparent)]
    Scene(#[from] fewview_scene::SceneError),
}

impl MetricsError {
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

pub type Result<T, E = MetricsError> = std::result::Result<T, E>;

/// Checks that two images have the same width, height and channel count.
pub(crate) fn check_same_shape(a: &fewview_scene::Image, b: &fewview_scene::Image) -> Result<()> {
    if (a.width, a.height, a.channels) != (b.width, b.height, b.channels) {
        return Err(MetricsError::ShapeMismatch(format!(
            "{}x{}x{} vs {}x{}x{}",
            a.width, a.height, a.channels, b.width, b.height, b.channels
        )));
    }
    if a.data.len() != a.width * a.height * a.channels
        || b.data.len() != b.width * b.height * b.channels
    {
        return Err(MetricsError::invalid(
            "image buffer length does not match its size",
        ));
    }
    Ok(())
}

/// Checks that a mask is a single-channel image of the given size.
pub(crate) fn check_mask(mask: &fewview_scene::Image, width: usize, height: usize) -> Result<()> {
    if mask.channels != 1 || mask.width != width || mask.height != height {
        return Err(MetricsError::ShapeMismatch(format!(
            "mask is {}x{}x{}, expected {}x{}x1",
            mask.width, mask.height, mask.channels, width, height
        )));
    }
    Ok(())
}
