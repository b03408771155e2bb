//! Multi-resolution hash encoding (Müller et al. 2022, "Instant NGP"), as used for SDFs by
//! Instant-NSR and Neuralangelo: `L` levels of `F` features each; level `l` is a grid of
//! resolution `N_l = ⌊N_min · b^l⌋`, `b = exp((ln N_max − ln N_min)/(L − 1))`, stored densely
//! when its `(N_l + 1)³` vertices fit in the table of `T` entries and hashed otherwise
//! (`(x · 1) ⊕ (y · 2654435761) ⊕ (z · 805459861) mod T`). A point's features at a level are
//! the trilinear interpolation of its cell's 8 vertices.
//!
//! The domain is the cube `[−bound, bound]³`; positions outside are clamped onto it (their
//! position gradient is then zero along the clamped axes).
//!
//! **Coarse-to-fine.** Each level's features are multiplied by a weight `w_l ∈ [0, 1]`
//! ([`level_window`]): the BARF window (Lin et al. 2021, Eq. 14) applied to hash levels as in
//! Heo et al. 2023 / Neuralangelo's progressive levels. Inactive levels output zero and get no
//! gradient.
//!
//! [`kernels`] holds the host forward/backward (generic over `f32`/`f64` for finite-difference
//! tests), [`op`] the Burn custom autodiff op.

pub mod kernels;
pub mod op;

use serde::{Deserialize, Serialize};

/// Shape of a hash grid.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HashGridConfig {
    /// Number of levels `L`.
    pub levels: usize,
    /// Features per level `F`.
    pub features_per_level: usize,
    /// `log2 T`: entries per level table.
    pub log2_table_size: u32,
    /// Coarsest resolution `N_min` (cells per axis over the domain).
    pub base_resolution: u32,
    /// Finest resolution `N_max`.
    pub finest_resolution: u32,
    /// Half-size of the cubic domain `[−bound, bound]³`.
    pub bound: f32,
}

impl Default for HashGridConfig {
    /// CPU-sized defaults: 16 levels × 2 features (Instant NGP), `T = 2¹⁶` (Instant NGP uses
    /// up to 2¹⁹; a smaller table keeps the random accesses in cache on a CPU), resolutions
    /// 16 … 1024 over the unit-sphere's bounding cube.
    fn default() -> Self {
        Self {
            levels: 16,
            features_per_level: 2,
            log2_table_size: 16,
            base_resolution: 16,
            finest_resolution: 1024,
            bound: 1.0,
        }
    }
}

/// Where one level lives in the flat parameter vector.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LevelLayout {
    /// Grid cells per axis.
    pub resolution: u32,
    /// Table entries of this level (`min(T, (N+1)³)`).
    pub entries: usize,
    /// Offset of the level's first entry (in entries, not floats).
    pub offset: usize,
    /// Dense (direct) indexing rather than hashing.
    pub dense: bool,
}

/// The resolved layout of a grid: per-level geometry and the total parameter count.
#[derive(Clone, Debug, PartialEq)]
pub struct GridLayout {
    pub levels: Vec<LevelLayout>,
    pub features: usize,
    pub bound: f32,
    /// Total number of table entries (parameters = entries × features).
    pub entries: usize,
}

impl HashGridConfig {
    /// Checks the configuration and computes the per-level layout.
    pub fn layout(&self) -> Result<GridLayout, String> {
        if self.levels == 0 || self.features_per_level == 0 {
            return Err("hash grid needs at least one level and one feature".into());
        }
        if !(1..=24).contains(&self.log2_table_size) {
            return Err(format!(
                "log2 table size {} is outside 1..=24",
                self.log2_table_size
            ));
        }
        if self.base_resolution < 1 || self.finest_resolution < self.base_resolution {
            return Err(format!(
                "resolutions {} … {} must satisfy 1 ≤ N_min ≤ N_max",
                self.base_resolution, self.finest_resolution
            ));
        }
        if !(self.bound.is_finite() && self.bound > 0.0) {
            return Err(format!("bound {} must be positive", self.bound));
        }
        let t = 1usize << self.log2_table_size;
        let growth = if self.levels > 1 {
            ((self.finest_resolution as f64).ln() - (self.base_resolution as f64).ln())
                / (self.levels - 1) as f64
        } else {
            0.0
        };
        let mut offset = 0;
        let levels = (0..self.levels)
            .map(|l| {
                let resolution = ((self.base_resolution as f64) * (growth * l as f64).exp() + 1e-6)
                    .floor() as u32;
                let resolution = resolution.clamp(self.base_resolution, self.finest_resolution);
                let vertices = (resolution as usize + 1).pow(3);
                let dense = vertices <= t;
                let entries = vertices.min(t);
                let lay = LevelLayout {
                    resolution,
                    entries,
                    offset,
                    dense,
                };
                offset += entries;
                lay
            })
            .collect();
        Ok(GridLayout {
            levels,
            features: self.features_per_level,
            bound: self.bound,
            entries: offset,
        })
    }

    /// Output width `L · F`.
    pub fn output_dim(&self) -> usize {
        self.levels * self.features_per_level
    }
}

impl GridLayout {
    /// Number of `f32` parameters.
    pub fn num_params(&self) -> usize {
        self.entries * self.features
    }

    pub fn output_dim(&self) -> usize {
        self.levels.len() * self.features
    }
}

/// BARF's coarse-to-fine weights (Lin et al. 2021, Eq. 14) over `levels` hash levels at
/// progress `alpha ∈ [0, levels]`: `w_l = (1 − cos(π · clamp(alpha − l, 0, 1))) / 2`, with the
/// first `always_on` levels fully active from the start (so the field has a coarse basis).
pub fn level_window(levels: usize, alpha: f64, always_on: usize) -> Vec<f32> {
    (0..levels)
        .map(|l| {
            if l < always_on {
                return 1.0;
            }
            let x = (alpha - (l - always_on) as f64).clamp(0.0, 1.0);
            ((1.0 - (std::f64::consts::PI * x).cos()) / 2.0) as f32
        })
        .collect()
}

/// Instant NGP's table initialisation: uniform in `[−1e-4, 1e-4]`, from a seed.
pub fn init_table(layout: &GridLayout, seed: u64) -> Vec<f32> {
    use rand::{RngExt, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    (0..layout.num_params())
        .map(|_| rng.random_range(-1e-4f32..1e-4f32))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_grows_geometrically_and_switches_to_hashing() {
        let cfg = HashGridConfig {
            levels: 8,
            features_per_level: 2,
            log2_table_size: 12,
            base_resolution: 4,
            finest_resolution: 512,
            bound: 1.0,
        };
        let lay = cfg.layout().unwrap();
        let res: Vec<u32> = lay.levels.iter().map(|l| l.resolution).collect();
        // b = (512/4)^(1/7) = 2: 4, 8, 16, ... 512.
        assert_eq!(res, vec![4, 8, 16, 32, 64, 128, 256, 512]);
        // (N+1)^3 ≤ 4096 only for N ≤ 15.
        let dense: Vec<bool> = lay.levels.iter().map(|l| l.dense).collect();
        assert_eq!(
            dense,
            vec![true, true, false, false, false, false, false, false]
        );
        assert_eq!(lay.levels[0].entries, 125);
        assert_eq!(lay.levels[1].offset, 125);
        assert_eq!(lay.entries, 125 + 729 + 6 * 4096);
        assert_eq!(lay.num_params(), 2 * lay.entries);
    }

    #[test]
    fn window_opens_level_by_level() {
        let w = level_window(4, 0.0, 1);
        assert_eq!(w, vec![1.0, 0.0, 0.0, 0.0]);
        let w = level_window(4, 1.5, 1);
        assert_eq!(w[1], 1.0);
        assert!((w[2] - 0.5).abs() < 1e-6);
        assert_eq!(w[3], 0.0);
        assert_eq!(level_window(4, 10.0, 0), vec![1.0; 4]);
    }

    #[test]
    fn bad_configs_are_rejected() {
        let base = HashGridConfig::default();
        for bad in [
            HashGridConfig {
                levels: 0,
                ..base.clone()
            },
            HashGridConfig {
                log2_table_size: 30,
                ..base.clone()
            },
            HashGridConfig {
                finest_resolution: 2,
                ..base.clone()
            },
            HashGridConfig {
                bound: f32::NAN,
                ..base.clone()
            },
        ] {
            assert!(bad.layout().is_err(), "{bad:?}");
        }
    }
}
