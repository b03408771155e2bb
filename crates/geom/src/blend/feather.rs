//! Gaussian feathering: each image weighted by its Gaussian-blurred mask, inside its mask only.

use fewview_scene::Image;

use super::{Weights, check_images, check_mask};
use crate::error::{GeomError, Result};

/// Separable Gaussian blur of a `w × h` plane (mirror boundary), kernel radius `⌈3σ⌉`.
pub fn gaussian_blur(plane: &[f32], w: usize, h: usize, sigma: f32) -> Vec<f32> {
    if sigma <= 0.0 {
        return plane.to_vec();
    }
    let r = (3.0 * sigma).ceil() as isize;
    let mut k: Vec<f32> = (-r..=r)
        .map(|x| (-(x * x) as f32 / (2.0 * sigma * sigma)).exp())
        .collect();
    let s: f32 = k.iter().sum();
    k.iter_mut().for_each(|v| *v /= s);
    let reflect = |x: isize, n: usize| -> usize {
        let n = n as isize;
        let mut x = x;
        loop {
            if x < 0 {
                x = -x - 1;
            } else if x >= n {
                x = 2 * n - x - 1;
            } else {
                return x as usize;
            }
        }
    };
    let mut tmp = vec![0.0; w * h];
    for j in 0..h {
        for i in 0..w {
            tmp[j * w + i] = (-r..=r)
                .map(|d| k[(d + r) as usize] * plane[j * w + reflect(i as isize + d, w)])
                .sum();
        }
    }
    let mut out = vec![0.0; w * h];
    for j in 0..h {
        for i in 0..w {
            out[j * w + i] = (-r..=r)
                .map(|d| k[(d + r) as usize] * tmp[reflect(j as isize + d, h) * w + i])
                .sum();
        }
    }
    out
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
