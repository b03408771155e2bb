//! From pairwise relative poses to absolute ones, as global structure from motion does:
//! rotation averaging (the chordal L2 mean: a spectral start, then block-coordinate descent,
//! Hartley et al., "Rotation averaging", 2013) and camera centres from the baseline directions
//! (linear least squares, with a weak prior on each baseline's length that fixes the lengths
//! the directions leave free).

use nalgebra::{DMatrix, Matrix3, Vector3};

/// The rotation from camera `i`'s to camera `j`'s frame, `R_j R_iᵀ` for world-to-camera
/// rotations, with a weight (e.g. the pair's inlier count).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RelativeRotation {
    pub i: usize,
    pub j: usize,
    pub rotation: Matrix3<f64>,
    pub weight: f64,
}

/// The rotation nearest `m` in the Frobenius norm.
pub fn project_to_rotation(m: &Matrix3<f64>) -> Matrix3<f64> {
    let svd = m.svd(true, true);
    let (u, v_t) = (svd.u.expect("u"), svd.v_t.expect("v_t"));
    let d = (u * v_t).determinant().signum();
    u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * v_t
}

/// World-to-camera rotations of `n` views that best agree with the `edges` in the chordal
/// sense, up to one rotation of the world (view 0 is returned as the identity), or `None` when
/// the edges do not connect the views.
pub fn average_rotations(n: usize, edges: &[RelativeRotation]) -> Option<Vec<Matrix3<f64>>> {
    if n == 0 || !connected(n, edges.iter().map(|e| (e.i, e.j))) {
        return None;
    }
    let mut g = DMatrix::<f64>::zeros(3 * n, 3 * n);
    for i in 0..n {
        let mut degree = 0.0;
        for e in edges.iter().filter(|e| e.i == i || e.j == i) {
            degree += e.weight;
        }
        for d in 0..3 {
            g[(3 * i + d, 3 * i + d)] = degree.max(1e-12);
        }
    }
    for e in edges {
        // Block (j, i) ≈ R_j R_iᵀ.
        for r in 0..3 {
            for c in 0..3 {
                g[(3 * e.j + r, 3 * e.i + c)] += e.weight * e.rotation[(r, c)];
                g[(3 * e.i + c, 3 * e.j + r)] += e.weight * e.rotation[(r, c)];
            }
        }
    }
    let eig = g.symmetric_eigen();
    let mut order: Vec<usize> = (0..3 * n).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let block = |i: usize, flip: f64| -> Matrix3<f64> {
        Matrix3::from_fn(|r, c| {
            let v = eig.eigenvectors[(3 * i + r, order[c])];
            if c == 2 { flip * v } else { v }
        })
    };
    let dets: f64 = (0..n).map(|i| block(i, 1.0).determinant()).sum();
    let flip = if dets < 0.0 { -1.0 } else { 1.0 };
    let mut rotations: Vec<Matrix3<f64>> = (0..n)
        .map(|i| project_to_rotation(&block(i, flip)))
        .collect();
    // Block-coordinate descent on Σ w ‖R_j − R_ij R_i‖²_F: each view in turn to the rotation
    // nearest the mean its neighbours predict.
    for _ in 0..100 {
        let mut moved = 0.0f64;
        for v in 0..n {
            let mut sum = Matrix3::zeros();
            for e in edges {
                if e.j == v {
                    sum += e.weight * e.rotation * rotations[e.i];
                } else if e.i == v {
                    sum += e.weight * e.rotation.transpose() * rotations[e.j];
                }
            }
            let next = project_to_rotation(&sum);
            moved = moved.max((next - rotations[v]).norm());
            rotations[v] = next;
        }
        if moved < 1e-13 {
            break;
        }
    }
    let r0t = rotations[0].transpose();
    Some(rotations.iter().map(|r| r * r0t).collect())
}

/// Whether the edges `(i, j)` reach every view from view 0.
fn connected(n: usize, edges: impl Iterator<Item = (usize, usize)> + Clone) -> bool {
    let mut reached = vec![false; n];
    reached[0] = true;
    let mut changed = true;
    while changed {
        changed = false;
        for (i, j) in edges.clone() {
            if i < n && j < n && reached[i] != reached[j] {
                reached[i] = true;
                reached[j] = true;
                changed = true;
            }
        }
    }
    reached.iter().all(|r| *r)
}

/// The direction of a baseline: `c_j − c_i` ∝ `direction`, with a prior length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Baseline {
    pub i: usize,
    pub j: usize,
    /// Unit vector in the world frame.
    pub direction: Vector3<f64>,
    /// The length expected before the directions are known (e.g. from rough poses).
    pub prior_length: f64,
    pub weight: f64,
    /// How much the prior length counts beside the direction: [`LENGTH_PRIOR_WEIGHT`] for a
    /// rough guess (the directions decide wherever they can), about 1 for a measured length.
    pub prior_weight: f64,
}

/// Weight of the length priors relative to the directions: small, so that the lengths the
/// directions fix (in triangles) follow the directions, and only the free ones the prior.
pub const LENGTH_PRIOR_WEIGHT: f64 = 1e-6;

/// Camera centres of `n` views (view 0 at the origin) from baseline directions: least squares
/// over the centres and the baselines' lengths `s` of `Σ w ‖c_j − c_i − s d‖² + Σ ε w (s − s₀)²`
/// with `ε` each baseline's [`Baseline::prior_weight`]. `None` when the baselines do not
/// connect the views.
pub fn centres_from_baselines(n: usize, baselines: &[Baseline]) -> Option<Vec<Vector3<f64>>> {
    if n == 0 {
        return None;
    }
    if !connected(n, baselines.iter().map(|b| (b.i, b.j))) {
        return None;
    }
    let unknowns = 3 * (n - 1) + baselines.len();
    let rows = 3 * baselines.len() + baselines.len();
    let mut a = DMatrix::<f64>::zeros(rows, unknowns);
    let mut rhs = DMatrix::<f64>::zeros(rows, 1);
    let centre = |v: usize| (v > 0).then(|| 3 * (v - 1));
    for (k, b) in baselines.iter().enumerate() {
        let w = b.weight.max(0.0).sqrt();
        for d in 0..3 {
            let row = 3 * k + d;
            if let Some(c) = centre(b.j) {
                a[(row, c + d)] += w;
            }
            if let Some(c) = centre(b.i) {
                a[(row, c + d)] -= w;
            }
            a[(row, 3 * (n - 1) + k)] = -w * b.direction[d];
        }
        let row = 3 * baselines.len() + k;
        let wp = (b.weight.max(0.0) * b.prior_weight.max(0.0)).sqrt();
        a[(row, 3 * (n - 1) + k)] = wp;
        rhs[(row, 0)] = wp * b.prior_length;
    }
    let solution = a.svd(true, true).solve(&rhs, 1e-12).ok()?;
    Some(
        (0..n)
            .map(|v| match centre(v) {
                Some(c) => Vector3::new(solution[c], solution[c + 1], solution[c + 2]),
                None => Vector3::zeros(),
            })
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    fn rotation(k: f64) -> Matrix3<f64> {
        Rotation3::from_euler_angles(0.3 * k, -0.2 * k + 0.1, 0.7 * k.sin()).into_inner()
    }

    #[test]
    fn exact_relative_rotations_give_the_absolute_ones_up_to_one_rotation() {
        let truth: Vec<Matrix3<f64>> = (0..4).map(|k| rotation(k as f64)).collect();
        let edges: Vec<RelativeRotation> = [(0, 1), (1, 2), (0, 2), (2, 3)]
            .iter()
            .map(|&(i, j)| RelativeRotation {
                i,
                j,
                rotation: truth[j] * truth[i].transpose(),
                weight: 1.0 + i as f64,
            })
            .collect();
        let found = average_rotations(4, &edges).unwrap();
        let g = truth[0].transpose();
        for (f, t) in found.iter().zip(&truth) {
            assert!((f - t * g).norm() < 1e-9, "{}", (f - t * g).norm());
        }
        assert!(
            average_rotations(5, &edges).is_none(),
            "view 4 is not connected"
        );
    }

    #[test]
    fn a_noisy_edge_is_outvoted_in_a_triangle_by_weight() {
        let truth: Vec<Matrix3<f64>> = (0..3).map(|k| rotation(k as f64)).collect();
        let noise = Rotation3::from_euler_angles(0.0, 0.0, 0.02).into_inner();
        let edge = |i: usize, j: usize, w: f64, bad: bool| RelativeRotation {
            i,
            j,
            rotation: if bad { noise } else { Matrix3::identity() }
                * truth[j]
                * truth[i].transpose(),
            weight: w,
        };
        let edges = [
            edge(0, 1, 100.0, false),
            edge(1, 2, 100.0, false),
            edge(0, 2, 1.0, true),
        ];
        let found = average_rotations(3, &edges).unwrap();
        let rel = found[2] * found[0].transpose() * (truth[2] * truth[0].transpose()).transpose();
        let err = ((rel.trace() - 1.0) / 2.0).clamp(-1.0, 1.0).acos();
        // The bad edge pulls with weight 1 against 100 + 100: well under a tenth of its 0.02.
        assert!(err < 0.02 / 10.0, "{err}");
    }

    #[test]
    fn a_triangle_of_directions_fixes_the_shape_and_a_chain_takes_the_priors() {
        let c = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.2, 0.0),
            Vector3::new(0.4, 1.5, 0.3),
        ];
        let baseline = |i: usize, j: usize, prior: f64| Baseline {
            i,
            j,
            direction: (c[j] - c[i]).normalize(),
            prior_length: prior,
            weight: 1.0,
            prior_weight: LENGTH_PRIOR_WEIGHT,
        };
        // Triangle with priors 30 % off: the directions fix the shape, the priors the scale.
        let tri = [
            baseline(0, 1, 1.3),
            baseline(1, 2, 1.3 * 1.5),
            baseline(0, 2, 1.2),
        ];
        let found = centres_from_baselines(3, &tri).unwrap();
        let scale = found[1].norm() / c[1].norm();
        for (f, t) in found.iter().zip(&c) {
            assert!(
                (f - t * scale).norm() < 1e-4 * scale,
                "{f} vs {}",
                t * scale
            );
        }
        // Chain: the length of each baseline is its prior.
        let chain = [baseline(0, 1, 2.0), baseline(1, 2, 0.5)];
        let found = centres_from_baselines(3, &chain).unwrap();
        assert!(((found[1] - found[0]).norm() - 2.0).abs() < 1e-9);
        assert!(((found[2] - found[1]).norm() - 0.5).abs() < 1e-9);
        assert!(centres_from_baselines(4, &chain).is_none());
    }
}
