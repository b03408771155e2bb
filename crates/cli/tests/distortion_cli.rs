//! Real-capture input through the binary: a demo capture with lens distortion written by
//! `demo --write-capture`, frames whose photos are missing (skipped with one warning), and bad
//! lenses and camera models (one-line errors, nothing written).

use std::path::Path;

mod common;
use common::{assert_clean_error, fewview, fewview_ok, s};

/// A 32×24 demo capture with the default phone-like lens.
fn capture(dir: &Path) {
    fewview_ok(&["demo", "--width", "32", "--write-capture", s(dir)]);
}

fn edit_json(path: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let mut doc: serde_json::Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    edit(&mut doc);
    std::fs::write(path, doc.to_string()).unwrap();
}

fn train(data: &Path, run: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec![
        "train",
        "--data",
        s(data),
        "--iterations",
        "2",
        "--init",
        "box",
        "--checkpoint-every",
        "0",
        "--out",
        s(run),
    ];
    args.extend_from_slice(extra);
    fewview(&args)
}

#[test]
fn missing_frames_are_skipped_with_one_warning() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("capture");
    capture(&data);
    for i in [5, 17] {
        std::fs::remove_file(data.join(format!("images/view_{i:02}.png"))).unwrap();
    }
    let out = train(&data, &dir.path().join("run"), &[]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let warnings: Vec<&str> = err.lines().filter(|l| l.starts_with("warning")).collect();
    assert_eq!(warnings.len(), 1, "{err}");
    assert!(warnings[0].contains("skipped 2 of 24 frames"), "{err}");
    assert!(
        err.contains("undistorted 22 photos (0 from the cache)"),
        "{err}"
    );
    // The undistorted camera, in the form `demo --capture-intrinsics` takes: COLMAP's framing
    // scales the principal point with the size (the capture's is the 32×24 image's centre).
    let camera = err
        .split(" to the pinhole ")
        .nth(1)
        .expect("camera printed");
    let k: Vec<f64> = camera
        .lines()
        .next()
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    let config: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("run/config.json")).unwrap())
            .unwrap();
    assert_eq!(
        [k[4], k[5]],
        [
            config["width"].as_f64().unwrap(),
            config["height"].as_f64().unwrap()
        ]
    );
    assert!(
        (k[2] - 16.0 * k[4] / 32.0).abs() < 1e-9 && (k[3] - 12.0 * k[5] / 24.0).abs() < 1e-9,
        "{k:?}"
    );
    // The second load reads every undistorted photo from the dataset's cache.
    let out = train(&data, &dir.path().join("run2"), &[]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("undistorted 22 photos (22 from the cache)"),
        "{err}"
    );
    // Bicubic resampling has cache entries of its own.
    for (run, cached) in [("run-cubic", 0), ("run-cubic2", 22)] {
        let out = train(&data, &dir.path().join(run), &["--resample", "bicubic"]);
        let err = String::from_utf8_lossy(&out.stderr);
        let want = format!("undistorted 22 photos ({cached} from the cache)");
        assert!(err.contains(&want), "{err}");
    }
    let out = train(&data, &dir.path().join("run4"), &["--resample", "lanczos"]);
    assert_clean_error(&out, &["--resample", "expected bilinear or bicubic"]);
    // No photo left: an error.
    for entry in std::fs::read_dir(data.join("images")).unwrap() {
        std::fs::remove_file(entry.unwrap().path()).unwrap();
    }
    let run = dir.path().join("run3");
    let out = train(&data, &run, &[]);
    assert_clean_error(
        &out,
        &[
            "transforms.json",
            "none of the 24 frames has its image file",
        ],
    );
    assert!(!run.exists(), "nothing written");
}

#[test]
fn bad_lenses_and_models_are_one_line_errors() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("capture");
    capture(&data);
    let transforms = data.join("transforms.json");
    let original = std::fs::read(&transforms).unwrap();
    let run = dir.path().join("run");

    edit_json(&transforms, |d| d["camera_model"] = "KANNALA".into());
    let out = train(&data, &run, &[]);
    assert_clean_error(
        &out,
        &["transforms.json", "camera_model KANNALA is not supported"],
    );

    // A fisheye with a focal length of 5 px on a 32 px image sees beyond 90° off axis.
    std::fs::write(&transforms, &original).unwrap();
    edit_json(&transforms, |d| {
        d["camera_model"] = "OPENCV_FISHEYE".into();
        for k in ["k1", "k2", "p1", "p2"] {
            d[k] = 0.0.into();
        }
        d["fl_x"] = 5.0.into();
        d["fl_y"] = 5.0.into();
    });
    let out = train(&data, &run, &[]);
    assert_clean_error(&out, &["transforms.json", "field of view of 180° or more"]);

    // A radial term that folds back inside the image.
    std::fs::write(&transforms, &original).unwrap();
    edit_json(&transforms, |d| d["k1"] = (-0.9).into());
    let out = train(&data, &run, &[]);
    assert_clean_error(
        &out,
        &["transforms.json", "does not invert inside the image"],
    );

    // COLMAP: an unknown model is refused by the reader, naming the line.
    let cameras = data.join("sparse/0/cameras.txt");
    let text = std::fs::read_to_string(&cameras).unwrap();
    std::fs::write(&cameras, text.replace("OPENCV", "WEIRD")).unwrap();
    let out = train(&data, &run, &["--format", "colmap"]);
    assert_clean_error(&out, &["cameras.txt", "unknown camera model WEIRD"]);
    assert!(!run.exists(), "nothing written");
}
