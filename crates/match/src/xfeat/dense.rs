//! XFeat* (the semi-dense mode of "XFeat: Accelerated Features for Lightweight Image Matching"):
//! the most reliable 8×8 cells of the image at two scales (0.6 and 1.3, a fifth and four fifths
//! of the budget) with their raw coarse descriptors, matched by mutual nearest neighbours and
//! moved to sub-pixel positions by the fine matcher (`detectAndComputeDense`, `extractDense`,
//! `batch_match`, `refine_matches` of the reference).

use super::detect::{DIM, prepare};
use super::network::Network;
use super::sample::{Map, resize_bilinear};
use crate::error::Result;

/// The two scales of `extract_dualscale` and their shares of the keypoint budget.
const SCALES: [(f64, f64); 2] = [(0.6, 0.20), (1.3, 0.80)];

/// Coarse keypoints (cell corners) with their raw descriptors and extraction scales.
#[derive(Clone, Debug, Default)]
pub struct DenseFeatures {
    pub keypoints: Vec<[f32; 2]>,
    /// Original-image pixels per network-input pixel at the keypoint's scale.
    pub scales: Vec<f32>,
    /// Unnormalised descriptors, `DIM` per keypoint.
    pub descriptors: Vec<f32>,
}

impl DenseFeatures {
    pub fn len(&self) -> usize {
        self.keypoints.len()
    }
    pub fn is_empty(&self) -> bool {
        self.keypoints.is_empty()
    }
}

/// `extract_dualscale`: both scales' cells, the smaller scale first.
pub fn dual_scale(net: &Network, image: Map, top_k: usize) -> Result<DenseFeatures> {
    let mut out = DenseFeatures::default();
    for (s, share) in SCALES {
        let w = (image.width as f64 * s).floor() as usize;
        let h = (image.height as f64 * s).floor() as usize;
        let inv = (1.0 / s) as f32;
        let resized = resize_bilinear(image, w, h, inv, inv);
        let map = Map {
            data: &resized,
            channels: image.channels,
            width: w,
            height: h,
        };
        let budget = (top_k as f64 * share) as usize;
        let one = extract(net, map, budget)?;
        let s = s as f32;
        out.keypoints
            .extend(one.keypoints.iter().map(|[x, y]| [x / s, y / s]));
        out.scales.extend(std::iter::repeat_n(inv, one.len()));
        out.descriptors.extend(one.descriptors);
    }
    Ok(out)
}

/// `extractDense`: the `top_k` cells of highest reliability (all when `top_k` is 0), in
/// descending order, at their top-left pixel scaled back to `image`.
fn extract(net: &Network, image: Map, top_k: usize) -> Result<DenseFeatures> {
    let p = prepare(image)?;
    let out = net.forward(&p.gray, p.width, p.height);
    let (w, h) = (p.width / 8, p.height / 8);
    let cells = w * h;
    let reliability = crate::tensor::host(out.reliability);
    let descriptors = crate::tensor::host(out.descriptors);
    let mut order: Vec<usize> = (0..cells).collect();
    order.sort_by(|&a, &b| reliability[b].total_cmp(&reliability[a]).then(a.cmp(&b)));
    order.truncate(if top_k == 0 { cells } else { top_k.min(cells) });
    let mut features = DenseFeatures::default();
    for &i in &order {
        let (x, y) = ((i % w * 8) as f32, (i / w * 8) as f32);
        features.keypoints.push([x * p.scale[0], y * p.scale[1]]);
        features.scales.push(1.0);
        features
            .descriptors
            .extend((0..DIM).map(|c| descriptors[c * cells + i]));
    }
    Ok(features)
}
