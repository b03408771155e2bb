//! Size and count flags found by fuzzing to panic, abort on allocation or produce NaN figures:
//! each is now refused where it is parsed, with one error line naming the flag, and nothing is
//! written.

mod common;
use common::{assert_clean_error, fewview, fewview_ok, s};

/// `study analyze --draws 4` to `9` passed the old `≥ 4` check and panicked (index out of
/// bounds) in the effective-sample-size code; huge counts allocated gigabytes.
#[test]
fn study_analyze_refuses_unusable_draw_counts() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("ok.csv");
    std::fs::write(
        &csv,
        "participant,question,scene,left,right,winner\n\
         p1,Q1,s,A,B,A\np1,Q1,s,A,C,C\np2,Q1,s,B,C,B\np2,Q1,s,A,B,left\n",
    )
    .unwrap();
    let out = dir.path().join("o1");
    for draws in ["0", "4", "9", "1000001", "100000000000"] {
        assert_clean_error(
            &fewview(&[
                "study",
                "analyze",
                "--responses",
                s(&csv),
                "--out",
                s(&out),
                "--draws",
                draws,
            ]),
            &["--draws", draws],
        );
        assert!(!out.exists(), "{draws}: nothing written");
    }
    // The smallest accepted count runs through the diagnostics.
    fewview_ok(&[
        "study",
        "analyze",
        "--responses",
        s(&csv),
        "--out",
        s(&out),
        "--draws",
        "10",
        "--tune",
        "10",
        "--chains",
        "2",
    ]);
}

/// `demo --width 4294967295` overflowed the image buffer's size (panic) and `100000000` aborted
/// on allocation.
#[test]
fn demo_refuses_huge_widths() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("demo");
    for width in ["4294967295", "100000000", "8193", "15", "-1"] {
        assert_clean_error(
            &fewview(&["demo", "--out", s(&run), &format!("--width={width}")]),
            &["--width", width],
        );
        assert!(!run.exists(), "{width}: nothing written");
    }
}

/// `bench --gaussians 1000000000000` aborted on allocation; `--gaussians`, `--train-steps` or
/// `--runs` 0 finished with NaN or 0 it/s figures and exit 0.
#[test]
fn bench_refuses_empty_and_huge_counts() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("b.json");
    let base = [
        ("--runs", "1"),
        ("--train-steps", "1"),
        ("--surface-steps", "1"),
    ];
    let cases: [(&str, &str); 5] = [
        ("--gaussians", "1000000000000"),
        ("--gaussians", "10000001"),
        ("--gaussians", "0"),
        ("--train-steps", "0"),
        ("--runs", "0"),
    ];
    for (flag, value) in cases {
        let mut args = vec!["bench", "--json", s(&json), flag, value];
        for (f, v) in base.iter().filter(|(f, _)| *f != flag) {
            args.extend([*f, *v]);
        }
        assert_clean_error(&fewview(&args), &[flag, value]);
        assert!(!json.exists(), "{flag} {value}: nothing written");
    }
}

/// `bench --only ssim` measures that section alone: the JSON holds its figures and none of the
/// others; an unknown section is refused before anything is measured.
#[test]
fn bench_only_measures_the_named_sections() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("b.json");
    fewview_ok(&["bench", "--json", s(&json), "--only", "ssim"]);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let ms = report["ssim"]["value_grad_ms"].as_f64().unwrap();
    assert!(ms.is_finite() && ms > 0.0, "SSIM {ms} ms");
    for absent in [
        "raster",
        "train_demo",
        "fusion_demo",
        "human_inference",
        "blend",
    ] {
        assert!(report.get(absent).is_none(), "{absent} was measured");
    }
    let other = dir.path().join("c.json");
    assert_clean_error(
        &fewview(&["bench", "--json", s(&other), "--only", "rastr"]),
        &["--only", "rastr"],
    );
    assert!(!other.exists());
}
