//! Bilinear resampling with half-pixel centres (PyTorch's `align_corners=False`, what
//! GPS-Gaussian's `nn.Upsample` uses).
//!
//! On the CPU this is Burn's `interpolate`. Burn's GPU backend has no backward pass for bilinear
//! interpolation, so on other devices the same resampling is composed from differentiable
//! gathers along each axis (two taps and their weights per output row or column, made on the
//! host): the same values up to rounding, checked against `interpolate` in the tests below.

use burn::tensor::module::interpolate;
use burn::tensor::ops::{InterpolateMode, InterpolateOptions};
use burn::tensor::{Device, Int, Tensor, TensorData};

/// `x` (`[N, C, H, W]`) resampled to `size` (`[H', W']`); the identity when the size matches.
pub fn resize(x: Tensor<4>, size: [usize; 2]) -> Tensor<4> {
    let [_, _, h, w] = x.dims();
    if [h, w] == size {
        return x;
    }
    if x.device() == Device::flex() {
        let options = InterpolateOptions::new(InterpolateMode::Bilinear)
            .with_align_corners(false)
            .with_output_size(size);
        return interpolate(x, options);
    }
    resize_composed(x, size)
}

/// The same resampling composed from gathers (differentiable on every backend).
pub fn resize_composed(x: Tensor<4>, size: [usize; 2]) -> Tensor<4> {
    resize_axis(resize_axis(x, 2, size[0]), 3, size[1])
}

/// Two source taps and the second tap's weight for each of `to` samples over `from`:
/// source position `(i + ½)·from/to − ½`, clamped below at 0.
fn taps(from: usize, to: usize) -> (Vec<i64>, Vec<i64>, Vec<f32>) {
    let scale = from as f32 / to as f32;
    let mut first = Vec::with_capacity(to);
    let mut second = Vec::with_capacity(to);
    let mut weight = Vec::with_capacity(to);
    for i in 0..to {
        let src = ((i as f32 + 0.5) * scale - 0.5).max(0.0);
        let i0 = (src.floor() as usize).min(from - 1);
        first.push(i0 as i64);
        second.push((i0 + 1).min(from - 1) as i64);
        weight.push(src - i0 as f32);
    }
    (first, second, weight)
}

/// Resamples dimension `axis` of `x` to `to` samples.
fn resize_axis(x: Tensor<4>, axis: usize, to: usize) -> Tensor<4> {
    let from = x.dims()[axis];
    if from == to {
        return x;
    }
    let device = x.device();
    let (first, second, weight) = taps(from, to);
    let index = |v: Vec<i64>| Tensor::<1, Int>::from_data(TensorData::new(v, [to]), &device);
    let mut shape = [1; 4];
    shape[axis] = to;
    let w1 = Tensor::<1>::from_data(TensorData::new(weight, [to]), &device).reshape(shape);
    let w0 = w1.clone().neg() + 1.0;
    let a = x.clone().select(axis, index(first));
    let b = x.select(axis, index(second));
    a * w0 + b * w1
}

#[cfg(test)]
mod tests {
    use super::*;

    fn values<const D: usize>(t: Tensor<D>) -> Vec<f32> {
        t.into_data().try_to_vec::<f32>().unwrap()
    }

    #[test]
    fn composed_resampling_matches_interpolate_in_value_and_gradient() {
        let device = Device::flex().autodiff();
        // Up by two, up by an odd ratio, and down: every tap pattern the decoder can meet.
        for (from, to) in [([3, 5], [6, 10]), ([4, 3], [7, 8]), ([8, 6], [5, 4])] {
            let len = 2 * 3 * from[0] * from[1];
            let data: Vec<f32> = (0..len)
                .map(|i| ((i * 37 % 23) as f32 - 11.0) / 7.0)
                .collect();
            let x =
                Tensor::<4>::from_data(TensorData::new(data, [2, 3, from[0], from[1]]), &device);
            let out_len = 2 * 3 * to[0] * to[1];
            let weights: Vec<f32> = (0..out_len)
                .map(|i| ((i * 13 % 17) as f32) / 17.0)
                .collect();
            let weights =
                Tensor::<4>::from_data(TensorData::new(weights, [2, 3, to[0], to[1]]), &device);
            let run = |composed: bool| {
                let x = x.clone().require_grad();
                let y = if composed {
                    resize_composed(x.clone(), to)
                } else {
                    resize(x.clone(), to)
                };
                let grads = (y.clone() * weights.clone()).sum().backward();
                (values(y), values(x.grad(&grads).unwrap()))
            };
            let (want, want_grad) = run(false);
            let (got, got_grad) = run(true);
            for (a, b) in want.iter().zip(&got).chain(want_grad.iter().zip(&got_grad)) {
                assert!((a - b).abs() < 1e-5, "{from:?} → {to:?}: {a} vs {b}");
            }
        }
    }
}
