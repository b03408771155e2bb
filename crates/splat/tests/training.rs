//! Training-level tests on the in-process demo scene: determinism and resume, PLY round trips of
//! trained models, divergence reporting, and that training actually learns the scene.

// Tests report what they measured.
#![allow(clippy::print_stdout, clippy::print_stderr)]

use burn::tensor::Device;
use fewview_scene::synthetic::{DemoOptions, DemoShading, demo_dataset};
use fewview_scene::{Dataset, Image};
use fewview_splat::eval::{evaluate, render_model};
use fewview_splat::pipeline::{
    RunConfig, RunData, initial_model, load_checkpoint, save_checkpoint, train_run,
};
use fewview_splat::ply::{read_ply, write_ply};
use fewview_splat::raster::{RenderCamera, RenderSettings};
use fewview_splat::train::pair::{CoRegConfig, TrainerPair, second_seed};
use fewview_splat::train::{TrainConfig, TrainError, TrainView, Trainer};

/// The demo scene, eight views on its arc, at `width × height` with these training views.
fn demo(width: usize, height: usize, train: Vec<usize>) -> Dataset {
    demo_dataset(&DemoOptions {
        width,
        height,
        views: 8,
        train,
        supersample: 2,
        shading: DemoShading::Lambertian,
        ..DemoOptions::default()
    })
}

fn small_demo() -> Dataset {
    demo(64, 48, vec![1, 4, 7])
}

/// A short run that exercises every part of the schedule: densification from iteration 5 every
/// 5, an opacity reset at 20, SH degree growth every 6.
fn short_config(iterations: usize) -> RunConfig {
    let mut train = TrainConfig::sparse_view(iterations);
    train.densify.from_iter = 5;
    train.densify.interval = 5;
    train.densify.until_iter = iterations - 5;
    train.densify.opacity_reset_interval = 20;
    // Low enough that some Gaussians clone and split in a few iterations.
    train.densify.grad_threshold = 2e-5;
    train.sh_increase_interval = 6;
    train.seed = 7;
    let mut cfg = RunConfig::new(train);
    cfg.init_points = 2000;
    cfg
}

fn trainer(ds: &Dataset, cfg: &RunConfig) -> Trainer {
    trainer_from(ds, cfg, initial_model(ds, cfg).unwrap())
}

fn trainer_from(ds: &Dataset, cfg: &RunConfig, model: fewview_splat::GaussianModel) -> Trainer {
    let device = Device::flex().autodiff();
    let views = ds
        .train_views()
        .map(|v| TrainView::new(&v.name, RenderCamera::from(&v.camera), &v.image, &device))
        .collect();
    let (_, extent) = ds.camera_extent();
    Trainer::new(cfg.train.clone(), model, views, extent as f32, device).unwrap()
}

#[test]
fn resumed_run_equals_uninterrupted_run() {
    let ds = small_demo();
    let cfg = short_config(40);
    let mut straight = trainer(&ds, &cfg);
    let mut densified = 0;
    while !straight.is_done() {
        densified += straight.step().unwrap().densified.is_some() as usize;
    }
    assert!(densified >= 3, "densification ran {densified} times");

    let mut first = trainer(&ds, &cfg);
    for _ in 0..17 {
        first.step().unwrap();
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("checkpoint.bin");
    let data = RunData::of(&ds).unwrap();
    let state = first.state().unwrap().clone();
    save_checkpoint(&path, &first.config, &data, &state).unwrap();
    drop(first);
    let saved = load_checkpoint(&path).unwrap();
    assert_eq!(saved.config, cfg.train);
    assert_eq!(saved.data, data);
    let mut resumed = trainer(&ds, &cfg);
    resumed.set_state(saved.state);
    while !resumed.is_done() {
        resumed.step().unwrap();
    }
    assert_eq!(resumed.iteration(), 40);
    // Bit-identical: same Gaussians, optimiser moments and statistics.
    assert_eq!(resumed.state().unwrap(), straight.state().unwrap());
}

/// CoR-GS's second field: the first's start, another seed.
fn second(ds: &Dataset, cfg: &RunConfig) -> Trainer {
    let mut second = cfg.clone();
    second.train.seed = second_seed(cfg.train.seed);
    trainer_from(ds, &second, initial_model(ds, cfg).unwrap())
}

/// CoR-GS's pair of fields, with co-pruning every densification step and the pseudo-view term.
fn pair_of(ds: &Dataset, first: Trainer, second: Trainer) -> TrainerPair {
    let cameras = ds.train_views().map(|v| v.camera.clone()).collect();
    let co = CoRegConfig {
        every: 1,
        ..CoRegConfig::default()
    };
    TrainerPair::new(first, second, cameras, co).unwrap()
}

#[test]
fn a_resumed_pair_of_fields_equals_an_uninterrupted_one() {
    let ds = small_demo();
    let cfg = short_config(30);
    let fresh = || pair_of(&ds, trainer(&ds, &cfg), second(&ds, &cfg));
    let mut straight = fresh();
    while !straight.first.is_done() {
        straight.step().unwrap();
    }
    let mut first = fresh();
    for _ in 0..13 {
        first.step().unwrap();
    }
    let saved = (
        first.first.state().unwrap().clone(),
        first.second.state().unwrap().clone(),
    );
    drop(first);
    let (mut a, mut b) = (trainer(&ds, &cfg), second(&ds, &cfg));
    a.set_state(saved.0);
    b.set_state(saved.1);
    let mut resumed = pair_of(&ds, a, b);
    while !resumed.first.is_done() {
        resumed.step().unwrap();
    }
    let (s, r) = (&mut straight, &mut resumed);
    assert_eq!(r.first.state().unwrap(), s.first.state().unwrap());
    assert_eq!(r.second.state().unwrap(), s.second.state().unwrap());
    let (a, b) = (
        s.first.state().unwrap().model.clone(),
        s.second.state().unwrap().model.clone(),
    );
    assert!(!a.is_empty() && !b.is_empty());
    assert_ne!(a, b, "the two fields draw differently");
}

#[test]
fn state_kept_on_the_device_trains_the_same_bits_as_on_the_host() {
    // On the CPU backend the device path's tensor arithmetic rounds as the host loops do, so
    // Adam, the densification statistics, densification (through the host) and the opacity
    // reset must agree bit for bit.
    let ds = small_demo();
    let cfg = short_config(40);
    let mut host = trainer(&ds, &cfg);
    let mut device = trainer(&ds, &cfg);
    device.keep_state_on_device(true).unwrap();
    let mut densified = 0;
    while !host.is_done() {
        let (a, b) = (host.step().unwrap(), device.step().unwrap());
        assert_eq!(
            a.loss.to_bits(),
            b.loss.to_bits(),
            "iteration {}",
            a.iteration
        );
        assert_eq!((a.gaussians, a.densified), (b.gaussians, b.densified));
        densified += a.densified.is_some() as usize;
        if a.iteration == 17 {
            // A mid-run read-back (a checkpoint) leaves the device copy as it was.
            assert_eq!(device.state().unwrap(), host.state().unwrap());
        }
    }
    assert!(densified >= 3, "densification ran {densified} times");
    assert_eq!(device.state().unwrap(), host.state().unwrap());
}

/// A checkpoint left by a run on views 1, 4, 7 of the 64 × 48 demo, after 5 iterations.
fn checkpoint_of_a_small_run(dir: &std::path::Path, ds: &Dataset, cfg: &RunConfig) {
    let mut t = trainer(ds, cfg);
    for _ in 0..5 {
        t.step().unwrap();
    }
    std::fs::create_dir_all(dir).unwrap();
    let data = RunData::of(ds).unwrap();
    let state = t.state().unwrap().clone();
    save_checkpoint(&dir.join("checkpoint.bin"), &t.config, &data, &state).unwrap();
}

/// A co-regularised run resumes only when both fields' checkpoints stopped at one iteration.
#[test]
fn a_pair_resumes_only_from_checkpoints_of_one_iteration() {
    let ds = small_demo();
    let mut cfg = short_config(20);
    cfg.co_reg = Some(CoRegConfig::default());
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    checkpoint_of_a_small_run(&run, &ds, &cfg);
    let e = train_run(&ds, &cfg, &run, true, |_| {})
        .unwrap_err()
        .to_string();
    assert!(e.contains("checkpoint_second.bin"), "{e}");
    let mut b = second(&ds, &cfg);
    for _ in 0..3 {
        b.step().unwrap();
    }
    let data = RunData::of(&ds).unwrap();
    let path = run.join("checkpoint_second.bin");
    let state = b.state().unwrap().clone();
    save_checkpoint(&path, &b.config, &data, &state).unwrap();
    let e = train_run(&ds, &cfg, &run, true, |_| {})
        .unwrap_err()
        .to_string();
    assert!(e.contains("iteration 3, the first at 5"), "{e}");
    for _ in 0..2 {
        b.step().unwrap();
    }
    let state = b.state().unwrap().clone();
    save_checkpoint(&path, &b.config, &data, &state).unwrap();
    let summary = train_run(&ds, &cfg, &run, true, |_| {}).unwrap();
    assert_eq!((summary.resumed_from, summary.iterations), (Some(5), 20));
    assert!(!path.exists(), "the finished run keeps no checkpoint");
}

#[test]
fn resuming_on_other_views_or_another_size_is_refused_before_anything_is_written() {
    let ds = small_demo();
    let cfg = short_config(20);
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    checkpoint_of_a_small_run(&run, &ds, &cfg);
    let other_views = demo(64, 48, vec![0, 3, 6]);
    let other_size = demo(32, 24, vec![1, 4, 7]);
    for (ds, expected) in [
        (&other_views, "training views"),
        (&other_size, "images 64x48 (now 32x24"),
    ] {
        let e = train_run(ds, &cfg, &run, true, |_| {})
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("belongs to another run") && e.contains(expected),
            "{e}"
        );
        assert!(
            !run.join("config.json").exists(),
            "config.json written before the check"
        );
    }
    // The same data resumes.
    let summary = train_run(&ds, &cfg, &run, true, |_| {}).unwrap();
    assert_eq!(summary.resumed_from, Some(5));
}

#[test]
fn a_bit_flipped_checkpoint_is_reported_as_corrupt() {
    let ds = small_demo();
    let cfg = short_config(20);
    let dir = tempfile::tempdir().unwrap();
    checkpoint_of_a_small_run(dir.path(), &ds, &cfg);
    let path = dir.path().join("checkpoint.bin");
    let mut bytes = std::fs::read(&path).unwrap();
    // A bit in the middle: inside the Gaussians' parameters, where postcard decodes any value.
    let middle = bytes.len() / 2;
    bytes[middle] ^= 0x10;
    std::fs::write(&path, &bytes).unwrap();
    let e = load_checkpoint(&path).unwrap_err().to_string();
    assert!(e.contains("checksum mismatch"), "{e}");
    assert!(e.starts_with(&path.display().to_string()), "{e}");
}

#[test]
fn trained_model_survives_the_ply_round_trip_bit_exactly() {
    let ds = small_demo();
    let cfg = short_config(25);
    let mut t = trainer(&ds, &cfg);
    while !t.is_done() {
        t.step().unwrap();
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("point_cloud.ply");
    let model = t.into_state().unwrap().model;
    write_ply(&path, &model).unwrap();
    let back = read_ply(&path).unwrap();
    assert_eq!(back, model);
    let settings = RenderSettings {
        sh_degree: 3,
        ..RenderSettings::default()
    };
    for v in ds.test_views() {
        let cam = RenderCamera::from(&v.camera);
        let a = render_model(&model, &cam, &settings);
        let b = render_model(&back, &cam, &settings);
        assert_eq!(a.rgb, b.rgb);
        assert_eq!(a.depth, b.depth);
    }
}

#[test]
fn non_finite_loss_is_reported_with_its_iteration() {
    let ds = small_demo();
    let cfg = short_config(10);
    let mut t = trainer(&ds, &cfg);
    // Colours at the edge of f32: blending overflows to infinity.
    for (i, v) in t.state_mut().unwrap().model.sh.iter_mut().enumerate() {
        if i % (16 * 3) < 3 {
            *v = 3.0e38;
        }
    }
    match t.step() {
        Err(TrainError::Diverged { iteration, loss }) => {
            assert_eq!(iteration, 1);
            assert!(!loss.is_finite());
        }
        other => panic!("expected divergence, got {other:?}"),
    }
}

/// When densification/pruning removes every Gaussian, training stops with an error naming the
/// iteration (and suggesting more initial points) instead of going on with an empty model.
#[test]
fn pruning_every_gaussian_is_an_error() {
    let ds = small_demo();
    let mut cfg = short_config(20);
    // Every Gaussian is below this opacity, so the first densification (iteration 10: after
    // `from_iter` 5, at a multiple of the interval 5) prunes them all.
    cfg.train.densify.min_opacity = 2.0;
    cfg.init_points = 50;
    let mut t = trainer(&ds, &cfg);
    let err = loop {
        match t.step() {
            Ok(p) => assert!(p.gaussians > 0 && p.iteration < 10, "{p:?}"),
            Err(e) => break e,
        }
    };
    match &err {
        TrainError::NoGaussiansLeft { iteration, before } => {
            assert_eq!(*iteration, 10);
            assert!(*before > 0);
        }
        other => panic!("expected NoGaussiansLeft, got {other:?}"),
    }
    let text = err.to_string();
    assert!(
        text.contains("iteration 10") && text.contains("--init-points"),
        "{text}"
    );
}

fn mean_psnr(model: &fewview_splat::model::GaussianModel, ds: &Dataset) -> f64 {
    let views: Vec<_> = ds.test_views().collect();
    let settings = RenderSettings {
        sh_degree: 3,
        ..RenderSettings::default()
    };
    evaluate(model, &views, &settings).unwrap().0.mean_psnr
}

#[test]
fn training_learns_the_demo_scene() {
    let ds = demo_dataset(&DemoOptions {
        width: 80,
        height: 60,
        views: 9,
        train: vec![1, 4, 7],
        supersample: 2,
        shading: DemoShading::Lambertian,
        ..DemoOptions::default()
    });
    let mut cfg = RunConfig::new(TrainConfig::sparse_view(600));
    cfg.init_points = 5000;
    let before = mean_psnr(&initial_model(&ds, &cfg).unwrap(), &ds);
    let dir = tempfile::tempdir().unwrap();
    let summary = train_run(&ds, &cfg, dir.path(), false, |_| {}).unwrap();
    // Held-out quality rises well above the initial point cloud's, to a level that only a
    // reconstruction of the scene reaches (a flat mean-colour image scores ~11 dB here).
    let flat = {
        let mean: Vec<f32> = (0..3)
            .map(|c| {
                ds.test_views()
                    .map(|v| {
                        v.image.channel(c).data.iter().sum::<f32>() / v.image.num_pixels() as f32
                    })
                    .sum::<f32>()
                    / ds.test.len() as f32
            })
            .collect();
        let views: Vec<_> = ds.test_views().collect();
        views
            .iter()
            .map(|v| {
                fewview_metrics::psnr(
                    &Image::filled(v.image.width, v.image.height, &mean),
                    &v.image,
                )
                .unwrap()
            })
            .sum::<f64>()
            / views.len() as f64
    };
    eprintln!(
        "held-out PSNR: flat {flat:.2}, initial {before:.2}, trained {:.2}",
        summary.test.mean_psnr
    );
    assert!(
        summary.test.mean_psnr > before + 3.0,
        "{} vs initial {before}",
        summary.test.mean_psnr
    );
    assert!(
        summary.test.mean_psnr > flat + 5.0,
        "{} vs flat {flat}",
        summary.test.mean_psnr
    );
    // The run directory holds what the docs promise, and no leftover checkpoint.
    for f in ["config.json", "metrics.json", "point_cloud.ply"] {
        assert!(dir.path().join(f).exists(), "{f} missing");
    }
    assert!(!dir.path().join("checkpoint.bin").exists());
    assert_eq!(
        std::fs::read_dir(dir.path().join("renders/test"))
            .unwrap()
            .count(),
        ds.test.len()
    );
}

/// Trains one white Gaussian, half opaque, against an empty RGBA view composited over white
/// (every pixel white, alpha 0), and returns the rendered alpha summed over the image before
/// and after.
fn train_white_floater(random_background: bool) -> (f64, f64) {
    use fewview_scene::{Camera, Intrinsics};
    use fewview_splat::model::GaussianModel;
    use fewview_splat::train::AlphaImage;
    use nalgebra::Vector3;

    let camera = Camera::look_at(
        Intrinsics::centered(40.0, 32, 32),
        Vector3::new(0.0, 0.0, -3.0),
        Vector3::zeros(),
        Vector3::new(0.0, -1.0, 0.0),
    );
    let white = [1.0f32; 3];
    let image = Image::filled(32, 32, &white);
    let alpha = Image::filled(32, 32, &[0.0]);
    let mut model = GaussianModel::new(0);
    model.push_isotropic([0.0; 3], 0.3, white, 0.5);

    let mut train = TrainConfig::sparse_view(100);
    train.sh_degree = 0;
    train.background = white;
    train.random_background = random_background;
    train.densify.from_iter = 1000;
    train.densify.until_iter = 0;
    let device = Device::flex().autodiff();
    let view = TrainView::new("empty", RenderCamera::from(&camera), &image, &device)
        .with_alpha(AlphaImage::new(&image, &alpha, white).unwrap());
    let settings = RenderSettings {
        background: white,
        sh_degree: 0,
        near_plane: 0.2,
    };
    let coverage = |m: &GaussianModel| {
        let r = render_model(m, &RenderCamera::from(&camera), &settings);
        r.alpha.data.iter().map(|&a| a as f64).sum::<f64>()
    };
    let before = coverage(&model);
    let mut t = Trainer::new(train, model, vec![view], 1.0, device).unwrap();
    t.run(|_| {}, |_, _| Ok(())).unwrap();
    (before, coverage(&t.into_state().unwrap().model))
}

#[test]
fn random_background_removes_a_floater_that_a_fixed_background_hides() {
    // Over the fixed white background the white Gaussian renders exactly as the target: no loss,
    // no gradient, and it stays.
    let (before, fixed) = train_white_floater(false);
    assert!(before > 20.0, "the Gaussian covers the view: {before}");
    assert!(
        (fixed - before).abs() < 1e-3 * before,
        "{fixed} vs {before}"
    );
    // Over random colours it shows wherever the target's alpha is 0, and fades away.
    let (_, random) = train_white_floater(true);
    assert!(random < 0.1 * before, "{random} vs {before}");
}

#[test]
fn default_run_length_grows_with_the_number_of_training_views() {
    use fewview_splat::pipeline::default_iterations;
    let mut ds = small_demo();
    // The demo's views have depth bounds: the forward-facing default.
    assert_eq!(default_iterations(&ds), 1000);
    for v in &mut ds.views {
        v.depth_bounds = None;
    }
    assert_eq!(default_iterations(&ds), 3000);
    ds.train = (0..100).map(|i| i % ds.views.len()).collect();
    assert_eq!(default_iterations(&ds), 5000);
}

/// A run killed while writing a checkpoint leaves a `.fewview-partial-…` file in its folder;
/// starting (or resuming) a run there removes it, and leaves other files alone.
#[test]
fn a_run_sweeps_partial_files_left_in_its_folder() {
    use fewview_scene::atomic::PARTIAL_PREFIX;
    let ds = small_demo();
    let mut cfg = short_config(10);
    cfg.init_points = 200;
    let dir = tempfile::tempdir().unwrap();
    let partial = dir.path().join(format!("{PARTIAL_PREFIX}Ab12Cd"));
    std::fs::write(&partial, b"half a checkpoint").unwrap();
    let keep = dir.path().join("notes.txt");
    std::fs::write(&keep, b"mine").unwrap();
    train_run(&ds, &cfg, dir.path(), false, |_| {}).unwrap();
    assert!(!partial.exists(), "partial file left behind");
    assert!(keep.exists());
    let leftovers: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}
