//! Speed figures for `fewview bench`: SSIM value + gradient at the LLFF training size
//! (504×378×3), on the global rayon pool and on one thread, with PSNR in the same run as a
//! memory-bound reference.

use std::time::Instant;

use fewview_scene::Image;

use crate::psnr::psnr;
use crate::ssim::{SsimOptions, SsimWorkspace, ssim_with};

/// Median wall-clock milliseconds of each measured operation.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SsimBench {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub threads: usize,
    /// `SsimWorkspace::value_and_grad` (reused buffers), zero-padded training variant, all threads.
    pub value_grad_ms: f64,
    /// The same on a one-thread pool.
    pub value_grad_1thread_ms: f64,
    /// `ssim_with` (value only, scikit-image variant), all threads.
    pub value_ms: f64,
    /// PSNR of the same pair: one pass over both images (reference).
    pub psnr_ms: f64,
    /// Pixel-channels per second per core of the value + gradient.
    pub value_grad_px_per_s_per_core: f64,
}

fn median_ms(reps: usize, mut f: impl FnMut()) -> f64 {
    f();
    let mut t: Vec<f64> = (0..reps)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

/// Runs the SSIM benchmark on a deterministic synthetic pair of `width × height × 3` images.
pub fn ssim_bench(width: usize, height: usize, reps: usize) -> SsimBench {
    let make = |phase: f32| {
        let mut img = Image::new(width, height, 3);
        for (i, v) in img.data.iter_mut().enumerate() {
            let (p, c) = (i / 3, i % 3);
            let (x, y) = ((p % width) as f32, (p / width) as f32);
            *v = 0.5 + 0.4 * ((x * 0.07 + phase).sin() * (y * 0.05 + c as f32).cos());
        }
        img
    };
    let (a, b) = (make(0.0), make(0.3));
    let train = SsimOptions::training_loss();
    let reps = reps.max(1);
    let mut ws = SsimWorkspace::new();
    let value_grad_ms = median_ms(reps, || {
        std::hint::black_box(ws.value_and_grad(&a, &b, None, &train).expect("valid"));
    });
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("thread pool");
    let value_grad_1thread_ms = one.install(|| {
        median_ms(reps, || {
            std::hint::black_box(ws.value_and_grad(&a, &b, None, &train).expect("valid"));
        })
    });
    let value_ms = median_ms(reps, || {
        std::hint::black_box(ssim_with(&a, &b, &SsimOptions::default()).expect("valid"));
    });
    let psnr_ms = median_ms(reps, || {
        std::hint::black_box(psnr(&a, &b).expect("valid"));
    });
    SsimBench {
        width,
        height,
        channels: 3,
        threads: rayon::current_num_threads(),
        value_grad_ms,
        value_grad_1thread_ms,
        value_ms,
        psnr_ms,
        value_grad_px_per_s_per_core: (width * height * 3) as f64 / (value_grad_1thread_ms * 1e-3),
    }
}
