//! The classical matcher: SIFT keypoints and descriptors (the `sift-features` crate, an
//! OpenCV-compatible implementation of Lowe 2004), brute-force nearest neighbours in descriptor
//! space with Lowe's ratio test and a mutual check, keypoints restricted to the object masks,
//! and an optional RANSAC fundamental-matrix filter.
//!
//! Confidence of a match: `1 − ratio²` (ratio of the nearest to the second-nearest descriptor
//! distance), so unambiguous matches weigh more in the correspondence loss.

use fewview_scene::Image;
use image::{GrayImage, Luma};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::correspondence::{Match, MatchInput, Matcher, luminance, ransac_filter};

/// Options of [`SiftMatcher`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SiftOptions {
    /// Lowe's ratio threshold (0.8 in Lowe 2004).
    pub ratio: f32,
    /// Keep only mutual nearest neighbours.
    pub mutual: bool,
    /// Most keypoints per image (strongest first); `None` = all.
    pub max_features: Option<usize>,
    /// RANSAC fundamental-matrix filter threshold (Sampson distance, pixels); `None` = off.
    pub ransac_px: Option<f64>,
    pub ransac_iterations: usize,
    pub seed: u64,
}

impl Default for SiftOptions {
    fn default() -> Self {
        Self {
            ratio: 0.8,
            mutual: true,
            max_features: Some(4000),
            ransac_px: Some(2.0),
            ransac_iterations: 2000,
            seed: 0,
        }
    }
}

/// SIFT + ratio test + mutual check (+ RANSAC).
#[derive(Clone, Debug, Default)]
pub struct SiftMatcher {
    pub options: SiftOptions,
}

/// The SIFT keypoints of one image and their descriptors, computed once and matched against
/// any number of other images ([`SiftMatcher::match_features`]).
#[derive(Clone, Debug, Default)]
pub struct SiftFeatures {
    /// Pixel coordinates in the crate convention (centres at half-integers).
    points: Vec<[f32; 2]>,
    descriptors: Vec<[f32; 128]>,
}

impl SiftFeatures {
    /// Number of keypoints.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The keypoints' 128-dimensional descriptors.
    pub fn descriptors(&self) -> &[[f32; 128]] {
        &self.descriptors
    }
}

fn to_gray(image: &Image) -> GrayImage {
    let (w, h) = (image.width, image.height);
    GrayImage::from_fn(w as u32, h as u32, |x, y| {
        let g = luminance(image.pixel(x as usize, y as usize));
        Luma([(g.clamp(0.0, 1.0) * 255.0).round() as u8])
    })
}

fn features(input: &MatchInput, limit: Option<usize>) -> SiftFeatures {
    let res = sift_features::sift(&to_gray(input.image), limit);
    let d = res
        .descriptors
        .as_slice()
        .map(<[u8]>::to_vec)
        .unwrap_or_else(|| res.descriptors.iter().copied().collect());
    let mut points = Vec::new();
    let mut descriptors = Vec::new();
    for (i, kp) in res.keypoints.iter().enumerate() {
        // OpenCV keypoints put pixel centres at integers.
        let (u, v) = (kp.x + 0.5, kp.y + 0.5);
        if let Some(m) = input.mask {
            let (x, y) = (u.floor() as isize, v.floor() as isize);
            if x < 0 || y < 0 || x as usize >= m.width || y as usize >= m.height {
                continue;
            }
            if m.get(x as usize, y as usize, 0) < 0.5 {
                continue;
            }
        }
        let mut desc = [0.0f32; 128];
        for k in 0..128 {
            desc[k] = d[i * 128 + k] as f32;
        }
        points.push([u, v]);
        descriptors.push(desc);
    }
    SiftFeatures {
        points,
        descriptors,
    }
}

/// Nearest and second-nearest squared distances from each of `a` to `b`: `(index, d1, d2)`.
fn nearest_two(a: &[[f32; 128]], b: &[[f32; 128]]) -> Vec<(usize, f32, f32)> {
    a.par_iter()
        .map(|da| {
            let (mut bi, mut d1, mut d2) = (usize::MAX, f32::INFINITY, f32::INFINITY);
            for (j, db) in b.iter().enumerate() {
                let mut s = 0.0f32;
                for k in 0..128 {
                    let t = da[k] - db[k];
                    s += t * t;
                }
                if s < d1 {
                    d2 = d1;
                    d1 = s;
                    bi = j;
                } else if s < d2 {
                    d2 = s;
                }
            }
            (bi, d1, d2)
        })
        .collect()
}

impl SiftMatcher {
    /// The keypoints and descriptors of `input` (inside its mask, when it has one).
    pub fn features(&self, input: &MatchInput) -> SiftFeatures {
        features(input, self.options.max_features)
    }

    /// Matches between two images' features (`view_a`/`view_b` 0 and 1): Lowe's ratio test,
    /// the mutual check and the RANSAC filter as the options say.
    pub fn match_features(&self, fa: &SiftFeatures, fb: &SiftFeatures) -> Vec<Match> {
        let o = &self.options;
        if fa.points.is_empty() || fb.points.is_empty() {
            return Vec::new();
        }
        let ab = nearest_two(&fa.descriptors, &fb.descriptors);
        let ba = if o.mutual {
            nearest_two(&fb.descriptors, &fa.descriptors)
        } else {
            Vec::new()
        };
        let mut out = Vec::new();
        for (i, &(j, d1, d2)) in ab.iter().enumerate() {
            if j == usize::MAX {
                continue;
            }
            let ratio = (d1 / d2.max(1e-12)).sqrt();
            if ratio.is_nan() || ratio >= o.ratio {
                continue;
            }
            if o.mutual && ba[j].0 != i {
                continue;
            }
            out.push(Match {
                view_a: 0,
                view_b: 1,
                a: fa.points[i],
                b: fb.points[j],
                confidence: 1.0 - ratio * ratio,
                b_covariance: None,
            });
        }
        match o.ransac_px {
            Some(px) => ransac_filter(out, px, o.ransac_iterations, o.seed),
            None => out,
        }
    }
}

impl Matcher for SiftMatcher {
    fn match_pair(&self, a: &MatchInput, b: &MatchInput) -> Vec<Match> {
        self.match_features(&self.features(a), &self.features(b))
    }

    fn name(&self) -> &str {
        "sift"
    }
}
