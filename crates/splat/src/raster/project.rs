//! Per-Gaussian projection (forward) and its exact backward.
//!
//! Forward, for a Gaussian with mean `p`, log-scales `ŝ`, quaternion `q`, opacity logit `ô` and
//! SH coefficients, seen by a camera `x_cam = W p + t`:
//! - `Σ = M Mᵀ`, `M = R(q/|q|) diag(exp ŝ)` (3DGS Eq. 6);
//! - `Σ' = J W Σ Wᵀ Jᵀ + 0.3 I` with the EWA Jacobian `J` of the perspective map at the
//!   (FoV-clamped) centre (3DGS Eq. 5, Zwicker et al. 2001);
//! - conic `Σ'⁻¹`, screen centre `(fx x/z + cx, fy y/z + cy)`, depth `z`;
//! - colour `max(0, Σ_k Y_k(d) sh_k + 0.5)` with `d` the unit direction from the camera centre;
//! - opacity `σ(ô)`.
//!
//! The code indexes small matrices and vectors by their mathematical indices, and rejects NaN
//! with negated comparisons (`!(z >= near)` is true for NaN), so two clippy lints are off here.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

use super::inputs::{ALPHA_MIN, DILATION, FOV_CLAMP, GaussianRefs, RenderCamera, sh_degree_of};
use crate::real::Real;
use crate::sh;

type M3<F> = [[F; 3]; 3];

/// What the blending stage needs of one visible Gaussian.
#[derive(Clone, Copy, Debug, Default)]
pub struct Splat<F> {
    /// Screen centre in pixels.
    pub mean: [F; 2],
    /// Inverse 2D covariance `(a, b, c)` of `[[a, b], [b, c]]`.
    pub conic: [F; 3],
    pub opacity: F,
    pub color: [F; 3],
    pub depth: F,
    /// Pixel rows `[y0, y1)` and columns `[x0, x1)` where `α ≥ 1/255` is possible, clipped to
    /// the image.
    pub rows: [u32; 2],
    pub cols: [u32; 2],
}

/// The projection of one Gaussian, or `None` when it is culled (behind the near plane,
/// degenerate, too transparent to ever reach α = 1/255, or off screen).
#[derive(Clone, Copy, Debug)]
pub struct Projection<F> {
    pub splat: Splat<F>,
    /// Screen radius (px) of the 3σ circle of the largest eigenvalue, as the reference code's
    /// `radii` (used by densification: screen-size pruning).
    pub radius: F,
}

/// Rotation matrix of a unit quaternion `(w, x, y, z)`.
#[inline]
fn quat_to_matrix<F: Real>(q: [F; 4]) -> M3<F> {
    let [w, x, y, z] = q;
    let one = F::one();
    let two = F::c(2.0);
    [
        [
            one - two * (y * y + z * z),
            two * (x * y - w * z),
            two * (x * z + w * y),
        ],
        [
            two * (x * y + w * z),
            one - two * (x * x + z * z),
            two * (y * z - w * x),
        ],
        [
            two * (x * z - w * y),
            two * (y * z + w * x),
            one - two * (x * x + y * y),
        ],
    ]
}

/// `dL/dq` for `R(q)` given `dL/dR` (q unit, treated as free; normalisation handled by caller).
#[inline]
fn quat_to_matrix_backward<F: Real>(q: [F; 4], g: &M3<F>) -> [F; 4] {
    let [w, x, y, z] = q;
    let two = F::c(2.0);
    let gw =
        two * (-z * g[0][1] + y * g[0][2] + z * g[1][0] - x * g[1][2] - y * g[2][0] + x * g[2][1]);
    let gx = two
        * (y * g[0][1] + z * g[0][2] + y * g[1][0] - two * x * g[1][1] - w * g[1][2]
            + z * g[2][0]
            + w * g[2][1]
            - two * x * g[2][2]);
    let gy = two
        * (-two * y * g[0][0] + x * g[0][1] + w * g[0][2] + x * g[1][0] + z * g[1][2]
            - w * g[2][0]
            + z * g[2][1]
            - two * y * g[2][2]);
    let gz = two
        * (-two * z * g[0][0] - w * g[0][1] + x * g[0][2] + w * g[1][0] - two * z * g[1][1]
            + y * g[1][2]
            + x * g[2][0]
            + y * g[2][1]);
    [gw, gx, gy, gz]
}

#[inline]
fn sigmoid<F: Real>(x: F) -> F {
    F::one() / (F::one() + (-x).exp())
}

/// Camera constants in the working precision.
#[derive(Clone, Copy, Debug)]
pub struct CameraF<F> {
    pub fx: F,
    pub fy: F,
    pub cx: F,
    pub cy: F,
    pub width: usize,
    pub height: usize,
    pub rotation: M3<F>,
    pub translation: [F; 3],
    pub center: [F; 3],
    /// FoV clamp limits of `x/z` (negative side, positive side) and `y/z`.
    pub lim_x: [F; 2],
    pub lim_y: [F; 2],
    pub near: F,
}

impl<F: Real> CameraF<F> {
    pub fn new(cam: &RenderCamera, near: f64) -> Self {
        let c = F::c;
        let r = cam.rotation;
        let center = cam.center();
        Self {
            fx: c(cam.fx),
            fy: c(cam.fy),
            cx: c(cam.cx),
            cy: c(cam.cy),
            width: cam.width,
            height: cam.height,
            rotation: [
                [c(r[0][0]), c(r[0][1]), c(r[0][2])],
                [c(r[1][0]), c(r[1][1]), c(r[1][2])],
                [c(r[2][0]), c(r[2][1]), c(r[2][2])],
            ],
            translation: [
                c(cam.translation[0]),
                c(cam.translation[1]),
                c(cam.translation[2]),
            ],
            center: [c(center[0]), c(center[1]), c(center[2])],
            lim_x: [
                c(FOV_CLAMP * cam.cx / cam.fx),
                c(FOV_CLAMP * (cam.width as f64 - cam.cx) / cam.fx),
            ],
            lim_y: [
                c(FOV_CLAMP * cam.cy / cam.fy),
                c(FOV_CLAMP * (cam.height as f64 - cam.cy) / cam.fy),
            ],
            near: c(near),
        }
    }

    #[inline]
    fn world_to_camera(&self, p: [F; 3]) -> [F; 3] {
        let r = &self.rotation;
        let t = &self.translation;
        [
            r[0][0] * p[0] + r[0][1] * p[1] + r[0][2] * p[2] + t[0],
            r[1][0] * p[0] + r[1][1] * p[1] + r[1][2] * p[2] + t[1],
            r[2][0] * p[0] + r[2][1] * p[1] + r[2][2] * p[2] + t[2],
        ]
    }
}

/// Intermediate values of the forward projection that the backward pass reuses.
struct Forward<F> {
    t: [F; 3],
    /// Clamped `x/z`, `y/z` and whether the clamp was active.
    ratio: [F; 2],
    clamped: [bool; 2],
    q_unit: [F; 4],
    q_norm: F,
    rot: M3<F>,
    scale: [F; 3],
    sigma: M3<F>,
    /// `T = J W`, 2×3.
    tmat: [[F; 3]; 2],
    /// Dilated 2D covariance `(a, b, c)`.
    cov: [F; 3],
    det: F,
    dir: [F; 3],
    dir_norm: F,
    basis: [F; 16],
    /// Unclamped colour (before `max(0, ·)`).
    color_raw: [F; 3],
    opacity: F,
}

/// Loads the parameters of Gaussian `i` and runs the forward projection up to (not including)
/// culling decisions. Returns `None` for centres behind the near plane or zero quaternions.
fn forward_one<F: Real>(
    g: &GaussianRefs<'_, F>,
    i: usize,
    cam: &CameraF<F>,
    sh_degree: usize,
) -> Option<Forward<F>> {
    let p = [g.means[3 * i], g.means[3 * i + 1], g.means[3 * i + 2]];
    let t = cam.world_to_camera(p);
    if !(t[2] >= cam.near) {
        return None;
    }
    let q = [
        g.quats[4 * i],
        g.quats[4 * i + 1],
        g.quats[4 * i + 2],
        g.quats[4 * i + 3],
    ];
    let q_norm = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    if !(q_norm > F::c(1e-12)) {
        return None;
    }
    let q_unit = [q[0] / q_norm, q[1] / q_norm, q[2] / q_norm, q[3] / q_norm];
    let rot = quat_to_matrix(q_unit);
    let scale = [
        g.log_scales[3 * i].exp(),
        g.log_scales[3 * i + 1].exp(),
        g.log_scales[3 * i + 2].exp(),
    ];
    // Σ = R S Sᵀ Rᵀ
    let mut sigma = [[F::zero(); 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            let mut s = F::zero();
            for k in 0..3 {
                s = s + rot[a][k] * scale[k] * scale[k] * rot[b][k];
            }
            sigma[a][b] = s;
        }
    }
    let inv_z = F::one() / t[2];
    let raw = [t[0] * inv_z, t[1] * inv_z];
    let lims = [cam.lim_x, cam.lim_y];
    let mut ratio = [F::zero(); 2];
    let mut clamped = [false; 2];
    for k in 0..2 {
        let lo = -lims[k][0];
        let hi = lims[k][1];
        ratio[k] = raw[k].max(lo).min(hi);
        clamped[k] = raw[k] < lo || raw[k] > hi;
    }
    // J = [[fx/z, 0, -fx x'/z], [0, fy/z, -fy y'/z]] with x' = clamped x/z.
    let j = [
        [cam.fx * inv_z, F::zero(), -cam.fx * ratio[0] * inv_z],
        [F::zero(), cam.fy * inv_z, -cam.fy * ratio[1] * inv_z],
    ];
    let w = &cam.rotation;
    let mut tmat = [[F::zero(); 3]; 2];
    for r in 0..2 {
        for c in 0..3 {
            tmat[r][c] = j[r][0] * w[0][c] + j[r][1] * w[1][c] + j[r][2] * w[2][c];
        }
    }
    // Σ' = T Σ Tᵀ + 0.3 I
    let mut ts = [[F::zero(); 3]; 2];
    for r in 0..2 {
        for c in 0..3 {
            ts[r][c] =
                tmat[r][0] * sigma[0][c] + tmat[r][1] * sigma[1][c] + tmat[r][2] * sigma[2][c];
        }
    }
    let dot = |a: &[F; 3], b: &[F; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let cov = [
        dot(&ts[0], &tmat[0]) + F::c(DILATION),
        dot(&ts[0], &tmat[1]),
        dot(&ts[1], &tmat[1]) + F::c(DILATION),
    ];
    let det = cov[0] * cov[2] - cov[1] * cov[1];

    let dv = [
        p[0] - cam.center[0],
        p[1] - cam.center[1],
        p[2] - cam.center[2],
    ];
    let dir_norm = dot(&dv, &dv).sqrt().max(F::c(1e-20));
    let dir = [dv[0] / dir_norm, dv[1] / dir_norm, dv[2] / dir_norm];
    let mut basis = [F::zero(); 16];
    let degree = sh_degree.min(sh_degree_of(g.sh_coeffs));
    sh::basis(degree, dir, &mut basis, None);
    let k_used = sh::num_coeffs(degree);
    let base = i * g.sh_coeffs * 3;
    let mut color_raw = [F::c(0.5); 3];
    for (k, yk) in basis.iter().enumerate().take(k_used) {
        for (ch, col) in color_raw.iter_mut().enumerate() {
            *col = *col + *yk * g.sh[base + 3 * k + ch];
        }
    }
    let opacity = sigmoid(g.opacity_logits[i]);
    Some(Forward {
        t,
        ratio,
        clamped,
        q_unit,
        q_norm,
        rot,
        scale,
        sigma,
        tmat,
        cov,
        det,
        dir,
        dir_norm,
        basis,
        color_raw,
        opacity,
    })
}

/// Projects Gaussian `i`; `None` when it cannot contribute to any pixel.
pub fn project_one<F: Real>(
    g: &GaussianRefs<'_, F>,
    i: usize,
    cam: &CameraF<F>,
    sh_degree: usize,
) -> Option<Projection<F>> {
    let f = forward_one(g, i, cam, sh_degree)?;
    if !(f.det > F::zero()) || !f.opacity.is_finite() {
        return None;
    }
    let inv_det = F::one() / f.det;
    let conic = [f.cov[2] * inv_det, -f.cov[1] * inv_det, f.cov[0] * inv_det];
    let inv_z = F::one() / f.t[2];
    let mean = [
        cam.fx * f.t[0] * inv_z + cam.cx,
        cam.fy * f.t[1] * inv_z + cam.cy,
    ];
    let mid = F::c(0.5) * (f.cov[0] + f.cov[2]);
    let lambda = mid + (mid * mid - f.det).max(F::c(0.1)).sqrt();
    let radius = (F::c(3.0) * lambda.sqrt()).ceil();

    // α = o·exp(−q/2) ≥ 1/255  ⇔  q ≤ 2 ln(255 o): the ellipse's axis-aligned half-extents are
    // sqrt(q_max Σ'_xx), sqrt(q_max Σ'_yy). One pixel of margin absorbs rounding.
    let q_max = F::c(2.0) * (f.opacity / F::c(ALPHA_MIN)).ln();
    if !(q_max > F::zero()) {
        return None;
    }
    let hx = (q_max * f.cov[0]).sqrt() + F::one();
    let hy = (q_max * f.cov[2]).sqrt() + F::one();
    let half = F::c(0.5);
    let span = |center: F, h: F, size: usize| -> Option<[u32; 2]> {
        // Pixel k's centre is k + 0.5.
        let lo = (center - h - half).ceil().max(F::zero());
        let hi = (center + h - half).floor() + F::one();
        let hi = hi.min(F::c(size as f64));
        if !(lo < hi) {
            return None;
        }
        Some([lo.to_f64_lossy() as u32, hi.to_f64_lossy() as u32])
    };
    let cols = span(mean[0], hx, cam.width)?;
    let rows = span(mean[1], hy, cam.height)?;
    let color = [
        f.color_raw[0].max(F::zero()),
        f.color_raw[1].max(F::zero()),
        f.color_raw[2].max(F::zero()),
    ];
    Some(Projection {
        splat: Splat {
            mean,
            conic,
            opacity: f.opacity,
            color,
            depth: f.t[2],
            rows,
            cols,
        },
        radius,
    })
}

/// Gradient of the loss with respect to one splat's blending inputs (pixel-space centre,
/// conic entries `a, b, c` as they appear in `−½(a dx² + c dy²) − b dx dy`, activated opacity,
/// clamped colour, depth).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SplatGrad<F> {
    pub mean: [F; 2],
    pub conic: [F; 3],
    pub opacity: F,
    pub color: [F; 3],
    pub depth: F,
}

impl<F: Real> SplatGrad<F> {
    pub const LEN: usize = 10;

    pub fn from_slice(s: &[F]) -> Self {
        Self {
            mean: [s[0], s[1]],
            conic: [s[2], s[3], s[4]],
            opacity: s[5],
            color: [s[6], s[7], s[8]],
            depth: s[9],
        }
    }
}

/// Gradients of one Gaussian's parameters (pre-activation, as stored).
#[derive(Clone, Copy, Debug, Default)]
pub struct ParamGrad<F> {
    pub mean: [F; 3],
    pub log_scale: [F; 3],
    pub quat: [F; 4],
    pub opacity_logit: F,
}

/// Backward of [`project_one`] for Gaussian `i`: parameter gradients, and the SH gradient
/// written to `sh_grad` (K×3 for this Gaussian).
pub fn project_one_backward<F: Real>(
    g: &GaussianRefs<'_, F>,
    i: usize,
    cam: &CameraF<F>,
    sh_degree: usize,
    dl: &SplatGrad<F>,
    sh_grad: &mut [F],
) -> ParamGrad<F> {
    let mut out = ParamGrad::default();
    let Some(f) = forward_one(g, i, cam, sh_degree) else {
        return out;
    };
    let zero = F::zero();
    let one = F::one();
    let two = F::c(2.0);

    // Opacity: o = σ(ô).
    out.opacity_logit = dl.opacity * f.opacity * (one - f.opacity);

    // Colour: max(0, raw) → SH coefficients and view direction.
    let degree = sh_degree.min(sh_degree_of(g.sh_coeffs));
    let k_used = sh::num_coeffs(degree);
    let mut dcolor = [zero; 3];
    for ch in 0..3 {
        dcolor[ch] = if f.color_raw[ch] < zero {
            zero
        } else {
            dl.color[ch]
        };
    }
    for k in 0..k_used {
        for ch in 0..3 {
            sh_grad[3 * k + ch] = f.basis[k] * dcolor[ch];
        }
    }
    let mut dmean = [zero; 3];
    if degree > 0 {
        let mut basis = [zero; 16];
        let mut dbasis = [[zero; 3]; 16];
        sh::basis(degree, f.dir, &mut basis, Some(&mut dbasis));
        let base = i * g.sh_coeffs * 3;
        let mut ddir = [zero; 3];
        for k in 0..k_used {
            let mut s = zero;
            for ch in 0..3 {
                s = s + dcolor[ch] * g.sh[base + 3 * k + ch];
            }
            for a in 0..3 {
                ddir[a] = ddir[a] + s * dbasis[k][a];
            }
        }
        // d = v/|v|: dL/dv = (ddir − d (d·ddir)) / |v|.
        let dd = f.dir[0] * ddir[0] + f.dir[1] * ddir[1] + f.dir[2] * ddir[2];
        for a in 0..3 {
            dmean[a] = (ddir[a] - f.dir[a] * dd) / f.dir_norm;
        }
    }

    // Screen-space quantities → camera-space point t and the 2D covariance.
    let mut dt = [zero; 3];
    let inv_z = one / f.t[2];
    // mean = (fx x/z + cx, fy y/z + cy)
    dt[0] = dt[0] + dl.mean[0] * cam.fx * inv_z;
    dt[1] = dt[1] + dl.mean[1] * cam.fy * inv_z;
    dt[2] = dt[2] - (dl.mean[0] * cam.fx * f.t[0] + dl.mean[1] * cam.fy * f.t[1]) * inv_z * inv_z;
    dt[2] = dt[2] + dl.depth;

    // conic = (c, −b, a)/det of cov = (a, b, c). With A = [[a,b],[b,c]] and the conic matrix
    // C = A⁻¹: dL/dA = −C G C, where G is dL/dC as a symmetric matrix (off-diagonals carry half
    // of dL/db since b appears twice).
    let det = f.det;
    let conic = [f.cov[2] / det, -f.cov[1] / det, f.cov[0] / det];
    let cm = [[conic[0], conic[1]], [conic[1], conic[2]]];
    let gm = [
        [dl.conic[0], dl.conic[1] * F::c(0.5)],
        [dl.conic[1] * F::c(0.5), dl.conic[2]],
    ];
    let mut cg = [[zero; 2]; 2];
    for r in 0..2 {
        for c in 0..2 {
            cg[r][c] = cm[r][0] * gm[0][c] + cm[r][1] * gm[1][c];
        }
    }
    let mut da = [[zero; 2]; 2];
    for r in 0..2 {
        for c in 0..2 {
            da[r][c] = -(cg[r][0] * cm[0][c] + cg[r][1] * cm[1][c]);
        }
    }
    // Σ' = T Σ Tᵀ (+ const): dL/dΣ = Tᵀ dA T, dL/dT = 2 dA T Σ (dA, Σ symmetric).
    let tm = &f.tmat;
    let mut dsigma = [[zero; 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            let mut s = zero;
            for r in 0..2 {
                for c in 0..2 {
                    s = s + tm[r][a] * da[r][c] * tm[c][b];
                }
            }
            dsigma[a][b] = s;
        }
    }
    let mut dtm = [[zero; 3]; 2];
    for r in 0..2 {
        for c in 0..3 {
            let mut s = zero;
            for k in 0..2 {
                for m in 0..3 {
                    s = s + da[r][k] * tm[k][m] * f.sigma[m][c];
                }
            }
            dtm[r][c] = two * s;
        }
    }
    // T = J W: dL/dJ = dL/dT Wᵀ.
    let w = &cam.rotation;
    let mut dj = [[zero; 3]; 2];
    for r in 0..2 {
        for c in 0..3 {
            dj[r][c] = dtm[r][0] * w[c][0] + dtm[r][1] * w[c][1] + dtm[r][2] * w[c][2];
        }
    }
    // J00 = fx/z, J02 = −fx r_x/z with r_x = x/z (unclamped) or a constant (clamped); same for y.
    let fxy = [cam.fx, cam.fy];
    dt[2] = dt[2] - dj[0][0] * cam.fx * inv_z * inv_z - dj[1][1] * cam.fy * inv_z * inv_z;
    for k in 0..2 {
        let djk2 = dj[k][2];
        if f.clamped[k] {
            // J_k2 = −f r/z with r constant.
            dt[2] = dt[2] + djk2 * fxy[k] * f.ratio[k] * inv_z * inv_z;
        } else {
            // J_k2 = −f t_k / z².
            dt[k] = dt[k] - djk2 * fxy[k] * inv_z * inv_z;
            dt[2] = dt[2] + djk2 * two * fxy[k] * f.t[k] * inv_z * inv_z * inv_z;
        }
    }
    // t = W p + t₀: dL/dp = Wᵀ dL/dt.
    for a in 0..3 {
        dmean[a] = dmean[a] + w[0][a] * dt[0] + w[1][a] * dt[1] + w[2][a] * dt[2];
    }
    out.mean = dmean;

    // Σ = M Mᵀ, M = R S: dL/dM = 2 dL/dΣ M; dL/ds_k = Σ_a R_ak dL/dM_ak; dL/dR = dL/dM S.
    let mut m = [[zero; 3]; 3];
    for a in 0..3 {
        for k in 0..3 {
            m[a][k] = f.rot[a][k] * f.scale[k];
        }
    }
    let sym = |a: usize, b: usize| (dsigma[a][b] + dsigma[b][a]) * F::c(0.5);
    let mut dm = [[zero; 3]; 3];
    for a in 0..3 {
        for k in 0..3 {
            let mut s = zero;
            for b in 0..3 {
                s = s + sym(a, b) * m[b][k];
            }
            dm[a][k] = two * s;
        }
    }
    let mut drot = [[zero; 3]; 3];
    for k in 0..3 {
        let mut ds = zero;
        for a in 0..3 {
            ds = ds + f.rot[a][k] * dm[a][k];
            drot[a][k] = dm[a][k] * f.scale[k];
        }
        // log-scale: ds/dŝ = s.
        out.log_scale[k] = ds * f.scale[k];
    }
    let dq_unit = quat_to_matrix_backward(f.q_unit, &drot);
    // q̂ = q/|q|: dL/dq = (dL/dq̂ − q̂ (q̂·dL/dq̂)) / |q|.
    let proj = f
        .q_unit
        .iter()
        .zip(&dq_unit)
        .fold(zero, |s, (a, b)| s + *a * *b);
    for k in 0..4 {
        out.quat[k] = (dq_unit[k] - f.q_unit[k] * proj) / f.q_norm;
    }
    out
}
