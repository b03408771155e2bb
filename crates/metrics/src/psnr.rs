//! Peak signal-to-noise ratio on `[0, 1]` images (data range 1):
//! `PSNR = 10 · log10(1 / MSE)`, the MSE taken over every pixel and channel, exactly as
//! scikit-image's `peak_signal_noise_ratio(a, b, data_range=1)` and the 3DGS/NeRF evaluation
//! scripts (`-10 · log10(mse)`). Identical images give `+∞`.

use fewview_scene::Image;

use crate::error::{MetricsError, Result, check_mask, check_same_shape};

/// Mean squared error over all pixels and channels, accumulated in `f64`.
pub fn mse(a: &Image, b: &Image) -> Result<f64> {
    check_same_shape(a, b)?;
    if a.data.is_empty() {
        return Err(MetricsError::invalid("PSNR of an empty image"));
    }
    let sum: f64 = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(&x, &y)| {
            let d = x as f64 - y as f64;
            d * d
        })
        .sum();
    finite_or_err(sum / a.data.len() as f64)
}

/// PSNR in dB with data range 1.
pub fn psnr(a: &Image, b: &Image) -> Result<f64> {
    Ok(psnr_from_mse(mse(a, b)?))
}

/// PSNR over the pixels where `mask > 0.5` (a 1-channel image of the same size): the MSE is the
/// mean over masked pixels × channels, as in the DTU evaluations of sparse-view surface papers.
pub fn psnr_masked(a: &Image, b: &Image, mask: &Image) -> Result<f64> {
    check_same_shape(a, b)?;
    check_mask(mask, a.width, a.height)?;
    let c = a.channels;
    let mut sum = 0.0f64;
    let mut count = 0usize;
    for (p, &m) in mask.data.iter().enumerate() {
        if m > 0.5 {
            for k in 0..c {
                let d = a.data[p * c + k] as f64 - b.data[p * c + k] as f64;
                sum += d * d;
            }
            count += c;
        }
    }
    if count == 0 {
        return Err(MetricsError::invalid("PSNR mask selects no pixel"));
    }
    Ok(psnr_from_mse(finite_or_err(sum / count as f64)?))
}

/// `10 · log10(1 / mse)`; `+∞` for `mse == 0`.
pub fn psnr_from_mse(mse: f64) -> f64 {
    if mse <= 0.0 {
        f64::INFINITY
    } else {
        -10.0 * mse.log10()
    }
}

fn finite_or_err(v: f64) -> Result<f64> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(MetricsError::invalid(
            "image contains NaN or infinite values",
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_values() {
        let a = Image::filled(4, 3, &[0.5, 0.5, 0.5]);
        let b = Image::filled(4, 3, &[0.6, 0.6, 0.6]);
        // MSE = 0.01 (up to f32 rounding of 0.6 − 0.5) → 20 dB.
        assert!((psnr(&a, &b).unwrap() - 20.0).abs() < 1e-5);
        assert_eq!(psnr(&a, &a).unwrap(), f64::INFINITY);
    }

    #[test]
    fn masked_averages_only_masked_pixels() {
        let a = Image::filled(2, 1, &[0.0, 0.0]);
        let mut b = Image::filled(2, 1, &[0.1, 0.1]);
        b.data[2] = 1.0; // second pixel differs a lot but is masked out
        b.data[3] = 1.0;
        let mask = Image::from_vec(2, 1, 1, vec![1.0, 0.0]);
        let v = psnr_masked(&a, &b, &mask).unwrap();
        assert!((v - 20.0).abs() < 1e-5, "{v}");
        let none = Image::from_vec(2, 1, 1, vec![0.0, 0.0]);
        assert!(psnr_masked(&a, &b, &none).is_err());
    }

    #[test]
    fn errors_on_bad_input() {
        let a = Image::filled(4, 3, &[0.5]);
        let b = Image::filled(3, 4, &[0.5]);
        assert!(
            psnr(&a, &b)
                .unwrap_err()
                .to_string()
                .contains("size mismatch")
        );
        let mut c = a.clone();
        c.data[0] = f32::NAN;
        assert!(psnr(&a, &c).is_err());
    }
}
