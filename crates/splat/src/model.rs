//! The Gaussian model on the host: flat `f32` arrays in the Inria PLY layout (pre-activation:
//! log-scales, w-first quaternions, opacity logits, SH coefficients with `f_dc = (c − 0.5)/C0`).

use burn::tensor::{Device, Tensor, TensorData};
use fewview_optim::{ReadbackError, f32_values};
use serde::{Deserialize, Serialize};

use crate::op::GaussianTensors;
use crate::raster::GaussianRefs;
use crate::sh::{SH_C0, num_coeffs};

/// `σ⁻¹(p)`.
pub fn inverse_sigmoid(p: f32) -> f32 {
    (p / (1.0 - p)).ln()
}

pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// A set of 3D Gaussians.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GaussianModel {
    /// N×3
    pub means: Vec<f32>,
    /// N×3, natural log of the standard deviations.
    pub log_scales: Vec<f32>,
    /// N×4, (w, x, y, z).
    pub quats: Vec<f32>,
    /// N
    pub opacity_logits: Vec<f32>,
    /// N×K×3, coefficient-major (K = `sh_coeffs`).
    pub sh: Vec<f32>,
    /// Coefficients per channel, `(degree + 1)²`.
    pub sh_coeffs: usize,
}

/// One Gaussian's parameters, for building models point by point.
#[derive(Clone, Debug, PartialEq)]
pub struct Gaussian {
    pub mean: [f32; 3],
    pub log_scale: [f32; 3],
    pub quat: [f32; 4],
    pub opacity_logit: f32,
    /// K×3
    pub sh: Vec<f32>,
}

impl GaussianModel {
    pub fn new(sh_degree: usize) -> Self {
        Self {
            sh_coeffs: num_coeffs(sh_degree),
            ..Default::default()
        }
    }

    pub fn len(&self) -> usize {
        self.opacity_logits.len()
    }

    pub fn is_empty(&self) -> bool {
        self.opacity_logits.is_empty()
    }

    /// The SH degree the coefficients were allocated for.
    pub fn sh_degree(&self) -> usize {
        crate::raster::sh_degree_of(self.sh_coeffs)
    }

    /// Adds an isotropic Gaussian of colour `rgb` (only the DC term set).
    pub fn push_isotropic(&mut self, mean: [f32; 3], scale: f32, rgb: [f32; 3], opacity: f32) {
        let mut sh = vec![0.0; self.sh_coeffs * 3];
        for c in 0..3 {
            sh[c] = ((rgb[c] as f64 - 0.5) / SH_C0) as f32;
        }
        let ls = scale.max(1e-12).ln();
        self.push(&Gaussian {
            mean,
            log_scale: [ls; 3],
            quat: [1.0, 0.0, 0.0, 0.0],
            opacity_logit: inverse_sigmoid(opacity.clamp(1e-6, 1.0 - 1e-6)),
            sh,
        });
    }

    pub fn push(&mut self, g: &Gaussian) {
        assert_eq!(g.sh.len(), self.sh_coeffs * 3, "SH coefficient count");
        self.means.extend_from_slice(&g.mean);
        self.log_scales.extend_from_slice(&g.log_scale);
        self.quats.extend_from_slice(&g.quat);
        self.opacity_logits.push(g.opacity_logit);
        self.sh.extend_from_slice(&g.sh);
    }

    pub fn get(&self, i: usize) -> Gaussian {
        let k3 = self.sh_coeffs * 3;
        Gaussian {
            mean: [
                self.means[3 * i],
                self.means[3 * i + 1],
                self.means[3 * i + 2],
            ],
            log_scale: [
                self.log_scales[3 * i],
                self.log_scales[3 * i + 1],
                self.log_scales[3 * i + 2],
            ],
            quat: [
                self.quats[4 * i],
                self.quats[4 * i + 1],
                self.quats[4 * i + 2],
                self.quats[4 * i + 3],
            ],
            opacity_logit: self.opacity_logits[i],
            sh: self.sh[k3 * i..k3 * (i + 1)].to_vec(),
        }
    }

    /// The Gaussians whose `keep` flag is set, in order.
    pub fn retain(&mut self, keep: &[bool]) {
        assert_eq!(keep.len(), self.len());
        let k3 = self.sh_coeffs * 3;
        fewview_optim::retain_rows(&mut self.means, 3, keep);
        fewview_optim::retain_rows(&mut self.log_scales, 3, keep);
        fewview_optim::retain_rows(&mut self.quats, 4, keep);
        fewview_optim::retain_rows(&mut self.opacity_logits, 1, keep);
        fewview_optim::retain_rows(&mut self.sh, k3, keep);
    }

    pub fn refs(&self) -> GaussianRefs<'_, f32> {
        GaussianRefs {
            means: &self.means,
            log_scales: &self.log_scales,
            quats: &self.quats,
            opacity_logits: &self.opacity_logits,
            sh: &self.sh,
            sh_coeffs: self.sh_coeffs,
        }
    }

    /// Checks shapes and that every value is finite.
    pub fn validate(&self) -> Result<(), String> {
        self.refs().check_shapes()?;
        for (name, v) in [
            ("means", &self.means),
            ("log_scales", &self.log_scales),
            ("quats", &self.quats),
            ("opacity_logits", &self.opacity_logits),
            ("sh", &self.sh),
        ] {
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(format!("{name}[{i}] is not finite ({})", v[i]));
            }
        }
        Ok(())
    }

    /// The parameters as Burn tensors on `device`, tracked for gradients when `require_grad`.
    pub fn to_tensors(&self, device: &Device, require_grad: bool) -> GaussianTensors {
        let n = self.len();
        let track = |t: Tensor<2>| if require_grad { t.require_grad() } else { t };
        let t2 = |v: &[f32], c: usize| {
            track(Tensor::<2>::from_data(
                TensorData::new(v.to_vec(), [n, c]),
                device,
            ))
        };
        let opacity =
            Tensor::<1>::from_data(TensorData::new(self.opacity_logits.clone(), [n]), device);
        let sh = Tensor::<3>::from_data(
            TensorData::new(self.sh.clone(), [n, self.sh_coeffs, 3]),
            device,
        );
        GaussianTensors {
            means: t2(&self.means, 3),
            log_scales: t2(&self.log_scales, 3),
            quats: t2(&self.quats, 4),
            opacity_logits: if require_grad {
                opacity.require_grad()
            } else {
                opacity
            },
            sh: if require_grad { sh.require_grad() } else { sh },
        }
    }

    /// The parameters of `tensors` read back to the host (any device; tracked or not).
    pub fn from_tensors(tensors: &GaussianTensors) -> Result<Self, ReadbackError> {
        let [_, sh_coeffs, _] = tensors.sh.dims();
        let model = Self {
            means: f32_values(tensors.means.clone(), "means")?,
            log_scales: f32_values(tensors.log_scales.clone(), "log-scales")?,
            quats: f32_values(tensors.quats.clone(), "rotations")?,
            opacity_logits: f32_values(tensors.opacity_logits.clone(), "opacity logits")?,
            sh: f32_values(tensors.sh.clone(), "SH coefficients")?,
            sh_coeffs,
        };
        Ok(model)
    }

    /// Axis-aligned bounds of the centres.
    pub fn bounds(&self) -> Option<([f32; 3], [f32; 3])> {
        if self.is_empty() {
            return None;
        }
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in self.means.chunks_exact(3) {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        Some((lo, hi))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn retain_keeps_rows_in_order() {
        let mut m = GaussianModel::new(1);
        for i in 0..5 {
            m.push_isotropic([i as f32, 0.0, 0.0], 0.1, [0.5, 0.5, 0.5], 0.5);
        }
        m.retain(&[true, false, true, false, true]);
        assert_eq!(m.len(), 3);
        assert_eq!(m.means, vec![0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 4.0, 0.0, 0.0]);
        assert_eq!(m.sh.len(), 3 * 4 * 3);
        m.validate().unwrap();
    }

    #[test]
    fn dc_colour_roundtrip() {
        let mut m = GaussianModel::new(0);
        m.push_isotropic([0.0; 3], 0.1, [0.2, 0.7, 1.0], 0.9);
        let c: Vec<f64> = m.sh.iter().map(|&s| s as f64 * SH_C0 + 0.5).collect();
        assert!(
            (c[0] - 0.2).abs() < 1e-6 && (c[1] - 0.7).abs() < 1e-6 && (c[2] - 1.0).abs() < 1e-6
        );
        assert!((sigmoid(m.opacity_logits[0]) - 0.9).abs() < 1e-6);
    }
}
