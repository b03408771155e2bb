//! `fewview benchmark`'s refusals: each is one line and leaves nothing written. The scenes are
//! made from the shared datasets (`FEWVIEW_DATA`) by linking their files.

mod common;

use std::path::{Path, PathBuf};

use common::{assert_clean_error, fewview, s};

fn data_dir() -> PathBuf {
    PathBuf::from(
        std::env::var_os("FEWVIEW_DATA")
            .expect("FEWVIEW_DATA must name the shared data folder (e.g. ../shared/data)"),
    )
}

/// Links `names` of `from` into `to` (made first).
fn link(from: &Path, to: &Path, names: &[&str]) {
    std::fs::create_dir_all(to).unwrap();
    for n in names {
        std::os::unix::fs::symlink(from.join(n), to.join(n)).unwrap();
    }
}

fn benchmark(protocol: &str, scene: &Path, out: &Path) -> std::process::Output {
    fewview(&[
        "benchmark",
        "--protocol",
        protocol,
        "--data",
        s(scene),
        "--out",
        s(out),
        "--iterations",
        "1",
    ])
}

#[test]
fn an_unknown_protocol_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let run = benchmark("tanks", dir.path(), &out);
    assert_clean_error(&run, &["tanks", "--protocol"]);
    assert!(!out.exists());
}

#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn dtu_without_masks_is_refused_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scan65");
    link(
        &data_dir().join("dtu/scan65"),
        &scene,
        &["image", "cameras_sphere.npz"],
    );
    let out = dir.path().join("out");
    let run = benchmark("dtu", &scene, &out);
    assert_clean_error(&run, &["scan65", "mask"]);
    assert!(!out.exists());
}

#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn a_scene_missing_a_view_or_of_another_format_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let fern = data_dir().join("llff/fern");
    let scene = dir.path().join("fern");
    link(&fern, &scene, &["poses_bounds.npy"]);
    let mut images: Vec<_> = std::fs::read_dir(fern.join("images_8"))
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    images.sort();
    // Image 10 is one of the protocol's three training views.
    images.remove(10);
    let names: Vec<String> = images
        .iter()
        .map(|n| n.to_string_lossy().into_owned())
        .collect();
    let names: Vec<&str> = names.iter().map(String::as_str).collect();
    link(&fern.join("images_8"), &scene.join("images_8"), &names);
    let out = dir.path().join("out");
    assert_clean_error(&benchmark("llff", &scene, &out), &["fern"]);
    assert!(!out.exists());
    assert_clean_error(&benchmark("blender", &fern, &out), &["fern", "blender"]);
    assert!(!out.exists());
}
