//! Analysis of pairwise two-alternative forced-choice (2AFC) user studies, as in the fusion paper
//! (supplementary §5–6): per method pair and question the win rate and the two-sided exact
//! binomial p-value (Tables 1–2), and a Bayesian Bradley–Terry ranking with credible intervals.

pub mod binomial;
pub mod bradley_terry;
pub mod diagnostics;
pub mod plot;
pub mod results;

use std::collections::BTreeMap;
use std::path::Path;

pub use binomial::binom_test_two_sided;
pub use bradley_terry::{BtPosterior, BtSettings, SkillSummary, WinCount, fit_bradley_terry};
pub use results::{PairResult, QuestionAnalysis, StudyAnalysis};

use crate::error::{Result, StudyError};

/// One answer: a participant saw `left` and `right` (method names) for `scene` and chose
/// `winner` (one of the two) for `question`.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Response {
    pub participant: String,
    pub question: String,
    pub scene: String,
    pub left: String,
    pub right: String,
    pub winner: String,
}

impl Response {
    fn loser(&self) -> &str {
        if self.winner == self.left {
            &self.right
        } else {
            &self.left
        }
    }

    fn validate(&self, at: &str) -> Result<()> {
        if self.left == self.right {
            return Err(StudyError::invalid(format!(
                "{at}: a method cannot be compared with itself ({})",
                self.left
            )));
        }
        if self.winner != self.left && self.winner != self.right {
            return Err(StudyError::invalid(format!(
                "{at}: winner {:?} is neither {:?} nor {:?}",
                self.winner, self.left, self.right
            )));
        }
        if self.question.is_empty() {
            return Err(StudyError::invalid(format!("{at}: empty question")));
        }
        Ok(())
    }
}

/// Reads responses from CSV with the header `participant,question,scene,left,right,winner`
/// (extra columns are ignored; `winner` may also be the literal `left` or `right`).
pub fn read_responses_csv(path: &Path) -> Result<Vec<Response>> {
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| StudyError::format(path, e.to_string()))?;
    let headers = reader
        .headers()
        .map_err(|e| StudyError::format(path, e.to_string()))?
        .clone();
    let column = |name: &str| {
        headers.iter().position(|h| h.eq_ignore_ascii_case(name)).ok_or_else(|| {
            StudyError::format(path, format!("missing column {name:?} (need participant,question,scene,left,right,winner)"))
        })
    };
    let cols = [
        column("participant")?,
        column("question")?,
        column("scene")?,
        column("left")?,
        column("right")?,
        column("winner")?,
    ];
    let mut out = Vec::new();
    for (i, record) in reader.records().enumerate() {
        let line = i + 2;
        let record = record.map_err(|e| StudyError::format(path, format!("line {line}: {e}")))?;
        let get = |c: usize| record.get(cols[c]).unwrap_or("").to_string();
        let mut r = Response {
            participant: get(0),
            question: get(1),
            scene: get(2),
            left: get(3),
            right: get(4),
            winner: get(5),
        };
        if r.winner.eq_ignore_ascii_case("left") {
            r.winner = r.left.clone();
        } else if r.winner.eq_ignore_ascii_case("right") {
            r.winner = r.right.clone();
        }
        if let Err(StudyError::Invalid(message)) = r.validate(&format!("line {line}")) {
            return Err(StudyError::format(path, message));
        }
        out.push(r);
    }
    Ok(out)
}

/// Writes responses as CSV (the format [`read_responses_csv`] reads), atomically.
pub fn write_responses_csv(path: &Path, responses: &[Response]) -> Result<()> {
    let mut w = csv::Writer::from_writer(Vec::new());
    for r in responses {
        w.serialize(r)
            .map_err(|e| StudyError::invalid(e.to_string()))?;
    }
    let bytes = w
        .into_inner()
        .map_err(|e| StudyError::invalid(e.to_string()))?;
    fewview_scene::atomic::write_bytes(path, &bytes)?;
    Ok(())
}

/// Analyses the responses. `method_order` fixes the order of methods in tables (default: first
/// appearance); every method of the responses must be in it.
pub fn analyze(
    responses: &[Response],
    method_order: Option<&[String]>,
    settings: &BtSettings,
) -> Result<StudyAnalysis> {
    if responses.is_empty() {
        return Err(StudyError::invalid("no responses to analyse"));
    }
    for (i, r) in responses.iter().enumerate() {
        r.validate(&format!("response {}", i + 1))?;
    }
    let mut questions: Vec<String> = Vec::new();
    let mut methods: Vec<String> = method_order.map(<[String]>::to_vec).unwrap_or_default();
    for r in responses {
        if !questions.contains(&r.question) {
            questions.push(r.question.clone());
        }
        for m in [&r.left, &r.right] {
            if !methods.contains(m) {
                if method_order.is_some() {
                    return Err(StudyError::invalid(format!(
                        "method {m:?} is not in the configured method list"
                    )));
                }
                methods.push(m.clone());
            }
        }
    }
    let index: BTreeMap<&str, usize> = methods
        .iter()
        .enumerate()
        .map(|(i, m)| (m.as_str(), i))
        .collect();
    let mut out = Vec::new();
    for q in &questions {
        let k = methods.len();
        let mut wins = vec![vec![0u64; k]; k];
        let mut count = 0;
        for r in responses.iter().filter(|r| &r.question == q) {
            wins[index[r.winner.as_str()]][index[r.loser()]] += 1;
            count += 1;
        }
        let mut pairs = Vec::new();
        for a in 0..k {
            for b in a + 1..k {
                let n = wins[a][b] + wins[b][a];
                if n == 0 {
                    continue;
                }
                pairs.push(PairResult {
                    method_a: methods[a].clone(),
                    method_b: methods[b].clone(),
                    wins_a: wins[a][b],
                    wins_b: wins[b][a],
                    win_rate_a: wins[a][b] as f64 / n as f64,
                    p_value: binom_test_two_sided(wins[a][b], n, 0.5)?,
                });
            }
        }
        let terms: Vec<WinCount> = (0..k)
            .flat_map(|w| (0..k).map(move |l| (w, l)))
            .filter(|&(w, l)| w != l)
            .map(|(w, l)| WinCount {
                winner: w,
                loser: l,
                count: wins[w][l],
            })
            .filter(|t| t.count > 0)
            .collect();
        let bradley_terry = fit_bradley_terry(&methods, &terms, settings)?;
        out.push(QuestionAnalysis {
            question: q.clone(),
            methods: methods.clone(),
            responses: count,
            pairs,
            bradley_terry,
        });
    }
    Ok(StudyAnalysis { questions: out })
}

/// A p-value as the paper prints it: `<0.0001` below 1e-4, else three decimals.
pub fn format_p(p: f64) -> String {
    if p < 1e-4 {
        "<0.0001".to_string()
    } else {
        format!("{p:.3}")
    }
}

impl StudyAnalysis {
    /// Markdown report: the paper's pairwise win-rate table (both directions of every pair, as
    /// Tables 1–2 list them), then the Bradley–Terry ranking and posterior win probabilities.
    pub fn to_markdown(&self) -> String {
        let mut s = String::from("# User-study analysis\n\n");
        for q in &self.questions {
            let bt = &q.bradley_terry;
            s += &format!("## Question {} ({} responses)\n\n", q.question, q.responses);
            s += "### Pairwise win rates (two-sided exact binomial test, H0: no preference)\n\n";
            s += "| Method | vs. | Wins | N | Win (%) | p-value |\n|---|---|---:|---:|---:|---:|\n";
            for m in &q.methods {
                for p in &q.pairs {
                    let (other, wins, n) = if &p.method_a == m {
                        (&p.method_b, p.wins_a, p.wins_a + p.wins_b)
                    } else if &p.method_b == m {
                        (&p.method_a, p.wins_b, p.wins_a + p.wins_b)
                    } else {
                        continue;
                    };
                    s += &format!(
                        "| {m} | {other} | {wins} | {n} | {:.2} | {} |\n",
                        100.0 * wins as f64 / n as f64,
                        format_p(p.p_value)
                    );
                }
            }
            s += &format!(
                "\n### Bayesian Bradley–Terry ranking (NUTS: {} chains × {} draws after {} tuning, target acceptance {}, prior Normal(0, σ={}))\n\n",
                bt.settings.chains,
                bt.settings.draws,
                bt.settings.tune,
                bt.settings.target_accept,
                bt.settings.prior_sigma
            );
            let mass = 100.0 * bt.settings.credible_mass;
            s += &format!(
                "| Rank | Method | Skill (mean) | SD | {mass:.0}% CrI | Relative skill | {mass:.0}% CrI (relative) | R-hat | ESS bulk | ESS tail |\n|---:|---|---:|---:|---|---:|---|---:|---:|---:|\n"
            );
            for (rank, &i) in bt.ranking().iter().enumerate() {
                let k = &bt.skills[i];
                s += &format!(
                    "| {} | {} | {:.3} | {:.3} | [{:.3}, {:.3}] | {:.3} | [{:.3}, {:.3}] | {:.4} | {:.0} | {:.0} |\n",
                    rank + 1,
                    k.method,
                    k.mean,
                    k.sd,
                    k.lower,
                    k.upper,
                    k.relative_mean,
                    k.relative_lower,
                    k.relative_upper,
                    k.rhat,
                    k.ess_bulk,
                    k.ess_tail
                );
            }
            s += &format!(
                "\nDivergent transitions: {}. Max R-hat: {:.4}.\n\n",
                bt.divergences, bt.max_rhat
            );
            s += "Posterior probability that the row method wins a new comparison against the column method:\n\n| |";
            for m in &bt.methods {
                s += &format!(" {m} |");
            }
            s += "\n|---|";
            s += &"---:|".repeat(bt.methods.len());
            s += "\n";
            for (i, m) in bt.methods.iter().enumerate() {
                s += &format!("| {m} |");
                for j in 0..bt.methods.len() {
                    if i == j {
                        s += " – |";
                    } else {
                        s += &format!(" {:.3} |", bt.win_probability[i][j]);
                    }
                }
                s += "\n";
            }
            s += "\n";
        }
        s
    }

    /// CSV of the pairwise table: one row per ordered (method, opponent) and question.
    pub fn pairs_csv(&self) -> String {
        let mut s = String::from("question,method,opponent,wins,n,win_percent,p_value\n");
        for q in &self.questions {
            for p in &q.pairs {
                let n = p.wins_a + p.wins_b;
                for (m, o, w) in [
                    (&p.method_a, &p.method_b, p.wins_a),
                    (&p.method_b, &p.method_a, p.wins_b),
                ] {
                    s += &format!(
                        "{},{},{},{},{},{:.4},{:.6e}\n",
                        csv_field(&q.question),
                        csv_field(m),
                        csv_field(o),
                        w,
                        n,
                        100.0 * w as f64 / n as f64,
                        p.p_value
                    );
                }
            }
        }
        s
    }

    /// CSV of the Bradley–Terry summaries.
    pub fn skills_csv(&self) -> String {
        let mut s = String::from(
            "question,rank,method,mean,sd,lower,upper,relative_mean,relative_lower,relative_upper,rhat,ess_bulk,ess_tail\n",
        );
        for q in &self.questions {
            let bt = &q.bradley_terry;
            for (rank, &i) in bt.ranking().iter().enumerate() {
                let k = &bt.skills[i];
                s += &format!(
                    "{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
                    csv_field(&q.question),
                    rank + 1,
                    csv_field(&k.method),
                    k.mean,
                    k.sd,
                    k.lower,
                    k.upper,
                    k.relative_mean,
                    k.relative_lower,
                    k.relative_upper,
                    k.rhat,
                    k.ess_bulk,
                    k.ess_tail
                );
            }
        }
        s
    }

    /// Writes `report.md`, `pairs.csv`, `skills.csv`, `analysis.json` and one ranking plot per
    /// question (`ranking_<question>.png`, `ranking_file_names`) into `dir`, each atomically.
    /// Returns the paths written.
    pub fn write_report(&self, dir: &Path) -> Result<Vec<std::path::PathBuf>> {
        std::fs::create_dir_all(dir).map_err(|e| StudyError::io(dir, e))?;
        let mut written = Vec::new();
        let json =
            serde_json::to_string_pretty(self).map_err(|e| StudyError::invalid(e.to_string()))?;
        for (name, text) in [
            ("report.md", self.to_markdown()),
            ("pairs.csv", self.pairs_csv()),
            ("skills.csv", self.skills_csv()),
            ("analysis.json", json),
        ] {
            let path = dir.join(name);
            fewview_scene::atomic::write_bytes(&path, text.as_bytes())?;
            written.push(path);
        }
        let questions: Vec<&str> = self.questions.iter().map(|q| q.question.as_str()).collect();
        for (q, name) in self.questions.iter().zip(ranking_file_names(&questions)) {
            let path = dir.join(name);
            plot::ranking_plot(q, &path)?;
            written.push(path);
        }
        Ok(written)
    }
}

/// `ranking_<question>.png` for each question, with every character but ASCII letters and
/// digits replaced by `_`. Names that would clash (`Q 1`, `Q_1` and `Q/1` all become `Q_1`; `q1`
/// and `Q1` on a case-insensitive file system) take the question's 1-based position as a
/// suffix, so no plot overwrites another.
fn ranking_file_names(questions: &[&str]) -> Vec<String> {
    let safe: Vec<String> = questions
        .iter()
        .map(|q| {
            q.chars()
                .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
                .collect()
        })
        .collect();
    let clashes = |s: &String| safe.iter().filter(|t| t.eq_ignore_ascii_case(s)).count() > 1;
    let names: Vec<String> = safe
        .iter()
        .enumerate()
        .map(|(i, s)| {
            if clashes(s) {
                format!("ranking_{s}_{}.png", i + 1)
            } else {
                format!("ranking_{s}.png")
            }
        })
        .collect();
    let lower: std::collections::HashSet<String> =
        names.iter().map(|n| n.to_ascii_lowercase()).collect();
    if lower.len() == names.len() {
        names
    } else {
        // A suffix met another question's name (`Q 1`, `Q_1`, `Q_1_2`): number them all in
        // front, which cannot clash (the number ends at the first `_`).
        safe.iter()
            .enumerate()
            .map(|(i, s)| format!("ranking_{}_{s}.png", i + 1))
            .collect()
    }
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::ranking_file_names;

    #[test]
    fn ranking_file_names_never_clash() {
        assert_eq!(
            ranking_file_names(&["Sharper?", "Q1"]),
            ["ranking_Sharper_.png", "ranking_Q1.png"]
        );
        assert_eq!(
            ranking_file_names(&["Q 1", "Q_1", "Q/1", "q1", "Q1"]),
            [
                "ranking_Q_1_1.png",
                "ranking_Q_1_2.png",
                "ranking_Q_1_3.png",
                "ranking_q1_4.png",
                "ranking_Q1_5.png"
            ]
        );
        let tricky = ranking_file_names(&["Q 1", "Q_1", "Q_1_2"]);
        assert_eq!(
            tricky,
            [
                "ranking_1_Q_1.png",
                "ranking_2_Q_1.png",
                "ranking_3_Q_1_2.png"
            ]
        );
    }
}
