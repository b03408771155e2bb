//! Times one forward pass of PoseGaussian's network on the CPU (`flex`), beside a reference
//! measured in the same run (one 3×3 convolution, 32 → 64 channels at 256×256, 1.21 G
//! multiply-adds), and prints the multiply-add count of both presets:
//! `cargo run --release -p fewview-human --example net_forward [variant 1-4] [repeats]`.

// An example program prints its results.
#![allow(clippy::print_stdout, clippy::print_stderr)]

use std::time::Instant;

use burn::tensor::{Device, Distribution, Tensor};
use fewview_human::net::{NetConfig, NetInput, PoseGaussianNet, Variant, forward_macs};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let variant = Variant::from_number(args.next().map_or(Ok(3), |a| a.parse())?)?;
    let repeats: usize = args.next().map_or(Ok(5), |a| a.parse())?;
    for config in [NetConfig::paper(variant), NetConfig::cpu(variant)] {
        let [h, w] = config.input;
        let macs = forward_macs(&config, h, w);
        println!(
            "{config}: {:.3} G multiply-adds per view",
            macs as f64 / 1e9
        );
    }
    let device = Device::flex();
    device.seed(0);
    let config = NetConfig::cpu(variant);
    let net = PoseGaussianNet::new(&config, &device)?;
    let [h, w] = config.input;
    let r = |c: usize| Tensor::<4>::random([1, c, h, w], Distribution::Uniform(0.0, 1.0), &device);
    let input = NetInput {
        image: r(3),
        pose: r(config.pose_channels),
        depth: r(1),
    };
    let run = || -> Result<f64, Box<dyn std::error::Error>> {
        let start = Instant::now();
        let out = net.forward(input.clone())?;
        let _ = out.scale.into_data();
        let _ = out.depth.into_data();
        Ok(start.elapsed().as_secs_f64() * 1e3)
    };
    println!("first pass (initialises the weights): {:.1} ms", run()?);
    let mut times: Vec<f64> = (0..repeats).map(|_| run()).collect::<Result<_, _>>()?;
    times.sort_by(f64::total_cmp);
    let macs = forward_macs(&config, h, w) as f64;
    let median = times[times.len() / 2];
    println!(
        "cpu preset {h}×{w}, config {}: median {median:.1} ms, min {:.1} ms over {repeats} passes, {:.1} G multiply-adds/s",
        variant.number(),
        times[0],
        macs / median / 1e6
    );
    println!(
        "reference, one conv 32→64 at 256×256: {}",
        reference(&device, repeats)
    );
    Ok(())
}

/// Median time and throughput of the reference convolution.
fn reference(device: &Device, repeats: usize) -> String {
    let conv = burn::nn::conv::Conv2dConfig::new([32, 64], [3, 3])
        .with_padding(burn::nn::PaddingConfig2d::Explicit(1, 1, 1, 1))
        .init(device);
    let x = Tensor::<4>::random([1, 32, 256, 256], Distribution::Uniform(0.0, 1.0), device);
    let mut times: Vec<f64> = (0..=repeats)
        .map(|_| {
            let start = Instant::now();
            let _ = conv.forward(x.clone()).into_data();
            start.elapsed().as_secs_f64() * 1e3
        })
        .skip(1)
        .collect();
    times.sort_by(f64::total_cmp);
    let median = times[times.len() / 2];
    let macs = (256 * 256 * 64 * 32 * 9) as f64;
    format!(
        "median {median:.1} ms, {:.1} G multiply-adds/s",
        macs / median / 1e6
    )
}
