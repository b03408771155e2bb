//! `fewview eval-video` on a GIF against a frame folder (both read by `fewview_video`):
//! a sequence with one flickering frame gives zero Δ between the steady frames and the same
//! per-frame values as the library on the decoded frames.

use std::process::Command;

use fewview_metrics::SsimOptions;
use fewview_metrics::temporal::{evaluate_sequence, frame_deltas};
use fewview_scene::Image;
use fewview_video::{ReadOptions, VideoOptions, read_video_with, write_video};

fn frame(shift: f32) -> Image {
    let mut img = Image::new(48, 40, 3);
    for y in 0..40 {
        for x in 0..48 {
            for c in 0..3 {
                let v = 0.5 + 0.35 * ((x as f32 * 0.3 + y as f32 * 0.2 + c as f32).sin()) + shift;
                img.set(x, y, c, v.clamp(0.0, 1.0));
            }
        }
    }
    img
}

#[test]
fn gif_against_frame_folder() {
    let dir = tempfile::tempdir().unwrap();
    let gt: Vec<Image> = (0..5).map(|_| frame(0.0)).collect();
    let out: Vec<Image> = (0..5)
        .map(|t| frame(if t == 2 { 0.08 } else { 0.0 }))
        .collect();
    let gt_dir = dir.path().join("gt");
    let out_gif = dir.path().join("out.gif");
    write_video(&gt_dir, &gt, 10.0, &VideoOptions::default()).unwrap();
    write_video(&out_gif, &out, 10.0, &VideoOptions::default()).unwrap();
    let json = dir.path().join("report.json");
    let status = Command::new(env!("CARGO_BIN_EXE_fewview"))
        .args(["eval-video", "--lpips", "none", "--output"])
        .arg(&out_gif)
        .arg("--ground-truth")
        .arg(&gt_dir)
        .arg("--json")
        .arg(&json)
        .stdout(std::process::Stdio::null())
        .status()
        .unwrap();
    assert!(status.success());
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(report["frames"], 5);
    // JSON has no infinity: an exact frame's PSNR (+∞) is written as null.
    let psnr: Vec<Option<f64>> =
        serde_json::from_value(report["psnr"]["per_frame"].clone()).unwrap();
    // The same numbers as the library on the decoded frames.
    let read = |p: &std::path::Path| read_video_with(p, &ReadOptions::default()).unwrap().0;
    let lib = evaluate_sequence(
        &read(&out_gif),
        &read(&gt_dir),
        &SsimOptions::default(),
        None,
        None,
    )
    .unwrap();
    assert_eq!(psnr.len(), 5);
    for (a, b) in psnr.iter().zip(&lib.psnr.per_frame) {
        match a {
            Some(a) => assert!((a - b).abs() < 1e-9, "{a} vs {b}"),
            None => assert!(b.is_infinite(), "null vs {b}"),
        }
    }
    assert!(
        lib.psnr.per_frame[2].is_finite(),
        "the flickering frame differs"
    );
    // Steady frames decode identically, so only the transitions into and out of frame 2 change.
    let d = frame_deltas(&lib.ssim.per_frame);
    assert!(
        d[0] == 0.0 && d[3] == 0.0 && d[1] > 0.0 && d[2] > 0.0,
        "{d:?}"
    );
    // Mismatched lengths are a one-line error naming both inputs and the problem.
    let short = dir.path().join("short.gif");
    write_video(&short, &out[..3], 10.0, &VideoOptions::default()).unwrap();
    let output = Command::new(env!("CARGO_BIN_EXE_fewview"))
        .args(["eval-video", "--lpips", "none", "--output"])
        .arg(&short)
        .arg("--ground-truth")
        .arg(&gt_dir)
        .output()
        .unwrap();
    assert!(!output.status.success());
    let err = String::from_utf8_lossy(&output.stderr);
    assert!(
        err.contains("3 output frames vs 5 ground-truth frames")
            && err.contains("short.gif against")
            && err.contains(&gt_dir.display().to_string()),
        "{err}"
    );
}
