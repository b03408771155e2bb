//! Real spherical harmonics up to degree 3, in the sign convention and coefficient order of the
//! Inria 3DGS code (`eval_sh`), so trained PLY files mean the same colours in every viewer.
//!
//! Colour for view direction `d` (unit, from the camera centre to the Gaussian) is
//! `c = Σ_k Y_k(d) · sh_k + 0.5`, clamped at 0 by the renderer.

use crate::real::Real;

/// `Y_0`, the DC constant. A colour `c` corresponds to `f_dc = (c − 0.5) / SH_C0`.
pub const SH_C0: f64 = 0.282_094_791_773_878_14;
const SH_C1: f64 = 0.488_602_511_902_919_9;
const SH_C2: [f64; 5] = [
    1.092_548_430_592_079_2,
    -1.092_548_430_592_079_2,
    0.315_391_565_252_520_05,
    -1.092_548_430_592_079_2,
    0.546_274_215_296_039_6,
];
const SH_C3: [f64; 7] = [
    -0.590_043_589_926_643_5,
    2.890_611_442_640_554,
    -0.457_045_799_464_465_8,
    0.373_176_332_590_115_4,
    -0.457_045_799_464_465_8,
    1.445_305_721_320_277,
    -0.590_043_589_926_643_5,
];

/// Number of coefficients per colour channel for a degree: `(d + 1)²`.
pub const fn num_coeffs(degree: usize) -> usize {
    (degree + 1) * (degree + 1)
}

/// The basis values `Y_k(d)` for `k < num_coeffs(degree)` written to `out` (rest untouched), and
/// optionally their derivatives with respect to the (not necessarily unit) direction components
/// `∂Y_k/∂d_x, ∂Y_k/∂d_y, ∂Y_k/∂d_z` treating `d` as given (normalisation is the caller's).
#[inline]
pub fn basis<F: Real>(
    degree: usize,
    d: [F; 3],
    out: &mut [F; 16],
    grad: Option<&mut [[F; 3]; 16]>,
) {
    let c = F::c;
    let [x, y, z] = d;
    out[0] = c(SH_C0);
    let mut g = grad;
    if let Some(g) = g.as_deref_mut() {
        g[0] = [F::zero(); 3];
    }
    if degree == 0 {
        return;
    }
    let c1 = c(SH_C1);
    out[1] = -c1 * y;
    out[2] = c1 * z;
    out[3] = -c1 * x;
    if let Some(g) = g.as_deref_mut() {
        let zero = F::zero();
        g[1] = [zero, -c1, zero];
        g[2] = [zero, zero, c1];
        g[3] = [-c1, zero, zero];
    }
    if degree == 1 {
        return;
    }
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xy, yz, xz) = (x * y, y * z, x * z);
    let two = c(2.0);
    out[4] = c(SH_C2[0]) * xy;
    out[5] = c(SH_C2[1]) * yz;
    out[6] = c(SH_C2[2]) * (two * zz - xx - yy);
    out[7] = c(SH_C2[3]) * xz;
    out[8] = c(SH_C2[4]) * (xx - yy);
    if let Some(g) = g.as_deref_mut() {
        let zero = F::zero();
        g[4] = [c(SH_C2[0]) * y, c(SH_C2[0]) * x, zero];
        g[5] = [zero, c(SH_C2[1]) * z, c(SH_C2[1]) * y];
        g[6] = [
            -two * c(SH_C2[2]) * x,
            -two * c(SH_C2[2]) * y,
            c(4.0) * c(SH_C2[2]) * z,
        ];
        g[7] = [c(SH_C2[3]) * z, zero, c(SH_C2[3]) * x];
        g[8] = [two * c(SH_C2[4]) * x, -two * c(SH_C2[4]) * y, zero];
    }
    if degree == 2 {
        return;
    }
    let three = c(3.0);
    let four = c(4.0);
    out[9] = c(SH_C3[0]) * y * (three * xx - yy);
    out[10] = c(SH_C3[1]) * xy * z;
    out[11] = c(SH_C3[2]) * y * (four * zz - xx - yy);
    out[12] = c(SH_C3[3]) * z * (two * zz - three * xx - three * yy);
    out[13] = c(SH_C3[4]) * x * (four * zz - xx - yy);
    out[14] = c(SH_C3[5]) * z * (xx - yy);
    out[15] = c(SH_C3[6]) * x * (xx - three * yy);
    if let Some(g) = g {
        let zero = F::zero();
        let k = |i: usize| c(SH_C3[i]);
        g[9] = [k(0) * c(6.0) * xy, k(0) * (three * xx - three * yy), zero];
        g[10] = [k(1) * yz, k(1) * xz, k(1) * xy];
        g[11] = [
            -two * k(2) * xy,
            k(2) * (four * zz - xx - three * yy),
            c(8.0) * k(2) * yz,
        ];
        g[12] = [
            -c(6.0) * k(3) * xz,
            -c(6.0) * k(3) * yz,
            k(3) * (c(6.0) * zz - three * xx - three * yy),
        ];
        g[13] = [
            k(4) * (four * zz - three * xx - yy),
            -two * k(4) * xy,
            c(8.0) * k(4) * xz,
        ];
        g[14] = [two * k(5) * xz, -two * k(5) * yz, k(5) * (xx - yy)];
        g[15] = [k(6) * (three * xx - three * yy), -c(6.0) * k(6) * xy, zero];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basis_gradient_matches_finite_differences() {
        let d = [0.3f64, -0.5, 0.81];
        let mut y = [0.0; 16];
        let mut g = [[0.0; 3]; 16];
        basis(3, d, &mut y, Some(&mut g));
        let h = 1e-6;
        for axis in 0..3 {
            let mut dp = d;
            let mut dm = d;
            dp[axis] += h;
            dm[axis] -= h;
            let (mut yp, mut ym) = ([0.0; 16], [0.0; 16]);
            basis(3, dp, &mut yp, None);
            basis(3, dm, &mut ym, None);
            for k in 0..16 {
                let fd = (yp[k] - ym[k]) / (2.0 * h);
                assert!(
                    (fd - g[k][axis]).abs() < 1e-8,
                    "k={k} axis={axis}: {fd} vs {}",
                    g[k][axis]
                );
            }
        }
    }

    #[test]
    fn basis_is_orthonormal_on_the_sphere() {
        // Monte-Carlo-free check: a fine quadrature over the sphere of Y_i Y_j ≈ δ_ij.
        let (nt, np) = (200, 400);
        let mut gram = [[0.0f64; 16]; 16];
        for it in 0..nt {
            let theta = (it as f64 + 0.5) / nt as f64 * std::f64::consts::PI;
            for ip in 0..np {
                let phi = (ip as f64 + 0.5) / np as f64 * 2.0 * std::f64::consts::PI;
                let d = [
                    theta.sin() * phi.cos(),
                    theta.sin() * phi.sin(),
                    theta.cos(),
                ];
                let mut y = [0.0; 16];
                basis(3, d, &mut y, None);
                let w = theta.sin()
                    * (std::f64::consts::PI / nt as f64)
                    * (2.0 * std::f64::consts::PI / np as f64);
                for i in 0..16 {
                    for j in 0..16 {
                        gram[i][j] += w * y[i] * y[j];
                    }
                }
            }
        }
        for (i, row) in gram.iter().enumerate() {
            for (j, g) in row.iter().enumerate() {
                let expect = if i == j { 1.0 } else { 0.0 };
                assert!((g - expect).abs() < 2e-4, "({i},{j}) = {g}");
            }
        }
    }
}
