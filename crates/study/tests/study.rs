//! User-study statistics: MCMC diagnostics against ArviZ, and the analysis of the fusion paper's
//! Tables 1–2 win counts (144 responses per pair).

use std::path::PathBuf;

use fewview_study::analysis::{self as study, BtSettings, Response, diagnostics};

#[test]
fn diagnostics_match_arviz() {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/study/diagnostics.json");
    let data: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    for case in data["cases"].as_array().unwrap() {
        let name = case["name"].as_str().unwrap();
        let chains: Vec<Vec<f64>> = serde_json::from_value(case["chains"].clone()).unwrap();
        let rhat = diagnostics::rhat_rank(&chains).unwrap();
        let bulk = diagnostics::ess_bulk(&chains).unwrap();
        let tail = diagnostics::ess_tail(&chains).unwrap();
        let want = |k: &str| case[k].as_f64().unwrap();
        assert!(
            (rhat - want("rhat_rank")).abs() < 1e-9,
            "{name}: rhat {rhat} vs {}",
            want("rhat_rank")
        );
        assert!(
            (bulk / want("ess_bulk") - 1.0).abs() < 1e-9,
            "{name}: bulk {bulk} vs {}",
            want("ess_bulk")
        );
        assert!(
            (tail / want("ess_tail") - 1.0).abs() < 1e-9,
            "{name}: tail {tail} vs {}",
            want("ess_tail")
        );
    }
}

/// `(method a, method b, Q1 win % of a, Q2 win % of a)` as printed in the fusion paper.
type Row = (&'static str, &'static str, f64, f64);

/// Responses whose win counts are those the printed percentages imply for 144 answers a pair.
fn responses_from_table(rows: &[Row]) -> Vec<Response> {
    let mut out = Vec::new();
    for (pair, &(a, b, q1, q2)) in rows.iter().enumerate() {
        for (question, pct) in [("Q1", q1), ("Q2", q2)] {
            let wins = (pct * 144.0 / 100.0).round() as usize;
            // The count reproduces the printed percentage.
            assert!(
                (100.0 * wins as f64 / 144.0 - pct).abs() < 0.005 + 1e-9,
                "{a} vs {b} {question}"
            );
            for i in 0..144 {
                let (left, right) = if (i + pair) % 2 == 0 { (a, b) } else { (b, a) };
                let winner = if i < wins { a } else { b };
                out.push(Response {
                    participant: format!("p{}", i % 18),
                    question: question.into(),
                    scene: format!("scene{}", i % 3),
                    left: left.into(),
                    right: right.into(),
                    winner: winner.into(),
                });
            }
        }
    }
    out
}

#[test]
fn reproduces_paper_000_table_2_p_values() {
    let rows: [Row; 6] = [
        ("(a) Sparse init.", "(b) k-NN color cons.", 72.22, 71.53),
        ("(a) Sparse init.", "(d) L1 loss on vir.", 54.17, 59.03),
        ("(a) Sparse init.", "(e) Poisson-blended", 54.86, 63.89),
        ("(b) k-NN color cons.", "(d) L1 loss on vir.", 42.36, 52.08),
        ("(b) k-NN color cons.", "(e) Poisson-blended", 38.19, 47.22),
        ("(d) L1 loss on vir.", "(e) Poisson-blended", 49.31, 52.78),
    ];
    // Printed p-values (Q1, Q2) of each row; the paper prints 0.08 with two decimals.
    let printed = [
        ("<0.0001", "<0.0001"),
        ("0.359", "0.037"),
        ("0.279", "0.001"),
        ("0.080", "0.677"),
        ("0.006", "0.560"),
        ("0.934", "0.560"),
    ];
    let settings = BtSettings {
        tune: 500,
        draws: 500,
        ..Default::default()
    };
    let analysis = study::analyze(&responses_from_table(&rows), None, &settings).unwrap();
    for q in &analysis.questions {
        for (row, want) in rows.iter().zip(printed) {
            let p = q
                .pairs
                .iter()
                .find(|p| p.method_a == row.0 && p.method_b == row.1)
                .unwrap();
            let want = if q.question == "Q1" { want.0 } else { want.1 };
            assert_eq!(
                study::format_p(p.p_value),
                want,
                "{} {} vs {}",
                q.question,
                row.0,
                row.1
            );
            assert_eq!(p.wins_a + p.wins_b, 144);
        }
    }
}

#[test]
fn reproduces_paper_000_table_1_ranking() {
    let rows: [Row; 6] = [
        ("FreeNeRF", "CoherentGS", 28.47, 24.31),
        ("FreeNeRF", "MVPGS", 7.64, 1.39),
        ("FreeNeRF", "Ours", 1.39, 0.0),
        ("CoherentGS", "MVPGS", 29.17, 25.69),
        ("CoherentGS", "Ours", 11.81, 9.03),
        ("MVPGS", "Ours", 12.50, 10.42),
    ];
    // The paper's sampler settings: 4 chains, 4000 tuning + 4000 draws, target acceptance 0.95.
    let settings = BtSettings {
        seed: 2024,
        ..Default::default()
    };
    let responses = responses_from_table(&rows);
    let analysis = study::analyze(&responses, None, &settings).unwrap();
    for q in &analysis.questions {
        let bt = &q.bradley_terry;
        let ranking: Vec<&str> = bt
            .ranking()
            .iter()
            .map(|&i| bt.methods[i].as_str())
            .collect();
        assert_eq!(
            ranking,
            ["Ours", "MVPGS", "CoherentGS", "FreeNeRF"],
            "{}",
            q.question
        );
        assert!(bt.max_rhat < 1.01, "{}: R-hat {}", q.question, bt.max_rhat);
        assert!(
            bt.min_ess_bulk > 1000.0,
            "{}: ESS {}",
            q.question,
            bt.min_ess_bulk
        );
        for p in &q.pairs {
            assert!(
                p.p_value < 1e-4,
                "{} {} vs {}",
                q.question,
                p.method_a,
                p.method_b
            );
        }
        // Relative skills: same order, centred on zero.
        let rel: Vec<f64> = bt
            .ranking()
            .iter()
            .map(|&i| bt.skills[i].relative_mean)
            .collect();
        assert!(rel.windows(2).all(|w| w[0] > w[1]), "{rel:?}");
        assert!(rel.iter().sum::<f64>().abs() < 1e-9);
        // The posterior win probability of each better-ranked method exceeds 1/2.
        for w in ranking.windows(2) {
            let (i, j) = (
                bt.methods.iter().position(|m| m == w[0]).unwrap(),
                bt.methods.iter().position(|m| m == w[1]).unwrap(),
            );
            assert!(
                bt.win_probability[i][j] > 0.5 && bt.prob_better[i][j] > 0.99,
                "{w:?}"
            );
        }
    }
    // Reports: Markdown, CSV round trip, and the PNG plot.
    let dir = tempfile::tempdir().unwrap();
    let written = analysis.write_report(dir.path()).unwrap();
    assert!(written.iter().any(|p| p.ends_with("ranking_Q1.png")));
    let plot = fewview_scene::Image::load(&dir.path().join("ranking_Q1.png")).unwrap();
    assert!(plot.width == 900 && plot.height > 300);
    // The plot is not blank: labels and markers put dark pixels on the white background.
    let dark = plot
        .data
        .chunks(3)
        .filter(|p| p.iter().all(|&v| v < 0.3))
        .count();
    assert!(dark > 500, "only {dark} dark pixels");
    let md = std::fs::read_to_string(dir.path().join("report.md")).unwrap();
    assert!(
        md.contains("| Ours | FreeNeRF | 142 | 144 | 98.61 | <0.0001 |"),
        "{md}"
    );
    let csv_path = dir.path().join("responses.csv");
    study::write_responses_csv(&csv_path, &responses).unwrap();
    assert_eq!(study::read_responses_csv(&csv_path).unwrap(), responses);
}

#[test]
fn rejects_malformed_responses() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.csv");
    std::fs::write(
        &path,
        "participant,question,scene,left,right,winner\np1,Q1,s,A,B,C\n",
    )
    .unwrap();
    let err = study::read_responses_csv(&path).unwrap_err().to_string();
    assert!(err.contains("bad.csv") && err.contains("line 2"), "{err}");
    std::fs::write(&path, "participant,question,left,right,winner\n").unwrap();
    let err = study::read_responses_csv(&path).unwrap_err().to_string();
    assert!(err.contains("missing column \"scene\""), "{err}");
    std::fs::write(
        &path,
        "participant,question,scene,left,right,winner\np1,Q1,s,A,B,right\n",
    )
    .unwrap();
    assert_eq!(study::read_responses_csv(&path).unwrap()[0].winner, "B");
}
