//! Leave-one-out scores of a capture whose every photo trains (a few photos, the fusion
//! paper's setting): an interior photo is held out, the model trained again on the rest, and
//! the held-out photo scored against its render, for up to [`MAX_LEFT_OUT`] photos spread
//! along the camera path. The ends of the path are never held out: a model cannot be asked to
//! extrapolate beyond the photos it has.

use std::path::Path;

use fewview_geom::stereo::pairs::order_along_baseline;
use fewview_metrics::gain::gain_matched;
use fewview_metrics::lpips::Lpips;
use fewview_scene::{Camera, Dataset};
use fewview_splat::eval::{render_model, score};
use fewview_splat::raster::RenderCamera;
use serde::{Deserialize, Serialize};

use crate::error::FusionError;
use crate::transition::model_of_run;

/// How a run is scored.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum EvalMode {
    /// Interior photos held out in turn, the model trained again without each
    /// ([`photos_to_leave_out`]); the default when no view is held out (a few photos).
    LeaveOneOut,
    /// The dataset's held-out views (its split, or `--test-views`).
    HeldOut,
}

impl EvalMode {
    /// The mode `chosen` (or the default for `ds`): leave-one-out where `ds` holds out nothing.
    /// Asking for held-out views of a dataset that has none is an error.
    pub fn resolve(chosen: Option<Self>, ds: &Dataset) -> Result<Self, FusionError> {
        match chosen {
            Some(Self::HeldOut) if ds.test.is_empty() => Err(FusionError::Invalid(format!(
                "{} holds no view out to score: name some with --test-views, or score by \
                 leave-one-out",
                ds.name
            ))),
            Some(mode) => Ok(mode),
            None if ds.test.is_empty() => Ok(Self::LeaveOneOut),
            None => Ok(Self::HeldOut),
        }
    }
}

/// The most photos held out in turn.
pub const MAX_LEFT_OUT: usize = 3;

/// The training views (dataset view indices) to hold out in turn: the interior of the camera
/// path (the training views ordered along their baseline, ends removed), at most
/// [`MAX_LEFT_OUT`] of them, spread evenly along it.
pub fn photos_to_leave_out(ds: &Dataset) -> Vec<usize> {
    let cameras: Vec<&Camera> = ds.train_views().map(|v| &v.camera).collect();
    let mut order = order_along_baseline(&cameras);
    if order.len() < 3 {
        return Vec::new();
    }
    // The path starts at the end with the first training view, whichever way its axis points.
    if order[0] > order[order.len() - 1] {
        order.reverse();
    }
    let interior = &order[1..order.len() - 1];
    let (m, k) = (interior.len(), interior.len().min(MAX_LEFT_OUT));
    // The `k` of `m` interior photos nearest `(j + 1)·(m + 1)/(k + 1) − 1`: evenly spread.
    let mut views: Vec<usize> = (0..k)
        .map(|j| {
            let at = ((j + 1) * (m + 1)) as f64 / (k + 1) as f64 - 1.0;
            ds.train[interior[(at.round_ties_even() as usize).min(m - 1)]]
        })
        .collect();
    views.dedup();
    views
}

/// `ds` with view `view` held out: the other training views train, it alone is scored.
pub fn without(ds: &Dataset, view: usize) -> Dataset {
    Dataset {
        train: ds.train.iter().copied().filter(|&v| v != view).collect(),
        test: vec![view],
        ..ds.clone()
    }
}

/// One held-out photo's scores (raw and after the per-channel gain fit).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LeftOut {
    pub view: String,
    pub psnr: f64,
    pub ssim: f64,
    pub lpips: Option<f64>,
    pub gain_matched_psnr: f64,
    pub gain_matched_ssim: f64,
    pub gain_matched_lpips: Option<f64>,
}

/// Every held-out photo's scores and their means.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LeaveOneOut {
    pub views: Vec<LeftOut>,
    pub mean_psnr: f64,
    pub mean_ssim: f64,
    pub mean_lpips: Option<f64>,
    pub mean_gain_matched_psnr: f64,
    pub mean_gain_matched_ssim: f64,
    pub mean_gain_matched_lpips: Option<f64>,
}

impl LeaveOneOut {
    pub fn of(views: Vec<LeftOut>) -> Self {
        let n = views.len().max(1) as f64;
        let mean = |f: &dyn Fn(&LeftOut) -> f64| views.iter().map(f).sum::<f64>() / n;
        let mean_of = |f: &dyn Fn(&LeftOut) -> Option<f64>| {
            let values: Option<Vec<f64>> = views.iter().map(f).collect();
            values.map(|v| v.iter().sum::<f64>() / n)
        };
        Self {
            mean_psnr: mean(&|v| v.psnr),
            mean_ssim: mean(&|v| v.ssim),
            mean_lpips: mean_of(&|v| v.lpips),
            mean_gain_matched_psnr: mean(&|v| v.gain_matched_psnr),
            mean_gain_matched_ssim: mean(&|v| v.gain_matched_ssim),
            mean_gain_matched_lpips: mean_of(&|v| v.gain_matched_lpips),
            views,
        }
    }
}

/// Scores the held-out view of `left_out` (a dataset of [`without`]) against the render of the
/// run in `dir` (its `point_cloud.ply`), with LPIPS when `lpips` is given.
pub fn score_left_out(
    left_out: &Dataset,
    dir: &Path,
    lpips: Option<&Lpips>,
) -> Result<LeftOut, FusionError> {
    let (model, settings) = model_of_run(left_out, dir)?;
    let view = left_out
        .test_views()
        .next()
        .ok_or_else(|| FusionError::Invalid("no view is held out".into()))?;
    let rendered = render_model(&model, &RenderCamera::from(&view.camera), &settings).rgb;
    let s = score(&view.name, &rendered, view)?;
    let (lpips_raw, lpips_matched) = match lpips {
        Some(l) => {
            let matched = gain_matched(&rendered, &view.image, view.valid.as_ref())?;
            (
                Some(l.distance(&rendered, &view.image)?),
                Some(l.distance(&matched, &view.image)?),
            )
        }
        None => (None, None),
    };
    Ok(LeftOut {
        view: view.name.clone(),
        psnr: s.psnr,
        ssim: s.ssim,
        lpips: lpips_raw,
        gain_matched_psnr: s.gain_matched_psnr,
        gain_matched_ssim: s.gain_matched_ssim,
        gain_matched_lpips: lpips_matched,
    })
}

/// Adds `value` under `key` to the JSON object in `path` (atomically; the file must exist).
pub fn add_to_json(path: &Path, key: &str, value: &impl Serialize) -> Result<(), FusionError> {
    let bytes = std::fs::read(path).map_err(|e| fewview_scene::SceneError::io(path, e))?;
    let mut doc: serde_json::Value = serde_json::from_slice(&bytes)
        .map_err(|e| FusionError::Invalid(format!("{}: {e}", path.display())))?;
    let value = serde_json::to_value(value).map_err(|e| FusionError::Invalid(e.to_string()))?;
    doc.as_object_mut()
        .ok_or_else(|| FusionError::Invalid(format!("{}: not a JSON object", path.display())))?
        .insert(key.to_string(), value);
    let json = serde_json::to_vec_pretty(&doc).map_err(|e| FusionError::Invalid(e.to_string()))?;
    fewview_scene::atomic::write_bytes(path, &json)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use fewview_scene::synthetic::{DemoOptions, demo_dataset};

    fn demo_with_train(train: Vec<usize>) -> Dataset {
        let opts = DemoOptions {
            width: 32,
            height: 24,
            views: 8,
            train: train.clone(),
            ..DemoOptions::default()
        };
        demo_dataset(&opts)
    }

    /// The demo's cameras lie on an arc in view order: the interior photos are held out, at
    /// most three, spread evenly, never an end of the path.
    #[test]
    fn interior_photos_are_left_out_spread_along_the_path() {
        let ds = demo_with_train((0..8).collect());
        assert_eq!(photos_to_leave_out(&ds), vec![2, 3, 5]);
        let ds = demo_with_train(vec![0, 3, 7]);
        assert_eq!(photos_to_leave_out(&ds), vec![3]);
        let ds = demo_with_train(vec![1, 6]);
        assert!(photos_to_leave_out(&ds).is_empty());
        let ds = demo_with_train((0..5).collect());
        let held = without(&ds, 2);
        assert_eq!((held.train, held.test), (vec![0, 1, 3, 4], vec![2]));
    }

    #[test]
    fn means_cover_every_left_out_photo() {
        let one = |psnr: f64, lpips: Option<f64>| LeftOut {
            view: "v".into(),
            psnr,
            ssim: 0.5,
            lpips,
            gain_matched_psnr: psnr + 1.0,
            gain_matched_ssim: 0.6,
            gain_matched_lpips: lpips,
        };
        let l = LeaveOneOut::of(vec![one(20.0, Some(0.2)), one(22.0, Some(0.4))]);
        assert_eq!((l.mean_psnr, l.mean_gain_matched_psnr), (21.0, 22.0));
        assert!((l.mean_lpips.unwrap() - 0.3).abs() < 1e-12);
        let l = LeaveOneOut::of(vec![one(20.0, Some(0.2)), one(22.0, None)]);
        assert_eq!(l.mean_lpips, None);
    }
}
