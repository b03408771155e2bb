//! `fewview human eval`.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::Args as ClapArgs;
use fewview_human::baseline::{BaselineInit, SplatBaselineOptions};

use super::shared::{CaptureArgs, TpsArgs, load_model, parse_frames, run_split};
use crate::commands::progress;

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
    /// Another run scored beside ours, `NAME=DIR`.
    ///
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
    /// Frames of the 3DGS-per-frame baseline.
    ///
    /// Train the 3DGS-per-frame baseline on this many consecutive frames from the first test
    /// frame (0: none; each takes minutes) and add a table of every method on them.
    #[arg(long, default_value_t = 0)]
    pub splat_frames: usize,
    /// Training iterations of each 3DGS-per-frame model.
    #[arg(long, value_name = "N", default_value_t = SplatBaselineOptions::default().iterations)]
    pub splat_iterations: usize,
    /// Where each 3DGS-per-frame model starts.
    ///
    /// `train` (what `fewview train` does on those views: the stereo start, else random points) or
    /// `hull` (points in the frame's visual hull, a prior plain 3DGS lacks; stronger).
    #[arg(long, value_enum, default_value_t)]
    pub splat_init: BaselineInit,
    #[command(flatten)]
    pub tps: TpsArgs,
    /// Validate on the training frames instead.
    ///
    /// Score the input cameras on the training frames instead, each predicted from its
    /// neighbours as in training (validation: choose `--tps-weight`/`--tps-speed` here without
    /// reading a held-out camera or a test frame).
    #[arg(long, conflicts_with = "splat_frames")]
    pub validation: bool,
    /// Source views per target at inference.
    ///
    /// For the run and its baselines (default: what each was trained with). The network sees one
    /// view at a time, so more views only add Gaussians where the two nearest views miss the
    /// person.
    #[arg(long, value_name = "N")]
    pub source_views: Option<usize>,
}

pub(super) fn eval(args: EvalArgs) -> anyhow::Result<()> {
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
            let opts = SplatBaselineOptions {
                iterations: args.splat_iterations,
                init: args.splat_init,
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
