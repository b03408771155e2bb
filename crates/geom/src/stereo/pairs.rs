//! Which training views form stereo pairs (the fusion paper §2): the views ordered along their common
//! baseline, each with the next, and the two ends together when they still overlap.

use fewview_scene::{Camera, Image};
use nalgebra::{Matrix3, Vector3};

use crate::error::{GeomError, Result};

/// A training view as the stereo start sees it.
#[derive(Clone, Copy, Debug)]
pub struct StereoView<'a> {
    pub name: &'a str,
    pub camera: &'a Camera,
    pub image: &'a Image,
    /// Near and far z-depth of the scene in this view, when the dataset knows them (LLFF).
    pub depth_bounds: Option<(f64, f64)>,
    /// Where the image shows the scene (1) and where only its background (0): the alpha of an
    /// RGBA capture. Pixels below 0.5 get no depth.
    pub mask: Option<&'a Image>,
    /// The scene's sparse structure-from-motion points (all of them, empty when the dataset has
    /// none), from which a pair's disparity range is taken
    /// ([`super::range::DisparityRange::FromSparsePoints`]).
    pub sparse_points: &'a [[f32; 3]],
}

impl<'a> StereoView<'a> {
    /// A dataset view: its name, camera, image, depth bounds, and its mask when that is the
    /// image's alpha (a mask drawn around an object, as DTU's, leaves the background in).
    pub fn of(view: &'a fewview_scene::View) -> Self {
        Self {
            name: &view.name,
            camera: &view.camera,
            image: &view.image,
            depth_bounds: view.depth_bounds,
            mask: view.mask.as_ref().filter(|_| view.mask_is_alpha),
            sparse_points: &[],
        }
    }
}

/// How much two views must share to be matched.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OverlapRule {
    /// Smallest fraction of the first view's pixels whose scene point (at the typical depth)
    /// projects into the second view.
    pub min_fraction: f64,
    /// Largest angle between the two optical axes (degrees): beyond it the views see surfaces
    /// too differently for block matching.
    pub max_angle_deg: f64,
}

impl Default for OverlapRule {
    fn default() -> Self {
        Self {
            min_fraction: 0.3,
            max_angle_deg: 45.0,
        }
    }
}

/// The typical z-depth of the scene in a view: the geometric mean of its depth bounds, else the
/// distance along its axis to the point all views look at.
pub fn typical_depth(view: &StereoView, look_at: &Vector3<f64>) -> f64 {
    match view.depth_bounds {
        Some((near, far)) => (near * far).sqrt(),
        None => {
            let z = view.camera.world_to_camera.transform_point(look_at).z;
            if z > 0.0 {
                z
            } else {
                (view.camera.center() - look_at).norm()
            }
        }
    }
}

/// `views` with every missing depth bound filled in: from the sparse points the view sees
/// ([`points_depth_bounds`]), else as half to twice its [`typical_depth`] (the
/// distance to the point the views look at), a wide guess for scenes whose loaders give no
/// bounds (NeRF-synthetic, DTU).
pub fn with_depth_bounds<'a>(views: &[StereoView<'a>]) -> Vec<StereoView<'a>> {
    let poses: Vec<_> = views.iter().map(|v| v.camera.world_to_camera).collect();
    let look_at = fewview_scene::axes_meeting_point(&poses);
    views
        .iter()
        .map(|v| {
            let t = typical_depth(v, &look_at);
            StereoView {
                depth_bounds: v
                    .depth_bounds
                    .or_else(|| points_depth_bounds(v))
                    .or(Some((0.5 * t, 2.0 * t))),
                ..*v
            }
        })
        .collect()
}

/// The fewest sparse points a view (or both views of a pair) must see for depth bounds or a
/// disparity range to be taken from them.
pub const MIN_RANGE_POINTS: usize = 20;

/// The 1st and 99th percentile of the z-depths of the sparse points `view` sees (in front of it
/// and inside its image): the scene's depth bounds in that view, as LLFF's `imgs2poses` takes
/// them from the points a photo observes. `None` below [`MIN_RANGE_POINTS`] points.
pub fn points_depth_bounds(view: &StereoView) -> Option<(f64, f64)> {
    let mut depths: Vec<f64> = view
        .sparse_points
        .iter()
        .filter_map(|p| {
            let x = Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
            sees(view, &x).then(|| view.camera.world_to_camera.transform_point(&x).z)
        })
        .collect();
    if depths.len() < MIN_RANGE_POINTS {
        return None;
    }
    let (near, far) = central_span(&mut depths);
    (near > 0.0 && near < far).then_some((near, far))
}

/// The 1st and 99th percentiles (nearest rank) of `values`, which must not be empty: the span
/// of a view's or a pair's points with their outliers left out.
pub(crate) fn central_span(values: &mut [f64]) -> (f64, f64) {
    values.sort_by(f64::total_cmp);
    let at = |q: f64| values[((values.len() - 1) as f64 * q).round() as usize];
    (at(0.01), at(0.99))
}

/// Whether `x` lies in front of `view`'s camera and projects inside its image.
pub fn sees(view: &StereoView, x: &Vector3<f64>) -> bool {
    let (w, h) = (view.camera.width() as f64, view.camera.height() as f64);
    view.camera
        .project(x)
        .is_some_and(|(u, v, z)| z > 0.0 && (0.0..w).contains(&u) && (0.0..h).contains(&v))
}

/// The fraction of `a`'s pixels (on a 32×24 grid) whose point at z-depth `depth` lands inside
/// `b`'s image.
pub fn overlap_fraction(a: &Camera, b: &Camera, depth: f64) -> f64 {
    let (nx, ny) = (32, 24);
    let (w, h) = (a.width() as f64, a.height() as f64);
    let (bw, bh) = (b.width() as f64, b.height() as f64);
    let mut inside = 0;
    for j in 0..ny {
        for i in 0..nx {
            let u = (i as f64 + 0.5) / nx as f64 * w;
            let v = (j as f64 + 0.5) / ny as f64 * h;
            let x = a.unproject(u, v, depth);
            if let Some((bu, bv, _)) = b.project(&x)
                && (0.0..bw).contains(&bu)
                && (0.0..bh).contains(&bv)
            {
                inside += 1;
            }
        }
    }
    inside as f64 / (nx * ny) as f64
}

/// The angle between two optical axes, in degrees.
pub fn axis_angle_deg(a: &Camera, b: &Camera) -> f64 {
    a.forward()
        .dot(&b.forward())
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

/// Indices of `cameras` sorted along the main direction of their centres (the first principal
/// axis), from one end of the rig to the other.
pub fn order_along_baseline(cameras: &[&Camera]) -> Vec<usize> {
    let centres: Vec<Vector3<f64>> = cameras.iter().map(|c| c.center()).collect();
    let n = centres.len().max(1) as f64;
    let mean = centres.iter().sum::<Vector3<f64>>() / n;
    let scatter: Matrix3<f64> = centres
        .iter()
        .map(|c| (c - mean) * (c - mean).transpose())
        .sum();
    let eig = scatter.symmetric_eigen();
    let k = eig.eigenvalues.imax();
    let axis = eig.eigenvectors.column(k).into_owned();
    let mut order: Vec<usize> = (0..cameras.len()).collect();
    order.sort_by(|&i, &j| {
        let (a, b) = (
            (centres[i] - mean).dot(&axis),
            (centres[j] - mean).dot(&axis),
        );
        a.total_cmp(&b).then(i.cmp(&j))
    });
    order
}

/// Checks that views `a` and `b` overlap under `rule`; the error names both views.
pub fn check_overlap(
    a: &StereoView,
    b: &StereoView,
    look_at: &Vector3<f64>,
    rule: &OverlapRule,
) -> Result<()> {
    let angle = axis_angle_deg(a.camera, b.camera);
    let fraction = overlap_fraction(a.camera, b.camera, typical_depth(a, look_at));
    if angle > rule.max_angle_deg || fraction < rule.min_fraction {
        return Err(GeomError::invalid(
            format!("views {} and {}", a.name, b.name),
            format!(
                "they do not overlap enough for stereo ({:.0} % of {} lands in {}, axes {angle:.0}° \
                 apart; need {:.0} % and at most {:.0}°)",
                100.0 * fraction,
                a.name,
                b.name,
                100.0 * rule.min_fraction,
                rule.max_angle_deg
            ),
        ));
    }
    Ok(())
}

/// The stereo pairs of a set of training views: consecutive views along the baseline, plus the
/// two ends when they overlap (with three views: (1, 2), (2, 3) and (1, 3)).
///
/// When two consecutive views do not overlap (a rig around an object rather than along a line,
/// such as NeRF-synthetic's views on a sphere), each view is paired instead with the view whose
/// optical axis is closest to its own among those it overlaps, and views that overlap none are
/// left out. Two views that do not overlap at all are an error naming them.
pub fn stereo_pairs(views: &[StereoView], rule: &OverlapRule) -> Result<Vec<(usize, usize)>> {
    match pairs_along_baseline(views, rule)? {
        Ok(pairs) => Ok(pairs),
        Err(failure) => {
            let look_at = look_at_point(views);
            let overlaps = |a: usize, b: usize| check_overlap(&views[a], &views[b], &look_at, rule);
            let nearest = nearest_overlapping(views, &overlaps);
            if nearest.is_empty() {
                Err(failure)
            } else {
                Ok(nearest)
            }
        }
    }
}

fn look_at_point(views: &[StereoView]) -> Vector3<f64> {
    let poses: Vec<_> = views.iter().map(|v| v.camera.world_to_camera).collect();
    fewview_scene::axes_meeting_point(&poses)
}

/// The pairs of views set along a line (consecutive views along the baseline and, when they
/// overlap, the two ends), or the error naming the first consecutive views that do not overlap.
/// The outer error is for fewer than two views.
pub fn pairs_along_baseline(
    views: &[StereoView],
    rule: &OverlapRule,
) -> Result<std::result::Result<Vec<(usize, usize)>, GeomError>> {
    if views.len() < 2 {
        return Err(GeomError::invalid(
            "training views",
            format!("stereo needs at least 2 views, got {}", views.len()),
        ));
    }
    let cameras: Vec<&Camera> = views.iter().map(|v| v.camera).collect();
    let look_at = look_at_point(views);
    let order = order_along_baseline(&cameras);
    let overlaps = |a: usize, b: usize| check_overlap(&views[a], &views[b], &look_at, rule);
    let mut pairs = Vec::new();
    for w in order.windows(2) {
        if let Err(e) = overlaps(w[0], w[1]) {
            return Ok(Err(e));
        }
        pairs.push((w[0], w[1]));
    }
    let (first, last) = (order[0], order[order.len() - 1]);
    if order.len() > 2 && overlaps(first, last).is_ok() {
        pairs.push((first, last));
    }
    Ok(Ok(pairs))
}

/// Each view with the overlapping view whose optical axis is closest to its own; each pair once.
fn nearest_overlapping(
    views: &[StereoView],
    overlaps: &dyn Fn(usize, usize) -> Result<()>,
) -> Vec<(usize, usize)> {
    let mut pairs = Vec::new();
    for a in 0..views.len() {
        let mut others: Vec<usize> = (0..views.len()).filter(|&b| b != a).collect();
        others.sort_by(|&b, &c| {
            let (ab, ac) = (
                axis_angle_deg(views[a].camera, views[b].camera),
                axis_angle_deg(views[a].camera, views[c].camera),
            );
            ab.total_cmp(&ac)
        });
        if let Some(&b) = others.iter().find(|&&b| overlaps(a, b).is_ok()) {
            let pair = (a.min(b), a.max(b));
            if !pairs.contains(&pair) {
                pairs.push(pair);
            }
        }
    }
    pairs
}

#[cfg(test)]
mod tests {
    use super::*;
    use fewview_scene::Intrinsics;

    fn camera_at(x: f64, yaw_deg: f64) -> Camera {
        let eye = Vector3::new(x, 0.0, -5.0);
        let target =
            eye + Vector3::new(yaw_deg.to_radians().sin(), 0.0, yaw_deg.to_radians().cos());
        Camera::look_at(
            Intrinsics::centered(300.0, 320, 240),
            eye,
            target,
            Vector3::new(0.0, -1.0, 0.0),
        )
    }

    fn view<'a>(name: &'a str, camera: &'a Camera, image: &'a Image) -> StereoView<'a> {
        StereoView {
            name,
            camera,
            image,
            depth_bounds: Some((3.0, 8.0)),
            mask: None,
            sparse_points: &[],
        }
    }

    #[test]
    fn views_are_ordered_along_the_rig_and_paired_with_their_neighbours() {
        let image = Image::new(320, 240, 3);
        let cams = [
            camera_at(0.4, 0.0),
            camera_at(-0.4, 0.0),
            camera_at(0.0, 0.0),
        ];
        let names = ["a", "b", "c"];
        let views: Vec<_> = (0..3).map(|i| view(names[i], &cams[i], &image)).collect();
        let refs: Vec<&Camera> = cams.iter().collect();
        let order = order_along_baseline(&refs);
        assert!(
            order == vec![1, 2, 0] || order == vec![0, 2, 1],
            "{order:?}"
        );
        let pairs = stereo_pairs(&views, &OverlapRule::default()).unwrap();
        assert_eq!(pairs.len(), 3, "{pairs:?}");
        assert!(pairs.contains(&(order[0], order[1])) && pairs.contains(&(order[1], order[2])));
        assert!(pairs.contains(&(order[0], order[2])));
    }

    #[test]
    fn views_that_do_not_overlap_are_named() {
        let image = Image::new(320, 240, 3);
        // Two cameras side by side looking away from each other.
        let cams = [camera_at(0.0, -60.0), camera_at(1.0, 60.0)];
        let views = [
            view("left", &cams[0], &image),
            view("right", &cams[1], &image),
        ];
        let e = stereo_pairs(&views, &OverlapRule::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("views left and right") && e.contains("overlap"),
            "{e}"
        );
        // Far apart sideways, looking straight ahead: no shared pixels at the scene's depth.
        let cams = [camera_at(0.0, 0.0), camera_at(50.0, 0.0)];
        let views = [view("a", &cams[0], &image), view("b", &cams[1], &image)];
        let e = stereo_pairs(&views, &OverlapRule::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("0 % of a lands in b"), "{e}");
    }

    #[test]
    fn views_around_an_object_pair_with_their_nearest_neighbours() {
        // Six cameras on a circle around the origin, 60° apart, in scrambled order: consecutive
        // views along the main axis face each other across the circle, so each view is paired
        // with a neighbour on the circle instead.
        let image = Image::new(320, 240, 3);
        let angles = [0.0f64, 180.0, 60.0, 240.0, 120.0, 300.0];
        let cams: Vec<Camera> = angles
            .iter()
            .map(|a| {
                let eye =
                    Vector3::new(4.0 * a.to_radians().sin(), 0.0, -4.0 * a.to_radians().cos());
                Camera::look_at(
                    Intrinsics::centered(200.0, 320, 240),
                    eye,
                    Vector3::zeros(),
                    Vector3::new(0.0, -1.0, 0.0),
                )
            })
            .collect();
        let names = ["a", "b", "c", "d", "e", "f"];
        let views: Vec<_> = (0..6).map(|i| view(names[i], &cams[i], &image)).collect();
        let rule = OverlapRule {
            max_angle_deg: 70.0,
            ..Default::default()
        };
        let pairs = stereo_pairs(&views, &rule).unwrap();
        assert!(!pairs.is_empty());
        for &(a, b) in &pairs {
            let apart = (angles[a] - angles[b]).abs();
            assert!(apart == 60.0 || apart == 300.0, "{a}, {b}: {apart}°");
        }
        let paired: std::collections::HashSet<usize> =
            pairs.iter().flat_map(|&(a, b)| [a, b]).collect();
        assert_eq!(paired.len(), 6, "{pairs:?}");
    }

    #[test]
    fn overlap_fraction_of_a_half_shifted_view_is_a_half() {
        // Shifted by half the frustum's width at depth 5: half of the pixels land inside.
        let a = camera_at(0.0, 0.0);
        let half_width = 5.0 * 160.0 / 300.0;
        let b = camera_at(half_width, 0.0);
        let f = overlap_fraction(&a, &b, 5.0);
        assert!((f - 0.5).abs() < 0.02, "{f}");
    }
}
