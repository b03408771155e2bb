//! NeuS volume rendering (the surface paper Eqs. 1–3; Wang et al. 2021): samples along each ray inside
//! the unit sphere, hierarchical up-sampling with fixed sharpness, then the unbiased opacity
//!
//! `α_i = max((Φ_s(s_prev) − Φ_s(s_next)) / Φ_s(s_prev), 0)`,
//!
//! the discrete form of Eq. 2 with section SDFs estimated from the mid-point SDF and the cosine
//! between the ray and the normal (NeuS `render_core`, with its cosine annealing), and
//! `T_i = Π_{j<i} (1 − α_j)`, `w_i = T_i α_i`, `C = Σ w_i c_i` (Eq. 1).
//!
//! **Sampling** (NeuS `render`): near/far where the ray's closest point to the origin is ±1,
//! `n_coarse` uniform samples with one random shift per ray, then `up_sample_steps` rounds that
//! each add `n_importance / steps` samples by inverse-CDF sampling of the weights computed with
//! `inv_s = 64 · 2^i` from the SDF at the current samples. Sampling runs on host values without
//! gradients; rendering then re-evaluates the field with gradients at the final samples.
//!
//! **Background**: the object lies in the unit sphere; opacity outside it is zero and the
//! colour left over is `background · (1 − Σ w)` (NeuS "w/ mask" setting: black).

use burn::tensor::{Tensor, TensorData};
use fewview_optim::f32_values;
use serde::{Deserialize, Serialize};

use crate::field::{Field, sdf_and_gradient};

/// Samples per ray.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SampleConfig {
    pub n_coarse: usize,
    pub n_importance: usize,
    pub up_sample_steps: usize,
}

impl Default for SampleConfig {
    /// Half of NeuS's 64 + 64 (CPU budget; see the crate README for the schedule).
    fn default() -> Self {
        Self {
            n_coarse: 32,
            n_importance: 32,
            up_sample_steps: 4,
        }
    }
}

impl SampleConfig {
    pub fn samples_per_ray(&self) -> usize {
        self.n_coarse + self.n_importance
    }

    /// The coarse samples must make at least one interval, and each of the up-sampling steps
    /// (which share `n_importance`) must add at least one sample.
    pub fn validate(&self) -> Result<(), String> {
        if self.n_coarse < 2 {
            return Err(format!(
                "{} coarse samples per ray; need at least 2",
                self.n_coarse
            ));
        }
        let steps = self.up_sample_steps.max(1);
        if self.n_importance > 0 && self.n_importance < steps {
            return Err(format!(
                "{} importance samples cannot be shared by {steps} up-sampling steps; use 0 or at least {steps}",
                self.n_importance
            ));
        }
        Ok(())
    }
}

/// Near and far distances of NeuS's `near_far_from_sphere` (unit `dir`): the closest point to
/// the origin ±1, near clamped at 0.
pub fn near_far(origin: [f32; 3], dir: [f32; 3]) -> (f32, f32) {
    let a = dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2];
    let b = 2.0 * (origin[0] * dir[0] + origin[1] * dir[1] + origin[2] * dir[2]);
    let mid = -0.5 * b / a;
    ((mid - 1.0).max(0.0), (mid + 1.0).max(1e-3))
}

fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// NeuS `up_sample` for one ray: `n` new samples from the weights of the sections between the
/// current samples, with SDF-slope-limited section estimates and sharpness `inv_s`.
fn up_sample_ray(
    origin: [f32; 3],
    dir: [f32; 3],
    z: &[f32],
    sdf: &[f32],
    n: usize,
    inv_s: f32,
) -> Vec<f32> {
    let m = z.len();
    let radius = |t: f32| {
        let p = [
            origin[0] + dir[0] * t,
            origin[1] + dir[1] * t,
            origin[2] + dir[2] * t,
        ];
        (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()
    };
    let mut weights = Vec::with_capacity(m - 1);
    let mut trans = 1.0f32;
    let mut prev_cos = 0.0f32;
    for i in 0..m - 1 {
        let inside = radius(z[i]) < 1.0 || radius(z[i + 1]) < 1.0;
        let dist = z[i + 1] - z[i];
        let mid_sdf = 0.5 * (sdf[i] + sdf[i + 1]);
        let cos = (sdf[i + 1] - sdf[i]) / (dist + 1e-5);
        let c = cos.min(prev_cos).clamp(-1e3, 0.0) * if inside { 1.0 } else { 0.0 };
        prev_cos = cos;
        let prev_cdf = sigmoid((mid_sdf - c * dist * 0.5) * inv_s);
        let next_cdf = sigmoid((mid_sdf + c * dist * 0.5) * inv_s);
        let alpha = (prev_cdf - next_cdf + 1e-5) / (prev_cdf + 1e-5);
        weights.push(alpha * trans);
        trans *= 1.0 - alpha + 1e-7;
    }
    sample_pdf(z, &weights, n)
}

/// Deterministic inverse-CDF sampling (NeuS/NeRF `sample_pdf` with `det=True`): `n` samples in
/// the bins `z` (length `m`) with section weights (length `m − 1`).
pub fn sample_pdf(z: &[f32], weights: &[f32], n: usize) -> Vec<f32> {
    let w: Vec<f32> = weights.iter().map(|w| w + 1e-5).collect();
    let total: f32 = w.iter().sum();
    let mut cdf = Vec::with_capacity(z.len());
    cdf.push(0.0f32);
    let mut acc = 0.0;
    for v in &w {
        acc += v / total;
        cdf.push(acc);
    }
    (0..n)
        .map(|k| {
            let u = (0.5 + k as f32) / n as f32;
            // First index with cdf > u (searchsorted right).
            let inds = cdf.partition_point(|c| *c <= u);
            let below = inds.saturating_sub(1);
            let above = inds.min(cdf.len() - 1);
            let denom = cdf[above] - cdf[below];
            let denom = if denom < 1e-5 { 1.0 } else { denom };
            let t = (u - cdf[below]) / denom;
            z[below] + t * (z[above] - z[below])
        })
        .collect()
}

/// Merges sorted `new` values (with their SDF, when known) into `z`/`sdf`.
fn merge_sorted(z: &mut Vec<f32>, sdf: &mut Vec<f32>, new_z: &[f32], new_sdf: Option<&[f32]>) {
    let mut pairs: Vec<(f32, f32)> = z.iter().copied().zip(sdf.iter().copied()).collect();
    for (k, &t) in new_z.iter().enumerate() {
        pairs.push((t, new_sdf.map(|s| s[k]).unwrap_or(f32::NAN)));
    }
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    *z = pairs.iter().map(|p| p.0).collect();
    *sdf = pairs.iter().map(|p| p.1).collect();
}

/// The final sample distances of every ray, `[R · S]` row-major, S = `samples_per_ray`.
/// `sdf` evaluates the field (no gradient) at flat `[N · 3]` points; `jitter` (one value in
/// `[−0.5, 0.5]` per ray) shifts the coarse samples, as NeuS's `perturb`.
pub fn sample_rays(
    sdf: &dyn Fn(&[f32]) -> crate::error::Result<Vec<f32>>,
    origins: &[[f32; 3]],
    dirs: &[[f32; 3]],
    cfg: &SampleConfig,
    jitter: Option<&[f32]>,
) -> crate::error::Result<Vec<f32>> {
    let r = origins.len();
    let nc = cfg.n_coarse.max(2);
    let mut zs: Vec<Vec<f32>> = (0..r)
        .map(|i| {
            let (near, far) = near_far(origins[i], dirs[i]);
            let shift = jitter.map(|j| j[i] * 2.0 / nc as f32).unwrap_or(0.0);
            (0..nc)
                .map(|k| near + (far - near) * k as f32 / (nc - 1) as f32 + shift)
                .collect()
        })
        .collect();
    let points_of = |ts: &[Vec<f32>]| -> Vec<f32> {
        let mut p = Vec::new();
        for (i, t) in ts.iter().enumerate() {
            for &z in t {
                for a in 0..3 {
                    p.push(origins[i][a] + dirs[i][a] * z);
                }
            }
        }
        p
    };
    let mut sdfs: Vec<Vec<f32>> = {
        let values = sdf(&points_of(&zs))?;
        values.chunks(nc).map(<[f32]>::to_vec).collect()
    };
    let steps = cfg.up_sample_steps.max(1);
    let per_step = cfg.n_importance / steps;
    if cfg.n_importance > 0 {
        for i in 0..steps {
            let n = if i + 1 == steps {
                cfg.n_importance - per_step * (steps - 1)
            } else {
                per_step
            };
            let inv_s = 64.0 * (1u32 << i) as f32;
            let new: Vec<Vec<f32>> = (0..r)
                .map(|k| up_sample_ray(origins[k], dirs[k], &zs[k], &sdfs[k], n, inv_s))
                .collect();
            let last = i + 1 == steps;
            let new_sdf: Option<Vec<Vec<f32>>> = if last {
                None
            } else {
                let v = sdf(&points_of(&new))?;
                Some(v.chunks(n).map(<[f32]>::to_vec).collect())
            };
            for k in 0..r {
                merge_sorted(
                    &mut zs[k],
                    &mut sdfs[k],
                    &new[k],
                    new_sdf.as_ref().map(|s| s[k].as_slice()),
                );
            }
        }
    }
    Ok(zs.into_iter().flatten().collect())
}

/// What a batch of rays renders to.
pub struct Rendered {
    /// `[R, 3]`
    pub color: Tensor<2>,
    /// `[R, 1]`: `Σ w_i t_i`, distance along the (unit) ray.
    pub depth: Tensor<2>,
    /// `[R, 3]`: `Σ w_i ∇s_i` (not normalised).
    pub normal: Tensor<2>,
    /// `[R, 1]`: `Σ w_i`, the rendered alpha mask.
    pub weight_sum: Tensor<2>,
    /// `[R, S]`
    pub weights: Tensor<2>,
    /// `[R·S, 1]`
    pub sdf: Tensor<2>,
    /// `[R·S, 3]`
    pub gradients: Tensor<2>,
    /// `[R·S]` sample distances along the rays (mid-points of the sections).
    pub mid_z: Vec<f32>,
    /// `[R·S]` 1 where the sample lies within radius 1.2 (NeuS's Eikonal region).
    pub relax_inside: Vec<f32>,
    pub rays: usize,
    pub samples: usize,
}

/// Renders rays `origins`/`dirs` (`[R, 3]`, unit directions, gradients flow to both) at the
/// sample distances `z` (`[R · S]` from [`sample_rays`]). `params` are the field's parameter
/// tensors (order of [`Field::param_shapes`]); `cos_anneal` is NeuS's cosine annealing ratio.
pub fn render_rays(
    field: &Field,
    params: &[Tensor<1>],
    origins: Tensor<2>,
    dirs: Tensor<2>,
    z: &[f32],
    cos_anneal: f32,
    background: [f32; 3],
) -> crate::error::Result<Rendered> {
    let [r, _] = origins.dims();
    let s = z.len() / r.max(1);
    let device = origins.device();
    let sample_dist = 2.0 / s.max(1) as f32;
    let mut dists = vec![0.0f32; r * s];
    let mut mid_z = vec![0.0f32; r * s];
    for i in 0..r {
        for k in 0..s {
            let d = if k + 1 < s {
                z[i * s + k + 1] - z[i * s + k]
            } else {
                sample_dist
            };
            dists[i * s + k] = d;
            mid_z[i * s + k] = z[i * s + k] + 0.5 * d;
        }
    }
    let mz = Tensor::<3>::from_data(TensorData::new(mid_z.clone(), [r, s, 1]), &device);
    let o3 = origins.reshape([r, 1, 3]);
    let d3 = dirs.reshape([r, 1, 3]);
    let pts = (o3 + d3.clone() * mz).reshape([r * s, 3]);
    let dirs_s = (d3 + Tensor::<3>::zeros([r, s, 3], &device)).reshape([r * s, 3]);

    // Radii for the sphere masks, from host values (no gradient).
    let pts_host = f32_values(pts.clone(), "sample points")?;
    let mut inside = vec![0.0f32; r * s];
    let mut relax_inside = vec![0.0f32; r * s];
    for k in 0..r * s {
        let p = &pts_host[3 * k..3 * k + 3];
        let rad = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        inside[k] = (rad < 1.0) as u8 as f32;
        relax_inside[k] = (rad < 1.2) as u8 as f32;
    }

    let idx = field.index();
    let (sdf, features, gradients) = sdf_and_gradient(
        field.sdf.as_ref(),
        &params[idx.sdf.clone()],
        pts.clone(),
        field.config.fd_scheme,
        field.sdf.fd_step(),
    );
    let rgb = field.color.forward(
        params[idx.color].clone(),
        pts,
        gradients.clone(),
        dirs_s.clone(),
        features,
    );

    let inv_s = (params[idx.variance].clone() * 10.0)
        .exp()
        .clamp(1e-6, 1e6)
        .reshape([1, 1]);
    let true_cos = (dirs_s * gradients.clone()).sum_dim(1);
    let iter_cos = ((true_cos.clone() * -0.5 + 0.5).clamp_min(0.0) * (1.0 - cos_anneal)
        + true_cos.neg().clamp_min(0.0) * cos_anneal)
        .neg();
    let dist_t = Tensor::<2>::from_data(TensorData::new(dists, [r * s, 1]), &device);
    let half = iter_cos * dist_t * 0.5;
    let next_cdf = burn::tensor::activation::sigmoid((sdf.clone() + half.clone()) * inv_s.clone());
    let prev_cdf = burn::tensor::activation::sigmoid((sdf.clone() - half) * inv_s);
    let inside_t = Tensor::<2>::from_data(TensorData::new(inside, [r * s, 1]), &device);
    let alpha = (((prev_cdf.clone() - next_cdf + 1e-5) / (prev_cdf + 1e-5)).clamp(0.0, 1.0)
        * inside_t)
        .reshape([r, s]);
    // T_i = Π_{j<i} (1 − α_j + 1e-7), through an exclusive cumulative sum of logarithms.
    let log_t = (alpha.clone().neg() + (1.0 + 1e-7)).log();
    let trans = (log_t.clone().cumsum(1) - log_t).exp();
    let weights = alpha * trans;
    let weight_sum = weights.clone().sum_dim(1);
    let w3 = weights.clone().reshape([r, s, 1]);
    let color = (w3.clone() * rgb.reshape([r, s, 3]))
        .sum_dim(1)
        .reshape([r, 3]);
    let bg = Tensor::<2>::from_data(TensorData::new(background.to_vec(), [1, 3]), &device);
    let color = color + bg * (weight_sum.clone().neg() + 1.0);
    let mzt = Tensor::<2>::from_data(TensorData::new(mid_z.clone(), [r, s]), &device);
    let depth = (weights.clone() * mzt).sum_dim(1);
    let normal = (w3 * gradients.clone().reshape([r, s, 3]))
        .sum_dim(1)
        .reshape([r, 3]);
    Ok(Rendered {
        color,
        depth,
        normal,
        weight_sum,
        weights,
        sdf,
        gradients,
        mid_z,
        relax_inside,
        rays: r,
        samples: s,
    })
}

/// NeuS's Eikonal term: mean of `(‖∇s‖ − 1)²` over samples within radius 1.2.
pub fn eikonal_loss(rendered: &Rendered) -> Tensor<1> {
    let device = rendered.gradients.device();
    let n = rendered.relax_inside.len();
    let count: f32 = rendered.relax_inside.iter().sum();
    let mask = Tensor::<2>::from_data(
        TensorData::new(rendered.relax_inside.clone(), [n, 1]),
        &device,
    );
    let norm = (rendered.gradients.clone() * rendered.gradients.clone())
        .sum_dim(1)
        .add_scalar(1e-12)
        .sqrt();
    ((norm - 1.0).powi_scalar(2) * mask).sum() / (count + 1e-5)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::{ColorNetwork, FieldConfig, SdfNetwork};
    use burn::tensor::Device;

    /// The exact SDF of a sphere of radius `r` at `c`, written with tensor ops.
    struct Sphere {
        center: [f32; 3],
        radius: f32,
    }

    impl SdfNetwork for Sphere {
        fn feature_dim(&self) -> usize {
            2
        }
        fn param_shapes(&self) -> Vec<(&'static str, usize)> {
            vec![]
        }
        fn init_params(&self, _: u64) -> Vec<Vec<f32>> {
            vec![]
        }
        fn set_progress(&mut self, _: f64) {}
        fn fd_step(&self) -> f32 {
            1e-3
        }
        fn forward(&self, _: &[Tensor<1>], p: Tensor<2>) -> Tensor<2> {
            let [n, _] = p.dims();
            let device = p.device();
            let c = Tensor::<2>::from_data(TensorData::new(self.center.to_vec(), [1, 3]), &device);
            let d = p - c;
            let sdf = (d.clone() * d).sum_dim(1).sqrt() - self.radius;
            Tensor::cat(vec![sdf, Tensor::zeros([n, 2], &device)], 1)
        }
    }

    fn sphere_field(center: [f32; 3], radius: f32) -> Field {
        Field {
            config: FieldConfig::default(),
            sdf: Box::new(Sphere { center, radius }),
            color: ColorNetwork::new(2, &[8]),
        }
    }

    fn phi(x: f64) -> f64 {
        1.0 / (1.0 + (-x).exp())
    }

    #[test]
    fn weights_integrate_to_the_alpha_mask_of_a_sphere() {
        let (center, radius) = ([0.1f32, -0.05, 0.0], 0.5f32);
        let field = sphere_field(center, radius);
        let inv_s = 400.0f64;
        let variance = (inv_s.ln() / 10.0) as f32;
        let device = Device::flex();
        let params = vec![
            Tensor::<1>::from_data(
                TensorData::new(field.color.init_params(1), [field.color.spec.num_params()]),
                &device,
            ),
            Tensor::<1>::from_data(TensorData::new(vec![variance], [1]), &device),
        ];
        // Rays from a camera at distance 3 towards points on a line across the sphere: some hit,
        // some miss, some graze.
        let eye = [0.0f32, 0.0, -3.0];
        let mut origins = Vec::new();
        let mut dirs = Vec::new();
        let offsets: Vec<f32> = (0..41).map(|k| -0.8 + 0.04 * k as f32).collect();
        for &x in &offsets {
            let target = [x, 0.0f32, 0.0];
            let d = [target[0] - eye[0], target[1] - eye[1], target[2] - eye[2]];
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            origins.push(eye);
            dirs.push([d[0] / n, d[1] / n, d[2] / n]);
        }
        let sdf_fn = |p: &[f32]| field.sdf_host(&[], p);
        let cfg = SampleConfig {
            n_coarse: 64,
            n_importance: 64,
            up_sample_steps: 4,
        };
        let z = sample_rays(&sdf_fn, &origins, &dirs, &cfg, None).unwrap();
        let r = origins.len();
        let o = Tensor::<2>::from_data(TensorData::new(origins.concat(), [r, 3]), &device);
        let d = Tensor::<2>::from_data(TensorData::new(dirs.concat(), [r, 3]), &device);
        let out = render_rays(&field, &params, o, d, &z, 1.0, [0.0; 3]).unwrap();
        let ws = out.weight_sum.into_data().try_to_vec::<f32>().unwrap();
        let depth = out.depth.into_data().try_to_vec::<f32>().unwrap();
        for k in 0..r {
            // Closest approach of the ray to the centre → min SDF along the ray.
            let (o, d) = (origins[k], dirs[k]);
            let oc: Vec<f64> = (0..3).map(|a| (o[a] - center[a]) as f64).collect();
            let tc = -(oc[0] * d[0] as f64 + oc[1] * d[1] as f64 + oc[2] * d[2] as f64);
            let closest: f64 = (0..3)
                .map(|a| (oc[a] + tc * d[a] as f64).powi(2))
                .sum::<f64>()
                .sqrt();
            let f_min = closest - radius as f64;
            let f0 = (oc.iter().map(|v| v * v).sum::<f64>()).sqrt() - radius as f64;
            // Continuous NeuS opacity along a ray whose SDF decreases from f0 to f_min.
            let want = 1.0 - phi(inv_s * f_min) / phi(inv_s * f0);
            assert!(
                (ws[k] as f64 - want).abs() < 0.02,
                "ray {k}: Σw = {} but the alpha mask is {want} (closest {closest})",
                ws[k]
            );
            if want > 0.99 {
                // Expected depth: the first intersection, tc − √(r² − closest²).
                let hit = tc - ((radius as f64).powi(2) - closest * closest).sqrt();
                assert!(
                    (depth[k] as f64 - hit).abs() < 0.01,
                    "ray {k}: depth {} vs {hit}",
                    depth[k]
                );
            }
        }
        // Both kinds of rays are present.
        assert!(ws.iter().filter(|w| **w > 0.99).count() > 10);
        assert!(ws.iter().filter(|w| **w < 0.01).count() > 10);
    }

    #[test]
    fn pdf_sampling_follows_the_weights() {
        let z: Vec<f32> = (0..11).map(|k| k as f32).collect();
        let mut w = vec![0.0f32; 10];
        w[3] = 1.0;
        let s = sample_pdf(&z, &w, 8);
        assert!(s.iter().all(|t| (3.0..=4.0).contains(t)), "{s:?}");
        assert!(s.windows(2).all(|p| p[0] <= p[1]));
    }
}
