//! `fewview fusion`: sparse-view splatting with gradient-domain fusion on virtual views
//! (the fusion paper), or one of its alternatives, and the transition video it is judged by.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args as ClapArgs;
use fewview_fusion::leave_one_out::EvalMode;
use fewview_fusion::reproject::{Occlusion, ReprojectOptions};
use fewview_fusion::{FusionConfig, Variant};
use fewview_scene::Dataset;
use fewview_scene::memory::StagePeaks;
use fewview_scene::photometric::{PhotoGain, jitter_training_photos, training_gains};
use fewview_scene::synthetic::{DemoOptions, demo_dataset};
use fewview_splat::pipeline::adopt_init_poses;
use fewview_splat::pipeline::default_iterations;

use super::dataset_args::{ViewList, object_only, parse_views};
use super::fusion_outputs::{print_transition, train_with_progress, transition, write_gains};
use super::fusion_study::write_study;
use super::leave_one_out;
use super::output_paths::check_folder;
use super::photo_args::{DemoSceneArgs, JitterArgs};
use super::poses_first;
use super::surface_first;
use super::train::{print_summary, training_finished};
use super::train_args::TrainArgs;

/// Train Gaussians whose colours change smoothly between the input views ("Splat-based
/// Gradient-domain Fusion for Seamless View Transition").
///
/// Trains as `train` does, from the stereo start, and adds the chosen variant's regulariser on
/// virtual views between adjacent training views: `gf` (ours: the rendered view's gradients
/// follow the guidance field of its two neighbours reprojected through meshes of rendered depth),
/// or the supplement's alternatives `plain`, `sparse-init` (a), `knn-color` (b), `tv` (c),
/// `l1-virtual` (d), `poisson` (e). Then renders `transition.mp4` (8 s at 20 fps through the
/// training views and back) and scores it (`transition.json`: warping error with the exact flow
/// of the rendered depth; on `--demo`, PSNR/SSIM/LPIPS against the ray-traced truth along the
/// path). Writes the run directory of `train` plus `fusion.json`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Dataset folder (any format `train` reads).
    #[arg(
        long,
        value_name = "DIR",
        required_unless_present_any = ["demo", "study", "table"],
        conflicts_with = "demo"
    )]
    pub data: Option<PathBuf>,
    /// Use the in-process demo scene instead of a dataset.
    ///
    /// Use the demo scene built in-process (3 of 24 ray-traced views, view-dependent shading)
    /// instead of a dataset; the path is then scored against its ray-traced truth.
    #[arg(long)]
    pub demo: bool,
    /// Demo image width (height 3/4 of it).
    #[arg(long, default_value_t = 200, requires = "demo")]
    pub width: usize,
    /// Downscale images by this integer factor on load.
    ///
    /// Downscale images by this integer factor on load (intrinsics follow). Default 1; for a
    /// folder of photos, the factor that brings them to about 1,000 px on their longer side.
    #[arg(long, value_name = "K")]
    pub downscale: Option<u32>,
    /// Training views of the format's sparse split.
    ///
    /// Number of training views of the format's standard sparse split.
    #[arg(long, value_name = "N")]
    pub n_train: Option<usize>,
    /// Explicit training views, e.g. `22,25,28`.
    ///
    /// Explicit training views (indices in the dataset's view order; with `--demo`, of its 24
    /// views on an arc).
    #[arg(long, value_name = "LIST", value_parser = parse_views)]
    pub train_views: Option<ViewList>,
    /// Explicit held-out views.
    #[arg(long, value_name = "LIST", value_parser = parse_views)]
    pub test_views: Option<ViewList>,
    /// Train and score the masked object alone (DTU).
    ///
    /// Use the dataset's separate foreground masks (DTU's `mask/`) as the photos' alpha:
    /// training and scores see the object alone, as IDR/NeuS and the surface method on DTU.
    #[arg(long)]
    pub object_only: bool,
    #[command(flatten)]
    pub train: TrainArgs,
    #[command(flatten)]
    pub jitter: JitterArgs,
    #[command(flatten)]
    pub scene: DemoSceneArgs,
    /// The regulariser: gf (ours), plain, or ablations a–e.
    ///
    /// The regulariser: gf (f, ours), plain, sparse-init (a), knn-color (b), tv (c),
    /// l1-virtual (d), poisson (e).
    #[arg(long, default_value = "gf", value_parser = parse_variant)]
    pub variant: Variant,
    /// Weight λ of the virtual-view loss.
    ///
    /// It weighs the loss of gf, l1-virtual and poisson.
    #[arg(long, default_value_t = FusionConfig::default().weight,
          value_parser = super::number_args::non_negative_f32)]
    pub weight: f32,
    /// Virtual-view loss every N iterations.
    ///
    /// Take the virtual-view loss every N iterations (from 20 % of the run).
    #[arg(long, default_value_t = FusionConfig::default().every,
          value_parser = super::number_args::positive_count)]
    pub every: usize,
    /// Refresh the training views' depth every N iterations.
    ///
    /// Re-render and re-mesh the training views' depth every N iterations.
    #[arg(long, default_value_t = FusionConfig::default().refresh_interval,
          value_parser = super::number_args::positive_count)]
    pub refresh: usize,
    /// Even the exposures of photos in a virtual view (default: on for gf).
    ///
    /// Bring the two photos reprojected into a virtual view to one exposure (their gain ratio
    /// where both see the surface, interpolated log-linearly) before the guidance field (or the
    /// pseudo ground truth of l1-virtual and poisson) is built from them. `--match-exposure`
    /// alone is `true`; `--match-exposure false` takes the references as they are (the
    /// supplement's reading). Default: on for gf, off for the alternatives.
    #[arg(long, value_name = "BOOL", num_args = 0..=1, default_missing_value = "true")]
    pub match_exposure: Option<bool>,
    /// What hides a reprojected photo in a virtual view (default: meshes for gf).
    ///
    /// What decides that a photo reprojected into a virtual view shows what that view sees
    /// (with `own-depth`, the supplement's reading, a floater in the virtual view hides the
    /// photos behind it from the loss; `meshes` ignores what the virtual view renders in
    /// front). Default: meshes for gf, own-depth for the alternatives.
    #[arg(long, value_enum)]
    pub occlusion: Option<Occlusion>,
    /// How the run is scored: leave-one-out or held-out.
    ///
    /// `leave-one-out` holds each of up to three interior photos out in turn and trains the
    /// same way on the rest (in `OUT/leave_one_out/<photo>/`), then scores the held-out photo;
    /// `held-out` scores the dataset's held-out views. Default: leave-one-out when no view is
    /// held out (a capture of 8 photos or fewer), else held-out.
    #[arg(long, value_enum, value_name = "MODE")]
    pub eval: Option<EvalMode>,
    /// Skip the transition video and its scores.
    #[arg(long)]
    pub no_transition: bool,
    /// Skip LPIPS (held-out views and, on `--demo`, the path).
    #[arg(long)]
    pub no_lpips: bool,
    /// Run directory (with `--study`: the study's folder).
    #[arg(long, value_name = "DIR", required_unless_present = "table")]
    pub out: Option<PathBuf>,
    /// Instead of training: put the transition videos of these finished runs (same dataset and
    /// views; each folder's name becomes a method's name) into a pairwise study in `--out`
    /// (`study.toml` with the fusion paper's two questions, and `videos/`), ready for
    /// `fewview study serve --config OUT/study.toml`.
    #[arg(long, num_args = 2.., value_name = "RUN", conflicts_with_all = ["demo", "data", "table"])]
    pub study: Vec<PathBuf>,
    /// Print the comparison table of these runs instead.
    ///
    /// Instead of training: print the comparison table (Markdown) of these finished runs.
    #[arg(long, num_args = 1.., value_name = "RUN", conflicts_with_all = ["demo", "data"])]
    pub table: Vec<PathBuf>,
    /// Continue the run in `--out`.
    ///
    /// From its last checkpoint, with the same flags. A run trained to its end (say, stopped
    /// while its transition was scored) goes on with the transition and the leave-one-out runs
    /// it has not finished.
    #[arg(long)]
    pub resume: bool,
    /// Only re-render and re-score the run in `--out`.
    ///
    /// Do not train: render and score the transition of the finished run in `--out` again
    /// (same dataset flags), e.g. after a change of the scores.
    #[arg(long, conflicts_with_all = ["resume", "no_transition"])]
    pub rescore: bool,
}

fn parse_variant(s: &str) -> Result<Variant, String> {
    s.parse()
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if !args.table.is_empty() {
        return print_table(&args.table);
    }
    let out = args.out.clone().expect("clap requires --out");
    check_folder(&out, "--out")?;
    if !args.study.is_empty() {
        return write_study(&args.study, &out);
    }
    let mut args = args;
    let mut poses_memory = StagePeaks::default();
    let mut photos = false;
    if let Some(data) = args.data.clone() {
        let folder = poses_first::dataset_folder(&data, &out)?;
        photos = folder.working_downscale.is_some();
        poses_memory = folder.memory.clone();
        args.downscale = Some(poses_first::chosen_downscale(
            args.downscale,
            &folder,
            &data,
        ));
        args.data = Some(folder.dir);
    }
    let (mut ds, demo, gains) = load(&args)?;
    let default = if demo.is_some() {
        2000
    } else {
        default_iterations(&ds)
    };
    if demo.is_some() && surface_first::wanted(&args.train.init) {
        bail!("--init surface runs the surface method on a dataset; pass --data");
    }
    let bare_surface = surface_first::take(&mut args.train.init, &out);
    let cfg = args
        .train
        .transition_run_config(ds.background, default, photos)?;
    let first = || {
        Ok(surface_first::SurfaceFirst {
            data: args
                .data
                .clone()
                .expect("clap requires --data without --demo"),
            downscale: args.downscale.unwrap_or(1),
            train_views: args.train_views.clone().map(|v| v.0),
            test_views: args.test_views.clone().map(|v| v.0),
            n_train: args.n_train,
            object_only: args.object_only,
            seed: args.train.seed,
        })
    };
    let poses = surface_first::run_if(bare_surface, first, &out, args.train.surface_poses)?;
    if let Some(line) = adopt_init_poses(&mut ds, &cfg, poses)? {
        eprintln!("{line}");
    }
    if args.rescore {
        if !out.join("point_cloud.ply").exists() {
            bail!(
                "{}: no finished run to rescore (point_cloud.ply is missing)",
                out.display()
            );
        }
        let report = transition(&ds, demo.as_ref(), &out, !args.no_lpips)?;
        print_transition(&report);
        return Ok(());
    }
    let fusion = fusion_config(&args);
    if let Err(m) = fusion.validate() {
        bail!("invalid fusion options: {m}");
    }
    eprintln!(
        "fusion ({}) on {} ({} train / {} held-out views) → {}",
        fusion.variant,
        ds.name,
        ds.train.len(),
        ds.test.len(),
        out.display()
    );
    let eval = EvalMode::resolve(args.eval, &ds)?;
    fewview_fusion::budget::check_dataset_fits(
        &ds,
        !args.no_transition,
        args.downscale.unwrap_or(1),
    )
    .map_err(anyhow::Error::msg)?;
    let summary = if training_finished(&out, args.resume) {
        None
    } else {
        let summary = train_with_progress(&ds, &cfg, &fusion, &out, args.resume)?;
        write_gains(&out, &gains)?;
        print_summary(&summary, &out);
        Some(summary)
    };
    let mut after = StagePeaks::default();
    if !args.no_transition {
        let report = after.measure("transition", || {
            transition(&ds, demo.as_ref(), &out, !args.no_lpips)
        })?;
        print_transition(&report);
    }
    if let Some(summary) = &summary {
        poses_first::record_memory(&out, &poses_memory, &summary.memory, &after)?;
    }
    if eval == EvalMode::LeaveOneOut {
        let train = |ds: &Dataset, dir: &std::path::Path, resume: bool| {
            train_with_progress(ds, &cfg, &fusion, dir, resume).map(|_| ())
        };
        if let Some(report) = leave_one_out::run(&ds, &out, !args.no_lpips, train)? {
            leave_one_out::print(&report);
        }
    }
    Ok(())
}

/// The dataset with its jittered training photos, the demo's options when it is the demo, and
/// each training photo's gain.
#[allow(clippy::type_complexity)]
fn load(args: &Args) -> anyhow::Result<(Dataset, Option<DemoOptions>, Vec<(String, PhotoGain)>)> {
    let jitter = args.jitter.jitter();
    if args.demo && args.object_only {
        bail!("--object-only uses a dataset's foreground masks; the demo scene has none");
    }
    if args.demo {
        let mut opts = args.scene.apply(DemoOptions {
            width: args.width,
            height: args.width * 3 / 4,
            jitter,
            ..DemoOptions::default()
        })?;
        if let Some(train) = &args.train_views {
            opts.train = train.0.clone();
        }
        let ds = demo_dataset(&opts);
        let gains = training_gains(&ds, &jitter);
        return Ok((ds, Some(opts), gains));
    }
    if args.scene.is_set() {
        bail!(
            "--specular, --mirror-floor and --baseline-scale change the demo scene; they need --demo"
        );
    }
    let folder = args
        .data
        .as_deref()
        .expect("clap requires --data without --demo");
    let options = fewview_scene::load::LoadOptions {
        downscale: args.downscale.unwrap_or(1),
        n_train: args.n_train,
        train_views: args.train_views.clone().map(|v| v.0),
        test_views: args.test_views.clone().map(|v| v.0),
        ..Default::default()
    };
    let mut ds = fewview_scene::load_dataset(folder, &options)
        .with_context(|| format!("cannot load dataset {}", folder.display()))?;
    if args.object_only {
        object_only(&mut ds, folder)?;
    }
    let gains = jitter_training_photos(&mut ds, &jitter);
    Ok((ds, None, gains))
}

fn print_table(runs: &[PathBuf]) -> anyhow::Result<()> {
    let rows = runs
        .iter()
        .map(|r| fewview_fusion::table::read_row(r))
        .collect::<Result<Vec<_>, _>>()?;
    print!("{}", fewview_fusion::table::markdown(&rows));
    Ok(())
}

/// The regulariser's flags as the library's configuration.
fn fusion_config(args: &Args) -> FusionConfig {
    let defaults = FusionConfig::for_variant(args.variant);
    FusionConfig {
        weight: args.weight,
        every: args.every,
        refresh_interval: args.refresh,
        match_exposure: args.match_exposure.unwrap_or(defaults.match_exposure),
        reproject: ReprojectOptions {
            occlusion: args.occlusion.unwrap_or(defaults.reproject.occlusion),
            ..defaults.reproject
        },
        ..defaults
    }
}

#[cfg(test)]
mod tests {
    use crate::commands::parse_for_tests::parse;

    /// Every regulariser flag's default is the library's.
    #[test]
    fn an_empty_command_line_gives_the_librarys_defaults() {
        let args: super::Args = parse(&["fusion", "--demo", "--out", "o"]);
        let config = super::fusion_config(&args);
        assert_eq!(config, super::FusionConfig::default());
        // The alternatives keep the supplement's reading unless asked otherwise.
        let args: super::Args = parse(&["fusion", "--demo", "--variant", "poisson", "--out", "o"]);
        let config = super::fusion_config(&args);
        assert!(!config.match_exposure);
        assert_eq!(
            config.reproject.occlusion,
            fewview_fusion::reproject::Occlusion::OwnDepth
        );
        let args: super::Args = parse(&[
            "fusion",
            "--demo",
            "--match-exposure",
            "false",
            "--occlusion",
            "own-depth",
            "--out",
            "o",
        ]);
        let config = super::fusion_config(&args);
        assert!(!config.match_exposure);
        assert_eq!(
            config.reproject.occlusion,
            fewview_fusion::reproject::Occlusion::OwnDepth
        );
    }
}
