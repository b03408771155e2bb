//! Exact binomial test, two-sided, as SciPy's `scipy.stats.binomtest(k, n, p).pvalue`: the sum
//! of the probabilities of every outcome no more likely than the observed one (with SciPy's
//! relative tolerance of 1e-7 on "no more likely"). The fusion paper (supplementary §6, Tables 1–2)
//! reports these p-values for each method pair's win count against the null of no preference
//! (`p = 0.5`).

use crate::error::{Result, StudyError};

/// Two-sided exact binomial p-value of `k` successes in `n` trials with success probability `p`.
pub fn binom_test_two_sided(k: u64, n: u64, p: f64) -> Result<f64> {
    if k > n {
        return Err(StudyError::invalid(format!(
            "binomial test: {k} successes in {n} trials"
        )));
    }
    if !(0.0..=1.0).contains(&p) {
        return Err(StudyError::invalid(format!(
            "binomial test: probability {p} outside [0, 1]"
        )));
    }
    if n == 0 {
        return Ok(1.0);
    }
    let logpmf = log_pmf_table(n, p);
    let observed = logpmf[k as usize];
    // SciPy: outcomes with pmf ≤ pmf(k)·(1 + 1e-7) count as "at least as extreme".
    let threshold = observed + (1.0 + 1e-7f64).ln();
    let total: f64 = logpmf
        .iter()
        .filter(|&&l| l <= threshold)
        .map(|&l| l.exp())
        .sum();
    Ok(total.min(1.0))
}

/// `ln P(X = i)`, `i = 0..=n`, for `X ~ Binomial(n, p)`, from a table of `ln i!`.
fn log_pmf_table(n: u64, p: f64) -> Vec<f64> {
    let n = n as usize;
    let mut ln_fact = vec![0.0f64; n + 1];
    for i in 1..=n {
        ln_fact[i] = ln_fact[i - 1] + (i as f64).ln();
    }
    (0..=n)
        .map(|i| {
            let ln_choose = ln_fact[n] - ln_fact[i] - ln_fact[n - i];
            let a = if i == 0 { 0.0 } else { i as f64 * p.ln() };
            let b = if i == n {
                0.0
            } else {
                (n - i) as f64 * (1.0 - p).ln()
            };
            ln_choose + a + b
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against a direct summation with exact integer binomial coefficients (n ≤ 60 fits u128).
    #[test]
    fn matches_exact_integer_reference() {
        fn choose(n: u64, k: u64) -> u128 {
            (0..k).fold(1u128, |acc, i| acc * (n - i) as u128 / (i + 1) as u128)
        }
        for n in [1u64, 2, 7, 20, 33, 60] {
            for k in 0..=n {
                let pk = choose(n, k);
                let extreme: u128 = (0..=n).map(|i| choose(n, i)).filter(|&c| c <= pk).sum();
                let reference = (extreme as f64 / 2f64.powi(n as i32)).min(1.0);
                let ours = binom_test_two_sided(k, n, 0.5).unwrap();
                assert!(
                    (ours - reference).abs() < 1e-12,
                    "n={n} k={k}: {ours} vs {reference}"
                );
            }
        }
    }

    /// The p-values the fusion paper prints in Table 2 for 144 responses per pair.
    #[test]
    fn reproduces_paper_000_table_2() {
        let cases = [
            (78, 0.359),
            (85, 0.037),
            (92, 0.001),
            (79, 0.279),
            (61, 0.08),
            (55, 0.006),
            (69, 0.677),
            (76, 0.56),
            (71, 0.934),
        ];
        for (k, printed) in cases {
            let p = binom_test_two_sided(k, 144, 0.5).unwrap();
            let digits = if printed == 0.08 { 2 } else { 3 };
            let scale = 10f64.powi(digits);
            assert_eq!((p * scale).round() / scale, printed, "k={k}: p={p}");
        }
    }

    #[test]
    fn rejects_bad_input() {
        assert!(binom_test_two_sided(5, 4, 0.5).is_err());
        assert!(binom_test_two_sided(1, 4, 1.5).is_err());
        assert_eq!(binom_test_two_sided(0, 0, 0.5).unwrap(), 1.0);
    }
}
