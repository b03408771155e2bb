//! The warm-up's solver: Sampson distances (plain or scaled by each match's covariance),
//! Cauchy weights, and Levenberg–Marquardt annealed over halving scales ([`anneal`]).

use fewview_scene::{Intrinsics, Se3};
use nalgebra::{DMatrix, DVector};

use super::options::WarmupOptions;
use crate::matching::fundamental::sampson_signed;
use crate::matching::{Match, fundamental_from_cameras};
use crate::pose::se3_exp;

/// Poses after the update `ξ` (6 numbers per view).
pub(super) fn apply(poses: &[Se3], xi: &[f64]) -> Vec<Se3> {
    poses
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let d: [f64; 6] = std::array::from_fn(|k| xi[6 * i + k]);
            se3_exp(&d).compose(p)
        })
        .collect()
}

/// Unweighted Sampson distances of all matches under `poses`.
pub(super) fn distances(poses: &[Se3], intrinsics: &[Intrinsics], matches: &[Match]) -> Vec<f64> {
    let n = poses.len();
    let mut fs = vec![None; n * n];
    matches
        .iter()
        .map(|m| {
            let key = m.view_a * n + m.view_b;
            let f = *fs[key].get_or_insert_with(|| {
                let ca = fewview_scene::Camera::new(intrinsics[m.view_a], poses[m.view_a]);
                let cb = fewview_scene::Camera::new(intrinsics[m.view_b], poses[m.view_b]);
                fundamental_from_cameras(&ca, &cb)
            });
            sampson_signed(
                &f,
                [m.a[0] as f64, m.a[1] as f64],
                [m.b[0] as f64, m.b[1] as f64],
            )
        })
        .collect()
}

/// The bounds of the factor [`covariance_scaled`] applies to a distance: a match counts at
/// most 25 times as much as the median one and at least 1/25, so that a window whose residual
/// happened to be tiny cannot take over the fit.
pub(super) const COVARIANCE_FACTOR: (f64, f64) = (0.2, 5.0);

/// The median of the matches' mean variances `(Σxx + Σyy)/2` (px²), the reference the
/// [`covariance_scaled`] factors are relative to; `None` when no match carries a covariance.
pub(super) fn median_variance(matches: &[Match]) -> Option<f64> {
    let mut v: Vec<f64> = matches
        .iter()
        .filter_map(|m| m.b_covariance)
        .map(|c| (c[0] as f64 + c[2] as f64) / 2.0)
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied()
}

/// Sampson distances under `poses`, each match with a covariance scaled by
/// `√(reference / nᵀΣn)`, where `n` is the unit normal of its epipolar line in view `b` and
/// `Σ` the covariance of its end there: the distance in units of its own standard deviation
/// across the line (times the reference's). With `a` a grid point placed exactly, that is the
/// maximum-likelihood residual of the epipolar constraint; matches on an edge along which the
/// window slides count little when the edge crosses their epipolar line. Matches without a
/// covariance keep their distance.
pub(super) fn covariance_scaled(
    poses: &[Se3],
    intrinsics: &[Intrinsics],
    matches: &[Match],
    reference: f64,
) -> Vec<f64> {
    let n = poses.len();
    let mut fs = vec![None; n * n];
    matches
        .iter()
        .map(|m| {
            let f = *fs[m.view_a * n + m.view_b].get_or_insert_with(|| {
                let ca = fewview_scene::Camera::new(intrinsics[m.view_a], poses[m.view_a]);
                let cb = fewview_scene::Camera::new(intrinsics[m.view_b], poses[m.view_b]);
                fundamental_from_cameras(&ca, &cb)
            });
            let d = sampson_signed(
                &f,
                [m.a[0] as f64, m.a[1] as f64],
                [m.b[0] as f64, m.b[1] as f64],
            );
            let Some(c) = m.b_covariance else {
                return d;
            };
            let line = f * nalgebra::Vector3::new(m.a[0] as f64, m.a[1] as f64, 1.0);
            let length = line.x.hypot(line.y);
            if length <= 0.0 {
                return d;
            }
            let (nx, ny) = (line.x / length, line.y / length);
            let [xx, xy, yy] = c.map(|v| v as f64);
            let across = nx * nx * xx + 2.0 * nx * ny * xy + ny * ny * yy;
            if !(across.is_finite() && across > 0.0) {
                return d;
            }
            d * (reference / across)
                .sqrt()
                .clamp(COVARIANCE_FACTOR.0, COVARIANCE_FACTOR.1)
        })
        .collect()
}

/// Cauchy loss `s²/2 · ln(1 + (d/s)²)` and its IRLS weight `1 / (1 + (d/s)²)`.
pub(super) fn cauchy(d: f64, s: f64) -> (f64, f64) {
    let q = (d / s) * (d / s);
    (0.5 * s * s * q.ln_1p(), 1.0 / (1.0 + q))
}

pub(super) fn median_abs(d: &[f64]) -> f64 {
    let mut a: Vec<f64> = d.iter().map(|x| x.abs()).collect();
    a.sort_by(f64::total_cmp);
    a.get(a.len() / 2).copied().unwrap_or(f64::NAN)
}

/// `start, start/2, …` down to `end`.
pub(super) fn halving_scales(start: f64, end: f64) -> Vec<f64> {
    let mut scales = vec![start];
    while let Some(&s) = scales.last() {
        if s <= end {
            break;
        }
        scales.push((0.5 * s).max(end));
    }
    scales
}

/// Fraction of matches whose two rays meet (closest approach) in front of both cameras.
pub(super) fn in_front_fraction(
    poses: &[Se3],
    intrinsics: &[Intrinsics],
    matches: &[Match],
) -> f64 {
    let ray = |view: usize, uv: [f32; 2]| {
        fewview_scene::Camera::new(intrinsics[view], poses[view]).ray(uv[0] as f64, uv[1] as f64)
    };
    let front = matches
        .iter()
        .filter(|m| {
            let (ca, da) = ray(m.view_a, m.a);
            let (cb, db) = ray(m.view_b, m.b);
            // Least squares for s·da − t·db = cb − ca.
            let (aa, ab, bb) = (da.dot(&da), da.dot(&db), db.dot(&db));
            let rhs = cb - ca;
            let (ra, rb) = (da.dot(&rhs), db.dot(&rhs));
            let det = aa * bb - ab * ab;
            if det.abs() < 1e-12 {
                return false;
            }
            let s = (ra * bb - ab * rb) / det;
            let t = (ab * ra - aa * rb) / det;
            s > 0.0 && t > 0.0
        })
        .count();
    front as f64 / matches.len().max(1) as f64
}

/// Levenberg–Marquardt on the Cauchy-weighted `residuals` of the matches (the Sampson
/// distances, or [`covariance_scaled`] ones), one scale after the other. Returns the poses,
/// their residuals and the iterations taken.
pub(super) fn anneal(
    poses: &[Se3],
    matches: &[Match],
    scales: &[f64],
    options: &WarmupOptions,
    residuals: &dyn Fn(&[Se3]) -> Vec<f64>,
) -> (Vec<Se3>, Vec<f64>, usize) {
    let unknowns = 6 * poses.len();
    let mut current = poses.to_vec();
    let mut d = residuals(poses);
    let mut iterations = 0;
    const STEP: f64 = 1e-6;
    for &s in scales {
        let cost_of = |d: &[f64]| -> f64 {
            d.iter()
                .zip(matches)
                .map(|(x, m)| m.confidence.max(0.0) as f64 * cauchy(*x, s).0)
                .sum()
        };
        let mut cost = cost_of(&d);
        let mut lambda = 1e-3;
        for _ in 0..options.max_iterations {
            // IRLS: confidence × Cauchy weight, as square roots on the residual rows.
            let w: Vec<f64> = d
                .iter()
                .zip(matches)
                .map(|(x, m)| (m.confidence.max(0.0) as f64 * cauchy(*x, s).1).sqrt())
                .collect();
            let mut jac = DMatrix::<f64>::zeros(matches.len(), unknowns);
            for k in 0..unknowns {
                let mut xi = vec![0.0; unknowns];
                xi[k] = STEP;
                let plus = residuals(&apply(&current, &xi));
                xi[k] = -STEP;
                let minus = residuals(&apply(&current, &xi));
                for r in 0..matches.len() {
                    jac[(r, k)] = w[r] * (plus[r] - minus[r]) / (2.0 * STEP);
                }
            }
            let res = DVector::from_iterator(matches.len(), d.iter().zip(&w).map(|(x, wi)| wi * x));
            let jtj = jac.transpose() * &jac;
            let jtr = jac.transpose() * res;
            let mut improved = false;
            for _ in 0..10 {
                let a = &jtj + DMatrix::<f64>::identity(unknowns, unknowns) * lambda;
                let Some(step) = a.cholesky().map(|c| c.solve(&(-&jtr))) else {
                    lambda *= 10.0;
                    continue;
                };
                let candidate = apply(&current, step.as_slice());
                let dc = residuals(&candidate);
                let cc = cost_of(&dc);
                if cc.is_finite() && cc < cost {
                    let rel = (cost - cc) / cost.max(1e-300);
                    current = candidate;
                    d = dc;
                    cost = cc;
                    lambda = (lambda * 0.3).max(1e-12);
                    improved = rel > options.tolerance;
                    break;
                }
                lambda *= 10.0;
            }
            iterations += 1;
            if !improved {
                break;
            }
        }
    }
    (current, d, iterations)
}
