//! The core commands end to end on small LLFF-format folders written here: a short `train`, then
//! `eval` and `render` of its PLY agree with the run's own figures; and every listed kind of bad
//! input gives a one-line error and a non-zero exit, never a panic.

use std::path::{Path, PathBuf};

mod common;
use common::{assert_clean_error, fewview, fewview_ok, s};

/// A run directory's `metrics.json`.
fn metrics(run: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(run.join("metrics.json")).unwrap()).unwrap()
}

/// Writes a `.npy` file of f64 values (NumPy format 1.0, C order).
fn write_npy(path: &Path, rows: usize, cols: usize, values: &[f64]) {
    let mut header =
        format!("{{'descr': '<f8', 'fortran_order': False, 'shape': ({rows}, {cols}), }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    for v in values {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    std::fs::write(path, bytes).unwrap();
}

/// A 10-view forward-facing capture in the LLFF layout (`poses_bounds.npy` + `images_8/`),
/// 48×36 images of a textured plane seen from cameras on a line.
fn write_llff(dir: &Path, tweak: impl Fn(usize, &mut [f64; 17])) -> PathBuf {
    let (w, h, f) = (48usize, 36usize, 40.0f64);
    std::fs::create_dir_all(dir.join("images_8")).unwrap();
    let mut rows = Vec::new();
    for i in 0..10 {
        let x = -0.5 + 0.1 * i as f64;
        // LLFF columns of R: (down, right, back) = (-y, +x, +z) for a camera looking along -z.
        let r = [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        let t = [x, 0.0, 0.0];
        let hwf = [h as f64 * 8.0, w as f64 * 8.0, f * 8.0];
        let mut row = [0.0; 17];
        for k in 0..3 {
            row[k * 5..k * 5 + 3].copy_from_slice(&r[k]);
            row[k * 5 + 3] = t[k];
            row[k * 5 + 4] = hwf[k];
        }
        row[15] = 2.0;
        row[16] = 6.0;
        tweak(i, &mut row);
        rows.extend_from_slice(&row);
        // A plane at depth 4 with a texture that moves with the camera's x.
        let mut img = fewview_scene::Image::new(w, h, 3);
        for py in 0..h {
            for px in 0..w {
                let u = (px as f64 + 0.5 - w as f64 / 2.0) / f * 4.0 + x;
                let v = (py as f64 + 0.5 - h as f64 / 2.0) / f * 4.0;
                let c = [
                    0.5 + 0.4 * (5.0 * u).sin(),
                    0.5 + 0.4 * (4.0 * v).cos(),
                    0.5 + 0.3 * (3.0 * (u + v)).sin(),
                ];
                for (k, ck) in c.iter().enumerate() {
                    img.set(px, py, k, *ck as f32);
                }
            }
        }
        img.save_png(&dir.join("images_8").join(format!("image{i:03}.png")))
            .unwrap();
    }
    write_npy(&dir.join("poses_bounds.npy"), 10, 17, &rows);
    dir.to_path_buf()
}

#[test]
fn train_then_eval_and_render_agree_with_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let data = write_llff(&dir.path().join("scene"), |_, _| {});
    let run = dir.path().join("run");
    let out = fewview_ok(&[
        "train",
        "--data",
        s(&data),
        "--iterations",
        "30",
        "--init-points",
        "1500",
        "--out",
        s(&run),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("held-out PSNR"), "{stdout}");
    let metrics = metrics(&run);
    let psnr = metrics["test"]["mean_psnr"].as_f64().unwrap();
    assert!(psnr.is_finite());

    // `eval` of the written PLY reproduces the run's held-out scores exactly.
    let json = dir.path().join("eval.json");
    let ply = run.join("point_cloud.ply");
    fewview_ok(&[
        "eval",
        "--ply",
        s(&ply),
        "--data",
        s(&data),
        "--json",
        s(&json),
    ]);
    let eval: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(eval["mean_psnr"].as_f64().unwrap(), psnr);

    // `render` of the PLY gives the same images the run saved.
    let renders = dir.path().join("renders");
    let video = dir.path().join("path.gif");
    fewview_ok(&[
        "render",
        "--ply",
        s(&ply),
        "--data",
        s(&data),
        "--out",
        s(&renders),
        "--depth",
        "--path",
        s(&video),
        "--frames-per-segment",
        "3",
    ]);
    for entry in std::fs::read_dir(run.join("renders/test")).unwrap() {
        let p = entry.unwrap().path();
        let a = fewview_scene::Image::load(&p).unwrap();
        let b = fewview_scene::Image::load(&renders.join(p.file_name().unwrap())).unwrap();
        assert_eq!(a, b, "{}", p.display());
    }
    let (frames, _) = fewview_video::read_video(&video).unwrap();
    assert_eq!(frames.len(), 2 * 3 + 1);

    // The held-out ST-LPIPS in metrics.json is the mean over the saved renders against their
    // photos (within the renders' 8-bit rounding).
    assert!(stdout.contains("held-out LPIPS"), "{stdout}");
    let lpips = fewview_metrics::lpips::Lpips::default_st_alex().unwrap();
    let mut distances = Vec::new();
    for entry in std::fs::read_dir(run.join("renders/test")).unwrap() {
        let p = entry.unwrap().path();
        let render = fewview_scene::Image::load(&p).unwrap();
        let photo = fewview_scene::Image::load(&data.join("images_8").join(p.file_name().unwrap()))
            .unwrap();
        distances.push(lpips.distance(&render, &photo).unwrap());
    }
    let want = distances.iter().sum::<f64>() / distances.len() as f64;
    let got = metrics["lpips"]["mean"].as_f64().unwrap();
    assert!(
        !distances.is_empty() && (got - want).abs() < 5e-3,
        "{got} vs {want}"
    );
}

#[test]
fn resume_without_a_checkpoint_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let data = write_llff(&dir.path().join("scene"), |_, _| {});
    let run = dir.path().join("run");
    let out = fewview(&[
        "train",
        "--data",
        s(&data),
        "--iterations",
        "5",
        "--out",
        s(&run),
        "--resume",
    ]);
    assert_clean_error(&out, &["checkpoint.bin", "no checkpoint"]);
}

#[test]
fn bad_inputs_give_one_line_errors() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let good = write_llff(&root.join("good"), |_, _| {});

    // Missing dataset folder.
    let missing = root.join("nope");
    assert_clean_error(
        &fewview(&["train", "--data", s(&missing), "--iterations", "2"]),
        &["nope"],
    );

    // Corrupt poses file.
    let corrupt = write_llff(&root.join("corrupt"), |_, _| {});
    std::fs::write(corrupt.join("poses_bounds.npy"), b"definitely not numpy").unwrap();
    assert_clean_error(
        &fewview(&["train", "--data", s(&corrupt), "--iterations", "2"]),
        &["poses_bounds.npy"],
    );

    // NaN in a pose.
    let nan = write_llff(&root.join("nan"), |i, row| {
        if i == 3 {
            row[3] = f64::NAN;
        }
    });
    assert_clean_error(
        &fewview(&["train", "--data", s(&nan), "--iterations", "2"]),
        &["poses_bounds.npy"],
    );

    // An image whose size disagrees with the cameras.
    let sized = write_llff(&root.join("sized"), |_, _| {});
    fewview_scene::Image::new(20, 20, 3)
        .save_png(&sized.join("images_8/image004.png"))
        .unwrap();
    assert_clean_error(
        &fewview(&["train", "--data", s(&sized), "--iterations", "2"]),
        &["image004.png"],
    );

    // View index out of range.
    assert_clean_error(
        &fewview(&[
            "train",
            "--data",
            s(&good),
            "--train-views",
            "1,2,42",
            "--iterations",
            "2",
        ]),
        &["42"],
    );

    // Missing or corrupt model file.
    let bad_ply = root.join("bad.ply");
    std::fs::write(
        &bad_ply,
        b"ply\nformat ascii 1.0\nelement vertex 1\nend_header\n",
    )
    .unwrap();
    assert_clean_error(
        &fewview(&["eval", "--ply", s(&bad_ply), "--data", s(&good)]),
        &["bad.ply"],
    );
    assert_clean_error(
        &fewview(&[
            "eval",
            "--ply",
            s(&root.join("absent.ply")),
            "--data",
            s(&good),
        ]),
        &["absent.ply"],
    );

    // A diverging loss is reported with its iteration: initial colours at the edge of f32.
    let mut model = fewview_splat::model::GaussianModel::new(3);
    for k in 0..50 {
        model.push_isotropic([0.02 * k as f32 - 0.5, 0.0, -4.0], 0.3, [0.5; 3], 0.9);
    }
    for (i, v) in model.sh.iter_mut().enumerate() {
        if i % 48 < 3 {
            *v = 3.0e38;
        }
    }
    let huge = root.join("huge.ply");
    fewview_splat::ply::write_ply(&huge, &model).unwrap();
    let init = format!("ply:{}", huge.display());
    assert_clean_error(
        &fewview(&[
            "train",
            "--data",
            s(&good),
            "--init",
            &init,
            "--iterations",
            "5",
            "--out",
            s(&root.join("div")),
        ]),
        &["diverged at iteration 1"],
    );

    // Bad flag values.
    assert_clean_error(
        &fewview(&["train", "--data", s(&good), "--iterations", "0"]),
        &["iterations"],
    );
    assert_clean_error(
        &fewview(&["train", "--data", s(&good), "--init", "sphere"]),
        &["--init sphere"],
    );
}

/// Runs `fewview train --data DATA FLAGS --out RUN` and asserts a one-line error with every
/// needle, with the run folder never made.
fn assert_train_refused_before_writing(data: &Path, run: &Path, flags: &[&str], needles: &[&str]) {
    let args: Vec<&str> = ["train", "--data", s(data)]
        .into_iter()
        .chain(flags.iter().copied())
        .chain(["--out", s(run)])
        .collect();
    assert_clean_error(&fewview(&args), needles);
    assert!(!run.exists(), "{flags:?}: nothing written");
}

/// Held-out views too small for SSIM (or whose mask a downscale empties) used to fail only at
/// the evaluation, after config.json and point_cloud.ply were written.
#[test]
fn train_refuses_views_too_small_to_score_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    let data = write_llff(&dir.path().join("scene"), |_, _| {});
    assert_train_refused_before_writing(
        &data,
        &dir.path().join("run"),
        &["--downscale", "5", "--iterations", "2"],
        &["SSIM window", "downscale"],
    );
}

/// 10¹² random initial points used to abort on allocation.
#[test]
fn train_refuses_too_many_initial_points() {
    let dir = tempfile::tempdir().unwrap();
    let data = write_llff(&dir.path().join("scene"), |_, _| {});
    assert_train_refused_before_writing(
        &data,
        &dir.path().join("run"),
        &["--init-points", "1000000000000"],
        &["--init-points 1000000000000", "allowed"],
    );
}

/// Training and held-out views that overlap (explicit lists against the default hold-out, or
/// against each other) used to train silently and report "held-out" PSNR on training views.
#[test]
fn train_refuses_overlapping_train_and_test_views() {
    let dir = tempfile::tempdir().unwrap();
    let data = write_llff(&dir.path().join("scene"), |_, _| {});
    let run = dir.path().join("run");
    // 10 views: the default hold-out (every 8th) is [0, 8].
    assert_train_refused_before_writing(
        &data,
        &run,
        &["--train-views", "0,8,9", "--iterations", "2"],
        &["train views [0, 8, 9]", "test views [0, 8]", "--test-views"],
    );
    assert_train_refused_before_writing(
        &data,
        &run,
        &[
            "--train-views",
            "1,2",
            "--test-views",
            "1,3",
            "--iterations",
            "2",
        ],
        &["train views [1, 2]", "test views [1, 3]", "share [1]"],
    );
}

/// A huge --frames-per-segment used to hang building the path before the output's container
/// was even looked at; now both are checked before anything is read or rendered.
#[test]
fn render_checks_the_path_flags_before_rendering() {
    let dir = tempfile::tempdir().unwrap();
    let data = write_llff(&dir.path().join("scene"), |_, _| {});
    let mut model = fewview_splat::model::GaussianModel::new(0);
    model.push_isotropic([0.0, 0.0, -4.0], 0.3, [0.5; 3], 0.9);
    let ply = dir.path().join("m.ply");
    fewview_splat::ply::write_ply(&ply, &model).unwrap();
    let renders = dir.path().join("renders");
    let render = |path: &Path, per_segment: &str| {
        fewview(&[
            "render",
            "--ply",
            s(&ply),
            "--data",
            s(&data),
            "--out",
            s(&renders),
            "--path",
            s(path),
            "--frames-per-segment",
            per_segment,
        ])
    };
    let json = dir.path().join("p.json");
    assert_clean_error(&render(&json, "100000000000"), &["p.json", ".json"]);
    let gif = dir.path().join("p.gif");
    assert_clean_error(
        &render(&gif, "100000000000"),
        &["--frames-per-segment 100000000000", "10000"],
    );
    // 3 training views: 2 segments of 6000 frames are over the cap too.
    assert_clean_error(&render(&gif, "6000"), &["12001-frame"]);
    assert!(!renders.exists() && !gif.exists(), "nothing written");
}

#[test]
fn surface_runs_on_the_built_in_analytic_scene_without_a_dataset() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("sdf");
    // A few iterations leave the field near its initial sphere: the whole surface is always
    // scored, but whether the registered blob lies near enough to the observed part for that
    // part to be scored depends on where the warm-up put the poses, i.e. on the seed.
    fewview_ok(&[
        "surface",
        "--synthetic",
        "--iterations",
        "4",
        "--mesh-resolution",
        "32",
        "--eval-views",
        "1",
        "--eval-scale",
        "4",
        "--out",
        s(&run),
    ]);
    let metrics = metrics(&run);
    // Scored against the scene's exact surface.
    let relative = metrics["chamfer"]["relative"].as_f64().unwrap();
    assert!(relative.is_finite() && relative > 0.0, "{relative}");
    // And on the part the training views see (all look down at 30°; the underside is hidden),
    // or, for any seed whose blob misses it, the reason it was not scored.
    match metrics["chamfer_observed"]["relative"].as_f64() {
        Some(seen) => assert!(seen.is_finite() && seen > 0.0, "{seen}"),
        None => {
            let why = metrics["chamfer_error"].as_str().unwrap_or_default();
            assert!(why.contains("observed part"), "{why:?}");
        }
    }
    assert!(run.join("mesh.ply").exists());
    // The default (CPU) schedule warms the poses up. The ring's sparse matches cannot tie its
    // views together, so dense ones are grown first (pairs 90° apart composed through the
    // view between); the warm-up then runs (measured 13.3° → 0.265° with the covariance
    // polish, which weighs every grown match), then the patch adjustment, whose poses are
    // held for the whole run.
    assert!(
        metrics["densified_because"].is_string(),
        "{}",
        metrics["densified_because"]
    );
    assert!(
        metrics["warmup"]["skipped"].is_null(),
        "{}",
        metrics["warmup"]
    );
    assert!(
        metrics["warmup"]["covariance_weighted"].as_u64().unwrap() > 2000,
        "{}",
        metrics["warmup"]
    );
    let warmed = metrics["warmup_pose_error"]["rotation_deg"]
        .as_f64()
        .unwrap();
    assert!(warmed < 1.0, "{warmed}");
    // After dense matches the photometric patch adjustment follows (measured 0.265° → 0.107°).
    assert!(
        metrics["patch_adjustment"]["skipped"].is_null(),
        "{}",
        metrics["patch_adjustment"]
    );
    assert!(metrics["patch_adjustment"]["joined"].as_u64().unwrap() > 1000);
    let patched = metrics["patch_adjustment_pose_error"]["rotation_deg"]
        .as_f64()
        .unwrap();
    assert!(patched < 0.6 * warmed, "{patched} vs {warmed}");
    // The same poses scored at SPARF's ε = 1e-7: every view's floor drops from 0.081° to
    // 0.026°, so the mean over the eight views drops by at least an eighth of that (Alg. 1's
    // anchor is aligned exactly).
    let sparf = &metrics["rotation_at_sparf_eps"];
    assert_eq!(sparf["eps"].as_f64(), Some(1e-7));
    for (at_printed, at_sparf) in [
        (&metrics["warmup_pose_error"], &sparf["warmup_deg"]),
        (
            &metrics["patch_adjustment_pose_error"],
            &sparf["patch_adjustment_deg"],
        ),
        (&metrics["final_pose_error"], &sparf["final_deg"]),
    ] {
        let (printed, sparf) = (
            at_printed["rotation_deg"].as_f64().unwrap(),
            at_sparf.as_f64().unwrap(),
        );
        assert!(
            sparf <= printed - (0.081 - 0.026) / 8.0,
            "{sparf} vs {printed}"
        );
    }
    assert_eq!(metrics["pose_timing_fell_back"], false);
    // The adjusted poses are kept for the whole run.
    assert_eq!(metrics["pose_timing"]["start"], 1.0);
    // With sparse matches only, the warm-up declines and the poses fall back to the paper's
    // timing: refined from the first iteration at 1e-3.
    let sparse = dir.path().join("sparse");
    fewview_ok(&[
        "surface",
        "--synthetic",
        "--densify",
        "off",
        "--iterations",
        "1",
        "--mesh-resolution",
        "32",
        "--eval-views",
        "0",
        "--out",
        s(&sparse),
    ]);
    let sparse = self::metrics(&sparse);
    assert!(sparse["densified_because"].is_null());
    assert!(
        sparse["warmup"]["skipped"].is_string(),
        "{}",
        sparse["warmup"]
    );
    assert_eq!(sparse["pose_timing_fell_back"], true);
    assert_eq!(sparse["pose_timing"]["start"], 0.0);
    assert_eq!(
        sparse["pose_timing"]["lr"]["start"].as_f64().unwrap() as f32,
        1e-3
    );
    // One iteration from 13° of noise forms no surface near the truth: the run still writes
    // its metrics and says why the observed part was not scored.
    let why = sparse["chamfer_error"].as_str().unwrap_or_default();
    assert!(why.contains("observed part"), "{why:?}");

    // Neither a dataset nor the analytic scene; both.
    assert_clean_error(&fewview(&["surface", "--iterations", "1"]), &["--data"]);
    assert_clean_error(
        &fewview(&["surface", "--synthetic", "--data", s(dir.path())]),
        &["--synthetic", "--data"],
    );
    // The matcher's images must be the training images at an integer multiple of their size.
    assert_clean_error(
        &fewview(&[
            "surface",
            "--data",
            s(dir.path()),
            "--downscale",
            "2",
            "--match-downscale",
            "3",
        ]),
        &["--match-downscale 3", "--downscale 2"],
    );
    assert_clean_error(
        &fewview(&["surface", "--synthetic", "--match-refine", "lk"]),
        &["--match-refine", "'lk'"],
    );
    // The default run refined its matches, and says so in its configuration.
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("config.json")).unwrap()).unwrap();
    assert_eq!(config["match_refinement"]["half_window"], 10, "{config}");
}

/// `surface` flags that used to be checked only after matching (leaving config.json,
/// matches.json and more in the run folder), or never (a huge mesh resolution ran for ever),
/// are refused while parsing or before the run folder is created.
#[test]
fn surface_refuses_bad_numbers_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let surface = |flags: &[&str]| {
        let mut args = vec!["surface", "--synthetic", "--out", s(&run)];
        args.extend_from_slice(flags);
        fewview(&args)
    };
    for (flag, value) in [
        ("--mesh-resolution", "100000"),
        ("--mesh-resolution", "0"),
        ("--mesh-resolution", "1"),
        ("--pose-noise", "NaN"),
        ("--pose-noise", "-1"),
        ("--pose-noise", "1e300"),
        ("--lambda", "mc=NaN"),
        ("--lambda", "u=-1"),
        ("--lambda", "gc=inf"),
        ("--lambda", "geo=1e300"),
        ("--lambda", "psdf=NaN"),
        ("--eval-scale", "0"),
    ] {
        let out = surface(&[&format!("{flag}={value}")]);
        assert_clean_error(&out, &[flag, value]);
        assert!(!run.exists(), "{flag} {value}: nothing written");
    }
    // Larger than the scored test views: checked once the views are known.
    let out = surface(&["--eval-scale", "100000", "--eval-views", "1"]);
    assert_clean_error(&out, &["--eval-scale 100000", "320×240"]);
    assert!(!run.exists(), "nothing written");
}

/// An `--init` the dataset cannot serve used to fail after the run folder was created.
#[test]
fn train_refuses_an_unusable_init_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    let data = write_llff(&dir.path().join("scene"), |_, _| {});
    let run = dir.path().join("run");
    let corrupt = dir.path().join("corrupt.ply");
    std::fs::write(&corrupt, b"not a ply at all").unwrap();
    let missing = dir.path().join("missing.ply");
    let inits = [
        (format!("ply:{}", missing.display()), "missing.ply"),
        (format!("ply:{}", corrupt.display()), "corrupt.ply"),
        ("points".to_string(), "no sparse points"),
        ("box:1e300".to_string(), "half-size"),
    ];
    for (init, needle) in &inits {
        let out = fewview(&[
            "train",
            "--data",
            s(&data),
            "--iterations",
            "2",
            "--init",
            init,
            "--out",
            s(&run),
        ]);
        assert_clean_error(&out, &[needle]);
        assert!(!run.exists(), "--init {init}: nothing written");
    }
}

/// `render` checks its outputs before rendering: a path video in a missing folder used to be
/// found only after every view was rendered and written, a GIF frame rate over 50 fps after
/// the folder was created, and `--views none` without `--path` created an empty folder.
#[test]
fn render_checks_its_outputs_before_rendering() {
    let dir = tempfile::tempdir().unwrap();
    let data = write_llff(&dir.path().join("scene"), |_, _| {});
    let mut model = fewview_splat::model::GaussianModel::new(0);
    model.push_isotropic([0.0, 0.0, -4.0], 0.3, [0.5; 3], 0.9);
    let ply = dir.path().join("m.ply");
    fewview_splat::ply::write_ply(&ply, &model).unwrap();
    let renders = dir.path().join("renders");
    let render = |extra: &[&str]| {
        let mut args = vec![
            "render",
            "--ply",
            s(&ply),
            "--data",
            s(&data),
            "--out",
            s(&renders),
            "--frames-per-segment",
            "2",
        ];
        args.extend_from_slice(extra);
        fewview(&args)
    };
    let nodir = dir.path().join("nodir");
    let gif = nodir.join("p.gif");
    assert_clean_error(
        &render(&["--path", s(&gif)]),
        &["--path", "nodir/p.gif", "does not exist"],
    );
    let gif = dir.path().join("p.gif");
    assert_clean_error(
        &render(&["--views", "none", "--path", s(&gif), "--fps", "1000000"]),
        &["--fps 1000000", "GIF"],
    );
    let mp4 = dir.path().join("p.mp4");
    assert_clean_error(
        &render(&["--path", s(&mp4), "--fps", "1e7"]),
        &["--fps 10000000", "MP4", "timescale"],
    );
    assert_clean_error(
        &render(&["--views", "none"]),
        &["--views none", "nothing to render"],
    );
    // A file where the output folder goes.
    let file = dir.path().join("file");
    std::fs::write(&file, b"x").unwrap();
    let out = fewview(&[
        "render",
        "--ply",
        s(&ply),
        "--data",
        s(&data),
        "--out",
        s(&file.join("renders")),
    ]);
    assert_clean_error(&out, &["--out", "is not a folder"]);
    assert!(
        !renders.exists() && !gif.exists() && !mp4.exists() && !nodir.exists(),
        "nothing written"
    );
    // `--views none` with a path writes the path only.
    let out = render(&["--views", "none", "--path", s(&gif)]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(gif.exists() && !renders.exists());
}

/// `eval --json` and `eval-video --json` in a missing folder used to print the whole report
/// and then fail on the write.
#[test]
fn eval_reports_in_a_missing_folder_are_refused_first() {
    let dir = tempfile::tempdir().unwrap();
    let data = write_llff(&dir.path().join("scene"), |_, _| {});
    let mut model = fewview_splat::model::GaussianModel::new(0);
    model.push_isotropic([0.0, 0.0, -4.0], 0.3, [0.5; 3], 0.9);
    let ply = dir.path().join("m.ply");
    fewview_splat::ply::write_ply(&ply, &model).unwrap();
    let json = dir.path().join("nodir/e.json");
    let out = fewview(&[
        "eval",
        "--ply",
        s(&ply),
        "--data",
        s(&data),
        "--json",
        s(&json),
    ]);
    assert_clean_error(&out, &["--json", "nodir/e.json", "does not exist"]);
    assert!(out.stdout.is_empty(), "report printed before failing");

    let frames: Vec<fewview_scene::Image> = (0..3)
        .map(|k| fewview_scene::Image::filled(16, 12, &[0.1 * k as f32, 0.5, 0.5]))
        .collect();
    let video = dir.path().join("frames");
    fewview_video::write_video(&video, &frames, 10.0, &Default::default()).unwrap();
    let out = fewview(&[
        "eval-video",
        "--lpips",
        "none",
        "--output",
        s(&video),
        "--ground-truth",
        s(&video),
        "--json",
        s(&json),
    ]);
    assert_clean_error(&out, &["--json", "nodir/e.json", "does not exist"]);
    assert!(out.stdout.is_empty(), "report printed before failing");
    assert!(!dir.path().join("nodir").exists(), "nothing written");
}
