//! What every blend takes and checks: the overlap's weights, the two images and their masks.

use fewview_scene::Image;

use crate::error::{GeomError, Result};

/// The weight `w_f` of image `f` in the overlap (`g` gets `1 − w_f`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Weights<'a> {
    Constant(f32),
    /// One weight per pixel, row-major.
    PerPixel(&'a [f32]),
}

impl Default for Weights<'_> {
    fn default() -> Self {
        Weights::Constant(0.5)
    }
}

impl Weights<'_> {
    #[inline]
    pub(crate) fn at(&self, p: usize) -> f64 {
        match self {
            Weights::Constant(w) => *w as f64,
            Weights::PerPixel(w) => w[p] as f64,
        }
    }

    pub(crate) fn check(&self, w: usize, h: usize) -> Result<()> {
        let bad = |v: f32| !(0.0..=1.0).contains(&v);
        match self {
            Weights::Constant(v) if bad(*v) => Err(GeomError::invalid(
                "weights",
                format!("{v} is not in [0, 1]"),
            )),
            Weights::PerPixel(v) if v.len() != w * h => Err(GeomError::invalid(
                "weights",
                format!("{} values for a {w}×{h} image", v.len()),
            )),
            Weights::PerPixel(v) => match v.iter().position(|x| bad(*x)) {
                Some(i) => Err(GeomError::invalid(
                    "weights",
                    format!("pixel ({}, {}) is {} (not in [0, 1])", i % w, i / w, v[i]),
                )),
                None => Ok(()),
            },
            _ => Ok(()),
        }
    }
}

/// Same size, same channels, finite values; returns `(w, h, channels)`.
pub(crate) fn check_images(f: &Image, g: &Image) -> Result<(usize, usize, usize)> {
    if (f.width, f.height) != (g.width, g.height) {
        return Err(GeomError::invalid(
            "images",
            format!(
                "sizes differ: {}×{} vs {}×{}",
                f.width, f.height, g.width, g.height
            ),
        ));
    }
    if f.channels != g.channels {
        return Err(GeomError::invalid(
            "images",
            format!("channel counts differ: {} vs {}", f.channels, g.channels),
        ));
    }
    if f.width == 0 || f.height == 0 {
        return Err(GeomError::invalid("images", "are empty"));
    }
    for (name, img) in [("first image", f), ("second image", g)] {
        if let Some(i) = img.data.iter().position(|v| !v.is_finite()) {
            let p = i / img.channels;
            return Err(GeomError::invalid(
                name,
                format!("pixel ({}, {}) is not finite", p % img.width, p / img.width),
            ));
        }
    }
    Ok((f.width, f.height, f.channels))
}

/// Right length and not empty.
pub(crate) fn check_mask(mask: &[bool], w: usize, h: usize, name: &str) -> Result<()> {
    if mask.len() != w * h {
        return Err(GeomError::invalid(
            name,
            format!("{} values for a {w}×{h} image", mask.len()),
        ));
    }
    if !mask.iter().any(|&m| m) {
        return Err(GeomError::invalid(name, "is empty (no valid pixel)"));
    }
    Ok(())
}

/// A mask from an image: channel 0 above `threshold` (use 0.5 for 0/255 PNG masks).
pub fn mask_from_image(img: &Image, threshold: f32) -> Vec<bool> {
    img.data
        .chunks_exact(img.channels)
        .map(|p| p[0] > threshold)
        .collect()
}
