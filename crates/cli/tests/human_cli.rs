//! `fewview human`: bad inputs fail with one line naming the file, before anything is written.

mod common;

use std::path::{Path, PathBuf};

use common::{assert_clean_error, fewview, s};

fn data_root() -> PathBuf {
    PathBuf::from(std::env::var("FEWVIEW_DATA").expect("set FEWVIEW_DATA to the data folder"))
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}

/// A capture with one mask missing is refused when opened: one line naming the file, and no
/// output folder.
#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn human_train_refuses_a_capture_with_a_missing_mask() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("human");
    copy_dir(&data_root().join("human"), &data);
    std::fs::remove_file(data.join("seq_a/masks/cam_03/frame_0010.png")).unwrap();
    let out = dir.path().join("run");
    let result = fewview(&[
        "human",
        "train",
        "--data",
        s(&data),
        "--out",
        s(&out),
        "--iterations",
        "1",
    ]);
    assert_clean_error(&result, &["cam_03/frame_0010.png", "missing"]);
    assert!(!out.exists(), "an output folder was written");
}

/// A folder that holds no run is refused by `human eval` before anything is written.
#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn human_eval_refuses_a_folder_without_a_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("eval");
    let data = data_root().join("human");
    let result = fewview(&[
        "human",
        "eval",
        "--run",
        s(dir.path()),
        "--data",
        s(&data),
        "--out",
        s(&out),
    ]);
    assert_clean_error(&result, &["state.bin"]);
    assert!(!out.exists(), "an output folder was written");
}
