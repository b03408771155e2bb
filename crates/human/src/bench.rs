//! Inference time per frame of the PoseGaussian network (the PoseGaussian paper reports about 100 ms on an
//! RTX 4080), split as the paper splits it, on a synthetic frame so that no data is needed; and
//! beside it, as the reference of the same run, the multiply-add rate of a plain matrix product
//! on the same backend, so that the network's own rate reads as a fraction of what the machine
//! does.

use std::time::Instant;

use burn::tensor::{Device, Distribution, Tensor};
use fewview_scene::{Camera, Image, Intrinsics};
use nalgebra::Vector3;
use serde::Serialize;

use crate::error::{HumanError, Result};
use crate::maps::{DepthMap, Mask};
use crate::net::{PoseGaussianNet, Variant, forward_macs};
use crate::tps::{Stabilizer, TpsConfig};
use crate::train::forward::{maps_of, net_input, render_prediction};
use crate::train::prepare::{Framing, PreparedView};
use crate::train::trainer::{Preset, TrainConfig, forward_settings, net_config};

/// Seconds per frame of one preset, by stage (means over the timed frames).
#[derive(Clone, Debug, Serialize)]
pub struct InferenceBench {
    pub preset: String,
    /// Crop `[width, height]` the network runs at.
    pub size: [usize; 2],
    pub source_views: usize,
    pub frames: usize,
    pub macs_per_frame: u64,
    pub seconds_per_frame: f64,
    pub image_encoder: f64,
    pub pose_encoder: f64,
    pub depth_encoder: f64,
    pub decoder_and_heads: f64,
    pub tps: f64,
    pub rendering: f64,
    /// The network's multiply-adds per second.
    pub network_gmacs_per_s: f64,
    /// A 1024³ matrix product's multiply-adds per second (the reference).
    pub matmul_gmacs_per_s: f64,
    /// `network_gmacs_per_s / matmul_gmacs_per_s`.
    pub network_vs_matmul: f64,
}

/// Seconds per training step of the network alone (forward and backward on two source views,
/// a loss that reads every head), and its rate against the same run's matrix product.
#[derive(Clone, Debug, Serialize)]
pub struct TrainingBench {
    pub preset: String,
    /// Where it ran: `cpu`, or `gpu` for any other device.
    pub device: String,
    pub size: [usize; 2],
    pub steps: usize,
    /// Forward and backward, seconds per step (the mean over the timed steps).
    pub seconds_per_step: f64,
    /// Of which the forward pass.
    pub forward_seconds: f64,
    /// Multiply-adds of a step: the forward's three times (the backward costs two forwards).
    pub macs_per_step: u64,
    pub network_gmacs_per_s: f64,
    pub matmul_gmacs_per_s: f64,
    /// `network_gmacs_per_s / matmul_gmacs_per_s`.
    pub network_vs_matmul: f64,
}

/// Times `steps` forward and backward passes of `preset` (after one warm-up step) on two
/// synthetic source views, on `device` (the CPU or a GPU) with autodiff, each pass waited for.
pub fn training_bench(preset: Preset, steps: usize, device: &Device) -> Result<TrainingBench> {
    let compute = device.clone();
    let device = compute.clone().autodiff();
    let device_error = |e: &dyn std::fmt::Debug| {
        HumanError::argument("training bench", format!("the device failed: {e:?}"))
    };
    let (net_cfg, framing, config) = bench_setup(preset);
    let parents = chain();
    let settings = forward_settings(&config, &framing, &parents);
    let net = PoseGaussianNet::new(&net_cfg, &device)?;
    let views = source_pair(&framing);
    let refs: Vec<&PreparedView> = views.iter().collect();
    let (mut total, mut forward) = (0.0f64, 0.0f64);
    for step in 0..=steps {
        let input = net_input(&refs, &settings, &device)?;
        let clock = Instant::now();
        let h = net.forward(input)?;
        let loss = h.scale.sum() + h.rotation.sum() + h.opacity.sum() + h.depth.sum();
        let loss = loss + h.uncertainty.sum();
        loss.clone().try_into_data().map_err(|e| device_error(&e))?;
        let t_forward = clock.elapsed().as_secs_f64();
        let grads = loss.backward();
        device.sync().map_err(|e| device_error(&e))?;
        drop(grads);
        if step > 0 {
            total += clock.elapsed().as_secs_f64();
            forward += t_forward;
        }
    }
    let k = 1.0 / steps.max(1) as f64;
    let size = framing.size;
    let macs = 3 * forward_macs(&net_cfg, size[1], size[0]) * views.len() as u64;
    let rate = macs as f64 / (total * k) / 1e9;
    let matmul = matmul_rate(&compute);
    Ok(TrainingBench {
        preset: format!("{preset:?}").to_lowercase(),
        device: if compute == Device::flex() {
            "cpu"
        } else {
            "gpu"
        }
        .into(),
        size,
        steps,
        seconds_per_step: total * k,
        forward_seconds: forward * k,
        macs_per_step: macs,
        network_gmacs_per_s: rate,
        matmul_gmacs_per_s: matmul,
        network_vs_matmul: rate / matmul,
    })
}

/// The network configuration, a framing of a person-sized box at 3 m, and the training
/// configuration of `preset`.
fn bench_setup(preset: Preset) -> (crate::net::NetConfig, Framing, TrainConfig) {
    let config = TrainConfig {
        preset,
        variant: Variant::Normalized,
        ..TrainConfig::default()
    };
    let net_cfg = net_config(&config, &chain());
    let size = [net_cfg.input[1], net_cfg.input[0]];
    let framing = Framing {
        bounds: [[-0.4, -0.3, 0.0], [0.4, 0.3, 1.8]],
        scale: size[1] as f64 / 512.0,
        size,
        near: 2.0,
        far: 4.0,
    };
    (net_cfg, framing, config)
}

/// Two synthetic source views 57° apart (cameras 0 and 1).
fn source_pair(framing: &Framing) -> [PreparedView; 2] {
    [
        synthetic_view(0, -0.5, framing),
        synthetic_view(1, 0.5, framing),
    ]
}

/// A 17-joint chain: the synthetic capture's joint count, so that the pose map has its 33
/// channels.
fn chain() -> Vec<i64> {
    (0..17).map(|j| j as i64 - 1).collect()
}

/// A source view of a person-sized ellipse at 3 m, seen by a camera on a ring.
fn synthetic_view(index: usize, angle: f64, framing: &Framing) -> PreparedView {
    let [w, h] = framing.size;
    let f = 640.0 * framing.scale;
    let k = Intrinsics {
        fx: f,
        fy: f,
        cx: w as f64 / 2.0,
        cy: h as f64 / 2.0,
        width: w as u32,
        height: h as u32,
    };
    let eye = Vector3::new(3.0 * angle.sin(), -3.0 * angle.cos(), 0.9);
    let camera = Camera::look_at(k, eye, Vector3::new(0.0, 0.0, 0.9), Vector3::z());
    let inside = |x: usize, y: usize| {
        let (u, v) = (
            (x as f64 + 0.5) / w as f64 - 0.5,
            (y as f64 + 0.5) / h as f64 - 0.5,
        );
        (u / 0.3).powi(2) + (v / 0.45).powi(2) < 1.0
    };
    let mask: Vec<bool> = (0..w * h).map(|p| inside(p % w, p / w)).collect();
    let image = Image {
        width: w,
        height: h,
        channels: 3,
        data: (0..w * h * 3)
            .map(|i| 0.5 + 0.4 * ((i / 3) as f32 * 0.37 + (i % 3) as f32).sin())
            .collect(),
    };
    let depth: Vec<f32> = mask.iter().map(|&m| if m { 3.0 } else { 0.0 }).collect();
    let joints = (0..17)
        .map(|j| [w as f64 / 2.0, h as f64 * (0.1 + 0.05 * j as f64)])
        .collect();
    let hull_depth = DepthMap {
        width: w,
        height: h,
        data: depth,
    };
    PreparedView {
        camera_index: index,
        camera,
        image,
        mask: Mask::new(w, h, mask),
        input_depth: hull_depth.clone(),
        stereo_matched: 0.0,
        hull_depth,
        depth: None,
        joints,
    }
}

/// The multiply-add rate of a 1024³ product (GMAC/s), best of three.
fn matmul_rate(device: &Device) -> f64 {
    let n = 1024;
    let a = Tensor::<2>::random([n, n], Distribution::Default, device);
    let b = Tensor::<2>::random([n, n], Distribution::Default, device);
    (0..3)
        .map(|_| {
            let t = Instant::now();
            let c = a.clone().matmul(b.clone());
            let _ = c.into_data();
            (n * n * n) as f64 / t.elapsed().as_secs_f64() / 1e9
        })
        .fold(0.0, f64::max)
}

/// Times `frames` frames (after one warm-up frame) of `preset` with randomly initialised
/// weights: two source views through the network, TPS and the render into a third camera.
pub fn inference_bench(preset: Preset, frames: usize) -> Result<InferenceBench> {
    let device = Device::flex();
    let parents = chain();
    let (net_cfg, framing, config) = bench_setup(preset);
    let size = framing.size;
    let settings = forward_settings(&config, &framing, &parents);
    let net = PoseGaussianNet::new(&net_cfg, &device)?;
    let views = source_pair(&framing);
    let refs: Vec<&PreparedView> = views.iter().collect();
    let target = synthetic_view(2, 0.0, &framing).camera;
    let mut tps = Stabilizer::new(TpsConfig::default());
    let joints: Vec<[f64; 3]> = (0..17).map(|j| [0.0, 0.0, 0.1 * j as f64]).collect();
    let mut sums = [0.0f64; 6];
    for frame in 0..=frames {
        let (heads, t) = net.forward_timed(net_input(&refs, &settings, &device)?)?;
        let maps = maps_of(&heads, &refs, &settings)?;
        let clock = Instant::now();
        for (v, m) in views.iter().zip(&maps) {
            let source = crate::infer::to_source_maps(m, &v.mask)?;
            tps.apply(v.camera_index, frame, &v.camera, source, &joints)?;
        }
        let t_tps = clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        crate::infer::to_image(&render_prediction(&refs, &maps, &target, &settings)?.rgb)?;
        let t_render = clock.elapsed().as_secs_f64();
        if frame > 0 {
            let parts = [
                t.image_encoder,
                t.pose_encoder,
                t.depth_encoder,
                t.decoder_and_heads,
                t_tps,
                t_render,
            ];
            sums.iter_mut().zip(parts).for_each(|(s, p)| *s += p);
        }
    }
    let k = 1.0 / frames.max(1) as f64;
    let [
        image_encoder,
        pose_encoder,
        depth_encoder,
        decoder_and_heads,
        tps_s,
        rendering,
    ] = sums.map(|s| s * k);
    let network = image_encoder + pose_encoder + depth_encoder + decoder_and_heads;
    let macs = forward_macs(&net_cfg, size[1], size[0]) * views.len() as u64;
    let network_rate = macs as f64 / network / 1e9;
    let matmul = matmul_rate(&device);
    Ok(InferenceBench {
        preset: format!("{preset:?}").to_lowercase(),
        size,
        source_views: views.len(),
        frames,
        macs_per_frame: macs,
        seconds_per_frame: network + tps_s + rendering,
        image_encoder,
        pose_encoder,
        depth_encoder,
        decoder_and_heads,
        tps: tps_s,
        rendering,
        network_gmacs_per_s: network_rate,
        matmul_gmacs_per_s: matmul,
        network_vs_matmul: network_rate / matmul,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The stages add up to the frame, and the multiply-adds are the network's for two views.
    #[test]
    fn cpu_preset_figures_add_up() {
        let _rng = crate::net::seed::seeded(3);
        let b = inference_bench(Preset::Cpu, 1).unwrap();
        let stages = b.image_encoder
            + b.pose_encoder
            + b.depth_encoder
            + b.decoder_and_heads
            + b.tps
            + b.rendering;
        assert!((stages - b.seconds_per_frame).abs() < 1e-9, "{b:?}");
        let cfg = net_config(&TrainConfig::default(), &chain());
        assert_eq!(b.macs_per_frame, 2 * forward_macs(&cfg, 256, 128));
        assert!(
            b.network_gmacs_per_s > 0.0 && b.matmul_gmacs_per_s > 0.0 && b.tps > 0.0,
            "{b:?}"
        );
        println!("{b:#?}");
    }
}
