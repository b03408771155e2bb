//! Rendering per-pixel Gaussians into a target camera with fewview-splat's differentiable
//! rasterizer (its Burn custom op, on the Gaussians' device), on black: the capture's images are
//! composited on black, so the render is compared with them as it is.

use burn::tensor::Tensor;
use fewview_scene::Camera;
use fewview_splat::op::{GaussianTensors, RenderView, render};
use fewview_splat::raster::{RenderCamera, RenderSettings};

use super::options::GaussianOptions;
use super::params::PixelMaps;
use super::pixels::{SourceView, pixel_gaussians};
use crate::error::{HumanError, Result};

/// A render of a target camera, tensors on the Gaussians' device.
#[derive(Clone, Debug)]
pub struct Rendered {
    /// sRGB over black, `[H, W, 3]`.
    pub rgb: Tensor<3>,
    /// Accumulated opacity `1 − T`, `[H, W, 1]` (the rendered silhouette).
    pub alpha: Tensor<3>,
}

/// Renders `gaussians` (degree-0 SH) into `target` on a black background; gradients reach
/// every Gaussian parameter.
pub fn render_gaussians(gaussians: &GaussianTensors, target: &Camera) -> Rendered {
    let [n, _] = gaussians.means.dims();
    let device = gaussians.means.device();
    let view = RenderView {
        camera: RenderCamera::from(target),
        settings: RenderSettings {
            background: [0.0; 3],
            sh_degree: 0,
            ..RenderSettings::default()
        },
    };
    let out = render(gaussians, Tensor::<2>::zeros([n, 2], &device), &view);
    let [h, w, _] = out.image.dims();
    Rendered {
        rgb: out.image.clone().slice([0..h, 0..w, 0..3]),
        alpha: out.image.slice([0..h, 0..w, 4..5]),
    }
}

/// The Gaussians of several views as one set, in order.
pub fn concat(parts: Vec<GaussianTensors>) -> GaussianTensors {
    let field = |f: fn(&GaussianTensors) -> Tensor<2>| parts.iter().map(f).collect::<Vec<_>>();
    GaussianTensors {
        means: Tensor::cat(field(|g| g.means.clone()), 0),
        log_scales: Tensor::cat(field(|g| g.log_scales.clone()), 0),
        quats: Tensor::cat(field(|g| g.quats.clone()), 0),
        opacity_logits: Tensor::cat(parts.iter().map(|g| g.opacity_logits.clone()).collect(), 0),
        sh: Tensor::cat(parts.iter().map(|g| g.sh.clone()).collect(), 0),
    }
}

/// Renders `target` from the foreground pixels of `sources` (chosen with
/// [`super::nearest_sources`]), each with its maps.
pub fn novel_view(
    sources: &[SourceView<'_>],
    maps: &[PixelMaps],
    target: &Camera,
    options: &GaussianOptions,
) -> Result<Rendered> {
    if sources.is_empty() || sources.len() != maps.len() {
        let m = format!(
            "{} source views with {} sets of maps",
            sources.len(),
            maps.len()
        );
        return Err(HumanError::argument("novel view", m));
    }
    let parts = sources
        .iter()
        .zip(maps)
        .map(|(s, m)| pixel_gaussians(s, m, options))
        .collect::<Result<Vec<_>>>()?;
    Ok(render_gaussians(&concat(parts), target))
}
