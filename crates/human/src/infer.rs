//! Novel views of a trained run: per frame, the network on every input camera once, the
//! Temporal Pose Stabilizer over frames ([`crate::tps`], a switch), and the render of each
//! target camera from its nearest input cameras. Frames go in order, so that TPS sees `t − 1`
//! before `t`.

use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

use burn::tensor::{Device, Tensor, TensorData};
use fewview_scene::{Camera, Image};
use serde::{Deserialize, Serialize};

use crate::error::{HumanError, Result};
use crate::gaussians::PixelMaps;
use crate::net::{ForwardTimes, PoseGaussianNet, checkpoint};
use crate::source::MultiView;
use crate::tps::{SourceMaps, Stabilizer, TpsConfig};
use crate::train::forward::{ForwardSettings, net_input, render_prediction};
use crate::train::prepare::{
    Framing, InferenceInputs, PreparedFrame, frame_hull, hull_config, prepare_frame,
};
use crate::train::trainer::{TrainConfig, forward_settings, net_config, stored_run};

/// A trained network with the framing and joint tree of its run.
pub struct Model {
    pub net: PoseGaussianNet,
    pub config: TrainConfig,
    pub framing: Framing,
    pub parents: Vec<i64>,
    /// Training iterations behind the weights.
    pub iterations: usize,
    device: Device,
}

impl Model {
    /// The run checkpointed in `dir` (as `fewview human train` writes it), on the CPU.
    pub fn load(dir: &Path) -> Result<Self> {
        let (config, framing, parents, iterations) = stored_run(dir)?;
        let device = Device::flex();
        let net = checkpoint::load(
            &dir.join("network.fvh"),
            &net_config(&config, &parents),
            &device,
        )?;
        Ok(Self {
            net,
            config,
            framing,
            parents,
            iterations,
            device,
        })
    }

    pub fn settings(&self) -> ForwardSettings<'_> {
        forward_settings(&self.config, &self.framing, &self.parents)
    }
}

/// Seconds one frame took, by stage (the PoseGaussian paper reports rendering, pose encoder, image
/// features, TPS and the rest).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameTimes {
    /// Visual hull, crops and input depth of the input views.
    pub preparation: f64,
    pub network: ForwardTimes,
    pub tps: f64,
    /// Pixel Gaussians and the rasterizer, all targets.
    pub rendering: f64,
}

impl FrameTimes {
    pub fn total(&self) -> f64 {
        let n = &self.network;
        self.preparation
            + n.image_encoder
            + n.pose_encoder
            + n.depth_encoder
            + n.decoder_and_heads
            + self.tps
            + self.rendering
    }

    fn add(&mut self, o: &FrameTimes) {
        self.preparation += o.preparation;
        self.network.image_encoder += o.network.image_encoder;
        self.network.pose_encoder += o.network.pose_encoder;
        self.network.depth_encoder += o.network.depth_encoder;
        self.network.decoder_and_heads += o.network.decoder_and_heads;
        self.tps += o.tps;
        self.rendering += o.rendering;
    }

    /// The mean of `times`.
    pub fn mean(times: &[FrameTimes]) -> FrameTimes {
        let mut sum = FrameTimes::default();
        times.iter().for_each(|t| sum.add(t));
        let k = 1.0 / times.len().max(1) as f64;
        let n = &mut sum.network;
        for v in [
            &mut n.image_encoder,
            &mut n.pose_encoder,
            &mut n.depth_encoder,
            &mut n.decoder_and_heads,
        ] {
            *v *= k;
        }
        sum.preparation *= k;
        sum.tps *= k;
        sum.rendering *= k;
        sum
    }
}

/// The renders of one frame: per target, without and (when on) with TPS.
pub struct FrameRenders {
    pub frame: usize,
    pub plain: Vec<Image>,
    pub stabilized: Option<Vec<Image>>,
    pub times: FrameTimes,
}

/// Renders target cameras frame after frame.
pub struct SequenceRenderer<'a> {
    model: &'a Model,
    inputs: InferenceInputs<'a>,
    joints: &'a dyn MultiView,
    stabilizer: Option<Stabilizer>,
}

impl<'a> SequenceRenderer<'a> {
    /// `tps` switches the stabilizer on (the plain renders are made either way).
    pub fn new(
        model: &'a Model,
        source: &'a dyn MultiView,
        split: &'a crate::split::Split,
        tps: Option<TpsConfig>,
    ) -> Self {
        Self {
            model,
            inputs: InferenceInputs {
                source,
                split,
                depth_maps: model.config.depth == crate::depth::DepthInput::Dataset,
            },
            joints: source,
            stabilizer: tps.map(Stabilizer::new),
        }
    }

    /// The targets `cameras` (full dataset cameras) at `frame`, cropped by the run's framing.
    pub fn render_frame(&mut self, frame: usize, cameras: &[Camera]) -> Result<FrameRenders> {
        self.render_frame_leaving_out(frame, cameras, &vec![None; cameras.len()])
    }

    /// As [`Self::render_frame`], with target `i` drawn without the input camera
    /// `leave_out[i]` among its sources: an input camera predicted from its neighbours, as in
    /// training (the validation protocol).
    pub fn render_frame_leaving_out(
        &mut self,
        frame: usize,
        cameras: &[Camera],
        leave_out: &[Option<usize>],
    ) -> Result<FrameRenders> {
        if leave_out.len() != cameras.len() {
            return Err(HumanError::argument(
                "inference",
                format!(
                    "{} cameras but {} leave-outs",
                    cameras.len(),
                    leave_out.len()
                ),
            ));
        }
        let mut times = FrameTimes::default();
        let clock = Instant::now();
        let prepared = self.prepare(frame)?;
        times.preparation = clock.elapsed().as_secs_f64();
        let k = self.model.config.source_views;
        let targets: Vec<Camera> = cameras
            .iter()
            .map(|c| self.model.framing.crop(c).camera(c))
            .collect();
        let sources: Vec<Vec<usize>> = targets
            .iter()
            .zip(leave_out)
            .map(|(t, &except)| prepared.nearest(t, k, except))
            .collect::<Result<_>>()?;
        let mut needed: Vec<usize> = sources.iter().flatten().copied().collect();
        needed.sort_unstable();
        needed.dedup();
        let settings = self.model.settings();
        let (maps, network) = self.predict(&prepared, &needed, &settings)?;
        times.network = network;
        let clock = Instant::now();
        let stabilized = match &mut self.stabilizer {
            Some(s) => Some(stabilize_all(
                s,
                &prepared,
                &needed,
                &maps,
                &self.joints.joints3d(frame)?,
                &self.model.device,
            )?),
            None => None,
        };
        times.tps = clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        let render = |maps: &HashMap<usize, PixelMaps>| -> Result<Vec<Image>> {
            targets
                .iter()
                .zip(&sources)
                .map(|(t, src)| {
                    let views: Vec<_> = src.iter().filter_map(|&c| prepared.view(c)).collect();
                    let m: Vec<PixelMaps> = src.iter().map(|c| maps[c].clone()).collect();
                    to_image(&render_prediction(&views, &m, t, &settings)?.rgb)
                })
                .collect()
        };
        let plain = render(&maps)?;
        let stabilized = stabilized.as_ref().map(render).transpose()?;
        times.rendering = clock.elapsed().as_secs_f64();
        Ok(FrameRenders {
            frame,
            plain,
            stabilized,
            times,
        })
    }

    fn prepare(&self, frame: usize) -> Result<PreparedFrame> {
        let mesh = frame_hull(
            &self.inputs,
            frame,
            &hull_config(self.model.config.hull_voxel),
        )?;
        let depth = self.model.config.depth_settings();
        prepare_frame(&self.inputs, frame, &mesh, &self.model.framing, &depth)
    }

    /// The network once on every needed input camera (one batch).
    fn predict(
        &self,
        prepared: &PreparedFrame,
        needed: &[usize],
        settings: &ForwardSettings<'_>,
    ) -> Result<(HashMap<usize, PixelMaps>, ForwardTimes)> {
        let views: Vec<_> = needed.iter().filter_map(|&c| prepared.view(c)).collect();
        let input = net_input(&views, settings, &self.model.device)?;
        let (heads, times) = self.model.net.forward_timed(input)?;
        let maps = crate::train::forward::maps_of(&heads, &views, settings)?;
        Ok((needed.iter().copied().zip(maps).collect(), times))
    }
}

/// Channels of the maps TPS blends besides depth: scale (3), rotation (4), opacity (1).
const QUATERNION: std::ops::Range<usize> = 3..7;

fn host(t: &Tensor<3>) -> Result<Vec<f32>> {
    t.clone()
        .into_data()
        .try_to_vec::<f32>()
        .map_err(|e| HumanError::argument("inference", format!("cannot read a map: {e:?}")))
}

pub(crate) fn to_source_maps(maps: &PixelMaps, mask: &crate::maps::Mask) -> Result<SourceMaps> {
    let (width, height) = maps.size();
    let mut values = host(&maps.scale)?;
    values.extend(host(&maps.rotation)?);
    values.extend(host(&maps.opacity)?);
    Ok(SourceMaps {
        width,
        height,
        mask: mask.data.clone(),
        depth: host(&maps.depth)?,
        channels: 8,
        values,
        quaternion: Some(QUATERNION),
    })
}

fn from_source_maps(s: &SourceMaps, device: &Device) -> PixelMaps {
    let (w, h) = (s.width, s.height);
    let n = w * h;
    let t = |v: &[f32], c: usize| {
        Tensor::<3>::from_data(TensorData::new(v.to_vec(), [c, h, w]), device)
    };
    PixelMaps {
        depth: t(&s.depth, 1),
        scale: t(&s.values[0..3 * n], 3),
        rotation: t(&s.values[3 * n..7 * n], 4),
        opacity: t(&s.values[7 * n..8 * n], 1),
    }
}

fn stabilize_all(
    stabilizer: &mut Stabilizer,
    prepared: &PreparedFrame,
    needed: &[usize],
    maps: &HashMap<usize, PixelMaps>,
    joints: &[[f64; 3]],
    device: &Device,
) -> Result<HashMap<usize, PixelMaps>> {
    needed
        .iter()
        .map(|&c| {
            let view = prepared.view(c).ok_or_else(|| {
                HumanError::argument("inference", format!("camera {c} is not prepared"))
            })?;
            let current = to_source_maps(&maps[&c], &view.mask)?;
            let (out, _) = stabilizer.apply(c, prepared.frame, &view.camera, current, joints)?;
            Ok((c, from_source_maps(&out, device)))
        })
        .collect()
}

/// An `[H, W, 3]` tensor as an image, clamped to `[0, 1]`; an error if it cannot be read.
pub fn to_image(t: &Tensor<3>) -> Result<Image> {
    let [h, w, _] = t.dims();
    Ok(Image {
        width: w,
        height: h,
        channels: 3,
        data: host(t)?.into_iter().map(|v| v.clamp(0.0, 1.0)).collect(),
    })
}
