//! Atomic file writes: write a temporary file beside the target, then rename it into place, so
//! an interrupted run never leaves a half-written output.

use std::io::{BufWriter, Write};
use std::path::Path;

use crate::error::{Result, SceneError};

/// Writes `path` through `fill`, atomically.
pub fn write_with<F>(path: &Path, fill: F) -> Result<()>
where
    F: FnOnce(&mut BufWriter<&mut std::fs::File>) -> std::io::Result<()>,
{
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(|e| SceneError::io(path, e))?;
    // Temporary files are created private (0600); outputs should be readable like any file.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        tmp.as_file()
            .set_permissions(std::fs::Permissions::from_mode(0o644))
            .map_err(|e| SceneError::io(path, e))?;
    }
    {
        let file = tmp.as_file_mut();
        let mut w = BufWriter::new(file);
        fill(&mut w).map_err(|e| SceneError::io(path, e))?;
        w.flush().map_err(|e| SceneError::io(path, e))?;
    }
    tmp.persist(path)
        .map_err(|e| SceneError::io(path, e.error))?;
    Ok(())
}

/// Writes bytes to `path` atomically.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    write_with(path, |w| w.write_all(bytes))
}
