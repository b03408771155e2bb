//! Surface-reconstruction metrics.
//!
//! **DTU protocol** ([`dtu_chamfer`]), as in the DTU evaluation used by IDR, NeuS and the surface paper
//! (`eval.py` of DTUeval-python, after the official MATLAB code): the predicted mesh is sampled
//! at density 0.2 ([`dtu_sample`]), shuffled and radius-down-sampled at the same 0.2
//! ([`radius_downsample`]); the points are restricted to the observation mask's bounding box
//! (enlarged by `patch` = 60 below and 120 above, as the reference does) and then to observed
//! voxels (`ObsMask` lookup at `round((p − BB_min)/Res)`). *Accuracy* is the mean distance from
//! the observed predicted points to the ground-truth points, *completeness* the mean distance
//! from the ground-truth points (optionally only those above the ground plane) to the in-box
//! predicted points, each over distances below `max_dist` = 20; *Chamfer* is their mean.
//! Because of the down-sampling, a mesh compared with its own dense samples has accuracy 0 but
//! completeness ≈ density/2 (≈ 0.1 mm): the protocol's floor.
//! Without an observation mask an optional plain bounding box stands in for it.
//!
//! **Synthetic ground truth** ([`surface_metrics`]): `n` uniform samples on each mesh;
//! accuracy/completeness are mean nearest-sample distances, Chamfer-L1 their mean, F-score@τ
//! the harmonic mean of the fractions within τ (Tatarchenko et al. 2019), normal consistency
//! the mean absolute cosine between each sample's face normal and that of its nearest sample on
//! the other mesh, averaged over both directions (Mescheder et al. 2019).

use serde::Serialize;

use crate::error::{GeomError, Result};
use crate::knn::PointTree;
use crate::mesh::Mesh;
use crate::sampling::{
    check_sample_count, dtu_sample, radius_downsample, sample_surface_with_faces,
};

/// The DTU observation mask (`ObsMask{scan}_10.mat`): a boolean voxel grid `mask[(i·ny + j)·nz
/// + k]` with voxel `(i, j, k)` centred at `bb_min + res·(i, j, k)`.
#[derive(Clone, Debug, PartialEq)]
pub struct ObservationMask {
    pub mask: Vec<bool>,
    pub dims: [usize; 3],
    /// `BB[0]` of the reference file.
    pub bb_min: [f64; 3],
    /// `BB[1]`.
    pub bb_max: [f64; 3],
    /// `Res`.
    pub res: f64,
}

/// Options of [`dtu_chamfer`]; the defaults are the protocol's.
#[derive(Clone, Debug, PartialEq)]
pub struct DtuOptions {
    /// Sampling density and down-sampling radius (0.2 mm).
    pub density: f64,
    /// Distances at or above this are left out of both means (20 mm).
    pub max_dist: f64,
    /// Enlargement of the mask's bounding box (60 mm; the box runs `[BB_min − patch,
    /// BB_max + 2·patch)`).
    pub patch: f64,
    pub obs_mask: Option<ObservationMask>,
    /// Used when there is no observation mask: keep predicted points inside `[min, max]`.
    pub bbox: Option<([f64; 3], [f64; 3])>,
    /// `(a, b, c, d)`: ground-truth points with `a·x + b·y + c·z + d > 0` count for completeness.
    pub ground_plane: Option<[f64; 4]>,
    /// Seed of the shuffle before down-sampling (the reference shuffles unseeded).
    pub seed: u64,
}

impl Default for DtuOptions {
    fn default() -> Self {
        Self {
            density: 0.2,
            max_dist: 20.0,
            patch: 60.0,
            obs_mask: None,
            bbox: None,
            ground_plane: None,
            seed: 0,
        }
    }
}

/// Result of the DTU protocol (units of the inputs, mm for DTU).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DtuChamfer {
    /// Mean distance predicted → ground truth ("d2s").
    pub accuracy: f64,
    /// Mean distance ground truth → predicted ("s2d").
    pub completeness: f64,
    /// `(accuracy + completeness) / 2`.
    pub chamfer: f64,
    /// Predicted points after down-sampling and masking.
    pub predicted_points: usize,
    /// Ground-truth points used for completeness.
    pub ground_truth_points: usize,
}

fn mean_below(d: &[(usize, f64)], max: f64, what: &str) -> Result<f64> {
    let kept: Vec<f64> = d.iter().map(|x| x.1).filter(|&x| x < max).collect();
    if kept.is_empty() {
        return Err(GeomError::invalid(
            what,
            format!("no distance below max_dist {max} (the surfaces do not overlap)"),
        ));
    }
    Ok(kept.iter().sum::<f64>() / kept.len() as f64)
}

/// The DTU protocol for a predicted mesh against ground-truth points (see the module docs).
pub fn dtu_chamfer(
    pred: &Mesh,
    gt_points: &[[f32; 3]],
    options: &DtuOptions,
) -> Result<DtuChamfer> {
    let samples = dtu_sample(pred, options.density)?;
    dtu_chamfer_points(&samples, gt_points, options)
}

/// The DTU protocol from already sampled predicted points (a point-cloud reconstruction):
/// down-sampling, masking and distances.
pub fn dtu_chamfer_points(
    pred: &[[f32; 3]],
    gt_points: &[[f32; 3]],
    options: &DtuOptions,
) -> Result<DtuChamfer> {
    if pred.is_empty() {
        return Err(GeomError::invalid("prediction", "has no points"));
    }
    if gt_points.is_empty() {
        return Err(GeomError::invalid("ground truth", "has no points"));
    }
    for (what, pts) in [("prediction", pred), ("ground truth", gt_points)] {
        if let Some(i) = pts.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
            return Err(GeomError::invalid(what, format!("point {i} is not finite")));
        }
    }
    let down = radius_downsample(pred, options.density, options.seed);
    let inside = |p: &[f32; 3], lo: [f64; 3], hi: [f64; 3], hi_open: bool| {
        (0..3).all(|k| {
            let x = p[k] as f64;
            x >= lo[k] && if hi_open { x < hi[k] } else { x <= hi[k] }
        })
    };
    let (data_in, data_obs): (Vec<[f32; 3]>, Vec<[f32; 3]>) = match &options.obs_mask {
        Some(m) => {
            if m.mask.len() != m.dims.iter().product::<usize>() || !(m.res > 0.0) {
                return Err(GeomError::invalid(
                    "observation mask",
                    "size does not match dims, or res ≤ 0",
                ));
            }
            let lo = m.bb_min.map(|b| b - options.patch);
            let hi = m.bb_max.map(|b| b + 2.0 * options.patch);
            let data_in: Vec<[f32; 3]> = down
                .into_iter()
                .filter(|p| inside(p, lo, hi, true))
                .collect();
            let obs = data_in
                .iter()
                .filter(|p| {
                    let g: [f64; 3] =
                        std::array::from_fn(|k| ((p[k] as f64 - m.bb_min[k]) / m.res).round());
                    if (0..3).any(|k| g[k] < 0.0 || g[k] >= m.dims[k] as f64) {
                        return false;
                    }
                    let [i, j, k] = g.map(|x| x as usize);
                    m.mask[(i * m.dims[1] + j) * m.dims[2] + k]
                })
                .copied()
                .collect();
            (data_in, obs)
        }
        None => {
            let data_in: Vec<[f32; 3]> = match options.bbox {
                Some((lo, hi)) => down
                    .into_iter()
                    .filter(|p| inside(p, lo, hi, false))
                    .collect(),
                None => down,
            };
            (data_in.clone(), data_in)
        }
    };
    if data_obs.is_empty() {
        return Err(GeomError::invalid(
            "prediction",
            "no point left inside the mask / bounding box",
        ));
    }
    let gt_used: Vec<[f32; 3]> = match options.ground_plane {
        Some(pl) => gt_points
            .iter()
            .filter(|p| {
                pl[0] * p[0] as f64 + pl[1] * p[1] as f64 + pl[2] * p[2] as f64 + pl[3] > 0.0
            })
            .copied()
            .collect(),
        None => gt_points.to_vec(),
    };
    let gt_tree = PointTree::new(gt_points);
    let d2s = gt_tree.nearest_many(&data_obs);
    let accuracy = mean_below(&d2s, options.max_dist, "accuracy")?;
    let data_tree = PointTree::new(&data_in);
    let s2d = data_tree.nearest_many(&gt_used);
    let completeness = mean_below(&s2d, options.max_dist, "completeness")?;
    Ok(DtuChamfer {
        accuracy,
        completeness,
        chamfer: 0.5 * (accuracy + completeness),
        predicted_points: data_obs.len(),
        ground_truth_points: gt_used.len(),
    })
}

/// Metrics against a synthetic ground-truth mesh.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SurfaceMetrics {
    pub accuracy: f64,
    pub completeness: f64,
    /// `(accuracy + completeness) / 2`.
    pub chamfer_l1: f64,
    /// Mean of the squared distances, both directions averaged.
    pub chamfer_l2: f64,
    pub normal_consistency: f64,
    /// `(τ, precision, recall, F-score)` for each requested τ.
    pub fscore: Vec<FScore>,
    pub samples: usize,
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct FScore {
    pub tau: f64,
    pub precision: f64,
    pub recall: f64,
    pub fscore: f64,
}

/// Chamfer-L1/L2, F-score@τ and normal consistency from `samples` uniform points per mesh.
pub fn surface_metrics(
    pred: &Mesh,
    gt: &Mesh,
    samples: usize,
    taus: &[f64],
    seed: u64,
) -> Result<SurfaceMetrics> {
    metrics_on(pred, gt, None, samples, taus, seed)
}

/// [`surface_metrics`] on the observed part of a synthetic ground truth, the way the DTU
/// protocol scores only what its scanner saw: `gt_face_observed[f]` says whether some input
/// view sees face `f`. Completeness runs from the samples on observed faces; accuracy from the
/// predicted samples whose nearest ground-truth sample lies on an observed face (a prediction
/// of an unseen part is neither rewarded nor punished).
pub fn surface_metrics_observed(
    pred: &Mesh,
    gt: &Mesh,
    gt_face_observed: &[bool],
    samples: usize,
    taus: &[f64],
    seed: u64,
) -> Result<SurfaceMetrics> {
    if gt_face_observed.len() != gt.faces.len() {
        return Err(GeomError::invalid(
            "observed faces",
            format!(
                "{} flags for {} ground-truth faces",
                gt_face_observed.len(),
                gt.faces.len()
            ),
        ));
    }
    metrics_on(pred, gt, Some(gt_face_observed), samples, taus, seed)
}

fn metrics_on(
    pred: &Mesh,
    gt: &Mesh,
    observed: Option<&[bool]>,
    samples: usize,
    taus: &[f64],
    seed: u64,
) -> Result<SurfaceMetrics> {
    if samples == 0 {
        return Err(GeomError::invalid("samples", "must be at least 1"));
    }
    check_sample_count(samples)?;
    let (pp, pf) = sample_surface_with_faces(pred, samples, seed)
        .map_err(|e| GeomError::invalid("prediction", e.to_string()))?;
    let (gp, gf) = sample_surface_with_faces(gt, samples, seed.wrapping_add(1))
        .map_err(|e| GeomError::invalid("ground truth", e.to_string()))?;
    let seen = |face: u32| observed.is_none_or(|o| o[face as usize]);
    // Completeness: from the (observed) ground-truth samples.
    let (go, gof): (Vec<[f32; 3]>, Vec<u32>) = gp
        .iter()
        .zip(&gf)
        .filter(|(_, f)| seen(**f))
        .map(|(p, f)| (*p, *f))
        .unzip();
    if go.is_empty() {
        return Err(GeomError::invalid(
            "ground truth",
            "no sample lies on an observed face",
        ));
    }
    let g_to_p = PointTree::new(&pp).nearest_many(&go);
    // Accuracy: from the predicted samples that face an observed part.
    let (p_to_g, pkept): (Vec<(usize, f64)>, Vec<u32>) = PointTree::new(&gp)
        .nearest_many(&pp)
        .into_iter()
        .zip(&pf)
        .filter(|((j, _), _)| seen(gf[*j]))
        .map(|(nn, f)| (nn, *f))
        .unzip();
    if p_to_g.is_empty() {
        return Err(GeomError::invalid(
            "prediction",
            "no sample lies near an observed part of the ground truth",
        ));
    }
    let normal = |m: &Mesh, f: u32| m.face_cross(f as usize).normalize();
    let mean = |d: &[(usize, f64)], pow: i32| {
        d.iter().map(|x| x.1.powi(pow)).sum::<f64>() / d.len() as f64
    };
    let accuracy = mean(&p_to_g, 1);
    let completeness = mean(&g_to_p, 1);
    let nc = |from: &Mesh, ff: &[u32], to: &Mesh, tf: &[u32], nn: &[(usize, f64)]| {
        nn.iter()
            .enumerate()
            .map(|(i, &(j, _))| normal(from, ff[i]).dot(&normal(to, tf[j])).abs())
            .filter(|c| c.is_finite())
            .sum::<f64>()
            / nn.len() as f64
    };
    let normal_consistency =
        0.5 * (nc(pred, &pkept, gt, &gf, &p_to_g) + nc(gt, &gof, pred, &pf, &g_to_p));
    let fscore = taus
        .iter()
        .map(|&tau| {
            let frac =
                |d: &[(usize, f64)]| d.iter().filter(|x| x.1 < tau).count() as f64 / d.len() as f64;
            let (precision, recall) = (frac(&p_to_g), frac(&g_to_p));
            let fscore = if precision + recall > 0.0 {
                2.0 * precision * recall / (precision + recall)
            } else {
                0.0
            };
            FScore {
                tau,
                precision,
                recall,
                fscore,
            }
        })
        .collect();
    Ok(SurfaceMetrics {
        accuracy,
        completeness,
        chamfer_l1: 0.5 * (accuracy + completeness),
        chamfer_l2: 0.5 * (mean(&p_to_g, 2) + mean(&g_to_p, 2)),
        normal_consistency,
        fscore,
        samples,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::test_cube;

    /// A `n×n` grid of squares spanning `size` in x and y at height z (mm-like units).
    fn plane(n: usize, size: f32, z: f32) -> Mesh {
        let mut v = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                v.push([i as f32 * size / n as f32, j as f32 * size / n as f32, z]);
            }
        }
        let mut f = Vec::new();
        let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
        for j in 0..n {
            for i in 0..n {
                f.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                f.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        Mesh::new(v, f)
    }

    #[test]
    fn dtu_self_is_zero_and_shift_is_d() {
        let m = plane(10, 30.0, 0.0);
        let gt = dtu_sample(&m, 0.2).unwrap();
        let opts = DtuOptions::default();
        let same = dtu_chamfer(&m, &gt, &opts).unwrap();
        // Accuracy is exactly 0 (the down-sampled points are ground-truth points); completeness
        // keeps the protocol's floor: ground-truth points lie up to one down-sampling radius
        // (0.2) from the nearest kept point, ≈ 0.1 on average.
        assert_eq!(same.accuracy, 0.0);
        assert!(same.completeness < 0.12 && same.chamfer < 0.06, "{same:?}");
        // That floor adds in quadrature to a shift: √(d² + 0.1²) is within 1 % of d for d ≥ 1.
        for d in [1.0f32, 2.0, 7.0] {
            let shifted = plane(10, 30.0, d);
            let r = dtu_chamfer(&shifted, &gt, &opts).unwrap();
            assert!((r.chamfer / d as f64 - 1.0).abs() < 0.01, "d = {d}: {r:?}");
            assert!(
                (r.accuracy / d as f64 - 1.0).abs() < 0.01
                    && (r.completeness / d as f64 - 1.0).abs() < 0.01
            );
        }
        // Past max_dist nothing counts.
        let far = plane(10, 30.0, 25.0);
        assert!(
            dtu_chamfer(&far, &gt, &opts)
                .unwrap_err()
                .to_string()
                .contains("max_dist")
        );
    }

    #[test]
    fn dtu_masks_bbox_and_plane_select_points() {
        let m = plane(10, 30.0, 0.0);
        let gt = dtu_sample(&m, 0.2).unwrap();
        // Prediction: the plane plus a far blob of outliers at 10 mm that a bbox excludes.
        let mut pred = m.clone();
        let base = pred.vertices.len() as u32;
        pred.vertices
            .extend([[5.0, 5.0, 10.0], [6.0, 5.0, 10.0], [5.0, 6.0, 10.0]]);
        pred.faces.push([base, base + 1, base + 2]);
        let with = dtu_chamfer(&pred, &gt, &DtuOptions::default()).unwrap();
        assert!(with.accuracy > 0.01);
        let boxed = DtuOptions {
            bbox: Some(([-1.0; 3], [31.0, 31.0, 1.0])),
            ..Default::default()
        };
        assert!(dtu_chamfer(&pred, &gt, &boxed).unwrap().accuracy < 1e-6);
        // An observation mask that observes only x < 15 (voxels of 1 mm from the origin).
        let dims = [31, 31, 11];
        let mut mask = vec![false; dims.iter().product()];
        for i in 0..15 {
            for j in 0..31 {
                for k in 0..11 {
                    mask[(i * 31 + j) * 11 + k] = k == 0;
                }
            }
        }
        let obs = ObservationMask {
            mask,
            dims,
            bb_min: [0.0; 3],
            bb_max: [30.0, 30.0, 10.0],
            res: 1.0,
        };
        let o = DtuOptions {
            obs_mask: Some(obs),
            ..Default::default()
        };
        let r = dtu_chamfer(&pred, &gt, &o).unwrap();
        assert!(r.accuracy < 1e-6, "the blob at z = 10 is unobserved: {r:?}");
        assert!(r.predicted_points < with.predicted_points / 2 + 10);
        // The ground plane z > 0.5 leaves no ground truth here.
        let p = DtuOptions {
            ground_plane: Some([0.0, 0.0, 1.0, -0.5]),
            ..Default::default()
        };
        assert!(dtu_chamfer(&pred, &gt, &p).is_err());
    }

    #[test]
    fn synthetic_metrics_self_shift_and_normals() {
        let m = plane(8, 1.0, 0.0);
        let s = surface_metrics(&m, &m, 20_000, &[0.01, 0.05], 3).unwrap();
        assert!(s.chamfer_l1 < 0.005, "{s:?}");
        assert!((s.normal_consistency - 1.0).abs() < 1e-9);
        assert!(s.fscore[1].fscore > 0.999);
        let d = 0.1;
        let shifted = plane(8, 1.0, d);
        let r = surface_metrics(&shifted, &m, 20_000, &[0.05, 0.2], 3).unwrap();
        // Nearest samples are √(d² + s²) away with s the sampling gap (≈ 0.004 here).
        assert!((r.chamfer_l1 / d as f64 - 1.0).abs() < 0.01, "{r:?}");
        assert_eq!(r.fscore[0].fscore, 0.0);
        assert_eq!(r.fscore[1].fscore, 1.0);
        // A cube against a plane: normals agree on the bottom only.
        let c = surface_metrics(&test_cube(), &plane(4, 1.0, 0.0), 20_000, &[0.01], 1).unwrap();
        assert!(c.normal_consistency < 0.8);
    }

    /// Two meshes as one; the faces of `b` follow those of `a`.
    fn stacked(a: &Mesh, b: &Mesh) -> Mesh {
        let offset = a.vertices.len() as u32;
        let mut m = a.clone();
        m.vertices.extend(b.vertices.iter().copied());
        m.faces.extend(
            b.faces
                .iter()
                .map(|f| [f[0] + offset, f[1] + offset, f[2] + offset]),
        );
        m
    }

    /// Ground truth: an observed plane at z = 0 and an unobserved one at z = 1. The prediction
    /// is the first shifted by 0.1 plus a guess at z = 1.3 of the unseen part: on the observed
    /// part both directions are 0.1 away; the guess and the unseen plane are not scored.
    #[test]
    fn observed_metrics_score_only_the_observed_part() {
        let gt = stacked(&plane(8, 1.0, 0.0), &plane(8, 1.0, 1.0));
        let half = gt.faces.len() / 2;
        let observed: Vec<bool> = (0..gt.faces.len()).map(|f| f < half).collect();
        let pred = stacked(&plane(8, 1.0, 0.1), &plane(8, 1.0, 1.3));
        let o = surface_metrics_observed(&pred, &gt, &observed, 20_000, &[0.2], 3).unwrap();
        assert!((o.accuracy / 0.1 - 1.0).abs() < 0.01, "{o:?}");
        assert!((o.completeness / 0.1 - 1.0).abs() < 0.01, "{o:?}");
        assert_eq!(o.fscore[0].fscore, 1.0);
        // Everything scored: the guess is 0.3 off the unseen plane.
        let all = surface_metrics(&pred, &gt, 20_000, &[0.2], 3).unwrap();
        assert!((all.accuracy / 0.2 - 1.0).abs() < 0.02, "{all:?}");
        // Every face observed gives the plain metrics.
        let every = vec![true; gt.faces.len()];
        let same = surface_metrics_observed(&pred, &gt, &every, 20_000, &[0.2], 3).unwrap();
        assert_eq!(same, all);
        let err = surface_metrics_observed(&pred, &gt, &observed[1..], 100, &[0.2], 3)
            .unwrap_err()
            .to_string();
        assert!(err.contains("flags for"), "{err}");
    }
}
