//! The synthetic capture's loader: conventions against independent references (the README's rig
//! and projections of the 3D joints), and its one-line errors on a capture the test writes.

// Tests report what they measured.
#![allow(clippy::print_stdout, clippy::print_stderr)]

mod common;

use fewview_human::{HumanDataset, MultiView};
use fewview_scene::{Camera, Intrinsics};
use nalgebra::Vector3;

fn tiny() -> (tempfile::TempDir, HumanDataset) {
    let dir = tempfile::tempdir().unwrap();
    common::write_capture(dir.path(), 3, 4);
    let data = HumanDataset::open(dir.path(), "seq").unwrap();
    (dir, data)
}

#[test]
fn tiny_capture_reads_every_kind_of_data() {
    let (_dir, data) = tiny();
    assert_eq!((data.cameras().len(), data.frame_count()), (3, 4));
    assert_eq!(data.camera_names()[2], "cam_02");
    // cx = 7.5 in the file (integer pixel centres) is 8.0 inside.
    assert_eq!(data.cameras()[0].intrinsics.cx, 8.0);
    assert_eq!(data.cameras()[1], common::ring_camera(1, 3));
    let img = data.image(1, 3).unwrap();
    assert_eq!((img.width, img.height, img.channels), (16, 16, 3));
    let mask = data.mask(0, 0).unwrap();
    assert_eq!(mask.count(), (16 * 16usize).div_ceil(3));
    assert!(mask.data[0] && !mask.data[1]);
    let depth = data.depth(2, 1).unwrap();
    assert_eq!(depth.get(0, 0), 2.0);
    assert_eq!(depth.get(5, 1), (2000 + 21) as f32 / 1000.0);
    assert_eq!(
        data.joints3d(2).unwrap()[1],
        [0.05f32 as f64, -0.02f32 as f64, 0.1f32 as f64]
    );
    for c in 0..3 {
        let j2 = data.joints2d(c, 2).unwrap();
        for (p, q) in j2.iter().zip(common::JOINTS) {
            let (u, v, _) = data.cameras()[c].project(&Vector3::from(q)).unwrap();
            assert!(
                (p[0] - u).abs() < 1e-4 && (p[1] - v).abs() < 1e-4,
                "{p:?} vs {u} {v}"
            );
        }
    }
}

#[test]
fn a_missing_mask_is_named() {
    let dir = tempfile::tempdir().unwrap();
    common::write_capture(dir.path(), 3, 4);
    let gone = dir.path().join("seq/masks/cam_01/frame_0002.png");
    std::fs::remove_file(&gone).unwrap();
    let e = HumanDataset::open(dir.path(), "seq")
        .unwrap_err()
        .to_string();
    assert!(e.contains("masks/cam_01/frame_0002.png: missing"), "{e}");
    assert!(!e.contains('\n'));
}

#[test]
fn camera_count_must_match_the_image_folders() {
    let dir = tempfile::tempdir().unwrap();
    common::write_capture(dir.path(), 3, 2);
    std::fs::create_dir(dir.path().join("seq/images/cam_99")).unwrap();
    let e = HumanDataset::open(dir.path(), "seq")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("4 camera folders but cameras.json has 3 cameras"),
        "{e}"
    );
}

#[test]
fn joint_arrays_must_have_every_frame() {
    let dir = tempfile::tempdir().unwrap();
    common::write_capture(dir.path(), 2, 3);
    let path = dir.path().join("seq/joints2d/cam_01.npy");
    common::write_npy(&path, &[2, 2, 2], &[0.0; 8]);
    let e = HumanDataset::open(dir.path(), "seq")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("cam_01.npy: shape [2, 2, 2], expected [3, 2, 2]"),
        "{e}"
    );
}

#[test]
fn joints_outside_the_image_name_camera_and_frame() {
    let dir = tempfile::tempdir().unwrap();
    common::write_capture(dir.path(), 2, 3);
    let path = dir.path().join("seq/joints2d/cam_01.npy");
    let mut values = vec![5.0f32; 12];
    values[8] = 16.2; // frame 2, joint 0, u: past the right border
    common::write_npy(&path, &[3, 2, 2], &values);
    let data = HumanDataset::open(dir.path(), "seq").unwrap();
    assert!(data.joints2d(1, 1).is_ok());
    let e = data.joints2d(1, 2).unwrap_err().to_string();
    assert!(
        e.contains("camera cam_01, frame 2: joint 0 at (16.70, 5.50) is outside"),
        "{e}"
    );
}

#[test]
fn distortion_and_bad_indices_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    common::write_capture(dir.path(), 2, 2);
    let data = HumanDataset::open(dir.path(), "seq").unwrap();
    let e = data.image(2, 0).unwrap_err().to_string();
    assert!(
        e.contains("camera 2 out of range (the capture has 2 cameras)"),
        "{e}"
    );
    assert!(
        data.mask(0, 5)
            .unwrap_err()
            .to_string()
            .contains("frame 5 out of range")
    );
    let path = dir.path().join("cameras.json");
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, text.replacen("\"dist\":[0.0,", "\"dist\":[0.1,", 1)).unwrap();
    let e = HumanDataset::open(dir.path(), "seq")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("cameras.json: cam_00: non-zero distortion"),
        "{e}"
    );
}

/// seq_a's cameras are the README's rig: 12 on a circle of radius 3 m, 1.35 m high, 30° apart
/// counter-clockwise from (0, −3, 1.35), looking at (0, 0, 0.85) without roll; fx = 640 and the
/// principal point at the image centre (255.5 with integer pixel centres, 256 inside).
#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn seq_a_cameras_are_the_readme_rig_and_joints_project_exactly() {
    let data = HumanDataset::open(&common::data_root().join("human"), "seq_a").unwrap();
    assert_eq!((data.cameras().len(), data.frame_count()), (12, 60));
    assert_eq!(data.joint_names().len(), 17);
    for (i, cam) in data.cameras().iter().enumerate() {
        let a = (i as f64 * 30.0).to_radians();
        let eye = Vector3::new(3.0 * a.sin(), -3.0 * a.cos(), 1.35);
        let want = Camera::look_at(
            Intrinsics::centered(640.0, 512, 512),
            eye,
            Vector3::new(0.0, 0.0, 0.85),
            Vector3::z(),
        );
        assert_eq!(cam.intrinsics, want.intrinsics);
        let dr = (cam.world_to_camera.rotation - want.world_to_camera.rotation).amax();
        assert!(
            dr < 1e-8 && (cam.center() - eye).norm() < 1e-8,
            "camera {i}: {dr}"
        );
    }
    // The stored 2D joints are the projections of the 3D joints, once both use one convention.
    let mut worst = 0f64;
    for f in [0, 31, 59] {
        let j3 = data.joints3d(f).unwrap();
        for c in 0..12 {
            for (p, q) in data.joints2d(c, f).unwrap().iter().zip(&j3) {
                let (u, v, _) = data.cameras()[c].project(&Vector3::from(*q)).unwrap();
                worst = worst.max((p[0] - u).abs()).max((p[1] - v).abs());
            }
        }
    }
    println!("seq_a: largest |stored 2D joint - projected 3D joint| = {worst:.2e} px");
    assert!(worst < 1e-3, "{worst}");
}

/// Depth is metric (within the README's range 2.111–3.958 m) and lies on the mask (the README
/// counts 0.03 % of depth pixels outside it, all at the silhouette).
#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn seq_a_depth_is_metric_and_inside_the_mask() {
    let data = HumanDataset::open(&common::data_root().join("human"), "seq_a").unwrap();
    let depth = data.depth(3, 45).unwrap();
    let mask = data.mask(3, 45).unwrap();
    let valid: Vec<usize> = (0..depth.data.len())
        .filter(|&i| depth.data[i] > 0.0)
        .collect();
    let in_mask = valid.iter().filter(|&&i| mask.data[i]).count();
    let (lo, hi) = valid.iter().fold((f32::MAX, 0f32), |(l, h), &i| {
        (l.min(depth.data[i]), h.max(depth.data[i]))
    });
    println!(
        "cam_03 frame 45: {} depth pixels, {:.3} in the mask, depth {lo:.3}-{hi:.3} m",
        valid.len(),
        in_mask as f64 / valid.len() as f64
    );
    assert!(in_mask as f64 / valid.len() as f64 > 0.99);
    assert!(lo >= 2.111 && hi <= 3.958);
    let img = data.image(3, 45).unwrap();
    assert_eq!((img.width, img.height, img.channels), (512, 512, 3));
}
