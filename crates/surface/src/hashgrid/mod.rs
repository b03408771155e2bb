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
mod layout;
pub mod op;

pub use layout::{GridLayout, HashGridConfig, LevelLayout};

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
