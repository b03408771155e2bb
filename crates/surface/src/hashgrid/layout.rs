//! A hash grid's configuration and the layout of its levels in the flat parameter vector.

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
