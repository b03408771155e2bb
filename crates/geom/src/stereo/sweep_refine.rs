//! Sub-plane refinement of a plane sweep's depths: the sweep's counterpart of
//! [`super::refine`] (Lucas–Kanade along rectified rows), here along the epipolar line of each
//! reference pixel in the source image.
//!
//! The window around a reference pixel is taken to lie on a plane whose inverse depth varies
//! linearly across the window, `ρ(i, j) = ρ + ρₓ·i + ρᵧ·j` (every 3D plane is linear in
//! inverse depth over the image), and Gauss–Newton fits `(ρ, ρₓ, ρᵧ, gain, bias)` to
//! `Σ_window (source(q(p, ρ(i, j))) − (gain·reference(p) + bias))²`, where `q` is the source
//! pixel of reference pixel `p` at inverse depth `ρ`. As in the rectified refinement, a value is
//! kept only where the window has texture along its epipolar lines, the fitted plane explains
//! the window (`1 − SSR/SST ≥ min_fit`) and the refined point stays within a pixel of the
//! sweep's in the source image.

use nalgebra::{SMatrix, SVector, Vector3};
use rayon::prelude::*;

use super::refine::RefineOptions;

/// A refinement step that moves the source point less than this (pixels) ends the iterations.
const CONVERGED_PX: f64 = 0.02;

/// A grey image with its gradients, sampled bilinearly (pixel centres at half-integers).
pub(super) struct Textured {
    pub width: usize,
    pub height: usize,
    values: Vec<f32>,
    dx: Vec<f32>,
    dy: Vec<f32>,
}

impl Textured {
    /// `values` (row-major, `width × height`) with central-difference gradients.
    pub fn new(values: Vec<f32>, width: usize, height: usize) -> Self {
        let at = |x: usize, y: usize| values[y * width + x];
        let mut dx = vec![0.0f32; width * height];
        let mut dy = vec![0.0f32; width * height];
        for y in 0..height {
            for x in 0..width {
                let (a, b) = (x.saturating_sub(1), (x + 1).min(width - 1));
                if b > a {
                    dx[y * width + x] = (at(b, y) - at(a, y)) / (b - a) as f32;
                }
                let (a, b) = (y.saturating_sub(1), (y + 1).min(height - 1));
                if b > a {
                    dy[y * width + x] = (at(x, b) - at(x, a)) / (b - a) as f32;
                }
            }
        }
        Self {
            width,
            height,
            values,
            dx,
            dy,
        }
    }

    /// Value and gradient at `(u, v)`; `None` outside the image.
    fn sample(&self, u: f64, v: f64) -> Option<[f64; 3]> {
        let (x, y) = (u - 0.5, v - 0.5);
        if !(x >= 0.0 && y >= 0.0) {
            return None;
        }
        let (x0, y0) = (x as usize, y as usize);
        if x0 + 1 >= self.width || y0 + 1 >= self.height {
            return None;
        }
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let i = y0 * self.width + x0;
        let bilinear = |m: &[f32]| {
            let (a, b) = (m[i] as f64, m[i + 1] as f64);
            let (c, d) = (m[i + self.width] as f64, m[i + self.width + 1] as f64);
            let top = a + fx * (b - a);
            top + fy * (c + fx * (d - c) - top)
        };
        Some([
            bilinear(&self.values),
            bilinear(&self.dx),
            bilinear(&self.dy),
        ])
    }

    pub fn value(&self, x: usize, y: usize) -> f64 {
        self.values[y * self.width + x] as f64
    }
}

/// How a reference pixel maps into the source: `q = ray + ρ·shift` (homogeneous).
pub(super) struct Rays<'a> {
    /// Per reference pixel, `K_s R K_r⁻¹ p`.
    pub rays: &'a [Vector3<f64>],
    /// `K_s t`.
    pub shift: Vector3<f64>,
}

impl Rays<'_> {
    /// The source pixel of reference pixel `i` at inverse depth `rho`, and its derivative in
    /// `rho`; `None` behind the source camera.
    fn project(&self, i: usize, rho: f64) -> Option<([f64; 2], [f64; 2])> {
        let q = self.rays[i] + self.shift * rho;
        if q.z <= 1e-9 {
            return None;
        }
        let b = &self.shift;
        let z2 = q.z * q.z;
        Some((
            [q.x / q.z, q.y / q.z],
            [(b.x * q.z - q.x * b.z) / z2, (b.y * q.z - q.y * b.z) / z2],
        ))
    }
}

/// Refines the inverse depth `rho` of every pixel of the reference (`reference`, row-major;
/// non-finite where there is none) against `source`; returns which pixels were refined.
pub(super) fn refine_inverse_depths(
    reference: &Textured,
    source: &Textured,
    rays: &Rays,
    rho: &mut [f64],
    options: &RefineOptions,
) -> Vec<bool> {
    let w = reference.width;
    let mut refined = vec![false; rho.len()];
    rho.par_chunks_mut(w)
        .zip(refined.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (row, done))| {
            for (x, value) in row.iter_mut().enumerate() {
                if !value.is_finite() {
                    continue;
                }
                if let Some(r) = refine_pixel(reference, source, rays, (x, y), *value, options) {
                    *value = r;
                    done[x] = true;
                }
            }
        });
    refined
}

/// Gauss–Newton on `(ρ, ρₓ, ρᵧ, gain, bias)` for the window around `(x, y)`.
fn refine_pixel(
    reference: &Textured,
    source: &Textured,
    rays: &Rays,
    (x, y): (usize, usize),
    rho0: f64,
    o: &RefineOptions,
) -> Option<f64> {
    let r = o.radius as i64;
    let (w, h) = (reference.width as i64, reference.height as i64);
    let (xi, yi) = (x as i64, y as i64);
    if xi < r || yi < r || xi + r >= w || yi + r >= h {
        return None;
    }
    let centre = y * reference.width + x;
    let (start, _) = rays.project(centre, rho0)?;
    let n = ((2 * r + 1) * (2 * r + 1)) as f64;
    let mut theta = SVector::<f64, 5>::new(rho0, 0.0, 0.0, 1.0, 0.0);
    for _ in 0..o.iterations {
        let fit = window_fit(reference, source, rays, (xi, yi, r), &theta)?;
        if fit.gradient_energy / n < o.min_gradient {
            return None;
        }
        let step = fit.normal.try_inverse()? * fit.rhs;
        let before = rays.project(centre, theta[0])?.0;
        theta -= step;
        let (now, _) = rays.project(centre, theta[0])?;
        if !theta[0].is_finite() || (now[0] - start[0]).hypot(now[1] - start[1]) > 1.0 {
            return None;
        }
        if (now[0] - before[0]).hypot(now[1] - before[1]) < CONVERGED_PX {
            let explained = fit.residual_energy <= (1.0 - o.min_fit) * fit.variance_energy;
            return (explained && theta[0] > 0.0).then_some(theta[0]);
        }
    }
    None
}

/// Normal equations of one window and its fit statistics.
struct Fit {
    normal: SMatrix<f64, 5, 5>,
    rhs: SVector<f64, 5>,
    /// `Σ (∂source/∂ρ)²` scaled to pixels: the texture along the epipolar lines.
    gradient_energy: f64,
    residual_energy: f64,
    variance_energy: f64,
}

fn window_fit(
    reference: &Textured,
    source: &Textured,
    rays: &Rays,
    (x, y, r): (i64, i64, i64),
    theta: &SVector<f64, 5>,
) -> Option<Fit> {
    let w = reference.width as i64;
    let mut normal = SMatrix::<f64, 5, 5>::zeros();
    let mut rhs = SVector::<f64, 5>::zeros();
    let (mut gradient_energy, mut residual_energy, mut sum, mut sum2) = (0.0, 0.0, 0.0, 0.0);
    for j in -r..=r {
        for i in -r..=r {
            let p = ((y + j) * w + x + i) as usize;
            let rho = theta[0] + theta[1] * i as f64 + theta[2] * j as f64;
            let ([u, v], [du, dv]) = rays.project(p, rho)?;
            let [s, sx, sy] = source.sample(u, v)?;
            let along = sx * du + sy * dv;
            let reference_value = reference.value((x + i) as usize, (y + j) as usize);
            let residual = s - (theta[3] * reference_value + theta[4]);
            let jac = SVector::<f64, 5>::from([
                along,
                along * i as f64,
                along * j as f64,
                -reference_value,
                -1.0,
            ]);
            normal += jac * jac.transpose();
            rhs += jac * residual;
            // The texture a one-pixel move along the epipolar line meets.
            let length = du.hypot(dv);
            if length > 0.0 {
                gradient_energy += (along / length).powi(2);
            }
            residual_energy += residual * residual;
            sum += s;
            sum2 += s * s;
        }
    }
    let n = ((2 * r + 1) * (2 * r + 1)) as f64;
    Some(Fit {
        normal,
        rhs,
        gradient_energy,
        residual_energy,
        variance_energy: sum2 - sum * sum / n,
    })
}
