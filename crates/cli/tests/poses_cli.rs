//! `fewview poses`: bad folders are one-line errors with nothing written; with `FEWVIEW_DATA`,
//! fern's three training photos register, and `train` on the folder of photos estimates the
//! poses first.

mod common;

use std::path::{Path, PathBuf};

use common::{assert_clean_error, fewview, fewview_ok, s};
use fewview_scene::Image;

/// A 160 × 120 photo of seeded noise (nothing in it matches another seed's).
fn noise_photo(path: &Path, seed: u32) {
    let mut state = seed.wrapping_mul(2_654_435_761).max(1);
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        (state % 1000) as f32 / 1000.0
    };
    let data: Vec<f32> = (0..160 * 120 * 3).map(|_| next()).collect();
    Image::from_vec(160, 120, 3, data).save_png(path).unwrap();
}

fn poses(images: &Path, out: &Path) -> std::process::Output {
    fewview(&["poses", "--images", s(images), "--out", s(out)])
}

#[test]
fn one_photo_is_an_error_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let images = dir.path().join("images");
    std::fs::create_dir(&images).unwrap();
    noise_photo(&images.join("a.png"), 1);
    let out = dir.path().join("out");
    assert_clean_error(&poses(&images, &out), &["1 photo", "at least two"]);
    assert!(!out.exists());
}

#[test]
fn photos_that_share_nothing_are_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let images = dir.path().join("images");
    std::fs::create_dir(&images).unwrap();
    for seed in 1..=3 {
        noise_photo(&images.join(format!("{seed}.png")), seed);
    }
    let out = dir.path().join("out");
    assert_clean_error(&poses(&images, &out), &["no two of the 3 photos"]);
    assert!(!out.exists());
}

#[test]
fn a_corrupt_photo_and_an_empty_folder_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let images = dir.path().join("images");
    std::fs::create_dir(&images).unwrap();
    let out = dir.path().join("out");
    assert_clean_error(&poses(&images, &out), &["images", "no .jpg"]);
    noise_photo(&images.join("a.png"), 1);
    std::fs::write(images.join("b.jpg"), b"\xff\xd8\xff\xe0 truncated").unwrap();
    assert_clean_error(&poses(&images, &out), &["b.jpg"]);
    assert!(!out.exists());
}

fn fern_photos(dir: &Path) -> PathBuf {
    let data = std::env::var_os("FEWVIEW_DATA")
        .expect("FEWVIEW_DATA must name the shared data folder (e.g. ../shared/data)");
    let source = PathBuf::from(data).join("llff/fern/images_8");
    let images = dir.join("fern3");
    std::fs::create_dir(&images).unwrap();
    for name in ["image001.png", "image010.png", "image019.png"] {
        std::fs::copy(source.join(name), images.join(name)).unwrap();
    }
    images
}

/// Three fern photos register; the output is a COLMAP model and a folder `train` reads.
#[test]
#[ignore = "needs FEWVIEW_DATA"]
fn fern_photos_register_and_train() {
    let dir = tempfile::tempdir().unwrap();
    let images = fern_photos(dir.path());
    let out = dir.path().join("model");
    let run = fewview_ok(&["poses", "--images", s(&images), "--out", s(&out)]);
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(stdout.contains("registered 3 of 3 photos"), "{stdout}");
    let model = fewview_scene::colmap::read_model(&out.join("sparse/0")).unwrap();
    assert_eq!(model.images.len(), 3);
    assert!(model.points.len() > 500, "{} points", model.points.len());
    // `train` on the folder of photos itself estimates the poses first, into the run.
    let train = dir.path().join("train");
    let run = fewview_ok(&[
        "train",
        "--data",
        s(&images),
        "--iterations",
        "10",
        "--out",
        s(&train),
    ]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(stderr.contains("holds only photos"), "{stderr}");
    assert!(train.join("poses/sparse/0/images.txt").exists());
    assert!(train.join("point_cloud.ply").exists());
}
