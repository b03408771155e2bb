//! The input depths of a capture side by side over time: per input camera and frame the visual
//! hull's, per-frame stereo's and (where the capture has it) the exact depth, with how much each
//! flickers between frames and how far each lies from the truth. This is the condition the
//! PoseGaussian paper's stability claim needs: per-frame depth that changes where the person
//! does not.

use std::ops::Range;

use fewview_geom::Mesh;
use fewview_geom::colormap::colorize_range;
use fewview_scene::{Camera, Image};
use serde::Serialize;

use crate::depth::{StereoSettings, flicker, mean_change};
use crate::error::{HumanError, Result};
use crate::eval::side_by_side;
use crate::maps::{DepthMap, Mask};
use crate::train::prepare::{
    DepthSettings, Framing, InputViews, PreparedFrame, PreparedView, frame_hull, hull_config,
    prepare_frame,
};

/// What [`measure`] prepares.
#[derive(Clone, Debug)]
pub struct DepthReportConfig {
    pub frames: Range<usize>,
    /// Crop `[width, height]` (the network preset's input).
    pub size: [usize; 2],
    pub crop_margin: f64,
    pub hull_voxel: f64,
    pub stereo: StereoSettings,
}

/// One input depth over the frames, all input cameras pooled.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct DepthStats {
    /// Mean `|d_t − d_{t−1}|` inside both masks (metres).
    pub flicker_m: Option<f64>,
    /// Mean `|(d_t − g_t) − (d_{t−1} − g_{t−1})|` against the truth `g`: the change the
    /// person's motion does not explain (metres).
    pub flicker_beyond_truth_m: Option<f64>,
    /// Mean `|d − g|` inside the mask (metres).
    pub error_m: Option<f64>,
}

/// The report `fewview human depth` writes as `depth_report.json`.
#[derive(Clone, Debug, Serialize)]
pub struct DepthReport {
    pub frames: [usize; 2],
    pub cameras: Vec<usize>,
    pub hull: DepthStats,
    pub stereo: DepthStats,
    /// The capture's own depth, when it has any (its flicker is the person's motion).
    pub truth: Option<DepthStats>,
    /// Mean fraction of the masked hull pixels stereo matched.
    pub stereo_matched: f64,
    /// `stereo.flicker_m / hull.flicker_m`.
    pub flicker_ratio: Option<f64>,
}

/// The prepared input views of every frame (hull and stereo depth) and their report.
pub fn measure(
    inputs: &dyn InputViews,
    config: &DepthReportConfig,
) -> Result<(DepthReport, Vec<PreparedFrame>)> {
    config.stereo.check()?;
    let voxel = hull_config(config.hull_voxel);
    let meshes = config
        .frames
        .clone()
        .map(|f| frame_hull(inputs, f, &voxel))
        .collect::<Result<Vec<Mesh>>>()?;
    let cameras = inputs
        .input_cameras()
        .iter()
        .map(|&c| inputs.camera(c).cloned())
        .collect::<Result<Vec<Camera>>>()?;
    let framing = Framing::of_hulls(&meshes, &cameras, config.size, config.crop_margin)?;
    let settings = DepthSettings {
        input: crate::depth::DepthInput::Stereo,
        stereo: config.stereo.clone(),
    };
    let prepared = config
        .frames
        .clone()
        .zip(&meshes)
        .map(|(f, mesh)| prepare_frame(inputs, f, mesh, &framing, &settings))
        .collect::<Result<Vec<_>>>()?;
    Ok((report(&prepared, config, inputs.input_cameras())?, prepared))
}

fn report(
    prepared: &[PreparedFrame],
    config: &DepthReportConfig,
    cameras: &[usize],
) -> Result<DepthReport> {
    if prepared.is_empty() {
        return Err(HumanError::argument("depth report", "no frames"));
    }
    let has_truth = prepared
        .iter()
        .all(|f| f.views.iter().all(|v| v.depth.is_some()));
    let hull = pooled(prepared, |v| Some(&v.hull_depth), has_truth);
    let stereo = pooled(prepared, |v| Some(&v.input_depth), has_truth);
    let truth = has_truth.then(|| pooled(prepared, |v| v.depth.as_ref(), true));
    let views = prepared.iter().flat_map(|f| &f.views);
    let count = views.clone().count().max(1);
    let stereo_matched = views.map(|v| v.stereo_matched).sum::<f64>() / count as f64;
    let flicker_ratio = match (stereo.flicker_m, hull.flicker_m) {
        (Some(s), Some(h)) if h > 0.0 => Some(s / h),
        _ => None,
    };
    Ok(DepthReport {
        frames: [config.frames.start, config.frames.end - 1],
        cameras: cameras.to_vec(),
        hull,
        stereo,
        truth,
        stereo_matched,
        flicker_ratio,
    })
}

/// Flicker and error of the depth `pick` chooses of each view, pooled over the views (each
/// view's mean weighted by its pixel count is close enough to a per-pixel pool; views are one
/// size). `pick` gives a map for every view.
fn pooled(
    prepared: &[PreparedFrame],
    pick: fn(&PreparedView) -> Option<&DepthMap>,
    has_truth: bool,
) -> DepthStats {
    let views = prepared.first().map_or(0, |f| f.views.len());
    let (mut flick, mut beyond, mut error) = (Vec::new(), Vec::new(), Vec::new());
    for v in 0..views {
        let maps: Vec<&DepthMap> = prepared
            .iter()
            .map(|f| pick(&f.views[v]).expect("a map for every view"))
            .collect();
        let masks: Vec<&Mask> = prepared.iter().map(|f| &f.views[v].mask).collect();
        let series: Vec<(&DepthMap, &Mask)> =
            maps.iter().copied().zip(masks.iter().copied()).collect();
        flick.extend(flicker(&series));
        if has_truth {
            let truths = prepared
                .iter()
                .map(|f| f.views[v].depth.as_ref().expect("checked by the caller"));
            let diffs: Vec<DepthMap> = maps.iter().zip(truths).map(|(d, g)| minus(d, g)).collect();
            let series: Vec<(&DepthMap, &Mask)> = diffs.iter().zip(masks.iter().copied()).collect();
            beyond.extend(mean_change(&series, f32::is_finite));
            error.extend(mean_abs(&diffs, &masks));
        }
    }
    let mean = |v: &[f64]| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
    DepthStats {
        flicker_m: mean(&flick),
        flicker_beyond_truth_m: mean(&beyond),
        error_m: mean(&error),
    }
}

/// `d − g` where both are known, NaN elsewhere.
fn minus(d: &DepthMap, g: &DepthMap) -> DepthMap {
    let data = d
        .data
        .iter()
        .zip(&g.data)
        .map(|(&a, &b)| if a > 0.0 && b > 0.0 { a - b } else { f32::NAN })
        .collect();
    DepthMap {
        width: d.width,
        height: d.height,
        data,
    }
}

/// Mean `|d|` over masked known pixels of every frame.
fn mean_abs(diffs: &[DepthMap], masks: &[&Mask]) -> Option<f64> {
    let (mut sum, mut count) = (0.0f64, 0usize);
    for (d, m) in diffs.iter().zip(masks) {
        for (v, &inside) in d.data.iter().zip(&m.data) {
            if inside && v.is_finite() {
                sum += v.abs() as f64;
                count += 1;
            }
        }
    }
    (count > 0).then(|| sum / count as f64)
}

/// One input camera's frames, one row each: the image, the hull's depth, stereo's and the
/// truth's (when known), all on one colour scale over the person's depth.
pub fn strip(prepared: &[PreparedFrame], camera: usize, frames: &[usize]) -> Result<Image> {
    let views: Vec<_> = frames
        .iter()
        .map(|&f| {
            prepared
                .iter()
                .find(|p| p.frame == f)
                .and_then(|p| p.view(camera))
                .ok_or_else(|| {
                    HumanError::argument(
                        "depth strip",
                        format!("frame {f} of camera {camera} is not prepared"),
                    )
                })
        })
        .collect::<Result<_>>()?;
    let masked = |d: &DepthMap, m: &Mask| -> Vec<f32> {
        d.data
            .iter()
            .zip(&m.data)
            .map(|(&v, &k)| if k && v > 0.0 { v } else { f32::NAN })
            .collect()
    };
    let known: Vec<f32> = views
        .iter()
        .flat_map(|v| masked(&v.hull_depth, &v.mask))
        .filter(|v| v.is_finite())
        .collect();
    let lo = known.iter().copied().fold(f32::INFINITY, f32::min) - 0.05;
    let hi = known.iter().copied().fold(f32::NEG_INFINITY, f32::max) + 0.1;
    let mut rows = Vec::new();
    for v in views {
        let (w, h) = (v.mask.width, v.mask.height);
        let paint = |d: &DepthMap| colorize_range(&masked(d, &v.mask), w, h, lo, hi);
        let mut columns = vec![v.image.clone(), paint(&v.hull_depth), paint(&v.input_depth)];
        columns.extend(v.depth.as_ref().map(paint));
        rows.push(side_by_side(&columns.iter().collect::<Vec<_>>()));
    }
    Ok(stack(&rows))
}

/// Images of one width, top to bottom.
fn stack(rows: &[Image]) -> Image {
    let width = rows[0].width;
    let data: Vec<f32> = rows.iter().flat_map(|r| r.data.iter().copied()).collect();
    Image {
        width,
        height: rows.iter().map(|r| r.height).sum(),
        channels: 3,
        data,
    }
}
