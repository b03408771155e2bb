//! End-to-end tests of the surface pipeline on the analytic scene (an SDF solid rendered by the
//! independent sphere tracer of `sdf_scene`): reconstruction accuracy with noisy poses, and
//! bit-exact resumption from a checkpoint.

// Tests report what they measured.
#![allow(clippy::print_stdout, clippy::print_stderr)]

use fewview_scene::Dataset;
use fewview_surface::checkpoint;
use fewview_surface::pipeline::{prepare, prepare_with_matching, run_identity};
use fewview_surface::sdf_scene::{SdfSceneOptions, observed_faces, sdf_dataset, surface_mesh};
use fewview_surface::train::Trainer;
use fewview_surface::{InitialPoses, Overrides, RunConfig, RunInputs, RunReport, Schedule, run};

/// The analytic scene with six views at `width × height`, these ones for training.
fn six_view_scene(width: usize, height: usize, train: Vec<usize>) -> Dataset {
    sdf_dataset(&SdfSceneOptions {
        width,
        height,
        views: 6,
        train,
        supersample: 1,
        ..Default::default()
    })
}

fn tiny_scene() -> Dataset {
    six_view_scene(64, 48, vec![0, 2, 4])
}

fn tiny_config(iterations: usize) -> RunConfig {
    let mut c = RunConfig::default();
    c.train.iterations = iterations;
    c.train.rays_per_batch = 96;
    c.train.matches_per_batch = 16;
    c.train.sample.n_coarse = 16;
    c.train.sample.n_importance = 16;
    c.initial_poses = InitialPoses::NoisyGroundTruth { sigma: 0.05 };
    c.checkpoint_every = 0;
    c.mesh_resolution = 48;
    c.eval_views = 1;
    c.eval_scale = 4;
    c
}

fn silent(_: fewview_surface::pipeline::Event) {}

fn inputs<'a>(ds: &'a Dataset, reference: Option<&'a fewview_geom::Mesh>) -> RunInputs<'a> {
    RunInputs {
        dataset: ds,
        truth: None,
        matching: None,
        reference,
        reference_observed: None,
        source: None,
    }
}

/// Matching on the same views at twice the size: the matches the losses get are the fine
/// matches with their coordinates halved (pixel centres at half-integers map exactly), the
/// warm-up and precision are computed in the fine pixels, and images that are not an integer
/// multiple of the training size are refused.
#[test]
fn matching_on_finer_images_scales_the_matches_down() {
    let scene = |w, h| {
        sdf_dataset(&SdfSceneOptions {
            width: w,
            height: h,
            views: 16,
            train: vec![0, 1, 2],
            supersample: 1,
            ..Default::default()
        })
    };
    let (coarse, fine) = (scene(160, 120), scene(320, 240));
    let mut config = tiny_config(1);
    // The refined matches of the weakest pair number 36 here; the warm-up must run for the
    // comparison of its results to mean anything.
    config.pose_warmup = Some(fewview_surface::warmup::WarmupOptions {
        min_matches_per_pair: 20,
        ..Default::default()
    });
    let direct = prepare(&fine, None, &config).unwrap();
    let via = prepare_with_matching(&coarse, None, Some(&fine), &config).unwrap();
    assert!(!direct.matches.is_empty());
    assert_eq!(via.matches.len(), direct.matches.len());
    for (v, d) in via.matches.iter().zip(&direct.matches) {
        assert_eq!(v.a, [d.a[0] / 2.0, d.a[1] / 2.0]);
        assert_eq!(v.b, [d.b[0] / 2.0, d.b[1] / 2.0]);
        assert_eq!(v.confidence, d.confidence);
    }
    assert_eq!(via.match_precision, direct.match_precision);
    let warmup = via.warmup.as_ref().expect("warm-up report");
    assert!(warmup.skipped.is_none(), "{:?}", warmup.skipped);
    assert_eq!(via.start, direct.start);
    assert_eq!(via.views[0].image.width, 160);
    let odd = scene(240, 180);
    let err = prepare_with_matching(&coarse, None, Some(&odd), &config)
        .err()
        .expect("refused")
        .to_string();
    assert!(err.contains("integer multiple"), "{err}");
}

/// A run interrupted after 4 of 8 iterations and resumed from its checkpoint ends with the
/// same parameters and poses, bit for bit, as the uninterrupted run; and the pipeline's
/// `resume` path picks the checkpoint up and reports the same final pose errors.
#[test]
fn resume_reproduces_the_uninterrupted_run() {
    let ds = tiny_scene();
    let config = tiny_config(8);
    let prep = prepare(&ds, None, &config).unwrap();
    let new_trainer = || {
        Trainer::new(
            config.train.clone(),
            prep.views.clone(),
            &prep.initial,
            prep.matches.clone(),
        )
        .unwrap()
    };
    let mut whole = new_trainer();
    for _ in 0..8 {
        whole.step().unwrap();
    }

    let dir = tempfile::tempdir().unwrap();
    let ckpt = dir.path().join("checkpoint.bin");
    let mut first = new_trainer();
    for _ in 0..4 {
        first.step().unwrap();
    }
    let identity = run_identity(&ds, None, None, &config).unwrap();
    checkpoint::save(&ckpt, &identity, &config.train, &first.state).unwrap();
    drop(first);
    let mut resumed = new_trainer();
    resumed
        .restore(checkpoint::load(&ckpt, &config.train).unwrap())
        .unwrap();
    resumed.sync_progress();
    assert_eq!(resumed.state.iteration, 4);
    for _ in 0..4 {
        resumed.step().unwrap();
    }
    assert_eq!(resumed.state, whole.state, "resumed state differs");
    // Bit-level check of the floats (PartialEq treats -0.0 == 0.0).
    assert_eq!(resumed.state.float_bits(), whole.state.float_bits());

    // The pipeline's resume path: it continues from the checkpoint of iteration 4.
    let uninterrupted: RunReport = run(
        inputs(&ds, None),
        &config,
        &dir.path().join("a"),
        false,
        &mut silent,
    )
    .unwrap();
    let b = dir.path().join("b");
    std::fs::create_dir_all(&b).unwrap();
    std::fs::copy(&ckpt, b.join("checkpoint.bin")).unwrap();
    let mut trained_from = None;
    let resumed_run = run(inputs(&ds, None), &config, &b, true, &mut |e| {
        if let fewview_surface::pipeline::Event::Stage("training") = e {
            trained_from = Some(());
        }
    })
    .unwrap();
    assert!(trained_from.is_some());
    assert_eq!(resumed_run.iterations, 8);
    assert_eq!(
        resumed_run.final_pose_error.rotation_deg.to_bits(),
        uninterrupted.final_pose_error.rotation_deg.to_bits()
    );
    assert_eq!(
        resumed_run.final_pose_error.translation.to_bits(),
        uninterrupted.final_pose_error.translation.to_bits()
    );
    let read = |p: &std::path::Path| std::fs::read(p.join("poses_refined.json")).unwrap();
    assert_eq!(read(&b), read(&dir.path().join("a")));
}

/// The poses are tracked by autodiff only in the iterations that step them (a held pose
/// skips the hash grid's gradient with respect to the sample positions). That is safe only if
/// the field's update never reads that gradient: one step from the same state with the poses
/// held and with them stepped gives the same field parameters, bit for bit, and only the
/// stepped trainer's poses move.
#[test]
fn tracking_the_poses_leaves_the_field_update_unchanged() {
    let ds = tiny_scene();
    let config = tiny_config(4);
    let prep = prepare(&ds, None, &config).unwrap();
    let trainer = |pose_start: f64| {
        let mut train = config.train.clone();
        train.pose_start = pose_start;
        Trainer::new(
            train,
            prep.views.clone(),
            &prep.initial,
            prep.matches.clone(),
        )
        .unwrap()
    };
    let (mut held, mut stepped) = (trainer(1.0), trainer(0.0));
    assert!(!held.steps_poses(0) && stepped.steps_poses(0));
    let start = held.state.poses.clone();
    held.step().unwrap();
    stepped.step().unwrap();
    let bits = |p: &[Vec<f32>]| -> Vec<u32> { p.iter().flatten().map(|v| v.to_bits()).collect() };
    assert_eq!(bits(&held.state.params), bits(&stepped.state.params));
    assert_eq!(held.state.poses, start, "the held poses moved");
    assert_ne!(
        held.state.poses, stepped.state.poses,
        "the stepped poses did not move"
    );
}

/// A checkpoint written under another configuration is refused with a one-line error.
#[test]
fn checkpoint_of_another_configuration_is_refused() {
    let ds = tiny_scene();
    let config = tiny_config(4);
    let prep = prepare(&ds, None, &config).unwrap();
    let t = Trainer::new(
        config.train.clone(),
        prep.views.clone(),
        &prep.initial,
        prep.matches.clone(),
    )
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let ckpt = dir.path().join("checkpoint.bin");
    let identity = run_identity(&ds, None, None, &config).unwrap();
    checkpoint::save(&ckpt, &identity, &config.train, &t.state).unwrap();
    let mut other = config.train.clone();
    other.seed += 1;
    let err = checkpoint::load(&ckpt, &other).unwrap_err().to_string();
    assert!(err.contains("different configuration"), "{err}");
    assert!(!err.contains('\n'));
    std::fs::write(&ckpt, b"garbage").unwrap();
    let err = checkpoint::load(&ckpt, &config.train)
        .unwrap_err()
        .to_string();
    assert!(err.contains("not a surface checkpoint"), "{err}");
    // Version 1 (postcard: the magic string's length, 29, then the string; no checksum).
    let mut v1 = b"\x1dfewview-surface-checkpoint-v1".to_vec();
    v1.extend_from_slice(&[0; 64]);
    std::fs::write(&ckpt, &v1).unwrap();
    let err = checkpoint::load(&ckpt, &config.train)
        .unwrap_err()
        .to_string();
    assert!(err.contains("from an older version of fewview"), "{err}");
    // Version 2 (sealed, but its run identity records no cameras).
    let v2 = fewview_scene::sealed::seal(b"fewview-surface-checkpoint-v2\0", &[0; 64]);
    std::fs::write(&ckpt, &v2).unwrap();
    let err = checkpoint::load(&ckpt, &config.train)
        .unwrap_err()
        .to_string();
    assert!(err.contains("from an older version of fewview"), "{err}");
}

/// `--resume` continues only the run the checkpoint belongs to: another pose noise, other
/// training views, another image size, an iteration count below the checkpoint's, or a
/// bit-flipped file are refused with one line naming the checkpoint, before anything is
/// written (before, each of these resumed silently, and the flipped file surfaced later as
/// "training diverged"). A changed output setting resumes.
#[test]
fn resume_refuses_a_checkpoint_of_another_run_before_writing() {
    let ds = tiny_scene();
    let config = tiny_config(4);
    let prep = prepare(&ds, None, &config).unwrap();
    let mut t = Trainer::new(
        config.train.clone(),
        prep.views.clone(),
        &prep.start,
        prep.matches.clone(),
    )
    .unwrap();
    t.step().unwrap();
    t.step().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let ckpt = dir.path().join("saved.bin");
    let identity = run_identity(&ds, None, None, &config).unwrap();
    checkpoint::save(&ckpt, &identity, &config.train, &t.state).unwrap();

    let other_views = six_view_scene(64, 48, vec![1, 3, 5]);
    let other_size = six_view_scene(32, 24, vec![0, 2, 4]);
    let mut noisier = config.clone();
    noisier.initial_poses = InitialPoses::NoisyGroundTruth { sigma: 0.1 };
    let shorter = tiny_config(1);
    // The same settings and views, but the camera file moved the last training view by 1 mm
    // in a 1 m scene: the run would start from other poses.
    let mut moved_camera = ds.clone();
    let last = *moved_camera.train.last().unwrap();
    moved_camera.views[last]
        .camera
        .world_to_camera
        .translation
        .x += 1e-3;
    let moved_name = moved_camera.views[last].name.clone();
    let moved_expected = format!("camera of training view {moved_name}");
    let cases: [(&Dataset, Option<&Dataset>, &RunConfig, &str); 6] = [
        (&ds, None, &noisier, "settings initial_poses"),
        (&other_views, None, &config, "training views"),
        (&other_size, None, &config, "image size 64x48 (now 32x24"),
        (
            &ds,
            None,
            &shorter,
            "is at iteration 2, past --iterations 1",
        ),
        (&moved_camera, None, &config, &moved_expected),
        (&ds, Some(&moved_camera), &config, "ground-truth cameras"),
    ];
    for (i, (data, truth, cfg, expected)) in cases.into_iter().enumerate() {
        let out = dir.path().join(format!("case{i}"));
        std::fs::create_dir_all(&out).unwrap();
        std::fs::copy(&ckpt, out.join("checkpoint.bin")).unwrap();
        let run_inputs = RunInputs {
            truth,
            ..inputs(data, None)
        };
        let err = run(run_inputs, cfg, &out, true, &mut silent)
            .expect_err("refused")
            .to_string();
        assert!(
            err.contains("checkpoint.bin") && err.contains(expected),
            "{err}"
        );
        assert!(!err.contains('\n'), "{err}");
        assert!(
            !out.join("config.json").exists(),
            "case {i} wrote config.json"
        );
    }

    let flipped = dir.path().join("flipped");
    std::fs::create_dir_all(&flipped).unwrap();
    let mut bytes = std::fs::read(&ckpt).unwrap();
    let middle = bytes.len() / 2;
    bytes[middle] ^= 0x04;
    std::fs::write(flipped.join("checkpoint.bin"), &bytes).unwrap();
    let err = run(inputs(&ds, None), &config, &flipped, true, &mut silent)
        .expect_err("refused")
        .to_string();
    assert!(err.contains("checksum mismatch"), "{err}");
    assert!(!flipped.join("config.json").exists());

    // Output settings may change: the run resumes at iteration 2.
    let mut other_outputs = config.clone();
    other_outputs.mesh_resolution = 32;
    other_outputs.checkpoint_every = 1;
    let same = dir.path().join("same");
    std::fs::create_dir_all(&same).unwrap();
    std::fs::copy(&ckpt, same.join("checkpoint.bin")).unwrap();
    let mut first_step = None;
    run(inputs(&ds, None), &other_outputs, &same, true, &mut |e| {
        if let fewview_surface::pipeline::Event::Step(s) = e {
            first_step.get_or_insert(s.iteration);
        }
    })
    .unwrap();
    assert_eq!(first_step, Some(2));
}

/// A configuration or dataset the run cannot use is refused before the run folder is made:
/// no `config.json`, `matches.json` or `poses_initial.json` is left behind (they were, when
/// the check sat in the trainer, after matching and the warm-up). Fewer importance samples
/// than up-sampling steps panicked in the sampler (a step of zero samples), and a NaN loss
/// weight was accepted.
#[test]
fn bad_configuration_or_single_view_writes_nothing() {
    let ds = tiny_scene();
    let dir = tempfile::tempdir().unwrap();
    let with = |change: &dyn Fn(&mut RunConfig)| {
        let mut c = tiny_config(4);
        change(&mut c);
        c
    };
    let cases: [(&str, RunConfig, Dataset); 6] = [
        (
            "importance samples fewer than the up-sampling steps",
            with(&|c| c.train.sample.n_importance = 3),
            ds.clone(),
        ),
        (
            "one coarse sample",
            with(&|c| c.train.sample.n_coarse = 1),
            ds.clone(),
        ),
        (
            "NaN loss weight",
            with(&|c| c.train.losses.lambda_mc = f32::NAN),
            ds.clone(),
        ),
        ("iterations", tiny_config(0), ds.clone()),
        (
            "rays",
            {
                let mut c = tiny_config(4);
                c.train.rays_per_batch = 0;
                c
            },
            ds.clone(),
        ),
        (
            "one view",
            tiny_config(4),
            Dataset {
                train: ds.train[..1].to_vec(),
                ..ds.clone()
            },
        ),
    ];
    for (name, config, dataset) in cases {
        let out = dir.path().join(name);
        let err = run(inputs(&dataset, None), &config, &out, false, &mut silent)
            .unwrap_err()
            .to_string();
        assert!(!err.contains('\n'), "{name}: {err}");
        let expected = [
            "must be positive",
            "need at least 2",
            "cannot be shared by 4 up-sampling steps",
            "lambda_mc = NaN",
        ];
        assert!(expected.iter().any(|e| err.contains(e)), "{name}: {err}");
        assert!(!out.exists(), "{name}: {} was created", out.display());
    }
    // A reference surface Chamfer cannot score (no faces; faces without area) was found out
    // only after training, as "not scored".
    let line = fewview_geom::Mesh {
        vertices: vec![[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
        faces: vec![[0, 1, 2]],
        ..Default::default()
    };
    let empty = fewview_geom::Mesh::default();
    for (name, reference, expected) in [
        ("empty", &empty, "has no faces (0 vertices)"),
        ("line", &line, "none of its 1 faces has any area"),
    ] {
        let out = dir.path().join(name);
        let err = run(
            inputs(&ds, Some(reference)),
            &tiny_config(4),
            &out,
            false,
            &mut silent,
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.starts_with("reference surface: ") && err.contains(expected),
            "{err}"
        );
        assert!(!out.exists(), "{name}: {} was created", out.display());
    }
}

/// The analytic scene from noisy poses under the CLI's default (CPU) schedule, reduced to fit
/// the CI budget: 6 views at 160 × 120, σ = 0.05 se(3) noise, 300 iterations. The poses must
/// come out better than they went in (by a third, in rotation and translation), and the
/// extracted mesh must lie near the true surface after the Alg. 3 registration: Chamfer-L1
/// within 5 % of the bounding-box diagonal, 2.5 % on the part a training view sees. These are
/// regression bounds under the figures in docs/experiments.md, not the ≤ 1 % acceptance figure
/// of the full run.
#[test]
fn analytic_scene_with_noisy_poses_reduced_run() {
    let ds = sdf_dataset(&SdfSceneOptions {
        width: 160,
        height: 120,
        views: 12,
        train: vec![0, 2, 4, 6, 8, 10],
        supersample: 2,
        ..Default::default()
    });
    // The CLI's default schedule, at a test's size.
    let config = RunConfig::resolve(
        Schedule::Cpu,
        &Overrides {
            iterations: analytic_iterations(),
            rays_per_batch: 384,
            matches_per_batch: 64,
            initial_poses: InitialPoses::NoisyGroundTruth { sigma: 0.05 },
            checkpoint_every: 0,
            mesh_resolution: 128,
            eval_views: 2,
            eval_scale: 2,
            ..Default::default()
        },
    )
    .unwrap();
    let truth = surface_mesh(192).unwrap();
    let cameras: Vec<_> = ds
        .train
        .iter()
        .map(|&i| ds.views[i].camera.clone())
        .collect();
    let observed = observed_faces(&truth, &cameras);
    let dir = tempfile::tempdir().unwrap();
    let report = run(
        RunInputs {
            reference_observed: Some(&observed),
            ..inputs(&ds, Some(&truth))
        },
        &config,
        dir.path(),
        false,
        &mut silent,
    )
    .unwrap();
    let chamfer = report.chamfer.clone().expect("chamfer");
    let seen = report.chamfer_observed.clone().expect("observed chamfer");
    eprintln!(
        "analytic: observed part {:.3} % of diag ({:.3} % of the faces seen)",
        100.0 * seen.relative,
        100.0 * observed.iter().filter(|&&o| o).count() as f64 / observed.len() as f64
    );
    eprintln!(
        "analytic: chamfer {:.5} ({:.3} % of diag), R {:.3}° → {:.3}°, t {:.4} → {:.4}, psnr {:?}, {:.0} s",
        chamfer.chamfer_l1,
        100.0 * chamfer.relative,
        report.initial_pose_error.rotation_deg,
        report.final_pose_error.rotation_deg,
        report.initial_pose_error.translation,
        report.final_pose_error.translation,
        report.mean_psnr_masked,
        report.train_seconds_wall
    );
    // Scored like DTU on the faces a training view sees (67 % of them).
    assert!(
        seen.relative <= 0.025 && seen.relative < chamfer.relative,
        "observed part {:.4} of the diagonal",
        seen.relative
    );
    assert!(
        chamfer.relative <= 0.05,
        "chamfer {:.4} of the diagonal",
        chamfer.relative
    );
    let (before, after) = (&report.initial_pose_error, &report.final_pose_error);
    assert!(
        after.rotation_deg < 0.67 * before.rotation_deg
            && after.translation < 0.67 * before.translation,
        "poses not improved: {before:?} → {after:?}"
    );
    for f in [
        "mesh.ply",
        "poses_refined.json",
        "metrics.json",
        "renders/001_rgb.png",
    ] {
        assert!(dir.path().join(f).exists(), "{f} missing");
    }
}

fn analytic_iterations() -> usize {
    300
}

/// Dense matches (`--densify`, a deviation) on the CLI's analytic ring: eight views 45° apart,
/// where SIFT finds 5–50 matches per neighbouring pair and almost none between views 90° apart,
/// so the epipolar warm-up cannot form triangles. Grown from SIFT's seeds and composed through
/// the view between, the matches chain triangles over all views and the warm-up brings σ = 0.15
/// noise (13°) under half a degree.
#[test]
fn densified_matches_let_the_warm_up_recover_the_analytic_ring() {
    use fewview_metrics::pose_error::{PoseErrorOptions, pose_error_pairwise};
    use fewview_surface::matching::densify::DensifyOptions;
    use fewview_surface::warmup::WarmupOptions;
    let ds = sdf_dataset(&SdfSceneOptions::ring_of_eight());
    let mut config = RunConfig {
        max_pair_angle_deg: 100.0,
        pose_warmup: Some(WarmupOptions {
            min_matches_per_pair: 30,
            ..Default::default()
        }),
        ..Default::default()
    };
    config.initial_poses = InitialPoses::NoisyGroundTruth { sigma: 0.15 };
    let error = |prep: &fewview_surface::pipeline::Prepared| {
        let e = |p: &[fewview_scene::Se3]| {
            pose_error_pairwise(p, &prep.ground_truth, &PoseErrorOptions::default()).unwrap()
        };
        (e(&prep.initial), e(&prep.start))
    };
    let sparse = prepare(&ds, None, &config).unwrap();
    assert!(sparse.warmup.as_ref().unwrap().skipped.is_some());
    config.densify = Some(DensifyOptions {
        spacing_px: 4,
        ..Default::default()
    });
    let dense = prepare(&ds, None, &config).unwrap();
    let (before, after) = error(&dense);
    eprintln!(
        "ring: {} sparse → {} dense matches ({:?}); R {:.3}° → {:.3}°, t×100 {:.2} → {:.2}",
        sparse.matches.len(),
        dense.matches.len(),
        dense.match_precision,
        before.rotation_deg,
        after.rotation_deg,
        100.0 * before.translation,
        100.0 * after.translation
    );
    assert!(dense.warmup.as_ref().unwrap().skipped.is_none());
    assert!(dense.matches.len() > 5 * sparse.matches.len());
    assert!(dense.match_precision.unwrap().precision_2px > 0.98);
    assert!(before.rotation_deg > 10.0);
    // Measured 0.342° and t×100 1.38 (from 13.3° and 78.1; 0.470° and 1.84 on the scene before
    // the 2026-11-22 texture hash and fill light).
    assert!(after.rotation_deg < 0.6, "{after:?}");
    assert!(after.translation < 0.03, "{after:?}");
}

/// The all-around analytic scene (`--synthetic-all-around`: the ring of eight plus rings at 0°
/// and −30°, 24 training views seeing the whole surface). The rings are joined by pairs whose
/// triangles share single views, not edges; the parallel-rigidity test still finds every
/// baseline length tied, and the warm-up on dense matches brings σ = 0.15 noise under 0.3°.
#[test]
fn dense_warm_up_recovers_the_all_around_scene() {
    use fewview_metrics::pose_error::{PoseErrorOptions, pose_error_pairwise};
    use fewview_surface::matching::densify::DensifyOptions;
    use fewview_surface::warmup::WarmupOptions;
    let ds = sdf_dataset(&SdfSceneOptions::ring_of_eight_all_around());
    let config = RunConfig {
        max_pair_angle_deg: 65.0,
        pose_warmup: Some(WarmupOptions {
            min_matches_per_pair: 25,
            ..Default::default()
        }),
        densify: Some(DensifyOptions {
            spacing_px: 4,
            ..Default::default()
        }),
        initial_poses: InitialPoses::NoisyGroundTruth { sigma: 0.15 },
        ..Default::default()
    };
    let prep = prepare(&ds, None, &config).unwrap();
    let e = |p: &[fewview_scene::Se3]| {
        pose_error_pairwise(p, &prep.ground_truth, &PoseErrorOptions::default()).unwrap()
    };
    let (before, after) = (e(&prep.initial), e(&prep.start));
    eprintln!(
        "all around: {} matches ({:?}); R {:.3}° → {:.3}°, t×100 {:.2} → {:.2}",
        prep.matches.len(),
        prep.match_precision,
        before.rotation_deg,
        after.rotation_deg,
        100.0 * before.translation,
        100.0 * after.translation
    );
    let warmup = prep.warmup.as_ref().unwrap();
    assert!(warmup.skipped.is_none(), "{:?}", warmup.skipped);
    assert!(prep.match_precision.unwrap().precision_2px > 0.98);
    assert!(before.rotation_deg > 10.0);
    // Measured 0.166° and t×100 0.63 (from 14.3° and 64.5).
    assert!(after.rotation_deg < 0.3, "{after:?}");
    assert!(after.translation < 0.012, "{after:?}");
}
