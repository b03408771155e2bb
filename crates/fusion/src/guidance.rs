//! The guidance field of the gradient-domain fusion (the fusion paper, "Splat-based Gradient-domain
//! Fusion for Seamless View Transition", Eq. 3's `w`), built from the two reprojected neighbours
//! of a virtual view.
//!
//! Gradients are forward differences per channel, `∇ₓf(x, y) = f(x+1, y) − f(x, y)`, taken only
//! where both pixels lie inside the image's mask, so no difference crosses an occlusion or the
//! mask's border. Where both references have a gradient, `w = (1 − t)·∇f* + t·∇g*` (the nearer
//! view weighs more); where one has, `w` is that one's; where neither has, there is no guidance.

use fewview_metrics::gain::gain_fit;
use fewview_scene::Image;

use crate::reproject::Reference;

/// A guidance field over a `width × height` image with 3 channels: the x differences live on
/// the `(width − 1) × height` grid, the y differences on `width × (height − 1)`, each with a
/// 0/1 weight saying where `w` is defined.
#[derive(Clone, Debug, PartialEq)]
pub struct GuidanceField {
    pub width: usize,
    pub height: usize,
    /// `[H, W − 1, 3]`, row-major.
    pub x: Vec<f32>,
    /// `[H, W − 1]`, 1 where `x` is defined.
    pub x_valid: Vec<f32>,
    /// `[H − 1, W, 3]`, row-major.
    pub y: Vec<f32>,
    /// `[H − 1, W]`, 1 where `y` is defined.
    pub y_valid: Vec<f32>,
}

impl GuidanceField {
    /// Number of positions (x and y) where the field is defined.
    pub fn defined(&self) -> usize {
        let count = |v: &[f32]| v.iter().filter(|&&m| m > 0.0).count();
        count(&self.x_valid) + count(&self.y_valid)
    }
}

/// One direction's forward differences of a reference: the difference and whether both pixels
/// are inside its mask.
fn difference(r: &Reference, p: usize, q: usize, c: usize) -> Option<f32> {
    (r.valid[p] && r.valid[q]).then(|| r.image[q * 3 + c] - r.image[p * 3 + c])
}

/// `w` at one position from the two references' differences (see the module docs).
fn blend(f: Option<f32>, g: Option<f32>, t: f32) -> Option<f32> {
    match (f, g) {
        (Some(a), Some(b)) => Some((1.0 - t) * a + t * b),
        (Some(a), None) => Some(a),
        (None, Some(b)) => Some(b),
        (None, None) => None,
    }
}

/// The guidance field of a virtual view `t` of the way from reference `f` to reference `g`
/// (both `width × height`, 3 channels).
pub fn guidance_field(f: &Reference, g: &Reference, t: f32) -> GuidanceField {
    let (w, h) = (f.width, f.height);
    let mut field = GuidanceField {
        width: w,
        height: h,
        x: vec![0.0; h * w.saturating_sub(1) * 3],
        x_valid: vec![0.0; h * w.saturating_sub(1)],
        y: vec![0.0; h.saturating_sub(1) * w * 3],
        y_valid: vec![0.0; h.saturating_sub(1) * w],
    };
    for y in 0..h {
        for x in 0..w {
            let p = y * w + x;
            let set = |values: &mut [f32], valid: &mut [f32], slot: usize, q: usize| {
                for c in 0..3 {
                    if let Some(v) = blend(difference(f, p, q, c), difference(g, p, q, c), t) {
                        values[slot * 3 + c] = v;
                        valid[slot] = 1.0;
                    }
                }
            };
            if x + 1 < w {
                set(&mut field.x, &mut field.x_valid, y * (w - 1) + x, p + 1);
            }
            if y + 1 < h {
                set(&mut field.y, &mut field.y_valid, p, p + w);
            }
        }
    }
    field
}

/// The fewest pixels both references must share for [`exposure_ratio`] to trust its estimate.
pub const MIN_SHARED_FRACTION: f64 = 0.01;

/// Per-channel gain `r` with `g* ≈ r·f*` on the pixels both references show (the least-squares
/// gain of [`gain_fit`], `Σ f·g / Σ f²`): how much brighter the second photo is than the first
/// where they see the same surface. 1 where they share less than [`MIN_SHARED_FRACTION`] of the
/// image or the estimate leaves `[1/4, 4]`.
pub fn exposure_ratio(f: &Reference, g: &Reference) -> [f32; 3] {
    let both: Vec<f32> = f
        .valid
        .iter()
        .zip(&g.valid)
        .map(|(&a, &b)| f32::from(u8::from(a && b)))
        .collect();
    let shared = both.iter().filter(|&&m| m > 0.0).count();
    if (shared as f64) < MIN_SHARED_FRACTION * f.valid.len() as f64 {
        return [1.0; 3];
    }
    let image = |r: &Reference| Image {
        width: r.width,
        height: r.height,
        channels: 3,
        data: r.image.clone(),
    };
    let mask = Image {
        width: f.width,
        height: f.height,
        channels: 1,
        data: both,
    };
    let Ok(gains) = gain_fit(&image(f), &image(g), Some(&mask)) else {
        return [1.0; 3];
    };
    std::array::from_fn(|c| {
        let r = gains[c];
        if (0.25..=4.0).contains(&r) {
            r as f32
        } else {
            1.0
        }
    })
}

/// The two references brought to one exposure: the gain `t` of the way from the first photo's
/// to the second's, log-linearly (`f*·r^t` and `g*·r^(t−1)`, `r` from [`exposure_ratio`]), the
/// natural colour transition between two photos whose exposure or white balance differ. Without
/// it the guidance field carries the first photo's gain where only it sees the surface, the
/// second's where only that one does, and their blend where both do.
pub fn exposure_matched(f: &Reference, g: &Reference, t: f32) -> (Reference, Reference) {
    let r = exposure_ratio(f, g);
    let scaled = |reference: &Reference, power: f32| {
        let mut out = reference.clone();
        for (i, v) in out.image.iter_mut().enumerate() {
            *v *= r[i % 3].powf(power);
        }
        out
    };
    (scaled(f, t), scaled(g, t - 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reference(w: usize, h: usize, seed: u32, valid: impl Fn(usize, usize) -> bool) -> Reference {
        let image = (0..w * h * 3)
            .map(|i| ((i as u32 * 2654435761u32.wrapping_add(seed)) % 1000) as f32 / 1000.0)
            .collect();
        let valid = (0..w * h).map(|p| valid(p % w, p / w)).collect();
        Reference {
            width: w,
            height: h,
            image,
            valid,
        }
    }

    #[test]
    fn with_one_valid_mask_the_field_is_that_images_gradient() {
        let (w, h) = (9, 7);
        let f = reference(w, h, 1, |x, _| x < 5);
        let g = reference(w, h, 2, |_, _| false);
        let field = guidance_field(&f, &g, 0.3);
        for y in 0..h {
            for x in 0..w - 1 {
                let slot = y * (w - 1) + x;
                let inside = x + 1 < 5;
                assert_eq!(field.x_valid[slot], if inside { 1.0 } else { 0.0 });
                for c in 0..3 {
                    let want = if inside {
                        f.image[(y * w + x + 1) * 3 + c] - f.image[(y * w + x) * 3 + c]
                    } else {
                        0.0
                    };
                    assert_eq!(field.x[slot * 3 + c], want);
                }
            }
        }
        for p in 0..(h - 1) * w {
            let inside = p % w < 5;
            assert_eq!(field.y_valid[p] > 0.0, inside);
            if inside {
                assert_eq!(field.y[p * 3], f.image[(p + w) * 3] - f.image[p * 3]);
            }
        }
        // The same with the roles swapped: t does not matter where one reference is valid.
        assert_eq!(guidance_field(&g, &f, 0.9), field);
    }

    #[test]
    fn matched_exposures_meet_at_the_interpolated_gain() {
        let (w, h) = (10, 8);
        let f = reference(w, h, 3, |x, _| x < 7);
        // g is f's scene at twice the exposure in red, half in blue, seen on x ≥ 3.
        let gains = [2.0f32, 1.0, 0.5];
        let mut g = f.clone();
        for (i, v) in g.image.iter_mut().enumerate() {
            *v *= gains[i % 3];
        }
        g.valid = (0..w * h).map(|p| p % w >= 3).collect();
        let r = exposure_ratio(&f, &g);
        for (got, want) in r.iter().zip(gains) {
            assert!((got - want).abs() < 1e-5, "{r:?}");
        }
        let t = 0.25;
        let (fm, gm) = exposure_matched(&f, &g, t);
        for i in 0..w * h * 3 {
            // Both carry the log-linear gain 2^(t·log2 r) of f's colours.
            let want = f.image[i] * gains[i % 3].powf(t);
            assert!((fm.image[i] - want).abs() < 1e-5);
            assert!((gm.image[i] - want).abs() < 1e-5);
        }
        // Too little shared: no correction.
        let mut apart = g.clone();
        apart.valid = (0..w * h).map(|p| p % w >= 7).collect();
        assert_eq!(exposure_ratio(&f, &apart), [1.0; 3]);
    }

    #[test]
    fn where_both_are_valid_the_field_weighs_the_nearer_reference_more() {
        let (w, h) = (6, 5);
        let f = reference(w, h, 1, |_, _| true);
        let g = reference(w, h, 7, |_, y| y >= 2);
        let t = 0.25;
        let field = guidance_field(&f, &g, t);
        // An x difference in row 3: both valid.
        let (x, y) = (2, 3);
        let (p, q) = (y * w + x, y * w + x + 1);
        let df = f.image[q * 3 + 1] - f.image[p * 3 + 1];
        let dg = g.image[q * 3 + 1] - g.image[p * 3 + 1];
        let got = field.x[(y * (w - 1) + x) * 3 + 1];
        assert!((got - ((1.0 - t) * df + t * dg)).abs() < 1e-6);
        // A y difference crossing g's mask border (rows 1 → 2): only f's.
        let p = w + x;
        let got = field.y[p * 3];
        assert!((got - (f.image[(p + w) * 3] - f.image[p * 3])).abs() < 1e-7);
        assert_eq!(field.defined(), h * (w - 1) + (h - 1) * w);
    }
}
