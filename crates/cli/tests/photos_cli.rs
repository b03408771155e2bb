//! A few photos of a scene, handed over as a person would: JPEG files with an EXIF focal length
//! and no poses. `fusion --data` estimates the poses, starts from stereo, trains on every photo,
//! scores by leave-one-out and writes the transition.

mod common;

use std::path::Path;

use common::{fewview_ok, s};
use fewview_scene::synthetic::{DemoOptions, demo_dataset};
use fewview_sfm::photos::{focal_35mm, save_photo_jpeg};

/// The demo's three training views as JPEG photos in `dir`, with their focal in EXIF; the
/// last one `last_width` pixels wide (the same field of view).
fn demo_photos(dir: &Path, last_width: usize) {
    let opts = DemoOptions {
        width: 200,
        height: 150,
        ..DemoOptions::default()
    };
    let ds = demo_dataset(&opts);
    std::fs::create_dir_all(dir).unwrap();
    let n = ds.train.len();
    for (k, view) in ds.train_views().enumerate() {
        let f35 = focal_35mm(view.camera.intrinsics.fx, 200, 150);
        let image = if k + 1 == n {
            view.image.resize(last_width, last_width * 3 / 4)
        } else {
            view.image.clone()
        };
        save_photo_jpeg(&image, Some(f35), &dir.join(format!("{k}.jpg"))).unwrap();
    }
}

#[test]
fn demo_photos_without_poses_run_fusion_end_to_end() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    demo_photos(&photos, 200);
    std::fs::write(photos.join("notes.txt"), "taken at noon").unwrap();
    let out = dir.path().join("run");
    let run = fewview_ok(&[
        "fusion",
        "--data",
        s(&photos),
        "--iterations",
        "40",
        "--out",
        s(&out),
    ]);
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(stderr.contains("holds only photos"), "{stderr}");
    assert!(
        stderr.contains("notes.txt: skipped, not a photo"),
        "{stderr}"
    );
    // The poses step's dataset carries its points and bounds.
    let transforms: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("poses/transforms.json")).unwrap()).unwrap();
    assert_eq!(transforms["ply_file_path"], "sparse_pc.ply");
    for frame in transforms["frames"].as_array().unwrap() {
        let [near, far] = [0, 1].map(|i| frame["depth_bounds"][i].as_f64().unwrap());
        assert!(0.0 < near && near < far, "{frame}");
        // The demo's focal is 0.9 of the width; EXIF carries it rounded to a whole 35 mm
        // focal length, and the bundle keeps it near there.
        let focal = frame["fl_x"].as_f64().unwrap();
        assert!(
            (focal / 180.0 - 1.0).abs() < 0.02,
            "focal {focal} px, truth 180"
        );
    }
    // Every photo trains, the start is stereo, the middle photo is scored left out.
    let metrics: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["init"], "stereo", "{metrics}");
    assert_eq!(metrics["test"]["views"].as_array().unwrap().len(), 0);
    let left_out = &metrics["leave_one_out"];
    assert_eq!(left_out["views"].as_array().unwrap().len(), 1, "{metrics}");
    assert_eq!(left_out["views"][0]["view"], "1");
    // 40 iterations on two photos 60° apart leave floaters: the score is a smoke check (raw
    // PSNR about 9 dB; it passed 12 only while the poses' focal was 22 % long).
    let psnr = left_out["mean_gain_matched_psnr"].as_f64().unwrap();
    assert!(psnr > 12.0, "leave-one-out PSNR, gain-matched {psnr}");
    assert!(left_out["mean_lpips"].as_f64().is_some());
    assert!(stdout.contains("leave-one-out"), "{stdout}");
    let transition: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("transition.json")).unwrap()).unwrap();
    assert_eq!(transition["leave_one_out"], *left_out);
    for file in [
        "transition.mp4",
        "midpath.jpg",
        "init/stereo.json",
        "leave_one_out/1/point_cloud.ply",
    ] {
        assert!(out.join(file).is_file(), "{file}");
    }
    let midpath = fewview_scene::Image::load(&out.join("midpath.jpg")).unwrap();
    assert_eq!((midpath.width, midpath.height), (2 * 200, 150));
}

/// Photos of different sizes (one larger than the others) run through as well: each keeps its
/// own intrinsics.
#[test]
fn photos_of_different_sizes_run_through() {
    let dir = tempfile::tempdir().unwrap();
    let photos = dir.path().join("photos");
    demo_photos(&photos, 240);
    let out = dir.path().join("run");
    fewview_ok(&[
        "fusion",
        "--data",
        s(&photos),
        "--iterations",
        "20",
        "--eval",
        "held-out",
        "--test-views",
        "1",
        "--out",
        s(&out),
    ]);
    let transforms: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("poses/transforms.json")).unwrap()).unwrap();
    let widths: Vec<u64> = transforms["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["w"].as_u64().unwrap())
        .collect();
    assert_eq!(widths, [200, 200, 240]);
    let metrics: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(metrics["test"]["views"][0]["name"], "1");
    assert!(out.join("transition.mp4").is_file());
}
