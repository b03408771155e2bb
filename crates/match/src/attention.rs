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

/// Softmax of one row, in place, with the AVX2 + FMA build where the CPU has it.
pub fn softmax_in_place(row: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if fewview_scene::cpu::avx2_fma() {
        // SAFETY: the CPU has AVX2 and FMA (checked just above).
        return unsafe { softmax_avx2(row) };
    }
    softmax_body(row);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn softmax_avx2(row: &mut [f32]) {
    softmax_body(row);
}

/// `exp(x − max) / Σ` with a branch-free exponential and eight partial sums and maxima, so
/// that every loop vectorises.
#[inline(always)]
fn softmax_body(row: &mut [f32]) {
    let max = lanes(row, f32::NEG_INFINITY, |a, b| if a > b { a } else { b });
    row.iter_mut().for_each(|x| *x = exp(*x - max));
    let inv = 1.0 / lanes(row, 0.0, |a, b| a + b);
    row.iter_mut().for_each(|x| *x *= inv);
}

/// `row` reduced by `op` in eight interleaved lanes, then across them.
#[inline(always)]
fn lanes(row: &[f32], init: f32, op: impl Fn(f32, f32) -> f32) -> f32 {
    let mut acc = [init; 8];
    let chunks = row.chunks_exact(8);
    let rest = chunks.remainder();
    for chunk in chunks {
        for k in 0..8 {
            acc[k] = op(acc[k], chunk[k]);
        }
    }
    rest.iter().chain(&acc).fold(init, |a, &b| op(a, b))
}

/// `eˣ` to about one unit in the last place (Cephes' `expf`: `2ⁿ · eʳ` with `n = ⌊x·log₂e⌉`,
/// `r` reduced by a two-part ln 2, `eʳ` by a degree-6 polynomial), branch-free; arguments below
/// −87.3 give the smallest normal number's neighbourhood instead of underflowing to 0.
#[inline(always)]
fn exp(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    let x = x.clamp(-87.3, 88.7);
    let n = (x * LOG2E + 0.5).floor();
    let r = x - n * LN2_HI - n * LN2_LO;
    let mut p = 1.987_569_2e-4f32;
    p = p * r + 1.398_199_9e-3;
    p = p * r + 8.333_452e-3;
    p = p * r + 4.166_579_6e-2;
    p = p * r + 1.666_666_5e-1;
    p = p * r + 0.5;
    let e_r = p * r * r + r + 1.0;
    e_r * f32::from_bits(((n as i32 + 127) as u32) << 23)
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
    fn the_exponential_is_within_a_few_ulp_of_std() {
        let mut worst = 0.0f32;
        for i in -87_000..=88_000 {
            let x = i as f32 * 1e-3;
            worst = worst.max((exp(x) - x.exp()).abs() / x.exp());
        }
        assert!(worst < 4e-7, "{worst}");
    }

    #[test]
    fn softmax_sums_to_one_and_neglects_far_terms() {
        let mut row = [0.0f32, -200.0, 1.0, -90.0];
        softmax_in_place(&mut row);
        assert!(row[1] < 1e-37 && row[3] < 1e-37, "{row:?}");
        let e = 1f32.exp();
        assert!(
            (row[2] - e / (1.0 + e)).abs() < 1e-7 && (row.iter().sum::<f32>() - 1.0).abs() < 1e-6
        );
    }
}
