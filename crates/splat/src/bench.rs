//! Rasterizer throughput figures for `fewview bench`, with a plain single-threaded blend loop
//! measured in the same run as the yardstick.

use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use serde::Serialize;

use crate::raster::project::Splat;
use crate::raster::render::{OUT_CHANNELS, backward, forward};
use crate::raster::{
    ALPHA_MAX, ALPHA_MIN, GaussianRefs, RenderCamera, RenderSettings, T_MIN, TILE,
};
use crate::sh::SH_C0;
use fewview_scene::cputime::measure;

/// A synthetic scene shaped like a trained forward-facing capture: Gaussians spread through the
/// view frustum between depths 2 and 10, screen sizes log-uniform between 0.5 and 6 px (σ),
/// anisotropic, opacities `σ(N(0, 2))`, SH degree 3.
pub struct SyntheticScene {
    pub means: Vec<f32>,
    pub log_scales: Vec<f32>,
    pub quats: Vec<f32>,
    pub opacity_logits: Vec<f32>,
    pub sh: Vec<f32>,
    pub camera: RenderCamera,
}

impl SyntheticScene {
    pub fn new(n: usize, width: usize, height: usize, seed: u64) -> Self {
        let focal = 0.8 * width as f64;
        let camera = RenderCamera {
            fx: focal,
            fy: focal,
            cx: width as f64 / 2.0,
            cy: height as f64 / 2.0,
            width,
            height,
            rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            translation: [0.0; 3],
        };
        let mut rng = StdRng::seed_from_u64(seed);
        let mut s = Self {
            means: Vec::with_capacity(n * 3),
            log_scales: Vec::with_capacity(n * 3),
            quats: Vec::with_capacity(n * 4),
            opacity_logits: Vec::with_capacity(n),
            sh: Vec::with_capacity(n * 48),
            camera,
        };
        for _ in 0..n {
            let z = 2.0 + 8.0 * rng.random::<f64>();
            let u = (rng.random::<f64>() - 0.5) * width as f64 * 1.1;
            let v = (rng.random::<f64>() - 0.5) * height as f64 * 1.1;
            s.means
                .extend([(u * z / focal) as f32, (v * z / focal) as f32, z as f32]);
            let sigma_px = (0.5f64.ln() + (12.0f64).ln() * rng.random::<f64>()).exp();
            let base = (sigma_px * z / focal).ln();
            for _ in 0..3 {
                s.log_scales
                    .push((base + 0.5 * (rng.random::<f64>() - 0.5)) as f32);
            }
            let q: [f32; 4] = std::array::from_fn(|_| rng.random::<f32>() - 0.5);
            s.quats.extend(q);
            let normal: f64 = (0..12).map(|_| rng.random::<f64>()).sum::<f64>() - 6.0;
            s.opacity_logits.push((2.0 * normal) as f32);
            for k in 0..48 {
                s.sh.push(if k < 3 {
                    ((rng.random::<f64>() - 0.5) / SH_C0) as f32
                } else {
                    0.1 * (rng.random::<f32>() - 0.5)
                });
            }
        }
        s
    }

    /// The scene as a model (to write it as a PLY).
    pub fn to_model(&self) -> crate::model::GaussianModel {
        crate::model::GaussianModel {
            means: self.means.clone(),
            log_scales: self.log_scales.clone(),
            quats: self.quats.clone(),
            opacity_logits: self.opacity_logits.clone(),
            sh: self.sh.clone(),
            sh_coeffs: 16,
        }
    }

    pub fn refs(&self) -> GaussianRefs<'_, f32> {
        GaussianRefs {
            means: &self.means,
            log_scales: &self.log_scales,
            quats: &self.quats,
            opacity_logits: &self.opacity_logits,
            sh: &self.sh,
            sh_coeffs: 16,
        }
    }
}

/// Rasterizer throughput at one load.
#[derive(Clone, Debug, Serialize)]
pub struct RasterBench {
    pub gaussians: usize,
    pub width: usize,
    pub height: usize,
    /// Threads of the wall-clock measurement (all of rayon's pool).
    pub threads: usize,
    /// Median wall-clock seconds of one render / one backward pass on all threads.
    pub forward_seconds: f64,
    pub backward_seconds: f64,
    /// Median CPU seconds (summed over threads) of the same.
    pub forward_cpu_seconds: f64,
    pub backward_cpu_seconds: f64,
    /// Median CPU seconds of one render / backward pass on a one-thread pool: the per-core
    /// measurement, free of the contention between threads that share a physical core.
    pub forward_single_thread_cpu_seconds: f64,
    pub backward_single_thread_cpu_seconds: f64,
    pub forward_pairs: u64,
    pub backward_pairs: u64,
    /// Splat–pixel pairs per CPU-second on one thread (per core).
    pub forward_pairs_per_sec_per_core: f64,
    pub backward_pairs_per_sec_per_core: f64,
    /// Splat–pixel pairs per CPU-second with all threads running (per CPU-second summed over
    /// threads; lower than per core when the threads share cores or memory bandwidth).
    pub forward_pairs_per_cpu_sec_all_threads: f64,
    pub backward_pairs_per_cpu_sec_all_threads: f64,
    /// The yardstick: a plain single-threaded per-pixel blend loop (library `exp`, scalar) over
    /// the same tile lists, pairs per CPU-second on one core.
    pub reference_pairs_per_sec: f64,
    pub reference_seconds: f64,
    pub forward_vs_reference: f64,
}

/// Median wall and CPU seconds of `runs` calls of `f` (CPU time summed over threads: the
/// core-seconds used, robust to other load on the machine).
pub fn median_seconds(runs: usize, mut f: impl FnMut()) -> (f64, f64) {
    let mut wall = Vec::with_capacity(runs);
    let mut cpu = Vec::with_capacity(runs);
    for _ in 0..runs.max(1) {
        let ((), w, c) = measure(&mut f);
        wall.push(w);
        cpu.push(c);
    }
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    (median(wall), median(cpu))
}

/// Plain blend over the tile lists: pixel-outer, splat-inner, library `exp`, early break. Returns
/// the image checksum (kept so the work is not optimised away) and the pairs evaluated.
fn reference_blend(
    splats: &[Splat<f32>],
    bins: &crate::raster::tiles::TileBins,
    width: usize,
    height: usize,
) -> (f64, u64) {
    let mut pairs = 0u64;
    let mut checksum = 0.0f64;
    for t in 0..bins.num_tiles() {
        let (tx, ty) = (t % bins.tiles_x, t / bins.tiles_x);
        let list = bins.tile_entries(t);
        for y in ty * TILE..((ty + 1) * TILE).min(height) {
            for x in tx * TILE..((tx + 1) * TILE).min(width) {
                let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
                let mut tr = 1.0f32;
                let mut c = [0.0f32; 3];
                for &si in list {
                    let s = &splats[si as usize];
                    pairs += 1;
                    let (dx, dy) = (px - s.mean[0], py - s.mean[1]);
                    let power =
                        -0.5 * (s.conic[0] * dx * dx + s.conic[2] * dy * dy) - s.conic[1] * dx * dy;
                    if power > 0.0 {
                        continue;
                    }
                    let alpha = (s.opacity * power.exp()).min(ALPHA_MAX as f32);
                    if alpha < ALPHA_MIN as f32 {
                        continue;
                    }
                    let next = tr * (1.0 - alpha);
                    if next < T_MIN as f32 {
                        break;
                    }
                    for (ck, sk) in c.iter_mut().zip(s.color) {
                        *ck += sk * alpha * tr;
                    }
                    tr = next;
                }
                checksum += (c[0] + c[1] + c[2]) as f64;
            }
        }
    }
    (checksum, pairs)
}

/// Measures forward and backward throughput on a [`SyntheticScene`]: per core on a one-thread
/// pool, and wall-clock on all threads.
pub fn raster_bench(n: usize, width: usize, height: usize, runs: usize) -> RasterBench {
    let scene = SyntheticScene::new(n, width, height, 1);
    let settings = RenderSettings::default();
    let g = scene.refs();
    let threads = rayon::current_num_threads();
    let (out, ctx) = forward(&g, &scene.camera, &settings);
    let grad_out: Vec<f32> = (0..out.data.len())
        .into_par_iter()
        .map(|i| if i % OUT_CHANNELS < 3 { 1e-3 } else { 0.0 })
        .collect();
    let grads = backward(&g, &ctx, &grad_out);
    let time_both = || {
        let fwd = median_seconds(runs, || {
            std::hint::black_box(forward(&g, &scene.camera, &settings));
        });
        let bwd = median_seconds(runs, || {
            std::hint::black_box(backward(&g, &ctx, &grad_out));
        });
        (fwd, bwd)
    };
    let ((forward_seconds, forward_cpu_seconds), (backward_seconds, backward_cpu_seconds)) =
        time_both();
    let ((_, forward_single), (_, backward_single)) =
        match rayon::ThreadPoolBuilder::new().num_threads(1).build() {
            Ok(pool) => pool.install(time_both),
            // No second pool (should not happen): fall back to the all-threads figures.
            Err(_) => (
                (forward_seconds, forward_cpu_seconds),
                (backward_seconds, backward_cpu_seconds),
            ),
        };
    let mut ref_pairs = 0;
    let (reference_seconds, reference_cpu_seconds) = median_seconds(runs.min(3), || {
        let (sum, pairs) = reference_blend(&ctx.splats, &ctx.bins, width, height);
        std::hint::black_box(sum);
        ref_pairs = pairs;
    });
    let rate = |pairs: u64, cpu_secs: f64| pairs as f64 / cpu_secs;
    let reference_pairs_per_sec = ref_pairs as f64 / reference_cpu_seconds;
    RasterBench {
        gaussians: n,
        width,
        height,
        threads,
        forward_seconds,
        backward_seconds,
        forward_cpu_seconds,
        backward_cpu_seconds,
        forward_single_thread_cpu_seconds: forward_single,
        backward_single_thread_cpu_seconds: backward_single,
        forward_pairs: out.pairs,
        backward_pairs: grads.pairs,
        forward_pairs_per_sec_per_core: rate(out.pairs, forward_single),
        backward_pairs_per_sec_per_core: rate(grads.pairs, backward_single),
        forward_pairs_per_cpu_sec_all_threads: rate(out.pairs, forward_cpu_seconds),
        backward_pairs_per_cpu_sec_all_threads: rate(grads.pairs, backward_cpu_seconds),
        reference_pairs_per_sec,
        reference_seconds,
        forward_vs_reference: rate(out.pairs, forward_single) / reference_pairs_per_sec,
    }
}

/// Training-step throughput on a dataset (the default sparse-view run's first iterations).
#[derive(Clone, Debug, Serialize)]
pub struct TrainStepBench {
    pub dataset: String,
    pub width: usize,
    pub height: usize,
    pub gaussians: usize,
    pub iterations: usize,
    pub seconds: f64,
    pub cpu_seconds: f64,
    pub iterations_per_second: f64,
    /// Iterations per CPU-second (per core).
    pub iterations_per_cpu_second: f64,
}

/// Times `iterations` training steps (after 2 warm-up steps) of the default run on `ds`, from
/// its default initialisation.
pub fn train_step_bench(
    ds: &fewview_scene::Dataset,
    iterations: usize,
    device: crate::device::ComputeDevice,
) -> Result<TrainStepBench, crate::pipeline::PipelineError> {
    let mut cfg = crate::pipeline::RunConfig::new(crate::train::TrainConfig::sparse_view(3000));
    cfg.train.background = ds.background;
    cfg.device = device;
    train_step_bench_with(ds, &cfg, Vec::new(), iterations)
}

/// [`train_step_bench`] of the run `cfg` with extra loss terms (e.g. the fusion method's).
pub fn train_step_bench_with(
    ds: &fewview_scene::Dataset,
    cfg: &crate::pipeline::RunConfig,
    terms: Vec<Box<dyn crate::train::LossTerm>>,
    iterations: usize,
) -> Result<TrainStepBench, crate::pipeline::PipelineError> {
    use crate::pipeline::initial_model;
    use crate::raster::RenderCamera;
    use crate::train::{TrainView, Trainer};
    let model = initial_model(ds, cfg)?;
    let device = cfg.device.open()?.autodiff();
    let views: Vec<TrainView> = ds
        .train_views()
        .map(|v| TrainView::new(&v.name, RenderCamera::from(&v.camera), &v.image, &device))
        .collect();
    let (_, extent) = ds.camera_extent();
    let first = &ds.views[ds.train[0]].image;
    let gaussians = model.len();
    let mut trainer = Trainer::new(cfg.train.clone(), model, views, extent as f32, device)?;
    for term in terms {
        trainer.add_term(term);
    }
    trainer.step()?;
    trainer.step()?;
    let (result, seconds, cpu_seconds) = measure(|| {
        for _ in 0..iterations {
            trainer.step()?;
        }
        Ok::<(), crate::train::TrainError>(())
    });
    result?;
    Ok(TrainStepBench {
        dataset: ds.name.clone(),
        width: first.width,
        height: first.height,
        gaussians,
        iterations,
        seconds,
        cpu_seconds,
        iterations_per_second: iterations as f64 / seconds,
        iterations_per_cpu_second: iterations as f64 / cpu_seconds,
    })
}

/// Training steps with and without a per-photo appearance model, same scene and start.
#[derive(Clone, Debug, Serialize)]
pub struct AppearanceStepBench {
    pub plain: TrainStepBench,
    pub affine: TrainStepBench,
    /// What the colour transform adds to a step: `t_affine / t_plain − 1` in CPU time (summed
    /// over threads, which other programs on the machine change little).
    pub overhead: f64,
}

/// Times `iterations` steps of `ds`'s default run without and with the affine colour transform
/// per photo ([`crate::train::appearance`]): two rounds, alternating, each side's faster round
/// kept, so that a load which comes and goes does not fall on one side only.
pub fn appearance_step_bench(
    ds: &fewview_scene::Dataset,
    iterations: usize,
) -> Result<AppearanceStepBench, crate::pipeline::PipelineError> {
    let mut plain_cfg =
        crate::pipeline::RunConfig::new(crate::train::TrainConfig::sparse_view(3000));
    plain_cfg.train.background = ds.background;
    let mut affine_cfg = plain_cfg.clone();
    affine_cfg.train.appearance.model = crate::train::AppearanceModel::Affine;
    let faster = |a: TrainStepBench, b: TrainStepBench| {
        if a.cpu_seconds <= b.cpu_seconds { a } else { b }
    };
    let mut plain = train_step_bench_with(ds, &plain_cfg, Vec::new(), iterations)?;
    let mut affine = train_step_bench_with(ds, &affine_cfg, Vec::new(), iterations)?;
    plain = faster(
        plain,
        train_step_bench_with(ds, &plain_cfg, Vec::new(), iterations)?,
    );
    affine = faster(
        affine,
        train_step_bench_with(ds, &affine_cfg, Vec::new(), iterations)?,
    );
    Ok(AppearanceStepBench {
        overhead: affine.cpu_seconds / plain.cpu_seconds - 1.0,
        plain,
        affine,
    })
}
