//! `fewview surface`: neural implicit surface + pose refinement from a few views with noisy
//! poses (the surface paper). The flags are the library's [`Overrides`]; this module parses them,
//! shows progress and prints the report.

use std::path::PathBuf;

use super::progress::Bar;
use anyhow::Context;
use clap::Args as ClapArgs;
use fewview_metrics::pose_error::PoseError;
use fewview_surface::adam::ExpSchedule;
use fewview_surface::field::{EncoderKind, FdScheme};
use fewview_surface::matching::learned::MatcherKind;
use fewview_surface::matching::refine::WarpModel;
use fewview_surface::pipeline::checkpoint_path;
use fewview_surface::warmup::{Connectivity, WarmupReport};
use fewview_surface::{
    Densify, Event, InitialPoses, LoadedInputs, LossSwitches, LossWeights, Overrides, RunConfig,
    RunReport, Scene, Schedule,
};

use super::dataset_args::DatasetArgs;
use super::number_args::{non_negative, non_negative_f32};
use super::output_paths::check_folder;
use super::progress;

/// The largest `--pose-noise`. σ is the standard deviation of every se(3) component: radians
/// for the rotation and units of the normalised scene (radius 1) for the translation. At σ = π
/// the rotations are already close to uniformly random and the cameras land several scene
/// radii away, so a larger σ describes no pose refinement problem (1e300 used to reach the
/// pose sampler and fail after the run folder was written).
const MAX_POSE_NOISE: f64 = std::f64::consts::PI;

/// `--pose-noise`: a finite σ in [0, [`MAX_POSE_NOISE`]].
fn pose_noise(s: &str) -> Result<f64, String> {
    match non_negative(s)? {
        v if v <= MAX_POSE_NOISE => Ok(v),
        _ => Err(format!("{s}: expected σ ≤ π (radians of rotation noise)")),
    }
}

/// The largest `--mesh-resolution`. Marching cubes evaluates the field at n³ grid points and
/// the mesh grows as n²: at 2048 that is 8.6·10⁹ field evaluations (hours on a CPU) and tens of
/// millions of triangles (gigabytes), 4× the 512 NeuS meshes at; 100000 ran for ever.
const MAX_MESH_RESOLUTION: i64 = 2048;

/// Reconstruct a surface (NeuS SDF) and refine noisy camera poses from a few views (the surface paper):
/// a run directory with the refined poses, `mesh.ply`, renders and `metrics.json`.
#[derive(Debug, ClapArgs)]
#[command(mut_arg("data", |a| a.required(false)))]
pub struct Args {
    #[command(flatten)]
    pub dataset: DatasetArgs,
    /// Use the built-in sphere-traced analytic scene instead of `--data`.
    #[arg(long)]
    pub synthetic: bool,
    /// With `--synthetic`: add 16 training views at 0° and −30° elevation, so that the
    /// underside is observed too.
    #[arg(long, requires = "synthetic")]
    pub synthetic_all_around: bool,
    /// Run directory. Default: `runs/surface-<dataset folder name>`.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Instead of a run: print the surface paper's Table 1 (Markdown) for these finished runs.
    #[arg(long, num_args = 1.., value_name = "RUN", conflicts_with_all = ["synthetic", "out", "resume"])]
    pub table: Vec<PathBuf>,
    /// Continue the run in `--out` from its checkpoint; only --iterations, --checkpoint-every
    /// and the output settings may change.
    #[arg(long)]
    pub resume: bool,
    /// Training iterations (the surface paper: 100k on a GPU; the default fits a CPU budget).
    #[arg(long, default_value_t = 2000)]
    pub iterations: usize,
    /// Random rays per iteration.
    #[arg(long, default_value_t = 512)]
    pub rays: usize,
    /// Correspondences per iteration (two rays each).
    #[arg(long, default_value_t = 128)]
    pub matches_per_batch: usize,
    /// σ of the se(3) pose noise (0 = ground-truth poses; at most π).
    #[arg(long, default_value_t = 0.15, value_parser = pose_noise)]
    pub pose_noise: f64,
    /// Start from the perturbed ground truth (`noisy`) or from the dataset's poses (`loaded`).
    #[arg(long, value_enum, default_value_t = InitialPosesArg::Noisy)]
    pub initial_poses: InitialPosesArg,
    /// Pose schedule (`cpu`: deviations from the surface paper's §B.1 that converge on a CPU
    /// budget).
    #[arg(long, value_enum, default_value_t)]
    pub schedule: Schedule,
    /// Pose learning rate at the start and end of its decay (default from `--schedule`).
    #[arg(long, value_name = "START,END", value_parser = pose_rates)]
    pub pose_lr: Option<ExpSchedule>,
    /// Keep the poses fixed, before training too: the warm-up and the bundle and patch
    /// adjustments are off unless switched on by their own flags.
    #[arg(long)]
    pub no_pose_refinement: bool,
    /// Downscale factor of the images the matcher sees; must divide `--downscale`.
    #[arg(long, default_value_t = 1, value_name = "K")]
    pub match_downscale: u32,
    /// Match only views whose optical axes are at most this many degrees apart (180: all).
    #[arg(long, default_value_t = 80.0, value_name = "DEG")]
    pub max_pair_angle: f64,
    /// Which matcher finds the correspondences: `classical` (SIFT), or the learned XFeat with
    /// mutual nearest neighbours (`xfeat`), semi-dense and refined (`xfeat-star`), or matched by
    /// LighterGlue (`lighterglue`); their weights come from `scripts/setup.sh`, and without
    /// them the run says so and uses the classical matcher.
    #[arg(long, value_enum, default_value_t = MatcherKind::Classical)]
    pub matcher: MatcherKind,
    /// Sub-pixel refinement of the matches by Lucas–Kanade (a deviation from the surface paper).
    #[arg(long, value_enum, default_value_t = MatchRefineArg::Affine)]
    pub match_refine: MatchRefineArg,
    /// With `--match-refine quadratic`: drop matches whose second-order term moves a window
    /// point by more than this many pixels.
    #[arg(long, value_name = "PX", value_parser = super::number_args::positive)]
    pub match_max_bend: Option<f64>,
    /// Grow dense matches on a grid of this spacing (a deviation); `auto`: only when the
    /// sparse ones cannot tie the views together for the warm-up.
    #[arg(long, default_value = "auto", value_name = "PX|auto|off")]
    pub densify: Densify,
    /// Refine the initial poses on the matches' epipolar constraints before training (default
    /// from `--schedule`).
    #[arg(long, value_name = "on|off")]
    pub pose_warmup: Option<Toggle>,
    /// The warm-up uses only the pairs of views with at least this many matches.
    #[arg(long, default_value_t = 40, value_name = "N")]
    pub warmup_min_matches: usize,
    /// Final scale (pixels) of the warm-up's Cauchy loss on the Sampson distances.
    #[arg(long, default_value_t = Overrides::default().warmup_cauchy_px, value_name = "PX",
          value_parser = super::number_args::positive)]
    pub warmup_cauchy: f64,
    /// Polish the warmed-up poses with each dense match weighted by its Lucas–Kanade
    /// covariance (default from `--schedule`).
    #[arg(long, value_name = "on|off")]
    pub warmup_covariance: Option<Toggle>,
    /// Start the warm-up from the initial poses, without the global start from the matches.
    #[arg(long)]
    pub no_global_start: bool,
    /// After a warm-up on dense matches, refine the poses photometrically on small planes
    /// seeded by the matches (default from `--schedule`).
    #[arg(long, value_name = "on|off")]
    pub patch_adjustment: Option<Toggle>,
    /// Bundle-adjust the matches' tracks after the warm-up (default from `--schedule`).
    #[arg(long, value_name = "on|off")]
    pub bundle_adjustment: Option<Toggle>,
    /// What the warm-up's pairs must form.
    #[arg(long, value_enum, default_value_t)]
    pub warmup_connectivity: Connectivity,
    /// Hold the poses fixed for this fraction of the iterations (default from `--schedule`).
    #[arg(long, value_name = "FRACTION")]
    pub pose_start: Option<f64>,
    /// Seed of the noise, sampling and initialisation.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Geometry encoder (`neus-mlp`: the paper's 8×256 MLP, slow on a CPU).
    #[arg(long, value_enum, default_value_t = EncoderKind::HashGrid)]
    pub encoder: EncoderKind,
    /// Finite-difference stencil of the normals (4 or 6 taps).
    #[arg(long, value_enum, default_value_t = FdScheme::Tetrahedron)]
    pub fd: FdScheme,
    /// Coarse samples per ray.
    #[arg(long, default_value_t = 32)]
    pub coarse: usize,
    /// Importance samples per ray.
    #[arg(long, default_value_t = 32)]
    pub importance: usize,
    /// Switch loss terms off for ablations, e.g. `--no-loss ncc,gc`.
    #[arg(long, value_name = "TERM,...", value_delimiter = ',')]
    pub no_loss: Vec<LossTerm>,
    /// Do not use object masks (colour loss on all pixels, no mask loss, no culling).
    #[arg(long)]
    pub no_masks: bool,
    /// Loss weights λ (mc, u, gc, geo, psdf), finite and ≥ 0, e.g. `--lambda u=0.02,gc=0`
    /// (defaults: the surface paper §B.1).
    #[arg(long, value_name = "NAME=VALUE,...", value_delimiter = ',', value_parser = loss_weight)]
    pub lambda: Vec<(WeightName, f32)>,
    /// Coarse-to-fine window (α₁, α₂) as fractions of the iterations, e.g. `0.4,0.7`.
    #[arg(long, value_name = "A1,A2", value_parser = c2f_window)]
    pub c2f: Option<(f64, f64)>,
    /// Marching-cubes resolution over [−1, 1]³ (2 to 2048).
    #[arg(long, default_value_t = 256,
          value_parser = clap::value_parser!(u32).range(2..=MAX_MESH_RESOLUTION))]
    pub mesh_resolution: u32,
    /// Test views rendered and scored.
    #[arg(long, default_value_t = 5)]
    pub eval_views: usize,
    /// Render test views at 1/K of their size.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub eval_scale: u32,
    /// Reference surface (PLY/OBJ, in the dataset's normalised frame) for Chamfer.
    #[arg(long, value_name = "FILE")]
    pub reference: Option<PathBuf>,
    /// Iterations between checkpoints.
    #[arg(long, default_value_t = 250)]
    pub checkpoint_every: usize,
}

/// `on` or `off` for a stage whose default comes from `--schedule`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Toggle {
    On,
    Off,
}

/// A loss term `--no-loss` switches off ([`LossSwitches`]; `gc`: geometric consistency).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum LossTerm {
    Matching,
    Ncc,
    Gc,
    Uncertainty,
    Psdf,
    Eikonal,
}

/// The λ that `--lambda NAME=VALUE` sets ([`LossWeights`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum WeightName {
    Mc,
    U,
    Gc,
    Geo,
    Psdf,
}

/// `NAME=VALUE` of `--lambda`.
fn loss_weight(s: &str) -> std::result::Result<(WeightName, f32), String> {
    use clap::ValueEnum;
    let (name, value) = s
        .split_once('=')
        .ok_or_else(|| format!("{s}: expected NAME=VALUE, e.g. u=0.02"))?;
    let name = WeightName::from_str(name.trim(), true)
        .map_err(|_| format!("{s}: unknown weight {name:?} (mc, u, gc, geo, psdf)"))?;
    Ok((name, non_negative_f32(value.trim())?))
}

/// `--initial-poses` ([`InitialPoses`]; the noise σ is `--pose-noise`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum InitialPosesArg {
    Noisy,
    Loaded,
}

/// `--match-refine`: the warp of the sub-pixel refinement ([`WarpModel`]), or none.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum MatchRefineArg {
    Affine,
    Quadratic,
    None,
}

impl MatchRefineArg {
    fn warp(self) -> Option<WarpModel> {
        match self {
            MatchRefineArg::Affine => Some(WarpModel::Affine),
            MatchRefineArg::Quadratic => Some(WarpModel::Quadratic),
            MatchRefineArg::None => None,
        }
    }
}

/// Two comma-separated numbers.
fn number_pair(s: &str, example: &str) -> Result<(f64, f64), String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("expected two numbers like {example}"))?;
    match v[..] {
        [a, b] => Ok((a, b)),
        _ => Err(format!("expected two numbers like {example}")),
    }
}

/// `--c2f`: 0 ≤ α₁ ≤ α₂ ≤ 1.
fn c2f_window(s: &str) -> Result<(f64, f64), String> {
    let (a1, a2) = number_pair(s, "0.4,0.7")?;
    if !((0.0..=1.0).contains(&a1) && (0.0..=1.0).contains(&a2) && a1 <= a2) {
        return Err("expected 0 ≤ α₁ ≤ α₂ ≤ 1".into());
    }
    Ok((a1, a2))
}

/// `--pose-lr`: two positive rates.
fn pose_rates(s: &str) -> Result<ExpSchedule, String> {
    let (start, end) = number_pair(s, "1e-3,1e-4")?;
    if !([start, end].iter().all(|r| r.is_finite() && *r > 0.0)) {
        return Err("expected two positive rates like 1e-3,1e-4".into());
    }
    Ok(ExpSchedule {
        start: start as f32,
        end: end as f32,
    })
}

/// `Some(true)` for `--x`, `Some(false)` for `--no-x`, `None` for neither (the schedule's).
fn switch(toggle: Option<Toggle>) -> Option<bool> {
    toggle.map(|t| t == Toggle::On)
}

impl Args {
    fn loss_switches(&self) -> LossSwitches {
        let on = |term| !self.no_loss.contains(&term);
        LossSwitches {
            matching: on(LossTerm::Matching),
            ncc: on(LossTerm::Ncc),
            geometric_consistency: on(LossTerm::Gc),
            uncertainty: on(LossTerm::Uncertainty),
            psdf: on(LossTerm::Psdf),
            eikonal: on(LossTerm::Eikonal),
        }
    }

    /// The λ given by `--lambda`; the last one wins where a name repeats.
    fn loss_weights(&self) -> LossWeights {
        let given = |name| {
            self.lambda
                .iter()
                .rev()
                .find(|(n, _)| *n == name)
                .map(|&(_, v)| v)
        };
        LossWeights {
            mc: given(WeightName::Mc),
            u: given(WeightName::U),
            gc: given(WeightName::Gc),
            geo: given(WeightName::Geo),
            psdf: given(WeightName::Psdf),
        }
    }

    /// The flags as the library's settings.
    pub fn overrides(&self) -> Overrides {
        Overrides {
            iterations: self.iterations,
            rays_per_batch: self.rays,
            matches_per_batch: self.matches_per_batch,
            seed: self.seed,
            initial_poses: match self.initial_poses {
                InitialPosesArg::Noisy => InitialPoses::NoisyGroundTruth {
                    sigma: self.pose_noise,
                },
                InitialPosesArg::Loaded => InitialPoses::AsLoaded,
            },
            pose_lr: self.pose_lr,
            pose_start: self.pose_start,
            refine_poses: !self.no_pose_refinement,
            max_pair_angle_deg: self.max_pair_angle,
            matcher: self.matcher,
            match_refine: self.match_refine.warp(),
            match_max_bend_px: self.match_max_bend,
            densify: self.densify,
            pose_warmup: switch(self.pose_warmup),
            warmup_min_matches: self.warmup_min_matches,
            warmup_cauchy_px: self.warmup_cauchy,
            warmup_connectivity: self.warmup_connectivity,
            warmup_covariance: switch(self.warmup_covariance),
            global_start: !self.no_global_start,
            bundle_adjustment: switch(self.bundle_adjustment),
            patch_adjustment: switch(self.patch_adjustment),
            encoder: self.encoder,
            fd_scheme: self.fd,
            n_coarse: self.coarse,
            n_importance: self.importance,
            losses: self.loss_switches(),
            weights: self.loss_weights(),
            use_masks: !self.no_masks,
            c2f: self.c2f,
            mesh_resolution: self.mesh_resolution as usize,
            eval_views: self.eval_views,
            eval_scale: self.eval_scale,
            checkpoint_every: self.checkpoint_every,
        }
    }

    /// The run's configuration: `--schedule` with the other flags on top.
    pub fn config(&self) -> anyhow::Result<RunConfig> {
        Ok(RunConfig::resolve(self.schedule, &self.overrides())?)
    }

    /// Where the views come from: `--synthetic` or `--data`.
    fn scene(&self) -> anyhow::Result<Scene<'_>> {
        let d = &self.dataset;
        match (self.synthetic, d.data.as_deref()) {
            (true, Some(_)) => anyhow::bail!("give either --data DIR or --synthetic, not both"),
            (true, None) => Ok(Scene::Synthetic {
                all_around: self.synthetic_all_around,
            }),
            (false, None) => anyhow::bail!("give --data DIR (or --synthetic)"),
            (false, Some(root)) => Ok(Scene::Folder {
                root,
                options: d.load_options(),
                match_downscale: self.match_downscale,
                reference: self.reference.as_deref(),
            }),
        }
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if !args.table.is_empty() {
        let rows = args
            .table
            .iter()
            .map(|r| fewview_surface::table1::read_row(r))
            .collect::<Result<Vec<_>, _>>()?;
        print!("{}", fewview_surface::table1::markdown(&rows));
        return Ok(());
    }
    let scene = args.scene()?;
    let config = args.config()?;
    let inputs = LoadedInputs::load(&scene, &config)?;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs").join(format!("surface-{}", inputs.name)));
    check_folder(&out, "--out")?;
    let ds = &inputs.dataset;
    eprintln!(
        "surface on {} ({} train views, {}x{}, {} iterations) → {}",
        ds.name,
        ds.train.len(),
        ds.views[ds.train[0]].image.width,
        ds.views[ds.train[0]].image.height,
        config.train.iterations,
        out.display()
    );
    let bar = progress::iterations(config.train.iterations as u64, "surface");
    let checkpoint = checkpoint_path(&out);
    if args.resume && !checkpoint.exists() {
        eprintln!(
            "note: --resume: no {} yet, starting from the first iteration",
            checkpoint.display()
        );
    }
    let report = fewview_surface::run(inputs.run_inputs(), &config, &out, args.resume, &mut |e| {
        print_event(&bar, e)
    })
    .with_context(|| format!("surface run in {}", out.display()))?;
    bar.finish_and_clear();
    print_report(&report, &out);
    Ok(())
}

/// Prints a pipeline event above the progress bar (or moves the bar).
fn print_event(bar: &Bar, e: Event) {
    match e {
        Event::Matched {
            matches,
            matcher,
            fallback,
            precision,
            densified_because,
        } => {
            let p = precision
                .map(|p| {
                    format!(
                        " ({:.0} % within 2 px of the true epipolar lines)",
                        100.0 * p.precision_2px
                    )
                })
                .unwrap_or_default();
            let by = matcher.map(|m| format!(" by {m}")).unwrap_or_default();
            bar.suspend(|| {
                if let Some(why) = fallback {
                    eprintln!("{why}");
                }
                if let Some(why) = densified_because {
                    eprintln!(
                        "sparse matches cannot tie the views together ({why}): growing dense ones"
                    );
                }
                eprintln!("{matches} correspondences{by}{p}")
            });
        }
        Event::Step(s) => {
            bar.set_position(s.iteration as u64 + 1);
            if s.iteration % 10 == 0 {
                bar.set_message(format!("psnr {:.2}  inv_s {:.0}", s.psnr, s.inv_s));
            }
        }
        Event::Checkpoint {
            iteration,
            pose_error,
        } => bar.suspend(|| {
            eprintln!(
                "iteration {iteration}: rotation error {:.3}°, translation error (×100) {:.3}",
                pose_error.rotation_deg,
                100.0 * pose_error.translation
            )
        }),
        Event::WarmedUp {
            report,
            pose_error,
            pair_errors_deg,
        } => bar.suspend(|| print_warmup(report, pose_error, pair_errors_deg)),
        Event::BundleAdjusted { report, pose_error } => bar.suspend(|| match &report.skipped {
            Some(why) => eprintln!("bundle adjustment skipped: {why}"),
            None => eprintln!(
                "bundle adjustment ({} tracks, {} in three views or more; {} iterations, median \
                 reprojection error {:.3} → {:.3} px): rotation error {:.3}°, translation error \
                 (×100) {:.3}",
                report.tracks,
                report.multi_view_tracks,
                report.iterations,
                report.median_px_before,
                report.median_px_after,
                pose_error.rotation_deg,
                100.0 * pose_error.translation
            ),
        }),
        Event::PatchesAdjusted { report, pose_error } => bar.suspend(|| match &report.skipped {
            Some(why) => eprintln!("patch adjustment skipped: {why}"),
            None => eprintln!(
                "patch adjustment ({} patches in {} views beyond their own, {} of them joined; \
                     {} iterations): rotation error {:.3}°, translation error (×100) {:.3}",
                report.patches,
                report.observations,
                report.joined,
                report.iterations,
                pose_error.rotation_deg,
                100.0 * pose_error.translation
            ),
        }),
        Event::PoseTimingFallback(timing) => bar.suspend(|| {
            let from = if timing.start > 0.0 {
                format!("{:.0} % into the run", 100.0 * timing.start)
            } else {
                "the first iteration".into()
            };
            eprintln!(
                "so the poses are refined from {from} at {:e} → {:e} instead (views that share \
                 few matches may need a larger --max-pair-angle: 180 matches every pair)",
                timing.lr.start, timing.lr.end
            )
        }),
        Event::Stage(st) => bar.set_message(st.to_string()),
        Event::Notice(text) => bar.suspend(|| eprintln!("note: {text}")),
    }
}

/// The global start's pairs and the epipolar warm-up's outcome.
fn print_warmup(report: &WarmupReport, pose_error: &PoseError, pair_errors_deg: &[f64]) {
    if let Some(why) = &report.global_start_failed {
        eprintln!("global start: none ({why})");
    }
    for (p, err) in report.global_start.iter().zip(pair_errors_deg) {
        eprintln!(
            "global start: views {}–{} five-point pose from {} of {} matches \
             (median {:.3} px), relative rotation {err:.3}° from the truth",
            p.view_a, p.view_b, p.inliers, p.matches, p.median_px
        );
    }
    match &report.skipped {
        Some(why) => eprintln!("epipolar warm-up skipped: {why}"),
        None => eprintln!(
            "epipolar warm-up (from the {} start, {} iterations, median Sampson distance \
             {:.2} → {:.2} px): rotation error {:.3}°, translation error (×100) {:.3}",
            report.chosen_start,
            report.iterations,
            report.initial_median_px,
            report.final_median_px,
            pose_error.rotation_deg,
            100.0 * pose_error.translation
        ),
    }
}

fn print_report(r: &RunReport, out: &std::path::Path) {
    println!(
        "poses            R {:.3}° → {:.3}°   t(×100) {:.2} → {:.2}",
        r.initial_pose_error.rotation_deg,
        r.final_pose_error.rotation_deg,
        100.0 * r.initial_pose_error.translation,
        100.0 * r.final_pose_error.translation
    );
    let warmed_up = r.warmup.as_ref().is_some_and(|w| w.skipped.is_none());
    if let Some(w) = r.warmup_pose_error.as_ref().filter(|_| warmed_up) {
        println!(
            "  after warm-up  R {:.3}°   t(×100) {:.2}",
            w.rotation_deg,
            100.0 * w.translation
        );
    }
    let bundled = r
        .bundle_adjustment
        .as_ref()
        .is_some_and(|b| b.skipped.is_none());
    if let Some(b) = r.bundle_adjustment_pose_error.as_ref().filter(|_| bundled) {
        println!(
            "  after bundle   R {:.3}°   t(×100) {:.2}",
            b.rotation_deg,
            100.0 * b.translation
        );
    }
    let adjusted = r
        .patch_adjustment
        .as_ref()
        .is_some_and(|p| p.skipped.is_none());
    if let Some(p) = r.patch_adjustment_pose_error.as_ref().filter(|_| adjusted) {
        println!(
            "  after patches  R {:.3}°   t(×100) {:.2}",
            p.rotation_deg,
            100.0 * p.translation
        );
    }
    let sparf = &r.rotation_at_sparf_eps;
    println!(
        "  at ε = {:.0e}     R {:.3}° → {}{:.3}° (SPARF's code; the surface paper Table 1's convention)",
        sparf.eps,
        sparf.initial_deg,
        [
            sparf.warmup_deg.filter(|_| warmed_up),
            sparf.bundle_adjustment_deg.filter(|_| bundled),
            sparf.patch_adjustment_deg.filter(|_| adjusted)
        ]
        .iter()
        .flatten()
        .map(|w| format!("{w:.3}° → "))
        .collect::<String>(),
        sparf.final_deg
    );
    println!(
        "training         {} iterations, {:.0} s ({:.2} it/s)",
        r.iterations, r.train_seconds_wall, r.iterations_per_second_wall
    );
    if r.pose_steps_skipped > 0 {
        println!(
            "  pose steps     {} skipped: the pose gradient was not finite (the field still stepped)",
            r.pose_steps_skipped
        );
    }
    if let (Some(p), Some(s)) = (r.mean_psnr_masked, r.mean_ssim_masked) {
        println!(
            "test views       masked PSNR {p:.2} dB, SSIM {s:.3} ({} views)",
            r.test_views.len()
        );
    }
    if let Some(c) = &r.chamfer {
        println!(
            "chamfer-L1       {:.5} ({:.2} % of the bounding-box diagonal)",
            c.chamfer_l1,
            100.0 * c.relative
        );
    }
    if let Some(c) = &r.chamfer_observed {
        println!(
            "  observed part  {:.5} ({:.2} % of the diagonal; the faces a training view sees)",
            c.chamfer_l1,
            100.0 * c.relative
        );
    }
    if let Some(why) = &r.chamfer_error {
        println!("chamfer-L1       not scored: {why}");
    }
    println!(
        "mesh             {} vertices, {} faces (mesh.ply; mesh_input_frame.ply in the input's world)",
        r.mesh_vertices, r.mesh_faces
    );
    if !r.refined_pose_files.is_empty() {
        println!("refined poses    {}", r.refined_pose_files.join(", "));
    }
    println!("written to       {}", out.display());
}

#[cfg(test)]
mod tests {
    use clap::Parser;
    use fewview_surface::matching::refine::WarpModel;
    use fewview_surface::schedule::PoseTiming;

    use super::Args;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: Args,
    }

    fn config(flags: &[&str]) -> fewview_surface::RunConfig {
        let argv = std::iter::once("surface")
            .chain(["--synthetic"])
            .chain(flags.iter().copied());
        Cli::try_parse_from(argv).unwrap().args.config().unwrap()
    }

    #[test]
    fn default_schedule_is_the_cpu_one_with_the_papers_fallback() {
        let c = config(&[]);
        assert!(c.pose_warmup.is_some());
        assert_eq!(PoseTiming::of(&c.train), PoseTiming::LATE_RELEASE);
        assert_eq!(c.pose_timing_without_warmup, Some(PoseTiming::PAPER));
    }

    #[test]
    fn paper_schedule_has_no_warm_up_and_refines_from_the_start() {
        let c = config(&["--schedule", "paper"]);
        assert!(c.pose_warmup.is_none());
        assert_eq!(PoseTiming::of(&c.train), PoseTiming::PAPER);
        assert_eq!(c.pose_timing_without_warmup, None);
        // A warm-up asked for explicitly keeps the paper's pose timing.
        let c = config(&["--schedule", "paper", "--pose-warmup", "on"]);
        assert!(c.pose_warmup.is_some());
        assert_eq!(PoseTiming::of(&c.train), PoseTiming::PAPER);
    }

    #[test]
    fn explicit_flags_override_the_schedule_and_its_fallback() {
        let c = config(&["--pose-warmup", "off"]);
        assert!(c.pose_warmup.is_none());
        let c = config(&["--pose-start", "0.5"]);
        assert_eq!(c.train.pose_start, 0.5);
        assert_eq!(c.pose_timing_without_warmup, None);
        let c = config(&["--pose-lr", "1e-2,1e-3"]);
        assert_eq!((c.train.pose_lr.start, c.train.pose_lr.end), (1e-2, 1e-3));
        assert_eq!(c.train.pose_start, 0.75);
        assert_eq!(c.pose_timing_without_warmup, None);
        let c = config(&["--warmup-min-matches", "30"]);
        assert_eq!(c.pose_warmup.unwrap().min_matches_per_pair, 30);
    }

    #[test]
    fn densify_is_automatic_explicit_or_off() {
        let c = config(&[]);
        assert_eq!(
            (c.densify.is_some(), c.densify_if_needed.is_some()),
            (false, true)
        );
        let c = config(&["--densify", "6"]);
        assert_eq!(c.densify.map(|d| d.spacing_px), Some(6));
        for off in ["off", "0"] {
            let c = config(&["--densify", off]);
            assert_eq!(
                (c.densify.is_some(), c.densify_if_needed.is_some()),
                (false, false)
            );
        }
        let c = config(&["--schedule", "paper"]);
        assert!(c.densify_if_needed.is_none());
        // A typo fails while parsing.
        let err = Cli::try_parse_from(["surface", "--densify", "dense"])
            .err()
            .expect("refused")
            .to_string();
        assert!(err.contains("--densify") && err.contains("dense"), "{err}");
    }

    #[test]
    fn match_refinement_warp_bend_limit_and_warm_up_scale_reach_the_config() {
        let c = config(&[]);
        let refine = c.match_refinement.unwrap();
        assert_eq!((refine.warp, refine.max_bend_px), (WarpModel::Affine, None));
        let c = config(&["--match-refine", "quadratic", "--match-max-bend", "4"]);
        let refine = c.match_refinement.unwrap();
        assert_eq!(
            (refine.warp, refine.max_bend_px),
            (WarpModel::Quadratic, Some(4.0))
        );
        assert!(
            config(&["--match-refine", "none"])
                .match_refinement
                .is_none()
        );
        let c = config(&["--warmup-cauchy", "0.3"]);
        assert_eq!(c.pose_warmup.unwrap().cauchy_px, 0.3);
        // The covariance polish: on with the CPU schedule, off with the paper's (whose
        // warm-up, when asked for, is the plain one), and either way by flag.
        assert!(c.pose_warmup.unwrap().covariance_polish);
        let c = config(&["--warmup-covariance", "off"]);
        assert!(!c.pose_warmup.unwrap().covariance_polish);
        let c = config(&["--schedule", "paper", "--pose-warmup", "on"]);
        assert!(!c.pose_warmup.unwrap().covariance_polish);
        let c = config(&[
            "--schedule",
            "paper",
            "--pose-warmup",
            "on",
            "--warmup-covariance",
            "on",
        ]);
        assert!(c.pose_warmup.unwrap().covariance_polish);
        let refused = |flags: &[&str]| {
            let argv = ["surface", "--synthetic"]
                .into_iter()
                .chain(flags.iter().copied());
            match Cli::try_parse_from(argv) {
                Err(e) => e.to_string(),
                Ok(cli) => cli.args.config().unwrap_err().to_string(),
            }
        };
        let err = refused(&["--match-max-bend", "4"]);
        assert!(err.contains("--match-refine quadratic"), "{err}");
        let err = refused(&["--match-refine", "cubic"]);
        assert!(
            err.contains("--match-refine") && err.contains("cubic"),
            "{err}"
        );
        assert!(refused(&["--warmup-cauchy", "0"]).contains("--warmup-cauchy"));
        assert!(refused(&["--match-max-bend", "NaN"]).contains("--match-max-bend"));
    }

    #[test]
    fn loss_switches_and_weights_reach_the_overrides() {
        let argv = [
            "surface",
            "--no-loss",
            "ncc,gc",
            "--no-loss",
            "eikonal",
            "--lambda",
            "u=0.02,GC=0",
            "--lambda",
            "u=0.5",
        ];
        let args = Cli::try_parse_from(argv).unwrap().args;
        let on = args.loss_switches();
        assert_eq!(
            (on.matching, on.ncc, on.geometric_consistency),
            (true, false, false)
        );
        assert_eq!((on.uncertainty, on.psdf, on.eikonal), (true, true, false));
        let w = args.loss_weights();
        assert_eq!(
            (w.u, w.gc, w.mc, w.geo, w.psdf),
            (Some(0.5), Some(0.0), None, None, None)
        );
        for bad in ["u", "v=1", "u=-1", "u=NaN"] {
            let err = Cli::try_parse_from(["surface", "--lambda", bad])
                .err()
                .expect("refused")
                .to_string();
            assert!(err.contains("--lambda") && err.contains(bad), "{err}");
        }
        assert!(Cli::try_parse_from(["surface", "--no-loss", "colour"]).is_err());
    }

    #[test]
    fn contradictory_or_bad_schedule_flags_are_refused() {
        let parse = |flags: &[&str]| {
            Cli::try_parse_from(std::iter::once("surface").chain(flags.iter().copied()))
        };
        assert!(parse(&["--pose-warmup", "on", "--pose-warmup", "off"]).is_err());
        assert!(parse(&["--pose-warmup", "yes"]).is_err());
        assert!(parse(&["--schedule", "fast"]).is_err());
        let args = parse(&["--pose-start", "1.5"]).unwrap().args;
        let err = args.config().unwrap_err().to_string();
        assert!(err.contains("--pose-start 1.5"), "{err}");
    }
}
