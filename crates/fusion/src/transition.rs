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
//! * **Local popping** ([`fewview_metrics::popping`]): the tail of the same warped differences,
//!   which sees a seam or a patch that switches colour where the mean does not; its per-transition
//!   maps are written as a video. It is reported over the whole frame and over the pixels whose
//!   surface at least two training views show ([`OVERLAP_VIEWS`]; in their frusta and not
//!   behind a nearer surface of their rendered depth), where colours are fused between photos;
//!   the rest of a frame (its borders as the camera swings, what one photo sees past an edge)
//!   shows what one photo or none constrains.
//! * With a **ground truth along the path** (the demo scene's ray tracer): per-frame PSNR, SSIM,
//!   LPIPS against the true frames, their Δ, and the truth's own warping error and popping (its
//!   view-dependent highlight moves, so an exact render's warping error is that, not 0), and the
//!   clip's popping in excess of the truth's, transition by transition. When the
//!   training photos' exposures differ, the truth of a frame between two photos has their gains
//!   interpolated log-linearly ([`fewview_scene::photometric`]): the natural colour transition.
//!   The path PSNR is also given after one gain per channel for the whole clip
//!   ([`fewview_metrics::gain::sequence_gain_matched`]): a model trained with per-photo colour
//!   transforms renders in a colour space of its own, and one gain undoes that but not a ramp.

use fewview_geom::colormap::colorize_range;
use fewview_metrics::flow::{Onlooker, path_flows, views_seeing};
use fewview_metrics::gain::sequence_gain_matched;
use fewview_metrics::lpips::Lpips;
use fewview_metrics::popping::{
    Popping, local_popping, local_popping_with, popping_excess, popping_of_maps,
};
use fewview_metrics::psnr::{psnr, psnr_from_mse};
use fewview_metrics::ssim::SsimOptions;
use fewview_metrics::temporal::{
    MetricSeries, evaluate_sequence, warping_errors, warping_errors_where_defined,
};
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

/// Where a frame of the transition path lies: `t` of the (eased) way from key `from` to key
/// `to` (indices into the keys).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathPosition {
    pub from: usize,
    pub to: usize,
    pub t: f64,
}

/// The positions of `frames` frames along a smooth loop through `keys` keys in order and back to
/// the first, eased with smoothstep on each segment so the camera slows down at each key
/// instead of turning sharply. The first key starts the loop; it does not end it twice.
pub fn transition_positions(keys: usize, frames: usize) -> Vec<PathPosition> {
    if keys == 0 {
        return Vec::new();
    }
    if keys == 1 {
        let still = PathPosition {
            from: 0,
            to: 0,
            t: 0.0,
        };
        return vec![still; frames];
    }
    let there_and_back: Vec<usize> = (0..keys).chain((0..keys - 1).rev()).collect();
    let segments = there_and_back.len() - 1;
    (0..frames)
        .map(|i| {
            let u = i as f64 * segments as f64 / frames as f64;
            let s = (u.floor() as usize).min(segments - 1);
            let f = u - s as f64;
            PathPosition {
                from: there_and_back[s],
                to: there_and_back[s + 1],
                t: f * f * (3.0 - 2.0 * f),
            }
        })
        .collect()
}

/// `frames` cameras along the loop of [`transition_positions`] through `keys` (SLERP rotations,
/// linear centres and intrinsics).
pub fn transition_path(keys: &[Camera], frames: usize) -> Vec<Camera> {
    transition_positions(keys.len(), frames)
        .into_iter()
        .map(|p| keys[p.from].interpolate(&keys[p.to], p.t))
        .collect()
}

/// One frame of the path as the ground truth sees it: its camera, and where it lies between the
/// training views (`from`, `to`: positions in the dataset's training order).
pub struct PathFrame<'a> {
    pub camera: &'a Camera,
    pub from: usize,
    pub to: usize,
    pub t: f64,
}

/// Renders the ground truth of a path frame (the demo scene's ray tracer, with the exposure of
/// the photos around it).
pub type TruthRenderer<'a> = &'a (dyn Fn(&PathFrame<'_>) -> Image + Sync);

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
    /// PSNR after one least-squares gain per channel for the whole clip. The gain minimises the
    /// clip's squared error, not the mean of the frames' PSNR, so where frames near the photos
    /// are much sharper than those between them this can read below the raw figure.
    pub psnr_gain_matched: MetricSeries,
    pub ssim: MetricSeries,
    /// ST-LPIPS AlexNet, when computed.
    pub lpips: Option<MetricSeries>,
    /// The truth's own warping error under the same flows.
    pub truth_warping_error: MetricSeries,
    /// The truth's own local popping under the same flows (a moving highlight pops a little).
    pub truth_popping: Popping,
    /// The same without the low-pass.
    pub truth_popping_per_pixel: Popping,
    /// Local popping in excess of the truth's along the same flows
    /// ([`fewview_metrics::popping::popping_excess`]): what the clip adds to what the scene
    /// itself does between the frames.
    pub popping_excess: Popping,
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
    /// Local popping ([`fewview_metrics::popping`]): the 99th percentile over transitions of
    /// the 99th percentile over co-visible pixels of `|frame_t − warp(frame_{t−1})|`, the frames
    /// low-passed with a Gaussian of two pixels and motion boundaries left out.
    pub popping: Popping,
    /// The same without the low-pass: resampling of sharp edges counts too.
    pub popping_per_pixel: Popping,
    /// Local popping over the pixels whose surface at least [`OVERLAP_VIEWS`] training views show
    /// ([`overlap_masks`]).
    pub popping_overlap: Popping,
    /// Fraction of pixels the flows trust (mean over transitions).
    pub flow_coverage: f64,
    pub truth: Option<PathTruth>,
    /// Mean ST-LPIPS AlexNet of the held-out views (sharpness beside the warping error), raw
    /// and gain-matched, when computed.
    pub held_out_lpips: Option<f64>,
    pub held_out_lpips_gain_matched: Option<f64>,
}

/// A scored path and the per-transition popping maps (`NaN` where the frames share no pixel).
pub struct ScoredPath {
    pub report: TransitionReport,
    pub popping_maps: Vec<Vec<f32>>,
}

/// Training views that must show a pixel's surface for [`TransitionReport::popping_overlap`].
pub const OVERLAP_VIEWS: u8 = 2;

/// Per transition `t = 1..T−1`, the pixels of frame `t` whose surface at least
/// [`OVERLAP_VIEWS`] of the `training` views show (in their frusta and not hidden behind a
/// nearer surface of their rendered depth, [`views_seeing`]): where the photos' colours meet.
pub fn overlap_masks(
    path: &RenderedPath,
    training: &RenderedPath,
) -> Result<Vec<Vec<bool>>, FusionError> {
    let onlookers: Vec<Onlooker<'_>> = training
        .cameras
        .iter()
        .zip(&training.depths)
        .map(|(camera, depth)| Onlooker {
            camera,
            depth: Some(depth),
        })
        .collect();
    (1..path.cameras.len())
        .into_par_iter()
        .map(|t| {
            let counts = views_seeing(&path.cameras[t], &path.depths[t], &onlookers)?;
            Ok(counts.into_iter().map(|c| c >= OVERLAP_VIEWS).collect())
        })
        .collect()
}

/// Scores a rendered path through the `training` views (rendered by the same model, for their
/// depth); `truth` (one image per frame) adds the ground-truth scores, `lpips` the perceptual
/// ones.
pub fn score_transition(
    path: &RenderedPath,
    training: &RenderedPath,
    truth: Option<&[Image]>,
    lpips: Option<&Lpips>,
) -> Result<ScoredPath, FusionError> {
    let flows = path_flows(&path.cameras, &path.depths)?;
    // A transition whose flow leaves the frame everywhere (the model shows nothing there) is
    // not scored: NaN in the series, left out of its mean.
    let errors = warping_errors_where_defined(&path.frames, &flows)?;
    let (popping, popping_maps) = local_popping(&path.frames, &flows)?;
    let popping_overlap = popping_of_maps(&popping_maps, Some(&overlap_masks(path, training)?))?;
    let popping_per_pixel = local_popping_with(&path.frames, &flows, 0.0)?.0;
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
            let matched = sequence_gain_matched(&path.frames, gt)?
                .iter()
                .zip(gt)
                .map(|(m, g)| psnr(m, g))
                .collect::<Result<Vec<f64>, _>>()?;
            let truth_popping = local_popping(gt, &flows)?.0;
            Some(PathTruth {
                psnr: r.psnr,
                psnr_gain_matched: MetricSeries::new("psnr", matched),
                ssim: r.ssim,
                lpips: r.lpips,
                truth_warping_error: MetricSeries::new(
                    "warping_error",
                    warping_errors(gt, &flows)?,
                ),
                popping_excess: popping_excess(&popping, &truth_popping)?,
                truth_popping,
                truth_popping_per_pixel: local_popping_with(gt, &flows, 0.0)?.0,
            })
        }
        None => None,
    };
    let report = TransitionReport {
        frames: path.frames.len(),
        fps: CLIP_FPS,
        warping_error: MetricSeries::over_scored("warping_error", errors),
        warp_psnr: MetricSeries::over_scored("warp_psnr", warp_psnr),
        popping,
        popping_per_pixel,
        popping_overlap,
        flow_coverage: coverage,
        truth,
        held_out_lpips: None,
        held_out_lpips_gain_matched: None,
    };
    Ok(ScoredPath {
        report,
        popping_maps,
    })
}

/// The popping maps' colour scale: 0 to this difference (25 of 255 levels) over the ramp.
pub const POPPING_MAP_MAX: f32 = 0.1;

/// Renders the trained run in `dir` along the transition path through `ds`'s training views
/// (ordered along their baseline; every frame the size of the first training view, photos of
/// other sizes keeping their field of view) and writes `transition.mp4`, `transition.json`,
/// `midpath.jpg` ([`midpath_picture`]), the popping
/// maps (`popping.mp4`, one frame per transition, 0 to [`POPPING_MAP_MAX`] on the ramp, black
/// where the frames share nothing) and the worst transition's map (`popping_worst.png`), and
/// returns the scores. `truth` renders the ground truth of any path frame (the demo scene's ray
/// tracer).
pub fn transition_of_run(
    ds: &Dataset,
    dir: &Path,
    truth: Option<TruthRenderer<'_>>,
    lpips: Option<&Lpips>,
) -> Result<TransitionReport, FusionError> {
    let (model, settings) = model_of_run(ds, dir)?;
    // One frame size for the clip: photos of other sizes keep their field of view.
    let first = &ds.views[ds.train[0]].camera;
    let (w, h) = (first.width(), first.height());
    let keys: Vec<Camera> = ds.train_views().map(|v| v.camera.resized(w, h)).collect();
    let cameras: Vec<&Camera> = keys.iter().collect();
    let order = order_along_baseline(&cameras);
    let positions = transition_positions(order.len(), clip_frames());
    let path: Vec<Camera> = positions
        .iter()
        .map(|p| cameras[order[p.from]].interpolate(cameras[order[p.to]], p.t))
        .collect();
    let rendered = render_path(&model, &path, &settings);
    let at_keys = render_path(&model, &keys, &settings);
    let truth_frames: Option<Vec<Image>> = truth.map(|f| {
        path.par_iter()
            .zip(&positions)
            .map(|(camera, p)| {
                f(&PathFrame {
                    camera,
                    from: order[p.from],
                    to: order[p.to],
                    t: p.t,
                })
            })
            .collect()
    });
    let ScoredPath {
        mut report,
        popping_maps,
    } = score_transition(&rendered, &at_keys, truth_frames.as_deref(), lpips)?;
    if let Some(l) = lpips.filter(|_| !ds.test.is_empty()) {
        let (raw, matched) = held_out_lpips(ds, &model, &settings, l)?;
        report.held_out_lpips = Some(raw);
        report.held_out_lpips_gain_matched = Some(matched);
    }
    write_video(
        &dir.join("transition.mp4"),
        &rendered.frames,
        CLIP_FPS,
        &VideoOptions::default(),
    )?;
    write_popping_maps(dir, &rendered, &popping_maps, &report.popping)?;
    let ordered: Vec<&Camera> = order.iter().map(|&i| cameras[i]).collect();
    midpath_picture(&model, &ordered, &settings).save_jpeg(&dir.join("midpath.jpg"))?;
    let json =
        serde_json::to_vec_pretty(&report).map_err(|e| FusionError::Invalid(e.to_string()))?;
    fewview_scene::atomic::write_bytes(&dir.join("transition.json"), &json)?;
    Ok(report)
}

/// Widest a frame of [`midpath_picture`] is drawn, and how many frames share a row.
pub const MIDPATH_FRAME_WIDTH: usize = 480;
pub const MIDPATH_COLUMNS: usize = 4;

/// The frames halfway between neighbouring photos of the path (`keys` in path order), side by
/// side, row after row, each at most [`MIDPATH_FRAME_WIDTH`] pixels wide: where floaters and
/// seams show first, since no photo constrains those views.
pub fn midpath_picture(
    model: &GaussianModel,
    keys: &[&Camera],
    settings: &RenderSettings,
) -> Image {
    let mids: Vec<Camera> = keys
        .windows(2)
        .map(|pair| pair[0].interpolate(pair[1], 0.5))
        .collect();
    let frames: Vec<Image> = mids
        .par_iter()
        .map(|c| {
            let frame = render_model(model, &RenderCamera::from(c), settings).rgb;
            let scale = (MIDPATH_FRAME_WIDTH as f64 / frame.width as f64).min(1.0);
            let w = ((frame.width as f64 * scale).round() as usize).max(1);
            let h = ((frame.height as f64 * scale).round() as usize).max(1);
            frame.resize(w, h)
        })
        .collect();
    tile(&frames, MIDPATH_COLUMNS)
}

/// `frames` laid out `columns` to a row on a black canvas (each cell as large as the largest).
fn tile(frames: &[Image], columns: usize) -> Image {
    let cell_w = frames.iter().map(|f| f.width).max().unwrap_or(1);
    let cell_h = frames.iter().map(|f| f.height).max().unwrap_or(1);
    let cols = columns.min(frames.len()).max(1);
    let rows = frames.len().div_ceil(cols).max(1);
    let mut canvas = Image::new(cols * cell_w, rows * cell_h, 3);
    for (k, f) in frames.iter().enumerate() {
        let (x0, y0) = ((k % cols) * cell_w, (k / cols) * cell_h);
        for y in 0..f.height {
            for x in 0..f.width {
                for c in 0..3 {
                    canvas.set(x0 + x, y0 + y, c, f.pixel(x, y)[c.min(f.channels - 1)]);
                }
            }
        }
    }
    canvas
}

/// `popping.mp4` and `popping_worst.png` (see [`transition_of_run`]).
fn write_popping_maps(
    dir: &Path,
    rendered: &RenderedPath,
    maps: &[Vec<f32>],
    popping: &Popping,
) -> Result<(), FusionError> {
    let (w, h) = (rendered.frames[0].width, rendered.frames[0].height);
    let pictures: Vec<Image> = maps
        .iter()
        .map(|m| colorize_range(m, w, h, 0.0, POPPING_MAP_MAX))
        .collect();
    write_video(
        &dir.join("popping.mp4"),
        &pictures,
        CLIP_FPS,
        &VideoOptions::default(),
    )?;
    let worst = popping
        .per_transition
        .iter()
        .enumerate()
        .filter(|(_, v)| v.is_finite())
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map_or(0, |(i, _)| i);
    pictures[worst].save_png(&dir.join("popping_worst.png"))?;
    Ok(())
}

/// [`held_out_lpips`] of the finished run in `dir` (its `point_cloud.ply`), rendered over the
/// dataset's background: the LPIPS column of `fewview train`'s scores.
pub fn held_out_lpips_of_run(
    ds: &Dataset,
    dir: &Path,
    lpips: &Lpips,
) -> Result<(f64, f64), FusionError> {
    let (model, settings) = model_of_run(ds, dir)?;
    held_out_lpips(ds, &model, &settings, lpips)
}

/// The finished run in `dir` (its `point_cloud.ply`) and the settings that render it over the
/// dataset's background at the model's SH degree.
pub(crate) fn model_of_run(
    ds: &Dataset,
    dir: &Path,
) -> Result<(GaussianModel, RenderSettings), FusionError> {
    let model = read_ply(&dir.join("point_cloud.ply"))?;
    let settings = RenderSettings {
        background: ds.background,
        sh_degree: model.sh_degree(),
        ..RenderSettings::default()
    };
    Ok((model, settings))
}

/// Mean LPIPS of `model`'s renders of the held-out views against their photos: raw, and after
/// the per-channel gain fit ([`fewview_splat::eval::held_out_lpips`], whole images).
pub fn held_out_lpips(
    ds: &Dataset,
    model: &GaussianModel,
    settings: &RenderSettings,
    lpips: &Lpips,
) -> Result<(f64, f64), FusionError> {
    Ok(fewview_splat::eval::held_out_lpips(
        ds, model, settings, lpips,
    )?)
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

    /// Five frames four to a row: two rows of cells as large as the largest frame, each frame
    /// at its cell's corner, black elsewhere.
    #[test]
    fn midpath_frames_are_tiled_row_after_row() {
        let frames: Vec<Image> = (0..5)
            .map(|k| Image::filled(10 + k, 6, &[0.1 * (k + 1) as f32, 0.0, 1.0]))
            .collect();
        let canvas = tile(&frames, 4);
        assert_eq!((canvas.width, canvas.height), (4 * 14, 2 * 6));
        assert_eq!(canvas.pixel(14 * 2 + 11, 5), &[0.3, 0.0, 1.0]);
        assert_eq!(canvas.pixel(9, 3), &[0.1, 0.0, 1.0]);
        assert_eq!(canvas.pixel(11, 0), &[0.0, 0.0, 0.0]);
        assert_eq!(canvas.pixel(13, 6), &[0.5, 0.0, 1.0]);
        assert_eq!(canvas.pixel(14 + 1, 7), &[0.0, 0.0, 0.0]);
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
