//! Atomic file writes: write a temporary file beside the target, then rename it into place, so
//! an interrupted run never leaves a half-written output.

use std::io::{BufWriter, Write};
use std::path::Path;

use crate::error::{Result, SceneError};

/// Name prefix of the temporary files [`write_with`] writes beside its target. A run killed
/// mid-write (SIGINT during a checkpoint) leaves one behind; [`remove_partial_files`] sweeps
/// them when a run starts again in that folder.
pub const PARTIAL_PREFIX: &str = ".fewview-partial-";

/// Writes `path` through `fill`, atomically: into a temporary `PARTIAL_PREFIX…` file beside
/// it, renamed over `path` once complete.
pub fn write_with<F>(path: &Path, fill: F) -> Result<()>
where
    F: FnOnce(&mut BufWriter<&mut std::fs::File>) -> std::io::Result<()>,
{
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let mut tmp = tempfile::Builder::new()
        .prefix(PARTIAL_PREFIX)
        .tempfile_in(dir)
        .map_err(|e| SceneError::io(path, e))?;
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

/// Removes the partial files ([`PARTIAL_PREFIX`]) an interrupted [`write_with`] left directly
/// in `dir` (not in its subfolders) and returns how many. A missing folder has none. Call it
/// only where no other process writes at the same time (a run folder when its run starts).
pub fn remove_partial_files(dir: &Path) -> Result<usize> {
    let entries = match std::fs::read_dir(dir) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(0),
        Err(e) => return Err(SceneError::io(dir, e)),
    };
    let mut removed = 0;
    for entry in entries {
        let entry = entry.map_err(|e| SceneError::io(dir, e))?;
        let partial = entry
            .file_name()
            .to_str()
            .is_some_and(|n| n.starts_with(PARTIAL_PREFIX));
        let is_file = entry.file_type().is_ok_and(|t| t.is_file());
        if partial && is_file {
            let path = entry.path();
            std::fs::remove_file(&path).map_err(|e| SceneError::io(&path, e))?;
            removed += 1;
        }
    }
    Ok(removed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn partial_files_are_recognisable_and_swept() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("checkpoint.bin");
        // A write that fails part-way leaves nothing (the temporary file is dropped).
        let err = write_with(&target, |w| {
            w.write_all(b"half")?;
            Err(std::io::Error::other("interrupted"))
        });
        assert!(err.is_err());
        assert!(!target.exists());
        // What a killed process leaves: a file with the prefix, swept; others are kept.
        let left = dir.path().join(format!("{PARTIAL_PREFIX}abc123"));
        std::fs::write(&left, b"half").unwrap();
        std::fs::create_dir(dir.path().join(format!("{PARTIAL_PREFIX}dir"))).unwrap();
        write_bytes(&target, b"whole").unwrap();
        assert_eq!(remove_partial_files(dir.path()).unwrap(), 1);
        assert!(!left.exists());
        assert_eq!(std::fs::read(&target).unwrap(), b"whole");
        assert!(dir.path().join(format!("{PARTIAL_PREFIX}dir")).is_dir());
        assert_eq!(
            remove_partial_files(&dir.path().join("missing")).unwrap(),
            0
        );
    }

    #[test]
    fn temporary_files_carry_the_prefix() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.bin");
        write_with(&target, |w| {
            let names: Vec<String> = std::fs::read_dir(dir.path())
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            assert_eq!(names.len(), 1, "{names:?}");
            assert!(names[0].starts_with(PARTIAL_PREFIX), "{names:?}");
            w.write_all(b"x")
        })
        .unwrap();
    }
}
