//! `fewview demo`: the whole pipeline on a scene built in-process (no downloads).

use std::path::PathBuf;

use clap::Args as ClapArgs;
use fewview_fusion::FusionConfig;
use fewview_scene::photometric::training_gains;
use fewview_scene::synthetic::{DemoOptions, demo_dataset};

use super::fusion_outputs::{print_transition, train_with_progress, transition, write_gains};
use super::number_args::count_in;
use super::output_paths::check_folder;
use super::photo_args::{DemoSceneArgs, JitterArgs};
use super::train::{check_init, print_summary};
use super::train_args::TrainArgs;

/// Run the whole pipeline on a scene built in-process (no data needed).
///
/// Builds a small textured scene with view-dependent shading, ray-traces 24 ground-truth views
/// of it (an independent renderer), trains 3D Gaussians from 3 of them with the gradient-domain
/// fusion of "Splat-based Gradient-domain Fusion" (as `fusion --demo`), and reports PSNR/SSIM
/// on the other 21 and the transition's scores against the ray-traced truth along its path.
///
/// Writes `point_cloud.ply`, `renders/test/*.png`, `metrics.json`, `fusion.json`, the
/// ground-truth images (`ground_truth/`), the transition through the training views and back
/// (`transition.mp4`, 8 s at 20 fps) and its scores (`transition.json`).
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Run directory.
    #[arg(long, default_value = "runs/demo", value_name = "DIR")]
    pub out: PathBuf,
    /// Image width of the demo views (16 to 8192).
    ///
    /// Image width of the demo views (height is 3/4 of it), 16 to 8192.
    #[arg(long, default_value_t = 200, value_parser = demo_width)]
    pub width: usize,
    #[command(flatten)]
    pub train: TrainArgs,
    #[command(flatten)]
    pub jitter: JitterArgs,
    #[command(flatten)]
    pub scene: DemoSceneArgs,
    /// Continue the run in `--out` from its last checkpoint.
    #[arg(long)]
    pub resume: bool,
    /// Write the views as a photo capture instead.
    ///
    /// Instead of training, write the demo's views as a real capture into DIR: photos ray
    /// traced through a lens with `--capture-distortion`, a nerfstudio `transforms.json` and a
    /// COLMAP model in `sparse/0/` (train on it with `fewview train --data DIR`).
    #[arg(long, value_name = "DIR")]
    pub write_capture: Option<PathBuf>,
    /// The capture's lens: OpenCV `k1,k2,p1,p2`.
    ///
    /// Phone-like by default; `0,0,0,0` for a pinhole.
    #[arg(
        long,
        value_name = "LIST",
        default_value = "0.06,-0.08,0.001,0.001",
        value_delimiter = ','
    )]
    pub capture_distortion: Vec<f64>,
    /// The capture's `fx,fy,cx,cy,width,height`.
    ///
    /// The capture's intrinsics `fx,fy,cx,cy,width,height` instead of the demo's (e.g. the
    /// undistorted camera of a distorted capture, to render its exact pinhole truth).
    #[arg(long, value_name = "LIST", value_delimiter = ',')]
    pub capture_intrinsics: Option<Vec<f64>>,
}

/// `--write-capture`: the demo views as a capture with lens distortion.
fn write_capture(
    dir: &std::path::Path,
    opts: &DemoOptions,
    coeffs: &[f64],
    intrinsics: Option<&[f64]>,
) -> anyhow::Result<()> {
    if coeffs.len() != 4 {
        anyhow::bail!(
            "--capture-distortion takes 4 values k1,k2,p1,p2, got {}",
            coeffs.len()
        );
    }
    let distortion = fewview_scene::distortion::Distortion::opencv(coeffs);
    let intrinsics = match intrinsics {
        Some(&[fx, fy, cx, cy, w, h]) if w >= 1.0 && h >= 1.0 => Some(fewview_scene::Intrinsics {
            fx,
            fy,
            cx,
            cy,
            width: w as u32,
            height: h as u32,
        }),
        Some(_) => anyhow::bail!("--capture-intrinsics takes fx,fy,cx,cy,width,height"),
        None => None,
    };
    let summary =
        fewview_scene::demo_capture::write_demo_capture(dir, opts, Some(distortion), intrinsics)?;
    let lens = match &summary.lens.distortion {
        Some(d) => format!("the lens ({d})"),
        None => "a pinhole".to_string(),
    };
    println!(
        "wrote {} views through {lens} to {} (the demo trains on views {:?})",
        summary.views,
        dir.display(),
        summary.train
    );
    Ok(())
}

/// The narrowest demo view: the SSIM window and the scene's textures need a few pixels.
const MIN_DEMO_WIDTH: usize = 16;

/// The widest demo view. Every one of the 24 ground-truth views is ray traced and kept in memory
/// as `f32` RGB, with a training copy: 8192 × 6144 is already about 14 GB and hours of ray
/// tracing, while `--width 100000000` aborted on allocation and 4294967295 overflowed the
/// buffer's size. (The demo is a smoke test; its default is 200.)
const MAX_DEMO_WIDTH: usize = 8192;

fn demo_width(s: &str) -> Result<usize, String> {
    count_in(s, MIN_DEMO_WIDTH, MAX_DEMO_WIDTH)
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let opts = args.scene.apply(DemoOptions {
        width: args.width,
        height: args.width * 3 / 4,
        jitter: args.jitter.jitter(),
        ..DemoOptions::default()
    })?;
    if let Some(dir) = &args.write_capture {
        return write_capture(
            dir,
            &opts,
            &args.capture_distortion,
            args.capture_intrinsics.as_deref(),
        );
    }
    eprintln!(
        "ray tracing {} ground-truth views at {}x{} ...",
        opts.views, opts.width, opts.height
    );
    check_folder(&args.out, "--out")?;
    let ds = demo_dataset(&opts);
    // Checked before anything is written.
    let cfg = args
        .train
        .transition_run_config(ds.background, 2000, false)?;
    check_init(&ds, &cfg, &args.train.init, args.resume)?;
    let gt = args.out.join("ground_truth");
    std::fs::create_dir_all(&gt)?;
    for v in &ds.views {
        v.image.save_png(&gt.join(format!("{}.png", v.name)))?;
    }
    eprintln!(
        "training from views {:?}, holding out {} views",
        ds.train,
        ds.test.len()
    );
    let fusion = FusionConfig::default();
    let summary = train_with_progress(&ds, &cfg, &fusion, &args.out, args.resume)?;
    write_gains(&args.out, &training_gains(&ds, &opts.jitter))?;
    let report = transition(&ds, Some(&opts), &args.out, true)?;
    print_summary(&summary, &args.out);
    print_transition(&report);
    println!(
        "transition       {}",
        args.out.join("transition.mp4").display()
    );
    Ok(())
}
