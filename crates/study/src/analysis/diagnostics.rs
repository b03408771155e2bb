//! MCMC convergence diagnostics of Vehtari, Gelman, Simpson, Carpenter & Bürkner (2021),
//! "Rank-normalization, folding, and localization: an improved R̂", as ArviZ computes them
//! (`az.rhat(method="rank")`, `az.ess(method="bulk")`, `az.ess(method="tail")`): split chains,
//! rank-normalise with Blom's offset (3/8), R̂ = max(bulk, folded), and the effective sample size
//! from Geyer's initial monotone sequence of the chain-averaged autocorrelations.

use crate::error::{Result, StudyError};

/// The fewest draws per chain: the chains are split in halves, and Geyer's initial positive
/// sequence in `ess` looks at lags 1 to 3 of each half, so a half needs at least 5 draws.
pub const MIN_DRAWS: usize = 10;

/// Rank-normalised split R̂ (the larger of the bulk and the folded-tail value).
/// `chains[c][i]` is draw `i` of chain `c`; every chain needs the same number (≥ [`MIN_DRAWS`])
/// of draws.
pub fn rhat_rank(chains: &[Vec<f64>]) -> Result<f64> {
    check(chains)?;
    let split = split_chains(chains);
    let bulk = rhat_plain(&z_scale(&split));
    let median = quantile_sorted(&sorted_all(&split), 0.5);
    let folded: Vec<Vec<f64>> = split
        .iter()
        .map(|c| c.iter().map(|v| (v - median).abs()).collect())
        .collect();
    let tail = rhat_plain(&z_scale(&folded));
    Ok(bulk.max(tail))
}

/// Bulk effective sample size (rank-normalised split chains).
pub fn ess_bulk(chains: &[Vec<f64>]) -> Result<f64> {
    check(chains)?;
    Ok(ess(&z_scale(&split_chains(chains))))
}

/// Tail effective sample size: the smaller ESS of the 5% and 95% quantile indicators.
pub fn ess_tail(chains: &[Vec<f64>]) -> Result<f64> {
    check(chains)?;
    let sorted = sorted_all(chains);
    let (q05, q95) = (
        quantile_sorted(&sorted, 0.05),
        quantile_sorted(&sorted, 0.95),
    );
    let indicator = |q: f64| -> Vec<Vec<f64>> {
        chains
            .iter()
            .map(|c| c.iter().map(|&v| if v <= q { 1.0 } else { 0.0 }).collect())
            .collect()
    };
    let low = ess(&split_chains(&indicator(q05)));
    let high = ess(&split_chains(&indicator(q95)));
    Ok(low.min(high))
}

fn check(chains: &[Vec<f64>]) -> Result<()> {
    let n = chains.first().map_or(0, Vec::len);
    if chains.is_empty() || n < MIN_DRAWS || chains.iter().any(|c| c.len() != n) {
        return Err(StudyError::invalid(format!(
            "diagnostics need chains of equal length with at least {MIN_DRAWS} draws"
        )));
    }
    if chains.iter().flatten().any(|v| !v.is_finite()) {
        return Err(StudyError::invalid(
            "diagnostics: draws contain NaN or infinite values",
        ));
    }
    Ok(())
}

/// Each chain's first and last `⌊n/2⌋` draws as two chains (ArviZ `_split_chains`).
fn split_chains(chains: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let half = chains[0].len() / 2;
    let mut out: Vec<Vec<f64>> = chains.iter().map(|c| c[..half].to_vec()).collect();
    out.extend(chains.iter().map(|c| c[c.len() - half..].to_vec()));
    out
}

fn sorted_all(chains: &[Vec<f64>]) -> Vec<f64> {
    let mut all: Vec<f64> = chains.iter().flatten().copied().collect();
    all.sort_by(f64::total_cmp);
    all
}

/// NumPy's default (linear) quantile of sorted data.
fn quantile_sorted(sorted: &[f64], q: f64) -> f64 {
    let pos = q * (sorted.len() - 1) as f64;
    let (lo, frac) = (pos.floor() as usize, pos - pos.floor());
    let hi = (lo + 1).min(sorted.len() - 1);
    sorted[lo] + frac * (sorted[hi] - sorted[lo])
}

/// Rank normalisation: pooled average ranks `r`, then `Φ⁻¹((r − 3/8) / (S + 1/4))`.
fn z_scale(chains: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let all: Vec<f64> = chains.iter().flatten().copied().collect();
    let s = all.len();
    let mut order: Vec<usize> = (0..s).collect();
    order.sort_by(|&a, &b| all[a].total_cmp(&all[b]));
    let mut rank = vec![0.0; s];
    let mut i = 0;
    while i < s {
        let mut j = i;
        while j + 1 < s && all[order[j + 1]] == all[order[i]] {
            j += 1;
        }
        let average = (i + j) as f64 / 2.0 + 1.0;
        for &k in &order[i..=j] {
            rank[k] = average;
        }
        i = j + 1;
    }
    let mut out = Vec::with_capacity(chains.len());
    let mut k = 0;
    for c in chains {
        out.push(
            c.iter()
                .map(|_| {
                    let z = normal_quantile((rank[k] - 0.375) / (s as f64 + 0.25));
                    k += 1;
                    z
                })
                .collect(),
        );
    }
    out
}

/// Classic R̂ of (already split) chains.
fn rhat_plain(chains: &[Vec<f64>]) -> f64 {
    let m = chains.len() as f64;
    let n = chains[0].len() as f64;
    let means: Vec<f64> = chains.iter().map(|c| c.iter().sum::<f64>() / n).collect();
    let vars: Vec<f64> = chains
        .iter()
        .zip(&means)
        .map(|(c, mu)| c.iter().map(|v| (v - mu).powi(2)).sum::<f64>() / (n - 1.0))
        .collect();
    let grand = means.iter().sum::<f64>() / m;
    let between = n * means.iter().map(|mu| (mu - grand).powi(2)).sum::<f64>() / (m - 1.0);
    let within = vars.iter().sum::<f64>() / m;
    ((between / within + n - 1.0) / n).sqrt()
}

/// Effective sample size of (already split/normalised) chains (ArviZ `_ess`).
fn ess(chains: &[Vec<f64>]) -> f64 {
    let m = chains.len();
    let n = chains[0].len();
    let (lo, hi) = chains
        .iter()
        .flatten()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    if hi - lo < 1e-15 {
        return (m * n) as f64;
    }
    let centred: Vec<Vec<f64>> = chains
        .iter()
        .map(|c| {
            let mu = c.iter().sum::<f64>() / n as f64;
            c.iter().map(|v| v - mu).collect()
        })
        .collect();
    // Chain-averaged biased autocovariance at lag t (computed on demand: Geyer's sequence
    // usually stops after a few lags).
    let mean_acov = |t: usize| -> f64 {
        centred
            .iter()
            .map(|c| {
                c[..n - t]
                    .iter()
                    .zip(&c[t..])
                    .map(|(a, b)| a * b)
                    .sum::<f64>()
                    / n as f64
            })
            .sum::<f64>()
            / m as f64
    };
    let nf = n as f64;
    let mean_var = mean_acov(0) * nf / (nf - 1.0);
    let mut var_plus = mean_var * (nf - 1.0) / nf;
    if m > 1 {
        let means: Vec<f64> = chains.iter().map(|c| c.iter().sum::<f64>() / nf).collect();
        let grand = means.iter().sum::<f64>() / m as f64;
        var_plus += means.iter().map(|mu| (mu - grand).powi(2)).sum::<f64>() / (m as f64 - 1.0);
    }
    let rho = |t: usize| 1.0 - (mean_var - mean_acov(t)) / var_plus;
    let mut rho_hat = vec![0.0; n];
    let mut even = 1.0;
    rho_hat[0] = even;
    let mut odd = rho(1);
    rho_hat[1] = odd;
    // Geyer's initial positive sequence.
    let mut t = 1;
    while t + 3 < n && even + odd > 0.0 {
        even = rho(t + 1);
        odd = rho(t + 2);
        if even + odd >= 0.0 {
            rho_hat[t + 1] = even;
            rho_hat[t + 2] = odd;
        }
        t += 2;
    }
    let total = (m * n) as f64;
    // τ is clamped below at 1 / log₁₀(total draws), as ArviZ does.
    let ess_of_tau = |tau: f64| total / tau.max(1.0 / total.log10());
    // ArviZ's `max_t = t - 2` is −1 when the sequence stops at once (ρ̂₁ ≤ −1, a chain that
    // alternates): no lag is summed, τ = −1 + ρ̂₀.
    let Some(max_t) = t.checked_sub(2) else {
        return ess_of_tau(-1.0 + rho_hat[0]);
    };
    if even > 0.0 {
        rho_hat[max_t + 1] = even;
    }
    // Geyer's initial monotone sequence.
    let mut t = 1;
    while t + 2 <= max_t {
        if rho_hat[t + 1] + rho_hat[t + 2] > rho_hat[t - 1] + rho_hat[t] {
            rho_hat[t + 1] = (rho_hat[t - 1] + rho_hat[t]) / 2.0;
            rho_hat[t + 2] = rho_hat[t + 1];
        }
        t += 2;
    }
    let tau = -1.0
        + 2.0 * rho_hat[..=max_t].iter().sum::<f64>()
        + rho_hat.get(max_t + 1).copied().unwrap_or(0.0);
    ess_of_tau(tau)
}

/// Standard normal quantile Φ⁻¹(p), Wichura's algorithm AS 241 (PPND16, relative accuracy about
/// 1e-16), `p ∈ (0, 1)`.
#[allow(clippy::excessive_precision)] // the published AS 241 coefficients, verbatim
pub fn normal_quantile(p: f64) -> f64 {
    let q = p - 0.5;
    if q.abs() <= 0.425 {
        let r = 0.180625 - q * q;
        return q
            * (((((((2509.0809287301226727 * r + 33430.575583588128105) * r
                + 67265.770927008700853)
                * r
                + 45921.953931549871457)
                * r
                + 13731.693765509461125)
                * r
                + 1971.5909503065514427)
                * r
                + 133.14166789178437745)
                * r
                + 3.387132872796366608)
            / (((((((5226.495278852545925 * r + 28729.085735721942674) * r
                + 39307.89580009271061)
                * r
                + 21213.794301586595867)
                * r
                + 5394.1960214247511077)
                * r
                + 687.1870074920579083)
                * r
                + 42.313330701600911252)
                * r
                + 1.0);
    }
    let mut r = if q < 0.0 { p } else { 1.0 - p };
    r = (-r.ln()).sqrt();
    let value = if r <= 5.0 {
        let r = r - 1.6;
        (((((((7.7454501427834140764e-4 * r + 0.0227238449892691845833) * r
            + 0.24178072517745061177)
            * r
            + 1.27045825245236838258)
            * r
            + 3.64784832476320460504)
            * r
            + 5.7694972214606914055)
            * r
            + 4.6303378461565452959)
            * r
            + 1.42343711074968357734)
            / (((((((1.05075007164441684324e-9 * r + 5.475938084995344946e-4) * r
                + 0.0151986665636164571966)
                * r
                + 0.14810397642748007459)
                * r
                + 0.68976733498510000455)
                * r
                + 1.6763848301838038494)
                * r
                + 2.05319162663775882187)
                * r
                + 1.0)
    } else {
        let r = r - 5.0;
        (((((((2.01033439929228813265e-7 * r + 2.71155556874348757815e-5) * r
            + 0.0012426609473880784386)
            * r
            + 0.026532189526576123093)
            * r
            + 0.29656057182850489123)
            * r
            + 1.7848265399172913358)
            * r
            + 5.4637849111641143699)
            * r
            + 6.6579046435011037772)
            / (((((((2.04426310338993978564e-15 * r + 1.4215117583164458887e-7) * r
                + 1.8463183175100546818e-5)
                * r
                + 7.868691311456132591e-4)
                * r
                + 0.0148753612908506148525)
                * r
                + 0.13692988092273580531)
                * r
                + 0.59983220655588793769)
                * r
                + 1.0)
    };
    if q < 0.0 { -value } else { value }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_quantile_known_values() {
        // Φ⁻¹ values from tables (SciPy `norm.ppf`).
        let cases = [
            (0.5, 0.0),
            (0.975, 1.959963984540054),
            (0.1, -1.2815515655446004),
            (1e-10, -6.361340902404056),
        ];
        for (p, z) in cases {
            assert!(
                (normal_quantile(p) - z).abs() < 1e-12,
                "{p}: {}",
                normal_quantile(p)
            );
        }
    }

    /// Fewer than [`MIN_DRAWS`] draws is an error, not an index out of bounds.
    #[test]
    fn short_chains_are_refused() {
        for n in 0..MIN_DRAWS {
            let chains = vec![(0..n).map(|i| (i * 7 % 5) as f64).collect::<Vec<_>>(); 2];
            assert!(rhat_rank(&chains).is_err(), "{n}");
            assert!(ess_bulk(&chains).is_err(), "{n}");
            assert!(ess_tail(&chains).is_err(), "{n}");
        }
        let chains: Vec<Vec<f64>> = (0..2)
            .map(|c| {
                (0..MIN_DRAWS)
                    .map(|i| ((i * 7 + c * 3) % 5) as f64)
                    .collect()
            })
            .collect();
        assert!(rhat_rank(&chains).unwrap().is_finite());
        assert!(ess_bulk(&chains).unwrap() > 0.0);
        assert!(ess_tail(&chains).unwrap() > 0.0);
    }

    /// Chains that alternate have ρ̂₁ < −1, so Geyer's sequence stops before its first step
    /// (ArviZ's `max_t = -1`); that used to underflow `t - 2`.
    #[test]
    fn alternating_chains_do_not_underflow() {
        let chains: Vec<Vec<f64>> = (0..2)
            .map(|_| {
                (0..12)
                    .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
                    .collect()
            })
            .collect();
        let ess = ess_bulk(&chains).unwrap();
        assert!(ess.is_finite() && ess > 0.0, "{ess}");
    }
}
