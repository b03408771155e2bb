//! Whole-network tests: head shapes and ranges in every variant and preset, input checks, a
//! finite-difference gradient check, and the multiply-add count against the built modules.

use burn::module::{Module, ModuleVisitor, Param};
use burn::tensor::{Device, Distribution, Tensor, TensorData};

use super::seed::seeded;
use super::*;

/// Widths 2/3/4/5 and a 2-channel pose map: every code path, in microseconds.
fn tiny(variant: Variant) -> NetConfig {
    NetConfig {
        widths: [2, 3, 4, 5],
        pose_channels: 2,
        ..NetConfig::cpu(variant)
    }
}

fn input(config: &NetConfig, n: usize, size: [usize; 2], device: &Device) -> NetInput {
    let [h, w] = size;
    let r =
        |c: usize, lo: f64| Tensor::random([n, c, h, w], Distribution::Uniform(lo, 1.0), device);
    NetInput {
        image: r(3, 0.0),
        pose: r(config.pose_channels, 0.0),
        depth: r(1, -1.0),
    }
}

fn host(t: &Tensor<4>) -> Vec<f32> {
    t.to_data().try_to_vec::<f32>().unwrap()
}

/// The rotation matrix of a unit quaternion (w first).
fn matrix(q: [f32; 4]) -> [[f32; 3]; 3] {
    let [w, x, y, z] = q;
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// Every pixel's quaternion is a rotation: RᵀR = I and det R = 1.
fn assert_rotations(rotation: &Tensor<4>) {
    let [n, _, h, w] = rotation.dims();
    let q = host(rotation);
    let px = h * w;
    for i in 0..n * px {
        let (b, p) = (i / px, i % px);
        let qi = [0, 1, 2, 3].map(|c| q[(b * 4 + c) * px + p]);
        let r = matrix(qi);
        for a in 0..3 {
            for c in 0..3 {
                let dot: f32 = (0..3).map(|k| r[k][a] * r[k][c]).sum();
                let want = if a == c { 1.0 } else { 0.0 };
                assert!(
                    (dot - want).abs() < 1e-5,
                    "pixel {i}: RᵀR[{a}][{c}] = {dot}"
                );
            }
        }
        let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
            - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
            + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
        assert!((det - 1.0).abs() < 1e-5, "pixel {i}: det {det}");
    }
}

fn assert_within(t: &Tensor<4>, lo: f32, hi: f32, what: &str) {
    for v in host(t) {
        assert!(v > lo && v < hi, "{what}: {v} outside ({lo}, {hi})");
    }
}

fn check_heads(config: &NetConfig, size: [usize; 2]) {
    let _rng = seeded(1);
    let device = Device::flex();
    let net = PoseGaussianNet::new(config, &device).unwrap();
    let out = net.forward(input(config, 2, size, &device)).unwrap();
    let [h, w] = size;
    let shape = |c: usize| [2, c, h, w];
    let what = config.to_string();
    assert_eq!(out.scale.dims(), shape(3), "{what}");
    assert_eq!(out.rotation.dims(), shape(4), "{what}");
    assert_eq!(out.opacity.dims(), shape(2), "{what}");
    assert_eq!(out.depth.dims(), shape(1), "{what}");
    assert_eq!(out.uncertainty.dims(), shape(2), "{what}");
    assert_within(&out.scale, 0.0, f32::INFINITY, "scale");
    assert_within(&out.opacity, 0.0, 1.0, "opacity");
    assert_within(&out.render_opacity(), 0.0, 1.0, "render opacity");
    assert_within(&out.uncertainty, 0.0, 1.0, "uncertainty");
    assert_within(&out.depth, -1.0, 1.0, "depth");
    assert_within(&out.metric_depth(0.5, 6.0), 0.5, 6.0, "metric depth");
    assert_rotations(&out.rotation);
}

#[test]
fn every_head_has_its_shape_and_range_in_every_variant_and_preset() {
    for v in Variant::ALL {
        // 13×22 is not a multiple of 8: the decoder resamples to each skip's exact size.
        check_heads(&tiny(v), [13, 22]);
        check_heads(&NetConfig::cpu(v), [16, 12]);
        check_heads(&NetConfig::paper(v), [16, 16]);
    }
}

/// Large Gibbs vectors (rotations near a half-turn) still give rotations.
#[test]
fn rotation_head_gives_rotations_for_any_three_numbers() {
    let _rng = seeded(2);
    let device = Device::flex();
    let g = Tensor::<4>::random([1, 3, 4, 5], Distribution::Uniform(-50.0, 50.0), &device);
    assert_rotations(&heads::quaternion_from_gibbs(g));
}

#[test]
fn forward_refuses_a_mismatched_input_in_one_line() {
    let device = Device::flex();
    let config = tiny(Variant::DeepResidual);
    let net = PoseGaussianNet::new(&config, &device).unwrap();
    let mut x = input(&config, 1, [8, 8], &device);
    x.pose = Tensor::zeros([1, 5, 8, 8], &device);
    let e = net.forward(x).unwrap_err().to_string();
    assert_eq!(
        e,
        "network input: pose map is [1, 5, 8, 8], expected [1, 2, 8, 8] (N, C, H, W)"
    );
}

/// Σ of every head's outputs, summed on the host in f64 so that the finite difference is not
/// drowned by f32 rounding of the sum.
fn objective(net: &PoseGaussianNet, x: NetInput) -> (Tensor<1>, f64) {
    let out = net.forward(x).unwrap();
    let heads = [
        out.scale,
        out.rotation,
        out.opacity,
        out.depth,
        out.uncertainty,
    ];
    let host_sum = heads.iter().flat_map(host).map(f64::from).sum();
    let sum = heads
        .into_iter()
        .map(burn::Tensor::sum)
        .reduce(|a, b| a + b)
        .unwrap();
    (sum, host_sum)
}

/// Autodiff gradient of the output sum w.r.t. one image pixel vs a central difference. The
/// pixel is the one of largest gradient, so that the check never lands where narrow ReLU layers
/// happen to cut the input off (a zero gradient would prove nothing).
fn gradient_check(variant: Variant) {
    let _rng = seeded(7);
    let device = Device::flex().autodiff();
    let config = NetConfig {
        widths: [4, 6, 8, 10],
        ..tiny(variant)
    };
    let net = PoseGaussianNet::new(&config, &device).unwrap();
    let x = input(&config, 1, [8, 8], &device);
    let image = x.image.clone().require_grad();
    let (sum, _) = objective(
        &net,
        NetInput {
            image: image.clone(),
            ..x.clone()
        },
    );
    let grads = sum.backward();
    let g = image
        .grad(&grads)
        .unwrap()
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    let at = (0..g.len())
        .max_by(|&a, &b| g[a].abs().total_cmp(&g[b].abs()))
        .unwrap();
    let analytic = g[at] as f64;
    let h = 1e-3;
    let shifted = |d: f32| {
        let mut v: Vec<f32> = x.image.to_data().try_to_vec::<f32>().unwrap();
        v[at] += d;
        let image = Tensor::from_data(TensorData::new(v, [1, 3, 8, 8]), &device);
        objective(&net, NetInput { image, ..x.clone() }).1
    };
    // Fourth-order central difference: batch norm over the coarse levels' few pixels is
    // strongly curved, and the two-point difference's h² error shows at any h above f32 noise.
    let numeric = (8.0 * (shifted(h) - shifted(-h)) - (shifted(2.0 * h) - shifted(-2.0 * h)))
        / (12.0 * h as f64);
    assert!(
        numeric.abs() > 1e-3,
        "{variant:?}: gradient too small to test ({numeric})"
    );
    let rel = (analytic - numeric).abs() / numeric.abs();
    assert!(
        rel < 1e-2,
        "{variant:?}: autodiff {analytic} vs finite difference {numeric}"
    );
}

#[test]
fn output_sum_gradient_matches_a_finite_difference() {
    for v in Variant::ALL {
        gradient_check(v);
    }
}

/// Convolution weight elements and fully connected weight elements of a module.
#[derive(Default)]
struct WeightCount {
    conv: usize,
    linear: usize,
}

impl ModuleVisitor for WeightCount {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let n = param.shape().num_elements();
        match D {
            4 => self.conv += n,
            2 => self.linear += n,
            _ => {}
        }
    }
}

/// Without downsampling (configs 1 and 4) every convolution runs at the input's resolution, so
/// the count is `H·W·Σ conv weights + Σ SE weights`, read from the built modules.
#[test]
fn multiply_adds_agree_with_the_built_weights_at_full_resolution() {
    for config in [
        NetConfig::paper(Variant::FullResolution),
        NetConfig::cpu(Variant::Simplified),
    ] {
        let net = PoseGaussianNet::new(&config, &Device::flex()).unwrap();
        let mut count = WeightCount::default();
        net.visit(&mut count);
        let [h, w] = config.input;
        let want = (h * w * count.conv + count.linear) as u64;
        assert_eq!(forward_macs(&config, h, w), want, "{config}");
    }
}
