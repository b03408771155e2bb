//! Errors of the relative poses between every pair of views: what no choice of world frame or
//! scale changes, so they need no alignment (structure-from-motion papers report them beside
//! the aligned errors, e.g. as relative rotation and translation-direction accuracy).
//!
//! For views `i < j` with world-to-camera poses `(R, t)`, the relative rotation is
//! `R_ij = R_j R_iᵀ` and the baseline direction, in view `i`'s frame, is
//! `R_i (c_j − c_i) / ‖c_j − c_i‖` with `c = −Rᵀ t`. The rotation error is the angle of
//! `R_ij,found R_ij,trueᵀ`; the direction error the angle between the two unit baselines.

use fewview_geom::similarity::rotation_angle_deg;
use fewview_scene::Se3;
use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

use crate::pose_error::PoseErrorError;

/// The relative-pose errors of every pair of views (degrees).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RelativeErrors {
    /// Pairs compared (pairs whose true or found centres coincide have no direction and are
    /// left out of the direction figures).
    pub pairs: usize,
    pub rotation_median_deg: f64,
    pub rotation_max_deg: f64,
    pub direction_median_deg: f64,
    pub direction_max_deg: f64,
}

/// The relative-pose errors of `found` against `truth` (the same views in the same order).
pub fn relative_errors(found: &[Se3], truth: &[Se3]) -> Result<RelativeErrors, PoseErrorError> {
    if found.len() != truth.len() || found.len() < 2 {
        return Err(PoseErrorError::Invalid(format!(
            "relative errors need the same views, at least two: {} found, {} true",
            found.len(),
            truth.len()
        )));
    }
    let (mut rotations, mut directions) = (Vec::new(), Vec::new());
    for i in 0..found.len() {
        for j in i + 1..found.len() {
            let (rf, bf) = relative(&found[i], &found[j]);
            let (rt, bt) = relative(&truth[i], &truth[j]);
            rotations.push(rotation_angle_deg(&(rf * rt.transpose())));
            if let (Some(bf), Some(bt)) = (bf, bt) {
                directions.push(bf.angle(&bt).to_degrees());
            }
        }
    }
    let pairs = rotations.len();
    let (rotation_median_deg, rotation_max_deg) = median_and_max(rotations);
    let (direction_median_deg, direction_max_deg) = median_and_max(directions);
    Ok(RelativeErrors {
        pairs,
        rotation_median_deg,
        rotation_max_deg,
        direction_median_deg,
        direction_max_deg,
    })
}

/// `R_j R_iᵀ` and the unit baseline from `i` to `j` in `i`'s frame (`None` when the centres
/// coincide).
fn relative(i: &Se3, j: &Se3) -> (Matrix3<f64>, Option<Vector3<f64>>) {
    let baseline = i.rotation * (j.inverse().translation - i.inverse().translation);
    let norm = baseline.norm();
    let direction = (norm > 1e-12 * (1.0 + i.translation.norm())).then(|| baseline / norm);
    (j.rotation * i.rotation.transpose(), direction)
}

/// The median (the mean of the middle two for an even count) and the largest; 0 for none.
fn median_and_max(mut values: Vec<f64>) -> (f64, f64) {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    let median = match n {
        0 => 0.0,
        _ if n % 2 == 1 => values[n / 2],
        _ => 0.5 * (values[n / 2 - 1] + values[n / 2]),
    };
    (median, values.last().copied().unwrap_or(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    fn pose(axis: Vector3<f64>, degrees: f64, centre: Vector3<f64>) -> Se3 {
        let r =
            Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), degrees.to_radians())
                .into_inner();
        Se3::new(r, -(r * centre))
    }

    fn rig() -> Vec<Se3> {
        vec![
            pose(Vector3::y(), 0.0, Vector3::new(0.0, 0.0, 0.0)),
            pose(Vector3::y(), -10.0, Vector3::new(1.0, 0.1, 0.0)),
            pose(
                Vector3::new(0.2, 1.0, 0.1),
                -20.0,
                Vector3::new(2.0, -0.1, 0.3),
            ),
        ]
    }

    #[test]
    fn a_similarity_of_the_world_changes_nothing() {
        let truth = rig();
        // x ↦ s R x + t: world-to-camera (R_c, t_c) becomes (R_c Rᵀ, s t_c − R_c Rᵀ t).
        let r = Rotation3::from_euler_angles(0.3, -0.2, 0.5).into_inner();
        let (s, t) = (3.5, Vector3::new(-1.0, 2.0, 0.5));
        let moved: Vec<Se3> = truth
            .iter()
            .map(|p| {
                let rc = p.rotation * r.transpose();
                Se3::new(rc, s * p.translation - rc * t)
            })
            .collect();
        let e = relative_errors(&moved, &truth).unwrap();
        assert_eq!(e.pairs, 3);
        assert!(e.rotation_max_deg < 1e-6, "{e:?}");
        assert!(e.direction_max_deg < 1e-6, "{e:?}");
    }

    #[test]
    fn one_view_turned_shows_in_its_two_pairs() {
        let truth = rig();
        let mut found = truth.clone();
        // Turn view 2 by 2° about its own optical axis, keeping its centre.
        let c = found[2].inverse().translation;
        let turn = Rotation3::from_axis_angle(&Vector3::z_axis(), 2f64.to_radians()).into_inner();
        let r = turn * found[2].rotation;
        found[2] = Se3::new(r, -(r * c));
        let e = relative_errors(&found, &truth).unwrap();
        // Pairs (0, 2) and (1, 2) are 2° off, pair (0, 1) exact: median 2°, maximum 2°.
        assert!((e.rotation_max_deg - 2.0).abs() < 1e-9, "{e:?}");
        assert!((e.rotation_median_deg - 2.0).abs() < 1e-9, "{e:?}");
        // Directions are measured in the first view of each pair, whose frame did not turn,
        // except (2, _), which has no pair here: all exact.
        assert!(e.direction_max_deg < 1e-6, "{e:?}");
        assert!(relative_errors(&found[..1], &truth[..1]).is_err());
    }
}
