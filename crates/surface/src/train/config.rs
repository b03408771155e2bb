//! The trainer's settings: loss weights and switches, iterations, batches and rates.

use serde::{Deserialize, Serialize};

use crate::error::{Result, SurfaceError};
use crate::field::{Field, FieldConfig};
use crate::render::SampleConfig;
use fewview_optim::{AdamConfig, ExpSchedule};

/// Loss weights and switches (defaults: the surface paper §B.1).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LossConfig {
    /// `λ_M.C.` of Eq. 10 (10⁻³).
    pub lambda_mc: f32,
    pub matching: bool,
    /// `λ_u` (the paper's `λ_occ`, 0.01): weight of `L_u = L_u,ncc + λ_u,gc L_u,gc`.
    pub lambda_u: f32,
    /// Patch NCC (Eq. 6).
    pub ncc: bool,
    /// Geometric consistency (Eq. 7).
    pub geometric_consistency: bool,
    /// `λ_u,gc` (0.1).
    pub lambda_gc: f32,
    /// Weight NCC and geometric consistency by `γ = 1 − u` (Eq. 5); off = `γ = 1`.
    pub uncertainty: bool,
    /// `λ_geo`: weight of `L_geo = L_Eik + λ_pSDF L_pSDF`. The paper's 10⁻³ multiplies
    /// `L_Eik = Σ_{P∈V} (‖n(P)‖ − 1)²`, a *sum* over all samples of the batch (tens of
    /// thousands), which is ~10–100 × NeuS's Eikonal weight 0.1 on the *mean*. We take the
    /// mean (NeuS's code, independent of the batch size) with NeuS's weight 0.1 as the
    /// default; with the paper's 10⁻³ on the mean the hash-grid SDF loses its distance
    /// property within a few dozen iterations.
    pub lambda_geo: f32,
    pub eikonal: bool,
    /// `λ_pSDF` (0.1).
    pub lambda_psdf: f32,
    pub psdf: bool,
    /// `λ_b` of Eq. 12 (0.1).
    pub lambda_b: f32,
    /// NeuS's mask loss weight (0.1), used when the views have masks.
    pub lambda_mask: f32,
    /// Half size of the NCC patches (3 → 7 × 7 pixels).
    pub patch_half: usize,
    /// Spacing of the NCC patch pixels, in pixels.
    pub patch_step: f32,
}

impl LossConfig {
    /// Every weight finite and not negative: a NaN weight would turn the whole loss into NaN
    /// and a negative one would reward the error it weighs.
    pub fn validate(&self) -> Result<()> {
        let weights = [
            ("lambda_mc", self.lambda_mc),
            ("lambda_u", self.lambda_u),
            ("lambda_gc", self.lambda_gc),
            ("lambda_geo", self.lambda_geo),
            ("lambda_psdf", self.lambda_psdf),
            ("lambda_b", self.lambda_b),
            ("lambda_mask", self.lambda_mask),
        ];
        for (name, w) in weights {
            if !(w.is_finite() && w >= 0.0) {
                return Err(SurfaceError::invalid(
                    "loss weights",
                    format!("{name} = {w}; expected a finite weight ≥ 0"),
                ));
            }
        }
        if !(self.patch_step.is_finite() && self.patch_step > 0.0) {
            return Err(SurfaceError::invalid(
                "NCC patches",
                format!("patch step {}; expected > 0 pixels", self.patch_step),
            ));
        }
        Ok(())
    }
}

impl Default for LossConfig {
    fn default() -> Self {
        Self {
            lambda_mc: 1e-3,
            matching: true,
            lambda_u: 0.01,
            ncc: true,
            geometric_consistency: true,
            lambda_gc: 0.1,
            uncertainty: true,
            lambda_geo: 0.1,
            eikonal: true,
            lambda_psdf: 0.1,
            psdf: true,
            lambda_b: 0.1,
            lambda_mask: 0.1,
            patch_half: 3,
            patch_step: 1.0,
        }
    }
}

/// Everything about one training run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    pub iterations: usize,
    /// Random pixels per iteration (colour and mask losses).
    pub rays_per_batch: usize,
    /// Correspondences per iteration (each renders two rays).
    pub matches_per_batch: usize,
    pub sample: SampleConfig,
    pub field: FieldConfig,
    pub losses: LossConfig,
    /// Learning rate of the networks and the sharpness (paper: 10⁻³ → 10⁻⁴).
    pub lr: ExpSchedule,
    /// Factor on `lr` for the hash table (Instant NGP trains the table with 10⁻²).
    pub hash_lr_factor: f32,
    /// Learning rate of the poses (paper: 10⁻³ → 10⁻⁴).
    pub pose_lr: ExpSchedule,
    pub refine_poses: bool,
    /// Deviation, 0 by default (the paper optimises the poses from the first iteration): hold
    /// the poses for this fraction of the iterations while the field forms. Early on the
    /// colour loss of a field fitted to wrong poses drags good (e.g. warmed-up) poses away.
    #[serde(default)]
    pub pose_start: f64,
    /// BARF/SPARF coarse-to-fine window `(α₁, α₂)` as fractions of the iterations (SPARF DTU:
    /// 0.4, 0.7). The hash levels (or frequencies) open over it and the pSDF loss is active
    /// within it (Eq. 13).
    pub c2f: (f64, f64),
    /// NeuS's cosine annealing ends at this fraction of the iterations (NeuS: 50k of 300k).
    pub cos_anneal_end: f64,
    pub use_masks: bool,
    pub background: [f32; 3],
    pub adam: AdamConfig,
    pub seed: u64,
}

impl TrainConfig {
    /// Checks what the configuration alone decides, so that a run can refuse it before it
    /// writes anything or spends minutes on matching.
    pub fn validate(&self) -> Result<()> {
        self.checked_field().map(|_| ())
    }

    /// The field this configuration describes, after the checks of [`Self::validate`].
    pub(super) fn checked_field(&self) -> Result<Field> {
        if self.iterations == 0 || self.rays_per_batch == 0 {
            return Err(SurfaceError::invalid(
                "config",
                "iterations and rays per batch must be positive",
            ));
        }
        self.sample
            .validate()
            .map_err(|e| SurfaceError::invalid("samples", e))?;
        self.losses.validate()?;
        Field::new(self.field.clone()).map_err(|e| SurfaceError::invalid("field", e))
    }
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            iterations: 6000,
            rays_per_batch: 512,
            matches_per_batch: 128,
            sample: SampleConfig::default(),
            field: FieldConfig::default(),
            losses: LossConfig::default(),
            lr: ExpSchedule {
                start: 1e-3,
                end: 1e-4,
            },
            hash_lr_factor: 10.0,
            pose_lr: ExpSchedule {
                start: 1e-3,
                end: 1e-4,
            },
            refine_poses: true,
            pose_start: 0.0,
            c2f: (0.4, 0.7),
            cos_anneal_end: 1.0 / 6.0,
            use_masks: true,
            background: [0.0; 3],
            adam: AdamConfig::default(),
            seed: 0,
        }
    }
}
