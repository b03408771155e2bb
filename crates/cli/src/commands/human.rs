//! `fewview human`: pose-guided feed-forward Gaussians of moving people (the PoseGaussian paper).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use clap::{Args as ClapArgs, Subcommand, ValueEnum};
use fewview_human::depth::DepthInput;
use fewview_human::net::Variant;
use fewview_human::tps::TpsConfig;
use fewview_human::train::{Preset, TrainConfig, Trainer};
use fewview_human::{MultiView, Split, TrainingView};

use super::progress;

/// Pose-guided Gaussians of moving people from synchronized multi-view video (PoseGaussian:
/// Pose-Driven Novel View Synthesis for Robust 3D Human Reconstruction).
///
/// `train` fits the network on the input cameras of the training frames (the split of
/// PoseGaussian's protocol: on `seq_a`, cameras 2, 5, 8, 11 and frames 40–59 are never read);
/// `render` draws any camera of the rig, or a path circling it, from the input cameras of each
/// frame; `eval` scores the held-out cameras against the baselines; `depth` compares the input
/// depths (hull, per-frame stereo, the capture's) and how much each flickers.
#[derive(Debug, ClapArgs)]
pub struct Args {
    #[command(subcommand)]
    pub command: HumanCommand,
}

#[derive(Debug, Subcommand)]
pub enum HumanCommand {
    Train(TrainArgs),
    Render(RenderArgs),
    Eval(EvalArgs),
    Depth(DepthArgs),
}

/// The depth the network reads (`fewview_human::depth::DepthInput`).
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum DepthArg {
    /// Two-view stereo per frame with the nearest input camera, searched over the visual
    /// hull's depth range, the hull where it does not match (the paper's setting: per-frame
    /// depth that flickers).
    Stereo,
    /// The visual hull of the input masks (smooth over time).
    Hull,
    /// The capture's own depth maps (an oracle; the synthetic capture has them).
    Dataset,
}

impl From<DepthArg> for DepthInput {
    fn from(d: DepthArg) -> Self {
        match d {
            DepthArg::Stereo => DepthInput::Stereo,
            DepthArg::Hull => DepthInput::Hull,
            DepthArg::Dataset => DepthInput::Dataset,
        }
    }
}

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum PresetArg {
    /// 128×256 crops around the person, widths 16/32/48/64 (two CPU cores).
    Cpu,
    /// 512×512 inputs, widths 32/64/96/128 (the paper's; for a GPU).
    Paper,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum SplatInitArg {
    /// `fewview train`'s own start on the frame's input views.
    Train,
    /// Points inside the frame's visual hull.
    Hull,
}

/// The capture, its sequence and the output folder, shared by the subcommands.
#[derive(Debug, ClapArgs)]
pub struct CaptureArgs {
    /// The capture's folder: the synthetic layout (`cameras.json`, `joints.json`, `SEQ/`) or
    /// ZJU-MoCap's (`annots.npy`, `Camera_B*/`, `mask/`, here or in `SEQ/`; 2D pose from
    /// `joints3d/<n>.npy`).
    #[arg(long, value_name = "DIR")]
    pub data: PathBuf,
    /// The sequence inside `--data` (ignored when `--data` itself holds `annots.npy`).
    #[arg(long, default_value = "seq_a")]
    pub sequence: String,
    /// Output folder.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

/// Train the network; writes checkpoints (`network.fvh`, `optimizer.bin`, `state.bin`) and
/// `train_log.jsonl` to `--out`.
#[derive(Debug, ClapArgs)]
pub struct TrainArgs {
    #[command(flatten)]
    pub capture: CaptureArgs,
    /// Network widths and input size.
    #[arg(long, value_enum, default_value = "cpu")]
    pub preset: PresetArg,
    /// Network configuration of the paper's appendix (1 simplified, 2 deep residual,
    /// 3 with batch norm, 4 without downsampling).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u8).range(1..=4))]
    pub variant: u8,
    /// Training steps, one target view of one frame each.
    #[arg(long, default_value_t = 2000)]
    pub iterations: usize,
    /// Adam's step size.
    #[arg(long, default_value_t = 2e-4)]
    pub lr: f64,
    /// Seeds the initial weights and the order of the targets.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Source views per target.
    #[arg(long, default_value_t = 2)]
    pub source_views: usize,
    /// Feed the pose encoder zeros (the per-frame baseline of PoseGaussian's comparison).
    #[arg(long)]
    pub no_pose: bool,
    /// The depth the network reads and refines.
    #[arg(long, value_enum, default_value = "stereo")]
    pub depth: DepthArg,
    /// Write a checkpoint every N iterations (and at the end).
    #[arg(long, default_value_t = 100)]
    pub checkpoint_every: usize,
    /// Continue the run in `--out` from its checkpoint (same settings; `--iterations` may grow).
    #[arg(long)]
    pub resume: bool,
    /// Input cameras, spread uniformly over the rig (PoseGaussian's protocol: 8; the others are
    /// held out for evaluation).
    #[arg(long, default_value_t = fewview_human::split::PAPER_INPUT_CAMERAS)]
    pub input_cameras: usize,
    /// Training frames, from the first (default: two thirds of the sequence; the rest test
    /// novel poses).
    #[arg(long, value_name = "N")]
    pub train_frames: Option<usize>,
    /// Stop after this many minutes of wall time (hull carving included) with a checkpoint, even
    /// before `--iterations`: a training budget; `--resume` continues later.
    #[arg(long, value_name = "MINUTES")]
    pub max_minutes: Option<f64>,
    /// Where to train: `cpu` (every build) or `gpu` (the network's convolutions and the splat
    /// rasterizer on the first GPU wgpu finds; builds with `--features gpu`).
    #[arg(long, value_enum, default_value_t = super::train_args::DeviceArg::Cpu)]
    pub device: super::train_args::DeviceArg,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        HumanCommand::Train(a) => train(a),
        HumanCommand::Render(a) => render(a),
        HumanCommand::Eval(a) => eval(a),
        HumanCommand::Depth(a) => depth(a),
    }
}

fn preset(arg: PresetArg) -> Preset {
    match arg {
        PresetArg::Cpu => Preset::Cpu,
        PresetArg::Paper => Preset::Paper,
    }
}

fn config(args: &TrainArgs) -> anyhow::Result<TrainConfig> {
    Ok(TrainConfig {
        preset: preset(args.preset),
        variant: Variant::from_number(args.variant)?,
        iterations: args.iterations,
        learning_rate: args.lr,
        seed: args.seed,
        source_views: args.source_views,
        use_pose: !args.no_pose,
        depth: args.depth.into(),
        bracket: DepthInput::from(args.depth).bracket(),
        ..TrainConfig::default()
    })
}

fn train(args: TrainArgs) -> anyhow::Result<()> {
    let config = config(&args)?;
    let (_, capture) = fewview_human::capture::open(&args.capture.data, &args.capture.sequence)?;
    let split = Split::for_capture(&*capture, args.input_cameras, args.train_frames)?;
    let view = TrainingView::new(&*capture, &split)?;
    let device = fewview_splat::ComputeDevice::from(args.device)
        .open()?
        .autodiff();
    let frames = split.train_frames.clone();
    let out = &args.capture.out;
    let started = Instant::now();
    let mut trainer = if args.resume {
        if Split::load(out)?.is_some_and(|s| s != split) {
            bail!(
                "{}: the run was trained on another split (see split.json); give the same --input-cameras and --train-frames",
                out.display()
            );
        }
        Trainer::resume(&view, frames, out, config.clone(), device)?
    } else {
        if out.join("state.bin").exists() {
            bail!(
                "{}: holds a run already (pass --resume to continue it)",
                out.display()
            );
        }
        let parents = capture.joint_parents()?;
        eprintln!(
            "carving the visual hulls of {} training frames…",
            split.train_frames.len()
        );
        Trainer::new(&view, frames, &parents, config.clone(), device)?
    };
    let f = trainer.framing();
    eprintln!(
        "human train on {} ({} input cameras, frames {:?}) → {}: crops {}×{} at scale {:.3}, depth {:.2}–{:.2} m",
        args.capture.data.display(),
        split.input_cameras.len(),
        split.train_frames,
        out.display(),
        f.size[0],
        f.size[1],
        f.scale,
        f.near,
        f.far
    );
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    split.save(out)?;
    let log_path = out.join("train_log.jsonl");
    let mut log = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&log_path)
        .with_context(|| format!("{}: cannot open", log_path.display()))?;
    let bar = progress::iterations(config.iterations as u64, "human train");
    bar.set_position(trainer.iteration() as u64);
    let budget = args
        .max_minutes
        .map(|m| std::time::Duration::from_secs_f64(m.max(0.0) * 60.0));
    let within_budget = || budget.is_none_or(|b| started.elapsed() < b);
    while trainer.iteration() < config.iterations && within_budget() {
        let stats = trainer.step()?;
        writeln!(log, "{}", serde_json::to_string(&stats)?)?;
        bar.set_position(stats.iteration as u64);
        bar.set_message(format!("loss {:.4}", stats.loss.total));
        let every = args.checkpoint_every.max(1);
        if stats.iteration % every == 0 || stats.iteration == config.iterations {
            trainer.save(out)?;
        }
    }
    bar.finish_and_clear();
    trainer.save(out)?;
    eprintln!(
        "trained {} iterations in {:.0} s; checkpoint in {}",
        trainer.iteration(),
        started.elapsed().as_secs_f64(),
        out.display()
    );
    Ok(())
}

/// Render a trained run from the input cameras of every frame: each `--cameras` camera (or a
/// path circling the rig with `--orbit`) as `OUT/<camera>/frame_NNNN.png` and `OUT/<camera>.mp4`.
#[derive(Debug, ClapArgs)]
pub struct RenderArgs {
    /// The run folder `human train` wrote.
    #[arg(long, value_name = "DIR")]
    pub run: PathBuf,
    #[command(flatten)]
    pub capture: CaptureArgs,
    /// Cameras of the capture to render, e.g. `2,5` (default: the run's held-out cameras).
    #[arg(long, value_delimiter = ',', conflicts_with = "orbit")]
    pub cameras: Vec<usize>,
    /// Render one camera circling the rig once over the frames instead (`OUT/orbit.mp4`).
    #[arg(long)]
    pub orbit: bool,
    /// First and last frame (inclusive), e.g. `40..=59`; default every frame.
    #[arg(long, value_name = "A..=B")]
    pub frames: Option<String>,
    /// Switch the Temporal Pose Stabilizer off.
    #[arg(long)]
    pub no_tps: bool,
    #[command(flatten)]
    pub tps: TpsArgs,
    /// Source views per target (default: what the run was trained with).
    #[arg(long)]
    pub source_views: Option<usize>,
    /// Frames per second of the videos.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f32,
}

fn render(args: RenderArgs) -> anyhow::Result<()> {
    use fewview_human::infer::SequenceRenderer;
    let model = load_model(&args.run, args.source_views)?;
    let (_, capture) = fewview_human::capture::open(&args.capture.data, &args.capture.sequence)?;
    let split = run_split(&args.run, &*capture)?;
    let frames = match &args.frames {
        Some(t) => parse_frames(t)?,
        None => split.all_frames(),
    };
    if frames.end > capture.frame_count() {
        bail!(
            "--frames {:?}: {} has {} frames",
            frames,
            capture.root().display(),
            capture.frame_count()
        );
    }
    let rig = capture.cameras();
    let chosen = if args.cameras.is_empty() {
        split.held_out_cameras.clone()
    } else {
        args.cameras.clone()
    };
    if let Some(c) = chosen.iter().find(|&&c| c >= rig.len()) {
        bail!(
            "--cameras: camera {c} does not exist ({} has {} cameras)",
            capture.root().display(),
            rig.len()
        );
    }
    // Per output: its name and one camera per frame.
    let outputs: Vec<(String, Vec<fewview_scene::Camera>)> = if args.orbit {
        let path = fewview_human::orbit::orbit_cameras(rig, frames.len());
        vec![("orbit".to_string(), path)]
    } else {
        chosen
            .iter()
            .map(|&c| {
                (
                    capture.camera_names()[c].clone(),
                    vec![rig[c].clone(); frames.len()],
                )
            })
            .collect()
    };
    let tps = if args.no_tps {
        None
    } else {
        Some(args.tps.config()?)
    };
    let mut renderer = SequenceRenderer::new(&model, &*capture, &split, tps);
    let out = &args.capture.out;
    for (name, _) in &outputs {
        let dir = out.join(name);
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("{}: cannot create", dir.display()))?;
    }
    let bar = progress::iterations(frames.len() as u64, "human render");
    let mut videos: Vec<Vec<fewview_scene::Image>> = vec![Vec::new(); outputs.len()];
    for (t, frame) in frames.clone().enumerate() {
        let cameras: Vec<_> = outputs.iter().map(|(_, path)| path[t].clone()).collect();
        let r = renderer.render_frame(frame, &cameras)?;
        let images = r.stabilized.unwrap_or(r.plain);
        for (k, image) in images.into_iter().enumerate() {
            let path = out
                .join(&outputs[k].0)
                .join(format!("frame_{frame:04}.png"));
            image.save_png(&path)?;
            videos[k].push(image);
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let opts = fewview_video::VideoOptions::default();
    for ((name, _), video) in outputs.iter().zip(&videos) {
        let path = out.join(format!("{name}.mp4"));
        fewview_video::write_video(&path, video, args.fps, &opts)?;
    }
    eprintln!(
        "rendered {} view(s) × {} frames of {} into {}",
        outputs.len(),
        frames.len(),
        args.run.display(),
        out.display()
    );
    Ok(())
}

/// Score a trained run on the held-out cameras (PSNR/SSIM/LPIPS and the temporal Δ-metrics),
/// with and without the Temporal Pose Stabilizer, beside baseline runs; writes `metrics.json`,
/// `table.md` and `side_by_side.mp4` (truth | ours | each baseline, first held-out camera).
#[derive(Debug, ClapArgs)]
pub struct EvalArgs {
    /// The run folder `human train` wrote.
    #[arg(long, value_name = "DIR")]
    pub run: PathBuf,
    #[command(flatten)]
    pub capture: CaptureArgs,
    /// A run trained with `--no-pose`: the per-frame baseline.
    #[arg(long, value_name = "DIR")]
    pub per_frame: Option<PathBuf>,
    /// Another trained run scored beside ours without TPS, as `NAME=DIR` (repeatable), e.g.
    /// `hull=runs/ours-hull` for the same method with the visual hull's depth.
    #[arg(long, value_name = "NAME=DIR")]
    pub baseline: Vec<String>,
    /// First and last frame (inclusive), e.g. `0..=59`; default every frame.
    #[arg(long, value_name = "A..=B")]
    pub frames: Option<String>,
    /// Skip LPIPS (and its Δ).
    #[arg(long)]
    pub no_lpips: bool,
    /// Train the 3DGS-per-frame baseline on this many consecutive frames from the first test
    /// frame (0: none; each takes minutes) and add a table of every method on them.
    #[arg(long, default_value_t = 0)]
    pub splat_frames: usize,
    /// Training iterations of each 3DGS-per-frame model.
    #[arg(long, default_value_t = 3000)]
    pub splat_iterations: usize,
    /// Where each 3DGS-per-frame model starts: `train` (what `fewview train` does on those
    /// views: the stereo start, else random points) or `hull` (points in the frame's visual
    /// hull, a prior plain 3DGS lacks; stronger).
    #[arg(long, value_enum, default_value = "train")]
    pub splat_init: SplatInitArg,
    #[command(flatten)]
    pub tps: TpsArgs,
    /// Score the input cameras on the training frames instead, each predicted from its
    /// neighbours as in training (validation: choose `--tps-weight`/`--tps-speed` here without
    /// reading a held-out camera or a test frame).
    #[arg(long, conflicts_with = "splat_frames")]
    pub validation: bool,
    /// Source views per target at inference, for the run and its baselines (default: what each
    /// was trained with). The network sees one view at a time, so more views only add
    /// Gaussians where the two nearest views miss the person.
    #[arg(long)]
    pub source_views: Option<usize>,
}

/// The Temporal Pose Stabilizer's settings (our design; see `fewview_human::tps`).
#[derive(Debug, ClapArgs)]
pub struct TpsArgs {
    /// Weight of the previous frame's (warped) maps where the body is still, in [0, 1].
    #[arg(long, default_value_t = TpsConfig::default().max_weight)]
    pub tps_weight: f32,
    /// Joint speed (metres per frame) at which that weight falls to 1/e of itself.
    #[arg(long, default_value_t = TpsConfig::default().speed_scale)]
    pub tps_speed: f32,
}

impl TpsArgs {
    fn config(&self) -> anyhow::Result<TpsConfig> {
        let config = TpsConfig {
            max_weight: self.tps_weight,
            speed_scale: self.tps_speed,
            ..TpsConfig::default()
        };
        config.check()?;
        Ok(config)
    }
}

/// The run in `dir`, rendering from `source_views` views per target when given.
fn load_model(
    dir: &std::path::Path,
    source_views: Option<usize>,
) -> anyhow::Result<fewview_human::infer::Model> {
    let mut model = fewview_human::infer::Model::load(dir)?;
    if let Some(n) = source_views {
        if n == 0 {
            bail!("--source-views must be at least 1");
        }
        model.config.source_views = n;
    }
    Ok(model)
}

/// The split `run` was trained with, or PoseGaussian's default protocol for runs without
/// `split.json`.
fn run_split(run: &std::path::Path, capture: &dyn MultiView) -> anyhow::Result<Split> {
    let split = match Split::load(run)? {
        Some(split) => split,
        None => Split::for_capture(capture, fewview_human::split::PAPER_INPUT_CAMERAS, None)?,
    };
    split.check_fits(capture)?;
    Ok(split)
}

fn parse_frames(text: &str) -> anyhow::Result<std::ops::Range<usize>> {
    let (a, b) = text
        .split_once("..=")
        .with_context(|| format!("--frames {text}: expected A..=B"))?;
    let (a, b): (usize, usize) = (a.trim().parse()?, b.trim().parse()?);
    if b <= a {
        bail!("--frames {text}: needs at least two frames");
    }
    Ok(a..b + 1)
}

fn eval(args: EvalArgs) -> anyhow::Result<()> {
    use fewview_human::eval::{EvalOptions, evaluate};
    use fewview_human::eval_outputs::{self, TableContext};
    use fewview_human::infer::Model;
    let model = load_model(&args.run, args.source_views)?;
    let mut compared: Vec<(String, Model)> = Vec::new();
    if let Some(run) = &args.per_frame {
        compared.push(("per-frame".to_string(), load_model(run, args.source_views)?));
    }
    for text in &args.baseline {
        let (name, run) = text
            .split_once('=')
            .with_context(|| format!("--baseline {text}: expected NAME=DIR"))?;
        let name = name.trim();
        if name.is_empty() || compared.iter().any(|(n, _)| n == name) || name.starts_with("ours") {
            bail!("--baseline {text}: give each baseline its own name (not `ours`)");
        }
        compared.push((
            name.to_string(),
            load_model(Path::new(run), args.source_views)?,
        ));
    }
    let (_, dataset) = fewview_human::capture::open(&args.capture.data, &args.capture.sequence)?;
    let split = run_split(&args.run, &*dataset)?;
    let frames = match &args.frames {
        Some(t) => parse_frames(t)?,
        None if args.validation => split.train_frames.clone(),
        None => split.all_frames(),
    };
    if args.validation
        && (frames.start < split.train_frames.start || frames.end > split.train_frames.end)
    {
        bail!(
            "--validation scores training frames only ({}..={}), not --frames {}..={}",
            split.train_frames.start,
            split.train_frames.end - 1,
            frames.start,
            frames.end - 1
        );
    }
    let cameras = if args.validation {
        split.input_cameras.clone()
    } else {
        split.held_out_cameras.clone()
    };
    std::fs::create_dir_all(&args.capture.out)
        .with_context(|| format!("{}: cannot create", args.capture.out.display()))?;
    let lpips = if args.no_lpips {
        None
    } else {
        Some(fewview_metrics::lpips::Lpips::default_st_alex()?)
    };
    let baselines: Vec<(String, &Model)> = compared.iter().map(|(n, m)| (n.clone(), m)).collect();
    let options = EvalOptions {
        frames: frames.clone(),
        cameras,
        leave_target_out: args.validation,
        tps: Some(args.tps.config()?),
        splat: (args.splat_frames > 0).then(|| {
            let start = split.test_frames.start.max(frames.start);
            let end = (start + args.splat_frames).min(frames.end);
            let opts = fewview_human::baseline::SplatBaselineOptions {
                iterations: args.splat_iterations,
                init: match args.splat_init {
                    SplatInitArg::Train => fewview_human::baseline::BaselineInit::Train,
                    SplatInitArg::Hull => fewview_human::baseline::BaselineInit::Hull,
                },
                ..Default::default()
            };
            (start..end, opts)
        }),
    };
    let bar = progress::iterations((frames.len() + args.splat_frames) as u64, "human eval");
    let perceptual = lpips
        .as_ref()
        .map(|l| l as &dyn fewview_metrics::temporal::PerceptualDistance);
    let (report, renders, truths) = evaluate(
        &model,
        &baselines,
        &*dataset,
        &split,
        &options,
        perceptual,
        &mut |_| bar.inc(1),
    )?;
    bar.finish_and_clear();
    let context = TableContext {
        validation: args.validation,
        test_frames: split.test_frames.clone(),
        splat_frames: options.splat.as_ref().map(|(r, _)| r.clone()),
    };
    let md = eval_outputs::write(&args.capture.out, &report, &context, &renders, &truths)?;
    print!("{md}");
    let t = &report.times;
    eprintln!(
        "per frame: {:.3} s (hull and crops {:.3}, image encoder {:.3}, pose encoder {:.3}, depth encoder {:.3}, decoder and heads {:.3}, TPS {:.3}, rendering {:.3}); written to {}",
        t.total(),
        t.preparation,
        t.network.image_encoder,
        t.network.pose_encoder,
        t.network.depth_encoder,
        t.network.decoder_and_heads,
        t.tps,
        t.rendering,
        args.capture.out.display()
    );
    Ok(())
}

/// Compare the input depths of the input cameras over frames: writes `depth_report.json` (each
/// depth's flicker between frames, its flicker beyond the person's motion and its error against
/// the capture's depth) and `depth_strip.png` (one camera's frames: image, hull, stereo, truth).
#[derive(Debug, ClapArgs)]
pub struct DepthArgs {
    #[command(flatten)]
    pub capture: CaptureArgs,
    /// Frames `A..=B` (default: all).
    #[arg(long, value_name = "A..=B")]
    pub frames: Option<String>,
    /// The crops' size, as the network preset reads them.
    #[arg(long, value_enum, default_value = "cpu")]
    pub preset: PresetArg,
    /// Input cameras, spread uniformly over the rig (as `train`).
    #[arg(long, default_value_t = fewview_human::split::PAPER_INPUT_CAMERAS)]
    pub input_cameras: usize,
    /// The camera of `depth_strip.png` (default: the first input camera).
    #[arg(long)]
    pub camera: Option<usize>,
}

fn depth(args: DepthArgs) -> anyhow::Result<()> {
    use fewview_human::depth_report::{DepthReportConfig, measure, strip};
    use fewview_human::train::prepare::InferenceInputs;
    let (_, capture) = fewview_human::capture::open(&args.capture.data, &args.capture.sequence)?;
    let split = Split::for_capture(&*capture, args.input_cameras, None)?;
    let frames = match &args.frames {
        Some(t) => parse_frames(t)?,
        None => split.all_frames(),
    };
    if frames.end > capture.frame_count() {
        bail!("--frames: the capture has {} frames", capture.frame_count());
    }
    let camera = args.camera.unwrap_or(split.input_cameras[0]);
    if !split.input_cameras.contains(&camera) {
        bail!(
            "--camera {camera} is not an input camera ({:?})",
            split.input_cameras
        );
    }
    let train = TrainConfig {
        preset: preset(args.preset),
        ..TrainConfig::default()
    };
    let net = fewview_human::train::trainer::net_config(&train, &capture.joint_parents()?);
    let config = DepthReportConfig {
        frames: frames.clone(),
        size: [net.input[1], net.input[0]],
        crop_margin: train.crop_margin,
        hull_voxel: train.hull_voxel,
        stereo: train.stereo.clone(),
    };
    let inputs = InferenceInputs {
        source: &*capture,
        split: &split,
        depth_maps: true,
    };
    eprintln!(
        "human depth: hull and stereo depth of {} input cameras over frames {}..={}…",
        split.input_cameras.len(),
        frames.start,
        frames.end - 1
    );
    let (report, prepared) = measure(&inputs, &config)?;
    let out = &args.capture.out;
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    let shown: Vec<usize> = frames.clone().take(4).collect();
    strip(&prepared, camera, &shown)?.save_png(&out.join("depth_strip.png"))?;
    let json = out.join("depth_report.json");
    std::fs::write(&json, serde_json::to_string_pretty(&report)?)
        .with_context(|| format!("{}: cannot write", json.display()))?;
    let mm = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{:.1} mm", 1e3 * v));
    for (name, s) in [("hull", &report.hull), ("stereo", &report.stereo)]
        .into_iter()
        .chain(report.truth.as_ref().map(|t| ("truth", t)))
    {
        println!(
            "{name:>6}: flicker {}, beyond the motion {}, error {}",
            mm(s.flicker_m),
            mm(s.flicker_beyond_truth_m),
            mm(s.error_m)
        );
    }
    println!(
        "stereo matched {:.0} % of the masked pixels; flicker stereo/hull {}; written to {}",
        100.0 * report.stereo_matched,
        report
            .flicker_ratio
            .map_or("–".to_string(), |r| format!("{r:.2}×")),
        out.display()
    );
    Ok(())
}
