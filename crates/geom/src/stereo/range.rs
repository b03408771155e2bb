//! Which disparities a rectified pair searches: from the structure-from-motion points both
//! views see (a capture's own depths), from the views' depth bounds, or a fixed range.
//!
//! Disparity is linear in inverse depth (`d = f·B / z + offset`), so every range is sampled
//! evenly in inverse depth: a far background costs few disparities, the near ground many.

use nalgebra::Vector3;

pub use super::pairs::MIN_RANGE_POINTS;
use super::pairs::{StereoView, central_span, sees};
use super::rectify::{Rectification, Side};

/// How the disparity search range of a pair is chosen.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DisparityRange {
    /// From the two views' depth bounds (10 % margin), rounded out to a multiple of 16.
    FromDepthBounds,
    /// From the sparse points both views see ([`points_disparity_range`]), as the fusion
    /// paper's cited multi-view stereo sets its depth range from the structure-from-motion
    /// points; from the depth bounds where fewer than [`MIN_RANGE_POINTS`] are seen by both.
    FromSparsePoints,
    /// Exactly these disparities, `min .. min + count`.
    Fixed { min: i32, count: usize },
}

/// The most disparities searched when the range comes from depth bounds or points.
pub const MAX_DISPARITIES: usize = 256;

/// The disparity range of rectified pair `rect` for scene depths `near..far`, with 10 % margins.
pub fn disparity_range(rect: &Rectification, near: f64, far: f64) -> (i32, usize) {
    exact_disparity_range(rect, near * 0.9, far * 1.1)
}

/// The disparity range of rectified pair `rect` for rectified z-depths exactly `near..far`:
/// the first disparity and a count of 16 to [`MAX_DISPARITIES`], a multiple of 16.
pub fn exact_disparity_range(rect: &Rectification, near: f64, far: f64) -> (i32, usize) {
    span_to_range(
        rect,
        rect.depth_to_disparity(far),
        rect.depth_to_disparity(near),
    )
}

/// The range from disparity `lo` to `hi` (pixels), never below the disparity at infinity.
fn span_to_range(rect: &Rectification, lo: f64, hi: f64) -> (i32, usize) {
    let lo = lo.floor().max(rect.offset.floor()) as i32;
    let hi = hi.ceil() as i64;
    let count = (hi - lo as i64 + 1).clamp(16, MAX_DISPARITIES as i64) as usize;
    (lo, count.div_ceil(16) * 16)
}

/// The range of rectified pair `rect` (whose left original is `left`, right `right`) from the
/// points both views see in front of them and inside their images: the 1st to 99th percentile
/// of their disparities, widened as a 10 % depth margin on either side would, as
/// [`disparity_range`] widens depth bounds. `None` when fewer than [`MIN_RANGE_POINTS`] are seen
/// by both.
pub fn points_disparity_range(
    rect: &Rectification,
    left: &StereoView,
    right: &StereoView,
    points: &[[f32; 3]],
) -> Option<(i32, usize)> {
    let mut disparities: Vec<f64> = points
        .iter()
        .filter_map(|p| {
            let x = Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            sees(left, &x).then_some(())?;
            sees(right, &x).then_some(())?;
            let (xl, _, zl) = rect.rectified(Side::Left).project(&x)?;
            let (xr, _, zr) = rect.rectified(Side::Right).project(&x)?;
            (zl > 0.0 && zr > 0.0).then_some(xl - xr)
        })
        .filter(|d| d.is_finite() && *d > rect.offset)
        .collect();
    if disparities.len() < MIN_RANGE_POINTS {
        return None;
    }
    let (lo, hi) = central_span(&mut disparities);
    // (d − offset) ∝ 1/z: a far bound 10 % farther, a near bound 10 % nearer.
    let off = rect.offset;
    Some(span_to_range(
        rect,
        off + (lo - off) / 1.1,
        off + (hi - off) / 0.9,
    ))
}

/// The depths of the sparse points both views see, in either camera: the 1st to 99th
/// percentile with a 10 % margin on either side (the depth range of a plane sweep over the
/// pair). `None` below [`MIN_RANGE_POINTS`] points.
pub fn points_depth_range(
    a: &StereoView,
    b: &StereoView,
    points: &[[f32; 3]],
) -> Option<(f64, f64)> {
    let mut depths: Vec<f64> = Vec::new();
    let mut seen = 0;
    for p in points {
        let x = Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
        if sees(a, &x) && sees(b, &x) {
            seen += 1;
            for v in [a, b] {
                depths.push(v.camera.world_to_camera.transform_point(&x).z);
            }
        }
    }
    if seen < MIN_RANGE_POINTS {
        return None;
    }
    let (near, far) = central_span(&mut depths);
    let (near, far) = (near * 0.9, far * 1.1);
    (near > 0.0 && near < far).then_some((near, far))
}

#[cfg(test)]
mod tests {
    use super::*;
    use fewview_scene::{Camera, Image, Intrinsics};

    /// Two cameras 0.2 apart looking at points 2 to 10 units away (and one at 1,000, one behind
    /// the cameras, both outliers or out of view): the range holds the points' disparities.
    #[test]
    fn the_range_holds_the_disparities_of_the_points_both_views_see() {
        let k = Intrinsics::centered(400.0, 320, 240);
        let cam = |x: f64| {
            Camera::look_at(
                k,
                Vector3::new(x, 0.0, 0.0),
                Vector3::new(x, 0.0, 1.0),
                -Vector3::y(),
            )
        };
        let (a, b) = (cam(0.0), cam(0.2));
        let image = Image::new(320, 240, 3);
        let view = |camera| StereoView {
            name: "v",
            camera,
            image: &image,
            depth_bounds: None,
            mask: None,
            sparse_points: &[],
        };
        let (left, right) = (view(&a), view(&b));
        let rect = Rectification::new(&a, &b).unwrap();
        let mut points: Vec<[f32; 3]> = (0..200)
            .map(|i| {
                let z = 2.0 + 8.0 * (i as f32 / 199.0);
                [0.1 + 0.02 * (i % 7) as f32, 0.05, z]
            })
            .collect();
        points.push([0.0, 0.0, -3.0]);
        assert!(points_disparity_range(&rect, &left, &right, &points[..10]).is_none());
        let (lo, count) = points_disparity_range(&rect, &left, &right, &points).unwrap();
        // f·B / z: 40 px at z = 2, 8 px at z = 10 (offset 0 for parallel cameras).
        assert!(rect.offset.abs() < 1e-9);
        let (d_near, d_far) = (400.0 * 0.2 / 2.0, 400.0 * 0.2 / 10.0);
        assert!(lo as f64 <= d_far && d_far - (lo as f64) < 3.0, "lo {lo}");
        let hi = lo as f64 + count as f64 - 1.0;
        assert!(hi >= d_near / 0.99, "hi {hi}");
        assert_eq!(count % 16, 0);
    }
}
