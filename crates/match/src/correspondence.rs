//! Correspondences between views. The surface paper uses PDC-Net (a learned dense matcher
//! whose weights cannot be fetched here); [`Matcher`] is the seam where a learned matcher plugs
//! in, and [`crate::sift::SiftMatcher`] is the classical one used by default: SIFT features, Lowe's
//! ratio test, a mutual nearest-neighbour check and an optional RANSAC fundamental-matrix
//! filter (no poses are used: the poses are what is being estimated).
//!
//! [`epipolar_precision`] scores matches against ground-truth cameras.

use fewview_scene::{Camera, Image, Se3};
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// One correspondence between two views, in pixel coordinates (pixel centres at
/// half-integers).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Match {
    /// Index (into the training views) of the view of `a`.
    pub view_a: usize,
    pub view_b: usize,
    pub a: [f32; 2],
    pub b: [f32; 2],
    /// In `[0, 1]`, higher is more reliable.
    pub confidence: f32,
    /// Covariance of `b` in px² (xx, xy, yy), when `b` was fitted by Lucas–Kanade at a grid
    /// point of `a` ([`crate::densify`]): a grid point is not chosen for its texture, and on an edge
    /// the window fixes `b` across the edge only. The warm-up can weigh the epipolar residuals
    /// by it (`WarmupOptions::covariance_polish`). `None` for feature matches, whose keypoints
    /// are blobs located in both directions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub b_covariance: Option<[f32; 3]>,
}

/// An image and its optional object mask, as matchers see them.
pub struct MatchInput<'a> {
    pub image: &'a Image,
    pub mask: Option<&'a Image>,
}

/// Whether the mask (value ≥ `threshold` at the pixel under `p`) admits `p`; no mask admits
/// everything.
pub(crate) fn mask_admits(mask: Option<&Image>, p: nalgebra::Vector2<f64>, threshold: f32) -> bool {
    let Some(m) = mask else {
        return true;
    };
    let (x, y) = (p.x.floor(), p.y.floor());
    x >= 0.0
        && y >= 0.0
        && (x as usize) < m.width
        && (y as usize) < m.height
        && m.get(x as usize, y as usize, 0) >= threshold
}

/// Grey value of a pixel as the matchers see it: Rec. 601 luminance of RGB(A), or the single
/// channel.
pub(crate) fn luminance(pixel: &[f32]) -> f32 {
    if pixel.len() >= 3 {
        0.299 * pixel[0] + 0.587 * pixel[1] + 0.114 * pixel[2]
    } else {
        pixel[0]
    }
}

/// A two-view matcher.
pub trait Matcher: Send + Sync {
    /// Correspondences between `a` and `b` (`view_a`/`view_b` of the results are 0 and 1).
    fn match_pair(&self, a: &MatchInput, b: &MatchInput) -> Vec<Match>;

    /// Short name for reports.
    fn name(&self) -> &str;
}

/// The matches that a RANSAC fundamental matrix (Sampson distance below `px`) keeps.
pub(crate) fn ransac_filter(
    matches: Vec<Match>,
    px: f64,
    iterations: usize,
    seed: u64,
) -> Vec<Match> {
    let pa: Vec<[f64; 2]> = matches
        .iter()
        .map(|m| [m.a[0] as f64, m.a[1] as f64])
        .collect();
    let pb: Vec<[f64; 2]> = matches
        .iter()
        .map(|m| [m.b[0] as f64, m.b[1] as f64])
        .collect();
    let keep = crate::fundamental::ransac_inliers(&pa, &pb, px, iterations, seed);
    matches
        .into_iter()
        .zip(keep)
        .filter_map(|(m, k)| k.then_some(m))
        .collect()
}

/// Matches every unordered pair of views (`view_a < view_b`, indices into `views`).
pub fn match_all_pairs(matcher: &dyn Matcher, views: &[MatchInput]) -> Vec<Match> {
    let pairs: Vec<(usize, usize)> = unordered_pairs(views.len()).collect();
    match_pairs(matcher, views, &pairs)
}

/// Every pair `(i, j)` with `i < j < n`.
pub(crate) fn unordered_pairs(n: usize) -> impl Iterator<Item = (usize, usize)> {
    (0..n).flat_map(move |i| (i + 1..n).map(move |j| (i, j)))
}

/// Matches the given pairs of views (`(a, b)` with `a < b`, indices into `views`).
pub fn match_pairs(
    matcher: &dyn Matcher,
    views: &[MatchInput],
    pairs: &[(usize, usize)],
) -> Vec<Match> {
    let mut out = Vec::new();
    for &(i, j) in pairs {
        for m in matcher.match_pair(&views[i], &views[j]) {
            out.push(Match {
                view_a: i,
                view_b: j,
                ..m
            });
        }
    }
    out
}

/// The pairs of views `(i, j)`, `i < j`, whose optical axes under the world-to-camera `poses`
/// are at most `max_angle_deg` apart. Views that look at an object from opposite sides share
/// no surface; what a descriptor matcher finds between them are look-alikes (on the analytic
/// ring scene, 56–81 such matches per opposite pair pass RANSAC, 78–132 px off their epipolar
/// lines), so they are not matched at all.
pub fn covisible_pairs(poses: &[Se3], max_angle_deg: f64) -> Vec<(usize, usize)> {
    let axis = |p: &Se3| p.rotation.transpose() * Vector3::z();
    let cos_max = max_angle_deg.to_radians().cos();
    unordered_pairs(poses.len())
        .filter(|&(i, j)| axis(&poses[i]).dot(&axis(&poses[j])) >= cos_max)
        .collect()
}

/// The fundamental matrix mapping points of `a` to epipolar lines in `b`: `x_bᵀ F x_a = 0`.
pub fn fundamental_from_cameras(a: &Camera, b: &Camera) -> Matrix3<f64> {
    let rel = b.world_to_camera.compose(&a.world_to_camera.inverse());
    let t = rel.translation;
    let tx = Matrix3::new(0.0, -t.z, t.y, t.z, 0.0, -t.x, -t.y, t.x, 0.0);
    let e = tx * rel.rotation;
    let ka = a
        .intrinsics
        .matrix()
        .try_inverse()
        .unwrap_or_else(Matrix3::identity);
    let kb = b
        .intrinsics
        .matrix()
        .try_inverse()
        .unwrap_or_else(Matrix3::identity);
    kb.transpose() * e * ka
}

/// Symmetric epipolar distance of one match (pixels): the mean of the distances of each point
/// to the epipolar line of the other.
pub fn epipolar_distance(f: &Matrix3<f64>, a: [f32; 2], b: [f32; 2]) -> f64 {
    let xa = Vector3::new(a[0] as f64, a[1] as f64, 1.0);
    let xb = Vector3::new(b[0] as f64, b[1] as f64, 1.0);
    let lb = f * xa;
    let la = f.transpose() * xb;
    let r = xb.dot(&lb);
    let db = r.abs() / (lb.x * lb.x + lb.y * lb.y).sqrt().max(1e-12);
    let da = r.abs() / (la.x * la.x + la.y * la.y).sqrt().max(1e-12);
    0.5 * (da + db)
}

/// Match quality against ground-truth cameras.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MatchPrecision {
    pub matches: usize,
    /// Fraction with symmetric epipolar distance below 1, 2 and 5 px.
    pub precision_1px: f64,
    pub precision_2px: f64,
    pub precision_5px: f64,
    pub median_px: f64,
}

/// Scores `matches` (indices into `cameras`) by their epipolar distance under the true cameras.
pub fn epipolar_precision(matches: &[Match], cameras: &[Camera]) -> MatchPrecision {
    let mut d: Vec<f64> = matches
        .iter()
        .map(|m| {
            let f = fundamental_from_cameras(&cameras[m.view_a], &cameras[m.view_b]);
            epipolar_distance(&f, m.a, m.b)
        })
        .collect();
    d.sort_by(f64::total_cmp);
    let n = d.len().max(1) as f64;
    let frac = |t: f64| d.iter().filter(|x| **x < t).count() as f64 / n;
    MatchPrecision {
        matches: d.len(),
        precision_1px: frac(1.0),
        precision_2px: frac(2.0),
        precision_5px: frac(5.0),
        median_px: if d.is_empty() {
            f64::NAN
        } else {
            d[d.len() / 2]
        },
    }
}

#[cfg(test)]
mod tests {
    use fewview_scene::Intrinsics;

    use super::*;

    /// Four cameras on a ring at 0°, 60°, 120° and 180° around the look-at point: with an 80°
    /// limit only the neighbours are paired; with 180° all six pairs.
    #[test]
    fn covisible_pairs_follow_the_angle_between_optical_axes() {
        let k = Intrinsics::centered(100.0, 64, 48);
        let poses: Vec<Se3> = [0.0f64, 60.0, 120.0, 180.0]
            .iter()
            .map(|deg| {
                let (s, c) = deg.to_radians().sin_cos();
                Camera::look_at(
                    k,
                    Vector3::new(3.0 * c, 3.0 * s, 0.5),
                    Vector3::zeros(),
                    Vector3::z(),
                )
                .world_to_camera
            })
            .collect();
        assert_eq!(covisible_pairs(&poses, 80.0), vec![(0, 1), (1, 2), (2, 3)]);
        assert_eq!(covisible_pairs(&poses, 180.0).len(), 6);
        assert_eq!(covisible_pairs(&poses, 10.0), vec![]);
    }

    #[test]
    fn true_correspondences_have_zero_epipolar_distance() {
        let k = Intrinsics::centered(200.0, 160, 120);
        let a = Camera::look_at(
            k,
            Vector3::new(3.0, 0.5, 1.0),
            Vector3::zeros(),
            Vector3::z(),
        );
        let b = Camera::look_at(
            k,
            Vector3::new(1.0, 2.8, 0.7),
            Vector3::zeros(),
            Vector3::z(),
        );
        let f = fundamental_from_cameras(&a, &b);
        let mut ms = Vec::new();
        for p in [Vector3::new(0.1, 0.2, -0.1), Vector3::new(-0.3, 0.0, 0.2)] {
            let (ua, va, _) = a.project(&p).unwrap();
            let (ub, vb, _) = b.project(&p).unwrap();
            let d = epipolar_distance(&f, [ua as f32, va as f32], [ub as f32, vb as f32]);
            assert!(d < 1e-3, "{d}");
            ms.push(Match {
                view_a: 0,
                view_b: 1,
                a: [ua as f32, va as f32],
                b: [ub as f32, vb as f32],
                confidence: 1.0,
                b_covariance: None,
            });
        }
        // A point moved 4 px across the epipolar line is 2–4 px away on average.
        ms.push(Match {
            b: [ms[0].b[0] + 4.0, ms[0].b[1] + 4.0],
            ..ms[0]
        });
        let p = epipolar_precision(&ms, &[a, b]);
        assert_eq!(p.matches, 3);
        assert!((p.precision_1px - 2.0 / 3.0).abs() < 1e-12);
        assert_eq!(p.precision_5px, 1.0);
    }
}
