//! Resampling exactly as the PyTorch reference does it: `F.interpolate(mode="bilinear",
//! align_corners=False)` on whole images and `F.grid_sample(align_corners=False,
//! padding_mode="zeros")` at sparse positions normalised by XFeat's `InterpolateSparse2d`
//! (which divides by `W − 1`, `H − 1` although the sampler then assumes half-pixel corners).
//! Matching the reference's arithmetic step by step keeps keypoints and descriptors equal to it.

/// A single-channel or multi-channel map, channel-major (`[C, H, W]`).
#[derive(Clone, Copy)]
pub struct Map<'a> {
    pub data: &'a [f32],
    pub channels: usize,
    pub width: usize,
    pub height: usize,
}

impl Map<'_> {
    /// Value at integer `(x, y)` of channel `c`, zero outside (PyTorch's `padding_mode="zeros"`).
    fn at(&self, c: usize, x: i64, y: i64) -> f32 {
        if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 {
            return 0.0;
        }
        self.data[(c * self.height + y as usize) * self.width + x as usize]
    }
}

/// How `grid_sample` interpolates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sampling {
    Nearest,
    Bilinear,
    /// Keys' cubic convolution with a = −0.75 (PyTorch's bicubic).
    Bicubic,
}

/// Samples every channel of `map` at pixel position `(x, y)` of an image of `image_w × image_h`
/// pixels, as `InterpolateSparse2d(mode)(map, pos, image_h, image_w)`, writing `out[c]`.
pub fn sample_sparse(
    map: Map,
    x: f32,
    y: f32,
    image_w: usize,
    image_h: usize,
    mode: Sampling,
    out: &mut [f32],
) {
    let gx = 2.0 * (x / (image_w - 1) as f32) - 1.0;
    let gy = 2.0 * (y / (image_h - 1) as f32) - 1.0;
    let ix = ((gx + 1.0) * map.width as f32 - 1.0) / 2.0;
    let iy = ((gy + 1.0) * map.height as f32 - 1.0) / 2.0;
    for (c, o) in out.iter_mut().enumerate().take(map.channels) {
        *o = match mode {
            Sampling::Nearest => {
                map.at(c, ix.round_ties_even() as i64, iy.round_ties_even() as i64)
            }
            Sampling::Bilinear => bilinear(map, c, ix, iy),
            Sampling::Bicubic => bicubic(map, c, ix, iy),
        };
    }
}

fn bilinear(map: Map, c: usize, ix: f32, iy: f32) -> f32 {
    let (x0, y0) = (ix.floor(), iy.floor());
    let (x1, y1) = (x0 + 1.0, y0 + 1.0);
    let nw = (x1 - ix) * (y1 - iy);
    let ne = (ix - x0) * (y1 - iy);
    let sw = (x1 - ix) * (iy - y0);
    let se = (ix - x0) * (iy - y0);
    let (x0, y0) = (x0 as i64, y0 as i64);
    map.at(c, x0, y0) * nw
        + map.at(c, x0 + 1, y0) * ne
        + map.at(c, x0, y0 + 1) * sw
        + map.at(c, x0 + 1, y0 + 1) * se
}

/// PyTorch's cubic convolution weights of the four taps around a fractional offset `t`.
fn cubic_weights(t: f32) -> [f32; 4] {
    const A: f32 = -0.75;
    let near = |x: f32| ((A + 2.0) * x - (A + 3.0)) * x * x + 1.0;
    let far = |x: f32| ((A * x - 5.0 * A) * x + 8.0 * A) * x - 4.0 * A;
    [far(t + 1.0), near(t), near(1.0 - t), far(2.0 - t)]
}

fn bicubic(map: Map, c: usize, ix: f32, iy: f32) -> f32 {
    let (x0, y0) = (ix.floor(), iy.floor());
    let wx = cubic_weights(ix - x0);
    let wy = cubic_weights(iy - y0);
    let (x0, y0) = (x0 as i64, y0 as i64);
    let row = |y: i64| {
        (0..4).fold(0.0f32, |acc, j| {
            acc + map.at(c, x0 - 1 + j as i64, y) * wx[j]
        })
    };
    (0..4).fold(0.0f32, |acc, i| acc + row(y0 - 1 + i as i64) * wy[i])
}

/// `F.interpolate(x, size=(out_h, out_w), mode="bilinear", align_corners=False)` of a
/// channel-major map, with source coordinates `scale · (dst + ½) − ½` (clamped at 0).
/// `scale` is `in/out` for a target size, or `1/s` for a scale factor `s`.
pub fn resize_bilinear(
    map: Map,
    out_w: usize,
    out_h: usize,
    scale_x: f32,
    scale_y: f32,
) -> Vec<f32> {
    let axis = |dst: usize, scale: f32, len: usize| {
        let src = (scale * (dst as f32 + 0.5) - 0.5).max(0.0);
        let i0 = src as usize;
        let step = usize::from(i0 < len - 1);
        let l1 = src - i0 as f32;
        (i0, i0 + step, 1.0 - l1, l1)
    };
    let xs: Vec<_> = (0..out_w).map(|x| axis(x, scale_x, map.width)).collect();
    let mut out = Vec::with_capacity(map.channels * out_w * out_h);
    for c in 0..map.channels {
        let plane = &map.data[c * map.width * map.height..(c + 1) * map.width * map.height];
        for y in 0..out_h {
            let (y0, y1, ly0, ly1) = axis(y, scale_y, map.height);
            let (r0, r1) = (&plane[y0 * map.width..], &plane[y1 * map.width..]);
            for &(x0, x1, lx0, lx1) in &xs {
                out.push(ly0 * (lx0 * r0[x0] + lx1 * r0[x1]) + ly1 * (lx0 * r1[x0] + lx1 * r1[x1]));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: usize, h: usize) -> Vec<f32> {
        (0..w * h)
            .map(|i| (i % w) as f32 * 0.5 + (i / w) as f32 * 2.0)
            .collect()
    }

    #[test]
    fn bilinear_reproduces_a_linear_ramp_inside() {
        // Bilinear reproduces linear functions exactly away from the zero padding.
        let (w, h) = (16, 12);
        let data = ramp(w, h);
        let map = Map {
            data: &data,
            channels: 1,
            width: w,
            height: h,
        };
        // An image 8× larger: the map pixel centres sit at image positions 8·i + 3.5 (half-pixel
        // corners) after XFeat's normalisation by W − 1.
        let (iw, ih) = (w * 8, h * 8);
        for &(x, y) in &[(40.0f32, 30.0f32), (57.0, 44.0), (70.0, 50.0)] {
            let ix = ((2.0 * (x / (iw - 1) as f32) - 1.0 + 1.0) * w as f32 - 1.0) / 2.0;
            let iy = ((2.0 * (y / (ih - 1) as f32) - 1.0 + 1.0) * h as f32 - 1.0) / 2.0;
            let expect = ix * 0.5 + iy * 2.0;
            let mut out = [0.0];
            sample_sparse(map, x, y, iw, ih, Sampling::Bilinear, &mut out);
            assert!(
                (out[0] - expect).abs() < 1e-4,
                "at ({x}, {y}): {} vs {expect}",
                out[0]
            );
        }
    }

    #[test]
    fn bicubic_interpolates_and_keeps_constants() {
        // Keys' kernel is interpolating (weights 0, 1, 0, 0 at a sample) and sums to one.
        assert_eq!(cubic_weights(0.0), [0.0, 1.0, 0.0, 0.0]);
        for t in [0.1f32, 0.37, 0.5, 0.93] {
            let w = cubic_weights(t);
            assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-6, "{w:?}");
            // a = −0.75: the outer weights are −0.75·t·(1−t)² and −0.75·t²·(1−t).
            assert!((w[0] + 0.75 * t * (1.0 - t).powi(2)).abs() < 1e-6, "{w:?}");
            assert!((w[3] + 0.75 * t * t * (1.0 - t)).abs() < 1e-6, "{w:?}");
        }
        let data = vec![0.7f32; 12 * 10];
        let map = Map {
            data: &data,
            channels: 1,
            width: 12,
            height: 10,
        };
        let mut out = [0.0];
        sample_sparse(map, 45.3, 41.8, 96, 80, Sampling::Bicubic, &mut out);
        assert!((out[0] - 0.7).abs() < 1e-6, "{}", out[0]);
    }

    #[test]
    fn nearest_rounds_half_to_even_and_pads_with_zero() {
        let data = vec![1.0, 2.0, 3.0, 4.0];
        let map = Map {
            data: &data,
            channels: 1,
            width: 4,
            height: 1,
        };
        // Image width equal to the map's: ix = x·W/(W−1) − ½, so x = 3 maps to 3.5 → 4 (outside).
        let mut out = [0.0];
        sample_sparse(map, 3.0, 0.0, 4, 2, Sampling::Nearest, &mut out);
        assert_eq!(out[0], 0.0);
        sample_sparse(map, 1.0, 0.0, 4, 2, Sampling::Nearest, &mut out);
        assert_eq!(out[0], 2.0); // 1·4/3 − ½ = 0.833 → 1
    }

    #[test]
    fn resize_by_one_is_the_identity_and_halving_averages_pairs() {
        let (w, h) = (6, 4);
        let data = ramp(w, h);
        let map = Map {
            data: &data,
            channels: 1,
            width: w,
            height: h,
        };
        assert_eq!(resize_bilinear(map, w, h, 1.0, 1.0), data);
        let half = resize_bilinear(map, 3, 2, 2.0, 2.0);
        // dst 0 ← src ½ between 0 and 1: the mean of each 2×2 block for a linear ramp.
        assert_eq!(half[0], (data[0] + data[1] + data[w] + data[w + 1]) / 4.0);
    }
}
