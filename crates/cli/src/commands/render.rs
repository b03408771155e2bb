//! `fewview render`: images of a trained model at dataset cameras, and a smooth camera path.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::{Args as ClapArgs, ValueEnum};
use fewview_splat::eval::render_model;
use fewview_splat::pipeline::render_path;
use fewview_splat::ply::read_ply;
use fewview_splat::raster::{RenderCamera, RenderSettings};
use fewview_video::{Container, MAX_GIF_FPS, MAX_MP4_FPS, VideoOptions, write_video};

use super::dataset_args::DatasetArgs;
use super::number_args::positive_f32;
use super::output_paths::{check_file, check_folder};
use super::progress;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Which {
    /// The held-out views.
    Test,
    /// The training views.
    Train,
    /// Every view of the dataset.
    All,
    /// No dataset views (only the camera path).
    None,
}

/// Render a trained model at dataset cameras and along a camera path.
///
/// Renders a trained model (Inria PLY) at a dataset's cameras to PNG, and optionally along a smooth
/// camera path through the training views (rotations by SLERP, centres linearly) to a video.
#[derive(Debug, ClapArgs)]
#[command(mut_arg("data", |a| a.required(false).required_unless_present("cameras")))]
pub struct Args {
    /// Trained Gaussians (Inria PLY layout).
    #[arg(long, value_name = "FILE")]
    pub ply: PathBuf,
    #[command(flatten)]
    pub dataset: DatasetArgs,
    /// Render at the cameras of this file instead.
    ///
    /// Instead of a dataset's: a run's `cameras.json` (its training cameras, then the held-out
    /// ones) or any camera file `pose-error` reads. Writes `camera_000.png`, `camera_001.png`, ...
    /// in the file's order.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["data", "views", "path"])]
    pub cameras: Option<PathBuf>,
    /// Background `R,G,B` with `--cameras`.
    ///
    /// The background with `--cameras` (a dataset brings its own): `R,G,B` in [0, 1], as the
    /// run's `config.json` has it.
    #[arg(long, value_name = "R,G,B", requires = "cameras", value_parser = parse_rgb)]
    pub background: Option<[f32; 3]>,
    /// Which dataset views to render.
    #[arg(long, value_enum, default_value_t = Which::Test)]
    pub views: Which,
    /// Output folder of the PNGs.
    ///
    /// Output folder for the PNGs (`<name>.png`, and `<name>_depth.png` with `--depth`); not
    /// created with `--views none`.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Also write the expected depth.
    ///
    /// Also write expected depth, normalised by alpha and scaled to the frame's range.
    #[arg(long)]
    pub depth: bool,
    /// Render a camera path (.mp4, .gif or frames).
    ///
    /// Render a camera path through the training views to this file: `.mp4` (H.264), `.gif`, or
    /// a folder of PNG frames (no extension).
    #[arg(long, value_name = "FILE")]
    pub path: Option<PathBuf>,
    /// Frames between consecutive training views on the path.
    #[arg(long, value_name = "N", default_value_t = 30)]
    pub frames_per_segment: usize,
    /// Frame rate of the path video (a GIF plays at most 50).
    #[arg(long, default_value_t = 30.0, value_parser = positive_f32)]
    pub fps: f32,
}

/// The most frames a camera path may have: they are all held in memory until the video is
/// written (about 2 MB each at LLFF's 1/8 resolution), and 10 000 frames last over 5 minutes at
/// 30 fps. A larger count is refused before anything is rendered.
const MAX_PATH_FRAMES: usize = 10_000;

fn parse_rgb(s: &str) -> Result<[f32; 3], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| {
            x.trim()
                .parse::<f32>()
                .map_err(|_| format!("`{x}` is not a number"))
        })
        .collect::<Result<_, _>>()?;
    match v.as_slice() {
        [r, g, b] if v.iter().all(|x| (0.0..=1.0).contains(x)) => Ok([*r, *g, *b]),
        _ => Err("give three numbers in [0, 1], e.g. 0,0,0".into()),
    }
}

/// `--cameras`: every camera of the file, with the given background.
fn render_cameras(args: &Args, file: &std::path::Path) -> anyhow::Result<()> {
    check_folder(&args.out, "--out")?;
    let cameras = fewview_geom::io::cameras::read_cameras(file)?;
    let model = read_ply(&args.ply).context("cannot read the model")?;
    let settings = RenderSettings {
        background: args.background.unwrap_or([0.0; 3]),
        sh_degree: model.sh_degree(),
        ..RenderSettings::default()
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let bar = progress::iterations(cameras.len() as u64, "render");
    for (i, c) in cameras.iter().enumerate() {
        let r = render_model(&model, &RenderCamera::from(c), &settings);
        r.rgb
            .save_png(&args.out.join(format!("camera_{i:03}.png")))?;
        if args.depth {
            r.normalized_depth()
                .scaled_to_unit_max()
                .save_png(&args.out.join(format!("camera_{i:03}_depth.png")))?;
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    println!(
        "rendered {} cameras to {}",
        cameras.len(),
        args.out.display()
    );
    Ok(())
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(file) = &args.cameras {
        return render_cameras(&args, file);
    }
    // The outputs and the path's flags are checked before any work: a bad container, frame
    // count, frame rate or output folder used to be found only after every view was rendered
    // and written (or never, for a huge count).
    if args.views == Which::None && args.path.is_none() {
        bail!("--views none without --path: nothing to render");
    }
    if args.views != Which::None {
        check_folder(&args.out, "--out")?;
    }
    if let Some(path) = &args.path {
        let container = Container::for_path(path)?;
        match container {
            Container::FrameFolder => check_folder(path, "--path")?,
            Container::Gif | Container::Mp4 => check_file(path, "--path")?,
        }
        if container == Container::Gif && args.fps > MAX_GIF_FPS {
            bail!(
                "--fps {}: a GIF plays at most {MAX_GIF_FPS} fps (browsers cap its frame delay \
                 at 2 cs); write an .mp4 or lower --fps",
                args.fps
            );
        }
        if container == Container::Mp4 && args.fps > MAX_MP4_FPS {
            bail!(
                "--fps {}: an MP4 records at most {MAX_MP4_FPS} fps (its track timescale is 32-bit)",
                args.fps
            );
        }
        if args.frames_per_segment == 0 {
            bail!("--frames-per-segment must be at least 1");
        }
        if args.frames_per_segment >= MAX_PATH_FRAMES {
            bail!(
                "--frames-per-segment {}: a camera path has at most {MAX_PATH_FRAMES} frames",
                args.frames_per_segment
            );
        }
    }
    let model = read_ply(&args.ply).context("cannot read the model")?;
    let ds = args.dataset.load()?;
    let keys: Vec<_> = ds.train_views().map(|v| v.camera.clone()).collect();
    if args.path.is_some() {
        if keys.len() < 2 {
            bail!(
                "a camera path needs at least 2 training views, the split has {}",
                keys.len()
            );
        }
        let frames = args.frames_per_segment * (keys.len() - 1) + 1;
        if frames > MAX_PATH_FRAMES {
            bail!(
                "--frames-per-segment {}: {} training views give a {frames}-frame camera path, \
                 more than the {MAX_PATH_FRAMES} allowed",
                args.frames_per_segment,
                keys.len()
            );
        }
    }
    let settings = RenderSettings {
        background: ds.background,
        sh_degree: model.sh_degree(),
        ..RenderSettings::default()
    };
    let indices: Vec<usize> = match args.views {
        Which::Test => ds.test.clone(),
        Which::Train => ds.train.clone(),
        Which::All => (0..ds.views.len()).collect(),
        Which::None => vec![],
    };
    if indices.is_empty() && args.path.is_none() {
        bail!(
            "--views {}: the split has no such views and there is no --path: nothing to render",
            format!("{:?}", args.views).to_lowercase()
        );
    }
    if !indices.is_empty() {
        std::fs::create_dir_all(&args.out)
            .with_context(|| format!("cannot create {}", args.out.display()))?;
    }
    let bar = progress::iterations(indices.len() as u64, "render");
    for &i in &indices {
        let v = &ds.views[i];
        let r = render_model(&model, &RenderCamera::from(&v.camera), &settings);
        r.rgb.save_png(&args.out.join(format!("{}.png", v.name)))?;
        if args.depth {
            r.normalized_depth()
                .scaled_to_unit_max()
                .save_png(&args.out.join(format!("{}_depth.png", v.name)))?;
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    if !indices.is_empty() {
        println!("rendered {} views to {}", indices.len(), args.out.display());
    }
    if let Some(path) = &args.path {
        let frames = render_path(&model, &keys, args.frames_per_segment, &settings);
        write_video(path, &frames, args.fps, &VideoOptions::default())?;
        println!(
            "wrote a {}-frame camera path to {}",
            frames.len(),
            path.display()
        );
    }
    Ok(())
}
