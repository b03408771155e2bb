//! The PoseGaussian protocol and the property that training never reads a held-out camera or a
//! test frame: every refused pair is an error before any file is touched, and the capture's read
//! log holds only training cameras and frames after a full training pass.

// Tests report what they measured.
#![allow(clippy::print_stdout, clippy::print_stderr)]

mod common;

use fewview_human::readlog::ReadKind;
use fewview_human::{HumanDataset, HumanError, MultiView, Split, TrainingView};

#[test]
fn seq_a_protocol_holds_out_every_third_camera() {
    let s = Split::seq_a();
    assert_eq!(Split::uniform(12, 8, 60, 40).unwrap(), s);
    assert_eq!(s.held_out_cameras, [2, 5, 8, 11]);
    assert_eq!(s.input_cameras, [0, 1, 3, 4, 6, 7, 9, 10]);
    assert_eq!(
        (s.train_frames.clone(), s.test_frames.clone()),
        (0..40, 40..60)
    );
    assert_eq!(s.training_pairs().len(), 8 * 40);
    assert_eq!(s.novel_view_targets().len(), 4 * 60);
    assert_eq!(s.novel_pose_targets().len(), 4 * 20);
    assert!(
        s.novel_pose_targets()
            .iter()
            .all(|&(c, f)| f >= 40 && !s.in_training(c, f))
    );
    // ZJU-MoCap's 23 cameras with 8 inputs, as the paper standardises.
    let z = Split::uniform(23, 8, 300, 200).unwrap();
    assert_eq!(z.input_cameras, [0, 2, 5, 8, 11, 14, 17, 20]);
    for (args, what) in [
        ((4, 4, 10, 5), "4 input cameras of 4"),
        ((4, 2, 10, 10), "10 training frames of 10"),
    ] {
        let e = Split::uniform(args.0, args.1, args.2, args.3)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("split: ") && e.contains(what), "{e}");
    }
}

/// Runs a training pass through `view`: every image, mask and 2D joint set of the training
/// pairs, and the 3D joints of the training frames.
fn training_pass(view: &TrainingView) -> usize {
    let split = view.split().clone();
    for (c, f) in split.training_pairs() {
        view.image(c, f).unwrap();
        view.mask(c, f).unwrap();
        view.joints2d(c, f).unwrap();
    }
    for f in split.train_frames.clone() {
        view.joints3d(f).unwrap();
    }
    split.training_pairs().len() * 3 + split.train_frames.len()
}

/// Every content read is of an input camera (or none, for 3D joints) on a training frame.
fn assert_only_training_reads(data: &dyn MultiView, split: &Split, expected: usize) {
    let reads = data.read_log().content_reads();
    assert_eq!(reads.len(), expected);
    for r in &reads {
        let frame = r.frame.expect("content reads belong to a frame");
        let camera_ok = r.camera.is_none_or(|c| split.input_cameras.contains(&c));
        assert!(
            camera_ok && split.train_frames.contains(&frame),
            "read outside training: {r:?}"
        );
    }
    // Headers read on open name no frame; they carry no pixel or joint values.
    let headers = data
        .read_log()
        .reads()
        .iter()
        .filter(|r| r.kind == ReadKind::Header)
        .count();
    assert_eq!(headers + reads.len(), data.read_log().len());
}

#[test]
fn training_view_reads_only_training_pairs() {
    let dir = tempfile::tempdir().unwrap();
    common::write_capture(dir.path(), 4, 6);
    let data = HumanDataset::open(dir.path(), "seq").unwrap();
    let split = Split::uniform(4, 2, 6, 4).unwrap();
    assert_eq!(
        (split.input_cameras.clone(), split.held_out_cameras.clone()),
        (vec![0, 2], vec![1, 3])
    );
    let view = TrainingView::new(&data, &split).unwrap();
    let before = data.read_log().len();
    for (c, f) in [(1, 0), (3, 2), (0, 4), (2, 5)] {
        let e = view.image(c, f).unwrap_err();
        let HumanError::OutsideTraining { what, .. } = e else {
            panic!("{e}")
        };
        assert_eq!(what, format!("camera {c}, frame {f}"));
        assert!(
            view.mask(c, f).is_err() && view.joints2d(c, f).is_err() && view.depth(c, f).is_err()
        );
    }
    assert!(view.joints3d(4).is_err() && view.camera(1).is_err());
    assert!(view.camera(2).is_ok());
    let e = view.mask(3, 5).unwrap_err().to_string();
    assert!(e.ends_with("camera 3, frame 5 is outside the training split (input cameras [0, 2], training frames 0..=3)"), "{e}");
    assert_eq!(
        data.read_log().len(),
        before,
        "a refused pair touched a file"
    );
    let n = training_pass(&view);
    assert_only_training_reads(&data, &split, n);
    let too_big = Split::uniform(5, 2, 6, 4).unwrap();
    assert!(TrainingView::new(&data, &too_big).is_err());
    let overlapping = Split {
        held_out_cameras: vec![0, 1],
        ..split.clone()
    };
    let e = TrainingView::new(&data, &overlapping)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("overlap training"), "{e}");
    let overlapping = Split {
        held_out_cameras: vec![0, 1],
        ..split.clone()
    };
    let e = TrainingView::new(&data, &overlapping)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("overlap training"), "{e}");
}

#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn seq_a_training_pass_never_reads_held_out_views_or_test_frames() {
    let data = HumanDataset::open(&common::data_root().join("human"), "seq_a").unwrap();
    let split = Split::seq_a();
    let view = TrainingView::new(&data, &split).unwrap();
    let n = training_pass(&view);
    for &(c, f) in split
        .novel_view_targets()
        .iter()
        .chain(&split.novel_pose_targets())
    {
        assert!(view.image(c, f).is_err());
    }
    assert!(view.image(0, 40).is_err() && view.joints3d(59).is_err());
    assert_only_training_reads(&data, &split, n);
    println!(
        "seq_a training pass: {n} content reads, all on cameras {:?} and frames 0-39",
        split.input_cameras
    );
}

/// The depth term's input: a capture without depth maps gives none, a broken depth file is an
/// error naming it (it used to read as "no depth").
#[test]
fn training_depth_is_absent_or_an_error_never_silently_dropped() {
    use fewview_human::train::InputViews;
    let dir = tempfile::tempdir().unwrap();
    common::write_capture(dir.path(), 4, 3);
    let split = Split::uniform(4, 2, 3, 2).unwrap();
    let depth_dir = dir.path().join("seq/depth");
    {
        let data = HumanDataset::open(dir.path(), "seq").unwrap();
        let view = TrainingView::new(&data, &split).unwrap();
        let depth = InputViews::depth(&view, 0, 1).unwrap().expect("depth");
        assert_eq!((depth.width, depth.height), (16, 16));
    }
    let broken = depth_dir.join("cam_00/frame_0001.png");
    std::fs::write(&broken, b"not a png").unwrap();
    {
        let data = HumanDataset::open(dir.path(), "seq").unwrap();
        let view = TrainingView::new(&data, &split).unwrap();
        let e = InputViews::depth(&view, 0, 1).unwrap_err().to_string();
        assert!(e.contains("frame_0001.png"), "{e}");
    }
    std::fs::remove_dir_all(&depth_dir).unwrap();
    let data = HumanDataset::open(dir.path(), "seq").unwrap();
    let view = TrainingView::new(&data, &split).unwrap();
    assert!(InputViews::depth(&view, 0, 1).unwrap().is_none());
}
