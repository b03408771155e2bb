//! `fewview train`: 3D Gaussian splatting on a dataset's sparse training views.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args as ClapArgs;
use fewview_fusion::leave_one_out::EvalMode;
use fewview_scene::split;
use fewview_splat::pipeline::adopt_init_poses;
use fewview_splat::pipeline::{
    RunConfig, RunSummary, default_iterations, initial_model, train_run,
};

use super::dataset_args::DatasetArgs;
use super::leave_one_out;
use super::output_paths::check_folder;
use super::poses_first;
use super::progress;
use super::surface_first;
use super::train_args::TrainArgs;

/// Train 3D Gaussians on a dataset's training views and score its held-out views.
///
/// Writes a run directory: `config.json`, `checkpoint.bin` while training (resume with
/// `--resume`), `point_cloud.ply` (Inria layout, opens in splat viewers), `renders/test/*.png`
/// and `metrics.json` (PSNR, SSIM per held-out view and their means; ST-LPIPS means).
#[derive(Debug, ClapArgs)]
pub struct Args {
    #[command(flatten)]
    pub dataset: DatasetArgs,
    #[command(flatten)]
    pub train: TrainArgs,
    /// Run directory. Default: `runs/<dataset folder name>`.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// How the run is scored: leave-one-out or held-out.
    ///
    /// `leave-one-out` holds each of up to three interior photos out in turn and trains again
    /// on the rest (in `OUT/leave_one_out/<photo>/`), then scores the held-out photo;
    /// `held-out` scores the dataset's held-out views. Default: leave-one-out when no view is
    /// held out (a capture of 8 photos or fewer), else held-out.
    #[arg(long, value_enum, value_name = "MODE")]
    pub eval: Option<EvalMode>,
    /// Skip LPIPS of the held-out views.
    ///
    /// By default the held-out views are also scored by ST-LPIPS (AlexNet; the original LPIPS
    /// backbones cannot be fetched), raw and gain-matched, into `metrics.json` under `lpips`.
    #[arg(long)]
    pub no_lpips: bool,
    /// Continue the run in `--out`.
    ///
    /// From its last checkpoint, with the same flags as the first time. A checkpoint of another
    /// dataset, split or image size is refused. A run trained to its end goes on with the
    /// leave-one-out runs it has not finished.
    #[arg(long)]
    pub resume: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let out = args.out.clone().unwrap_or_else(|| {
        let name = args
            .dataset
            .data
            .as_deref()
            .and_then(|d| d.file_name())
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "run".into());
        PathBuf::from("runs").join(name)
    });
    check_folder(&out, "--out")?;
    let mut args = args;
    let data = args.dataset.folder()?.to_path_buf();
    let folder = poses_first::dataset_folder(&data, &out)?;
    let poses_memory = folder.memory.clone();
    let photos = folder.working_downscale.is_some();
    args.dataset.downscale = Some(poses_first::chosen_downscale(
        args.dataset.downscale,
        &folder,
        &data,
    ));
    args.dataset.data = Some(folder.dir);
    let mut ds = args.dataset.load()?;
    // The standard splits are disjoint; explicit `--train-views` / `--test-views` could overlap
    // them or each other, and the held-out PSNR would then be measured on training views.
    if let Err(e) = split::check_disjoint(&ds.train, &ds.test, args.dataset.folder()?) {
        bail!("{e}; pass disjoint --train-views and --test-views");
    }
    let eval = EvalMode::resolve(args.eval, &ds)?;
    fewview_fusion::budget::check_dataset_fits(&ds, false, args.dataset.downscale.unwrap_or(1))
        .map_err(anyhow::Error::msg)?;
    let bare_surface = surface_first::take(&mut args.train.init, &out);
    let cfg = args
        .train
        .run_config(ds.background, default_iterations(&ds), photos)?;
    let d = &args.dataset;
    let first = || {
        Ok(surface_first::SurfaceFirst {
            data: d.folder()?.to_path_buf(),
            downscale: d.downscale.unwrap_or(1),
            train_views: d.train_views.clone().map(|v| v.0),
            test_views: d.test_views.clone().map(|v| v.0),
            n_train: d.n_train,
            object_only: d.object_only,
            seed: args.train.seed,
        })
    };
    let poses = surface_first::run_if(bare_surface, first, &out, args.train.surface_poses)?;
    if let Some(line) = adopt_init_poses(&mut ds, &cfg, poses)? {
        eprintln!("{line}");
    }
    eprintln!(
        "training on {} ({} train / {} held-out views, {}x{}) → {}",
        ds.name,
        ds.train.len(),
        ds.test.len(),
        ds.views[ds.train[0]].image.width,
        ds.views[ds.train[0]].image.height,
        out.display()
    );
    if !training_finished(&out, args.resume) {
        let summary = train_with_progress(&ds, &cfg, &out, args.resume)?;
        print_summary(&summary, &out);
        poses_first::record_memory(&out, &poses_memory, &summary.memory, &Default::default())?;
        if !args.no_lpips && !ds.test.is_empty() {
            score_lpips(&ds, &out)?;
        }
    }
    if eval == EvalMode::LeaveOneOut {
        let train = |ds: &fewview_scene::Dataset, dir: &std::path::Path, resume: bool| {
            train_with_progress(ds, &cfg, dir, resume).map(|_| ())
        };
        if let Some(report) = leave_one_out::run(&ds, &out, true, train)? {
            leave_one_out::print(&report);
        }
    }
    Ok(())
}

/// Scores the held-out views of the run in `out` by ST-LPIPS, adds them to its `metrics.json`
/// (`lpips`: the network, the mean raw and gain-matched) and prints them.
fn score_lpips(ds: &fewview_scene::Dataset, out: &std::path::Path) -> anyhow::Result<()> {
    let lpips = fewview_metrics::lpips::Lpips::default_st_alex()?;
    let (w, h) = (
        ds.views[ds.test[0]].image.width,
        ds.views[ds.test[0]].image.height,
    );
    if w.min(h) < lpips.min_side() {
        let min = lpips.min_side();
        println!("held-out LPIPS   not scored: the views are {w}x{h}, ST-LPIPS needs {min}x{min}");
        return Ok(());
    }
    let (raw, matched) = fewview_fusion::transition::held_out_lpips_of_run(ds, out, &lpips)?;
    let value = serde_json::json!({
        "network": "ST-LPIPS AlexNet",
        "mean": raw,
        "mean_gain_matched": matched,
    });
    fewview_fusion::leave_one_out::add_to_json(&out.join("metrics.json"), "lpips", &value)?;
    println!("held-out LPIPS   {raw:.4}, gain-matched {matched:.4} (ST-LPIPS AlexNet)");
    Ok(())
}

/// Builds the initial Gaussians once, for a caller that writes something before it trains
/// (`demo` writes its ground-truth images): an `--init` the dataset cannot serve (a missing or
/// corrupt `ply:FILE`, `points` without sparse points) then fails with nothing written.
/// [`train_run`] itself creates the run folder only after building them. A resumed run starts
/// from its checkpoint instead.
pub fn check_init(
    ds: &fewview_scene::Dataset,
    cfg: &RunConfig,
    init: &str,
    resume: bool,
) -> anyhow::Result<()> {
    if !resume {
        initial_model(ds, cfg).with_context(|| format!("--init {init}"))?;
    }
    Ok(())
}

/// Runs the pipeline with a progress bar.
pub fn train_with_progress(
    ds: &fewview_scene::Dataset,
    cfg: &fewview_splat::pipeline::RunConfig,
    out: &std::path::Path,
    resume: bool,
) -> anyhow::Result<RunSummary> {
    let bar = progress::iterations(cfg.train.iterations as u64, "train");
    let summary = train_run(ds, cfg, out, resume, |p| {
        bar.set_position(p.iteration as u64);
        if p.iteration % 10 == 0 || p.iteration == p.iterations {
            bar.set_message(format!("loss {:.4}  {} Gaussians", p.loss, p.gaussians));
        }
    })
    .with_context(|| format!("training run in {}", out.display()))?;
    bar.finish_and_clear();
    Ok(summary)
}

/// Whether `--resume` finds the run in `out` trained to its end (its model written, no
/// checkpoint left), so only the stages after training remain (the transition, leave-one-out);
/// says so when it does.
pub fn training_finished(out: &std::path::Path, resume: bool) -> bool {
    let finished = resume && fewview_splat::pipeline::RunDir(out.to_path_buf()).finished();
    if finished {
        eprintln!(
            "{}: training already finished; going on with the stages after it",
            out.display()
        );
    }
    finished
}

pub fn print_summary(s: &RunSummary, out: &std::path::Path) {
    println!("dataset          {}", s.dataset);
    println!("initialisation   {}", s.init);
    for note in &s.init_notes {
        println!("                 {note}");
    }
    println!(
        "iterations       {}{}",
        s.iterations,
        s.resumed_from
            .map(|i| format!(" (resumed at {i})"))
            .unwrap_or_default()
    );
    println!("Gaussians        {}", s.gaussians);
    println!("training time    {:.1} s", s.train_seconds);
    println!("held-out views   {}", s.test.views.len());
    if s.test.views.is_empty() {
        println!("outputs          {}", out.display());
        return;
    }
    println!("held-out PSNR    {:.3} dB", s.test.mean_psnr);
    println!("held-out SSIM    {:.4}", s.test.mean_ssim);
    println!(
        "gain-matched     PSNR {:.3} dB, SSIM {:.4} (a least-squares gain per channel first)",
        s.test.mean_gain_matched_psnr, s.test.mean_gain_matched_ssim
    );
    if let (Some(p), Some(q)) = (s.test.mean_masked_psnr, s.test.mean_masked_ssim) {
        println!("masked PSNR      {p:.3} dB");
        println!("masked SSIM      {q:.4}");
    }
    println!("outputs          {}", out.display());
}
