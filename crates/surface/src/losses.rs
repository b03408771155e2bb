//! The loss terms of the surface paper (§3.3–3.5), each a function of rendered tensors so that the
//! trainer can switch them on and off for ablations.
//!
//! Reductions the paper leaves open are chosen as in the code it builds on and documented at
//! each function: batch means (SPARF/NeuS) rather than sums, `1 − NCC` as the photometric
//! distance (NeuralWarp), the L1 norm for Eq. 8 (iSDF).

use burn::tensor::{Int, Tensor, TensorData};
use fewview_optim::f32_values;

use crate::error::Result;
use crate::rays::project;

fn constant2(data: Vec<f32>, rows: usize, cols: usize, device: &burn::tensor::Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(data, [rows, cols]), device)
}

/// Colour loss of Eq. 10, `Σ_r w_r ‖C_r − Ĉ_r‖² / (3 Σ_r w_r)`: the mean squared error the
/// paper names, over the rays with weight `w_r` (the object mask when masks are used, as
/// NeuS's "w/ mask" setting; 1 otherwise).
pub fn color_loss(color: &Tensor<2>, target: &[f32], ray_weights: &[f32]) -> Tensor<1> {
    let device = color.device();
    let r = ray_weights.len();
    let t = constant2(target.to_vec(), r, 3, &device);
    let w = constant2(ray_weights.to_vec(), r, 1, &device);
    let total: f32 = ray_weights.iter().sum::<f32>().max(1e-5);
    ((color.clone() - t).powi_scalar(2) * w).sum() / (3.0 * total)
}

/// NeuS's mask loss: binary cross-entropy between the rendered opacity `Σ w` (clipped to
/// `[10⁻³, 1 − 10⁻³]`) and the object mask.
pub fn mask_loss(weight_sum: &Tensor<2>, mask: &[f32]) -> Tensor<1> {
    let device = weight_sum.device();
    let r = mask.len();
    let m = constant2(mask.to_vec(), r, 1, &device);
    let o = weight_sum.clone().clamp(1e-3, 1.0 - 1e-3);
    let bce = m.clone() * o.clone().log() + (m.neg() + 1.0) * (o.neg() + 1.0).log();
    bce.mean().neg()
}

/// One batch of correspondences with everything rendered for both ends.
pub struct CorrespondenceBatch {
    /// `[B, 12]` pose rows of the target view `t` (where `p` lies) and the source view `s`.
    pub rows_t: Tensor<2>,
    pub rows_s: Tensor<2>,
    /// `[B, 4]` intrinsics rows.
    pub k_t: Tensor<2>,
    pub k_s: Tensor<2>,
    /// Pixel coordinates `p` (in `t`) and `q` (in `s`), host.
    pub p: Vec<[f32; 2]>,
    pub q: Vec<[f32; 2]>,
    /// Matcher confidences.
    pub confidence: Vec<f32>,
    /// Back-projected points `π⁻¹(p, z_p, P_t)` and `π⁻¹(q, z_q, P_s)`, `[B, 3]`.
    pub x_p: Tensor<2>,
    pub x_q: Tensor<2>,
}

/// `L_M.C.` of Eq. 10 in both directions (as SPARF): `‖p − π(π⁻¹(q, z_q, P_s), P_t)‖₂` and
/// `‖q − π(π⁻¹(p, z_p, P_t), P_s)‖₂`, averaged over the batch with the matcher confidences as
/// weights (SPARF's weighted mean; the paper's Σ is read as this mean). Points that land
/// behind a camera are left out.
pub fn matching_loss(b: &CorrespondenceBatch) -> Result<Tensor<1>> {
    let device = b.x_p.device();
    let n = b.p.len();
    let dir = |rows: &Tensor<2>, k: &Tensor<2>, x: &Tensor<2>, target: &[[f32; 2]]| {
        let (uv, z) = project(rows, k, x);
        let zh = f32_values(z, "depths of the reprojected matches")?;
        let w: Vec<f32> = (0..n)
            .map(|i| {
                if zh.get(i).copied().unwrap_or(0.0) > 1e-3 {
                    b.confidence[i]
                } else {
                    0.0
                }
            })
            .collect();
        let t = constant2(target.concat(), n, 2, &device);
        let err = ((uv - t).powi_scalar(2).sum_dim(1) + 1e-12).sqrt();
        let total = w.iter().sum::<f32>().max(1e-6);
        Ok::<_, crate::error::SurfaceError>((err * constant2(w, n, 1, &device)).sum() / total)
    };
    Ok((dir(&b.rows_t, &b.k_t, &b.x_q, &b.p)? + dir(&b.rows_s, &b.k_s, &b.x_p, &b.q)?) * 0.5)
}

/// `D = ‖π⁻¹(p) − π⁻¹(q)‖²` per correspondence, `[B, 1]` (Eq. 5's distances).
pub fn backprojection_distances(b: &CorrespondenceBatch) -> Tensor<2> {
    (b.x_p.clone() - b.x_q.clone()).powi_scalar(2).sum_dim(1)
}

/// The uncertainty of Eq. 5, `u = N(D)` with `N` the min–max scaling over the batch, and the
/// weights `γ = 1 − u` of Eqs. 6–7 (constants: no gradient flows through the uncertainty).
pub fn uncertainty_weights(distances: &[f32]) -> Vec<f32> {
    let lo = distances.iter().copied().fold(f32::INFINITY, f32::min);
    let hi = distances.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let range = hi - lo;
    distances
        .iter()
        .map(|d| {
            if range > 0.0 {
                1.0 - (d - lo) / range
            } else {
                1.0
            }
        })
        .collect()
}

/// `L_u,gc = (1/B) Σ γ ⊙ D` (Eq. 7).
pub fn geometric_consistency_loss(distances: &Tensor<2>, gamma: &[f32]) -> Tensor<1> {
    let device = distances.device();
    let n = gamma.len();
    (distances.clone() * constant2(gamma.to_vec(), n, 1, &device)).sum() / n.max(1) as f32
}

/// Grayscale images of all views, flattened, for differentiable bilinear lookups.
pub struct GrayStack {
    pub values: Tensor<1>,
    pub host: Vec<f32>,
    pub width: usize,
    pub height: usize,
}

impl GrayStack {
    /// Host bilinear lookup (pixel centres at half-integers), `None` outside.
    pub fn sample_host(&self, view: usize, u: f32, v: f32) -> Option<f32> {
        let (x, y) = (u - 0.5, v - 0.5);
        let (x0, y0) = (x.floor(), y.floor());
        if x0 < 0.0 || y0 < 0.0 || x0 as usize + 1 >= self.width || y0 as usize + 1 >= self.height {
            return None;
        }
        let (fx, fy) = (x - x0, y - y0);
        let base = view * self.width * self.height;
        let at = |xx: usize, yy: usize| self.host[base + yy * self.width + xx];
        let (xi, yi) = (x0 as usize, y0 as usize);
        Some(
            at(xi, yi) * (1.0 - fx) * (1.0 - fy)
                + at(xi + 1, yi) * fx * (1.0 - fy)
                + at(xi, yi + 1) * (1.0 - fx) * fy
                + at(xi + 1, yi + 1) * fx * fy,
        )
    }

    /// Differentiable bilinear lookup at `uv` (`[N, 2]`, gradients to the coordinates) in the
    /// given views: values `[N, 1]` and validity (inside the image) per point.
    pub fn sample(&self, views: &[usize], uv: &Tensor<2>) -> Result<(Tensor<2>, Vec<bool>)> {
        let device = uv.device();
        let n = views.len();
        let host = f32_values(uv.clone(), "lookup coordinates")?;
        let mut idx = vec![[0i64; 4]; n];
        let mut base_xy = vec![0.0f32; 2 * n];
        let mut valid = vec![false; n];
        for i in 0..n {
            let (x, y) = (host[2 * i] - 0.5, host[2 * i + 1] - 0.5);
            let ok = x.is_finite() && y.is_finite();
            let (x0, y0) = if ok {
                (x.floor(), y.floor())
            } else {
                (0.0, 0.0)
            };
            valid[i] = ok
                && x0 >= 0.0
                && y0 >= 0.0
                && (x0 as usize) + 1 < self.width
                && (y0 as usize) + 1 < self.height;
            let (xi, yi) = if valid[i] {
                (x0 as usize, y0 as usize)
            } else {
                (0, 0)
            };
            let base = (views[i] * self.width * self.height) as i64;
            let w = self.width as i64;
            let (xi, yi) = (xi as i64, yi as i64);
            idx[i] = [
                base + yi * w + xi,
                base + yi * w + xi + 1,
                base + (yi + 1) * w + xi,
                base + (yi + 1) * w + xi + 1,
            ];
            // For invalid points the fraction is computed from (0, 0) and the result unused.
            base_xy[2 * i] = if valid[i] { x0 + 0.5 } else { host[2 * i] };
            base_xy[2 * i + 1] = if valid[i] { y0 + 0.5 } else { host[2 * i + 1] };
        }
        let frac = uv.clone() - constant2(base_xy, n, 2, &device);
        let fx = frac.clone().slice([0..n, 0..1]);
        let fy = frac.slice([0..n, 1..2]);
        let gather = |c: usize| {
            let ids: Vec<i64> = idx.iter().map(|q| q[c]).collect();
            self.values
                .clone()
                .select(
                    0,
                    Tensor::<1, Int>::from_data(TensorData::new(ids, [n]), &device),
                )
                .reshape([n, 1])
        };
        let one_fx = fx.clone().neg() + 1.0;
        let one_fy = fy.clone().neg() + 1.0;
        let value = gather(0) * one_fx.clone() * one_fy.clone()
            + gather(1) * fx.clone() * one_fy
            + gather(2) * one_fx * fy.clone()
            + gather(3) * fx * fy;
        Ok((value, valid))
    }
}

/// Offsets of a square patch of `(2h + 1)²` pixels with spacing `step`.
pub fn patch_offsets(half: usize, step: f32) -> Vec<[f32; 2]> {
    let h = half as i32;
    let mut out = Vec::new();
    for dy in -h..=h {
        for dx in -h..=h {
            out.push([dx as f32 * step, dy as f32 * step]);
        }
    }
    out
}

/// The uncertainty-aware patch NCC of Eq. 6, `(1/B) Σ γ ⊙ (1 − NCC(s_t, s_s))`.
///
/// The patch around `p` in the target view is warped into the source view through the plane of
/// the rendered surface point `x_p` with the rendered normal `normal_p` (NeuralWarp /
/// SCNeuS's plane-induced homography), sampling grayscale intensities bilinearly; gradients
/// reach the geometry (point, normal) and both poses. `1 − NCC` (NCC of Eq. 4 in `[−1, 1]`) is
/// the photometric distance, as in NeuralWarp. Patches that leave the source image, or whose
/// plane is seen edge-on, get weight 0.
#[allow(clippy::too_many_arguments)]
pub fn ncc_loss(
    gray: &GrayStack,
    b: &CorrespondenceBatch,
    views_t: &[usize],
    views_s: &[usize],
    origins_t: &Tensor<2>,
    normal_p: &Tensor<2>,
    offsets: &[[f32; 2]],
    gamma: &[f32],
) -> Result<Tensor<1>> {
    let device = b.x_p.device();
    let nb = b.p.len();
    let np = offsets.len();
    let n = nb * np;
    // Repeat each correspondence's tensors for its patch pixels.
    let rep: Vec<i64> = (0..nb)
        .flat_map(|i| std::iter::repeat_n(i as i64, np))
        .collect();
    let rep_t = Tensor::<1, Int>::from_data(TensorData::new(rep, [n]), &device);
    let take = |t: &Tensor<2>| t.clone().select(0, rep_t.clone());
    let (rows_t, rows_s, k_s) = (take(&b.rows_t), take(&b.rows_s), take(&b.k_s));
    let (o, x0) = (take(origins_t), take(&b.x_p));
    let nrm = {
        let nn = take(normal_p);
        let len = (nn.clone().powi_scalar(2).sum_dim(1) + 1e-12).sqrt();
        nn / len
    };
    // Camera-frame directions of the target patch pixels (constants).
    let k_t_host = f32_values(b.k_t.clone(), "intrinsics of the target views")?;
    let mut dcam = Vec::with_capacity(n * 3);
    let mut reference = Vec::with_capacity(n);
    let mut ref_valid = vec![true; nb];
    for i in 0..nb {
        let (fx, fy, cx, cy) = (
            k_t_host[4 * i],
            k_t_host[4 * i + 1],
            k_t_host[4 * i + 2],
            k_t_host[4 * i + 3],
        );
        for off in offsets {
            let (u, v) = (b.p[i][0] + off[0], b.p[i][1] + off[1]);
            dcam.extend([(u - cx) / fx, (v - cy) / fy, 1.0]);
            match gray.sample_host(views_t[i], u, v) {
                Some(g) => reference.push(g),
                None => {
                    reference.push(0.0);
                    ref_valid[i] = false;
                }
            }
        }
    }
    let dc = constant2(dcam, n, 3, &device);
    let c = |t: &Tensor<2>, a: usize, z: usize| t.clone().slice([0..n, a..z]);
    let d = c(&rows_t, 0, 3) * c(&dc, 0, 1)
        + c(&rows_t, 3, 6) * c(&dc, 1, 2)
        + c(&rows_t, 6, 9) * c(&dc, 2, 3);
    let denom = (nrm.clone() * d.clone()).sum_dim(1);
    let denom_host = f32_values(denom.clone(), "patch plane denominators")?;
    let safe = denom_host
        .iter()
        .map(|v| if v.abs() < 1e-3 { 1.0 } else { 0.0 })
        .collect::<Vec<f32>>();
    let denom = denom + constant2(safe, n, 1, &device);
    let tstar = (nrm * (x0 - o.clone())).sum_dim(1) / denom;
    let x = o + d * tstar;
    let (uv, z) = project(&rows_s, &k_s, &x);
    let zh = f32_values(z, "depths of the warped patches")?;
    let views_rep: Vec<usize> = (0..nb)
        .flat_map(|i| std::iter::repeat_n(views_s[i], np))
        .collect();
    let (warped, valid) = gray.sample(&views_rep, &uv)?;
    let mut weight = vec![0.0f32; nb];
    for i in 0..nb {
        let ok = ref_valid[i]
            && (0..np).all(|k| {
                valid[i * np + k] && zh[i * np + k] > 1e-3 && denom_host[i * np + k].abs() >= 1e-3
            });
        weight[i] = if ok { gamma[i] } else { 0.0 };
    }
    let count = weight.iter().filter(|w| **w > 0.0).count();
    if count == 0 {
        return Ok(Tensor::zeros([1], &device));
    }
    let s = warped.reshape([nb, np]);
    let t = constant2(reference, nb, np, &device);
    let sm = s.clone() - s.clone().mean_dim(1);
    let tm = t.clone() - t.mean_dim(1);
    let cov = (sm.clone() * tm.clone()).mean_dim(1);
    let var_s = sm.powi_scalar(2).mean_dim(1);
    let var_t = tm.powi_scalar(2).mean_dim(1);
    let ncc = cov / (var_s * var_t + 1e-8).sqrt();
    Ok(((ncc.neg() + 1.0) * constant2(weight, nb, 1, &device)).sum() / nb as f32)
}

/// The band `b(k) = λ_b cos(A(k) π/2) d` of Eq. 12 for a ray of rendered depth `d`, with
/// `A(k) = (k − α₁)/(α₂ − α₁)`; zero outside `[α₁, α₂)` (Eq. 13). `progress` is `k` as a fraction
/// of training, `window` = `(α₁, α₂)`.
pub fn psdf_band(progress: f64, window: (f64, f64), lambda_b: f64, depth: f64) -> f64 {
    let (a1, a2) = window;
    if progress < a1 || progress >= a2 || a2 <= a1 {
        return 0.0;
    }
    let a = (progress - a1) / (a2 - a1);
    lambda_b * (a * std::f64::consts::FRAC_PI_2).cos() * depth
}

/// The progressive SDF loss, Eqs. 8–9 and 12–13: for each sample `P` of a ray with rendered
/// depth `d` (constant) and `|d(P) − d| < b`, the target SDF is `d' = d − d(P)`, the signed
/// distance along the ray to the rendered surface point; `L = mean(h · |d' − s(P)|)` over the
/// samples in the band with `h = b(k)` (Eq. 13). The L1 norm follows iSDF, which the paper
/// adapts (Eq. 8 prints the bare difference). Rays with `ray_ok = false` (background) are left
/// out.
pub fn psdf_loss(
    sdf: &Tensor<2>,
    mid_z: &[f32],
    samples: usize,
    depth: &[f32],
    ray_ok: &[bool],
    band: &dyn Fn(f32) -> f32,
) -> Option<Tensor<1>> {
    let device = sdf.device();
    let n = mid_z.len();
    let mut target = vec![0.0f32; n];
    let mut weight = vec![0.0f32; n];
    let mut count = 0usize;
    for (r, &d) in depth.iter().enumerate() {
        if !ray_ok[r] {
            continue;
        }
        let b = band(d);
        if b <= 0.0 {
            continue;
        }
        for k in 0..samples {
            let i = r * samples + k;
            if (mid_z[i] - d).abs() < b {
                target[i] = d - mid_z[i];
                weight[i] = b;
                count += 1;
            }
        }
    }
    if count == 0 {
        return None;
    }
    let t = constant2(target, n, 1, &device);
    let w = constant2(weight, n, 1, &device);
    Some(((t - sdf.clone()).abs() * w).sum() / count as f32)
}

#[cfg(test)]
mod tests {
    use burn::tensor::Device;

    use super::*;

    #[test]
    fn uncertainty_is_min_max_scaled() {
        let g = uncertainty_weights(&[1.0, 3.0, 2.0, 5.0]);
        assert_eq!(g, vec![1.0, 0.5, 0.75, 0.0]);
        assert_eq!(uncertainty_weights(&[2.0, 2.0]), vec![1.0, 1.0]);
    }

    #[test]
    fn psdf_band_follows_the_cosine_schedule() {
        assert_eq!(psdf_band(0.1, (0.4, 0.7), 0.1, 3.0), 0.0);
        assert!((psdf_band(0.4, (0.4, 0.7), 0.1, 3.0) - 0.3).abs() < 1e-12);
        let mid = psdf_band(0.55, (0.4, 0.7), 0.1, 3.0);
        assert!((mid - 0.3 * (std::f64::consts::FRAC_PI_4).cos()).abs() < 1e-12);
        assert_eq!(psdf_band(0.7, (0.4, 0.7), 0.1, 3.0), 0.0);
    }

    #[test]
    fn psdf_targets_are_signed_distances_along_the_ray() {
        let device = Device::flex();
        // One ray, samples at 1.0 … 1.9, rendered depth 1.5, band 0.25: samples 1.3 … 1.7 count.
        let mid: Vec<f32> = (0..10).map(|k| 1.0 + 0.1 * k as f32).collect();
        // SDF equal to the target everywhere → zero loss.
        let exact: Vec<f32> = mid.iter().map(|t| 1.5 - t).collect();
        let sdf = Tensor::<2>::from_data(TensorData::new(exact.clone(), [10, 1]), &device);
        let l = psdf_loss(&sdf, &mid, 10, &[1.5], &[true], &|_| 0.25).unwrap();
        assert!(l.into_data().try_to_vec::<f32>().unwrap()[0].abs() < 1e-6);
        // SDF off by 0.1 everywhere → loss 0.25 · 0.1 (weight h = b).
        let off: Vec<f32> = exact.iter().map(|v| v + 0.1).collect();
        let sdf = Tensor::<2>::from_data(TensorData::new(off, [10, 1]), &device);
        let l = psdf_loss(&sdf, &mid, 10, &[1.5], &[true], &|_| 0.25).unwrap();
        assert!((l.into_data().try_to_vec::<f32>().unwrap()[0] - 0.025).abs() < 1e-6);
        assert!(psdf_loss(&sdf, &mid, 10, &[1.5], &[false], &|_| 0.25).is_none());
    }

    #[test]
    fn bilinear_lookup_matches_host_and_has_coordinate_gradients() {
        let (w, h) = (6usize, 5usize);
        let host: Vec<f32> = (0..2 * w * h)
            .map(|i| ((i * 7) % 13) as f32 / 13.0)
            .collect();
        let device = Device::flex().autodiff();
        let stack = GrayStack {
            values: Tensor::from_data(TensorData::new(host.clone(), [2 * w * h]), &device),
            host,
            width: w,
            height: h,
        };
        let pts = vec![1.3f32, 2.7, 4.9, 0.6, 3.25, 3.5, 7.0, 1.0];
        let uv =
            Tensor::<2>::from_data(TensorData::new(pts.clone(), [4, 2]), &device).require_grad();
        let views = [0usize, 1, 1, 0];
        let (vals, valid) = stack.sample(&views, &uv).unwrap();
        assert_eq!(valid, vec![true, true, true, false]);
        let v = vals.clone().into_data().try_to_vec::<f32>().unwrap();
        for i in 0..3 {
            let want = stack
                .sample_host(views[i], pts[2 * i], pts[2 * i + 1])
                .unwrap();
            assert!((v[i] - want).abs() < 1e-6);
        }
        // d value / du by finite differences of the host lookup.
        let g = vals.sum().backward();
        let gu = uv
            .grad(&g)
            .unwrap()
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        for i in 0..3 {
            let e = 1e-3;
            let fd = (stack
                .sample_host(views[i], pts[2 * i] + e, pts[2 * i + 1])
                .unwrap()
                - stack
                    .sample_host(views[i], pts[2 * i] - e, pts[2 * i + 1])
                    .unwrap())
                / (2.0 * e);
            assert!((gu[2 * i] - fd).abs() < 1e-3, "{} vs {fd}", gu[2 * i]);
        }
    }
}
