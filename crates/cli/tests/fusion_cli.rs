//! `fewview fusion`: a short run of the method and of plain training on a small demo scene, the
//! comparison table and the study built from them, and the refusals of bad input.

mod common;

use common::{assert_clean_error, fewview, fewview_ok, s};

/// A short fusion run on the 64-pixel demo scene.
fn short_run(variant: &str, out: &std::path::Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec![
        "fusion",
        "--demo",
        "--width",
        "64",
        "--iterations",
        "60",
        "--checkpoint-every",
        "0",
        "--no-lpips",
        "--variant",
        variant,
        "--out",
        s(out),
    ];
    args.extend_from_slice(extra);
    fewview(&args)
}

#[test]
fn fusion_writes_its_run_transition_table_and_study() {
    let dir = tempfile::tempdir().unwrap();
    let (gf, plain) = (dir.path().join("gf"), dir.path().join("plain"));
    for (variant, out) in [("gf", &gf), ("plain", &plain)] {
        let run = short_run(variant, out, &[]);
        assert!(
            run.status.success(),
            "{}",
            String::from_utf8_lossy(&run.stderr)
        );
        let stdout = String::from_utf8_lossy(&run.stdout);
        assert!(stdout.contains("path vs truth"), "{stdout}");
        for f in [
            "point_cloud.ply",
            "metrics.json",
            "fusion.json",
            "transition.json",
            "transition.mp4",
        ] {
            assert!(out.join(f).exists(), "{variant}: {f} missing");
        }
    }
    // The fusion term ran (from 20 % of the run, every 3rd iteration) and covered something.
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(gf.join("fusion.json")).unwrap()).unwrap();
    assert_eq!(record["config"]["variant"], "gf");
    assert_eq!(record["term"]["applied"], 17, "{record}");
    assert!(
        record["term"]["mean_coverage"].as_f64().unwrap() > 0.01,
        "{record}"
    );
    // The transition: 8 s at 20 fps, scored against the ray-traced truth.
    let t: serde_json::Value =
        serde_json::from_slice(&std::fs::read(gf.join("transition.json")).unwrap()).unwrap();
    assert_eq!(t["frames"], 160);
    assert_eq!(
        t["truth"]["psnr"]["per_frame"].as_array().unwrap().len(),
        160
    );
    assert!(t["warping_error"]["mean"].as_f64().unwrap() > 0.0);

    // A run stopped after training (here: its transition removed) goes on with `--resume`
    // from the stages after training, without training again.
    std::fs::remove_file(plain.join("transition.json")).unwrap();
    let trained = std::fs::metadata(plain.join("point_cloud.ply"))
        .unwrap()
        .modified()
        .unwrap();
    let run = short_run("plain", &plain, &["--resume"]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    assert!(stderr.contains("training already finished"), "{stderr}");
    assert!(plain.join("transition.json").exists());
    let after = std::fs::metadata(plain.join("point_cloud.ply"))
        .unwrap()
        .modified()
        .unwrap();
    assert_eq!(after, trained, "the model was written again");

    let table = fewview_ok(&["fusion", "--table", s(&gf), s(&plain)]);
    let table = String::from_utf8_lossy(&table.stdout);
    assert_eq!(table.lines().count(), 4, "{table}");
    assert!(
        table.contains("| demo | gf | 0 |") && table.contains("| demo | plain | 0 |"),
        "{table}"
    );

    let study = dir.path().join("study");
    fewview_ok(&["fusion", "--study", s(&gf), s(&plain), "--out", s(&study)]);
    let config = std::fs::read_to_string(study.join("study.toml")).unwrap();
    assert!(config.contains("natural color transitions"), "{config}");
    for method in ["gf", "plain"] {
        let video = study.join(format!("videos/demo/{method}.mp4"));
        assert!(video.exists(), "{} missing", video.display());
    }
}

#[test]
fn bad_variants_views_and_studies_are_refused_with_nothing_written() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    assert_clean_error(
        &short_run("gradient", &out, &[]),
        &["gradient", "knn-color"],
    );
    assert!(!out.exists());
    // Photometric jitter out of range, and an appearance model (d) and (e) cannot take.
    for (flag, value, needle) in [
        ("--exposure-jitter", "3.5", "exposure"),
        ("--exposure-jitter", "-0.5", "exposure"),
        ("--white-balance-jitter", "0.8", "white-balance"),
        ("--vignetting", "nan", "vignetting"),
        ("--mirror-floor", "1.5", "mirror"),
        ("--specular", "0.4", "KS,EXP"),
    ] {
        let arg = format!("{flag}={value}");
        assert_clean_error(&short_run("gf", &out, &[&arg]), &[needle]);
        assert!(!out.exists(), "{arg} wrote {}", out.display());
    }
    for variant in ["poisson", "l1-virtual"] {
        let run = short_run(variant, &out, &["--appearance", "affine"]);
        assert_clean_error(&run, &["affine", variant]);
        assert!(!out.exists());
    }
    // The two ends of the demo arc: 50° apart, they share too little for virtual views.
    let run = short_run("gf", &out, &["--train-views", "0,23"]);
    assert_clean_error(&run, &["view_00", "view_23", "overlap"]);
    assert!(!out.exists(), "a refused run wrote {}", out.display());

    // A surface start from a folder that is no surface run, or a run of other data; masks
    // the demo does not have.
    let elsewhere = dir.path().join("surface-of-scan65");
    std::fs::create_dir_all(&elsewhere).unwrap();
    let metrics = r#"{"dataset": "scan65", "train_views": [22, 25, 28]}"#;
    std::fs::write(elsewhere.join("metrics.json"), metrics).unwrap();
    for (surface, needle) in [
        (dir.path().join("no-such-run"), "not a finished surface run"),
        (elsewhere, "a surface run of `scan65`"),
    ] {
        let init = format!("surface:{}", surface.display());
        assert_clean_error(&short_run("gf", &out, &["--init", &init]), &[needle]);
        assert!(!out.exists(), "--init {init} wrote {}", out.display());
    }
    assert_clean_error(
        &short_run("gf", &out, &["--object-only"]),
        &["--object-only"],
    );
    assert!(!out.exists());
    // A surface run made here needs a dataset.
    assert_clean_error(
        &short_run("gf", &out, &["--init", "surface"]),
        &["--init surface", "--data"],
    );
    assert!(!out.exists());

    // A study over runs of different data.
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    assert!(
        short_run("plain", &a, &["--no-transition"])
            .status
            .success()
    );
    std::fs::create_dir_all(&b).unwrap();
    let mut config: serde_json::Value =
        serde_json::from_slice(&std::fs::read(a.join("config.json")).unwrap()).unwrap();
    config["dataset"] = "fern".into();
    std::fs::write(b.join("config.json"), config.to_string()).unwrap();
    let study = dir.path().join("study");
    let run = fewview(&["fusion", "--study", s(&a), s(&b), "--out", s(&study)]);
    assert_clean_error(&run, &["different data", "fern"]);
    assert!(!study.exists());
    // ... and over runs without their transition video.
    std::fs::write(
        b.join("config.json"),
        std::fs::read(a.join("config.json")).unwrap(),
    )
    .unwrap();
    let run = fewview(&["fusion", "--study", s(&a), s(&b), "--out", s(&study)]);
    assert_clean_error(&run, &["transition.mp4"]);
    assert!(!study.exists());
}
