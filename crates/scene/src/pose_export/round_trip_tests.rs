//! Each format's export read back by the format's own loader: the replaced views project world
//! points where the refined cameras do, keep their stored intrinsics, and the other views are
//! untouched.

use std::path::Path;

use nalgebra::{Matrix4, Rotation3, Vector3};

use super::{PoseSource, write_refined_poses};
use crate::camera::{Camera, Se3};
use crate::dataset::Dataset;
use crate::load::{LoadOptions, load_dataset};

/// Copies a fixture folder (small files only) recursively.
fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let p = entry.unwrap().path();
        let dest = to.join(p.file_name().unwrap());
        if p.is_dir() {
            copy_dir(&p, &dest);
        } else {
            std::fs::copy(&p, &dest).unwrap();
        }
    }
}

/// A small known change of view `k`'s pose (in camera coordinates), scaled to the scene.
fn nudged(pose: &Se3, k: usize, scale: f64) -> Se3 {
    let delta = Se3::new(
        Rotation3::from_euler_angles(0.01 * (k + 1) as f64, -0.02, 0.015).into_inner(),
        Vector3::new(0.01, -0.02, 0.03 * (k + 1) as f64) * scale,
    );
    delta.compose(pose)
}

/// Points in front of `camera` (world coordinates of the dataset's frame).
fn points_before(camera: &Camera, depth: f64) -> Vec<Vector3<f64>> {
    let c2w = camera.camera_to_world();
    [(0.0, 0.0), (0.1, -0.05), (-0.08, 0.12)]
        .iter()
        .map(|&(x, y)| c2w.transform_point(&(Vector3::new(x, y, 1.0) * depth)))
        .collect()
}

/// Point `x` of `from`'s world in `to`'s world, through their source frames.
fn between_frames(from: &Dataset, to: &Dataset, x: &Vector3<f64>) -> Vector3<f64> {
    let source = from
        .to_source_world
        .unwrap_or_else(Matrix4::identity)
        .transform_point(&(*x).into());
    let back = to
        .to_source_world
        .unwrap_or_else(Matrix4::identity)
        .try_inverse()
        .unwrap();
    back.transform_point(&source).coords
}

/// Exports nudged poses of the training views of the scene at `root`, installs the exported
/// files over the originals (`installs`: written name → original path inside the scene) in a
/// copy, reloads with `reload` and checks every view.
fn round_trip(
    root: &Path,
    load: &LoadOptions,
    reload: &LoadOptions,
    depth: f64,
    installs: &[(&str, &str)],
) {
    let original = load_dataset(root, load).unwrap();
    let scale = original.camera_extent().1;
    let poses: Vec<(usize, Se3)> = original
        .train
        .iter()
        .enumerate()
        .map(|(k, &v)| {
            (
                v,
                nudged(&original.views[v].camera.world_to_camera, k, scale),
            )
        })
        .collect();
    let out = tempfile::tempdir().unwrap();
    let source = PoseSource {
        root,
        options: load,
    };
    let written = write_refined_poses(source, &original, &poses, out.path()).unwrap();
    assert_eq!(written.len(), installs.len(), "{written:?}");
    let copy = tempfile::tempdir().unwrap();
    copy_dir(root, copy.path());
    for (written_name, original_name) in installs {
        let from = out.path().join(written_name);
        assert!(written.contains(&from), "{from:?} not in {written:?}");
        std::fs::copy(&from, copy.path().join(original_name)).unwrap();
    }
    let reloaded = load_dataset(copy.path(), reload).unwrap();
    assert_eq!(reloaded.views.len(), original.views.len());
    for (i, (before, after)) in original.views.iter().zip(&reloaded.views).enumerate() {
        let expected = match poses.iter().find(|(v, _)| *v == i) {
            Some((_, pose)) => Camera::new(before.camera.intrinsics, *pose),
            None => before.camera.clone(),
        };
        let k0 = before.camera.intrinsics;
        let k1 = after.camera.intrinsics;
        let intrinsics_off = [k0.fx - k1.fx, k0.fy - k1.fy, k0.cx - k1.cx, k0.cy - k1.cy]
            .iter()
            .fold(0.0f64, |m, d| m.max(d.abs()));
        assert!(
            intrinsics_off < 1e-9,
            "view {i}: intrinsics moved by {intrinsics_off}"
        );
        for x in points_before(&expected, depth) {
            let (u0, v0, _) = expected.project(&x).unwrap();
            let (u1, v1, _) = after
                .camera
                .project(&between_frames(&original, &reloaded, &x))
                .unwrap();
            let off = (u0 - u1).hypot(v0 - v1);
            assert!(off < 1e-6, "view {i}: a point moved by {off} px");
        }
    }
}

#[test]
fn llff_rows_round_trip_through_the_normalisation() {
    let dir = tempfile::tempdir().unwrap();
    crate::llff::tests::write_scene(dir.path(), &crate::llff::tests::eyes(6), "images_8", (8, 6));
    // Normalised on load (the default), so the export undoes the normalisation; the reload is
    // raw, because the new poses move NeRF's average pose and with it the normalised frame.
    let load = LoadOptions::default();
    let raw = LoadOptions {
        llff_normalize: false,
        ..Default::default()
    };
    round_trip(
        dir.path(),
        &load,
        &raw,
        5.0,
        &[("poses_bounds_refined.npy", "poses_bounds.npy")],
    );
    round_trip(
        dir.path(),
        &raw,
        &raw,
        5.0,
        &[("poses_bounds_refined.npy", "poses_bounds.npy")],
    );
}

#[test]
fn dtu_world_mats_round_trip_through_scale_mat_at_any_downscale() {
    let dir = tempfile::tempdir().unwrap();
    crate::dtu::tests::write_scene(dir.path(), 8, 1.0);
    let opts = LoadOptions {
        train_views: Some(vec![1, 4, 6]),
        test_views: Some(vec![0]),
        ..Default::default()
    };
    let install = [("cameras_sphere_refined.npz", "cameras_sphere.npz")];
    round_trip(dir.path(), &opts, &opts, 4.0, &install);
    // Loaded at half resolution: the file keeps the stored intrinsics.
    let half = LoadOptions {
        downscale: 2,
        ..opts
    };
    round_trip(dir.path(), &half, &half, 4.0, &install);
}

#[test]
fn blender_and_nerfstudio_frames_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    crate::transforms::tests::write_blender(dir.path(), 5, 2, serde_json::json!({}));
    let opts = LoadOptions {
        train_views: Some(vec![3, 0, 4]),
        ..Default::default()
    };
    round_trip(
        dir.path(),
        &opts,
        &opts,
        4.0,
        &[("transforms_train_refined.json", "transforms_train.json")],
    );
    // Frames stored in reverse name order: the views' order is not the file's.
    let dir = tempfile::tempdir().unwrap();
    crate::transforms::tests::write_nerfstudio(dir.path());
    let opts = LoadOptions::default();
    round_trip(
        dir.path(),
        &opts,
        &opts,
        3.0,
        &[("transforms_refined.json", "transforms.json")],
    );
}

#[test]
fn colmap_text_and_binary_models_round_trip() {
    for (sub, ext) in [("text", "txt"), ("binary", "bin")] {
        let scene = crate::colmap::tests::scene(sub);
        let opts = LoadOptions::default();
        let names: Vec<(String, String)> = ["cameras", "images", "points3D"]
            .iter()
            .map(|n| {
                (
                    format!("sparse_refined/{n}.{ext}"),
                    format!("sparse/0/{n}.{ext}"),
                )
            })
            .collect();
        let installs: Vec<(&str, &str)> = names
            .iter()
            .map(|(a, b)| (a.as_str(), b.as_str()))
            .collect();
        round_trip(scene.path(), &opts, &opts, 3.0, &installs);
        // Only the poses changed: the 2D points and the other images' records are as stored.
        let out = tempfile::tempdir().unwrap();
        let d = load_dataset(scene.path(), &opts).unwrap();
        let same: Vec<(usize, Se3)> = d
            .train
            .iter()
            .map(|&v| (v, d.views[v].camera.world_to_camera))
            .collect();
        let source = PoseSource {
            root: scene.path(),
            options: &opts,
        };
        write_refined_poses(source, &d, &same, out.path()).unwrap();
        let before = std::fs::read(scene.path().join(format!("sparse/0/images.{ext}"))).unwrap();
        let after = std::fs::read(out.path().join(format!("sparse_refined/images.{ext}"))).unwrap();
        // Unchanged poses are written as their normalised quaternion and translation, so
        // at most the pose fields of the training images differ: 56 bytes of each binary
        // record, one line per image of the text file.
        let n_train = d.train.len();
        if ext == "bin" {
            assert_eq!(before.len(), after.len());
            let differing = before.iter().zip(&after).filter(|(a, b)| a != b).count();
            assert!(differing <= 56 * n_train, "{differing} bytes differ");
        } else {
            let text = |b: &[u8]| String::from_utf8(b.to_vec()).unwrap();
            let (b, a) = (text(&before), text(&after));
            let differing = b.lines().zip(a.lines()).filter(|(x, y)| x != y).count();
            assert_eq!(b.lines().count(), a.lines().count());
            assert!(differing <= n_train, "{differing} lines differ");
        }
    }
}

#[test]
fn a_view_past_the_dataset_is_a_one_line_error() {
    let dir = tempfile::tempdir().unwrap();
    crate::dtu::tests::write_scene(dir.path(), 4, 1.0);
    let opts = LoadOptions {
        train_views: Some(vec![1, 2]),
        test_views: Some(vec![0]),
        ..Default::default()
    };
    let d = load_dataset(dir.path(), &opts).unwrap();
    let out = tempfile::tempdir().unwrap();
    let source = PoseSource {
        root: dir.path(),
        options: &opts,
    };
    let err = write_refined_poses(source, &d, &[(9, Se3::identity())], out.path())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("view 9 does not exist") && !err.contains('\n'),
        "{err}"
    );
    assert_eq!(std::fs::read_dir(out.path()).unwrap().count(), 0);
}
