//! Adam (Kingma & Ba 2015) on host parameter vectors, with PyTorch's `ExponentialLR`-style
//! schedule `lr(k) = lr₀ · (lr_end / lr₀)^(k / K)` (paper 001 §B.1: 10⁻³ → 10⁻⁴ for both the
//! model and the camera optimiser).

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Adam constants (PyTorch defaults).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AdamConfig {
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
}

impl Default for AdamConfig {
    fn default() -> Self {
        Self {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        }
    }
}

/// Moments of one parameter vector.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct AdamState {
    pub m: Vec<f32>,
    pub v: Vec<f32>,
    pub step: u64,
}

impl AdamState {
    pub fn new(len: usize) -> Self {
        Self {
            m: vec![0.0; len],
            v: vec![0.0; len],
            step: 0,
        }
    }

    /// One step `p −= lr · m̂ / (√v̂ + eps)`.
    pub fn step(&mut self, params: &mut [f32], grads: &[f32], lr: f32, cfg: &AdamConfig) {
        assert_eq!(params.len(), self.m.len(), "Adam state out of sync");
        assert_eq!(grads.len(), params.len(), "gradient size");
        self.step += 1;
        let t = self.step as i32;
        let bc1 = 1.0 - cfg.beta1.powi(t);
        let bc2_sqrt = (1.0 - cfg.beta2.powi(t)).sqrt();
        let (b1, b2, eps) = (cfg.beta1, cfg.beta2, cfg.eps);
        const CHUNK: usize = 8192;
        params
            .par_chunks_mut(CHUNK)
            .zip(self.m.par_chunks_mut(CHUNK))
            .zip(self.v.par_chunks_mut(CHUNK))
            .zip(grads.par_chunks(CHUNK))
            .for_each(|(((p, m), v), g)| {
                for i in 0..p.len() {
                    m[i] = b1 * m[i] + (1.0 - b1) * g[i];
                    v[i] = b2 * v[i] + (1.0 - b2) * g[i] * g[i];
                    let denom = v[i].sqrt() / bc2_sqrt + eps;
                    p[i] -= lr / bc1 * m[i] / denom;
                }
            });
    }
}

/// Exponential decay from `start` to `end` over `total` steps (PyTorch's `ExponentialLR` with
/// `γ = (end/start)^(1/total)`), held at `end` afterwards.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExpSchedule {
    pub start: f32,
    pub end: f32,
}

impl ExpSchedule {
    pub fn at(&self, step: usize, total: usize) -> f32 {
        if total == 0 || self.start <= 0.0 {
            return self.start;
        }
        let f = (step as f64 / total as f64).min(1.0);
        (self.start as f64 * (self.end as f64 / self.start as f64).powf(f)) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Adam written out from the paper's Algorithm 1, in f64.
    fn reference(p0: f64, grads: &[f64], lr: f64, cfg: &AdamConfig) -> f64 {
        let (b1, b2, eps) = (cfg.beta1 as f64, cfg.beta2 as f64, cfg.eps as f64);
        let (mut p, mut m, mut v) = (p0, 0.0, 0.0);
        for (t, g) in grads.iter().enumerate() {
            m = b1 * m + (1.0 - b1) * g;
            v = b2 * v + (1.0 - b2) * g * g;
            let mh = m / (1.0 - b1.powi(t as i32 + 1));
            let vh = v / (1.0 - b2.powi(t as i32 + 1));
            p -= lr * mh / (vh.sqrt() + eps);
        }
        p
    }

    #[test]
    fn matches_the_paper_algorithm() {
        let cfg = AdamConfig::default();
        let grads: Vec<f64> = (0..60)
            .map(|i| ((i * 37 % 11) as f64 - 5.0) * 0.1)
            .collect();
        let mut st = AdamState::new(1);
        let mut p = [0.3f32];
        for g in &grads {
            st.step(&mut p, &[*g as f32], 0.01, &cfg);
        }
        let want = reference(0.3, &grads, 0.01, &cfg);
        assert!((p[0] as f64 - want).abs() < 1e-5, "{} vs {want}", p[0]);
    }

    #[test]
    fn schedule_decays_geometrically() {
        let s = ExpSchedule {
            start: 1e-3,
            end: 1e-4,
        };
        assert!((s.at(0, 100) - 1e-3).abs() < 1e-9);
        assert!((s.at(50, 100) - 1e-3 / 10f32.sqrt()).abs() < 1e-8);
        assert!((s.at(100, 100) - 1e-4).abs() < 1e-9);
        assert!((s.at(500, 100) - 1e-4).abs() < 1e-9);
    }
}
