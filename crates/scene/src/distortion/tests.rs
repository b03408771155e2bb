//! The camera models against OpenCV (fixtures of `tools/make_distortion_fixtures.py`), exact
//! analytic cases, round trips and the invertibility checks.

use std::path::{Path, PathBuf};

use serde_json::Value;

use super::*;
use crate::image::Image;
use crate::load::{LoadOptions, UndistortMode, load_dataset_with_report};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/distortion")
}

fn cases() -> Vec<Value> {
    let text = std::fs::read_to_string(fixtures().join("points.json")).unwrap();
    let v: Value = serde_json::from_str(&text).unwrap();
    v["cases"].as_array().unwrap().clone()
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn lens_of(case: &Value) -> LensCamera {
    let w = case["width"].as_u64().unwrap() as u32;
    let h = case["height"].as_u64().unwrap() as u32;
    camera_from_colmap(
        case["model"].as_str().unwrap(),
        &floats(&case["params"]),
        w,
        h,
    )
    .unwrap()
}

fn npy_image(name: &str) -> Image {
    let a = crate::numpy::read_npy(&fixtures().join(name)).unwrap();
    let (h, w, c) = (a.shape[0], a.shape[1], a.shape[2]);
    Image::from_vec(w, h, c, a.data.iter().map(|&v| v as f32).collect())
}

/// `cv2.undistortPoints` / `cv2.fisheye.undistortPoints` and `cv2.projectPoints` /
/// `cv2.fisheye.distortPoints`, to 0.01 px (OpenCV's pixel centres are half a pixel off ours).
#[test]
fn points_match_opencv() {
    for case in cases() {
        let name = case["name"].as_str().unwrap();
        let lens = lens_of(&case);
        let k = lens.intrinsics;
        let (mut worst_u, mut worst_d) = (0.0f64, 0.0f64);
        let px = case["undistort"]["distorted_px"].as_array().unwrap();
        let norm = case["undistort"]["normalized"].as_array().unwrap();
        for (p, n) in px.iter().zip(norm) {
            let (p, n) = (floats(p), floats(n));
            let (x, y) = lens.undistort_normalized(p[0] + 0.5, p[1] + 0.5).unwrap();
            let err = ((x - n[0]) * k.fx).abs().max(((y - n[1]) * k.fy).abs());
            worst_u = worst_u.max(err);
        }
        let ideal = case["distort"]["normalized"].as_array().unwrap();
        let dpx = case["distort"]["distorted_px"].as_array().unwrap();
        for (n, p) in ideal.iter().zip(dpx) {
            let (n, p) = (floats(n), floats(p));
            let (u, v) = lens.distort_pixel(k.fx * n[0] + k.cx, k.fy * n[1] + k.cy);
            worst_d = worst_d.max((u - p[0] - 0.5).abs().max((v - p[1] - 0.5).abs()));
        }
        assert!(worst_u < 0.01, "{name}: undistort off by {worst_u} px");
        assert!(worst_d < 0.01, "{name}: distort off by {worst_d} px");
    }
}

/// `cv2.initUndistortRectifyMap` + `cv2.remap` (bilinear) to the same camera matrix, to 1e-3
/// where both read inside the photo (OpenCV blends its constant border in, we repeat the edge).
#[test]
fn images_match_opencv_remap() {
    for case in cases() {
        let name = case["name"].as_str().unwrap();
        let lens = lens_of(&case);
        let source = npy_image(&format!("{name}_source.npy"));
        let reference = npy_image(&format!("{name}_undistorted.npy"));
        let out = undistort_image(&source, &lens, &lens.intrinsics, Resample::Bilinear);
        let (w, h) = (out.width, out.height);
        let (mut worst, mut compared) = (0.0f32, 0);
        for y in 0..h {
            for x in 0..w {
                let (u, v) = lens.distort_pixel(x as f64 + 0.5, y as f64 + 0.5);
                let inside = u >= 1.5 && v >= 1.5 && u <= w as f64 - 1.5 && v <= h as f64 - 1.5;
                if !inside {
                    continue;
                }
                compared += 1;
                for c in 0..3 {
                    worst = worst.max((out.get(x, y, c) - reference.get(x, y, c)).abs());
                }
            }
        }
        assert!(
            compared > w * h / 2,
            "{name}: only {compared} pixels compared"
        );
        assert!(worst < 1e-3, "{name}: image off by {worst}");
    }
}

/// The largest absolute difference between two images of the same shape.
fn max_abs_diff(a: &Image, b: &Image) -> f32 {
    assert_eq!(
        (a.width, a.height, a.channels),
        (b.width, b.height, b.channels)
    );
    a.data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max)
}

/// `cv2.remap` with `INTER_CUBIC` and `BORDER_REPLICATE` of an image with pixel-scale detail and
/// hard edges, clipped to [0, 1], to 1e-3 on every pixel (both repeat the edge pixel). Bilinear
/// resampling of the same image is far off the reference, so the fixture tells the kernels
/// apart.
#[test]
fn bicubic_images_match_opencv_remap() {
    let source = npy_image("detail_source.npy");
    for case in cases() {
        let name = case["name"].as_str().unwrap();
        let lens = lens_of(&case);
        let reference = npy_image(&format!("{name}_undistorted_cubic.npy"));
        let cubic = undistort_image(&source, &lens, &lens.intrinsics, Resample::Bicubic);
        let worst = max_abs_diff(&cubic, &reference);
        assert!(worst < 1e-3, "{name}: bicubic image off by {worst}");
        let linear = undistort_image(&source, &lens, &lens.intrinsics, Resample::Bilinear);
        let apart = max_abs_diff(&linear, &reference);
        assert!(apart > 0.05, "{name}: bilinear only {apart} from bicubic");
    }
}

/// Degenerate inputs give an image of the asked size, never a panic: an empty photo, and
/// positions far outside the photo or not a number clamp to the edge.
#[test]
fn resampling_degenerate_inputs() {
    let lens = lens_of(&cases()[2]);
    let out = lens.intrinsics;
    for resample in [Resample::Bilinear, Resample::Bicubic] {
        let empty = Image::from_vec(0, 0, 3, Vec::new());
        let img = undistort_image(&empty, &lens, &out, resample);
        assert_eq!(
            (img.width, img.height),
            (out.width as usize, out.height as usize)
        );
        let wild = LensCamera::new(
            lens.intrinsics,
            Some(Distortion::opencv(&[f64::NAN, 1e30, 0.0, 0.0])),
        );
        let photo = npy_image("detail_source.npy");
        let img = undistort_image(&photo, &wild, &out, resample);
        assert!(img.data.iter().all(|v| (0.0..=1.0).contains(v)));
    }
    assert_eq!("bicubic".parse(), Ok(Resample::Bicubic));
    assert_eq!("bilinear".parse(), Ok(Resample::Bilinear));
    assert!(
        "lanczos"
            .parse::<Resample>()
            .unwrap_err()
            .contains("bilinear or bicubic")
    );
}

#[test]
fn undistort_inverts_distort_exactly() {
    let fisheye = Distortion::Fisheye {
        k: [0.05, -0.01, 0.002, -0.0005],
    };
    let full = Distortion::opencv(&[0.1, -0.05, 1e-3, 5e-4, 0.01, 0.05, -0.01, 0.005]);
    let phone = Distortion::opencv(&[0.06, -0.08, 1e-3, 1e-3]);
    for d in [fisheye, full, phone] {
        for i in 0..200 {
            let t = i as f64 * 0.731;
            let (x, y) = (0.7 * t.sin(), 0.5 * (1.3 * t).cos());
            let (xd, yd) = d.distort(x, y);
            let (bx, by) = d.undistort(xd, yd).unwrap();
            assert!(
                (bx - x).abs() < 1e-9 && (by - y).abs() < 1e-9,
                "{d:?} at ({x}, {y})"
            );
        }
    }
}

#[test]
fn analytic_cases() {
    // SIMPLE_RADIAL on the x axis: x_d = x (1 + k x²).
    let d = Distortion::opencv(&[-0.08]);
    let (xd, _) = d.distort(0.5, 0.0);
    assert!((xd - 0.5 * (1.0 - 0.08 * 0.25)).abs() < 1e-15);
    let (x, y) = d.undistort(xd, 0.0).unwrap();
    assert!((x - 0.5).abs() < 1e-14 && y == 0.0);
    // The equidistant fisheye (all k zero): θ_d = θ, so r_d = atan(r).
    let f = Distortion::Fisheye { k: [0.0; 4] };
    let (xd, yd) = f.distort(3.0, 4.0);
    assert!((xd.hypot(yd) - 5.0f64.atan()).abs() < 1e-14);
    let (x, y) = f.undistort(0.6, 0.8).unwrap();
    assert!((x.hypot(y) - 1.0f64.tan()).abs() < 1e-12);
    // Tangential terms alone at (x, 0): x_d = x + p2·3x², y_d = p1·x².
    let t = Distortion::opencv(&[0.0, 0.0, 0.01, 0.02]);
    let (xd, yd) = t.distort(0.5, 0.0);
    assert!((xd - (0.5 + 0.02 * 0.75)).abs() < 1e-15 && (yd - 0.01 * 0.25).abs() < 1e-15);
}

#[test]
fn jacobian_matches_finite_differences() {
    let models = [
        Distortion::opencv(&[0.1, -0.05, 1e-3, 5e-4, 0.01, 0.05, -0.01, 0.005]),
        Distortion::Fisheye {
            k: [0.05, -0.01, 0.002, -0.0005],
        },
    ];
    for d in models {
        let (x, y) = (0.31, -0.22);
        let (_, j) = d.distort_with_jacobian(x, y);
        let e = 1e-6;
        let (px, py) = (d.distort(x + e, y), d.distort(x - e, y));
        let (qx, qy) = (d.distort(x, y + e), d.distort(x, y - e));
        let fd = [
            (px.0 - py.0) / (2.0 * e),
            (qx.0 - qy.0) / (2.0 * e),
            (px.1 - py.1) / (2.0 * e),
            (qx.1 - qy.1) / (2.0 * e),
        ];
        for (a, b) in j.iter().zip(fd) {
            assert!((a - b).abs() < 1e-8, "{d:?}: {j:?} vs {fd:?}");
        }
    }
}

#[test]
fn lenses_that_do_not_invert_are_refused() {
    let k = crate::camera::Intrinsics::centered(10.0, 64, 48);
    let fisheye = LensCamera::new(k, Some(Distortion::Fisheye { k: [0.0; 4] }));
    let e = fisheye.check_invertible().unwrap_err();
    assert!(e.contains("180°"), "{e}");
    let k = crate::camera::Intrinsics::centered(30.0, 64, 48);
    let folding = LensCamera::new(k, Some(Distortion::opencv(&[-0.5])));
    let e = folding.check_invertible().unwrap_err();
    assert!(
        e.contains("does not invert") && e.contains("turns back"),
        "{e}"
    );
    // The phone-like lens inverts at a normal field of view (f = 50 px on 64 px, 65°) but not
    // at 94° (f = 30 px), where its radius turns back before the corner.
    let phone = Distortion::opencv(&[0.06, -0.08, 1e-3, 1e-3]);
    let normal = crate::camera::Intrinsics::centered(50.0, 64, 48);
    LensCamera::new(normal, Some(phone))
        .check_invertible()
        .unwrap();
    let e = LensCamera::new(k, Some(phone))
        .check_invertible()
        .unwrap_err();
    assert!(e.contains("turns back"), "{e}");
    let unknown = camera_from_colmap("KANNALA", &[1.0], 4, 4).unwrap_err();
    assert_eq!(unknown, "unknown camera model KANNALA");
    let other = camera_from_colmap("FOV", &[1.0; 5], 4, 4).unwrap_err();
    assert!(other.contains("FOV is not supported"), "{other}");
}

#[test]
fn framing_follows_colmap() {
    // Barrel distortion pulls the photo's border inwards, the corners most: undistorted, the
    // corners stick out farthest, so no-border framing crops them and all-pixels framing
    // leaves blank pixels at the middle of the edges.
    let k = crate::camera::Intrinsics::centered(40.0, 64, 48);
    let lens = LensCamera::new(k, Some(Distortion::opencv(&[-0.1])));
    let fill = undistorted_intrinsics(&lens, UndistortFit::NoBorder).unwrap();
    let all = undistorted_intrinsics(&lens, UndistortFit::AllPixels).unwrap();
    assert!(
        all.width > fill.width && all.height > fill.height,
        "{fill:?} {all:?}"
    );
    assert_eq!((fill.fx, all.fx), (40.0, 40.0));
    assert!((fill.cx - fill.width as f64 / 2.0).abs() < 1e-9);
    assert!(
        valid_mask(&lens, &fill).is_none(),
        "no blank pixel with NoBorder"
    );
    let mask = valid_mask(&lens, &all).unwrap();
    let blank = mask.data.iter().filter(|&&v| v == 0.0).count();
    assert!(
        blank > 0 && mask.get(all.width as usize / 2, 0, 0) == 0.0,
        "{blank} blank"
    );
    // Every photo border pixel lands inside the AllPixels frame.
    for y in 0..48 {
        for u in [0.5, 63.5] {
            let (x, v) = lens.undistort_pixel(u, y as f64 + 0.5).unwrap();
            let (x, v) = (x - k.cx + all.cx, v - k.cy + all.cy);
            assert!(
                (-0.5..=all.width as f64 + 0.5).contains(&x) && v > -0.5,
                "({x}, {v})"
            );
        }
    }
}

/// A COLMAP scene from the binary fixture (one camera of each model), with smooth photos.
fn colmap_scene() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("sparse/0");
    std::fs::create_dir_all(&model).unwrap();
    for name in ["cameras.bin", "images.bin", "points3D.bin"] {
        std::fs::copy(
            fixtures().join("colmap_binary").join(name),
            model.join(name),
        )
        .unwrap();
    }
    std::fs::create_dir_all(dir.path().join("images")).unwrap();
    let photo = npy_image("opencv_source.npy");
    for i in 0..7 {
        photo
            .save_png(&dir.path().join(format!("images/view_{i}.png")))
            .unwrap();
    }
    dir
}

#[test]
fn colmap_binary_fixture_reads_every_model() {
    let text = std::fs::read_to_string(fixtures().join("colmap_binary.json")).unwrap();
    let reference: Value = serde_json::from_str(&text).unwrap();
    let model = crate::colmap::read_model(&fixtures().join("colmap_binary")).unwrap();
    let cams = reference["cameras"].as_array().unwrap();
    assert_eq!(model.cameras.len(), cams.len());
    for c in cams {
        let got = &model.cameras[&(c["id"].as_u64().unwrap() as u32)];
        assert_eq!(got.model, c["model"].as_str().unwrap());
        assert_eq!(got.params, floats(&c["params"]));
        let lens = got.lens().unwrap();
        assert_eq!(lens.distortion.is_some(), !got.model.contains("PINHOLE"));
    }
    let dir = colmap_scene();
    let opts = LoadOptions {
        train_views: Some(vec![0, 1, 2, 3]),
        test_views: Some(vec![4, 5, 6]),
        ..Default::default()
    };
    let (d, report) = load_dataset_with_report(dir.path(), &opts).unwrap();
    assert_eq!(d.views.len(), 7);
    assert_eq!(
        (report.undistorted, report.cache_writes, report.cache_hits),
        (5, 5, 0)
    );
    assert!(d.views.iter().all(|v| v.valid.is_none()));
    // The pinhole views keep their camera; the distorted ones get COLMAP's framing.
    let lens = model.cameras[&5].lens().unwrap();
    let expected = undistorted_intrinsics(&lens, UndistortFit::NoBorder).unwrap();
    assert_eq!(d.views[4].camera.intrinsics, expected);
    assert_eq!(d.views[0].camera.intrinsics.width, 64);
    // A second load reads every undistorted photo from the cache and writes nothing.
    let cache = dir.path().join(cache::CACHE_SUBDIR);
    let stamps = |dir: &Path| -> Vec<(PathBuf, std::time::SystemTime)> {
        let mut v: Vec<_> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| {
                let p = e.unwrap().path();
                let t = std::fs::metadata(&p).unwrap().modified().unwrap();
                (p, t)
            })
            .collect();
        v.sort();
        v
    };
    let before = stamps(&cache);
    assert_eq!(before.len(), 5);
    let (again, report) = load_dataset_with_report(dir.path(), &opts).unwrap();
    assert_eq!(
        (report.undistorted, report.cache_writes, report.cache_hits),
        (5, 0, 5)
    );
    assert_eq!(stamps(&cache), before);
    // Bit for bit: the first load trains on the values the cache stores.
    for (a, b) in d.views.iter().zip(&again.views) {
        assert_eq!(
            a.image.data, b.image.data,
            "{}: cached image differs",
            a.name
        );
    }
    // Another kernel is another cache entry, and another image.
    let bicubic = LoadOptions {
        resample: Resample::Bicubic,
        ..opts.clone()
    };
    let (sharp, report) = load_dataset_with_report(dir.path(), &bicubic).unwrap();
    assert_eq!((report.cache_writes, report.cache_hits), (5, 0));
    assert!(max_abs_diff(&sharp.views[4].image, &d.views[4].image) > 1e-3);
    let (_, report) = load_dataset_with_report(dir.path(), &bicubic).unwrap();
    assert_eq!((report.cache_writes, report.cache_hits), (0, 5));
    assert_eq!(stamps(&cache).len(), 10);
    // All pixels kept: a validity mask where the border is blank; ignored: the photos as they are.
    let (all, _) = load_dataset_with_report(
        dir.path(),
        &LoadOptions {
            undistort: UndistortMode::AllPixels,
            ..opts.clone()
        },
    )
    .unwrap();
    assert!(all.views[4..].iter().any(|v| v.valid.is_some()));
    let (raw, report) = load_dataset_with_report(
        dir.path(),
        &LoadOptions {
            undistort: UndistortMode::Ignore,
            ..opts.clone()
        },
    )
    .unwrap();
    assert_eq!(report.undistorted, 0);
    assert!(raw.views.iter().all(|v| v.camera.intrinsics.width == 64));
}

#[test]
fn lenses_print_with_opencvs_coefficient_names() {
    let phone = Distortion::opencv(&[0.06, -0.08, 0.001, 0.001]);
    assert_eq!(
        phone.to_string(),
        "OpenCV k1=0.06 k2=-0.08 p1=0.001 p2=0.001"
    );
    let full = Distortion::opencv(&[0.1, 0.0, 0.0, 0.0, 0.2, 0.0, 0.3, 0.0]);
    assert_eq!(
        full.to_string(),
        "OpenCV k1=0.1 k2=0 p1=0 p2=0 k3=0.2 k5=0.3"
    );
    let fisheye = Distortion::Fisheye {
        k: [0.1, -0.01, 0.0, 0.0],
    };
    assert_eq!(fisheye.to_string(), "fisheye k1=0.1 k2=-0.01 k3=0 k4=0");
}
