//! Small fully connected networks (the SDF and colour heads) as one fused custom op: on a CPU,
//! narrow layers over hundreds of thousands of rows are limited by memory traffic, so the op
//! keeps each row's activations in cache instead of materialising `[N, width]` tensors per
//! layer (measured in [`crate::bench`]).
//!
//! Parameters are one flat vector: for each layer `k`, the weights `W_k` (`dims[k] × dims[k+1]`,
//! row-major, `y = x W + b`) followed by the bias `b_k`.

pub mod kernels;
pub mod op;
mod spec;

use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

pub use spec::{Activation, MlpSpec};

/// PyTorch's default `nn.Linear` initialisation: weights and biases uniform in
/// `±1/√fan_in`.
pub fn init_default(spec: &MlpSpec, seed: u64) -> Vec<f32> {
    use rand::RngExt;
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut p = Vec::with_capacity(spec.num_params());
    for w in spec.dims.windows(2) {
        let bound = 1.0 / (w[0] as f32).sqrt();
        for _ in 0..w[0] * w[1] + w[1] {
            p.push(rng.random_range(-bound..bound));
        }
    }
    p
}

/// The geometric initialisation of SAL (Atzmon & Lipman 2020) as NeuS applies it: the network
/// starts as (approximately) the SDF of a sphere of radius `radius`, `‖x‖ − radius`. The first
/// `xyz` inputs are the point; the other inputs (encodings) start with zero weights, hidden
/// layers with `N(0, 2/width)`, the last layer with mean `√π/√width` and bias `−radius`.
/// Only the first output (the SDF) gets the sphere; the other outputs (features) start small.
pub fn init_geometric(spec: &MlpSpec, xyz: usize, radius: f32, seed: u64) -> Vec<f32> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut p = Vec::with_capacity(spec.num_params());
    let n_layers = spec.dims.len() - 1;
    for k in 0..n_layers {
        let (din, dout) = (spec.dims[k], spec.dims[k + 1]);
        if k + 1 == n_layers {
            let mean = (std::f32::consts::PI).sqrt() / (din as f32).sqrt();
            let sdf = Normal::new(mean, 1e-4).unwrap();
            let feat = Normal::new(0.0, 1e-4).unwrap();
            for _i in 0..din {
                for j in 0..dout {
                    p.push(if j == 0 {
                        sdf.sample(&mut rng)
                    } else {
                        feat.sample(&mut rng)
                    });
                }
            }
            for j in 0..dout {
                p.push(if j == 0 { -radius } else { 0.0 });
            }
        } else {
            let std = (2.0f32).sqrt() / (dout as f32).sqrt();
            let n = Normal::new(0.0, std).unwrap();
            for i in 0..din {
                for _j in 0..dout {
                    let w = n.sample(&mut rng);
                    p.push(if k == 0 && i >= xyz { 0.0 } else { w });
                }
            }
            p.extend(std::iter::repeat_n(0.0, dout));
        }
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geometric_init_is_close_to_a_sphere() {
        let spec = MlpSpec {
            dims: vec![3 + 8, 256, 13],
            hidden: Activation::Softplus(100.0),
            output: Activation::None,
        };
        let p = init_geometric(&spec, 3, 0.5, 1);
        assert_eq!(p.len(), spec.num_params());
        let mut worst = 0.0f64;
        for k in 0..100 {
            let t = k as f64 / 100.0 * std::f64::consts::TAU;
            // Away from the origin, where Softplus(100) differs from ReLU by its ln 2/β offset.
            let r = 0.35 + 0.55 * (k as f64 / 100.0);
            let x = [r * t.cos(), r * t.sin() * 0.6, r * t.sin() * 0.8];
            let mut input = vec![x[0] as f32, x[1] as f32, x[2] as f32];
            input.extend([0.3f32; 8]);
            let y = kernels::forward(&spec, &p, &input);
            // The random-feature sum approximates ‖x‖ up to a direction-dependent factor of
            // relative spread ≈ 0.58/(0.4·√width) (≈ 9 % at width 256).
            worst = worst.max((y[0] as f64 - (r - 0.5)).abs() / r);
        }
        assert!(worst < 0.25, "{worst}");
    }
}
