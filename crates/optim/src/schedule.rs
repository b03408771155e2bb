//! Learning-rate schedules.

use serde::{Deserialize, Serialize};

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
