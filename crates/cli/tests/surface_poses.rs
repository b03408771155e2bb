//! The surface paper's pose recovery on more than the scan it was developed on: the default
//! `fewview surface` command's matching, global start and epipolar warm-up on DTU scan37 and
//! scan65 (wide triplet 22, 25, 28 at 400 × 300, σ = 0.15 noise), stopped after one training
//! iteration. They need `FEWVIEW_DATA` (CI sets it to `../shared/data`).

// Tests report what they measured.
#![allow(clippy::print_stdout, clippy::print_stderr)]

use std::path::PathBuf;
use std::process::Command;

fn scan(name: &str) -> PathBuf {
    let dir = std::env::var_os("FEWVIEW_DATA")
        .expect("FEWVIEW_DATA must name the shared data folder (e.g. ../shared/data)");
    PathBuf::from(dir).join("dtu").join(name)
}

/// The run's `metrics.json` after matching, the warm-up and one iteration.
fn warm_up(name: &str, seed: &str) -> serde_json::Value {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join(name);
    let done = Command::new(env!("CARGO_BIN_EXE_fewview"))
        .arg("surface")
        .arg("--data")
        .arg(scan(name))
        .args([
            "--train-views",
            "22,25,28",
            "--downscale",
            "2",
            "--seed",
            seed,
        ])
        .args([
            "--iterations",
            "1",
            "--mesh-resolution",
            "32",
            "--eval-views",
            "1",
        ])
        .args(["--eval-scale", "4", "--checkpoint-every", "0", "--out"])
        .arg(&out)
        .output()
        .expect("run fewview");
    let stderr = String::from_utf8_lossy(&done.stderr);
    assert!(done.status.success(), "{name}: {stderr}");
    eprintln!("{name}:\n{stderr}");
    serde_json::from_slice(&std::fs::read(out.join("metrics.json")).unwrap()).unwrap()
}

/// Rotation error (degrees) of one of the report's pose errors.
fn rotation(metrics: &serde_json::Value, key: &str) -> f64 {
    metrics[key]["rotation_deg"].as_f64().unwrap()
}

/// The warm-up ends better than it started, by the matches and by the truth.
fn assert_not_worse(name: &str, metrics: &serde_json::Value) {
    let warmup = &metrics["warmup"];
    assert!(warmup["skipped"].is_null(), "{name}: {warmup}");
    let (before, after) = (
        warmup["initial_cost"].as_f64().unwrap(),
        warmup["final_cost"].as_f64().unwrap(),
    );
    assert!(after < before, "{name}: epipolar cost {before} → {after}");
    let (r0, r1) = (
        rotation(metrics, "initial_pose_error"),
        rotation(metrics, "warmup_pose_error"),
    );
    assert!(r1 < r0, "{name}: rotation {r0}° → {r1}°");
}

/// scan37's wide triplet: the local warm-up alone settled 12.8° off (from 12.4°); from the
/// global start the warm-up must end below 0.3°.
#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn scan37_wide_warm_up_recovers_the_poses() {
    let metrics = warm_up("scan37", "0");
    assert_not_worse("scan37", &metrics);
    let r = rotation(&metrics, "warmup_pose_error");
    assert!(r < 0.3, "scan37 warm-up rotation error {r}°");
    // The tracks' bundle adjustment then halves it (measured 0.189° → 0.084°).
    let bundled = rotation(&metrics, "bundle_adjustment_pose_error");
    assert!(
        bundled < 0.12 && bundled < r,
        "scan37 bundle adjustment {r}° → {bundled}°"
    );
    let pairs = metrics["global_start_rotation_errors_deg"]
        .as_array()
        .unwrap();
    assert_eq!(
        pairs.len(),
        3,
        "every pair of the triplet has a relative pose"
    );
}

/// scan65's wide triplet, where the local warm-up already worked: no worse than its 0.103°.
#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn scan65_wide_warm_up_is_not_worse_with_the_global_start() {
    let metrics = warm_up("scan65", "0");
    assert_not_worse("scan65", &metrics);
    let r = rotation(&metrics, "warmup_pose_error");
    assert!(r < 0.15, "scan65 warm-up rotation error {r}°");
    // Here the bundle adjustment moves away from the truth (measured 0.103° → 0.154°).
    let bundled = rotation(&metrics, "bundle_adjustment_pose_error");
    assert!(bundled < 0.2, "scan65 bundle adjustment {r}° → {bundled}°");
}

/// scan37's wide triplet at seed 2: the dense growth from SIFT seeds reached only 2 matches for
/// the weakest pair and the warm-up declined (the run ended at 12.4°). The dense matcher now
/// seeds the growth again, and the poses come back (measured 12.42° → warm-up 0.489° → bundle
/// 0.424° → patches 0.169°).
#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn scan37_wide_seed_2_needs_the_dense_matcher() {
    let metrics = warm_up("scan37", "2");
    let why = metrics["densified_because"].as_str().unwrap_or_default();
    assert!(why.contains("dense matcher"), "{why}");
    assert_not_worse("scan37 seed 2", &metrics);
    let adjusted = rotation(&metrics, "patch_adjustment_pose_error");
    assert!(adjusted < 0.3, "scan37 seed 2: {adjusted}°");
}
