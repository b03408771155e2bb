//! The relative lengths of the pairs' baselines, measured by the points two pairs share.
//!
//! **Why.** Camera centres from baseline directions alone
//! ([`fewview_geom::epipolar::centres_from_baselines`]) fix a baseline's length only where the
//! directions close a triangle of some width. A camera walking forward, the commonest way a
//! street or a corridor is photographed, puts every centre on one line: the triangles are flat,
//! the lengths free, and the start spaces the photos evenly whatever their true spacing, a
//! basin the bundle adjustment may not leave. Global structure from motion measures those
//! lengths from the scene instead (the relative scales of triplets sharing points, as in
//! Moulon et al., "Global Fusion of Relative Motions for Robust, Accurate and Scalable
//! Structure from Motion"): a point that two pairs with a common view both triangulate has one
//! depth in that view, so the ratio of its two unit-baseline depths is the ratio of the two
//! baselines' lengths. Each ratio inherits its two pairs' pose errors, so the poses use it only
//! where the directions cannot fix the lengths (`global_start`'s line test).
//!
//! **Model.** Each pair's matches are triangulated with its relative pose and a unit baseline
//! (midpoint of the two rays; points seen at less than [`MIN_PARALLAX_DEG`] are too uncertain
//! and left out). Two pairs sharing a view and at least [`MIN_SHARED_POINTS`] points at the
//! same pixel of it give `log s_p − log s_q = median log(z_q / z_p)`, weighted by the count;
//! the logarithms of all lengths come from the least squares of these, with a faint pull to 0
//! so that pairs no other pair measures keep the unit length.

use std::collections::HashMap;

use fewview_scene::Intrinsics;
use nalgebra::{DMatrix, DVector, Matrix3, Matrix3x2, Vector3};

/// Least parallax (degrees) at which a pair's point counts in a ratio.
pub const MIN_PARALLAX_DEG: f64 = 1.0;

/// Fewest points two pairs must share for their length ratio to count.
pub const MIN_SHARED_POINTS: usize = 5;

/// One pair's relative pose and matched pixels: views `a` and `b`, `x_b = R x_a + t` with a
/// unit `t`, the pixels in `a`, then in `b`.
pub struct PairPixels<'a> {
    pub views: (usize, usize),
    pub rotation: Matrix3<f64>,
    pub translation: Vector3<f64>,
    pub in_a: &'a [[f64; 2]],
    pub in_b: &'a [[f64; 2]],
}

/// Each pair's baseline length up to one common scale (module docs); `None` for a pair that
/// shares too few points with every other pair to be measured.
pub fn baseline_lengths(pairs: &[PairPixels<'_>], intrinsics: &[Intrinsics]) -> Vec<Option<f64>> {
    let depths: Vec<[HashMap<PixelKey, f64>; 2]> = pairs
        .iter()
        .map(|p| unit_baseline_depths(p, intrinsics))
        .collect();
    let mut ratios: Vec<(usize, usize, f64, usize)> = Vec::new();
    for p in 0..pairs.len() {
        for q in p + 1..pairs.len() {
            for (side_p, side_q) in shared_views(pairs[p].views, pairs[q].views) {
                let (dp, dq) = (&depths[p][side_p], &depths[q][side_q]);
                let mut logs: Vec<f64> = dp
                    .iter()
                    .filter_map(|(key, zp)| dq.get(key).map(|zq| (zq / zp).ln()))
                    .collect();
                if logs.len() >= MIN_SHARED_POINTS {
                    let middle = logs.len() / 2;
                    let median = *logs.select_nth_unstable_by(middle, f64::total_cmp).1;
                    ratios.push((p, q, median, logs.len()));
                }
            }
        }
    }
    solve_log_lengths(pairs.len(), &ratios)
}

/// A pixel of a view, exactly (tracks join matches at identical pixels).
type PixelKey = (u64, u64);

fn key(p: &[f64; 2]) -> PixelKey {
    (p[0].to_bits(), p[1].to_bits())
}

/// The sides (0: view a, 1: view b) by which two pairs share a view.
fn shared_views(p: (usize, usize), q: (usize, usize)) -> Vec<(usize, usize)> {
    let (vp, vq) = ([p.0, p.1], [q.0, q.1]);
    let mut out = Vec::new();
    for (i, a) in vp.iter().enumerate() {
        for (j, b) in vq.iter().enumerate() {
            if a == b {
                out.push((i, j));
            }
        }
    }
    out
}

/// The depth of each of a pair's matches in view a and in view b, with a unit baseline, keyed
/// by the pixel in that view.
fn unit_baseline_depths(
    p: &PairPixels<'_>,
    intrinsics: &[Intrinsics],
) -> [HashMap<PixelKey, f64>; 2] {
    let (r, t) = (p.rotation, p.translation);
    let (ka, kb) = (&intrinsics[p.views.0], &intrinsics[p.views.1]);
    let ray = |k: &Intrinsics, x: &[f64; 2]| {
        Vector3::new((x[0] - k.cx) / k.fx, (x[1] - k.cy) / k.fy, 1.0)
    };
    let mut out = [HashMap::new(), HashMap::new()];
    for (xa, xb) in p.in_a.iter().zip(p.in_b) {
        let (fa, fb) = (r * ray(ka, xa), ray(kb, xb));
        if fa.angle(&fb).to_degrees() < MIN_PARALLAX_DEG {
            continue;
        }
        // x_b = R x_a + t: λ_a R f_a + t = λ_b f_b, in least squares.
        let m = Matrix3x2::from_columns(&[fa, -fb]);
        let Some(lambda) = (m.transpose() * m)
            .try_inverse()
            .map(|inv| inv * m.transpose() * (-t))
        else {
            continue;
        };
        if lambda[0] > 0.0 && lambda[1] > 0.0 {
            out[0].insert(key(xa), lambda[0]);
            out[1].insert(key(xb), lambda[1]);
        }
    }
    out
}

/// Weight of the pull of every log-length to 0, beside ratios weighted by their point counts.
const UNIT_PULL: f64 = 1e-6;

/// The lengths `exp(x)` from `x_p − x_q = m` for each ratio `(p, q, m, count)`.
fn solve_log_lengths(n: usize, ratios: &[(usize, usize, f64, usize)]) -> Vec<Option<f64>> {
    let mut measured = vec![false; n];
    let rows = ratios.len() + n;
    let mut a = DMatrix::<f64>::zeros(rows, n);
    let mut b = DVector::<f64>::zeros(rows);
    for (row, &(p, q, m, count)) in ratios.iter().enumerate() {
        let w = (count as f64).sqrt();
        a[(row, p)] = w;
        a[(row, q)] = -w;
        b[row] = w * m;
        measured[p] = true;
        measured[q] = true;
    }
    for p in 0..n {
        a[(ratios.len() + p, p)] = UNIT_PULL.sqrt();
    }
    let Ok(x) = a.svd(true, true).solve(&b, 1e-12) else {
        return vec![None; n];
    };
    (0..n).map(|p| measured[p].then(|| x[p].exp())).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ratios_give_the_lengths_up_to_one_scale() {
        // Three pairs with true lengths 1, 3 and 4: x_0 − x_1 = ln(1/3), x_0 − x_2 = ln(1/4).
        let ratios = [
            (0, 1, (1.0f64 / 3.0).ln(), 40),
            (0, 2, (0.25f64).ln(), 30),
            (1, 2, (0.75f64).ln(), 20),
        ];
        let lengths = solve_log_lengths(4, &ratios);
        let s = lengths[0].unwrap();
        assert!((lengths[1].unwrap() / s - 3.0).abs() < 1e-6, "{lengths:?}");
        assert!((lengths[2].unwrap() / s - 4.0).abs() < 1e-6, "{lengths:?}");
        assert_eq!(lengths[3], None);
    }
}
