//! Single-head attention on the host, `softmax(q·kᵀ/√d)·v`, with the score matrix in a buffer
//! reused between calls: LighterGlue's score matrices hold millions of entries, and computing
//! them with two GEMMs and an in-place row softmax avoids allocating (and the kernel zeroing)
//! a fresh matrix per layer.

use std::cell::RefCell;

use rayon::prelude::*;

thread_local! {
    static SCORES: RefCell<Vec<f32>> = const { RefCell::new(Vec::new()) };
}

/// `softmax(q·kᵀ/√d)·v` for row-major `q [m×d]`, `k [n×d]`, `v [n×dv]`; returns `[m×dv]`.
pub fn attend(q: &[f32], k: &[f32], v: &[f32], d: usize, dv: usize) -> Vec<f32> {
    let (m, n) = (q.len() / d, k.len() / d);
    let mut out = vec![0.0f32; m * dv];
    if m == 0 || n == 0 {
        return out;
    }
    SCORES.with_borrow_mut(|scores| {
        scores.resize(m * n, 0.0);
        scaled_scores(q, k, m, n, d, scores);
        scores.par_chunks_mut(n).for_each(softmax_in_place);
        // out[m×dv] = scores[m×n] · v[n×dv]
        unsafe {
            gemm::gemm(
                m,
                dv,
                n,
                out.as_mut_ptr(),
                1,
                dv as isize,
                false,
                scores.as_ptr(),
                1,
                n as isize,
                v.as_ptr(),
                1,
                dv as isize,
                0.0,
                1.0,
                false,
                false,
                false,
                gemm::Parallelism::Rayon(0),
            );
        }
    });
    out
}

/// `scores[m×n] = q·kᵀ / √d`.
fn scaled_scores(q: &[f32], k: &[f32], m: usize, n: usize, d: usize, scores: &mut [f32]) {
    // kᵀ[d×n]: element (row r, column j) is k[j·d + r].
    unsafe {
        gemm::gemm(
            m,
            n,
            d,
            scores.as_mut_ptr(),
            1,
            n as isize,
            false,
            q.as_ptr(),
            1,
            d as isize,
            k.as_ptr(),
            d as isize,
            1,
            0.0,
            1.0 / (d as f32).sqrt(),
            false,
            false,
            false,
            gemm::Parallelism::Rayon(0),
        );
    }
}

/// Softmax of one row, in place. Terms more than 87 below the maximum are zero (their
/// exponential underflows single precision), which spares `exp` its slow underflow path.
pub fn softmax_in_place(row: &mut [f32]) {
    let max = row.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let mut sum = 0.0f32;
    for x in row.iter_mut() {
        let t = *x - max;
        *x = if t < -87.0 { 0.0 } else { t.exp() };
        sum += *x;
    }
    let inv = 1.0 / sum;
    row.iter_mut().for_each(|x| *x *= inv);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The same attention, one dot product at a time.
    fn naive(q: &[f32], k: &[f32], v: &[f32], d: usize, dv: usize) -> Vec<f32> {
        let (m, n) = (q.len() / d, k.len() / d);
        let mut out = vec![0.0f32; m * dv];
        for i in 0..m {
            let s: Vec<f64> = (0..n)
                .map(|j| {
                    (0..d)
                        .map(|c| (q[i * d + c] * k[j * d + c]) as f64)
                        .sum::<f64>()
                        / (d as f64).sqrt()
                })
                .collect();
            let max = s.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let e: Vec<f64> = s.iter().map(|x| (x - max).exp()).collect();
            let sum: f64 = e.iter().sum();
            for c in 0..dv {
                out[i * dv + c] = (0..n)
                    .map(|j| e[j] / sum * v[j * dv + c] as f64)
                    .sum::<f64>() as f32;
            }
        }
        out
    }

    #[test]
    fn attention_equals_the_naive_sum() {
        let (m, n, d, dv) = (37, 53, 8, 5);
        let value = |i: usize, s: usize| (((i * 7919 + s * 104729) % 1000) as f32 / 250.0) - 2.0;
        let q: Vec<f32> = (0..m * d).map(|i| value(i, 1)).collect();
        let k: Vec<f32> = (0..n * d).map(|i| value(i, 2)).collect();
        let v: Vec<f32> = (0..n * dv).map(|i| value(i, 3)).collect();
        let ours = attend(&q, &k, &v, d, dv);
        let reference = naive(&q, &k, &v, d, dv);
        for (a, b) in ours.iter().zip(&reference) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
    }

    #[test]
    fn softmax_ignores_underflowing_terms_and_sums_to_one() {
        let mut row = [0.0f32, -200.0, 1.0, -90.0];
        softmax_in_place(&mut row);
        assert_eq!((row[1], row[3]), (0.0, 0.0));
        let e = 1f32.exp();
        assert!(
            (row[2] - e / (1.0 + e)).abs() < 1e-7 && (row.iter().sum::<f32>() - 1.0).abs() < 1e-6
        );
    }
}
