//! `fewview human train`.

use std::io::Write;
use std::time::Instant;

use anyhow::{Context, bail};
use clap::Args as ClapArgs;
use fewview_human::depth::{DepthBracket, DepthInput};
use fewview_human::net::Variant;
use fewview_human::train::{Preset, TrainConfig, Trainer};
use fewview_human::{Split, TrainingView};

use super::shared::{CaptureArgs, StereoArgs, parse_metres_pair};
use fewview_splat::ComputeDevice;

use crate::commands::progress;

/// Train the network; writes checkpoints (`network.fvh`, `optimizer.bin`, `state.bin`) and
/// `train_log.jsonl` to `--out`.
/// The library's defaults, the one source of the flags' defaults below.
fn defaults() -> TrainConfig {
    TrainConfig::default()
}

#[derive(Debug, ClapArgs)]
pub struct TrainArgs {
    #[command(flatten)]
    pub capture: CaptureArgs,
    /// Network widths and input size.
    #[arg(long, value_enum, default_value_t = defaults().preset)]
    pub preset: Preset,
    /// Network configuration of the appendix (1–4).
    ///
    /// Network configuration of the paper's appendix (1 simplified, 2 deep residual,
    /// 3 with batch norm, 4 without downsampling).
    #[arg(long, default_value_t = defaults().variant.number(),
          value_parser = clap::value_parser!(u8).range(1..=4))]
    pub variant: u8,
    /// Training steps, one target view of one frame each.
    #[arg(long, default_value_t = defaults().iterations)]
    pub iterations: usize,
    /// Adam's step size.
    #[arg(long, default_value_t = defaults().learning_rate)]
    pub lr: f64,
    /// Seeds the initial weights and the order of the targets.
    #[arg(long, default_value_t = defaults().seed)]
    pub seed: u64,
    /// Source views per target.
    #[arg(long, value_name = "N", default_value_t = defaults().source_views)]
    pub source_views: usize,
    /// Feed the pose encoder zeros (per-frame baseline).
    ///
    /// Feed the pose encoder zeros (the per-frame baseline of PoseGaussian's comparison).
    #[arg(long)]
    pub no_pose: bool,
    /// The depth the network reads and refines.
    #[arg(long, value_enum, default_value_t)]
    pub depth: DepthInput,
    /// How far the depth head may move its input (m).
    ///
    /// Where the depth head's output may move the input depth: in front of it and behind it,
    /// in metres (default: the depth input's own bracket).
    #[arg(long, value_name = "FRONT,BEHIND", value_parser = parse_metres_pair)]
    pub depth_bracket: Option<(f64, f64)>,
    #[command(flatten)]
    pub stereo: StereoArgs,
    /// Write a checkpoint every N iterations (and at the end).
    #[arg(long, value_name = "N", default_value_t = 100)]
    pub checkpoint_every: usize,
    /// Continue the run in `--out`.
    ///
    /// From its checkpoint, with the same settings; `--iterations` may grow.
    #[arg(long)]
    pub resume: bool,
    /// Input cameras, spread over the rig.
    ///
    /// Input cameras, spread uniformly over the rig (PoseGaussian's protocol: 8; the others are
    /// held out for evaluation).
    #[arg(long, default_value_t = fewview_human::split::PAPER_INPUT_CAMERAS)]
    pub input_cameras: usize,
    /// Training frames, from the first.
    ///
    /// Default: two thirds of the sequence; the rest test novel poses.
    #[arg(long, value_name = "N")]
    pub train_frames: Option<usize>,
    /// Stop with a checkpoint after this many minutes.
    ///
    /// Stop after this many minutes of wall time (hull carving included) with a checkpoint, even
    /// before `--iterations`: a training budget; `--resume` continues later.
    #[arg(long, value_name = "MINUTES")]
    pub max_minutes: Option<f64>,
    /// Where to train: cpu, or gpu (`--features gpu`).
    ///
    /// Where to train: `cpu` (every build) or `gpu` (the network's convolutions and the splat
    /// rasterizer on the first GPU wgpu finds; builds with `--features gpu`).
    #[arg(long, value_enum, default_value_t)]
    pub device: ComputeDevice,
}

fn config(args: &TrainArgs) -> anyhow::Result<TrainConfig> {
    Ok(TrainConfig {
        preset: args.preset,
        variant: Variant::from_number(args.variant)?,
        iterations: args.iterations,
        learning_rate: args.lr,
        seed: args.seed,
        source_views: args.source_views,
        use_pose: !args.no_pose,
        depth: args.depth,
        bracket: bracket(args)?,
        stereo: args.stereo.settings()?,
        ..TrainConfig::default()
    })
}

/// `--depth-bracket`, or the depth input's own bracket.
fn bracket(args: &TrainArgs) -> anyhow::Result<DepthBracket> {
    let bracket = match args.depth_bracket {
        Some((front, behind)) => DepthBracket {
            front: front as f32,
            behind: behind as f32,
        },
        None => args.depth.bracket(),
    };
    bracket.check()?;
    Ok(bracket)
}

pub(super) fn train(args: TrainArgs) -> anyhow::Result<()> {
    let config = config(&args)?;
    let (_, capture) = fewview_human::capture::open(&args.capture.data, &args.capture.sequence)?;
    let split = Split::for_capture(&*capture, args.input_cameras, args.train_frames)?;
    let view = TrainingView::new(&*capture, &split)?;
    let device = args.device.open()?.autodiff();
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::commands::parse_for_tests::parse;

    /// Every flag's default is the library's: an empty command line gives `TrainConfig::default()`.
    #[test]
    fn an_empty_command_line_gives_the_librarys_defaults() {
        assert_eq!(config(&parsed(&[])).unwrap(), TrainConfig::default());
    }

    /// `human train` on placeholder paths with `extra` flags.
    fn parsed(extra: &[&str]) -> TrainArgs {
        let mut line = vec!["train", "--data", "d", "--out", "o"];
        line.extend(extra);
        parse(&line)
    }

    #[test]
    fn the_stereo_and_bracket_flags_reach_the_config() {
        let args = parsed(&[
            "--stereo-checks",
            "dense",
            "--stereo-search",
            "0.3,0.6",
            "--depth-bracket",
            "0.25,0.5",
        ]);
        let c = config(&args).unwrap();
        assert_eq!(c.stereo.checks, fewview_human::depth::StereoChecks::Dense);
        assert_eq!((c.stereo.hull_front, c.stereo.hull_behind), (0.3, 0.6));
        assert_eq!((c.bracket.front, c.bracket.behind), (0.25, 0.5));
        let err = config(&parsed(&["--depth-bracket", "0,0"]))
            .unwrap_err()
            .to_string();
        assert!(err.contains("depth bracket"), "{err}");
    }
}
