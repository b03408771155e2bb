//! `--eval leave-one-out` of `train` and `fusion`: each interior photo held out in turn, the
//! run's method trained again on the rest in `RUN/leave_one_out/<photo>/`, and the held-out
//! photo scored. A finished sub-run is reused and an interrupted one resumed, so the whole
//! command can be run again after a stop.

use std::path::Path;

use anyhow::Context;
use fewview_fusion::leave_one_out::{
    LeaveOneOut, add_to_json, photos_to_leave_out, score_left_out, without,
};
use fewview_scene::Dataset;

/// Trains every leave-one-out sub-run of `ds` under `out` with `train(dataset, dir, resume)`,
/// scores them (LPIPS when `lpips`) and adds the scores to `out/metrics.json` (and
/// `out/transition.json` when it exists) under `leave_one_out`. `None` when the path has no
/// interior photo (fewer than three photos).
pub fn run(
    ds: &Dataset,
    out: &Path,
    lpips: bool,
    mut train: impl FnMut(&Dataset, &Path, bool) -> anyhow::Result<()>,
) -> anyhow::Result<Option<LeaveOneOut>> {
    let views = photos_to_leave_out(ds);
    if views.is_empty() {
        eprintln!("leave-one-out: fewer than three photos along the path, none can be held out");
        return Ok(None);
    }
    let lpips = lpips
        .then(fewview_metrics::lpips::Lpips::default_st_alex)
        .transpose()?;
    let mut scores = Vec::with_capacity(views.len());
    for (i, &view) in views.iter().enumerate() {
        let left_out = without(ds, view);
        let name = &ds.views[view].name;
        let dir = out.join("leave_one_out").join(name);
        if !dir.join("metrics.json").is_file() {
            eprintln!(
                "leave-one-out {}/{}: training without {name} → {}",
                i + 1,
                views.len(),
                dir.display()
            );
            train(&left_out, &dir, dir.join("checkpoint.bin").is_file())?;
        }
        scores.push(
            score_left_out(&left_out, &dir, lpips.as_ref())
                .with_context(|| format!("scoring {name} held out"))?,
        );
    }
    let report = LeaveOneOut::of(scores);
    for file in ["metrics.json", "transition.json"] {
        let path = out.join(file);
        if path.is_file() {
            add_to_json(&path, "leave_one_out", &report)?;
        }
    }
    Ok(Some(report))
}

pub fn print(report: &LeaveOneOut) {
    let lpips = |v: Option<f64>| v.map(|l| format!(", LPIPS {l:.4}")).unwrap_or_default();
    for v in &report.views {
        println!(
            "left out {:<7} PSNR {:.3} dB, SSIM {:.4}{} (gain-matched {:.3} dB)",
            v.view,
            v.psnr,
            v.ssim,
            lpips(v.lpips),
            v.gain_matched_psnr
        );
    }
    println!(
        "leave-one-out    PSNR {:.3} dB, SSIM {:.4}{} (gain-matched {:.3} dB, SSIM {:.4}{})",
        report.mean_psnr,
        report.mean_ssim,
        lpips(report.mean_lpips),
        report.mean_gain_matched_psnr,
        report.mean_gain_matched_ssim,
        lpips(report.mean_gain_matched_lpips)
    );
}
