//! XFeat's sparse detection, step by step as the reference's `detectAndCompute`: the image
//! resized to multiples of 32 and made grey and instance-normalised; keypoint logits turned into
//! a full-resolution heatmap (softmax over each 8×8 cell's 65 bins, the "no keypoint" bin
//! dropped); 5×5 non-maximum suppression above a threshold; each keypoint scored by its heatmap
//! value times the reliability map; the top k kept; descriptors sampled bicubically from the
//! L2-normalised dense map and normalised again.

use fewview_scene::Image;

use super::sample::{Map, Sampling, resize_bilinear, sample_sparse};
use crate::error::{MatchError, Result};

/// XFeat's input stride: image sides are cut to multiples of it.
pub const STRIDE: usize = 32;
/// Descriptor length.
pub const DIM: usize = 64;

/// An image prepared for the network: grey, instance-normalised, sides multiples of 32.
pub struct Prepared {
    pub gray: Vec<f32>,
    pub width: usize,
    pub height: usize,
    /// Original over prepared size, per axis: keypoints are scaled by it at the end.
    pub scale: [f32; 2],
}

/// An image's colour channels (at most three), channel-major, as the reference's tensor.
pub fn planar(image: &Image) -> Vec<f32> {
    (0..image.channels.min(3))
        .flat_map(|c| image.data.iter().skip(c).step_by(image.channels).copied())
        .collect()
}

/// `preprocess_tensor` then the network's `mean(dim=1)` and `InstanceNorm2d`, on a
/// channel-major image.
pub fn prepare(image: Map) -> Result<Prepared> {
    let (w, h) = (image.width, image.height);
    let (pw, ph) = (w / STRIDE * STRIDE, h / STRIDE * STRIDE);
    if pw == 0 || ph == 0 {
        return Err(MatchError::invalid(format!(
            "a {w}×{h} image is smaller than XFeat's {STRIDE}-pixel stride"
        )));
    }
    let resized = resize_bilinear(image, pw, ph, w as f32 / pw as f32, h as f32 / ph as f32);
    let (n, channels) = (pw * ph, image.channels);
    let gray: Vec<f32> = (0..n)
        .map(|i| (0..channels).fold(0.0f32, |s, c| s + resized[c * n + i]) / channels as f32)
        .collect();
    Ok(Prepared {
        gray: instance_norm(gray),
        width: pw,
        height: ph,
        scale: [(w as f64 / pw as f64) as f32, (h as f64 / ph as f64) as f32],
    })
}

/// `(x − mean) / √(var + 1e-5)` over the whole plane, with the biased variance.
fn instance_norm(mut x: Vec<f32>) -> Vec<f32> {
    let n = x.len() as f64;
    let mean = x.iter().map(|&v| v as f64).sum::<f64>() / n;
    let var = x.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / n;
    let inv_std = (1.0 / (var + 1e-5).sqrt()) as f32;
    let mean = mean as f32;
    x.iter_mut().for_each(|v| *v = (*v - mean) * inv_std);
    x
}

/// The full-resolution keypoint heatmap (`get_kpts_heatmap`) from logits `[65, h, w]`.
pub fn keypoint_heatmap(logits: &[f32], w: usize, h: usize) -> Vec<f32> {
    let cells = w * h;
    let mut heat = vec![0.0f32; cells * 64];
    let width = w * 8;
    let mut bins = [0.0f32; 65];
    for cell in 0..cells {
        let (cx, cy) = (cell % w, cell / w);
        for (k, b) in bins.iter_mut().enumerate() {
            *b = logits[k * cells + cell];
        }
        let max = bins.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        let mut sum = 0.0f32;
        for b in &mut bins {
            *b = (*b - max).exp();
            sum += *b;
        }
        for (k, &b) in bins[..64].iter().enumerate() {
            heat[(cy * 8 + k / 8) * width + cx * 8 + k % 8] = b / sum;
        }
    }
    heat
}

/// Positions `(x, y)` (row-major order) that are the maximum of their 5×5 window and above
/// `threshold` (`NMS(kernel_size=5)`).
pub fn local_maxima(heat: &[f32], w: usize, h: usize, threshold: f32) -> Vec<[usize; 2]> {
    const R: usize = 2;
    let mut out = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let v = heat[y * w + x];
            if v <= threshold {
                continue;
            }
            let is_max = (y.saturating_sub(R)..(y + R + 1).min(h)).all(|yy| {
                (x.saturating_sub(R)..(x + R + 1).min(w)).all(|xx| heat[yy * w + xx] <= v)
            });
            if is_max {
                out.push([x, y]);
            }
        }
    }
    out
}

/// Sparse features of one image.
#[derive(Clone, Debug, Default)]
pub struct Features {
    /// Keypoints `(x, y)` in the original image's pixels (XFeat's convention: the keypoint of
    /// heatmap pixel `i` is at `i · scale`).
    pub keypoints: Vec<[f32; 2]>,
    /// Heatmap × reliability, descending.
    pub scores: Vec<f32>,
    /// Unit descriptors, `DIM` per keypoint.
    pub descriptors: Vec<f32>,
    /// The original image's `(width, height)`.
    pub image_size: [usize; 2],
}

impl Features {
    pub fn len(&self) -> usize {
        self.keypoints.len()
    }
    pub fn is_empty(&self) -> bool {
        self.keypoints.is_empty()
    }
    /// Descriptor `i`.
    pub fn descriptor(&self, i: usize) -> &[f32] {
        &self.descriptors[i * DIM..(i + 1) * DIM]
    }

    /// Keeps the keypoints (with their scores and descriptors) for which `keep` holds.
    pub fn retain(&mut self, keep: impl Fn([f32; 2]) -> bool) {
        let kept: Vec<usize> = (0..self.len())
            .filter(|&i| keep(self.keypoints[i]))
            .collect();
        self.descriptors = kept
            .iter()
            .flat_map(|&i| self.descriptor(i).to_vec())
            .collect();
        self.keypoints = kept.iter().map(|&i| self.keypoints[i]).collect();
        self.scores = kept.iter().map(|&i| self.scores[i]).collect();
    }
}

/// Scores, orders and describes the maxima; keeps the `top_k` best with a positive score.
pub struct Select<'a> {
    pub heat: &'a [f32],
    pub reliability: Map<'a>,
    /// L2-normalised dense descriptors.
    pub descriptors: Map<'a>,
    pub prepared_size: [usize; 2],
    pub scale: [f32; 2],
    pub image_size: [usize; 2],
}

impl Select<'_> {
    pub fn run(&self, maxima: &[[usize; 2]], top_k: usize) -> Features {
        let [pw, ph] = self.prepared_size;
        let heat = Map {
            data: self.heat,
            channels: 1,
            width: pw,
            height: ph,
        };
        let mut scored: Vec<(f32, [usize; 2])> = maxima
            .iter()
            .map(|&[x, y]| {
                let (fx, fy) = (x as f32, y as f32);
                let (mut a, mut b) = ([0.0], [0.0]);
                sample_sparse(heat, fx, fy, pw, ph, Sampling::Nearest, &mut a);
                sample_sparse(self.reliability, fx, fy, pw, ph, Sampling::Bilinear, &mut b);
                let score = if x == 0 && y == 0 { -1.0 } else { a[0] * b[0] };
                (score, [x, y])
            })
            .collect();
        scored.sort_by(|a, b| b.0.total_cmp(&a.0));
        scored.truncate(top_k);
        scored.retain(|s| s.0 > 0.0);
        let mut features = Features {
            image_size: self.image_size,
            ..Default::default()
        };
        let mut d = [0.0f32; DIM];
        for (score, [x, y]) in scored {
            sample_sparse(
                self.descriptors,
                x as f32,
                y as f32,
                pw,
                ph,
                Sampling::Bicubic,
                &mut d,
            );
            normalize(&mut d);
            features.descriptors.extend_from_slice(&d);
            features.scores.push(score);
            features
                .keypoints
                .push([x as f32 * self.scale[0], y as f32 * self.scale[1]]);
        }
        features
    }
}

/// `F.normalize`: divides by the L2 norm, at least 1e-12.
pub fn normalize(v: &mut [f32]) {
    let norm = v.iter().map(|x| x * x).sum::<f32>().sqrt().max(1e-12);
    v.iter_mut().for_each(|x| *x /= norm);
}

/// L2-normalises each pixel's `channels`-vector of a channel-major map.
pub fn normalize_channels(map: &mut [f32], channels: usize) {
    let n = map.len() / channels;
    let mut v = vec![0.0f32; channels];
    for i in 0..n {
        for (c, x) in v.iter_mut().enumerate() {
            *x = map[c * n + i];
        }
        normalize(&mut v);
        for (c, x) in v.iter().enumerate() {
            map[c * n + i] = *x;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heatmap_places_each_bin_at_its_pixel() {
        // One cell (w = h = 1): logit 10 on bin 8·3 + 5, so pixel (5, 3) takes almost all mass.
        let mut logits = vec![0.0f32; 65];
        logits[29] = 10.0;
        let heat = keypoint_heatmap(&logits, 1, 1);
        let best = heat
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .unwrap()
            .0;
        assert_eq!(best, 3 * 8 + 5);
        let total: f32 = heat.iter().sum();
        // All bins but the dropped 65th: (63 + e¹⁰) / (64 + e¹⁰).
        let expect = (63.0 + 10f32.exp()) / (64.0 + 10f32.exp());
        assert!((total - expect).abs() < 1e-5);
    }

    #[test]
    fn maxima_need_their_whole_window_and_the_threshold() {
        let (w, h) = (8, 6);
        let mut heat = vec![0.01f32; w * h];
        heat[2 * w + 2] = 0.5; // a maximum
        heat[2 * w + 4] = 0.4; // within 2 px of a larger value: suppressed
        heat[5 * w + 7] = 0.3; // corner region, a maximum
        heat[0] = 0.04; // below the threshold
        assert_eq!(local_maxima(&heat, w, h, 0.05), vec![[2, 2], [7, 5]]);
    }

    #[test]
    fn too_small_images_are_refused() {
        let img = Image::new(31, 64, 3);
        let data = planar(&img);
        let map = Map {
            data: &data,
            channels: 3,
            width: 31,
            height: 64,
        };
        let err = prepare(map).err().expect("refused").to_string();
        assert!(err.contains("31×64"), "{err}");
    }
}
