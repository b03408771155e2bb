//! The ZJU-MoCap loader on fixtures made by `tools/make_zju_fixture.py`: the seq_a-derived
//! capture (cameras against the README's rig and, with `FEWVIEW_DATA`, against seq_a itself),
//! undistortion against OpenCV, and NumPy object arrays against the values NumPy pickled.

// Tests report what they measured.
#![allow(clippy::print_stdout, clippy::print_stderr)]

mod common;

use std::path::{Path, PathBuf};

use fewview_human::zju::numpy::{ArrayData, Value, read_object_npy};
use fewview_human::zju::undistort::UndistortMap;
use fewview_human::{HumanDataset, MultiView, ZjuDataset};
use fewview_scene::numpy::read_npy;
use fewview_scene::{Camera, Intrinsics};
use nalgebra::{Matrix3, Vector3};

/// The seq_a cameras the fixture holds, in order.
const SEQ_A_CAMERAS: [usize; 4] = [0, 3, 6, 9];

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// The README's rig: camera `i` at 30°·i counter-clockwise from (0, −3, 1.35), looking at
/// (0, 0, 0.85), fx = 640, principal point at the image centre.
fn readme_camera(i: usize) -> Camera {
    let a = (i as f64 * 30.0).to_radians();
    let eye = Vector3::new(3.0 * a.sin(), -3.0 * a.cos(), 1.35);
    let k = Intrinsics::centered(640.0, 512, 512);
    Camera::look_at(k, eye, Vector3::new(0.0, 0.0, 0.85), Vector3::z())
}

fn camera_difference(a: &Camera, b: &Camera) -> f64 {
    let (ka, kb) = (&a.intrinsics, &b.intrinsics);
    let k = [ka.fx - kb.fx, ka.fy - kb.fy, ka.cx - kb.cx, ka.cy - kb.cy];
    let r = (a.world_to_camera.rotation - b.world_to_camera.rotation).amax();
    let t = (a.world_to_camera.translation - b.world_to_camera.translation).amax();
    k.iter().fold(r.max(t), |m, v| m.max(v.abs()))
}

#[test]
fn small_fixture_loads_with_the_rig_cameras() {
    let data = ZjuDataset::open(&fixture("zju_small")).unwrap();
    assert_eq!(
        data.camera_names(),
        ["Camera_B1", "Camera_B4", "Camera_B7", "Camera_B10"]
    );
    assert_eq!(data.frame_count(), 3);
    for (cam, &i) in data.cameras().iter().zip(&SEQ_A_CAMERAS) {
        let d = camera_difference(cam, &readme_camera(i));
        assert!(d < 1e-6, "camera {i}: {d}");
        assert_eq!((cam.width(), cam.height()), (512, 512));
    }
    let img = data.image(2, 1).unwrap();
    assert_eq!((img.width, img.height, img.channels), (512, 512, 3));
    assert!(data.depth(0, 0).is_err());
    let params = data.smpl_params(2).unwrap();
    assert_eq!((params.poses.len(), params.shapes.len()), (72, 10));
    assert_eq!(params.rh, [0.0; 3]);
    // Th is the pelvis: the first 3D joint.
    let pelvis = data.joints3d(2).unwrap()[0];
    assert!((0..3).all(|a| (params.th[a] - pelvis[a]).abs() < 1e-7));
}

/// The acceptance check: the ZJU copy of seq_a loads with seq_a's cameras (1e-5), images,
/// masks and 2D joints (projected from `joints3d/`, against seq_a's stored 2D joints).
#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn small_fixture_equals_seq_a() {
    let zju = ZjuDataset::open(&fixture("zju_small")).unwrap();
    let seq = HumanDataset::open(&common::data_root().join("human"), "seq_a").unwrap();
    let mut worst_joint = 0f64;
    for (c, &s) in SEQ_A_CAMERAS.iter().enumerate() {
        let d = camera_difference(&zju.cameras()[c], &seq.cameras()[s]);
        assert!(d < 1e-5, "camera {s}: {d}");
        for f in 0..3 {
            assert_eq!(zju.image(c, f).unwrap(), seq.image(s, f).unwrap());
            assert_eq!(zju.mask(c, f).unwrap(), seq.mask(s, f).unwrap());
            for (p, q) in zju
                .joints2d(c, f)
                .unwrap()
                .iter()
                .zip(seq.joints2d(s, f).unwrap())
            {
                worst_joint = worst_joint
                    .max((p[0] - q[0]).abs())
                    .max((p[1] - q[1]).abs());
            }
        }
    }
    println!("ZJU fixture vs seq_a: largest 2D joint difference {worst_joint:.2e} px");
    assert!(worst_joint < 1e-3);
}

/// Undistortion against OpenCV (`initUndistortRectifyMap` + `remap`, see the tools script): the
/// sampling map to 1e-3 px, the image to 1e-3 against exact bilinear sampling at OpenCV's map,
/// and the mask against OpenCV's nearest-neighbour remap.
#[test]
fn undistortion_matches_opencv() {
    let root = fixture("zju_distorted");
    let data = ZjuDataset::open(&root).unwrap();
    let d = *data.distortion(0).unwrap();
    assert!(!d.is_identity());
    let k = Matrix3::new(58.0, 0.0, 31.7, 0.0, 57.0, 23.2, 0.0, 0.0, 1.0);
    let map = UndistortMap::new(&k, &d, 64, 48);
    let mx = read_npy(&root.join("reference/map_x.npy")).unwrap();
    let my = read_npy(&root.join("reference/map_y.npy")).unwrap();
    let mut worst_map = 0f64;
    for (i, p) in map.source.iter().enumerate() {
        worst_map = worst_map
            .max((p[0] - mx.data[i]).abs())
            .max((p[1] - my.data[i]).abs());
    }
    let img = data.image(0, 0).unwrap();
    let exact = read_npy(&root.join("reference/image.npy")).unwrap();
    assert_eq!(exact.shape, vec![48, 64, 3]);
    let worst_img = img
        .data
        .iter()
        .zip(&exact.data)
        .map(|(a, b)| (*a as f64 - b).abs())
        .fold(0.0, f64::max);
    let cv = fewview_scene::Image::load(&root.join("reference/cv2_image.png")).unwrap();
    let worst_cv = img
        .data
        .iter()
        .zip(&cv.data)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max);
    let mask = data.mask(0, 0).unwrap();
    let cv_mask = fewview_human::Mask::load(&root.join("reference/mask.png"), 128).unwrap();
    let differ = mask
        .data
        .iter()
        .zip(&cv_mask.data)
        .filter(|(a, b)| a != b)
        .count();
    println!(
        "undistortion vs OpenCV: map {worst_map:.2e} px, image {worst_img:.2e} (exact bilinear), \
         {:.2}/255 (cv2.remap, 8-bit), mask {differ} of {} pixels differ",
        worst_cv * 255.0,
        mask.data.len()
    );
    assert!(worst_map < 1e-3 && worst_img < 1e-3);
    assert!(worst_cv <= 2.0 / 255.0);
    assert_eq!(differ, 0);
    // The lens moved the picture: the undistorted image is not the recorded one.
    let raw = fewview_scene::Image::load(&root.join("Camera_B1/000000.png")).unwrap();
    assert!(
        raw.data
            .iter()
            .zip(&img.data)
            .any(|(a, b)| (a - b).abs() > 0.1)
    );
}

fn numbers(v: &Value) -> (Vec<usize>, Vec<f64>) {
    match v {
        Value::Array(a) => match &a.data {
            ArrayData::Numbers(n) => (a.shape.clone(), n.clone()),
            other => panic!("not numeric: {other:?}"),
        },
        other => panic!("not an array: {other:?}"),
    }
}

/// Object arrays pickled by NumPy with protocols 2, 4 and 5 read back as NumPy wrote them.
#[test]
fn pickled_object_arrays_match_numpy() {
    let root = fixture("pickle");
    let expected: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(root.join("expected.json")).unwrap())
            .unwrap();
    for protocol in [2, 4, 5] {
        let v = read_object_npy(&root.join(format!("case_p{protocol}.npy"))).unwrap();
        for key in ["f8", "f4", "fortran", "big_endian", "i8", "u1", "bool"] {
            let (shape, data) = numbers(v.get(key).unwrap());
            let want = &expected[key];
            let want_shape: Vec<usize> = serde_json::from_value(want["shape"].clone()).unwrap();
            let want_data: Vec<f64> = serde_json::from_value(want["data"].clone()).unwrap();
            assert_eq!(
                (shape, data),
                (want_shape, want_data),
                "protocol {protocol}, {key}"
            );
        }
        for key in ["unicode", "bytes"] {
            let got: Vec<String> = v
                .get(key)
                .unwrap()
                .items()
                .unwrap()
                .iter()
                .map(|s| s.as_str().unwrap().to_owned())
                .collect();
            let want: Vec<String> = serde_json::from_value(expected[key].clone()).unwrap();
            assert_eq!(got, want, "protocol {protocol}, {key}");
        }
        assert_eq!(v.get("scalar"), Some(&Value::Float(0.125)));
        assert_eq!(v.get("big_int"), Some(&Value::Int(1 << 40)));
        assert_eq!(v.get("none"), Some(&Value::None));
        let Some(Value::List(nested)) = v.get("nested") else {
            panic!("nested")
        };
        assert_eq!(numbers(&nested[0]), (vec![2, 2], vec![1.0, 0.0, 0.0, 1.0]));
        assert_eq!(
            nested[1],
            Value::List(vec![
                Value::Int(1),
                Value::Float(2.5),
                Value::Str("x".into())
            ])
        );
        assert_eq!(
            nested[2].get("deep"),
            Some(&Value::List(vec![Value::None, Value::Bool(true)]))
        );
    }
}

#[test]
fn missing_files_and_bad_annots_are_one_line_errors() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("cap");
    copy_dir(&fixture("zju_small"), &root);
    std::fs::remove_file(root.join("mask/Camera_B7/000001.png")).unwrap();
    let e = ZjuDataset::open(&root).unwrap_err().to_string();
    assert!(
        e.contains("mask/Camera_B7/000001.png: missing (listed in annots.npy for frame 1)"),
        "{e}"
    );
    std::fs::write(root.join("annots.npy"), b"\x93NUMPY garbage").unwrap();
    let e = ZjuDataset::open(&root).unwrap_err().to_string();
    assert!(
        e.contains("annots.npy: not a valid .npy file") && !e.contains('\n'),
        "{e}"
    );
    // A numeric array where the dict should be.
    common::write_npy(&root.join("annots.npy"), &[2], &[1.0, 2.0]);
    let e = ZjuDataset::open(&root).unwrap_err().to_string();
    assert!(
        e.contains("annots.npy: dtype '<f4' is not a pickled object array"),
        "{e}"
    );
    // A truncated pickle.
    let bytes = std::fs::read(fixture("zju_small/annots.npy")).unwrap();
    std::fs::write(root.join("annots.npy"), &bytes[..bytes.len() / 2]).unwrap();
    let e = ZjuDataset::open(&root).unwrap_err().to_string();
    assert!(
        e.contains("annots.npy: cannot unpickle: pickle byte"),
        "{e}"
    );
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.path().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}
