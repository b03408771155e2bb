//! Gaussian feathering: each image weighted by its Gaussian-blurred mask, inside its mask only.

use fewview_scene::Image;

use super::inputs::{Weights, check_images, check_mask};
use crate::error::{GeomError, Result};

/// Separable Gaussian blur of a `w × h` plane (mirror boundary), kernel radius `⌈3σ⌉`.
pub fn gaussian_blur(plane: &[f32], w: usize, h: usize, sigma: f32) -> Vec<f32> {
    if sigma <= 0.0 {
        return plane.to_vec();
    }
    let (kx, ky) = (AxisKernel::new(sigma, w), AxisKernel::new(sigma, h));
    let mut tmp = vec![0.0; w * h];
    for j in 0..h {
        for i in 0..w {
            tmp[j * w + i] = kx
                .taps()
                .map(|(d, k)| k * plane[j * w + reflect(i as isize + d, w)])
                .sum();
        }
    }
    let mut out = vec![0.0; w * h];
    for j in 0..h {
        for i in 0..w {
            out[j * w + i] = ky
                .taps()
                .map(|(d, k)| k * tmp[reflect(j as isize + d, h) * w + i])
                .sum();
        }
    }
    out
}

/// Mirror (half-sample symmetric) index of `x` in `0..n`. The mirrored signal repeats every
/// `2n` samples, so one remainder replaces bouncing back and forth one width at a time (which
/// took forever for offsets far outside the image).
fn reflect(x: isize, n: usize) -> usize {
    let period = 2 * n as isize;
    let m = x.rem_euclid(period);
    (if m < n as isize { m } else { period - 1 - m }) as usize
}

/// Longest kernel half-width summed, in periods `2n` of the mirrored signal. Past this the
/// Gaussian is flat over each period to within `2n/σ < 0.4 %`, so a longer kernel only adds
/// equal weight to every tap; the cap keeps the work bounded for any σ (σ = 10⁶ or 10³⁰).
const MAX_PERIODS: f64 = 1000.0;

/// The normalised 1-D Gaussian taps of one axis of length `n`, as (offset, weight) pairs.
struct AxisKernel {
    offsets: Vec<isize>,
    weights: Vec<f32>,
}

impl AxisKernel {
    fn new(sigma: f32, n: usize) -> Self {
        let period = 2 * n;
        // In f32 as before the cap, so that ordinary σ give the same kernel to the bit.
        let r = (3.0 * sigma)
            .ceil()
            .min((MAX_PERIODS * period as f64) as f32) as isize;
        if 2 * r < period as isize {
            // The kernel fits in one period of the mirrored signal: the plain kernel.
            let mut k: Vec<f32> = (-r..=r)
                .map(|x| (-(x * x) as f32 / (2.0 * sigma * sigma)).exp())
                .collect();
            let s: f32 = k.iter().sum();
            k.iter_mut().for_each(|v| *v /= s);
            return Self {
                offsets: (-r..=r).collect(),
                weights: k,
            };
        }
        // Wider than the mirrored period: taps `period` apart read the same pixel, so fold them
        // into `period` taps, which keeps the cost at most `2n` per pixel.
        let two_s2 = 2.0 * sigma as f64 * sigma as f64;
        let mut folded = vec![0f64; period];
        for d in -r..=r {
            let x = d as f64;
            folded[d.rem_euclid(period as isize) as usize] += (-x * x / two_s2).exp();
        }
        let s: f64 = folded.iter().sum();
        Self {
            offsets: (0..period as isize).collect(),
            weights: folded.iter().map(|v| (v / s) as f32).collect(),
        }
    }

    fn taps(&self) -> impl Iterator<Item = (isize, f32)> + '_ {
        self.offsets
            .iter()
            .copied()
            .zip(self.weights.iter().copied())
    }
}

/// Gaussian feathering: weights `W_f = w_f · (G_σ * 1_{Ω_f}) · 1_{Ω_f}` and likewise for `g`,
/// result `(W_f f + W_g g)/(W_f + W_g)`. A pixel valid in one image only gets that image
/// exactly; across the overlap the weights ramp over about σ pixels.
pub fn gaussian_feather_blend(
    f: &Image,
    g: &Image,
    mask_f: &[bool],
    mask_g: &[bool],
    sigma: f32,
    weights: Weights,
) -> Result<Image> {
    let (w, h, ch) = check_images(f, g)?;
    check_mask(mask_f, w, h, "mask of f")?;
    check_mask(mask_g, w, h, "mask of g")?;
    weights.check(w, h)?;
    if !(sigma.is_finite() && sigma >= 0.0) {
        return Err(GeomError::invalid("sigma", format!("{sigma} must be ≥ 0")));
    }
    let to_plane = |m: &[bool]| -> Vec<f32> { m.iter().map(|&b| b as u8 as f32).collect() };
    let bf = gaussian_blur(&to_plane(mask_f), w, h, sigma);
    let bg = gaussian_blur(&to_plane(mask_g), w, h, sigma);
    let mut out = Image::new(w, h, ch);
    for p in 0..w * h {
        let wf = if mask_f[p] {
            bf[p] * weights.at(p) as f32
        } else {
            0.0
        };
        let wg = if mask_g[p] {
            bg[p] * (1.0 - weights.at(p) as f32)
        } else {
            0.0
        };
        let (wf, wg) = match (mask_f[p], mask_g[p]) {
            (true, false) => (1.0, 0.0),
            (false, true) => (0.0, 1.0),
            _ => (wf, wg),
        };
        let sum = wf + wg;
        if sum > 0.0 {
            for c in 0..ch {
                out.data[p * ch + c] = (wf * f.data[p * ch + c] + wg * g.data[p * ch + c]) / sum;
            }
        }
    }
    Ok(out)
}
