//! The five-point solver for the essential matrix (Nistér 2004, in the action-matrix form of
//! Stewénius, Engels and Nistér 2006, "Recent developments on direct relative orientation").
//!
//! Five correspondences of normalised image points `q ↔ q'` (`q = K⁻¹(u, v, 1)`) give five
//! linear constraints `q'ᵀ E q = 0` on the nine entries of `E`, so `E = x X + y Y + z Z + W`
//! over the four-dimensional null space. An essential matrix also satisfies `det E = 0` and
//! `2 E Eᵀ E − tr(E Eᵀ) E = 0`: ten cubic equations in `(x, y, z)`. Their 20 monomials are
//! split into the ten cubic ones and the ten of degree ≤ 2; eliminating the cubic block expresses
//! every cubic monomial through the lower ones, which gives the 10 × 10 matrix of the
//! multiplication by `x` on the quotient ring spanned by `x², xy, xz, y², yz, z², x, y, z, 1`.
//! Its real eigenvalues are the `x` of the (up to ten) solutions, its eigenvectors the
//! monomials there, from which `y` and `z` are read.

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

/// Exponents `(x, y, z)` of the 20 monomials: the ten cubic ones, then the basis of the
/// quotient ring (degree ≤ 2, ending with the constant).
const MONOMIALS: [[u8; 3]; 20] = [
    [3, 0, 0],
    [2, 1, 0],
    [2, 0, 1],
    [1, 2, 0],
    [1, 1, 1],
    [1, 0, 2],
    [0, 3, 0],
    [0, 2, 1],
    [0, 1, 2],
    [0, 0, 3],
    [2, 0, 0],
    [1, 1, 0],
    [1, 0, 1],
    [0, 2, 0],
    [0, 1, 1],
    [0, 0, 2],
    [1, 0, 0],
    [0, 1, 0],
    [0, 0, 1],
    [0, 0, 0],
];

/// Index into [`MONOMIALS`] of `x^a y^b z^c` (total degree ≤ 3).
fn monomial(e: [u8; 3]) -> usize {
    MONOMIALS
        .iter()
        .position(|m| *m == e)
        .expect("a monomial of degree ≤ 3")
}

/// A polynomial of degree ≤ 3 in `(x, y, z)`, one coefficient per [`MONOMIALS`] entry.
#[derive(Clone, Copy)]
struct Poly([f64; 20]);

impl Poly {
    fn zero() -> Self {
        Poly([0.0; 20])
    }

    /// `x·cx + y·cy + z·cz + c1`.
    fn linear(cx: f64, cy: f64, cz: f64, c1: f64) -> Self {
        let mut p = Self::zero();
        p.0[monomial([1, 0, 0])] = cx;
        p.0[monomial([0, 1, 0])] = cy;
        p.0[monomial([0, 0, 1])] = cz;
        p.0[monomial([0, 0, 0])] = c1;
        p
    }

    /// The product; the factors' degrees must add up to at most 3.
    fn mul(&self, other: &Poly) -> Poly {
        let mut out = Poly::zero();
        for (i, &a) in self.0.iter().enumerate() {
            if a == 0.0 {
                continue;
            }
            for (j, &b) in other.0.iter().enumerate() {
                if b == 0.0 {
                    continue;
                }
                let (p, q) = (MONOMIALS[i], MONOMIALS[j]);
                let e = [p[0] + q[0], p[1] + q[1], p[2] + q[2]];
                assert!(e.iter().sum::<u8>() <= 3, "product of degree > 3");
                out.0[monomial(e)] += a * b;
            }
        }
        out
    }

    fn add(&self, other: &Poly) -> Poly {
        Poly(std::array::from_fn(|k| self.0[k] + other.0[k]))
    }

    fn scale(&self, s: f64) -> Poly {
        Poly(self.0.map(|c| c * s))
    }
}

/// The four null-space vectors `X, Y, Z, W` of the five constraints `q'ᵀ E q = 0` (entries of
/// `E` row-major), or `None` when the points are degenerate.
fn null_space(q: &[Vector3<f64>; 5], qp: &[Vector3<f64>; 5]) -> Option<[SVector<f64, 9>; 4]> {
    let mut a = SMatrix::<f64, 9, 9>::zeros();
    for k in 0..5 {
        for i in 0..3 {
            for j in 0..3 {
                a[(k, 3 * i + j)] = qp[k][i] * q[k][j];
            }
        }
    }
    let svd = a.svd(false, true);
    let v_t = svd.v_t?;
    let mut order: Vec<usize> = (0..9).collect();
    order.sort_by(|&i, &j| svd.singular_values[i].total_cmp(&svd.singular_values[j]));
    // Five independent constraints leave exactly four zero singular values.
    if svd.singular_values[order[4]] <= 1e-12 * svd.singular_values[order[8]].max(1e-300) {
        return None;
    }
    Some(std::array::from_fn(|k| v_t.row(order[k]).transpose()))
}

/// The ten cubic constraints on `(x, y, z)` as a 10 × 20 coefficient matrix.
fn constraints(basis: &[SVector<f64, 9>; 4]) -> SMatrix<f64, 10, 20> {
    let [x, y, z, w] = basis;
    let e: [[Poly; 3]; 3] = std::array::from_fn(|i| {
        std::array::from_fn(|j| {
            let k = 3 * i + j;
            Poly::linear(x[k], y[k], z[k], w[k])
        })
    });
    let minor = |a: &Poly, b: &Poly, c: &Poly, d: &Poly| a.mul(b).add(&c.mul(d).scale(-1.0));
    let det = e[0][0]
        .mul(&minor(&e[1][1], &e[2][2], &e[1][2], &e[2][1]))
        .add(
            &e[0][1]
                .mul(&minor(&e[1][0], &e[2][2], &e[1][2], &e[2][0]))
                .scale(-1.0),
        )
        .add(&e[0][2].mul(&minor(&e[1][0], &e[2][1], &e[1][1], &e[2][0])));
    let eet: [[Poly; 3]; 3] = std::array::from_fn(|i| {
        std::array::from_fn(|j| (0..3).fold(Poly::zero(), |acc, k| acc.add(&e[i][k].mul(&e[j][k]))))
    });
    let trace = eet[0][0].add(&eet[1][1]).add(&eet[2][2]);
    let mut m = SMatrix::<f64, 10, 20>::zeros();
    for (c, v) in det.0.iter().enumerate() {
        m[(0, c)] = *v;
    }
    for i in 0..3 {
        for j in 0..3 {
            let eete = (0..3).fold(Poly::zero(), |acc, k| acc.add(&eet[i][k].mul(&e[k][j])));
            let row = eete.scale(2.0).add(&trace.mul(&e[i][j]).scale(-1.0));
            for (c, v) in row.0.iter().enumerate() {
                m[(1 + 3 * i + j, c)] = *v;
            }
        }
    }
    m
}

/// The matrix of the multiplication by `x` on the quotient basis, from the constraints: row `i`
/// holds `x · basisᵢ` in the basis. `None` when the cubic block is singular.
fn action_matrix(m: &SMatrix<f64, 10, 20>) -> Option<SMatrix<f64, 10, 10>> {
    let cubic: SMatrix<f64, 10, 10> = m.fixed_columns::<10>(0).into_owned();
    let lower: SMatrix<f64, 10, 10> = m.fixed_columns::<10>(10).into_owned();
    // Each cubic monomial ≡ −(row of B) · basis.
    let b = cubic.full_piv_lu().solve(&lower)?;
    let mut action = SMatrix::<f64, 10, 10>::zeros();
    // x · {x², xy, xz, y², yz, z²} = {x³, x²y, x²z, xy², xyz, xz²}: the cubic rows 0–5.
    for r in 0..6 {
        for c in 0..10 {
            action[(r, c)] = -b[(r, c)];
        }
    }
    // x · {x, y, z, 1} = {x², xy, xz, x}: basis entries 0, 1, 2 and 6.
    for (r, target) in [(6, 0), (7, 1), (8, 2), (9, 6)] {
        action[(r, target)] = 1.0;
    }
    Some(action)
}

/// Every real essential matrix (unit Frobenius norm) with `q'ᵢᵀ E qᵢ = 0` for the five pairs
/// of normalised image points (`q` in the first view, `q'` in the second, third coordinate 1):
/// up to ten. Empty when the points are degenerate.
pub fn five_point(q: &[Vector3<f64>; 5], qp: &[Vector3<f64>; 5]) -> Vec<Matrix3<f64>> {
    let Some(basis) = null_space(q, qp) else {
        return Vec::new();
    };
    let Some(action) = action_matrix(&constraints(&basis)) else {
        return Vec::new();
    };
    let scale = action.norm().max(1e-300);
    let mut out = Vec::new();
    for lambda in action.complex_eigenvalues().iter() {
        if lambda.im.abs() > 1e-8 * scale {
            continue;
        }
        let shifted = action - SMatrix::<f64, 10, 10>::identity() * lambda.re;
        let svd = shifted.svd(false, true);
        let Some(v_t) = svd.v_t else { continue };
        let k = (0..10)
            .min_by(|&i, &j| svd.singular_values[i].total_cmp(&svd.singular_values[j]))
            .unwrap_or(0);
        let v = v_t.row(k);
        if v[9].abs() < 1e-12 {
            continue;
        }
        let (x, y, z) = (v[6] / v[9], v[7] / v[9], v[8] / v[9]);
        let e = basis[0] * x + basis[1] * y + basis[2] * z + basis[3];
        let e = Matrix3::from_row_slice(e.as_slice());
        let norm = e.norm();
        if norm.is_finite() && norm > 0.0 {
            out.push(e / norm);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    fn skew(t: &Vector3<f64>) -> Matrix3<f64> {
        Matrix3::new(0.0, -t.z, t.y, t.z, 0.0, -t.x, -t.y, t.x, 0.0)
    }

    /// Five points seen by two cameras `x_b = R x_a + t`: one of the solutions is `[t]× R`.
    #[test]
    fn one_solution_is_the_true_essential_matrix() {
        for trial in 0..20 {
            let f = trial as f64;
            let r = Rotation3::from_euler_angles(0.1 + 0.03 * f, -0.2 + 0.02 * f, 0.05 * f)
                .into_inner();
            let t = Vector3::new(1.0, 0.2 * f.sin(), 0.1 * f.cos()).normalize();
            let mut q = [Vector3::zeros(); 5];
            let mut qp = [Vector3::zeros(); 5];
            for k in 0..5 {
                let g = (k as f64 + 1.0) * (f + 1.3);
                let p = Vector3::new(g.sin(), (1.7 * g).cos(), 4.0 + (0.7 * g).sin());
                let pb = r * p + t;
                q[k] = p / p.z;
                qp[k] = pb / pb.z;
            }
            let truth = skew(&t) * r;
            let truth = truth / truth.norm();
            let solutions = five_point(&q, &qp);
            assert!(!solutions.is_empty() && solutions.len() <= 10);
            let best = solutions
                .iter()
                .map(|e| (e - truth).norm().min((e + truth).norm()))
                .fold(f64::INFINITY, f64::min);
            assert!(best < 1e-8, "trial {trial}: nearest solution {best} away");
            for e in &solutions {
                // Every solution is essential and satisfies the five constraints.
                for k in 0..5 {
                    assert!((qp[k].transpose() * e * q[k])[0].abs() < 1e-9);
                }
                let s = e.svd(false, false).singular_values;
                let mut s: Vec<f64> = s.iter().copied().collect();
                s.sort_by(f64::total_cmp);
                assert!(s[0] < 1e-8 && (s[1] - s[2]).abs() < 1e-8, "{s:?}");
            }
        }
    }
}
