//! One prediction: the network on the source views, their pixel Gaussians, the render into a
//! target camera. Shared by training and inference so that both see exactly the same model.

use burn::tensor::{Device, Tensor, TensorData};
use fewview_scene::Camera;
use fewview_splat::op::GaussianTensors;

use super::prepare::{Framing, PreparedView};
pub use crate::depth::DepthBracket;
use crate::error::Result;
use crate::gaussians::{
    GaussianOptions, PixelMaps, Rendered, SourceView, concat, pixel_gaussians, render_gaussians,
};
use crate::net::posemap::pose_map_host;
use crate::net::{HeadOutputs, NetInput, PoseGaussianNet, PoseMapConfig};

/// What the prediction reads besides the views.
#[derive(Clone, Debug)]
pub struct ForwardSettings<'a> {
    pub framing: &'a Framing,
    pub bracket: DepthBracket,
    pub parents: &'a [i64],
    pub pose_map: PoseMapConfig,
    /// `false` feeds the pose encoder zeros: the per-frame baseline, which knows no pose.
    pub use_pose: bool,
    pub gaussians: GaussianOptions,
}

/// The network's outputs for a batch of source views and their Gaussian maps.
#[derive(Clone, Debug)]
pub struct Prediction {
    pub heads: HeadOutputs,
    pub maps: Vec<PixelMaps>,
}

fn chw(data: &[f32], channels: usize, w: usize, h: usize) -> Vec<f32> {
    let mut out = vec![0.0; data.len()];
    for p in 0..w * h {
        for c in 0..channels {
            out[c * w * h + p] = data[p * channels + c];
        }
    }
    out
}

/// The network's input for `views`: the image in `[−1, 1]`, the pose map, the input depth
/// ([`crate::depth`]) normalised to `[−1, 1]` over the framing's near/far (1 where there is none).
pub fn net_input(
    views: &[&PreparedView],
    s: &ForwardSettings<'_>,
    device: &Device,
) -> Result<NetInput> {
    let [w, h] = s.framing.size;
    let n = views.len();
    let (mut image, mut pose, mut depth) = (Vec::new(), Vec::new(), Vec::new());
    let channels = crate::net::pose_map_channels(s.parents, s.pose_map.style);
    for v in views {
        image.extend(
            chw(&v.image.data, 3, w, h)
                .into_iter()
                .map(|x| 2.0 * x - 1.0),
        );
        if s.use_pose {
            pose.extend(pose_map_host(&v.joints, s.parents, [h, w], &s.pose_map)?);
        } else {
            pose.extend(std::iter::repeat_n(0.0, channels * w * h));
        }
        let (near, far) = (s.framing.near as f32, s.framing.far as f32);
        depth.extend(v.input_depth.data.iter().map(|&d| {
            if d > 0.0 {
                (2.0 * (d - near) / (far - near) - 1.0).clamp(-1.0, 1.0)
            } else {
                1.0
            }
        }));
    }
    let t =
        |v: Vec<f32>, c: usize| Tensor::<4>::from_data(TensorData::new(v, [n, c, h, w]), device);
    Ok(NetInput {
        image: t(image, 3),
        pose: t(pose, channels),
        depth: t(depth, 1),
    })
}

/// Metric depth of batch item `index`: the bracket around the input depth where there is one,
/// the framing's near/far elsewhere.
fn bracket_depth(
    heads: &HeadOutputs,
    index: usize,
    view: &PreparedView,
    s: &ForwardSettings<'_>,
) -> Tensor<3> {
    let [_, _, h, w] = heads.depth.dims();
    let (near, far) = (s.framing.near as f32, s.framing.far as f32);
    let b = s.bracket;
    let (base, span): (Vec<f32>, Vec<f32>) = view
        .input_depth
        .data
        .iter()
        .map(|&d| {
            if d > 0.0 {
                (d - b.front, b.front + b.behind)
            } else {
                (near, far - near)
            }
        })
        .unzip();
    let device = heads.depth.device();
    let t = |v: Vec<f32>| Tensor::<3>::from_data(TensorData::new(v, [1, h, w]), &device);
    let unit = heads
        .depth
        .clone()
        .narrow(0, index, 1)
        .reshape([1, h, w])
        .add_scalar(1.0)
        .mul_scalar(0.5);
    unit * t(span) + t(base)
}

/// Runs the network on `views` (one batch) and turns its heads into per-view Gaussian maps.
pub fn predict(
    net: &PoseGaussianNet,
    views: &[&PreparedView],
    s: &ForwardSettings<'_>,
    device: &Device,
) -> Result<Prediction> {
    let heads = net.forward(net_input(views, s, device)?)?;
    let maps = maps_of(&heads, views, s)?;
    Ok(Prediction { heads, maps })
}

/// The per-view Gaussian maps of the heads' outputs for `views` (one batch item each).
pub fn maps_of(
    heads: &HeadOutputs,
    views: &[&PreparedView],
    s: &ForwardSettings<'_>,
) -> Result<Vec<PixelMaps>> {
    views
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let mut m =
                PixelMaps::from_heads(heads, i, s.framing.near as f32, s.framing.far as f32)?;
            m.depth = bracket_depth(heads, i, v, s);
            Ok(m)
        })
        .collect()
}

/// The source views' Gaussians, concatenated.
pub fn prediction_gaussians(
    views: &[&PreparedView],
    maps: &[PixelMaps],
    s: &ForwardSettings<'_>,
) -> Result<GaussianTensors> {
    let parts = views
        .iter()
        .zip(maps)
        .map(|(v, m)| {
            let view = SourceView {
                image: &v.image,
                mask: &v.mask,
                camera: &v.camera,
            };
            pixel_gaussians(&view, m, &s.gaussians)
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(concat(parts))
}

/// The source views' Gaussians rendered into `target` (a crop camera).
pub fn render_prediction(
    views: &[&PreparedView],
    maps: &[PixelMaps],
    target: &Camera,
    s: &ForwardSettings<'_>,
) -> Result<Rendered> {
    Ok(render_gaussians(
        &prediction_gaussians(views, maps, s)?,
        target,
    ))
}

/// A constant `[1, H, W]` map of `view`'s mask as 0/1.
pub fn mask_tensor(mask: &crate::maps::Mask, device: &Device) -> Tensor<3> {
    let v: Vec<f32> = mask.data.iter().map(|&m| f32::from(u8::from(m))).collect();
    Tensor::from_data(TensorData::new(v, [1, mask.height, mask.width]), device)
}

/// A constant `[H, W, 3]` image tensor.
pub fn image_tensor(image: &fewview_scene::Image, device: &Device) -> Tensor<3> {
    Tensor::from_data(
        TensorData::new(image.data.clone(), [image.height, image.width, 3]),
        device,
    )
}
