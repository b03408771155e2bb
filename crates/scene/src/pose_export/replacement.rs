//! What every writer of refined poses shares: where the dataset came from, the poses that
//! replace its entries, and the name of a refined file.

use std::path::{Path, PathBuf};

use crate::camera::Se3;
use crate::load::LoadOptions;

/// Where a dataset was read from: its folder and the options it was loaded with (the format, the
/// DTU camera file).
#[derive(Clone, Copy, Debug)]
pub struct PoseSource<'a> {
    pub root: &'a Path,
    pub options: &'a LoadOptions,
}

/// One view's new pose, in the source file's world frame.
#[derive(Clone, Debug)]
pub(super) struct Replacement {
    /// Index into the dataset's views.
    pub(super) view: usize,
    /// The view's entry in the camera file ([`crate::View::source_index`]).
    pub(super) entry: usize,
    pub(super) world_to_camera: Se3,
}

/// `out_dir/<file stem>_refined.<extension>` for an input file.
pub(super) fn refined_name(input: &Path, out_dir: &Path) -> PathBuf {
    let stem = input
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = match input.extension() {
        Some(ext) => format!("{stem}_refined.{}", ext.to_string_lossy()),
        None => format!("{stem}_refined"),
    };
    out_dir.join(name)
}
