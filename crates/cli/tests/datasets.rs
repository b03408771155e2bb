//! The engine core's acceptance runs on the shared datasets, through the `fewview` binary with
//! the default command a user would type: LLFF fern 3-view, NeRF-synthetic lego 8-view and DTU
//! scan65 3-view with masks. They need `FEWVIEW_DATA` (CI sets it to `../shared/data`).

// Tests report what they measured.
#![allow(clippy::print_stdout, clippy::print_stderr)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

fn data_dir() -> PathBuf {
    let dir = std::env::var_os("FEWVIEW_DATA")
        .expect("FEWVIEW_DATA must name the shared data folder (e.g. ../shared/data)");
    PathBuf::from(dir)
}

/// Runs `fewview train` with `args`, prints its wall time, and returns the run's `metrics.json`.
fn train(name: &str, args: &[&str]) -> serde_json::Value {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join(name);
    let start = Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_fewview"))
        .arg("train")
        .args(args)
        .arg("--out")
        .arg(&run)
        .output()
        .expect("run fewview");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{name}: {}\n{stdout}",
        String::from_utf8_lossy(&out.stderr)
    );
    eprintln!(
        "{name}: {:.0} s wall\n{stdout}",
        start.elapsed().as_secs_f64()
    );
    read_json(&run.join("metrics.json"))
}

fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

fn arg(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn fern_three_views_default_command_matches_3dgs_from_a_stereo_start() {
    let fern = data_dir().join("llff/fern");
    let metrics = train("fern", &["--data", arg(&fern)]);
    let test = &metrics["test"];
    let names: Vec<&str> = test["views"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v["name"].as_str().unwrap())
        .collect();
    assert_eq!(names.len(), 3, "standard test views 0, 8, 16: {names:?}");
    assert_eq!(
        metrics["init"], "stereo",
        "the default starts from stereo on fern"
    );
    let psnr = test["mean_psnr"].as_f64().unwrap();
    // Published 3DGS from a stereo-fused start on LLFF 3-view: 19.22 dB (from random: 16.5).
    assert!(
        psnr >= 19.2,
        "fern 3-view held-out PSNR {psnr:.2} dB < 19.2"
    );
}

#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn lego_eight_views_default_command_beats_published_3dgs() {
    let lego = data_dir().join("nerf_synthetic/lego");
    // The default command: 3000 iterations over random backgrounds (the images have alpha).
    let metrics = train("lego", &["--data", arg(&lego)]);
    let test = &metrics["test"];
    assert_eq!(test["views"].as_array().unwrap().len(), 25);
    let psnr = test["mean_psnr"].as_f64().unwrap();
    // Published 3DGS with 8 views: ~22.2 dB; issue 2 asks ≥ 22.5.
    assert!(
        psnr >= 22.5,
        "lego 8-view held-out PSNR {psnr:.2} dB < 22.5"
    );
}

#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn dtu_scan65_three_views_reports_masked_scores() {
    let scan = data_dir().join("dtu/scan65");
    let metrics = train(
        "scan65",
        &[
            "--data",
            arg(&scan),
            "--downscale",
            "2",
            "--train-views",
            "22,25,28",
            "--iterations",
            "1000",
        ],
    );
    let test = &metrics["test"];
    let views = test["views"].as_array().unwrap();
    assert_eq!(views.len(), 25, "the standard DTU test list");
    // Every held-out view has its object mask, so every view has a masked score.
    for v in views {
        let m = v["masked_psnr"].as_f64();
        assert!(
            m.is_some_and(f64::is_finite),
            "{}: no masked PSNR",
            v["name"]
        );
    }
    let masked = test["mean_masked_psnr"].as_f64().unwrap();
    let full = test["mean_psnr"].as_f64().unwrap();
    eprintln!("scan65 3-view 400x300: masked PSNR {masked:.2} dB, full-image PSNR {full:.2} dB");
    // Measured on 2026-11-27 (2-core development machine, stereo start, this command): masked
    // 17.80 dB, full-image 17.68 dB, the same as on 2026-11-26; from the random box it was
    // 8.42 dB. The floor sits 1 dB under the measurement, so losing the stereo start or a
    // regression in training fails here.
    assert!(
        masked >= 16.8,
        "scan65 3-view masked PSNR {masked:.2} dB < 16.8 (measured 17.80)"
    );
}
