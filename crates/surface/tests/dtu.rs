//! DTU scan65 (needs `FEWVIEW_DATA`): the CLI's pipeline end to end on the wide 3-view set
//! (22, 25, 28) at 400 × 300 from σ = 0.15 noisy poses: correspondences with their epipolar
//! precision against the true poses, a short joint optimisation, pose errors, outputs.
//!
//! It does **not** assert that the pose error drops, because on this data it does not yet:
//! measured with this configuration at 50 iterations R 12.39° → 16.97°, t×100 58.84 → 82.06;
//! at 200 iterations, R 12.39° → 17.97° and t×100
//! 58.84 → 69.85; at 800 iterations R 12.39° → 14.91°, t×100 58.84 → 52.40 (crate README).

// Tests report what they measured.
#![allow(clippy::print_stdout, clippy::print_stderr)]

use fewview_scene::load::{LoadOptions, load_dataset};
use fewview_scene::pose_export::PoseSource;
use fewview_surface::adam::ExpSchedule;
use fewview_surface::{InitialPoses, Overrides, RunConfig, RunInputs, Schedule, run};

fn scan65() -> std::path::PathBuf {
    let root = std::env::var("FEWVIEW_DATA")
        .expect("set FEWVIEW_DATA to the data folder (e.g. /work/shared/data)");
    std::path::Path::new(&root).join("dtu/scan65")
}

/// The wide triplet at 400 × 300 with view 24 held out.
fn wide_options() -> LoadOptions {
    LoadOptions {
        downscale: 2,
        train_views: Some(vec![22, 25, 28]),
        test_views: Some(vec![24]),
        ..LoadOptions::default()
    }
}

/// The run's inputs: `ds` (with `truth` for its errors) loaded from `dir` with `options`.
fn inputs<'a>(
    ds: &'a fewview_scene::Dataset,
    truth: Option<&'a fewview_scene::Dataset>,
    dir: &'a std::path::Path,
    options: &'a LoadOptions,
) -> RunInputs<'a> {
    RunInputs {
        dataset: ds,
        truth,
        matching: None,
        reference: None,
        reference_observed: None,
        source: Some(PoseSource { root: dir, options }),
    }
}

#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn dtu_scan65_short_run_end_to_end() {
    let dir = scan65();
    let options = wide_options();
    let ds = load_dataset(&dir, &options).unwrap_or_else(|e| panic!("{e}"));
    let mut config = RunConfig::default();
    config.train.iterations = 50;
    config.train.pose_lr = ExpSchedule {
        start: 1e-2,
        end: 1e-3,
    };
    config.initial_poses = InitialPoses::NoisyGroundTruth { sigma: 0.15 };
    config.checkpoint_every = 0;
    config.mesh_resolution = 64;
    config.eval_views = 1;
    config.eval_scale = 4;
    let out = tempfile::tempdir().unwrap();
    let inputs = inputs(&ds, None, &dir, &options);
    let report = run(inputs, &config, out.path(), false, &mut |_| {}).unwrap();
    let (a, b) = (&report.initial_pose_error, &report.final_pose_error);
    eprintln!(
        "scan65 50 it: R {:.3}° → {:.3}°, t×100 {:.2} → {:.2}, {} matches, {:.0} s",
        a.rotation_deg,
        b.rotation_deg,
        100.0 * a.translation,
        100.0 * b.translation,
        report.matches,
        report.train_seconds_wall
    );
    assert!(report.matches >= 20, "{} correspondences", report.matches);
    let precision = report.match_precision.as_ref().expect("match precision");
    assert!(precision.precision_2px >= 0.6, "{precision:?}");
    assert!(
        a.rotation_deg > 5.0 && a.translation > 0.2,
        "σ = 0.15 noise too small: {a:?}"
    );
    assert!(b.rotation_deg.is_finite() && b.translation.is_finite());
    assert_eq!(report.iterations, 50);
    for f in [
        "mesh.ply",
        "poses_refined.json",
        "metrics.json",
        "renders/024_rgb.png",
    ] {
        assert!(out.path().join(f).exists(), "{f} missing");
    }
    refined_cameras_file_reloads_as_the_refined_poses(&dir, &options, out.path(), &report);
    input_frame_outputs_overlay_the_refined_cameras(&dir, &options, out.path());
}

/// `mesh_input_frame.ply` is in the world of the run's `cameras_sphere_refined.npz` (DTU's
/// millimetres): mapped back by the reloaded file's `scale_mat` and projected by its cameras, each
/// vertex lands where `mesh.ply`'s vertex lands under `poses_refined.json`. The test view's
/// `024_depth.npy` is in millimetres too: its median depth is the distance along the true test
/// camera's axis to the mesh's centre, within the object's depth (the skull is about 150 mm deep).
fn input_frame_outputs_overlay_the_refined_cameras(
    scene: &std::path::Path,
    options: &LoadOptions,
    run_dir: &std::path::Path,
) {
    use fewview_geom::io::read_mesh;
    let (_copy, reloaded) = reload_with(scene, run_dir, "cameras_sphere.npz", options);
    let refined = fewview_geom::io::cameras::read_cameras(&run_dir.join("poses_refined.json"))
        .unwrap_or_else(|e| panic!("{e}"));
    let mesh = read_mesh(&run_dir.join("mesh.ply")).unwrap_or_else(|e| panic!("{e}"));
    let in_mm = read_mesh(&run_dir.join("mesh_input_frame.ply")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(mesh.faces, in_mm.faces);
    assert!(
        mesh.vertices.len() > 100,
        "{} vertices",
        mesh.vertices.len()
    );
    let to_mm = reloaded.to_source_world.expect("DTU keeps scale_mat");
    let from_mm = to_mm.try_inverse().unwrap();
    let v3 = |p: &[f32; 3]| nalgebra::Point3::new(p[0] as f64, p[1] as f64, p[2] as f64);
    let mut worst: f64 = 0.0;
    for (view, cam) in [22, 25, 28].into_iter().zip(&refined) {
        let file_cam = &reloaded.views[view].camera;
        for (p, q) in mesh.vertices.iter().zip(&in_mm.vertices) {
            let (Some(a), Some(b)) = (
                cam.project(&v3(p).coords),
                file_cam.project(&from_mm.transform_point(&v3(q)).coords),
            ) else {
                panic!("view {view}: a vertex behind the camera");
            };
            worst = worst.max((a.0 - b.0).hypot(a.1 - b.1));
        }
    }
    assert!(worst < 1e-2, "vertices land {worst:.2e} px apart");
    let depth = fewview_scene::numpy::read_npy(&run_dir.join("renders/024_depth.npy"))
        .unwrap_or_else(|e| panic!("{e}"));
    let truth = load_dataset(scene, options).unwrap_or_else(|e| panic!("{e}"));
    let test_cam = &truth.views[24].camera;
    assert_eq!(
        depth.shape,
        [
            test_cam.height() as usize / 4,
            test_cam.width() as usize / 4
        ]
    );
    // Back-projected through the true test camera and mapped to millimetres, the depth pixels
    // fall on the mesh: each one's distance to the nearest vertex of `mesh_input_frame.ply`.
    let mm_per_unit = to_mm.fixed_view::<3, 3>(0, 0).determinant().cbrt();
    let small = test_cam.resized(depth.shape[1] as u32, depth.shape[0] as u32);
    let width = depth.shape[1];
    let mut off_mm: Vec<f64> = (0..depth.data.len())
        .filter(|&i| depth.data[i] > 0.0)
        .map(|i| {
            let (u, v) = ((i % width) as f64 + 0.5, (i / width) as f64 + 0.5);
            let p = small.unproject(u, v, depth.data[i] / mm_per_unit);
            let p_mm = to_mm.transform_point(&p.into());
            in_mm
                .vertices
                .iter()
                .map(|q| (v3(q) - p_mm).norm())
                .fold(f64::INFINITY, f64::min)
        })
        .collect();
    assert!(
        off_mm.len() > depth.data.len() / 10,
        "{} foreground pixels",
        off_mm.len()
    );
    off_mm.sort_by(f64::total_cmp);
    let median = off_mm[off_mm.len() / 2];
    eprintln!(
        "test view 24: depth pixels lie {median:.2} mm (median) from the mesh; vertices agree to {worst:.1e} px"
    );
    // Points on a surface lie within about half an edge of its nearest vertex (64³ marching cubes:
    // edges of several millimetres); a depth map in the wrong units or frame lands hundreds of
    // millimetres off (the skull is 600 mm from the camera).
    let edge = in_mm
        .faces
        .iter()
        .map(|f| (v3(&in_mm.vertices[f[0] as usize]) - v3(&in_mm.vertices[f[1] as usize])).norm())
        .sum::<f64>()
        / in_mm.faces.len() as f64;
    eprintln!("mean edge {edge:.2} mm");
    assert!(
        median < 2.0 * edge,
        "depth pixels {median} mm from the mesh (edges {edge} mm)"
    );
}

/// The scene at `scene` with the run's `<camera_file stem>_refined.npz` in place of
/// `camera_file`, loaded with `options` (the folder is returned to keep it alive).
fn reload_with(
    scene: &std::path::Path,
    run_dir: &std::path::Path,
    camera_file: &str,
    options: &LoadOptions,
) -> (tempfile::TempDir, fewview_scene::Dataset) {
    let copy = tempfile::tempdir().unwrap();
    for folder in ["image", "mask"] {
        std::os::unix::fs::symlink(scene.join(folder), copy.path().join(folder)).unwrap();
    }
    let written = camera_file.replace(".npz", "_refined.npz");
    std::fs::copy(run_dir.join(written), copy.path().join(camera_file)).unwrap();
    // Named as the format: a folder with only `cameras_linear_init.npz` is not detected as DTU.
    let options = LoadOptions {
        format: Some(fewview_scene::DatasetFormat::DtuIdr),
        ..options.clone()
    };
    let reloaded = load_dataset(copy.path(), &options).unwrap_or_else(|e| panic!("{e}"));
    (copy, reloaded)
}

/// Starting from scan65's `cameras_linear_init.npz` (`--initial-poses loaded`, a `scale_mat`
/// 76 mm away from `cameras_sphere.npz`'s), the refined `cameras_linear_init_refined.npz` puts
/// each camera as far from the true one, in the DTU world's millimetres, as Alg. 2 measures in
/// the true cameras' normalised frame (times that frame's scale).
#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn dtu_scan65_linear_init_export_lands_in_the_world_of_the_true_cameras() {
    let dir = scan65();
    let truth_options = wide_options();
    let options = LoadOptions {
        cameras_file: Some("cameras_linear_init.npz".into()),
        ..truth_options.clone()
    };
    let ds = load_dataset(&dir, &options).unwrap_or_else(|e| panic!("{e}"));
    let truth = load_dataset(&dir, &truth_options).unwrap_or_else(|e| panic!("{e}"));
    let mut config = RunConfig::default();
    config.train.iterations = 10;
    config.initial_poses = InitialPoses::AsLoaded;
    config.checkpoint_every = 0;
    config.mesh_resolution = 32;
    config.eval_views = 0;
    let out = tempfile::tempdir().unwrap();
    let inputs = inputs(&ds, Some(&truth), &dir, &options);
    let report = run(inputs, &config, out.path(), false, &mut |_| {}).unwrap();
    assert_eq!(
        report.refined_pose_files,
        ["cameras_linear_init_refined.npz"]
    );
    let (_copy, reloaded) = reload_with(&dir, out.path(), "cameras_linear_init.npz", &options);
    let in_mm = |d: &fewview_scene::Dataset, view: usize| {
        let m = d.to_source_world.expect("DTU keeps scale_mat");
        m.transform_point(&d.views[view].camera.center().into())
            .coords
    };
    let truth_scale = truth
        .to_source_world
        .unwrap()
        .fixed_view::<3, 3>(0, 0)
        .determinant()
        .cbrt();
    let err = &report.final_pose_error;
    for (k, view) in [22, 25, 28].into_iter().enumerate() {
        let off_mm = (in_mm(&reloaded, view) - in_mm(&truth, view)).norm();
        let reported_mm = err.per_view_translation[k] * truth_scale;
        eprintln!("view {view}: {off_mm:.4} mm from the truth, Alg. 2 says {reported_mm:.4} mm");
        assert!(
            (off_mm - reported_mm).abs() < 1e-3,
            "view {view}: {off_mm} mm against {reported_mm} mm"
        );
    }
}

/// The run's `cameras_sphere_refined.npz`, put in place of the scene's camera file, loads (by
/// the DTU loader, at the run's resolution) to the cameras of `poses_refined.json` mapped by
/// the Alg. 1 alignment into the ground-truth frame, and those are as close to the true
/// cameras as the reported error says.
fn refined_cameras_file_reloads_as_the_refined_poses(
    scene: &std::path::Path,
    options: &LoadOptions,
    run_dir: &std::path::Path,
    report: &fewview_surface::pipeline::RunReport,
) {
    assert_eq!(report.refined_pose_files, ["cameras_sphere_refined.npz"]);
    let (_copy, reloaded) = reload_with(scene, run_dir, "cameras_sphere.npz", options);
    let refined = fewview_geom::io::cameras::read_cameras(&run_dir.join("poses_refined.json"))
        .unwrap_or_else(|e| panic!("{e}"));
    let alignment = &report.final_pose_error.alignment;
    let truth = load_dataset(scene, options).unwrap_or_else(|e| panic!("{e}"));
    // `poses_refined_aligned.json`, what a splat run's `--init surface:DIR` trains with: the
    // same aligned poses, in the frame of the dataset as loaded.
    let aligned =
        fewview_geom::io::cameras::read_cameras(&run_dir.join("poses_refined_aligned.json"))
            .unwrap_or_else(|e| panic!("{e}"));
    for (cam, a) in refined.iter().zip(&aligned) {
        let expected = alignment.apply_to_pose(&cam.world_to_camera);
        let r = (a.world_to_camera.rotation - expected.rotation).abs().max();
        let t = (a.world_to_camera.translation - expected.translation).norm();
        assert!(
            r < 1e-7 && t < 1e-7,
            "aligned camera off by {r:.2e}, {t:.2e}"
        );
    }
    for (k, (view, cam)) in [22, 25, 28].into_iter().zip(&refined).enumerate() {
        let got = &reloaded.views[view].camera;
        let expected = alignment.apply_to_pose(&cam.world_to_camera);
        let (r, t) = (
            (got.world_to_camera.rotation - expected.rotation)
                .abs()
                .max(),
            (got.world_to_camera.translation - expected.translation).norm(),
        );
        // The JSON holds the poses as written; the npz goes through K [R | t] and back.
        assert!(
            r < 1e-6 && t < 1e-6,
            "view {view}: rotation off {r:.2e}, translation {t:.2e}"
        );
        let (k0, k1) = (&got.intrinsics, &cam.intrinsics);
        assert!((k0.fx - k1.fx).abs() < 1e-6 && (k0.cx - k1.cx).abs() < 1e-6);
        // In the file's frame: as far from the true camera centre as Alg. 2 measured.
        let off = (got.center() - truth.views[view].camera.center()).norm();
        let reported = report.final_pose_error.per_view_translation[k];
        assert!(
            (off - reported).abs() < 1e-6,
            "view {view}: {off} against {reported}"
        );
    }
}

/// The epipolar warm-up (`--pose-warmup on`, a deviation) on the narrow triplet 22, 23, 24,
/// trained at 400 × 300 and matched at 800 × 600, from σ = 0.15 noise, three seeds: the
/// affinely refined matches alone bring the rotation error from about 12° to under 0.13°, and
/// without the refinement (seed 0) the error is more than twice as large. On the wide triplet
/// (10 matches between views 22 and 28) it declines to run; with dense matches (`--densify`,
/// a deviation) it runs on all three seeds and, with the CPU schedule's covariance polish, lands
/// under 0.14°.
#[test]
#[ignore = "needs FEWVIEW_DATA (dataset tests)"]
fn dtu_scan65_epipolar_warmup_recovers_most_of_the_pose_noise() {
    use fewview_metrics::pose_error::{PoseErrorOptions, pose_error_pairwise};
    use fewview_surface::pipeline::prepare_with_matching;
    use fewview_surface::warmup::WarmupOptions;
    let dir = scan65();
    let load = |views: Vec<usize>, downscale: u32| {
        load_dataset(
            &dir,
            &LoadOptions {
                downscale,
                train_views: Some(views),
                test_views: Some(vec![0]),
                ..LoadOptions::default()
            },
        )
        .unwrap_or_else(|e| panic!("{e}"))
    };
    let error = |est: &[fewview_scene::Se3], gt: &[fewview_scene::Se3]| {
        pose_error_pairwise(est, gt, &PoseErrorOptions::default()).unwrap()
    };
    // Trained at 400 × 300, matched at 800 × 600 (the CLI's default `--match-downscale 1`).
    let narrow = load(vec![22, 23, 24], 2);
    let narrow_fine = load(vec![22, 23, 24], 1);
    for seed in 0..3 {
        // The CLI's defaults: it would densify if the sparse matches fell short.
        let config = RunConfig::resolve(
            Schedule::Cpu,
            &Overrides {
                seed,
                ..Overrides::default()
            },
        )
        .unwrap();
        let prep = prepare_with_matching(&narrow, None, Some(&narrow_fine), &config).unwrap();
        let before = error(&prep.initial, &prep.ground_truth);
        // The warm-up's poses (the schedule's bundle adjustment follows them).
        let after = error(&prep.warmup_poses, &prep.ground_truth);
        eprintln!(
            "seed {seed}: R {:.3}° → {:.3}°, t×100 {:.2} → {:.2}",
            before.rotation_deg,
            after.rotation_deg,
            100.0 * before.translation,
            100.0 * after.translation
        );
        assert!(prep.warmup.as_ref().unwrap().skipped.is_none());
        assert_eq!(prep.densified_because, None, "the sparse matches suffice");
        assert!(before.rotation_deg > 5.0, "{before:?}");
        // Measured 0.106° / 0.106° / 0.093° and t×100 0.36 / 0.36 / 0.34 (unrefined matches:
        // 0.293° / 0.310° / 0.278°, 1.25 / 1.19 / 0.95; matching at 400 × 300: 0.59–0.72°).
        assert!(after.rotation_deg < 0.13, "seed {seed}: {after:?}");
        assert!(after.translation < 0.005, "seed {seed}: {after:?}");
        if seed == 0 {
            let unrefined = RunConfig {
                match_refinement: None,
                ..config.clone()
            };
            let prep =
                prepare_with_matching(&narrow, None, Some(&narrow_fine), &unrefined).unwrap();
            let raw = error(&prep.warmup_poses, &prep.ground_truth);
            eprintln!(
                "seed 0 unrefined: R {:.3}°, t×100 {:.2}",
                raw.rotation_deg,
                100.0 * raw.translation
            );
            assert!(
                raw.rotation_deg > 2.0 * after.rotation_deg,
                "{raw:?} vs {after:?}"
            );
        }
    }
    // Even at 800 × 600 the wide pair 22–28 shares only 10 matches.
    let wide = load(vec![22, 25, 28], 2);
    let wide_fine = load(vec![22, 25, 28], 1);
    let config = RunConfig {
        pose_warmup: Some(WarmupOptions::default()),
        ..Default::default()
    };
    let prep = prepare_with_matching(&wide, None, Some(&wide_fine), &config).unwrap();
    assert!(prep.warmup.unwrap().skipped.is_some());
    assert_eq!(prep.start, prep.initial);
    // On the chain 22–25–28 (29 and 38 refined matches; `--warmup-connectivity connected
    // --warmup-min-matches 25`) it runs. Seed 0 measured 12.39° → 0.30°; seeds 1 and 2 reach
    // only 3.4° and 1.6° (see the crate README), so only seed 0 is asserted.
    let chain = RunConfig {
        pose_warmup: Some(WarmupOptions {
            min_matches_per_pair: 25,
            connectivity: fewview_surface::warmup::Connectivity::Connected,
            ..Default::default()
        }),
        ..Default::default()
    };
    let prep = prepare_with_matching(&wide, None, Some(&wide_fine), &chain).unwrap();
    assert!(prep.warmup.as_ref().unwrap().skipped.is_none());
    let (before, after) = (
        error(&prep.initial, &prep.ground_truth),
        error(&prep.start, &prep.ground_truth),
    );
    eprintln!(
        "wide chain, seed 0: R {:.3}° → {:.3}°",
        before.rotation_deg, after.rotation_deg
    );
    assert!(after.rotation_deg < 1.0, "{before:?} → {after:?}");
    // Dense matches, grown because the sparse ones cannot tie the views together (the CLI's
    // default `--schedule cpu --densify auto`, with `--max-pair-angle 180`; the same as
    // `--densify 4 --max-pair-angle 180 --warmup-min-matches 30`): the outer pair, seeded through
    // view 25, gets ~320 matches, triangles form, and every seed's warm-up runs; the CPU
    // schedule's covariance polish then weighs each dense match by its Lucas–Kanade
    // uncertainty. Measured 0.103° / 0.126° / 0.110°, t×100 0.39 / 0.40 / 0.48 (without the
    // polish 0.163° / 0.159° / 0.186°, t×100 0.64 / 0.63 / 0.86). The patch adjustment then
    // lands under 0.1° (its measured figures in docs/experiments.md).
    for seed in 0..3 {
        let dense = RunConfig::resolve(
            Schedule::Cpu,
            &Overrides {
                seed,
                max_pair_angle_deg: 180.0,
                ..Overrides::default()
            },
        )
        .unwrap();
        let prep = prepare_with_matching(&wide, None, Some(&wide_fine), &dense).unwrap();
        let why = prep.densified_because.as_deref().unwrap_or_default();
        assert!(why.contains("too few matches"), "seed {seed}: {why:?}");
        assert!(prep.warmup.as_ref().unwrap().skipped.is_none());
        let patches = prep.patch_adjustment.as_ref().expect("patches adjusted");
        let after = error(&prep.warmup_poses, &prep.ground_truth);
        let adjusted = error(&prep.start, &prep.ground_truth);
        eprintln!(
            "wide dense, seed {seed}: {} matches, R {:.3}°, t×100 {:.2}; {} patches: R {:.3}°, t×100 {:.2}",
            prep.matches.len(),
            after.rotation_deg,
            100.0 * after.translation,
            patches.patches,
            adjusted.rotation_deg,
            100.0 * adjusted.translation
        );
        assert!(
            prep.warmup.as_ref().unwrap().covariance_weighted > 1000,
            "seed {seed}: the polish weighs the dense matches"
        );
        assert!(after.rotation_deg < 0.14, "seed {seed}: {after:?}");
        assert!(after.translation < 0.0055, "seed {seed}: {after:?}");
        // The photometric patch adjustment that follows (CPU schedule) meets the surface paper's
        // target on every seed.
        assert!(
            patches.skipped.is_none() && patches.joined > 800,
            "{patches:?}"
        );
        assert!(adjusted.rotation_deg < 0.1, "seed {seed}: {adjusted:?}");
        assert!(adjusted.translation < 0.006, "seed {seed}: {adjusted:?}");
    }
}
