//! Sub-pixel refinement of a disparity map by Lucas–Kanade along the rows of a rectified pair.
//!
//! Semi-Global Matching picks integer disparities and moves them by a parabola through the
//! aggregated costs; its smoothness term and the parabola pull values towards whole pixels and
//! towards fronto-parallel steps, which on a slanted surface 40 px of disparity away is about
//! ±1 % of depth. Each valid disparity `d₀` is refined by Gauss–Newton on
//! `Σ_window (other(x + s·d, y) − (α·ref(x, y) + β))²` over `(d, α, β)` (a window with its own
//! gain and bias, i.e. the sum-of-squares form of zero-mean normalised cross-correlation), on the
//! float images, starting from `d₀`. The refined value replaces `d₀` only when the window has
//! horizontal texture (the normal matrix is well conditioned) and the step stays within one
//! pixel; otherwise `d₀` is kept. This step is ours, not OpenCV's (`--stereo-refine none` skips it).

use fewview_scene::Image;
use nalgebra::{SMatrix, SVector};
use rayon::prelude::*;

/// A disparity step below this (pixels) ends the iterations.
const CONVERGED_PX: f64 = 0.005;

/// Options of the refinement.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RefineOptions {
    /// Half size of the square window (pixels).
    pub radius: usize,
    /// Gauss–Newton iterations at most.
    pub iterations: usize,
    /// Smallest mean squared horizontal gradient (intensity in [0, 1] per pixel) a window needs.
    pub min_gradient: f64,
    /// Smallest share of the window's variance the fitted warp must explain (`1 − SSR/SST`,
    /// the squared correlation): a window that straddles an occlusion cannot be fitted by one
    /// slanted plane.
    pub min_fit: f64,
    /// Drop the disparities that cannot be refined (too little texture, or the refined value
    /// moved more than a pixel) instead of keeping SGM's value.
    pub drop_unrefined: bool,
}

impl Default for RefineOptions {
    fn default() -> Self {
        Self {
            radius: 4,
            iterations: 6,
            min_gradient: 1e-5,
            min_fit: 0.95,
            drop_unrefined: false,
        }
    }
}

/// Grey values of an image (mean of its first three channels).
pub fn grey(image: &Image) -> Vec<f32> {
    let c = image.channels.max(1);
    image
        .data
        .chunks(c)
        .map(|p| p[..c.min(3)].iter().sum::<f32>() / c.min(3) as f32)
        .collect()
}

/// Refines `disparity` (row-major, NaN where invalid) of the `reference` image against `other`:
/// reference pixel `x` matches `other` at `x + direction·d` (`direction` −1 for a left map, +1
/// for a right map). Both images are grey, `width × height`. Returns which pixels were refined.
pub fn refine(
    reference: &[f32],
    other: &[f32],
    width: usize,
    height: usize,
    disparity: &mut [f32],
    direction: f32,
    options: &RefineOptions,
) -> Vec<bool> {
    let gradient = horizontal_gradient(other, width, height);
    let images = Images {
        reference,
        other,
        gradient: &gradient,
        width,
        height,
    };
    let mut refined = vec![false; disparity.len()];
    disparity
        .par_chunks_mut(width)
        .zip(refined.par_chunks_mut(width))
        .enumerate()
        .for_each(|(y, (row, done))| {
            for (x, d) in row.iter_mut().enumerate() {
                if !d.is_finite() {
                    continue;
                }
                match images.refine_pixel(x, y, *d, direction, options) {
                    Some(r) => {
                        *d = r;
                        done[x] = true;
                    }
                    None if options.drop_unrefined => *d = f32::NAN,
                    None => {}
                }
            }
        });
    refined
}

struct Images<'a> {
    reference: &'a [f32],
    other: &'a [f32],
    gradient: &'a [f32],
    width: usize,
    height: usize,
}

/// Central differences along rows (one-sided at the ends).
fn horizontal_gradient(img: &[f32], w: usize, h: usize) -> Vec<f32> {
    let mut g = vec![0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            let (a, b) = (x.saturating_sub(1), (x + 1).min(w - 1));
            if b > a {
                g[y * w + x] = (img[y * w + b] - img[y * w + a]) / (b - a) as f32;
            }
        }
    }
    g
}

impl Images<'_> {
    /// Linear interpolation of `values` along row `y` at continuous column `x` (pixel centres at
    /// integers here); `None` outside the row.
    fn along_row(&self, values: &[f32], x: f64, y: usize) -> Option<f64> {
        if !(0.0..=(self.width - 1) as f64).contains(&x) {
            return None;
        }
        let x0 = (x.floor() as usize).min(self.width - 2);
        let t = x - x0 as f64;
        let row = &values[y * self.width..(y + 1) * self.width];
        Some(row[x0] as f64 * (1.0 - t) + row[x0 + 1] as f64 * t)
    }

    /// Gauss–Newton on `(d, ∂d/∂x, ∂d/∂y, gain, bias)`: the window's disparity varies linearly
    /// across it (a slanted plane), so that a steep surface does not bias the centre.
    fn refine_pixel(&self, x: usize, y: usize, d0: f32, s: f32, o: &RefineOptions) -> Option<f32> {
        let r = o.radius as i64;
        let (x, y) = (x as i64, y as i64);
        if x < r || y < r || x + r >= self.width as i64 || y + r >= self.height as i64 {
            return None;
        }
        let n = ((2 * r + 1) * (2 * r + 1)) as f64;
        let s = s as f64;
        // (d, slope x, slope y, gain, bias)
        let mut theta = SVector::<f64, 5>::new(d0 as f64, 0.0, 0.0, 1.0, 0.0);
        for _ in 0..o.iterations {
            let fit = self.window_fit(x, y, r, s, &theta)?;
            if fit.gradient_energy / n < o.min_gradient {
                return None;
            }
            let step = fit.normal.try_inverse()? * fit.rhs;
            theta -= step;
            if (theta[0] - d0 as f64).abs() > 1.0 || !theta[0].is_finite() {
                return None;
            }
            if step[0].abs() < CONVERGED_PX {
                // Judged on the residual before this last small step, which can only lower it.
                let explained = fit.residual_energy <= (1.0 - o.min_fit) * fit.variance_energy;
                return explained.then_some(theta[0] as f32);
            }
        }
        None
    }

    /// The normal equations of the window at parameters `theta`, and how well it fits.
    fn window_fit(&self, x: i64, y: i64, r: i64, s: f64, theta: &SVector<f64, 5>) -> Option<Fit> {
        // Upper triangle of JᵀJ for J = (s·g, s·g·i, s·g·j, −ref, −1), then Jᵀr.
        let mut m = [0.0f64; 15];
        let mut rhs = [0.0f64; 5];
        let (mut gradient_energy, mut residual_energy, mut sum, mut sum2) = (0.0, 0.0, 0.0, 0.0);
        for j in -r..=r {
            let yj = (y + j) as usize;
            for i in -r..=r {
                let xi = x + i;
                let d = theta[0] + theta[1] * i as f64 + theta[2] * j as f64;
                let xo = xi as f64 + s * d;
                let o_val = self.along_row(self.other, xo, yj)?;
                let g = self.along_row(self.gradient, xo, yj)?;
                let rv = self.reference[yj * self.width + xi as usize] as f64;
                let residual = o_val - (theta[3] * rv + theta[4]);
                let jac = [s * g, s * g * i as f64, s * g * j as f64, -rv, -1.0];
                let mut k = 0;
                for a in 0..5 {
                    for b in a..5 {
                        m[k] += jac[a] * jac[b];
                        k += 1;
                    }
                    rhs[a] += jac[a] * residual;
                }
                gradient_energy += g * g;
                residual_energy += residual * residual;
                sum += o_val;
                sum2 += o_val * o_val;
            }
        }
        let mut normal = SMatrix::<f64, 5, 5>::zeros();
        let mut k = 0;
        for a in 0..5 {
            for b in a..5 {
                normal[(a, b)] = m[k];
                normal[(b, a)] = m[k];
                k += 1;
            }
        }
        let n = ((2 * r + 1) * (2 * r + 1)) as f64;
        Some(Fit {
            normal,
            rhs: SVector::from(rhs),
            gradient_energy,
            residual_energy,
            variance_energy: sum2 - sum * sum / n,
        })
    }
}

/// Normal equations of one window and its fit statistics.
struct Fit {
    normal: SMatrix<f64, 5, 5>,
    rhs: SVector<f64, 5>,
    /// `Σ g²` of the horizontal gradient.
    gradient_energy: f64,
    /// `Σ residual²`.
    residual_energy: f64,
    /// `Σ (other − mean)²`.
    variance_energy: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth texture sampled at `x + shift` (so the pair's true disparity is `shift`).
    fn texture(w: usize, h: usize, shift: f64) -> Vec<f32> {
        let mut out = vec![0f32; w * h];
        for y in 0..h {
            for x in 0..w {
                let u = x as f64 + shift;
                let v = y as f64;
                out[y * w + x] = (0.5
                    + 0.2 * (0.7 * u).sin() * (0.3 * v).cos()
                    + 0.15 * (0.23 * u + 0.4 * v).sin()) as f32;
            }
        }
        out
    }

    #[test]
    fn a_fractional_shift_is_recovered_from_the_nearest_integer() {
        let (w, h) = (64, 24);
        let left = texture(w, h, 0.0);
        // right(x) = left(x + 7.3), i.e. left(x) matches right(x − 7.3); with a gain and bias.
        let right: Vec<f32> = texture(w, h, 7.3).iter().map(|v| 0.8 * v + 0.05).collect();
        let mut disp = vec![7.0f32; w * h];
        let drop = RefineOptions {
            drop_unrefined: true,
            ..Default::default()
        };
        refine(&left, &right, w, h, &mut disp, -1.0, &drop);
        for y in 4..h - 4 {
            for x in 12..w - 4 {
                let d = disp[y * w + x];
                // Linear interpolation of a 9-pixel sinusoid leaves a few hundredths of a pixel.
                assert!((d - 7.3).abs() < 0.05, "({x}, {y}): {d}");
            }
        }
        // A flat window keeps its value, or loses it when unrefined values are dropped.
        let flat = vec![0.5f32; w * h];
        let mut disp = vec![3.0f32; w * h];
        refine(
            &flat,
            &flat,
            w,
            h,
            &mut disp,
            -1.0,
            &RefineOptions::default(),
        );
        assert!(disp.iter().all(|&d| d == 3.0));
        refine(&flat, &flat, w, h, &mut disp, -1.0, &drop);
        assert!(disp.iter().all(|d| d.is_nan()));
    }
}
