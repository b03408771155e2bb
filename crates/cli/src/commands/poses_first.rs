//! `train --data DIR` and `fusion --data DIR` on a folder that holds only photos: the poses
//! are estimated first (as `fewview poses`) into the run's `poses/` folder, which then is the
//! dataset; a finished one is reused.

use std::path::{Path, PathBuf};

use fewview_sfm::folder::{has_model, holds_only_photos};
use fewview_sfm::photos::DEFAULT_FOV_DEG;
use fewview_sfm::{FolderOptions, poses_for_folder};

/// The folder to load as the dataset: `data` itself, or `run/poses` when `data` holds only
/// photos (estimated now, or by an earlier invocation of the same run).
pub fn dataset_folder(data: &Path, run: &Path) -> anyhow::Result<PathBuf> {
    if !holds_only_photos(data) {
        return Ok(data.to_path_buf());
    }
    let dir = run.join("poses");
    if has_model(&dir) {
        eprintln!(
            "{} holds only photos: using the poses estimated earlier in {}",
            data.display(),
            dir.display()
        );
        return Ok(dir);
    }
    eprintln!(
        "{} holds only photos: estimating their poses first into {} (as `fewview poses`)",
        data.display(),
        dir.display()
    );
    let model = super::poses::with_progress(|on| {
        poses_for_folder(data, &dir, &FolderOptions::default(), on)
    })?;
    super::poses::print_model(&model, DEFAULT_FOV_DEG);
    Ok(dir)
}
