//! The regularisers rendered virtual views are trained with: the gradient-domain fusion loss
//! (ours, variant (f)) and the supplement's §4 alternatives that act on a rendered image, total
//! variation (c) and a masked L1 to a pseudo ground truth ((d), (e)). Each takes the rendered
//! `[H, W, 3]` tensor and returns a scalar that back-propagates to the Gaussians.

use burn::tensor::{Tensor, TensorData};

use crate::guidance::GuidanceField;

/// Forward differences of an `[H, W, C]` tensor along x (`[H, W − 1, C]`) and y (`[H − 1, W, C]`).
fn forward_differences(rgb: Tensor<3>) -> (Tensor<3>, Tensor<3>) {
    let [h, w, c] = rgb.dims();
    let dx = rgb.clone().slice([0..h, 1..w, 0..c]) - rgb.clone().slice([0..h, 0..w - 1, 0..c]);
    let dy = rgb.clone().slice([1..h, 0..w, 0..c]) - rgb.slice([0..h - 1, 0..w, 0..c]);
    (dx, dy)
}

/// A host buffer as a constant tensor of `shape` on `like`'s device.
fn constant(values: Vec<f32>, shape: [usize; 3], like: &Tensor<3>) -> Tensor<3> {
    Tensor::from_data(TensorData::new(values, shape), &like.device())
}

/// Per-position 0/1 weights repeated over the 3 channels.
fn per_channel(valid: &[f32]) -> Vec<f32> {
    valid.iter().flat_map(|&m| [m; 3]).collect()
}

/// The gradient-domain fusion loss: the L1 distance between the rendered view's forward
/// differences and the guidance field `w`, averaged over the positions where `w` is defined and
/// the 3 channels. `None` where `w` is defined nowhere (the references do not reach this view).
pub fn gradient_fusion_loss(rgb: Tensor<3>, field: &GuidanceField) -> Option<Tensor<1>> {
    let defined = field.defined();
    let [h, w, _] = rgb.dims();
    if defined == 0 || w < 2 || h < 2 {
        return None;
    }
    let (dx, dy) = forward_differences(rgb.clone());
    let wx = constant(field.x.clone(), [h, w - 1, 3], &rgb);
    let mx = constant(per_channel(&field.x_valid), [h, w - 1, 3], &rgb);
    let wy = constant(field.y.clone(), [h - 1, w, 3], &rgb);
    let my = constant(per_channel(&field.y_valid), [h - 1, w, 3], &rgb);
    let sum = ((dx - wx).abs() * mx).sum() + ((dy - wy).abs() * my).sum();
    Some(sum / (3 * defined) as f32)
}

/// [`gradient_fusion_loss`] on the host, written out loop by loop: the reference the tensor
/// version is tested against.
pub fn gradient_fusion_loss_reference(rgb: &[f32], field: &GuidanceField) -> f64 {
    let (w, h) = (field.width, field.height);
    let mut sum = 0.0f64;
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                let v = rgb[(y * w + x) * 3 + c] as f64;
                if x + 1 < w && field.x_valid[y * (w - 1) + x] > 0.0 {
                    let d = rgb[(y * w + x + 1) * 3 + c] as f64 - v;
                    sum += (d - field.x[(y * (w - 1) + x) * 3 + c] as f64).abs();
                }
                if y + 1 < h && field.y_valid[y * w + x] > 0.0 {
                    let d = rgb[((y + 1) * w + x) * 3 + c] as f64 - v;
                    sum += (d - field.y[(y * w + x) * 3 + c] as f64).abs();
                }
            }
        }
    }
    sum / (3 * field.defined()).max(1) as f64
}

/// Anisotropic L1 total variation, `mean |∂ₓI| + mean |∂ᵧI|` over the whole image (variant (c)).
pub fn total_variation(rgb: Tensor<3>) -> Tensor<1> {
    let (dx, dy) = forward_differences(rgb);
    dx.abs().mean() + dy.abs().mean()
}

/// Mean absolute difference to `target` (`[H, W, 3]`, row-major) over the pixels where `valid`
/// holds and the 3 channels; `None` where no pixel is valid (variants (d) and (e)).
pub fn masked_l1(rgb: Tensor<3>, target: &[f32], valid: &[bool]) -> Option<Tensor<1>> {
    let count = valid.iter().filter(|&&v| v).count();
    if count == 0 {
        return None;
    }
    let [h, w, _] = rgb.dims();
    let mask: Vec<f32> = valid.iter().flat_map(|&v| [v as u8 as f32; 3]).collect();
    let t = constant(target.to_vec(), [h, w, 3], &rgb);
    let m = constant(mask, [h, w, 3], &rgb);
    Some(((rgb - t).abs() * m).sum() / (3 * count) as f32)
}

#[cfg(test)]
mod tests {
    use burn::tensor::Device;

    use super::*;
    use crate::guidance::guidance_field;
    use crate::reproject::Reference;

    /// Pseudo-random values in [0, 1) (a SplitMix64 hash of the index and the seed, so no two
    /// images share their differences).
    fn pattern(n: usize, seed: u64) -> Vec<f32> {
        (0..n as u64)
            .map(|i| {
                let mut z = (i ^ (seed << 32)).wrapping_add(0x9E37_79B9_7F4A_7C15);
                z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
                z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
                ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
            })
            .collect()
    }

    fn field(w: usize, h: usize) -> GuidanceField {
        let f = Reference {
            width: w,
            height: h,
            image: pattern(w * h * 3, 1),
            valid: (0..w * h).map(|p| p % w < w - 2).collect(),
        };
        let g = Reference {
            width: w,
            height: h,
            image: pattern(w * h * 3, 5),
            valid: (0..w * h).map(|p| p / w > 1).collect(),
        };
        guidance_field(&f, &g, 0.4)
    }

    fn tensor(values: &[f32], shape: [usize; 3]) -> Tensor<3> {
        Tensor::from_data(
            TensorData::new(values.to_vec(), shape),
            &Device::flex().autodiff(),
        )
        .require_grad()
    }

    #[test]
    fn the_fusion_loss_matches_its_loop_by_loop_reference() {
        let (w, h) = (11, 8);
        let field = field(w, h);
        let rgb = pattern(w * h * 3, 9);
        let got = gradient_fusion_loss(tensor(&rgb, [h, w, 3]), &field).unwrap();
        let got = got.into_data().try_to_vec::<f32>().unwrap()[0] as f64;
        let want = gradient_fusion_loss_reference(&rgb, &field);
        assert!((got - want).abs() < 1e-6, "{got} vs {want}");
    }

    #[test]
    fn the_fusion_loss_gradient_matches_finite_differences() {
        let (w, h) = (7, 6);
        let field = field(w, h);
        let rgb = pattern(w * h * 3, 3);
        let x = tensor(&rgb, [h, w, 3]);
        let grads = gradient_fusion_loss(x.clone(), &field).unwrap().backward();
        let analytic = x
            .grad(&grads)
            .unwrap()
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        // Central differences of the f64 reference; the step stays inside one linear piece of
        // the L1 for almost every element, so the comparison is exact up to rounding.
        let eps = 1e-4f32;
        let mut checked = 0;
        for i in 0..rgb.len() {
            let (mut plus, mut minus) = (rgb.clone(), rgb.clone());
            plus[i] += eps;
            minus[i] -= eps;
            let numeric = (gradient_fusion_loss_reference(&plus, &field)
                - gradient_fusion_loss_reference(&minus, &field))
                / (2.0 * eps as f64);
            assert!(
                (numeric - analytic[i] as f64).abs() < 1e-3 * (1.0 + numeric.abs()),
                "element {i}: numeric {numeric} analytic {}",
                analytic[i]
            );
            checked += (analytic[i] != 0.0) as usize;
        }
        assert!(checked > rgb.len() / 2, "only {checked} non-zero gradients");
    }

    #[test]
    fn an_image_whose_gradients_are_the_field_has_zero_loss() {
        // One reference valid everywhere and the other nowhere: w = ∇f, so f itself (and f plus
        // any constant) scores 0.
        let (w, h) = (6, 5);
        let image = pattern(w * h * 3, 2);
        let f = Reference {
            width: w,
            height: h,
            image: image.clone(),
            valid: vec![true; w * h],
        };
        let g = Reference {
            valid: vec![false; w * h],
            ..f.clone()
        };
        let field = guidance_field(&f, &g, 0.5);
        let shifted: Vec<f32> = image.iter().map(|v| v + 0.3).collect();
        let loss = gradient_fusion_loss(tensor(&shifted, [h, w, 3]), &field).unwrap();
        assert!(loss.into_data().try_to_vec::<f32>().unwrap()[0].abs() < 1e-6);
        assert!(
            gradient_fusion_loss(tensor(&image, [h, w, 3]), &guidance_field(&g, &g, 0.5)).is_none()
        );
    }

    #[test]
    fn total_variation_and_masked_l1_match_their_definitions() {
        let (w, h) = (5, 4);
        let rgb = pattern(w * h * 3, 4);
        let tv = total_variation(tensor(&rgb, [h, w, 3]));
        let (mut sx, mut sy) = (0.0f64, 0.0f64);
        for y in 0..h {
            for x in 0..w {
                for c in 0..3 {
                    let v = rgb[(y * w + x) * 3 + c] as f64;
                    if x + 1 < w {
                        sx += (rgb[(y * w + x + 1) * 3 + c] as f64 - v).abs();
                    }
                    if y + 1 < h {
                        sy += (rgb[((y + 1) * w + x) * 3 + c] as f64 - v).abs();
                    }
                }
            }
        }
        let want = sx / (h * (w - 1) * 3) as f64 + sy / ((h - 1) * w * 3) as f64;
        let got = tv.into_data().try_to_vec::<f32>().unwrap()[0] as f64;
        assert!((got - want).abs() < 1e-6);

        let target = pattern(w * h * 3, 8);
        let valid: Vec<bool> = (0..w * h).map(|p| p % 3 != 0).collect();
        let got = masked_l1(tensor(&rgb, [h, w, 3]), &target, &valid).unwrap();
        let got = got.into_data().try_to_vec::<f32>().unwrap()[0] as f64;
        let (mut sum, mut n) = (0.0f64, 0);
        for p in (0..w * h).filter(|p| valid[*p]) {
            for c in 0..3 {
                sum += (rgb[p * 3 + c] - target[p * 3 + c]).abs() as f64;
            }
            n += 3;
        }
        assert!((got - sum / n as f64).abs() < 1e-6);
        assert!(masked_l1(tensor(&rgb, [h, w, 3]), &target, &vec![false; w * h]).is_none());
    }
}
