//! The training loss of one target view.
//!
//! `L = (1 − λ)·L1 + λ·(1 − SSIM)` on the target image (λ = 0.2, the PoseGaussian paper's 0.8/0.2), plus two
//! terms weighted by the network's own confidences (the uncertainty head's two channels, in
//! `(0, 1)`). Both use the Laplace negative log-likelihood with the confidence as the inverse
//! scale, `c·e − log c` (Kendall and Gal, "What Uncertainties Do We Need in Bayesian Deep
//! Learning for Computer Vision?", 2017): a pixel may declare itself unsure (small `c`) to pay
//! less for a large error `e`, at the price `−log c`. The form is ours; the PoseGaussian paper says only that
//! the confidences weight the depth and SR-opacity terms.
//!
//! - **Depth** (where the dataset has depth): per source foreground pixel, `e = |d − d*| / τ`
//!   with τ = 1 cm, confidence = the depth-confidence channel.
//! - **Silhouette** (SR-opacity): per target pixel, `e = |α − M|` between the rendered opacity
//!   and the target's mask, confidence = the Gaussians' SR-opacity confidences splatted like
//!   colours (a second pass of the rasterizer, composited over 1 so that pixels no Gaussian
//!   reaches count fully).

use burn::tensor::{Int, Tensor, TensorData};
use fewview_splat::loss::photometric_loss;
use fewview_splat::op::GaussianTensors;
use fewview_splat::sh::SH_C0;
use serde::{Deserialize, Serialize};

use super::forward::{image_tensor, mask_tensor};
use super::prepare::PreparedView;
use crate::error::HumanError;
use crate::gaussians::{PixelMaps, Rendered, render_gaussians};
use crate::net::HeadOutputs;

/// Weights of the loss's terms.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LossWeights {
    /// λ of the D-SSIM term.
    pub dssim: f32,
    pub depth: f32,
    pub silhouette: f32,
    /// τ of the depth term, metres.
    pub depth_scale: f32,
}

impl Default for LossWeights {
    fn default() -> Self {
        Self {
            dssim: 0.2,
            depth: 0.1,
            silhouette: 0.1,
            depth_scale: 0.01,
        }
    }
}

/// The loss's terms as numbers, for the log.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LossParts {
    pub photometric: f32,
    pub depth: f32,
    pub silhouette: f32,
    pub total: f32,
}

/// The value of a one-element loss term, read back for the log; `what` names the term in the
/// error when the read-back fails.
fn scalar(t: &Tensor<1>, what: &str) -> Result<f32, HumanError> {
    let failed = |message: String| HumanError::argument("training", message);
    let values = t
        .clone()
        .into_data()
        .try_to_vec::<f32>()
        .map_err(|e| failed(format!("reading the {what} loss back: {e:?}")))?;
    values
        .first()
        .copied()
        .ok_or_else(|| failed(format!("the {what} loss has no value")))
}

/// Laplace NLL `mean(c·e − log c)` over the pixels where `valid` is 1.
fn laplace_nll(e: Tensor<3>, c: Tensor<3>, valid: Tensor<3>) -> Tensor<1> {
    let count = valid.clone().sum().clamp_min(1.0);
    let c = c.clamp(1e-4, 1.0);
    ((c.clone() * e - c.log()) * valid).sum() / count
}

/// The depth term of source view `index` (None without dataset depth).
fn depth_term(
    heads: &HeadOutputs,
    maps: &PixelMaps,
    index: usize,
    view: &PreparedView,
    tau: f32,
) -> Option<Tensor<1>> {
    let truth = view.depth.as_ref()?;
    let device = maps.depth.device();
    let [_, h, w] = maps.depth.dims();
    let valid: Vec<f32> = truth
        .data
        .iter()
        .zip(&view.mask.data)
        .map(|(&d, &m)| f32::from(u8::from(m && d > 0.0)))
        .collect();
    let t = |v: Vec<f32>| Tensor::<3>::from_data(TensorData::new(v, [1, h, w]), &device);
    let e = (maps.depth.clone() - t(truth.data.clone())).abs() / tau;
    let c = heads
        .uncertainty
        .clone()
        .narrow(0, index, 1)
        .narrow(1, 0, 1)
        .reshape([1, h, w]);
    Some(laplace_nll(e, c, t(valid)))
}

/// The SR-opacity confidences of `views`' foreground pixels as grey degree-0 SH, `[N, 1, 3]`.
fn confidence_colours(heads: &HeadOutputs, views: &[&PreparedView]) -> Tensor<3> {
    let device = heads.uncertainty.device();
    let parts = views
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let [_, _, h, w] = heads.uncertainty.dims();
            let idx: Vec<i64> = (0..w * h)
                .filter(|&p| v.mask.data[p])
                .map(|p| p as i64)
                .collect();
            let n = idx.len();
            let idx = Tensor::<1, Int>::from_data(TensorData::new(idx, [n]), &device);
            let c = heads
                .uncertainty
                .clone()
                .narrow(0, i, 1)
                .narrow(1, 1, 1)
                .reshape([1, h * w])
                .select(1, idx);
            c.reshape([n, 1, 1]).repeat_dim(2, 3)
        })
        .collect();
    Tensor::cat(parts, 0)
        .sub_scalar(0.5)
        .div_scalar(SH_C0 as f32)
}

/// The silhouette term: rendered opacity against the target mask, confidence-weighted.
fn silhouette_term(
    gaussians: &GaussianTensors,
    rendered: &Rendered,
    heads: &HeadOutputs,
    views: &[&PreparedView],
    target: &PreparedView,
) -> Tensor<1> {
    let device = rendered.alpha.device();
    let confident = GaussianTensors {
        sh: confidence_colours(heads, views),
        ..gaussians.clone()
    };
    let splat = render_gaussians(&confident, &target.camera);
    let [h, w, _] = rendered.alpha.dims();
    let alpha = rendered.alpha.clone().reshape([1, h, w]);
    let c = splat.rgb.narrow(2, 0, 1).reshape([1, h, w]) + alpha.clone().neg().add_scalar(1.0);
    let e = (alpha - mask_tensor(&target.mask, &device)).abs();
    laplace_nll(e, c, Tensor::ones([1, h, w], &device))
}

/// The loss of rendering `target` from `views` (whose network outputs are `heads` and `maps`,
/// whose Gaussians are `gaussians`, rendered as `rendered`).
pub fn training_loss(
    heads: &HeadOutputs,
    maps: &[PixelMaps],
    views: &[&PreparedView],
    gaussians: &GaussianTensors,
    rendered: &Rendered,
    target: &PreparedView,
    weights: &LossWeights,
) -> Result<(Tensor<1>, LossParts), HumanError> {
    let device = rendered.rgb.device();
    let truth = image_tensor(&target.image, &device)
        * mask_tensor(&target.mask, &device).permute([1, 2, 0]);
    let photometric = photometric_loss(rendered.rgb.clone(), truth, weights.dssim);
    let depth_terms: Vec<Tensor<1>> = views
        .iter()
        .enumerate()
        .filter_map(|(i, v)| depth_term(heads, &maps[i], i, v, weights.depth_scale))
        .collect();
    let count = depth_terms.len();
    let depth = (count > 0)
        .then(|| {
            depth_terms
                .into_iter()
                .reduce(|a, b| a + b)
                .map(|t| t / count as f32)
        })
        .flatten();
    let silhouette = silhouette_term(gaussians, rendered, heads, views, target);
    let mut parts = LossParts {
        photometric: scalar(&photometric, "photometric")?,
        silhouette: scalar(&silhouette, "silhouette")?,
        ..Default::default()
    };
    let mut total = photometric + silhouette * weights.silhouette;
    if let Some(d) = depth {
        parts.depth = scalar(&d, "depth")?;
        total = total + d * weights.depth;
    }
    parts.total = scalar(&total, "total")?;
    Ok((total, parts))
}
