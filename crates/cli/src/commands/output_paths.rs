//! Checks of output paths, made before a command reads or computes anything: a report whose
//! folder is missing used to fail only after the main output was written (or after a long
//! computation), leaving a half-finished result behind. Each error names the flag and the path.

use std::path::Path;

use anyhow::{Result, bail};

/// The folder `path` goes into (`.` for a bare file name).
fn parent(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// `path` can be written as a file: it is not a folder, and the folder it goes into exists.
pub fn check_file(path: &Path, flag: &str) -> Result<()> {
    if path.is_dir() {
        bail!(
            "{flag} {}: is a folder, expected a file name",
            path.display()
        );
    }
    let dir = parent(path);
    if !dir.is_dir() {
        if dir.exists() {
            bail!(
                "{flag} {}: {} is not a folder",
                path.display(),
                dir.display()
            );
        }
        bail!(
            "{flag} {}: the folder {} does not exist",
            path.display(),
            dir.display()
        );
    }
    Ok(())
}

/// [`check_file`] for an optional output.
pub fn check_optional_file(path: Option<&Path>, flag: &str) -> Result<()> {
    path.map_or(Ok(()), |p| check_file(p, flag))
}

/// `path` can be an output folder, created with its parents: it is not an existing file, and
/// no file stands where one of its parent folders would go.
pub fn check_folder(path: &Path, flag: &str) -> Result<()> {
    for p in path.ancestors().filter(|p| !p.as_os_str().is_empty()) {
        if p.exists() && !p.is_dir() {
            if p == path {
                bail!("{flag} {}: is a file, expected a folder", path.display());
            }
            bail!("{flag} {}: {} is not a folder", path.display(), p.display());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_need_an_existing_folder_and_folders_no_file_in_the_way() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        std::fs::write(root.join("f"), b"x").unwrap();
        assert!(check_file(&root.join("a.json"), "--json").is_ok());
        assert!(check_file(&root.join("f"), "--json").is_ok());
        let err = check_file(&root.join("nodir/a.json"), "--json").unwrap_err();
        assert!(err.to_string().starts_with("--json "), "{err}");
        assert!(err.to_string().contains("does not exist"), "{err}");
        let err = check_file(root, "--json").unwrap_err().to_string();
        assert!(err.contains("is a folder"), "{err}");
        let err = check_file(&root.join("f/a.json"), "--json")
            .unwrap_err()
            .to_string();
        assert!(err.contains("is not a folder"), "{err}");
        assert!(check_file(Path::new("bare.json"), "--json").is_ok());

        assert!(check_folder(&root.join("new/deeper"), "--out").is_ok());
        assert!(check_folder(root, "--out").is_ok());
        let err = check_folder(&root.join("f"), "--out")
            .unwrap_err()
            .to_string();
        assert!(err.contains("is a file"), "{err}");
        let err = check_folder(&root.join("f/sub"), "--out")
            .unwrap_err()
            .to_string();
        assert!(err.contains("is not a folder"), "{err}");
    }
}
