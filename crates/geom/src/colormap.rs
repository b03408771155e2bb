//! False colour for scalar maps (disparity, depth): a perceptually ordered ramp from dark blue
//! through green to yellow and red, with black for missing values.

use fewview_scene::Image;

/// Anchor colours of the ramp, evenly spaced over `[0, 1]` (dark to bright, blue to red).
const RAMP: [[f32; 3]; 6] = [
    [0.19, 0.07, 0.23],
    [0.16, 0.47, 0.93],
    [0.10, 0.89, 0.71],
    [0.64, 0.99, 0.24],
    [0.98, 0.73, 0.22],
    [0.73, 0.10, 0.03],
];

/// The ramp's colour at `t ∈ [0, 1]` (clamped).
pub fn ramp(t: f32) -> [f32; 3] {
    let x = t.clamp(0.0, 1.0) * (RAMP.len() - 1) as f32;
    let k = (x.floor() as usize).min(RAMP.len() - 2);
    let f = x - k as f32;
    std::array::from_fn(|c| RAMP[k][c] * (1.0 - f) + RAMP[k + 1][c] * f)
}

/// `values` (row-major, `width × height`) as colours between their 1st and 99th percentile among
/// the finite positive values; `≤ 0` or non-finite values are black. `invert` maps small values
/// to the bright end (depth: near is bright, as disparity is).
pub fn colorize(values: &[f32], width: usize, height: usize, invert: bool) -> Image {
    let mut valid: Vec<f32> = values
        .iter()
        .copied()
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    let mut img = Image::new(width, height, 3);
    if valid.is_empty() {
        return img;
    }
    valid.sort_by(f32::total_cmp);
    let at = |q: f64| valid[((q * (valid.len() - 1) as f64).round() as usize).min(valid.len() - 1)];
    let (lo, hi) = (at(0.01), at(0.99));
    let span = (hi - lo).max(f32::EPSILON);
    for (p, &v) in values.iter().enumerate() {
        if v.is_finite() && v > 0.0 {
            let t = (v - lo) / span;
            img.data[3 * p..3 * p + 3].copy_from_slice(&ramp(if invert { 1.0 - t } else { t }));
        }
    }
    img
}

/// `values` as colours on a fixed scale: `lo` to `hi` over the ramp (clamped outside), black
/// where a value is not finite. Maps drawn on one scale compare across runs.
pub fn colorize_range(values: &[f32], width: usize, height: usize, lo: f32, hi: f32) -> Image {
    let mut img = Image::new(width, height, 3);
    let span = (hi - lo).max(f32::EPSILON);
    for (p, &v) in values.iter().enumerate().take(width * height) {
        if v.is_finite() {
            img.data[3 * p..3 * p + 3].copy_from_slice(&ramp((v - lo) / span));
        }
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fixed_range_maps_its_ends_to_the_ramps_ends() {
        let img = colorize_range(&[0.0, 0.05, 0.1, 0.3, f32::NAN, -1.0], 6, 1, 0.0, 0.1);
        assert_eq!(img.pixel(0, 0), &RAMP[0]);
        assert_eq!(img.pixel(2, 0), &RAMP[5]);
        assert_eq!(img.pixel(3, 0), &RAMP[5]);
        assert_eq!(img.pixel(4, 0), &[0.0; 3]);
        assert_eq!(img.pixel(5, 0), &RAMP[0]);
        assert_eq!(img.pixel(1, 0), &ramp(0.5));
    }

    #[test]
    fn the_ramp_runs_through_its_anchors_and_missing_values_are_black() {
        assert_eq!(ramp(0.0), RAMP[0]);
        assert_eq!(ramp(1.0), RAMP[5]);
        let mid = ramp(0.1);
        for c in 0..3 {
            assert!((mid[c] - 0.5 * (RAMP[0][c] + RAMP[1][c])).abs() < 1e-6);
        }
        let img = colorize(&[0.0, 1.0, 2.0, f32::NAN], 2, 2, false);
        assert_eq!(img.pixel(0, 0), &[0.0, 0.0, 0.0]);
        assert_eq!(img.pixel(1, 1), &[0.0, 0.0, 0.0]);
        assert_eq!(img.pixel(1, 0), &RAMP[0]);
        assert_eq!(img.pixel(0, 1), &RAMP[5]);
        let inverted = colorize(&[1.0, 2.0], 2, 1, true);
        assert_eq!(inverted.pixel(0, 0), &RAMP[5]);
    }
}
