//! Training and inference on `seq_a`: a few steps of the CPU preset, resumed bit for bit, never
//! reading outside the training set, and a held-out view rendered from the result.

mod common;

use fewview_human::infer::{Model, SequenceRenderer};
use fewview_human::train::{TrainConfig, Trainer, default_device};
use fewview_human::{HumanDataset, MultiView, Split, TrainingView};
use fewview_metrics::psnr;
use fewview_scene::Image;

fn open() -> HumanDataset {
    HumanDataset::open(&common::data_root().join("human"), "seq_a").expect("seq_a opens")
}

/// Five steps in one go, and five invocations of one step each resumed from the previous one's
/// checkpoint, give the same losses to the last bit (the weights and Adam's moments survive
/// each checkpoint, the seed fixes the initial weights, the step number alone the frame and
/// target); the run read input cameras of training frames only.
#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn seq_a_training_resumes_bit_for_bit_inside_the_training_set() {
    let data = open();
    let split = Split::seq_a();
    let view = TrainingView::new(&data, &split).unwrap();
    let parents = data.joint_parents().unwrap();
    let frames = 0..2;
    let config = TrainConfig {
        iterations: 5,
        ..TrainConfig::default()
    };
    let dir = tempfile::tempdir().unwrap();

    let mut straight = Trainer::new(
        &view,
        frames.clone(),
        &parents,
        config.clone(),
        default_device(),
    )
    .unwrap();
    let mut losses = Vec::new();
    for _ in 0..5 {
        let s = straight.step().unwrap();
        losses.push(s.loss.total);
        assert!(
            s.loss.total.is_finite() && s.loss.photometric > 0.0,
            "{s:?}"
        );
        assert!(
            !s.sources.contains(&s.target) && s.sources.len() == 2,
            "{s:?}"
        );
    }
    // Five invocations of one step each, every one resumed from the previous checkpoint, as
    // `human train --resume --max-minutes` runs a long training in pieces. Each step's loss
    // reads every weight, and from the second step on Adam's moments through the weights.
    let mut pieces = Vec::new();
    for piece in 0..5 {
        let mut t = if piece == 0 {
            Trainer::new(
                &view,
                frames.clone(),
                &parents,
                config.clone(),
                default_device(),
            )
        } else {
            Trainer::resume(
                &view,
                frames.clone(),
                dir.path(),
                config.clone(),
                default_device(),
            )
        }
        .unwrap();
        assert_eq!(t.iteration(), piece);
        pieces.push(t.step().unwrap().loss.total);
        t.save(dir.path()).unwrap();
    }
    assert_eq!(
        pieces, losses,
        "losses of five one-step invocations against one run"
    );

    let reads = data.read_log().content_reads();
    assert!(!reads.is_empty());
    for r in reads {
        let (camera, frame) = (r.camera, r.frame.expect("per-frame data"));
        let inside = camera.map_or(split.train_frames.contains(&frame), |c| {
            split.in_training(c, frame)
        });
        assert!(inside, "read {}", r.path.display());
    }
    // Another configuration is refused.
    let other = TrainConfig {
        use_pose: false,
        ..config
    };
    let err = Trainer::resume(&view, frames, dir.path(), other, default_device())
        .err()
        .unwrap();
    assert!(err.to_string().contains("other settings"), "{err}");
}

/// A run of a few steps already renders the held-out camera 2 far better than black: colours
/// come from the source pixels and positions from the hull, whatever the weights.
#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn seq_a_held_out_view_renders_from_a_saved_run() {
    let data = open();
    let split = Split::seq_a();
    let view = TrainingView::new(&data, &split).unwrap();
    let config = TrainConfig {
        iterations: 2,
        ..TrainConfig::default()
    };
    let mut trainer = Trainer::new(
        &view,
        0..2,
        &data.joint_parents().unwrap(),
        config,
        default_device(),
    )
    .unwrap();
    trainer.step().unwrap();
    let dir = tempfile::tempdir().unwrap();
    trainer.save(dir.path()).unwrap();

    let model = Model::load(dir.path()).unwrap();
    let camera = data.cameras()[2].clone();
    let mut renderer = SequenceRenderer::new(&model, &data, &split, Some(Default::default()));
    let out = renderer
        .render_frame(45, std::slice::from_ref(&camera))
        .unwrap();
    let truth = fewview_human::eval::truth_frames(&data, &model.framing, 2, 45..46).unwrap();
    let [w, h] = model.framing.size;
    assert_eq!((out.plain[0].width, out.plain[0].height), (w, h));
    let black = Image {
        width: w,
        height: h,
        channels: 3,
        data: vec![0.0; w * h * 3],
    };
    let ours = psnr(&out.plain[0], &truth[0]).unwrap();
    let blank = psnr(&black, &truth[0]).unwrap();
    assert!(
        ours > blank + 6.0,
        "render {ours:.2} dB, black {blank:.2} dB"
    );
    assert!(out.stabilized.is_some() && out.times.total() > 0.0);

    // Input camera 1 drawn with itself among its sources reproduces its own pixels (a pixel
    // lifted at any depth projects back onto itself); left out, it comes from its neighbours.
    let input = data.cameras()[1].clone();
    let truth = fewview_human::eval::truth_frames(&data, &model.framing, 1, 45..46).unwrap();
    let mut plain = SequenceRenderer::new(&model, &data, &split, None);
    let with_itself = plain
        .render_frame(45, std::slice::from_ref(&input))
        .unwrap();
    let left_out = plain
        .render_frame_leaving_out(45, std::slice::from_ref(&input), &[Some(1)])
        .unwrap();
    let (a, b) = (
        psnr(&with_itself.plain[0], &truth[0]).unwrap(),
        psnr(&left_out.plain[0], &truth[0]).unwrap(),
    );
    assert!(a > b + 3.0, "with itself {a:.2} dB, left out {b:.2} dB");
}
