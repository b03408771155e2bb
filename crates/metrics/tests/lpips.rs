//! LPIPS against the reference Python packages on committed fixtures (made by
//! `tools/make_lpips_fixtures.py`, whose header says exactly what is compared with what).
//! The reference weight files come from `scripts/setup.sh` (the test command runs it).

// Tests report what they measured.
#![allow(clippy::print_stdout, clippy::print_stderr)]

use std::path::PathBuf;

use fewview_metrics::lpips::{LoadOptions, Lpips, LpipsNet};
use fewview_scene::Image;

fn fixture_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/lpips")
}

fn weights_dir() -> PathBuf {
    let dir = std::env::var_os("FEWVIEW_LPIPS_WEIGHTS")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../.cache/lpips-weights")
        });
    assert!(
        dir.join("stlpips/vgg_shift_tolerant.pth").exists(),
        "reference LPIPS weights missing in {}: run scripts/setup.sh (scripts/test.sh does)",
        dir.display()
    );
    dir
}

fn pairs() -> Vec<serde_json::Value> {
    let text = std::fs::read_to_string(fixture_dir().join("expected.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["pairs"].as_array().unwrap().clone()
}

/// Compares `model` with the fixture column `key` on every pair that has it; returns how many.
fn check(model: &Lpips, key: &str) -> usize {
    let mut n = 0;
    let mut worst = 0.0f64;
    let mut sizes = std::collections::BTreeSet::new();
    for p in pairs() {
        let Some(want) = p[key].as_f64() else {
            continue;
        };
        let a = Image::load(&fixture_dir().join(p["a"].as_str().unwrap())).unwrap();
        let b = Image::load(&fixture_dir().join(p["b"].as_str().unwrap())).unwrap();
        let got = model.distance(&a, &b).unwrap();
        assert!(
            (got - want).abs() < 1e-4,
            "{key} {}x{}: ours {got}, reference {want}",
            a.width,
            a.height
        );
        sizes.insert((a.width, a.height));
        worst = worst.max((got - want).abs());
        n += 1;
    }
    eprintln!(
        "{key} ({}): max |ours − reference| = {worst:.2e} over {n} pairs",
        model.source()
    );
    assert_eq!(sizes.len(), n, "pairs of different sizes");
    n
}

#[test]
fn embedded_st_alex_matches_stlpips_package() {
    let model = Lpips::default_st_alex().unwrap();
    assert_eq!(model.net(), LpipsNet::StAlex);
    assert!(check(&model, "st_alex") >= 10);
    // Identical images are at distance 0.
    let a = Image::load(&fixture_dir().join("pair00_a.png")).unwrap();
    assert!(model.distance(&a, &a).unwrap().abs() < 1e-7);
}

#[test]
fn st_alex_from_file_matches_embedded() {
    let w = weights_dir();
    let model = Lpips::load(
        LpipsNet::StAlex,
        &[w.join("stlpips/alex_shift_tolerant.pth")],
        LoadOptions::default(),
    )
    .unwrap();
    assert!(check(&model, "st_alex") >= 10);
}

#[test]
fn st_vgg_matches_stlpips_package() {
    let w = weights_dir();
    let model = Lpips::load(
        LpipsNet::StVgg,
        &[w.join("stlpips/vgg_shift_tolerant.pth")],
        LoadOptions::default(),
    )
    .unwrap();
    assert!(check(&model, "st_vgg") >= 5);
}

#[test]
fn lpips_alex_code_path_matches_lpips_package() {
    let w = weights_dir();
    let files = [
        w.join("stlpips/alex_shift_tolerant.pth"),
        w.join("lpips/alex.pth"),
    ];
    let model = Lpips::load(
        LpipsNet::Alex,
        &files,
        LoadOptions {
            match_convs_by_order: true,
        },
    )
    .unwrap();
    assert!(check(&model, "lpips_alex") >= 10);
}

#[test]
fn lpips_vgg_code_path_matches_lpips_package() {
    let w = weights_dir();
    let files = [
        w.join("stlpips/vgg_shift_tolerant.pth"),
        w.join("lpips/vgg.pth"),
    ];
    let model = Lpips::load(
        LpipsNet::Vgg,
        &files,
        LoadOptions {
            match_convs_by_order: true,
        },
    )
    .unwrap();
    assert!(check(&model, "lpips_vgg") >= 5);
}

#[test]
fn lpips_squeeze_matches_lpips_package() {
    let w = weights_dir();
    let files = [
        fixture_dir().join("squeeze_random_f16.pth"),
        w.join("lpips/squeeze.pth"),
    ];
    let model = Lpips::load(LpipsNet::Squeeze, &files, LoadOptions::default()).unwrap();
    assert!(check(&model, "lpips_squeeze") >= 10);
}

#[test]
fn bad_weight_files_give_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("junk.pth");
    std::fs::write(&bad, b"definitely not a checkpoint").unwrap();
    let err = Lpips::load(LpipsNet::Alex, &[bad], LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains("junk.pth"), "{err}");
    // The lin heads alone lack the backbone.
    let w = weights_dir();
    let err = Lpips::load(
        LpipsNet::Alex,
        &[w.join("lpips/alex.pth")],
        LoadOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("missing weight features.0.weight"), "{err}");
    // ST AlexNet convolutions are not the plain AlexNet's by index.
    let err = Lpips::load(
        LpipsNet::Alex,
        &[w.join("stlpips/alex_shift_tolerant.pth")],
        LoadOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("missing weight"), "{err}");
    let model = Lpips::default_st_alex().unwrap();
    let small = Image::filled(20, 20, &[0.5, 0.5, 0.5]);
    assert!(
        model
            .distance(&small, &small)
            .unwrap_err()
            .to_string()
            .contains("at least 32x32")
    );
}

/// The cached-feature sequence path gives exactly the pairwise distances.
#[test]
fn sequence_distances_match_pairwise_calls() {
    use fewview_metrics::temporal::PerceptualDistance;
    let model = Lpips::default_st_alex().unwrap();
    let a = Image::load(&fixture_dir().join("pair00_a.png")).unwrap();
    let b = Image::load(&fixture_dir().join("pair00_b.png")).unwrap();
    let mut c = a.clone();
    c.data.iter_mut().for_each(|v| *v = 1.0 - *v);
    let out = [a.clone(), b.clone(), c.clone()];
    let gt = [b.clone(), a.clone(), a.clone()];
    let (per_frame, tlp) = model.sequence_distances(&out, &gt).unwrap();
    for t in 0..3 {
        assert!((per_frame[t] - model.distance(&out[t], &gt[t]).unwrap()).abs() < 1e-6);
    }
    for t in 1..3 {
        let want = 100.0
            * (model.distance(&gt[t - 1], &gt[t]).unwrap()
                - model.distance(&out[t - 1], &out[t]).unwrap())
            .abs();
        assert!((tlp[t - 1] - want).abs() < 1e-4, "{} vs {want}", tlp[t - 1]);
    }
}
