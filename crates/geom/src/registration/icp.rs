//! Iterative closest point with Open3D's semantics (`registration_icp`): correspondences are
//! nearest target points within `max_correspondence_distance` of the transformed source; fitness
//! = correspondences / source points, inlier RMSE = RMS distance over them; iteration stops
//! after `max_iteration` steps or when both fitness and RMSE change by less than
//! `relative_fitness` / `relative_rmse` (absolute differences, as Open3D compares them).

use nalgebra::{Matrix6, Rotation3, Vector3, Vector6};
use rayon::prelude::*;
use serde::Serialize;

use crate::error::{GeomError, Result};
use crate::knn::PointTree;
use crate::mesh::v3;
use crate::similarity::{Similarity, umeyama};

/// What ICP minimises.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum IcpMethod {
    /// `Σ ‖T s − t‖²` (Besl & McKay), optionally with a scale (Umeyama).
    PointToPoint { with_scaling: bool },
    /// `Σ ((T s − t)·n_t)²` (Chen & Medioni), linearised; needs target normals.
    PointToPlane,
}

impl IcpMethod {
    /// The method with point-to-point's scale estimation set to `scaling` (point-to-plane
    /// estimates no scale and stays as it is).
    pub fn with_scaling(self, scaling: bool) -> Self {
        match self {
            Self::PointToPoint { .. } => Self::PointToPoint {
                with_scaling: scaling,
            },
            other => other,
        }
    }
}

/// The command line names the two objectives; point-to-point's scale is a flag of its own
/// (see [`IcpMethod::with_scaling`]).
#[cfg(feature = "cli")]
impl clap::ValueEnum for IcpMethod {
    fn value_variants<'a>() -> &'a [Self] {
        &[
            Self::PointToPoint {
                with_scaling: false,
            },
            Self::PointToPlane,
        ]
    }

    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        use clap::builder::PossibleValue;
        Some(match self {
            Self::PointToPoint { .. } => PossibleValue::new("point-to-point")
                .help("Σ ‖T s − t‖² (Besl & McKay), with a scale under --with-scaling"),
            Self::PointToPlane => PossibleValue::new("point-to-plane")
                .help("Σ ((T s − t)·n_t)² (Chen & Medioni); needs target normals"),
        })
    }
}

/// Open3D's `ICPConvergenceCriteria` (its defaults).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct IcpCriteria {
    pub relative_fitness: f64,
    pub relative_rmse: f64,
    pub max_iteration: usize,
}

impl Default for IcpCriteria {
    fn default() -> Self {
        Self {
            relative_fitness: 1e-6,
            relative_rmse: 1e-6,
            max_iteration: 30,
        }
    }
}

/// Fitness and RMSE of a transform, as Open3D's `evaluate_registration`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Evaluation {
    pub fitness: f64,
    pub inlier_rmse: f64,
    pub correspondences: usize,
}

/// Result of ICP.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct IcpResult {
    pub transformation: Similarity,
    pub evaluation: Evaluation,
    pub iterations: usize,
}

fn correspondences(
    source: &[Vector3<f64>],
    target_tree: &PointTree,
    max_dist: f64,
) -> Vec<(usize, usize, f64)> {
    source
        .par_iter()
        .enumerate()
        .filter_map(|(i, s)| {
            let (j, d) = target_tree.nearest64(&[s.x, s.y, s.z]);
            (d <= max_dist).then_some((i, j, d))
        })
        .collect()
}

fn evaluate_corr(n_source: usize, corr: &[(usize, usize, f64)]) -> Evaluation {
    let n = corr.len();
    Evaluation {
        fitness: if n_source == 0 {
            0.0
        } else {
            n as f64 / n_source as f64
        },
        inlier_rmse: if n == 0 {
            0.0
        } else {
            (corr.iter().map(|c| c.2 * c.2).sum::<f64>() / n as f64).sqrt()
        },
        correspondences: n,
    }
}

/// Open3D's `evaluate_registration`.
pub fn evaluate_registration(
    source: &[[f32; 3]],
    target: &[[f32; 3]],
    max_dist: f64,
    transform: &Similarity,
) -> Evaluation {
    let tree = PointTree::new(target);
    let moved: Vec<Vector3<f64>> = source.iter().map(|p| transform.apply(&v3(p))).collect();
    evaluate_corr(source.len(), &correspondences(&moved, &tree, max_dist))
}

/// Evaluation against a prebuilt target tree (used inside RANSAC).
pub(crate) fn evaluate_with_tree(
    source: &[Vector3<f64>],
    tree: &PointTree,
    max_dist: f64,
    transform: &Similarity,
) -> Evaluation {
    let moved: Vec<Vector3<f64>> = source.iter().map(|p| transform.apply(p)).collect();
    evaluate_corr(source.len(), &correspondences(&moved, tree, max_dist))
}

/// ICP from `init`; `target_normals` are needed for point-to-plane.
pub fn icp(
    source: &[[f32; 3]],
    target: &[[f32; 3]],
    target_normals: Option<&[[f32; 3]]>,
    max_correspondence_distance: f64,
    init: &Similarity,
    method: IcpMethod,
    criteria: &IcpCriteria,
) -> Result<IcpResult> {
    if source.is_empty() || target.is_empty() {
        return Err(GeomError::invalid("ICP", "source or target has no points"));
    }
    if !(max_correspondence_distance > 0.0) {
        return Err(GeomError::invalid(
            "max correspondence distance",
            format!("{max_correspondence_distance} must be positive"),
        ));
    }
    let normals = match method {
        IcpMethod::PointToPlane => Some(
            target_normals
                .filter(|n| n.len() == target.len())
                .ok_or_else(|| {
                    GeomError::invalid("ICP", "point-to-plane needs one normal per target point")
                })?,
        ),
        IcpMethod::PointToPoint { .. } => None,
    };
    let tree = PointTree::new(target);
    let src: Vec<Vector3<f64>> = source.iter().map(v3).collect();
    let mut t = *init;
    let mut moved: Vec<Vector3<f64>> = src.iter().map(|p| t.apply(p)).collect();
    let mut corr = correspondences(&moved, &tree, max_correspondence_distance);
    let mut eval = evaluate_corr(src.len(), &corr);
    let mut iterations = 0;
    for _ in 0..criteria.max_iteration {
        if corr.len() < 3 {
            break;
        }
        let update = match method {
            IcpMethod::PointToPoint { with_scaling } => {
                let a: Vec<Vector3<f64>> = corr.iter().map(|c| moved[c.0]).collect();
                let b: Vec<Vector3<f64>> = corr.iter().map(|c| v3(&target[c.1])).collect();
                match umeyama(&a, &b, with_scaling) {
                    Ok(u) => u,
                    Err(_) => break,
                }
            }
            IcpMethod::PointToPlane => {
                let nrm = normals.unwrap_or(&[]);
                let mut ata = Matrix6::<f64>::zeros();
                let mut atb = Vector6::<f64>::zeros();
                for c in &corr {
                    let s = moved[c.0];
                    let q = v3(&target[c.1]);
                    let n = v3(&nrm[c.1]);
                    let row =
                        Vector6::new(s.cross(&n).x, s.cross(&n).y, s.cross(&n).z, n.x, n.y, n.z);
                    let r = (s - q).dot(&n);
                    ata += row * row.transpose();
                    atb -= row * r;
                }
                let Some(x) = ata.cholesky().map(|c| c.solve(&atb)) else {
                    break;
                };
                let omega = Vector3::new(x[0], x[1], x[2]);
                Similarity::new(
                    1.0,
                    Rotation3::new(omega).into_inner(),
                    Vector3::new(x[3], x[4], x[5]),
                )
            }
        };
        t = update.compose(&t);
        moved = src.iter().map(|p| t.apply(p)).collect();
        iterations += 1;
        let prev = eval;
        corr = correspondences(&moved, &tree, max_correspondence_distance);
        eval = evaluate_corr(src.len(), &corr);
        if (prev.fitness - eval.fitness).abs() < criteria.relative_fitness
            && (prev.inlier_rmse - eval.inlier_rmse).abs() < criteria.relative_rmse
        {
            break;
        }
    }
    Ok(IcpResult {
        transformation: t,
        evaluation: eval,
        iterations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::similarity::tests::random_similarity;
    use rand::{RngExt, SeedableRng};

    fn cloud() -> Vec<[f32; 3]> {
        // A wavy surface patch: enough structure to pin all six degrees of freedom.
        (0..40)
            .flat_map(|i| {
                (0..40).map(move |j| {
                    let (x, y) = (i as f32 * 0.025, j as f32 * 0.025);
                    [x, y, 0.2 * (6.0 * x).sin() * (5.0 * y).cos()]
                })
            })
            .collect()
    }

    #[test]
    fn point_to_point_and_plane_recover_a_small_motion() {
        let target = cloud();
        let truth = Similarity::new(
            1.0,
            Rotation3::from_euler_angles(0.03, -0.02, 0.04).into_inner(),
            Vector3::new(0.01, -0.02, 0.015),
        );
        // source = truth⁻¹(target), so registering source onto target must return `truth`.
        let source = truth.inverse().apply_points(&target);
        let normals = crate::registration::features::estimate_normals(
            &crate::mesh::Points::from_positions(target.clone()),
            0.08,
            30,
        );
        let crit = IcpCriteria {
            max_iteration: 100,
            ..Default::default()
        };
        for method in [
            IcpMethod::PointToPoint {
                with_scaling: false,
            },
            IcpMethod::PointToPlane,
        ] {
            let r = icp(
                &source,
                &target,
                Some(&normals),
                0.1,
                &Similarity::identity(),
                method,
                &crit,
            )
            .unwrap();
            let err = (r.transformation.rotation - truth.rotation).norm();
            assert!(err < 1e-3, "{method:?}: rotation error {err}");
            assert!((r.transformation.translation - truth.translation).norm() < 1e-3);
            assert!(r.evaluation.fitness > 0.95);
        }
        // With scaling.
        let scaled = Similarity::new(1.03, truth.rotation, truth.translation);
        let source = scaled.inverse().apply_points(&target);
        let r = icp(
            &source,
            &target,
            None,
            0.1,
            &Similarity::identity(),
            IcpMethod::PointToPoint { with_scaling: true },
            &crit,
        )
        .unwrap();
        assert!(
            (r.transformation.scale - 1.03).abs() < 1e-3,
            "{}",
            r.transformation.scale
        );
    }

    #[test]
    fn evaluation_counts_inliers() {
        let target = cloud();
        let mut rng = rand::rngs::StdRng::seed_from_u64(1);
        let t = random_similarity(4);
        let mut source = t.inverse().apply_points(&target);
        // Push a quarter of the points far away.
        for p in source.iter_mut().take(400) {
            p[2] += 10.0 + rng.random::<f32>();
        }
        let e = evaluate_registration(&source, &target, 1e-3, &t);
        assert_eq!(e.correspondences, 1600 - 400);
        assert!((e.fitness - 0.75).abs() < 1e-12);
        assert!(e.inlier_rmse < 1e-5);
    }
}
