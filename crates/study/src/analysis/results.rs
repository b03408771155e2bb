//! What the analysis of a study gives: per question, the pairwise win rates and the ranking.

use super::bradley_terry::BtPosterior;

/// Win counts of one unordered method pair for one question.
#[derive(Clone, Debug, serde::Serialize)]
pub struct PairResult {
    pub method_a: String,
    pub method_b: String,
    pub wins_a: u64,
    pub wins_b: u64,
    /// `wins_a / (wins_a + wins_b)`.
    pub win_rate_a: f64,
    /// Two-sided exact binomial test of `wins_a` against no preference (p = 0.5).
    pub p_value: f64,
}

/// Everything computed for one question.
#[derive(Clone, Debug, serde::Serialize)]
pub struct QuestionAnalysis {
    pub question: String,
    pub methods: Vec<String>,
    pub responses: u64,
    pub pairs: Vec<PairResult>,
    pub bradley_terry: BtPosterior,
}

/// The analysis of a whole study, one entry per question (in first-appearance order).
#[derive(Clone, Debug, serde::Serialize)]
pub struct StudyAnalysis {
    pub questions: Vec<QuestionAnalysis>,
}
