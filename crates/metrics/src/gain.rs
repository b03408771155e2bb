//! Scoring a render against a photo whose exposure and white balance the method cannot know:
//! a least-squares gain per channel first, then the usual metrics.
//!
//! Evaluations of in-the-wild captures fit the render's colours to the held-out photo before
//! scoring (NeRF in the Wild optimises an appearance code on half of each test image; gain or
//! affine colour fits are the cheap form of the same idea). Here the fit is the narrowest one
//! that undoes exposure and white balance: one gain per channel, `g_c = Σ r·p / Σ r²` over the
//! scored pixels (render `r`, photo `p`), the render multiplied by it and clipped to `[0, 1]`.
//! Tables say "gain-matched" beside every figure taken this way.

use fewview_scene::Image;

use crate::error::{MetricsError, Result, check_mask, check_same_shape};

/// Per-channel least-squares gains that bring `render` closest to `photo` over the pixels where
/// `mask > 0.5` (all pixels without a mask). A channel that is black in the render keeps gain 1.
pub fn gain_fit(render: &Image, photo: &Image, mask: Option<&Image>) -> Result<Vec<f64>> {
    check_same_shape(render, photo)?;
    if let Some(m) = mask {
        check_mask(m, render.width, render.height)?;
    }
    let c = render.channels;
    let (mut rp, mut rr) = (vec![0.0f64; c], vec![0.0f64; c]);
    for p in 0..render.num_pixels() {
        if mask.is_some_and(|m| m.data[p] <= 0.5) {
            continue;
        }
        for k in 0..c {
            let (r, t) = (render.data[p * c + k] as f64, photo.data[p * c + k] as f64);
            rp[k] += r * t;
            rr[k] += r * r;
        }
    }
    let gains: Vec<f64> = (0..c)
        .map(|k| if rr[k] > 0.0 { rp[k] / rr[k] } else { 1.0 })
        .collect();
    if gains.iter().all(|g| g.is_finite()) {
        Ok(gains)
    } else {
        Err(MetricsError::invalid(
            "image contains NaN or infinite values",
        ))
    }
}

/// `render` with the gains of [`gain_fit`] applied and clipped to `[0, 1]`.
pub fn gain_matched(render: &Image, photo: &Image, mask: Option<&Image>) -> Result<Image> {
    Ok(with_gains(render, &gain_fit(render, photo, mask)?))
}

/// `image` with channel `c` multiplied by `gains[c]`, clipped to `[0, 1]`.
fn with_gains(image: &Image, gains: &[f64]) -> Image {
    let mut out = image.clone();
    for (i, v) in out.data.iter_mut().enumerate() {
        *v = (*v as f64 * gains[i % image.channels]).clamp(0.0, 1.0) as f32;
    }
    out
}

/// Every frame of `frames` multiplied by one set of per-channel gains, fitted by least squares
/// over the whole sequence against `truth`, and clipped to `[0, 1]`. One fit for the clip removes
/// a model's overall colour offset and keeps what changes along it (a transition's exposure
/// ramp); a fit per frame would remove that too.
pub fn sequence_gain_matched(frames: &[Image], truth: &[Image]) -> Result<Vec<Image>> {
    if frames.len() != truth.len() || frames.is_empty() {
        return Err(MetricsError::ShapeMismatch(format!(
            "{} frames against {} true frames (need the same number, at least one)",
            frames.len(),
            truth.len()
        )));
    }
    let stack = |images: &[Image]| -> Result<Image> {
        let first = &images[0];
        let mut out = Image::new(first.width, first.height * images.len(), first.channels);
        for (i, im) in images.iter().enumerate() {
            check_same_shape(first, im)?;
            let n = im.data.len();
            out.data[i * n..(i + 1) * n].copy_from_slice(&im.data);
        }
        Ok(out)
    };
    let gains = gain_fit(&stack(frames)?, &stack(truth)?, None)?;
    Ok(frames.iter().map(|f| with_gains(f, &gains)).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::psnr::{psnr, psnr_masked};

    /// A textured photo and the same photo under another exposure and white balance.
    fn photo_and_render() -> (Image, Image) {
        let (w, h) = (16, 12);
        let mut photo = Image::new(w, h, 3);
        let mut render = Image::new(w, h, 3);
        let gains = [1.25f32, 0.8, 1.1];
        for y in 0..h {
            for x in 0..w {
                for (c, gain) in gains.iter().enumerate() {
                    let v = 0.1 + 0.7 * ((x * 7 + y * 3 + c * 5) % 11) as f32 / 11.0;
                    photo.set(x, y, c, v);
                    render.set(x, y, c, v / gain);
                }
            }
        }
        (photo, render)
    }

    #[test]
    fn the_fit_undoes_a_per_channel_gain() {
        let (photo, render) = photo_and_render();
        let g = gain_fit(&render, &photo, None).unwrap();
        for (got, want) in g.iter().zip([1.25, 0.8, 1.1]) {
            assert!((got - want).abs() < 1e-6, "{g:?}");
        }
        assert!(psnr(&render, &photo).unwrap() < 25.0);
        let matched = gain_matched(&render, &photo, None).unwrap();
        assert!(psnr(&matched, &photo).unwrap() > 100.0);
    }

    #[test]
    fn the_fit_is_least_squares_over_the_mask_only() {
        let (photo, mut render) = photo_and_render();
        // Pixels outside the mask are wrong; the fit must ignore them.
        let mut mask = Image::filled(16, 12, &[1.0]);
        for x in 0..16 {
            mask.set(x, 0, 0, 0.0);
            for c in 0..3 {
                render.set(x, 0, c, 0.9);
            }
        }
        let matched = gain_matched(&render, &photo, Some(&mask)).unwrap();
        assert!(psnr_masked(&matched, &photo, &mask).unwrap() > 100.0);
        // Against a naive reference: g = argmin Σ (g·r − p)² by a fine scan.
        let g = gain_fit(&render, &photo, None).unwrap()[0];
        let cost = |g: f64| -> f64 {
            (0..16 * 12)
                .map(|p| (g * render.data[p * 3] as f64 - photo.data[p * 3] as f64).powi(2))
                .sum()
        };
        let best = (0..20_000)
            .map(|i| 0.5 + i as f64 * 1e-4)
            .min_by(|a, b| cost(*a).total_cmp(&cost(*b)))
            .unwrap();
        assert!((g - best).abs() < 1e-4, "{g} vs scan {best}");
    }

    #[test]
    fn black_channels_keep_gain_one_and_shapes_are_checked() {
        let render = Image::filled(3, 2, &[0.0, 0.5, 0.5]);
        let photo = Image::filled(3, 2, &[0.2, 0.25, 0.5]);
        assert_eq!(
            gain_fit(&render, &photo, None).unwrap(),
            vec![1.0, 0.5, 1.0]
        );
        assert!(gain_fit(&render, &Image::filled(2, 3, &[0.0, 0.0, 0.0]), None).is_err());
    }

    #[test]
    fn one_gain_for_a_sequence_keeps_its_ramp() {
        // Truth: a texture brightening along the clip; render: the same ramp at 0.8 of the
        // exposure. One gain for the clip restores every frame; the ramp survives.
        let (photo, _) = photo_and_render();
        let scaled = |im: &Image, g: f32| {
            let mut out = im.clone();
            out.data.iter_mut().for_each(|v| *v *= g);
            out
        };
        let truth: Vec<Image> = (0..4)
            .map(|t| scaled(&photo, 0.8 + 0.05 * t as f32))
            .collect();
        let frames: Vec<Image> = truth.iter().map(|im| scaled(im, 0.8)).collect();
        let matched = sequence_gain_matched(&frames, &truth).unwrap();
        for (m, t) in matched.iter().zip(&truth) {
            assert!(psnr(m, t).unwrap() > 90.0);
        }
        // A render that lacks the ramp keeps its error: one gain cannot make it up.
        let flat: Vec<Image> = (0..4).map(|_| scaled(&photo, 0.7)).collect();
        let matched = sequence_gain_matched(&flat, &truth).unwrap();
        assert!(psnr(&matched[0], &truth[0]).unwrap() < 40.0);
        assert!(sequence_gain_matched(&frames[..2], &truth).is_err());
    }
}
