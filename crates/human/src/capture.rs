//! Opening a capture folder whatever its layout: the synthetic one ([`HumanDataset`]) or
//! ZJU-MoCap's ([`ZjuDataset`]), told apart by ZJU-MoCap's `annots.npy`.

use std::path::Path;

use crate::dataset::HumanDataset;
use crate::error::{HumanError, Result};
use crate::source::MultiView;
use crate::zju::ZjuDataset;

/// A capture's file layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// `cameras.json`, `joints.json` and one folder per sequence (`$FEWVIEW_DATA/human`).
    Synthetic,
    /// `annots.npy`, `Camera_B*/`, `mask/` (ZJU-MoCap); a sequence is a subfolder
    /// (`CoreView_313`) or the folder itself.
    Zju,
}

/// Opens `sequence` of the capture in `root`. A folder holding `annots.npy` (either `root`
/// itself or `root/sequence`) is read as ZJU-MoCap; anything else as the synthetic layout.
pub fn open(root: &Path, sequence: &str) -> Result<(Layout, Box<dyn MultiView>)> {
    if !root.is_dir() {
        return Err(HumanError::invalid(root, "not a folder"));
    }
    for folder in [root.join(sequence), root.to_path_buf()] {
        if folder.join("annots.npy").is_file() {
            return Ok((Layout::Zju, Box::new(ZjuDataset::open(&folder)?)));
        }
    }
    let data = HumanDataset::open(root, sequence)?;
    Ok((Layout::Synthetic, Box::new(data)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fixture() -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures")
    }

    #[test]
    fn zju_folders_are_recognised_directly_or_as_a_sequence() {
        let (layout, data) = open(&fixture().join("zju_small"), "seq_a").unwrap();
        assert_eq!(layout, Layout::Zju);
        assert_eq!(data.cameras().len(), 4);
        let (layout, data) = open(&fixture(), "zju_small").unwrap();
        assert_eq!(layout, Layout::Zju);
        assert_eq!(data.frame_count(), 3);
        assert_eq!(data.joint_parents().unwrap().len(), 17);
    }

    #[test]
    fn a_missing_folder_is_named() {
        let path = fixture().join("no_such_capture");
        let err = open(&path, "seq_a").err().unwrap().to_string();
        assert!(
            err.contains("no_such_capture") && err.contains("not a folder"),
            "{err}"
        );
    }
}
