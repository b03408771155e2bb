//! The surface paper Alg. 3 on the bunny fixture made by `tools/registration_fixture.py` (random
//! similarity, 1 % Gaussian noise, 70 % overlap, camera pre-alignment), against Open3D's
//! FPFH + RANSAC + ICP result on the same inputs, recorded in the fixture.

// Tests report what they measured.
#![allow(clippy::print_stdout, clippy::print_stderr)]

use std::path::PathBuf;

use fewview_geom::io::{read_mesh, read_points};
use fewview_geom::registration::{DenoiseOptions, IcpCriteria, RegistrationOptions, register};
use fewview_geom::similarity::{Similarity, rotation_angle_deg};
use nalgebra::{Matrix4, Vector3};
use serde_json::Value;

fn fixture_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/registration")
}

fn low_noise_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/registration_low_noise")
}

fn matrix(v: &Value) -> Matrix4<f64> {
    let rows = v.as_array().expect("4×4 rows");
    Matrix4::from_fn(|r, c| rows[r][c].as_f64().expect("number"))
}

/// Rotation error (degrees) and RMS displacement of `points` between two transforms.
fn errors(est: &Similarity, truth: &Similarity, points: &[Vector3<f64>]) -> (f64, f64) {
    let rot = rotation_angle_deg(&(est.rotation * truth.rotation.transpose()));
    let ms = points
        .iter()
        .map(|p| (est.apply(p) - truth.apply(p)).norm_squared())
        .sum::<f64>()
        / points.len() as f64;
    (rot, ms.sqrt())
}

/// Runs Alg. 3 on a fixture (with the local-plane denoising before ICP when `denoise`);
/// returns ((ours rotation °, displacement / diagonal), (Open3D's)).
fn run_fixture(dir: &std::path::Path, denoise: bool, seed: u64) -> ((f64, f64), (f64, f64)) {
    let fx: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("fixture.json")).unwrap()).unwrap();
    let source = read_points(&dir.join("source.ply")).unwrap();
    let target = read_points(&dir.join("target.ply")).unwrap();
    assert_eq!(source.len() as u64, fx["source_points"].as_u64().unwrap());
    let truth = Similarity::from_matrix4(&matrix(&fx["true_source_to_target"])).unwrap();
    let pre = Similarity::from_matrix4(&matrix(&fx["prealignment"])).unwrap();
    let o3d = Similarity::from_matrix4(&matrix(&fx["open3d"]["icp_transformation"])).unwrap();
    let diag = fx["bbox_diagonal"].as_f64().unwrap();
    let voxel = fx["voxel_size"].as_f64().unwrap();
    let thresholds: Vec<f64> = fx["icp_threshold"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    // The errors are measured on the clean source points of the truth: the target's inverse image.
    let reference: Vec<Vector3<f64>> = source
        .positions
        .iter()
        .map(|p| Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64))
        .collect();
    let mut options = RegistrationOptions::for_voxel(voxel);
    options.icp_thresholds = thresholds;
    options.icp_criteria = IcpCriteria {
        max_iteration: 100,
        ..Default::default()
    };
    options.ransac.seed = seed;
    options.icp_denoise = denoise.then(|| DenoiseOptions::for_voxel(voxel));
    let result = register(&source, &target, Some(&pre), &options).unwrap();
    let (ours_rot, ours_disp) = errors(&result.transformation, &truth, &reference);
    let (o3d_rot, o3d_disp) = errors(&o3d, &truth, &reference);
    let (pre_rot, pre_disp) = errors(&pre, &truth, &reference);
    let (g_rot, _) = errors(
        &result
            .global
            .as_ref()
            .expect("RANSAC result")
            .transformation
            .compose(&pre),
        &truth,
        &reference,
    );
    eprintln!(
        "denoise {denoise}, seed {seed}; pre-alignment: {pre_rot:.3}°, {:.3} % of the diagonal\n\
         ours   (RANSAC {g_rot:.2}°): {ours_rot:.3}°, {:.3} % (fitness {:.3}, rmse {:.5})\n\
         Open3D (RANSAC {:.2}°): {o3d_rot:.3}°, {:.3} %",
        100.0 * pre_disp / diag,
        100.0 * ours_disp / diag,
        result.refined.evaluation.fitness,
        result.refined.evaluation.inlier_rmse,
        fx["open3d"]["ransac_errors"]["rotation_deg"]
            .as_f64()
            .unwrap(),
        100.0 * o3d_disp / diag,
    );
    ((ours_rot, ours_disp / diag), (o3d_rot, o3d_disp / diag))
}

/// The setting, σ = 1 % of the diagonal, with the paper's pipeline as it is: neither
/// Open3D (≈ 1°) nor we reach 0.5°, because with this much noise on both clouds and 30 %
/// unmatched points, point-to-point ICP's minimum itself sits about a degree from the truth.
/// Both stay within 1 % of the diagonal.
#[test]
fn alg3_at_one_percent_noise_matches_open3d() {
    let ((rot, disp), (o3d_rot, _)) = run_fixture(&fixture_dir(), false, 0);
    assert!(disp < 0.01, "displacement {disp} of the diagonal");
    assert!(
        rot < o3d_rot.max(0.5) + 0.5,
        "rotation {rot}° vs Open3D {o3d_rot}°"
    );
}

/// The setting with the local-plane denoising before ICP (`--denoise-radius`): the
/// < 0.5° and < 1 % targets hold (measured 0.29°, 0.12 % with RANSAC seed 0), whatever
/// RANSAC's seed.
#[test]
fn denoised_alg3_at_one_percent_noise_meets_the_targets() {
    for seed in 0..3 {
        let ((rot, disp), (o3d_rot, o3d_disp)) = run_fixture(&fixture_dir(), true, seed);
        assert!(
            rot < 0.5 && disp < 0.01,
            "seed {seed}: ours {rot}°, {disp}; Open3D {o3d_rot}°, {o3d_disp}"
        );
        assert!(rot < 0.5 * o3d_rot, "ours {rot}° vs Open3D {o3d_rot}°");
    }
}

/// σ = 0.2 % of the diagonal: the < 0.5° and < 1 % targets hold with and without denoising.
#[test]
fn alg3_at_low_noise_recovers_the_similarity() {
    for denoise in [false, true] {
        let ((rot, disp), (o3d_rot, o3d_disp)) = run_fixture(&low_noise_dir(), denoise, 0);
        assert!(
            rot < 0.5 && disp < 0.01,
            "denoise {denoise}: ours {rot}°, {disp}; Open3D {o3d_rot}°, {o3d_disp}"
        );
    }
}

#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn fixture_clouds_come_from_the_bunny() {
    let data = std::env::var("FEWVIEW_DATA")
        .expect("set FEWVIEW_DATA to the data folder (../shared/data)");
    let bunny = read_mesh(&PathBuf::from(data).join("meshes/bunny.obj")).unwrap();
    let target = read_points(&fixture_dir().join("target.ply")).unwrap();
    let tree = fewview_geom::knn::PointTree::new(
        &fewview_geom::sampling::sample_surface(&bunny, 200_000, 0).unwrap(),
    );
    let mean = target
        .positions
        .iter()
        .map(|p| tree.nearest(p).1)
        .sum::<f64>()
        / target.len() as f64;
    // Gaussian noise of σ = 1 % of the diagonal: mean distance to the surface ≈ σ·√(2/π).
    let diag = fewview_geom::mesh::bbox_diagonal(&bunny.vertices);
    assert!(mean < 0.012 * diag, "{mean} vs diagonal {diag}");
}
