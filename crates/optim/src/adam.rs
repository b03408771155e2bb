//! Adam (Kingma & Ba 2015) on host parameter arrays whose rows can be appended and removed
//! (3DGS densification), as the reference code's `cat_tensors_to_optimizer` /
//! `_prune_optimizer`: new rows start with zero moments, removed rows take their moments with
//! them. One implementation for the Gaussian trainer (rows of a Gaussian's parameters) and the
//! surface trainer (rows of width 1).

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Moments of one parameter group (rows of `width` values).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct AdamState {
    pub width: usize,
    pub m: Vec<f32>,
    pub v: Vec<f32>,
    /// Steps taken (for bias correction), shared by all rows as in PyTorch's Adam on one tensor.
    pub step: u64,
}

/// Adam constants. `Default` is PyTorch's (β = 0.9, 0.999, eps = 1e-8);
/// [`AdamConfig::inria_3dgs`] is the reference 3DGS code's, which sets eps to 1e-15.
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

impl AdamConfig {
    /// The reference 3DGS code's optimiser (`torch.optim.Adam(..., eps=1e-15)`).
    pub fn inria_3dgs() -> Self {
        Self {
            eps: 1e-15,
            ..Self::default()
        }
    }
}

impl AdamState {
    pub fn new(width: usize, rows: usize) -> Self {
        Self {
            width,
            m: vec![0.0; width * rows],
            v: vec![0.0; width * rows],
            step: 0,
        }
    }

    /// One step: `params -= lr · m̂ / (√v̂ + eps)`.
    pub fn step(&mut self, params: &mut [f32], grads: &[f32], lr: f32, cfg: &AdamConfig) {
        self.step_per_column(params, grads, |_| lr, cfg);
    }

    /// One step with a learning rate per column of the rows (e.g. SH bands within a row):
    /// exactly as separate Adam groups that all step every iteration.
    pub fn step_per_column(
        &mut self,
        params: &mut [f32],
        grads: &[f32],
        lr_of_column: impl Fn(usize) -> f32 + Sync,
        cfg: &AdamConfig,
    ) {
        assert_eq!(
            params.len(),
            self.m.len(),
            "Adam state out of sync with parameters"
        );
        assert_eq!(grads.len(), params.len(), "gradient size");
        self.step += 1;
        let t = self.step as i32;
        let bc1 = 1.0 - cfg.beta1.powi(t);
        let bc2_sqrt = (1.0 - cfg.beta2.powi(t)).sqrt();
        let (b1, b2, eps) = (cfg.beta1, cfg.beta2, cfg.eps);
        let width = self.width.max(1);
        const CHUNK: usize = 4096;
        params
            .par_chunks_mut(CHUNK)
            .zip(self.m.par_chunks_mut(CHUNK))
            .zip(self.v.par_chunks_mut(CHUNK))
            .zip(grads.par_chunks(CHUNK))
            .enumerate()
            .for_each(|(c, (((p, m), v), g))| {
                for i in 0..p.len() {
                    let lr = lr_of_column((c * CHUNK + i) % width);
                    m[i] = b1 * m[i] + (1.0 - b1) * g[i];
                    v[i] = b2 * v[i] + (1.0 - b2) * g[i] * g[i];
                    let denom = v[i].sqrt() / bc2_sqrt + eps;
                    p[i] -= lr / bc1 * m[i] / denom;
                }
            });
    }

    /// Keeps the rows whose flag is set.
    pub fn retain(&mut self, keep: &[bool]) {
        crate::rows::retain_rows(&mut self.m, self.width, keep);
        crate::rows::retain_rows(&mut self.v, self.width, keep);
    }

    /// Appends `rows` rows of zero moments.
    pub fn extend_zeros(&mut self, rows: usize) {
        self.m.resize(self.m.len() + rows * self.width, 0.0);
        self.v.resize(self.v.len() + rows * self.width, 0.0);
    }

    /// Zeroes the moments of every row (the reference code does this for opacities when it
    /// resets them).
    pub fn reset(&mut self) {
        self.m.iter_mut().for_each(|x| *x = 0.0);
        self.v.iter_mut().for_each(|x| *x = 0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Adam written out directly from the paper's Algorithm 1, in f64.
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
        let grads: Vec<f64> = (0..50)
            .map(|i| ((i * 37 % 11) as f64 - 5.0) * 0.1)
            .collect();
        let mut st = AdamState::new(1, 1);
        let mut p = [0.3f32];
        for g in &grads {
            st.step(&mut p, &[*g as f32], 0.01, &cfg);
        }
        let want = reference(0.3, &grads, 0.01, &cfg);
        assert!((p[0] as f64 - want).abs() < 1e-5, "{} vs {want}", p[0]);
    }

    #[test]
    fn rows_follow_densification() {
        let mut st = AdamState::new(2, 3);
        st.m = vec![1.0, 1.0, 2.0, 2.0, 3.0, 3.0];
        st.v = st.m.clone();
        st.retain(&[true, false, true]);
        assert_eq!(st.m, vec![1.0, 1.0, 3.0, 3.0]);
        st.extend_zeros(1);
        assert_eq!(st.v, vec![1.0, 1.0, 3.0, 3.0, 0.0, 0.0]);
    }
}
