//! One source view's foreground pixels to 3D Gaussians (module docs of [`super`] give the
//! formulas), as fewview-splat's [`GaussianTensors`] in the Inria layout: means, log-scales,
//! w-first quaternions, opacity logits and degree-0 SH.

use burn::tensor::{Device, Int, Tensor, TensorData};
use fewview_scene::{Camera, Image};
use fewview_splat::op::GaussianTensors;
use fewview_splat::sh::SH_C0;

use super::options::GaussianOptions;
use super::params::PixelMaps;
use crate::error::{HumanError, Result};
use crate::maps::Mask;

/// Smallest standard deviation (metres) before the logarithm, so that a vanishing scale gives a
/// finite log-scale.
const MIN_SCALE: f32 = 1e-8;
/// Opacity is kept this far from 0 and 1 before the logit (the rasterizer caps α at 0.99
/// anyway, so 1 − 1e-6 renders as 1 does).
const OPACITY_MARGIN: f32 = 1e-6;

/// A source view: its image, the person's mask and its camera, all of one size.
#[derive(Clone, Copy, Debug)]
pub struct SourceView<'a> {
    /// sRGB in `[0, 1]`, H×W×3.
    pub image: &'a Image,
    /// Pixels that spawn Gaussians.
    pub mask: &'a Mask,
    pub camera: &'a Camera,
}

/// The Gaussians of `view`'s foreground pixels, in row-major pixel order. Gradients flow from
/// the means to `maps.depth`, and from the log-scales, quaternions and opacity logits to the
/// other maps; colours are constants. An error if the sizes disagree or the mask is empty.
pub fn pixel_gaussians(
    view: &SourceView<'_>,
    maps: &PixelMaps,
    options: &GaussianOptions,
) -> Result<GaussianTensors> {
    let (w, h) = check_sizes(view, maps)?;
    let pixels: Vec<usize> = (0..w * h).filter(|&p| view.mask.data[p]).collect();
    if pixels.is_empty() {
        return Err(HumanError::argument(
            "source view",
            "the mask selects no pixel",
        ));
    }
    let n = pixels.len();
    let device = maps.depth.device();
    let index: Vec<i64> = pixels.iter().map(|&p| p as i64).collect();
    let index = Tensor::<1, Int>::from_data(TensorData::new(index, [n]), &device);
    let pick = |m: &Tensor<3>| {
        let [c, _, _] = m.dims();
        m.clone()
            .reshape([c, h * w])
            .select(1, index.clone())
            .transpose()
    };
    let (rays, centre) = rays(view.camera, &pixels, w, &device);
    let means = rays * pick(&maps.depth).repeat_dim(1, 3) + centre;
    let mut scale = pick(&maps.scale);
    if let Some(max) = options.max_scale {
        scale = scale.clamp_max(max);
    }
    let opacity = pick(&maps.opacity).clamp(OPACITY_MARGIN, 1.0 - OPACITY_MARGIN);
    let logits = (opacity.clone() / (opacity.neg().add_scalar(1.0))).log();
    Ok(GaussianTensors {
        means,
        log_scales: scale.clamp_min(MIN_SCALE).log(),
        quats: to_world(pick(&maps.rotation), view.camera),
        opacity_logits: logits.reshape([n]),
        sh: colours(view.image, &pixels, &device),
    })
}

fn check_sizes(view: &SourceView<'_>, maps: &PixelMaps) -> Result<(usize, usize)> {
    maps.check()?;
    let (w, h) = maps.size();
    let k = &view.camera.intrinsics;
    let sizes = [
        ("image", (view.image.width, view.image.height)),
        ("mask", (view.mask.width, view.mask.height)),
        ("camera", (k.width as usize, k.height as usize)),
    ];
    for (name, size) in sizes {
        if size != (w, h) {
            let m = format!("{name} is {}×{}, the maps {w}×{h}", size.0, size.1);
            return Err(HumanError::argument("source view", m));
        }
    }
    if view.image.channels != 3 {
        let m = format!("image has {} channels, expected 3", view.image.channels);
        return Err(HumanError::argument("source view", m));
    }
    Ok((w, h))
}

/// Per pixel the world direction `Rᵀ K⁻¹ [x + ½, y + ½, 1]ᵀ` (camera z component 1, so that a
/// z-depth scales it to the point), and the camera centre repeated, both `[N, 3]` constants.
fn rays(
    camera: &Camera,
    pixels: &[usize],
    width: usize,
    device: &Device,
) -> (Tensor<2>, Tensor<2>) {
    let k = &camera.intrinsics;
    let r_t = camera.world_to_camera.rotation.transpose();
    let c = camera.center();
    let mut dirs = Vec::with_capacity(pixels.len() * 3);
    let mut centres = Vec::with_capacity(pixels.len() * 3);
    for &p in pixels {
        let (u, v) = ((p % width) as f64 + 0.5, (p / width) as f64 + 0.5);
        let d = r_t * nalgebra::Vector3::new((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0);
        dirs.extend(d.iter().map(|&x| x as f32));
        centres.extend(c.iter().map(|&x| x as f32));
    }
    let n = pixels.len();
    let t = |v: Vec<f32>| Tensor::<2>::from_data(TensorData::new(v, [n, 3]), device);
    (t(dirs), t(centres))
}

/// Camera-frame quaternions `[N, 4]` (w first) to world: `q_c2w ⊗ q`, a fixed linear map of `q`.
fn to_world(q: Tensor<2>, camera: &Camera) -> Tensor<2> {
    let c2w = camera.camera_to_world().quaternion();
    let (w, x, y, z) = (c2w.w as f32, c2w.i as f32, c2w.j as f32, c2w.k as f32);
    // Rows of the left-multiplication matrix L(p) with (p ⊗ q) = L(p) q; q_world = q Lᵀ.
    let l = [[w, -x, -y, -z], [x, w, -z, y], [y, z, w, -x], [z, -y, x, w]];
    let l_t: Vec<f32> = (0..16).map(|i| l[i % 4][i / 4]).collect();
    let l_t = Tensor::<2>::from_data(TensorData::new(l_t, [4, 4]), &q.device());
    q.matmul(l_t)
}

/// The pixels' colours as degree-0 SH, `[N, 1, 3]`: `(c − ½) / C0`.
fn colours(image: &Image, pixels: &[usize], device: &Device) -> Tensor<3> {
    let sh: Vec<f32> = pixels
        .iter()
        .flat_map(|&p| &image.data[3 * p..3 * p + 3])
        .map(|&c| ((c as f64 - 0.5) / SH_C0) as f32)
        .collect();
    Tensor::<3>::from_data(TensorData::new(sh, [pixels.len(), 1, 3]), device)
}
