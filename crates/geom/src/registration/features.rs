//! Normal estimation and FPFH features (Rusu et al. 2009), with Open3D's conventions.
//!
//! Normals: the eigenvector of the smallest eigenvalue of the covariance of each point's hybrid
//! neighbourhood (≤ `max_nn` points within `radius`, the point included). Open3D leaves their
//! sign to the eigen-solver; we orient them away from the cloud's centroid, a rule that moves
//! with the cloud under any rigid motion, so corresponding points of two clouds agree.
//!
//! FPFH: 33 bins (three 11-bin histograms of the Darboux-frame angles `α`, `φ`, `θ`). Each
//! point's simplified histogram (SPFH) counts its pairs with the hybrid neighbours (itself
//! excluded) at `100/k` per pair; its FPFH adds the neighbours' SPFHs weighted by
//! `1/‖p − p_k‖²`, each 11-bin block of that sum rescaled to total 100, to its own SPFH.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use rayon::prelude::*;

use crate::knn::PointTree;
use crate::mesh::{Points, v3};

/// Number of FPFH bins.
pub const FPFH_BINS: usize = 33;

/// The least-squares plane of `points`: their mean and the unit eigenvector of the smallest
/// eigenvalue of their covariance (the plane's normal, sign arbitrary).
pub fn least_squares_plane(points: &[Vector3<f64>]) -> (Vector3<f64>, Vector3<f64>) {
    let mean = points.iter().sum::<Vector3<f64>>() / points.len().max(1) as f64;
    let mut cov = Matrix3::zeros();
    for x in points {
        let d = x - mean;
        cov += d * d.transpose();
    }
    let eig = SymmetricEigen::new(cov);
    let imin = (0..3)
        .min_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]))
        .unwrap_or(0);
    (mean, eig.eigenvectors.column(imin).into_owned())
}

/// Unit normals from local PCA, oriented away from the centroid.
pub fn estimate_normals(points: &Points, radius: f64, max_nn: usize) -> Vec<[f32; 3]> {
    let tree = PointTree::new(&points.positions);
    let centroid =
        points.positions.iter().map(v3).sum::<Vector3<f64>>() / points.len().max(1) as f64;
    points
        .positions
        .par_iter()
        .map(|p| {
            let q = v3(p);
            let nb = tree.hybrid(&[q.x, q.y, q.z], radius, max_nn);
            if nb.len() < 3 {
                return [0.0, 0.0, 1.0];
            }
            let pts: Vec<Vector3<f64>> =
                nb.iter().map(|&(i, _)| v3(&points.positions[i])).collect();
            let (_, mut n) = least_squares_plane(&pts);
            if n.dot(&(q - centroid)) < 0.0 {
                n = -n;
            }
            [n.x as f32, n.y as f32, n.z as f32]
        })
        .collect()
}

/// The Darboux-frame pair features `(φ, α, θ, d)` of Rusu et al. (Open3D's
/// `ComputePairFeatures` order): the frame starts at the point whose normal is closer to the
/// connecting line.
pub fn pair_features(
    p1: &Vector3<f64>,
    n1: &Vector3<f64>,
    p2: &Vector3<f64>,
    n2: &Vector3<f64>,
) -> [f64; 4] {
    let mut dp = p2 - p1;
    let dist = dp.norm();
    if dist == 0.0 {
        return [0.0; 4];
    }
    let (mut u, mut n_other) = (*n1, *n2);
    let a1 = n1.dot(&dp) / dist;
    let a2 = n2.dot(&dp) / dist;
    let f3 = if a1.abs().acos() > a2.abs().acos() {
        u = *n2;
        n_other = *n1;
        dp = -dp;
        -a2
    } else {
        a1
    };
    let v = dp.cross(&u);
    let vn = v.norm();
    if vn == 0.0 {
        return [0.0; 4];
    }
    let v = v / vn;
    let w = u.cross(&v);
    let f2 = v.dot(&n_other);
    let f1 = w.dot(&n_other).atan2(u.dot(&n_other));
    [f1, f2, f3, dist]
}

fn bin(x: f64, lo: f64, hi: f64) -> usize {
    ((11.0 * (x - lo) / (hi - lo)).floor() as i64).clamp(0, 10) as usize
}

/// FPFH descriptors (33 values per point); `normals` must match `points`.
pub fn compute_fpfh(
    points: &[[f32; 3]],
    normals: &[[f32; 3]],
    radius: f64,
    max_nn: usize,
) -> Vec<[f32; FPFH_BINS]> {
    let tree = PointTree::new(points);
    let neighbours: Vec<Vec<(usize, f64)>> = points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let q = [p[0] as f64, p[1] as f64, p[2] as f64];
            tree.hybrid(&q, radius, max_nn)
                .into_iter()
                .filter(|&(j, _)| j != i)
                .collect()
        })
        .collect();
    let spfh: Vec<[f64; FPFH_BINS]> = (0..points.len())
        .into_par_iter()
        .map(|i| {
            let mut h = [0.0; FPFH_BINS];
            let nb = &neighbours[i];
            if nb.is_empty() {
                return h;
            }
            let inc = 100.0 / nb.len() as f64;
            let (p, n) = (v3(&points[i]), v3(&normals[i]));
            for &(k, _) in nb {
                let f = pair_features(&p, &n, &v3(&points[k]), &v3(&normals[k]));
                h[bin(f[0], -std::f64::consts::PI, std::f64::consts::PI)] += inc;
                h[11 + bin(f[1], -1.0, 1.0)] += inc;
                h[22 + bin(f[2], -1.0, 1.0)] += inc;
            }
            h
        })
        .collect();
    (0..points.len())
        .into_par_iter()
        .map(|i| {
            let mut acc = [0.0f64; FPFH_BINS];
            let mut sums = [0.0f64; 3];
            for &(k, d) in &neighbours[i] {
                if d == 0.0 {
                    continue;
                }
                let wgt = 1.0 / (d * d);
                for b in 0..FPFH_BINS {
                    let v = spfh[k][b] * wgt;
                    acc[b] += v;
                    sums[b / 11] += v;
                }
            }
            let mut out = [0.0f32; FPFH_BINS];
            for b in 0..FPFH_BINS {
                let s = sums[b / 11];
                let scaled = if s != 0.0 { acc[b] * 100.0 / s } else { 0.0 };
                out[b] = (scaled + spfh[i][b]) as f32;
            }
            out
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    #[test]
    fn plane_normals_and_invariant_features() {
        // A noisy-free grid on the plane z = 0.5 x: normals ∝ (−0.5, 0, 1) up to sign.
        let pts: Vec<[f32; 3]> = (0..20)
            .flat_map(|i| {
                (0..20).map(move |j| [i as f32 * 0.05, j as f32 * 0.05, i as f32 * 0.025])
            })
            .collect();
        let n = estimate_normals(&Points::from_positions(pts.clone()), 0.12, 30);
        let want = Vector3::new(-0.5, 0.0, 1.0).normalize();
        for v in &n {
            assert!((v3(v).dot(&want).abs() - 1.0).abs() < 1e-5);
        }
        // Pair features do not change under a rigid motion.
        let r = Rotation3::from_euler_angles(0.3, -1.1, 2.0);
        let (p1, n1) = (Vector3::new(0.1, 0.2, 0.3), Vector3::new(0.0, 0.6, 0.8));
        let (p2, n2) = (Vector3::new(0.4, -0.1, 0.2), Vector3::new(0.6, 0.0, 0.8));
        let a = pair_features(&p1, &n1, &p2, &n2);
        let b = pair_features(
            &(r * p1 + Vector3::new(1.0, 2.0, 3.0)),
            &(r * n1),
            &(r * p2 + Vector3::new(1.0, 2.0, 3.0)),
            &(r * n2),
        );
        for k in 0..4 {
            assert!((a[k] - b[k]).abs() < 1e-12);
        }
        // Symmetric in the order of the pair.
        let c = pair_features(&p2, &n2, &p1, &n1);
        for k in 0..4 {
            assert!((a[k] - c[k]).abs() < 1e-12, "{a:?} vs {c:?}");
        }
        // Each FPFH block sums to 200 (own SPFH 100 + normalised neighbours 100) inside the grid.
        let f = compute_fpfh(&pts, &n, 0.12, 100);
        let mid = 10 * 20 + 10;
        for blk in 0..3 {
            let s: f32 = f[mid][blk * 11..blk * 11 + 11].iter().sum();
            assert!((s - 200.0).abs() < 1e-3, "{s}");
        }
    }
}
