//! Training on the GPU (feature `gpu`) reaches the held-out PSNR of the same run on the CPU.
//! Runs wherever wgpu finds an adapter; CI runs it on Mesa's lavapipe.
#![cfg(feature = "gpu")]
// Tests report what they measured.
#![allow(clippy::print_stderr)]

use fewview_scene::synthetic::{DemoOptions, DemoShading, demo_dataset};
use fewview_splat::ComputeDevice;
use fewview_splat::pipeline::{RunConfig, train_run};
use fewview_splat::train::TrainConfig;

/// Iterations of each run: enough for the held-out PSNR to rise well above the start.
const ITERATIONS: usize = 300;

#[test]
fn gpu_training_matches_cpu_training_on_the_demo_scene() {
    let ds = demo_dataset(&DemoOptions {
        width: 80,
        height: 60,
        views: 9,
        train: vec![1, 4, 7],
        supersample: 2,
        shading: DemoShading::Lambertian,
        ..DemoOptions::default()
    });
    let mut psnr = Vec::new();
    for device in [ComputeDevice::Cpu, ComputeDevice::Gpu] {
        let mut cfg = RunConfig::new(TrainConfig::sparse_view(ITERATIONS));
        cfg.init_points = 5000;
        cfg.device = device;
        let dir = tempfile::tempdir().unwrap();
        let summary = train_run(&ds, &cfg, dir.path(), false, |_| {}).unwrap();
        eprintln!(
            "{}: held-out PSNR {:.3} dB after {ITERATIONS} iterations",
            device.name(),
            summary.test.mean_psnr
        );
        psnr.push(summary.test.mean_psnr);
    }
    assert!(
        (psnr[0] - psnr[1]).abs() <= 0.1,
        "CPU {:.3} dB, GPU {:.3} dB",
        psnr[0],
        psnr[1]
    );
}
