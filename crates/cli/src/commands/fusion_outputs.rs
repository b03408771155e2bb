//! What `fusion` and `demo` share after the arguments: the photos' gains, training with a
//! progress bar, and the transition's render, scores and printout.

use std::path::Path;

use anyhow::Context;
use fewview_fusion::transition::{PathFrame, TransitionReport, transition_of_run};
use fewview_fusion::{FusionConfig, fusion_run};
use fewview_scene::photometric::PhotoGain;
use fewview_scene::synthetic::{DemoOptions, demo_render};
use fewview_scene::{Dataset, Image};
use fewview_splat::pipeline::{RunConfig, RunSummary};

use super::progress;

/// `photo_gains.json`: the exposure, white balance and vignetting each training photo was
/// given (nothing is written when the photos were left as they are).
pub fn write_gains(out: &Path, gains: &[(String, PhotoGain)]) -> anyhow::Result<()> {
    if gains.iter().all(|(_, g)| *g == PhotoGain::default()) {
        return Ok(());
    }
    let rows: Vec<serde_json::Value> = gains
        .iter()
        .map(|(name, gain)| serde_json::json!({ "view": name, "gain": gain }))
        .collect();
    let path = out.join("photo_gains.json");
    fewview_scene::atomic::write_bytes(&path, &serde_json::to_vec_pretty(&rows)?)
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Trains one fusion run with a progress bar.
pub fn train_with_progress(
    ds: &Dataset,
    cfg: &RunConfig,
    fusion: &FusionConfig,
    out: &Path,
    resume: bool,
) -> anyhow::Result<RunSummary> {
    let bar = progress::iterations(cfg.train.iterations as u64, "train");
    let (summary, _) = fusion_run(ds, cfg, fusion, out, resume, |p| {
        bar.set_position(p.iteration as u64);
        if p.iteration % 10 == 0 {
            bar.set_message(format!("loss {:.4}  {} Gaussians", p.loss, p.gaussians));
        }
    })
    .with_context(|| format!("fusion run in {}", out.display()))?;
    bar.finish_and_clear();
    Ok(summary)
}

/// Renders and scores the run's transition; on the demo scene against its ray-traced truth
/// (with LPIPS when `lpips`), whose exposure follows the training photos' gains log-linearly
/// between the two photos a frame lies between.
pub fn transition(
    ds: &Dataset,
    demo: Option<&DemoOptions>,
    out: &Path,
    lpips: bool,
) -> anyhow::Result<TransitionReport> {
    eprintln!("rendering and scoring the transition ...");
    let truth = demo.map(|opts| {
        let gains: Vec<PhotoGain> = ds.train.iter().map(|&i| opts.jitter.gain(i)).collect();
        move |f: &PathFrame<'_>| -> Image {
            let neutral = demo_render(f.camera, opts);
            if opts.jitter.is_none() {
                neutral
            } else {
                PhotoGain::apply_between(&gains[f.from], &gains[f.to], f.t, &neutral)
            }
        }
    });
    let truth_ref = truth
        .as_ref()
        .map(|f| f as &(dyn Fn(&PathFrame<'_>) -> Image + Sync));
    let lpips = lpips
        .then(fewview_metrics::lpips::Lpips::default_st_alex)
        .transpose()?;
    Ok(transition_of_run(ds, out, truth_ref, lpips.as_ref())?)
}

pub fn print_transition(r: &TransitionReport) {
    println!(
        "path warping err {:.5} (Δ {:.5}), warp PSNR {:.2} dB",
        r.warping_error.mean, r.warping_error.delta.mean, r.warp_psnr.mean
    );
    println!(
        "local popping    {:.1} levels of 255 (frames low-passed, σ 2 px; unfiltered {:.1}; \
         where two photos overlap {:.1})",
        r.popping.p99 * 255.0,
        r.popping_per_pixel.p99 * 255.0,
        r.popping_overlap.p99 * 255.0
    );
    if let (Some(l), Some(g)) = (r.held_out_lpips, r.held_out_lpips_gain_matched) {
        println!("held-out LPIPS   {l:.4}, gain-matched {g:.4} (ST-LPIPS AlexNet)");
    }
    if let Some(t) = &r.truth {
        println!(
            "path vs truth    PSNR {:.2} dB (Δ {:.3}; {:.2} after one gain for the clip), SSIM {:.4}{}",
            t.psnr.mean,
            t.psnr.delta.mean,
            t.psnr_gain_matched.mean,
            t.ssim.mean,
            t.lpips
                .as_ref()
                .map(|l| format!(", LPIPS {:.4}", l.mean))
                .unwrap_or_default()
        );
        println!(
            "truth's popping  {:.1} levels (unfiltered {:.1}); the clip's in excess of it {:.1}",
            t.truth_popping.p99 * 255.0,
            t.truth_popping_per_pixel.p99 * 255.0,
            t.popping_excess.p99 * 255.0
        );
    }
}
