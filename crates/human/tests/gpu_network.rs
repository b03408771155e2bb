//! The PoseGaussian network on the GPU (feature `gpu`) computes what it computes on the CPU:
//! the same weights and inputs give every head's output to 1e-4 and the input gradient to 1e-3
//! relative, in every variant. Off the CPU the decoder's bilinear resize is composed from gathers
//! (`net::resize`), so this is also that path's end-to-end check. Runs wherever wgpu finds an
//! adapter; CI runs it on Mesa's lavapipe.
#![cfg(feature = "gpu")]
// Tests report what they measured.
#![allow(clippy::print_stderr)]

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};
use fewview_human::net::seed::seeded;
use fewview_human::net::{HeadOutputs, NetConfig, NetInput, PoseGaussianNet, Variant};
use fewview_splat::ComputeDevice;

/// Input side: three downsampling levels deep, so that every decoder resize runs.
const SIZE: usize = 24;

fn config(variant: Variant) -> NetConfig {
    NetConfig {
        widths: [4, 6, 8, 10],
        pose_channels: 2,
        ..NetConfig::cpu(variant)
    }
}

/// A deterministic input in `[lo, 1)` (a fixed pattern, the same on every device).
fn pattern(channels: usize, lo: f32, salt: usize) -> Vec<f32> {
    (0..channels * SIZE * SIZE)
        .map(|i| {
            let u = ((i * 7919 + salt * 104_729) % 1009) as f32 / 1009.0;
            lo + (1.0 - lo) * u
        })
        .collect()
}

fn tensor(values: &[f32], channels: usize, device: &Device) -> Tensor<4> {
    Tensor::from_data(
        TensorData::new(values.to_vec(), [1, channels, SIZE, SIZE]),
        device,
    )
}

fn host(t: Tensor<4>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().unwrap()
}

fn heads(out: &HeadOutputs) -> [(&'static str, Tensor<4>); 5] {
    [
        ("scale", out.scale.clone()),
        ("rotation", out.rotation.clone()),
        ("opacity", out.opacity.clone()),
        ("depth", out.depth.clone()),
        ("uncertainty", out.uncertainty.clone()),
    ]
}

/// Each head's name and values on the host.
type Heads = Vec<(&'static str, Vec<f32>)>;

/// Every head's values and the gradient of a weighted sum of all heads with respect to the
/// image, on `device`.
fn run(net: &PoseGaussianNet, config: &NetConfig, device: &Device) -> (Heads, Vec<f32>) {
    let net = net.clone().fork(device);
    let image = tensor(&pattern(3, 0.0, 1), 3, device).require_grad();
    let input = NetInput {
        image: image.clone(),
        pose: tensor(
            &pattern(config.pose_channels, 0.0, 2),
            config.pose_channels,
            device,
        ),
        depth: tensor(&pattern(1, -1.0, 3), 1, device),
    };
    let out = net.forward(input).unwrap();
    let mut values = Vec::new();
    let mut objective = Tensor::<1>::zeros([1], device);
    for (k, (name, head)) in heads(&out).into_iter().enumerate() {
        let channels = head.dims()[1];
        let weights = tensor(&pattern(channels, -1.0, 10 + k), channels, device);
        objective = objective + (head.clone() * weights).sum();
        values.push((name, host(head)));
    }
    let grads = objective.backward();
    let grad = image.grad(&grads).unwrap();
    (values, host(grad))
}

/// The largest difference relative to the largest magnitude of `want`.
fn relative_error(got: &[f32], want: &[f32]) -> f64 {
    assert_eq!(got.len(), want.len());
    let scale = want.iter().fold(0f64, |m, &v| m.max(v.abs() as f64));
    let diff = got
        .iter()
        .zip(want)
        .fold(0f64, |m, (&a, &b)| m.max((a as f64 - b as f64).abs()));
    diff / scale.max(1e-12)
}

#[test]
fn gpu_network_matches_the_cpu_in_value_and_gradient() {
    let gpu = ComputeDevice::Gpu.open().unwrap().autodiff();
    let cpu = Device::flex().autodiff();
    for variant in Variant::ALL {
        let config = config(variant);
        let net = {
            let _generator = seeded(5);
            PoseGaussianNet::new(&config, &cpu).unwrap()
        };
        let (cpu_values, cpu_grad) = run(&net, &config, &cpu);
        let (gpu_values, gpu_grad) = run(&net, &config, &gpu);
        for ((name, got), (_, want)) in gpu_values.iter().zip(&cpu_values) {
            let err = relative_error(got, want);
            eprintln!("{variant:?} {name}: relative error {err:.2e}");
            assert!(err <= 1e-4, "{variant:?} {name}: GPU vs CPU {err:.2e}");
        }
        let err = relative_error(&gpu_grad, &cpu_grad);
        eprintln!("{variant:?} image gradient: relative error {err:.2e}");
        assert!(
            cpu_grad.iter().any(|g| g.abs() > 1e-6),
            "{variant:?}: zero gradient"
        );
        assert!(
            err <= 1e-3,
            "{variant:?} image gradient: GPU vs CPU {err:.2e}"
        );
    }
}
