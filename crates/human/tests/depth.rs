//! The network's input depth on captures: a capture without depth maps cannot give the dataset's
//! depth, and, with `FEWVIEW_DATA`, per-frame stereo on seq_a against the exact depth.

// Tests report what they measured.
#![allow(clippy::print_stdout, clippy::print_stderr)]

mod common;

use std::path::Path;

use fewview_human::depth::{DepthInput, StereoPartner, StereoSettings};
use fewview_human::depth_report::{DepthReportConfig, measure};
use fewview_human::train::prepare::{
    DepthSettings, Framing, InferenceInputs, frame_hull, hull_config, prepare_frame,
};
use fewview_human::{HumanDataset, MultiView, Split, ZjuDataset};

#[test]
fn the_dataset_depth_of_a_capture_without_depth_maps_is_an_error() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/zju_small");
    let capture = ZjuDataset::open(&root).unwrap();
    assert!(!capture.has_depth());
    let split = Split::for_capture(&capture, 3, None).unwrap();
    let inputs = InferenceInputs {
        source: &capture,
        split: &split,
        depth_maps: true,
    };
    let mesh = frame_hull(&inputs, 0, &hull_config(0.02)).unwrap();
    let cameras: Vec<_> = capture.cameras().to_vec();
    let framing = Framing::of_hulls(std::slice::from_ref(&mesh), &cameras, [64, 128], 0.1).unwrap();
    let settings = DepthSettings {
        input: DepthInput::Dataset,
        ..DepthSettings::default()
    };
    let err = prepare_frame(&inputs, 0, &mesh, &framing, &settings)
        .unwrap_err()
        .to_string();
    assert!(err.contains("no depth maps"), "{err}");
}

/// Stereo of each input camera with its nearest input camera, at the CPU preset's crops,
/// matches most of the person and lies within a few centimetres of the exact depth; the
/// measured flicker is what the report says it is (the truth's own flicker beyond itself is 0).
#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn seq_a_stereo_depth_against_exact_depth() {
    let data = HumanDataset::open(&common::data_root().join("human"), "seq_a").unwrap();
    let split = Split::seq_a();
    let inputs = InferenceInputs {
        source: &data,
        split: &split,
        depth_maps: true,
    };
    let config = DepthReportConfig {
        frames: 0..3,
        size: [128, 256],
        crop_margin: 0.1,
        hull_voxel: 0.01,
        stereo: StereoSettings {
            partner: StereoPartner::Nearest,
            ..StereoSettings::default()
        },
    };
    let (report, prepared) = measure(&inputs, &config).unwrap();
    println!("{}", serde_json::to_string(&report).unwrap());
    assert_eq!(prepared.len(), 3);
    assert!(report.stereo_matched > 0.6, "{}", report.stereo_matched);
    let truth = report.truth.as_ref().expect("seq_a has depth");
    assert_eq!(truth.error_m, Some(0.0));
    assert_eq!(truth.flicker_beyond_truth_m, Some(0.0));
    let (stereo, hull) = (report.stereo.error_m.unwrap(), report.hull.error_m.unwrap());
    assert!(stereo < 0.03 && hull < 0.03, "stereo {stereo}, hull {hull}");
    assert!(report.flicker_ratio.is_some_and(f64::is_finite));
}
