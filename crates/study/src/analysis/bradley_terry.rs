//! Bayesian Bradley–Terry model of the fusion paper (supplementary §5): each method's skill
//! `s_m ~ Normal(0, σ = 2)`; each comparison won by `w` against `l` is a Bernoulli observation of
//! probability `logistic(s_w − s_l)`. The posterior is sampled with NUTS (`nuts-rs`, the sampler
//! behind PyMC's `nutpie`) with the paper's settings: 4 chains, 4000 tuning steps, 4000 draws,
//! target acceptance 0.95. Comparisons with the same winner and loser are summed into one
//! binomial-count term, which leaves the log-posterior unchanged.
//!
//! The paper says only "N(0, 2)"; PyMC's `pm.Normal(mu, sigma)` takes the standard deviation, so
//! σ = 2 is the default here and [`BtSettings::prior_sigma`] changes it.

use std::collections::HashMap;

use nuts_rs::{Chain, CpuLogpFunc, CpuMath, DiagNutsSettings, HasDims, LogpError, Settings};
use rayon::prelude::*;

use super::diagnostics::{ess_bulk, ess_tail, rhat_rank};
use crate::error::{Result, StudyError};

/// The fewest post-tuning draws per chain the convergence diagnostics can use: R̂ and the ESS
/// split every chain in halves, and Geyer's initial positive sequence
/// ([`super::diagnostics`]) needs at least 5 draws per half.
pub const MIN_DRAWS: u64 = super::diagnostics::MIN_DRAWS as u64;

/// The most post-tuning draws per chain. Every draw of every method is kept in memory (8 bytes
/// each, and the diagnostics copy them a few times over) and costs a NUTS trajectory: 10⁶ draws
/// is 250 times the paper's 4000 and a few hundred MB for a dozen methods, while 10¹¹ draws
/// reached 1.3 GB before sampling got anywhere.
pub const MAX_DRAWS: u64 = 1_000_000;

/// Sampler settings (defaults: the paper's).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct BtSettings {
    /// Standard deviation of the Normal(0, σ) skill prior.
    pub prior_sigma: f64,
    pub chains: usize,
    pub tune: u64,
    pub draws: u64,
    pub target_accept: f64,
    pub seed: u64,
    /// Mass of the equal-tailed credible intervals reported (0.95).
    pub credible_mass: f64,
}

impl Default for BtSettings {
    fn default() -> Self {
        Self {
            prior_sigma: 2.0,
            chains: 4,
            tune: 4000,
            draws: 4000,
            target_accept: 0.95,
            seed: 0,
            credible_mass: 0.95,
        }
    }
}

/// Posterior summary of one method's skill.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SkillSummary {
    pub method: String,
    pub mean: f64,
    pub sd: f64,
    /// Equal-tailed credible interval of mass [`BtSettings::credible_mass`].
    pub lower: f64,
    pub upper: f64,
    pub rhat: f64,
    pub ess_bulk: f64,
    pub ess_tail: f64,
    /// The skill relative to the mean of all methods' skills in the same draw
    /// (`s_m − mean_j s_j`): the likelihood only sees skill differences, so the common level is
    /// set by the prior alone and widens every raw interval alike; the relative skill removes it.
    /// Posterior mean and equal-tailed interval. The ranking plot shows these.
    pub relative_mean: f64,
    pub relative_lower: f64,
    pub relative_upper: f64,
}

/// The fitted model: per-method summaries (in the input order), pairwise posterior win
/// probabilities, and sampler diagnostics.
#[derive(Clone, Debug, serde::Serialize)]
pub struct BtPosterior {
    pub methods: Vec<String>,
    pub skills: Vec<SkillSummary>,
    /// `win_probability[i][j]` = posterior mean of `logistic(s_i − s_j)`: the probability that
    /// method `i` wins a new comparison against `j`.
    pub win_probability: Vec<Vec<f64>>,
    /// `prob_better[i][j]` = posterior probability that `s_i > s_j`.
    pub prob_better: Vec<Vec<f64>>,
    pub divergences: u64,
    pub max_rhat: f64,
    pub min_ess_bulk: f64,
    pub settings: BtSettings,
}

impl BtPosterior {
    /// Method indices from the highest to the lowest posterior mean skill.
    pub fn ranking(&self) -> Vec<usize> {
        let mut order: Vec<usize> = (0..self.methods.len()).collect();
        order.sort_by(|&a, &b| self.skills[b].mean.total_cmp(&self.skills[a].mean));
        order
    }
}

/// One (winner, loser, count) term of the likelihood, by method index.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WinCount {
    pub winner: usize,
    pub loser: usize,
    pub count: u64,
}

#[derive(Debug)]
struct BtLogp {
    dim: usize,
    terms: Vec<WinCount>,
    inv_var: f64,
}

#[derive(Debug, thiserror::Error)]
#[error("non-finite log density")]
struct BtLogpError;

impl LogpError for BtLogpError {
    fn is_recoverable(&self) -> bool {
        true
    }
}

impl HasDims for BtLogp {
    fn dim_sizes(&self) -> HashMap<String, u64> {
        HashMap::from([("unconstrained_parameter".to_string(), self.dim as u64)])
    }
}

/// `ln σ(d)` computed stably for either sign of `d`.
fn log_sigmoid(d: f64) -> f64 {
    if d >= 0.0 {
        -(-d).exp().ln_1p()
    } else {
        d - d.exp().ln_1p()
    }
}

fn sigmoid(d: f64) -> f64 {
    if d >= 0.0 {
        1.0 / (1.0 + (-d).exp())
    } else {
        d.exp() / (1.0 + d.exp())
    }
}

impl BtLogp {
    /// Log posterior (up to a constant) and its gradient.
    fn eval(&self, s: &[f64], grad: &mut [f64]) -> f64 {
        let mut logp = 0.0;
        for (g, &v) in grad.iter_mut().zip(s) {
            logp -= 0.5 * v * v * self.inv_var;
            *g = -v * self.inv_var;
        }
        for t in &self.terms {
            let d = s[t.winner] - s[t.loser];
            let n = t.count as f64;
            logp += n * log_sigmoid(d);
            // d/dd ln σ(d) = 1 − σ(d) = σ(−d)
            let dl = n * sigmoid(-d);
            grad[t.winner] += dl;
            grad[t.loser] -= dl;
        }
        logp
    }
}

impl CpuLogpFunc for BtLogp {
    type LogpError = BtLogpError;
    type FlowParameters = ();
    type ExpandedVector = Vec<f64>;

    fn dim(&self) -> usize {
        self.dim
    }

    fn logp(
        &mut self,
        position: &[f64],
        grad: &mut [f64],
    ) -> std::result::Result<f64, BtLogpError> {
        let v = self.eval(position, grad);
        if v.is_finite() {
            Ok(v)
        } else {
            Err(BtLogpError)
        }
    }

    fn expand_vector<R>(
        &mut self,
        _rng: &mut R,
        array: &[f64],
    ) -> std::result::Result<Vec<f64>, nuts_rs::CpuMathError>
    where
        R: nuts_rs::rand::Rng + ?Sized,
    {
        Ok(array.to_vec())
    }
}

/// SplitMix64: a seeded stream for the chains' initial positions.
fn splitmix(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Samples the posterior skills of `methods` given the win counts; returns the summaries.
pub fn fit_bradley_terry(
    methods: &[String],
    wins: &[WinCount],
    settings: &BtSettings,
) -> Result<BtPosterior> {
    let k = methods.len();
    if k < 2 {
        return Err(StudyError::invalid(
            "Bradley–Terry needs at least two methods",
        ));
    }
    if let Some(t) = wins
        .iter()
        .find(|t| t.winner >= k || t.loser >= k || t.winner == t.loser)
    {
        return Err(StudyError::invalid(format!(
            "Bradley–Terry: bad comparison {t:?} for {k} methods"
        )));
    }
    if !(settings.prior_sigma > 0.0 && settings.prior_sigma.is_finite()) {
        return Err(StudyError::invalid(
            "Bradley–Terry: prior sigma must be positive",
        ));
    }
    if settings.chains < 1 || !(0.0 < settings.target_accept && settings.target_accept < 1.0) {
        return Err(StudyError::invalid(
            "Bradley–Terry: need ≥ 1 chain and a target acceptance in (0, 1)",
        ));
    }
    if !(MIN_DRAWS..=MAX_DRAWS).contains(&settings.draws) {
        return Err(StudyError::invalid(format!(
            "Bradley–Terry: {} draws per chain; expected {MIN_DRAWS} to {MAX_DRAWS}",
            settings.draws
        )));
    }
    if !(0.0 < settings.credible_mass && settings.credible_mass < 1.0) {
        return Err(StudyError::invalid(
            "Bradley–Terry: credible mass must be in (0, 1)",
        ));
    }

    let mut nuts = DiagNutsSettings {
        num_tune: settings.tune,
        num_draws: settings.draws,
        seed: settings.seed,
        num_chains: settings.chains,
        ..Default::default()
    };
    nuts.adapt_options.step_size_settings.target_accept = settings.target_accept;

    let terms: Vec<WinCount> = wins.iter().copied().filter(|t| t.count > 0).collect();
    let inv_var = 1.0 / (settings.prior_sigma * settings.prior_sigma);
    // Per chain: draws[method][i], and the number of divergent post-tuning transitions.
    let chains: Vec<Result<(Vec<Vec<f64>>, u64)>> = (0..settings.chains)
        .into_par_iter()
        .map(|chain| {
            let logp = BtLogp {
                dim: k,
                terms: terms.clone(),
                inv_var,
            };
            let mut rng =
                <nuts_rs::rand::rngs::StdRng as nuts_rs::rand::SeedableRng>::seed_from_u64(
                    settings.seed ^ (chain as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
                );
            let mut sampler = nuts
                .new_chain(chain as u64, CpuMath::new(logp), &mut rng)
                .map_err(|e| StudyError::invalid(format!("NUTS setup: {e}")))?;
            // PyMC's default initialisation: uniform jitter in (−1, 1) around zero.
            let mut state = settings
                .seed
                .wrapping_add(0x1234_5678)
                .wrapping_mul(chain as u64 + 1);
            let init: Vec<f64> = (0..k)
                .map(|_| (splitmix(&mut state) >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0)
                .collect();
            sampler
                .set_position(&init)
                .map_err(|e| StudyError::invalid(format!("NUTS init: {e}")))?;
            let mut draws = vec![Vec::with_capacity(settings.draws as usize); k];
            let mut divergences = 0;
            for _ in 0..settings.tune + settings.draws {
                let (pos, info) = sampler
                    .draw()
                    .map_err(|e| StudyError::invalid(format!("NUTS draw: {e}")))?;
                if info.tuning {
                    continue;
                }
                divergences += info.diverging as u64;
                for (d, &v) in draws.iter_mut().zip(pos.iter()) {
                    d.push(v);
                }
            }
            Ok((draws, divergences))
        })
        .collect();
    let chains: Vec<(Vec<Vec<f64>>, u64)> = chains.into_iter().collect::<Result<_>>()?;
    if chains.iter().any(|(d, _)| (d[0].len() as u64) < MIN_DRAWS) {
        return Err(StudyError::invalid(
            "NUTS returned fewer post-tuning draws than asked for",
        ));
    }
    summarise(methods, &chains, settings)
}

fn summarise(
    methods: &[String],
    chains: &[(Vec<Vec<f64>>, u64)],
    settings: &BtSettings,
) -> Result<BtPosterior> {
    let k = methods.len();
    let alpha = (1.0 - settings.credible_mass) / 2.0;
    let mut skills = Vec::with_capacity(k);
    // Per draw, the mean skill over methods.
    let level: Vec<f64> = chains
        .iter()
        .flat_map(|(d, _)| {
            (0..d[0].len()).map(move |i| d.iter().map(|m| m[i]).sum::<f64>() / d.len() as f64)
        })
        .collect();
    let quantile = |sorted: &[f64], p: f64| {
        let pos = p * (sorted.len() - 1) as f64;
        let lo = pos.floor() as usize;
        let hi = (lo + 1).min(sorted.len() - 1);
        sorted[lo] + (pos - lo as f64) * (sorted[hi] - sorted[lo])
    };
    for (m, name) in methods.iter().enumerate() {
        let per_chain: Vec<Vec<f64>> = chains.iter().map(|(d, _)| d[m].clone()).collect();
        let mut all: Vec<f64> = per_chain.iter().flatten().copied().collect();
        let mut relative: Vec<f64> = all.iter().zip(&level).map(|(s, l)| s - l).collect();
        let n = all.len() as f64;
        let mean = all.iter().sum::<f64>() / n;
        let relative_mean = relative.iter().sum::<f64>() / n;
        let sd = (all.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        all.sort_by(f64::total_cmp);
        relative.sort_by(f64::total_cmp);
        let q = |p: f64| quantile(&all, p);
        skills.push(SkillSummary {
            relative_mean,
            relative_lower: quantile(&relative, alpha),
            relative_upper: quantile(&relative, 1.0 - alpha),
            method: name.clone(),
            mean,
            sd,
            lower: q(alpha),
            upper: q(1.0 - alpha),
            rhat: rhat_rank(&per_chain)?,
            ess_bulk: ess_bulk(&per_chain)?,
            ess_tail: ess_tail(&per_chain)?,
        });
    }
    let mut win_probability = vec![vec![0.5; k]; k];
    let mut prob_better = vec![vec![0.5; k]; k];
    let total: usize = chains.iter().map(|(d, _)| d[0].len()).sum();
    for i in 0..k {
        for j in 0..k {
            if i == j {
                continue;
            }
            let (mut p, mut b) = (0.0, 0usize);
            for (d, _) in chains {
                for (si, sj) in d[i].iter().zip(&d[j]) {
                    p += sigmoid(si - sj);
                    b += (si > sj) as usize;
                }
            }
            win_probability[i][j] = p / total as f64;
            prob_better[i][j] = b as f64 / total as f64;
        }
    }
    let max_rhat = skills
        .iter()
        .map(|s| s.rhat)
        .fold(f64::NEG_INFINITY, f64::max);
    let min_ess_bulk = skills
        .iter()
        .map(|s| s.ess_bulk)
        .fold(f64::INFINITY, f64::min);
    Ok(BtPosterior {
        methods: methods.to_vec(),
        skills,
        win_probability,
        prob_better,
        divergences: chains.iter().map(|(_, d)| d).sum(),
        max_rhat,
        min_ess_bulk,
        settings: settings.clone(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gradient_matches_finite_differences() {
        let model = BtLogp {
            dim: 3,
            terms: vec![
                WinCount {
                    winner: 0,
                    loser: 1,
                    count: 7,
                },
                WinCount {
                    winner: 1,
                    loser: 0,
                    count: 2,
                },
                WinCount {
                    winner: 2,
                    loser: 1,
                    count: 5,
                },
            ],
            inv_var: 0.25,
        };
        let s = [0.3, -0.7, 1.1];
        let mut g = [0.0; 3];
        model.eval(&s, &mut g);
        for i in 0..3 {
            let (mut p, mut m) = (s, s);
            p[i] += 1e-6;
            m[i] -= 1e-6;
            let mut scratch = [0.0; 3];
            let fd = (model.eval(&p, &mut scratch) - model.eval(&m, &mut scratch)) / 2e-6;
            assert!((fd - g[i]).abs() < 1e-6, "{i}: {fd} vs {}", g[i]);
        }
    }

    /// Two methods, no data: the posterior is the prior, so each skill has mean 0 and sd 2, and
    /// `P(s_0 > s_1) = 1/2`.
    #[test]
    fn without_data_the_posterior_is_the_prior() {
        let methods = vec!["a".to_string(), "b".to_string()];
        let settings = BtSettings {
            tune: 1000,
            draws: 2000,
            seed: 3,
            ..Default::default()
        };
        let post = fit_bradley_terry(&methods, &[], &settings).unwrap();
        for s in &post.skills {
            assert!(s.mean.abs() < 0.15, "{s:?}");
            assert!((s.sd - 2.0).abs() < 0.15, "{s:?}");
            // 95% interval of N(0, 2): ±3.92
            assert!(
                (s.upper - 3.92).abs() < 0.3 && (s.lower + 3.92).abs() < 0.3,
                "{s:?}"
            );
            assert!(s.rhat < 1.01);
        }
        assert!((post.prob_better[0][1] - 0.5).abs() < 0.05);
    }

    /// 4 to 9 draws passed the old `≥ 4` check and then indexed out of bounds in the ESS
    /// (fuzzing: `study analyze --draws 4`); too many draws are refused before any allocation.
    #[test]
    fn draw_counts_the_diagnostics_cannot_use_are_refused() {
        let methods = vec!["a".to_string(), "b".to_string()];
        for draws in [0, 4, 9, MAX_DRAWS + 1, u64::MAX] {
            let settings = BtSettings {
                tune: 10,
                draws,
                ..Default::default()
            };
            let err = fit_bradley_terry(&methods, &[], &settings).unwrap_err();
            assert!(err.to_string().contains("draws"), "{draws}: {err}");
        }
        let settings = BtSettings {
            chains: 2,
            tune: 10,
            draws: MIN_DRAWS,
            ..Default::default()
        };
        let post = fit_bradley_terry(&methods, &[], &settings).unwrap();
        assert!(post.skills.iter().all(|s| s.ess_bulk.is_finite()));
    }
}
