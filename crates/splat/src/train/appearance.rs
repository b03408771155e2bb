//! Per-photo appearance: a learned affine colour transform per training photo, applied to the
//! render before the photometric loss, so that photos whose exposure and white balance differ
//! do not have to be explained by the Gaussians' colours.
//!
//! It is the splat trainers' usual answer to such captures (gsplat's appearance optimisation and
//! bilateral grids, nerfstudio splatfacto's appearance embedding); the form here is gsplat's
//! bilateral grid with a single cell, i.e. one 3×4 matrix `[A | b]` per photo, and the render's
//! colour `c` becomes `A·c + b`. Each matrix starts at the identity, has its own Adam learning
//! rate, and is pulled towards the identity by `weight·‖[A | b] − [I | 0]‖²` (the single cell
//! has no neighbour for the grid's total variation; the pull fixes the colour space the
//! Gaussians learn near the photos' average). New views are rendered without it.

use burn::tensor::{Tensor, TensorData};
use serde::{Deserialize, Serialize};

use fewview_optim::adam::{AdamConfig, AdamState};

/// Which appearance model training uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum AppearanceModel {
    /// The render is compared with the photo as it is.
    #[default]
    None,
    /// A 3×4 colour transform per training photo.
    Affine,
}

impl AppearanceModel {
    /// The name flags and files use.
    pub fn name(self) -> &'static str {
        match self {
            AppearanceModel::None => "none",
            AppearanceModel::Affine => "affine",
        }
    }
}

impl std::str::FromStr for AppearanceModel {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "none" => Ok(AppearanceModel::None),
            "affine" => Ok(AppearanceModel::Affine),
            _ => Err(format!(
                "unknown appearance model `{s}`; expected none or affine"
            )),
        }
    }
}

/// Settings of the appearance model.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AppearanceConfig {
    pub model: AppearanceModel,
    /// Adam learning rate of the transforms (gsplat's bilateral-grid rate, 2e-3).
    pub lr: f32,
    /// Weight of the squared distance of each transform to the identity.
    pub weight: f32,
}

impl Default for AppearanceConfig {
    fn default() -> Self {
        Self {
            model: AppearanceModel::None,
            lr: 2e-3,
            weight: 1e-2,
        }
    }
}

impl AppearanceConfig {
    /// Checks the values; the message names the setting.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.lr.is_finite() && self.lr >= 0.0) {
            return Err(format!(
                "appearance learning rate {} must be finite and ≥ 0",
                self.lr
            ));
        }
        if !(self.weight.is_finite() && self.weight >= 0.0) {
            return Err(format!(
                "appearance weight {} must be finite and ≥ 0",
                self.weight
            ));
        }
        Ok(())
    }
}

/// A colour transform `[A | b]`, 3×4 row-major: `out_r = A_r0·r + A_r1·g + A_r2·b + b_r`.
pub type Affine = [f32; 12];

/// The transform that changes nothing.
pub const IDENTITY: Affine = [
    1.0, 0.0, 0.0, 0.0, //
    0.0, 1.0, 0.0, 0.0, //
    0.0, 0.0, 1.0, 0.0,
];

/// The transforms of every training photo and their optimiser state (empty without a model).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct AppearanceState {
    pub transforms: Vec<Affine>,
    /// One Adam state per photo: a photo's transform steps only when that photo is trained on.
    pub adam: Vec<AdamState>,
}

impl AppearanceState {
    /// Identity transforms for `views` photos under `model` (none for [`AppearanceModel::None`]).
    pub fn new(model: AppearanceModel, views: usize) -> Self {
        let n = if model == AppearanceModel::Affine {
            views
        } else {
            0
        };
        Self {
            transforms: vec![IDENTITY; n],
            adam: vec![AdamState::new(12, 1); n],
        }
    }

    /// The transform of photo `view`, when the run has an appearance model.
    pub fn transform(&self, view: usize) -> Option<&Affine> {
        self.transforms.get(view)
    }

    /// One Adam step of photo `view`'s transform.
    pub fn step(&mut self, view: usize, grad: &[f32], lr: f32, cfg: &AdamConfig) {
        self.adam[view].step(&mut self.transforms[view], grad, lr, cfg);
    }
}

/// `rgb` (`[H, W, 3]`) through the transform `m` (`[3, 4]`): `rgb·Aᵀ + b` per pixel.
pub fn apply(rgb: Tensor<3>, m: Tensor<2>) -> Tensor<3> {
    let [h, w, _] = rgb.dims();
    let a = m.clone().slice([0..3, 0..3]);
    let b = m.slice([0..3, 3..4]).reshape([1, 3]);
    (rgb.reshape([h * w, 3]).matmul(a.transpose()) + b).reshape([h, w, 3])
}

/// `weight · ‖m − [I | 0]‖²`.
pub fn regularization(m: Tensor<2>, weight: f32) -> Tensor<1> {
    let identity = Tensor::<2>::from_data(TensorData::new(IDENTITY.to_vec(), [3, 4]), &m.device());
    (m - identity).powi_scalar(2).sum() * weight
}

/// `m` as a `[3, 4]` tensor on `device` whose gradient is tracked.
pub fn tracked(m: &Affine, device: &burn::tensor::Device) -> Tensor<2> {
    Tensor::<2>::from_data(TensorData::new(m.to_vec(), [3, 4]), device).require_grad()
}

/// The inverse transform (`A⁻¹·(c − b)`), `None` when `A` is singular: maps a photo's colours
/// into the colour space the Gaussians learn.
pub fn inverse(m: &Affine) -> Option<Affine> {
    let a = nalgebra::Matrix3::from_fn(|r, c| m[r * 4 + c] as f64);
    let b = nalgebra::Vector3::new(m[3] as f64, m[7] as f64, m[11] as f64);
    let inv = a.try_inverse()?;
    let shift = -(inv * b);
    Some(std::array::from_fn(|i| {
        let (r, c) = (i / 4, i % 4);
        (if c < 3 { inv[(r, c)] } else { shift[r] }) as f32
    }))
}

/// `m` applied to interleaved RGB values on the host.
pub fn apply_host(m: &Affine, rgb: &[f32]) -> Vec<f32> {
    rgb.chunks_exact(3)
        .flat_map(|c| {
            [0, 1, 2]
                .map(|r| m[r * 4] * c[0] + m[r * 4 + 1] * c[1] + m[r * 4 + 2] * c[2] + m[r * 4 + 3])
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use burn::tensor::Device;

    use super::*;

    fn values<const D: usize>(t: Tensor<D>) -> Vec<f32> {
        t.into_data().try_to_vec::<f32>().unwrap()
    }

    /// The render, target and transform of the gradient check.
    fn case() -> (Vec<f32>, Vec<f32>, Affine) {
        let (h, w) = (3, 4);
        let rgb: Vec<f32> = (0..h * w * 3)
            .map(|i| 0.1 + 0.8 * ((i * 7) % 13) as f32 / 13.0)
            .collect();
        let target: Vec<f32> = (0..h * w * 3)
            .map(|i| 0.05 + 0.9 * ((i * 5) % 11) as f32 / 11.0)
            .collect();
        let m = [
            1.2, 0.1, -0.05, 0.02, //
            0.03, 0.9, 0.1, -0.04, //
            -0.1, 0.05, 1.1, 0.01,
        ];
        (rgb, target, m)
    }

    /// The loss of the check in f64 on the host: mean |m(rgb) − target| + weight·‖m − I‖².
    fn reference_loss(rgb: &[f32], target: &[f32], m: &[f64; 12], weight: f64) -> f64 {
        let mut l1 = 0.0;
        for (c, t) in rgb.chunks_exact(3).zip(target.chunks_exact(3)) {
            for r in 0..3 {
                let v = m[r * 4] * c[0] as f64
                    + m[r * 4 + 1] * c[1] as f64
                    + m[r * 4 + 2] * c[2] as f64
                    + m[r * 4 + 3];
                l1 += (v - t[r] as f64).abs();
            }
        }
        let reg: f64 = m
            .iter()
            .zip(IDENTITY)
            .map(|(a, b)| (a - b as f64).powi(2))
            .sum();
        l1 / rgb.len() as f64 + weight * reg
    }

    #[test]
    fn the_gradient_of_the_transform_matches_finite_differences() {
        let (rgb, target, m) = case();
        let weight = 0.05;
        let device = Device::flex().autodiff();
        let image = Tensor::<3>::from_data(TensorData::new(rgb.clone(), [3, 4, 3]), &device);
        let goal = Tensor::<3>::from_data(TensorData::new(target.clone(), [3, 4, 3]), &device);
        let tracked = tracked(&m, &device);
        let loss = (apply(image, tracked.clone()) - goal).abs().mean()
            + regularization(tracked.clone(), weight);
        let grads = loss.backward();
        let got = values(tracked.grad(&grads).unwrap());
        let m64: [f64; 12] = m.map(f64::from);
        for i in 0..12 {
            let h = 1e-6;
            let (mut up, mut down) = (m64, m64);
            up[i] += h;
            down[i] -= h;
            let fd = (reference_loss(&rgb, &target, &up, weight as f64)
                - reference_loss(&rgb, &target, &down, weight as f64))
                / (2.0 * h);
            assert!(
                (got[i] as f64 - fd).abs() < 1e-5 * (1.0 + fd.abs()),
                "parameter {i}: autodiff {} vs finite differences {fd}",
                got[i]
            );
        }
    }

    #[test]
    fn the_tensor_transform_agrees_with_the_host_one_and_the_inverse_undoes_it() {
        let (rgb, _, m) = case();
        let device = Device::flex();
        let image = Tensor::<3>::from_data(TensorData::new(rgb.clone(), [3, 4, 3]), &device);
        let m_tensor = Tensor::<2>::from_data(TensorData::new(m.to_vec(), [3, 4]), &device);
        let on_device = values(apply(image, m_tensor));
        let on_host = apply_host(&m, &rgb);
        for (a, b) in on_device.iter().zip(&on_host) {
            assert!((a - b).abs() < 1e-6);
        }
        let back = apply_host(&inverse(&m).unwrap(), &on_host);
        for (a, b) in back.iter().zip(&rgb) {
            assert!((a - b).abs() < 1e-5);
        }
        assert_eq!(inverse(&IDENTITY), Some(IDENTITY));
        let mut singular = IDENTITY;
        singular[10] = 0.0;
        assert_eq!(inverse(&singular), None);
    }

    #[test]
    fn the_state_holds_one_identity_per_photo_and_steps_only_that_photo() {
        assert!(
            AppearanceState::new(AppearanceModel::None, 3)
                .transforms
                .is_empty()
        );
        let mut s = AppearanceState::new(AppearanceModel::Affine, 3);
        assert_eq!(s.transforms, vec![IDENTITY; 3]);
        let mut grad = [0.0f32; 12];
        grad[3] = 1.0;
        s.step(1, &grad, 0.01, &AdamConfig::default());
        assert_eq!(s.transforms[0], IDENTITY);
        assert!(
            (s.transforms[1][3] + 0.01).abs() < 1e-6,
            "{:?}",
            s.transforms[1]
        );
        assert_eq!((s.adam[0].step, s.adam[1].step), (0, 1));
    }

    #[test]
    fn names_parse_and_bad_settings_are_refused() {
        assert_eq!("affine".parse(), Ok(AppearanceModel::Affine));
        assert!(
            "bilateral"
                .parse::<AppearanceModel>()
                .unwrap_err()
                .contains("affine")
        );
        let bad = AppearanceConfig {
            lr: f32::NAN,
            ..AppearanceConfig::default()
        };
        assert!(bad.validate().unwrap_err().contains("learning rate"));
    }
}
