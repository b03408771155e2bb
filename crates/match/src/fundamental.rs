//! Robust two-view geometry without poses: the normalised eight-point algorithm (Hartley 1997)
//! inside RANSAC with the Sampson error, used to drop matches that no rigid scene explains.

use nalgebra::{DMatrix, Matrix3, Vector3};
use rand::SeedableRng;
use rand::seq::index::sample;

/// Hartley normalisation of a point set: centroid to the origin, mean distance √2.
fn normalisation(pts: &[[f64; 2]]) -> Matrix3<f64> {
    let n = pts.len().max(1) as f64;
    let cx = pts.iter().map(|p| p[0]).sum::<f64>() / n;
    let cy = pts.iter().map(|p| p[1]).sum::<f64>() / n;
    let mean = pts
        .iter()
        .map(|p| ((p[0] - cx).powi(2) + (p[1] - cy).powi(2)).sqrt())
        .sum::<f64>()
        / n;
    let s = if mean > 0.0 { 2f64.sqrt() / mean } else { 1.0 };
    Matrix3::new(s, 0.0, -s * cx, 0.0, s, -s * cy, 0.0, 0.0, 1.0)
}

/// The fundamental matrix (`x_bᵀ F x_a = 0`, rank 2) of ≥ 8 correspondences by the
/// normalised eight-point algorithm; `None` when degenerate.
pub fn eight_point(a: &[[f64; 2]], b: &[[f64; 2]]) -> Option<Matrix3<f64>> {
    let n = a.len();
    if n < 8 || b.len() != n {
        return None;
    }
    let (ta, tb) = (normalisation(a), normalisation(b));
    let mut m = DMatrix::<f64>::zeros(n.max(9), 9);
    for i in 0..n {
        let pa = ta * Vector3::new(a[i][0], a[i][1], 1.0);
        let pb = tb * Vector3::new(b[i][0], b[i][1], 1.0);
        let row = [
            pb.x * pa.x,
            pb.x * pa.y,
            pb.x,
            pb.y * pa.x,
            pb.y * pa.y,
            pb.y,
            pa.x,
            pa.y,
            1.0,
        ];
        for (j, v) in row.iter().enumerate() {
            m[(i, j)] = *v;
        }
    }
    let svd = m.svd(false, true);
    let vt = svd.v_t?;
    // The right singular vector of the smallest singular value.
    let (imin, _) = svd
        .singular_values
        .iter()
        .enumerate()
        .min_by(|x, y| x.1.total_cmp(y.1))?;
    let f = vt.row(imin);
    let fm = Matrix3::new(f[0], f[1], f[2], f[3], f[4], f[5], f[6], f[7], f[8]);
    // Enforce rank 2.
    let s = fm.svd(true, true);
    let (u, v_t) = (s.u?, s.v_t?);
    let mut d = s.singular_values;
    let k = (0..3).min_by(|&x, &y| d[x].total_cmp(&d[y]))?;
    d[k] = 0.0;
    let f2 = u * Matrix3::from_diagonal(&d) * v_t;
    let f = tb.transpose() * f2 * ta;
    let norm = f.norm();
    (norm > 0.0 && norm.is_finite()).then(|| f / norm)
}

/// The epipolar residual `x_bᵀ F x_a` of one correspondence and the squared norm of its
/// gradient, `(F x_a)₁² + (F x_a)₂² + (Fᵀ x_b)₁² + (Fᵀ x_b)₂²`: the Sampson distance is
/// their ratio.
fn sampson_parts(f: &Matrix3<f64>, a: [f64; 2], b: [f64; 2]) -> (f64, f64) {
    let xa = Vector3::new(a[0], a[1], 1.0);
    let xb = Vector3::new(b[0], b[1], 1.0);
    let fa = f * xa;
    let fb = f.transpose() * xb;
    (
        xb.dot(&fa),
        fa.x * fa.x + fa.y * fa.y + fb.x * fb.x + fb.y * fb.y,
    )
}

/// Sampson distance (first-order geometric error, pixels²) of one correspondence.
pub fn sampson(f: &Matrix3<f64>, a: [f64; 2], b: [f64; 2]) -> f64 {
    let (r, g2) = sampson_parts(f, a, b);
    r * r / g2.max(1e-300)
}

/// The signed square root of [`sampson`] (pixels), 0 where `F` has no gradient: a residual
/// for least squares over the poses that `F` comes from.
pub fn sampson_signed(f: &Matrix3<f64>, a: [f64; 2], b: [f64; 2]) -> f64 {
    let (r, g2) = sampson_parts(f, a, b);
    if g2 > 0.0 { r / g2.sqrt() } else { 0.0 }
}

/// RANSAC over eight-point samples: the inlier flags of the model with most inliers
/// (Sampson distance below `threshold_px²`), refitted on all its inliers. `seed` makes it
/// deterministic.
pub fn ransac_inliers(
    a: &[[f64; 2]],
    b: &[[f64; 2]],
    threshold_px: f64,
    iterations: usize,
    seed: u64,
) -> Vec<bool> {
    let n = a.len();
    if n < 8 {
        return vec![false; n];
    }
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let thr = threshold_px * threshold_px;
    let count = |f: &Matrix3<f64>| (0..n).filter(|&i| sampson(f, a[i], b[i]) < thr).count();
    let mut best: Option<(usize, Matrix3<f64>)> = None;
    for _ in 0..iterations {
        let idx = sample(&mut rng, n, 8);
        let sa: Vec<[f64; 2]> = idx.iter().map(|i| a[i]).collect();
        let sb: Vec<[f64; 2]> = idx.iter().map(|i| b[i]).collect();
        if let Some(f) = eight_point(&sa, &sb) {
            let c = count(&f);
            if best.as_ref().is_none_or(|(bc, _)| c > *bc) {
                best = Some((c, f));
            }
        }
    }
    let Some((_, mut f)) = best else {
        return vec![false; n];
    };
    // Two rounds of refitting on the inliers.
    for _ in 0..2 {
        let inl: Vec<usize> = (0..n).filter(|&i| sampson(&f, a[i], b[i]) < thr).collect();
        let sa: Vec<[f64; 2]> = inl.iter().map(|&i| a[i]).collect();
        let sb: Vec<[f64; 2]> = inl.iter().map(|&i| b[i]).collect();
        match eight_point(&sa, &sb) {
            Some(g) if count(&g) >= inl.len() => f = g,
            _ => break,
        }
    }
    (0..n).map(|i| sampson(&f, a[i], b[i]) < thr).collect()
}

#[cfg(test)]
mod tests {
    use fewview_scene::{Camera, Intrinsics};
    use rand::RngExt;

    use super::*;
    use crate::{epipolar_distance, fundamental_from_cameras};

    #[test]
    fn recovers_the_true_geometry_and_rejects_outliers() {
        let k = Intrinsics::centered(300.0, 320, 240);
        let ca = Camera::look_at(
            k,
            Vector3::new(3.0, 0.4, 1.0),
            Vector3::zeros(),
            Vector3::z(),
        );
        let cb = Camera::look_at(
            k,
            Vector3::new(2.0, 2.3, 0.6),
            Vector3::zeros(),
            Vector3::z(),
        );
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let (mut a, mut b, mut truth) = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..200 {
            let p = Vector3::new(
                rng.random_range(-0.6..0.6),
                rng.random_range(-0.6..0.6),
                rng.random_range(-0.6..0.6),
            );
            let (ua, va, _) = ca.project(&p).unwrap();
            let (ub, vb, _) = cb.project(&p).unwrap();
            let outlier = i % 5 == 0;
            let (ub, vb) = if outlier {
                (rng.random_range(0.0..320.0), rng.random_range(0.0..240.0))
            } else {
                (
                    ub + rng.random_range(-0.3..0.3),
                    vb + rng.random_range(-0.3..0.3),
                )
            };
            a.push([ua, va]);
            b.push([ub, vb]);
            truth.push(!outlier);
        }
        let inl = ransac_inliers(&a, &b, 1.5, 500, 1);
        let f_true = fundamental_from_cameras(&ca, &cb);
        let mut kept_good = 0;
        for i in 0..200 {
            if inl[i] {
                let d = epipolar_distance(
                    &f_true,
                    [a[i][0] as f32, a[i][1] as f32],
                    [b[i][0] as f32, b[i][1] as f32],
                );
                assert!(d < 3.0, "a kept match is {d} px off its epipolar line");
                kept_good += truth[i] as usize;
            }
        }
        assert!(kept_good > 150, "kept {kept_good} of 160 good matches");
        // Exact data: the eight-point solution equals the true F up to scale and sign.
        let (ea, eb): (Vec<_>, Vec<_>) = (0..200)
            .filter(|i| truth[*i])
            .map(|i| {
                let p = Vector3::new(
                    (i as f64 * 0.37).sin() * 0.5,
                    (i as f64 * 0.71).cos() * 0.5,
                    (i as f64 * 0.13).sin() * 0.5,
                );
                let (ua, va, _) = ca.project(&p).unwrap();
                let (ub, vb, _) = cb.project(&p).unwrap();
                ([ua, va], [ub, vb])
            })
            .unzip();
        let f = eight_point(&ea, &eb).unwrap();
        let ft = f_true / f_true.norm();
        assert!((f - ft).norm().min((f + ft).norm()) < 1e-6);
    }
}
