//! Transition videos and how smooth they are (the fusion paper, "Splat-based Gradient-domain Fusion for
//! Seamless View Transition"): the camera moves through the training views in order and back,
//! 8 s at 20 fps as the paper's study clips, and the frames are scored for temporal consistency.
//!
//! * **Warping error** (Lai et al. 2018, Eq. 8) between consecutive frames, with the *exact*
//!   backward flow from the rendered depth and the two cameras, masked where the forward and
//!   backward flows disagree (occlusion) ([`fewview_metrics::flow::flow_between`]). Its PSNR
//!   form, `warp PSNR_t = PSNR(frame_t, warp(frame_{t−1}))`, and the Δ of that series (mean of
//!   `|m_t − m_{t−1}|`) show jumps. Warping error alone rewards blur: report it beside the
//!   held-out PSNR/SSIM/LPIPS.
//! * With a **ground truth along the path** (the demo scene's ray tracer): per-frame PSNR, SSIM,
//!   LPIPS against the true frames, their Δ, and the truth's own warping error (its view-dependent
//!   highlight moves, so an exact render's warping error is that, not 0).

use fewview_metrics::flow::path_flows;
use fewview_metrics::lpips::Lpips;
use fewview_metrics::psnr::psnr_from_mse;
use fewview_metrics::ssim::SsimOptions;
use fewview_metrics::temporal::{MetricSeries, evaluate_sequence, warping_errors};
use std::path::Path;

use fewview_geom::stereo::pairs::order_along_baseline;
use fewview_scene::{Camera, Dataset, Image};
use fewview_splat::eval::render_model;
use fewview_splat::model::GaussianModel;
use fewview_splat::ply::read_ply;
use fewview_splat::raster::{RenderCamera, RenderSettings};
use fewview_video::{VideoOptions, write_video};
use rayon::prelude::*;
use serde::Serialize;

use crate::error::FusionError;
use crate::reproject::surface_depth;

/// Length and rate of the paper's study clips.
pub const CLIP_SECONDS: f32 = 8.0;
pub const CLIP_FPS: f32 = 20.0;

/// Frames of one clip.
pub fn clip_frames() -> usize {
    (CLIP_SECONDS * CLIP_FPS).round() as usize
}

/// `frames` cameras along a smooth loop through `keys` in order and back to the first
/// (SLERP rotations, linear centres and intrinsics, eased with smoothstep on each segment so the
/// camera slows down at each training view instead of turning sharply). The first key starts the
/// loop; it does not end it twice.
pub fn transition_path(keys: &[Camera], frames: usize) -> Vec<Camera> {
    if keys.len() < 2 {
        return keys.iter().cloned().cycle().take(frames).collect();
    }
    let there_and_back: Vec<&Camera> = keys.iter().chain(keys.iter().rev().skip(1)).collect();
    let segments = there_and_back.len() - 1;
    (0..frames)
        .map(|i| {
            let u = i as f64 * segments as f64 / frames as f64;
            let s = (u.floor() as usize).min(segments - 1);
            let f = u - s as f64;
            let eased = f * f * (3.0 - 2.0 * f);
            there_and_back[s].interpolate(there_and_back[s + 1], eased)
        })
        .collect()
}

/// Frames rendered along a path, with the depth of their visible surface.
pub struct RenderedPath {
    pub cameras: Vec<Camera>,
    pub frames: Vec<Image>,
    /// z-depth per frame, 0 where the render is nearly transparent.
    pub depths: Vec<Vec<f32>>,
}

/// Renders `model` at every camera of `path`.
pub fn render_path(
    model: &GaussianModel,
    path: &[Camera],
    settings: &RenderSettings,
) -> RenderedPath {
    let (frames, depths) = path
        .par_iter()
        .map(|c| {
            let r = render_model(model, &RenderCamera::from(c), settings);
            let depth = surface_depth(&r.depth.data, &r.alpha.data, 0.5);
            (r.rgb, depth)
        })
        .unzip();
    RenderedPath {
        cameras: path.to_vec(),
        frames,
        depths,
    }
}

/// Scores of a path against its ground truth.
#[derive(Clone, Debug, Serialize)]
pub struct PathTruth {
    pub psnr: MetricSeries,
    pub ssim: MetricSeries,
    /// ST-LPIPS AlexNet, when computed.
    pub lpips: Option<MetricSeries>,
    /// The truth's own warping error under the same flows.
    pub truth_warping_error: MetricSeries,
}

/// How smooth a transition is (see the module docs).
#[derive(Clone, Debug, Serialize)]
pub struct TransitionReport {
    pub frames: usize,
    pub fps: f32,
    /// Warping error per transition (`t = 1..T−1`), its mean and Δ.
    pub warping_error: MetricSeries,
    /// `PSNR(frame_t, warp(frame_{t−1}))` per transition, its mean and Δ.
    pub warp_psnr: MetricSeries,
    /// Fraction of pixels the flows trust (mean over transitions).
    pub flow_coverage: f64,
    pub truth: Option<PathTruth>,
    /// Mean ST-LPIPS AlexNet of the held-out views (sharpness beside the warping error), when
    /// computed.
    pub held_out_lpips: Option<f64>,
}

/// Scores a rendered path; `truth` (one image per frame) adds the ground-truth scores, `lpips`
/// the perceptual ones.
pub fn score_transition(
    path: &RenderedPath,
    truth: Option<&[Image]>,
    lpips: Option<&Lpips>,
) -> Result<TransitionReport, FusionError> {
    let flows = path_flows(&path.cameras, &path.depths)?;
    let errors = warping_errors(&path.frames, &flows)?;
    // The warping error sums the squared difference over the 3 channels.
    let warp_psnr: Vec<f64> = errors.iter().map(|e| psnr_from_mse(e / 3.0)).collect();
    let coverage = flows
        .iter()
        .map(|f| match &f.valid {
            Some(v) => v.iter().filter(|&&b| b).count() as f64 / v.len().max(1) as f64,
            None => 1.0,
        })
        .sum::<f64>()
        / flows.len().max(1) as f64;
    let truth = match truth {
        Some(gt) => {
            let perceptual = lpips.map(|l| l as &dyn fewview_metrics::temporal::PerceptualDistance);
            let r = evaluate_sequence(&path.frames, gt, &SsimOptions::default(), perceptual, None)?;
            Some(PathTruth {
                psnr: r.psnr,
                ssim: r.ssim,
                lpips: r.lpips,
                truth_warping_error: MetricSeries::new(
                    "warping_error",
                    warping_errors(gt, &flows)?,
                ),
            })
        }
        None => None,
    };
    Ok(TransitionReport {
        frames: path.frames.len(),
        fps: CLIP_FPS,
        warping_error: MetricSeries::new("warping_error", errors),
        warp_psnr: MetricSeries::new("warp_psnr", warp_psnr),
        flow_coverage: coverage,
        truth,
        held_out_lpips: None,
    })
}

/// Renders the trained run in `dir` along the transition path through `ds`'s training views
/// (ordered along their baseline), writes `transition.mp4` and `transition.json`, and returns
/// the scores. `truth` renders the ground truth of any camera (the demo scene's ray tracer).
pub fn transition_of_run(
    ds: &Dataset,
    dir: &Path,
    truth: Option<&(dyn Fn(&Camera) -> Image + Sync)>,
    lpips: Option<&Lpips>,
) -> Result<TransitionReport, FusionError> {
    let model = read_ply(&dir.join("point_cloud.ply"))?;
    let settings = RenderSettings {
        background: ds.background,
        sh_degree: model.sh_degree(),
        ..RenderSettings::default()
    };
    let cameras: Vec<&Camera> = ds.train_views().map(|v| &v.camera).collect();
    let keys: Vec<Camera> = order_along_baseline(&cameras)
        .into_iter()
        .map(|i| cameras[i].clone())
        .collect();
    let path = transition_path(&keys, clip_frames());
    let rendered = render_path(&model, &path, &settings);
    let truth_frames: Option<Vec<Image>> = truth.map(|f| path.par_iter().map(f).collect());
    let mut report = score_transition(&rendered, truth_frames.as_deref(), lpips)?;
    report.held_out_lpips = lpips
        .map(|l| held_out_lpips(ds, &model, &settings, l))
        .transpose()?;
    write_video(
        &dir.join("transition.mp4"),
        &rendered.frames,
        CLIP_FPS,
        &VideoOptions::default(),
    )?;
    let json =
        serde_json::to_vec_pretty(&report).map_err(|e| FusionError::Invalid(e.to_string()))?;
    fewview_scene::atomic::write_bytes(&dir.join("transition.json"), &json)?;
    Ok(report)
}

/// Mean LPIPS of `model`'s renders of the held-out views against their photos.
pub fn held_out_lpips(
    ds: &Dataset,
    model: &GaussianModel,
    settings: &RenderSettings,
    lpips: &Lpips,
) -> Result<f64, FusionError> {
    let views: Vec<_> = ds.test_views().collect();
    let mut sum = 0.0;
    for v in &views {
        let r = render_model(model, &RenderCamera::from(&v.camera), settings);
        sum += lpips.distance(&r.rgb, &v.image)?;
    }
    Ok(sum / views.len().max(1) as f64)
}

#[cfg(test)]
mod tests {
    use fewview_scene::Intrinsics;
    use nalgebra::Vector3;

    use super::*;

    fn key(x: f64) -> Camera {
        Camera::look_at(
            Intrinsics::centered(50.0, 32, 24),
            Vector3::new(x, -4.0, 1.0),
            Vector3::zeros(),
            Vector3::z(),
        )
    }

    #[test]
    fn the_path_visits_the_keys_in_order_and_back() {
        let keys = [key(-1.0), key(0.0), key(2.0)];
        let path = transition_path(&keys, 160);
        assert_eq!(path.len(), 160);
        // 4 segments of 40 frames: keys at frames 0, 40, 80 (the last), 120 (the middle again).
        for (frame, k) in [(0, 0), (40, 1), (80, 2), (120, 1)] {
            assert!(
                (path[frame].center() - keys[k].center()).norm() < 1e-9,
                "frame {frame}"
            );
        }
        // Eased: the camera moves slowly next to a key and fastest between keys.
        let step = |i: usize| (path[i + 1].center() - path[i].center()).norm();
        assert!(step(0) < 0.2 * step(20));
        assert!(step(39) < 0.2 * step(20));
    }
}
