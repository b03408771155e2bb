//! Rasterizer figures on the GPU for `fewview bench --device gpu`: forward and forward+backward
//! through the Burn op on a [`SyntheticScene`], the CPU rasterizer on the same scene in the same
//! run as the yardstick, and the device memory the allocator reserved.

use std::time::Instant;

use burn::tensor::{Device, Tensor, TensorData};
use serde::Serialize;

use crate::bench::SyntheticScene;
use crate::op::{GaussianTensors, RenderView, render_deferred};
use crate::raster::RenderSettings;
use crate::raster::render::{OUT_CHANNELS, backward, forward};

/// What `fewview bench --device gpu` reports.
#[derive(Clone, Debug, Serialize)]
pub struct GpuRasterBench {
    pub adapter: String,
    pub gaussians: usize,
    pub width: usize,
    pub height: usize,
    pub runs: usize,
    /// Median wall seconds of a render, waited for.
    pub forward_seconds: f64,
    /// Median wall seconds of a render, a weighted-sum loss and its backward pass, waited for.
    pub forward_backward_seconds: f64,
    /// The same two on the CPU rasterizer (all threads), on the same scene.
    pub cpu_forward_seconds: f64,
    pub cpu_forward_backward_seconds: f64,
    pub speedup_forward: f64,
    pub speedup_forward_backward: f64,
    /// Bytes the device allocator held after the timed runs (an upper bound of the peak).
    pub device_bytes_reserved: Option<u64>,
    /// Median seconds of each stage of a forward+backward pass, in separate runs that wait for
    /// the device after every stage (so their sum exceeds `forward_backward_seconds`).
    pub stages: Vec<StageTime>,
}

/// One rasterizer stage's median wall time.
#[derive(Clone, Debug, Serialize)]
pub struct StageTime {
    pub stage: String,
    pub seconds: f64,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn gaussians(scene: &SyntheticScene, device: &Device) -> GaussianTensors {
    let n = scene.opacity_logits.len();
    let t2 = |v: &Vec<f32>, c: usize| {
        Tensor::<2>::from_data(TensorData::new(v.clone(), [n, c]), device).require_grad()
    };
    GaussianTensors {
        means: t2(&scene.means, 3),
        log_scales: t2(&scene.log_scales, 3),
        quats: t2(&scene.quats, 4),
        opacity_logits: Tensor::<1>::from_data(
            TensorData::new(scene.opacity_logits.clone(), [n]),
            device,
        )
        .require_grad(),
        sh: Tensor::<3>::from_data(TensorData::new(scene.sh.clone(), [n, 16, 3]), device)
            .require_grad(),
    }
}

/// Times the GPU rasterizer on `device` (a GPU device, without autodiff) against the CPU one.
pub fn gpu_raster_bench(
    device: &Device,
    scene: &SyntheticScene,
    runs: usize,
) -> Result<GpuRasterBench, String> {
    let runs = runs.max(1);
    let n = scene.opacity_logits.len();
    let cam = scene.camera.clone();
    let view = RenderView {
        camera: cam.clone(),
        settings: RenderSettings::default(),
    };
    let train = device.clone().autodiff();
    let g = gaussians(scene, &train);
    let (h, w) = (cam.height, cam.width);
    let weights: Vec<f32> = (0..h * w * OUT_CHANNELS)
        .map(|i| if i % OUT_CHANNELS < 3 { 1e-3 } else { 0.0 })
        .collect();
    let weights_t = Tensor::<3>::from_data(
        TensorData::new(weights.clone(), [h, w, OUT_CHANNELS]),
        &train,
    );
    let sync = || train.sync().map_err(|e| format!("device: {e:?}"));
    let step = |backward: bool| -> Result<f64, String> {
        let t0 = Instant::now();
        let probe = Tensor::<2>::zeros([n, 2], &train).require_grad();
        // As a training step renders: the pair count stays on the device.
        let (out, pairs) = render_deferred(&g, probe, &view);
        if backward {
            let grads = (out.image * weights_t.clone()).sum().backward();
            std::hint::black_box(g.means.grad(&grads));
        } else {
            std::hint::black_box(out.image);
        }
        sync()?;
        let seconds = t0.elapsed().as_secs_f64();
        // Checked after the clock stops: a render without room for its pairs would be timed
        // short (the warm-up render sizes the buffers, so none should be).
        if pairs.overflowed() {
            return Err("a timed render ran out of pair slots".into());
        }
        Ok(seconds)
    };
    step(true)?;
    step(true)?;
    let forward_seconds = median((0..runs).map(|_| step(false)).collect::<Result<_, _>>()?);
    let forward_backward_seconds = median((0..runs).map(|_| step(true)).collect::<Result<_, _>>()?);
    crate::gpu::profile::start();
    for _ in 0..runs {
        step(true)?;
    }
    let stages = crate::gpu::profile::finish()
        .into_iter()
        .map(|(stage, times)| StageTime {
            stage: stage.to_string(),
            seconds: median(times),
        })
        .collect();
    let refs = scene.refs();
    let cpu_runs = runs.min(3);
    let cpu_forward_seconds = median(
        (0..cpu_runs)
            .map(|_| {
                let t0 = Instant::now();
                std::hint::black_box(forward(&refs, &cam, &view.settings));
                t0.elapsed().as_secs_f64()
            })
            .collect(),
    );
    let cpu_forward_backward_seconds = median(
        (0..cpu_runs)
            .map(|_| {
                let t0 = Instant::now();
                let (_, ctx) = forward(&refs, &cam, &view.settings);
                std::hint::black_box(backward(&refs, &ctx, &weights));
                t0.elapsed().as_secs_f64()
            })
            .collect(),
    );
    Ok(GpuRasterBench {
        adapter: format!("{device:?}"),
        gaussians: n,
        width: w,
        height: h,
        runs,
        forward_seconds,
        forward_backward_seconds,
        cpu_forward_seconds,
        cpu_forward_backward_seconds,
        speedup_forward: cpu_forward_seconds / forward_seconds,
        speedup_forward_backward: cpu_forward_backward_seconds / forward_backward_seconds,
        device_bytes_reserved: device.memory_pool_usage().map(|u| u.bytes_reserved),
        stages,
    })
}
