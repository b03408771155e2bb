//! Semi-Global Matching against OpenCV's `StereoSGBM` with the same parameters, bit for bit, on
//! the pairs `tools/make_sgbm_fixtures.py` wrote (synthetic planes always; the rectified fern
//! pair (1, 10) and a demo-scene pair when the script was run with `--data`).

// Tests report what they measured.
#![allow(clippy::print_stdout, clippy::print_stderr)]

use std::path::{Path, PathBuf};

use fewview_geom::stereo::sgm::{Border, Disparity, GrayOrRgb, Paths, SgmParams, match_left};
use serde_json::Value;

fn fixture_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sgbm")
}

struct Case {
    width: usize,
    height: usize,
    channels: usize,
    left: Vec<u8>,
    right: Vec<u8>,
    opencv: Vec<i16>,
    params: SgmParams,
}

fn load_png(path: &Path, channels: usize) -> (usize, usize, Vec<u8>) {
    let img = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let (w, h) = (img.width() as usize, img.height() as usize);
    let data = if channels == 1 {
        img.to_luma8().into_raw()
    } else {
        img.to_rgb8().into_raw()
    };
    (w, h, data)
}

fn load_case(name: &str, meta: &Value) -> Case {
    let dir = fixture_dir();
    let channels = meta["channels"].as_u64().unwrap() as usize;
    let (width, height, left) = load_png(&dir.join(format!("{name}_left.png")), channels);
    let (_, _, right) = load_png(&dir.join(format!("{name}_right.png")), channels);
    let bytes = std::fs::read(dir.join(format!("{name}_opencv.npy"))).unwrap();
    let opencv: Vec<i16> = npyz::NpyFile::new(&bytes[..]).unwrap().into_vec().unwrap();
    let p = &meta["params"];
    let int = |k: &str| p[k].as_i64().unwrap();
    let params = SgmParams {
        min_disparity: int("min_disparity") as i32,
        num_disparities: int("num_disparities") as usize,
        block_size: int("block_size") as usize,
        p1: None,
        p2: None,
        pre_filter_cap: int("pre_filter_cap") as i32,
        uniqueness_ratio: int("uniqueness_ratio") as i32,
        disp12_max_diff: int("disp12_max_diff") as i32,
        speckle_window_size: int("speckle_window_size") as usize,
        speckle_range: int("speckle_range") as i32,
        paths: match p["paths"].as_str().unwrap() {
            "five" => Paths::Five,
            _ => Paths::Eight,
        },
        // OpenCV leaves the columns left of the disparity range invalid.
        border: Border::OpenCv,
    };
    Case {
        width,
        height,
        channels,
        left,
        right,
        opencv,
        params,
    }
}

/// Agreement of two fixed-point maps: (fraction of the pixels both call valid that agree within
/// 1 px, valid-set intersection over union, fraction identical).
fn agreement(ours: &Disparity, theirs: &[i16]) -> (f64, f64, f64) {
    let (mut both, mut either, mut close, mut same) = (0usize, 0usize, 0usize, 0usize);
    for (&a, &b) in ours.fixed.iter().zip(theirs) {
        let (va, vb) = (a != ours.invalid, b != ours.invalid);
        same += (a == b) as usize;
        if va || vb {
            either += 1;
        }
        if va && vb {
            both += 1;
            close += ((a as i32 - b as i32).abs() <= 16) as usize;
        }
    }
    (
        close as f64 / both.max(1) as f64,
        both as f64 / either.max(1) as f64,
        same as f64 / theirs.len() as f64,
    )
}

fn check_case(name: &str, meta: &Value) {
    let c = load_case(name, meta);
    let l = GrayOrRgb::new(c.width, c.height, c.channels, &c.left).unwrap();
    let r = GrayOrRgb::new(c.width, c.height, c.channels, &c.right).unwrap();
    let ours = match_left(&l, &r, &c.params).unwrap();
    let (close, overlap, same) = agreement(&ours, &c.opencv);
    eprintln!(
        "{name}: within 1 px {close:.4}, valid IoU {overlap:.4}, identical {same:.4}, valid ours {:.4} / OpenCV {:.4}",
        ours.valid_fraction(),
        meta["opencv_valid_fraction"]
    );
    // What the README and the crate docs claim: bit-identical fixed-point disparities,
    // invalid pixels included.
    let differing = ours
        .fixed
        .iter()
        .zip(&c.opencv)
        .filter(|(a, b)| a != b)
        .count();
    assert_eq!(ours.fixed.len(), c.opencv.len(), "{name}: sizes differ");
    assert_eq!(
        differing, 0,
        "{name}: {differing} pixels differ from OpenCV (identical {same:.4}, within 1 px \
         {close:.4}, valid IoU {overlap:.4})"
    );
}

fn cases() -> Value {
    let text = std::fs::read_to_string(fixture_dir().join("cases.json")).unwrap();
    serde_json::from_str::<Value>(&text).unwrap()["cases"].clone()
}

#[test]
fn synthetic_pairs_match_opencv() {
    let cases = cases();
    for name in ["planes_gray", "planes_rgb_eight", "planes_rgb_min4"] {
        check_case(name, &cases[name]);
    }
}

#[test]
fn rectified_fern_and_demo_pairs_match_opencv() {
    let cases = cases();
    for name in ["fern_1_10", "demo_2_11"] {
        check_case(name, &cases[name]);
    }
}
