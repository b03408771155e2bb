//! Rendering a trained model to images and scoring held-out views (PSNR, SSIM as papers report
//! them: scikit-image SSIM, data range 1; masked variants when the dataset has masks), raw and
//! gain-matched (a per-channel least-squares gain to the photo first,
//! [`fewview_metrics::gain`], as evaluations of captures with varying exposure do).

use fewview_metrics::gain::gain_matched;
use fewview_metrics::lpips::Lpips;
use fewview_metrics::psnr::{psnr, psnr_masked};
use fewview_metrics::ssim::{SsimOptions, ssim_masked, ssim_with};
use fewview_scene::{Dataset, Image, View};
use serde::Serialize;

use crate::model::GaussianModel;
use crate::raster::render::forward;
use crate::raster::{RenderCamera, RenderSettings};

/// A render on the host: RGB (background composited), expected depth `Σ wᵢ zᵢ`, and alpha.
pub struct Rendered {
    pub rgb: Image,
    pub depth: Image,
    pub alpha: Image,
}

impl Rendered {
    /// Depth normalised by alpha (the expected depth of the visible surface), 0 where alpha is 0.
    pub fn normalized_depth(&self) -> Image {
        let data = self
            .depth
            .data
            .iter()
            .zip(&self.alpha.data)
            .map(|(d, a)| if *a > 1e-6 { d / a } else { 0.0 })
            .collect();
        Image::from_vec(self.depth.width, self.depth.height, 1, data)
    }
}

pub fn render_model(
    model: &GaussianModel,
    camera: &RenderCamera,
    settings: &RenderSettings,
) -> Rendered {
    let (out, _) = forward(&model.refs(), camera, settings);
    let (w, h) = (out.width, out.height);
    Rendered {
        rgb: Image::from_vec(w, h, 3, out.rgb()),
        depth: Image::from_vec(w, h, 1, out.channel(3)),
        alpha: Image::from_vec(w, h, 1, out.channel(4)),
    }
}

/// Scores of one held-out view.
#[derive(Clone, Debug, Serialize)]
pub struct ViewScore {
    pub name: String,
    pub psnr: f64,
    pub ssim: f64,
    /// Over the object mask, when the dataset has masks (DTU protocol).
    pub masked_psnr: Option<f64>,
    pub masked_ssim: Option<f64>,
    /// PSNR and SSIM after the per-channel gain fit (over the pixels the raw scores count).
    pub gain_matched_psnr: f64,
    pub gain_matched_ssim: f64,
}

/// Scores of a set of held-out views and their means.
#[derive(Clone, Debug, Serialize)]
pub struct EvalReport {
    pub views: Vec<ViewScore>,
    pub mean_psnr: f64,
    pub mean_ssim: f64,
    pub mean_masked_psnr: Option<f64>,
    pub mean_masked_ssim: Option<f64>,
    pub mean_gain_matched_psnr: f64,
    pub mean_gain_matched_ssim: f64,
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    if n == 0 { f64::NAN } else { s / n as f64 }
}

/// The product of two masks of one size (both must hold for a pixel to count).
fn intersect(a: &Image, b: &Image) -> Image {
    let data = a.data.iter().zip(&b.data).map(|(x, y)| x * y).collect();
    Image::from_vec(a.width, a.height, 1, data)
}

/// Scores one render against a view's image (and mask). A view with a validity mask (the
/// blank border of an undistorted photo) is scored on its valid pixels only, the masked
/// scores on the pixels both masks keep.
pub fn score(
    name: &str,
    rendered: &Image,
    view: &View,
) -> Result<ViewScore, fewview_metrics::error::MetricsError> {
    let opts = SsimOptions::default();
    let mask = match (&view.mask, &view.valid) {
        (Some(m), Some(v)) if m.data.len() == v.data.len() => Some(intersect(m, v)),
        (m, _) => m.clone(),
    };
    let (mp, ms) = match &mask {
        Some(mask) => (
            Some(psnr_masked(rendered, &view.image, mask)?),
            Some(ssim_masked(rendered, &view.image, mask, &opts)?),
        ),
        None => (None, None),
    };
    let scores = |image: &Image| match &view.valid {
        Some(valid) => Ok::<_, fewview_metrics::error::MetricsError>((
            psnr_masked(image, &view.image, valid)?,
            ssim_masked(image, &view.image, valid, &opts)?,
        )),
        None => Ok((
            psnr(image, &view.image)?,
            ssim_with(image, &view.image, &opts)?,
        )),
    };
    let (p, s) = scores(rendered)?;
    let matched = gain_matched(rendered, &view.image, view.valid.as_ref())?;
    let (gp, gs) = scores(&matched)?;
    Ok(ViewScore {
        name: name.to_string(),
        psnr: p,
        ssim: s,
        masked_psnr: mp,
        masked_ssim: ms,
        gain_matched_psnr: gp,
        gain_matched_ssim: gs,
    })
}

/// Checks that [`score`] can score `view`: SSIM needs an image at least as large as its window
/// and, with a mask, a mask pixel inside the region SSIM evaluates (the masked PSNR's region
/// contains it). A run checks its held-out views with this before it writes anything, so that
/// e.g. a too-large `--downscale` is reported up front rather than after training.
pub fn check_scorable(view: &View) -> Result<(), String> {
    let r = SsimOptions::default().radius();
    let (w, h) = (view.image.width, view.image.height);
    let side = 2 * r + 1;
    if w < side || h < side {
        return Err(format!(
            "held-out view `{}` is {w}x{h} pixels, smaller than the {side}x{side} SSIM window \
             (use a smaller downscale)",
            view.name
        ));
    }
    if let Some(mask) = &view.mask {
        let inside = mask.data.len() == w * h
            && (r..h - r).any(|y| (r..w - r).any(|x| mask.data[y * w + x] > 0.5));
        if !inside {
            return Err(format!(
                "the mask of held-out view `{}` selects no pixel at least {r} pixels from the \
                 border of its {w}x{h} image, so masked PSNR/SSIM cannot score it \
                 (use a smaller downscale)",
                view.name
            ));
        }
    }
    Ok(())
}

/// Renders every view and scores it. Returns the report and the renders (same order).
pub fn evaluate(
    model: &GaussianModel,
    views: &[&View],
    settings: &RenderSettings,
) -> Result<(EvalReport, Vec<Rendered>), fewview_metrics::error::MetricsError> {
    let mut scores = Vec::with_capacity(views.len());
    let mut renders = Vec::with_capacity(views.len());
    for v in views {
        let r = render_model(model, &RenderCamera::from(&v.camera), settings);
        scores.push(score(&v.name, &r.rgb, v)?);
        renders.push(r);
    }
    let masked = scores.iter().all(|s| s.masked_psnr.is_some()) && !scores.is_empty();
    let report = EvalReport {
        mean_psnr: mean(scores.iter().map(|s| s.psnr)),
        mean_ssim: mean(scores.iter().map(|s| s.ssim)),
        mean_masked_psnr: masked.then(|| mean(scores.iter().filter_map(|s| s.masked_psnr))),
        mean_masked_ssim: masked.then(|| mean(scores.iter().filter_map(|s| s.masked_ssim))),
        mean_gain_matched_psnr: mean(scores.iter().map(|s| s.gain_matched_psnr)),
        mean_gain_matched_ssim: mean(scores.iter().map(|s| s.gain_matched_ssim)),
        views: scores,
    };
    Ok((report, renders))
}

/// Mean LPIPS of `model`'s renders of `ds`'s held-out views against their photos: raw, and after
/// the per-channel gain fit ([`fewview_metrics::gain`]), whole images (the masked DTU scores are
/// [`crate::benchmark::masked`]'s).
pub fn held_out_lpips(
    ds: &Dataset,
    model: &GaussianModel,
    settings: &RenderSettings,
    lpips: &Lpips,
) -> Result<(f64, f64), fewview_metrics::MetricsError> {
    let (mut raw, mut matched) = (0.0, 0.0);
    for v in ds.test_views() {
        let rendered = render_model(model, &RenderCamera::from(&v.camera), settings).rgb;
        raw += lpips.distance(&rendered, &v.image)?;
        let gm = gain_matched(&rendered, &v.image, v.valid.as_ref())?;
        matched += lpips.distance(&gm, &v.image)?;
    }
    let n = ds.test.len().max(1) as f64;
    Ok((raw / n, matched / n))
}

#[cfg(test)]
mod tests {
    use fewview_scene::{Camera, Intrinsics, Se3};

    use super::*;

    /// Pixels outside a view's validity mask (the blank border of an undistorted photo) do not
    /// count: an error of 0.1 inside gives exactly 20 dB whatever the border holds.
    #[test]
    fn the_blank_border_is_not_scored() {
        let (w, h) = (24, 20);
        let target = Image::filled(w, h, &[0.5, 0.5, 0.5]);
        let mut valid = Image::filled(w, h, &[1.0]);
        let mut rendered = Image::filled(w, h, &[0.6, 0.6, 0.6]);
        for y in 0..h {
            for x in 0..3 {
                valid.set(x, y, 0, 0.0);
                for c in 0..3 {
                    rendered.set(x, y, c, 1.0);
                }
            }
        }
        let view = View {
            name: "v".into(),
            camera: Camera::new(
                Intrinsics::centered(20.0, w as u32, h as u32),
                Se3::identity(),
            ),
            image: target,
            mask: None,
            mask_is_alpha: false,
            valid: Some(valid),
            depth_bounds: None,
            source_index: 0,
        };
        let s = score("v", &rendered, &view).unwrap();
        assert!((s.psnr - 20.0).abs() < 1e-4, "{}", s.psnr);
        let unmasked = View {
            valid: None,
            ..view
        };
        assert!(score("v", &rendered, &unmasked).unwrap().psnr < 19.0);
    }
}
