//! The `surface` command's flags and their translation into the library's [`Overrides`].

use std::path::PathBuf;

use clap::Args as ClapArgs;
use fewview_surface::adam::ExpSchedule;
use fewview_surface::field::{EncoderKind, FdScheme};
use fewview_surface::matching::learned::MatcherKind;
use fewview_surface::warmup::Connectivity;
use fewview_surface::{
    DEFAULT_POSE_NOISE, Densify, InitialPoses, LossSwitches, LossWeights, Overrides, RunConfig,
    Scene, Schedule,
};

use super::flags::{
    LossTerm, MAX_MESH_RESOLUTION, MatchRefine, Toggle, WeightName, c2f_window, loss_weight,
    match_refine, pose_noise, pose_rates, switch,
};
use crate::commands::dataset_args::DatasetArgs;

/// The library's defaults, the one source of every flag's default below.
fn defaults() -> Overrides {
    Overrides::default()
}

/// Reconstruct a surface (NeuS SDF) and refine noisy camera poses from a few views (the surface paper):
/// a run directory with the refined poses, `mesh.ply`, renders and `metrics.json`.
#[derive(Debug, ClapArgs)]
#[command(mut_arg("data", |a| a.required(false)))]
pub struct Args {
    #[command(flatten)]
    pub dataset: DatasetArgs,
    /// Use the built-in analytic scene.
    ///
    /// Use the built-in sphere-traced analytic scene instead of `--data`.
    #[arg(long)]
    pub synthetic: bool,
    /// With `--synthetic`: add views from below.
    ///
    /// With `--synthetic`: add 16 training views at 0° and −30° elevation, so that the
    /// underside is observed too.
    #[arg(long, requires = "synthetic")]
    pub synthetic_all_around: bool,
    /// Run directory. Default: `runs/surface-<dataset folder name>`.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Print Table 1 of these finished runs instead.
    ///
    /// Instead of a run: print the surface paper's Table 1 (Markdown) for these finished runs.
    #[arg(long, num_args = 1.., value_name = "RUN", conflicts_with_all = ["synthetic", "out", "resume"])]
    pub table: Vec<PathBuf>,
    /// Continue the run in `--out`.
    ///
    /// From its checkpoint; only --iterations, --checkpoint-every and the output settings may
    /// change.
    #[arg(long)]
    pub resume: bool,
    /// Training iterations.
    ///
    /// The surface paper: 100k on a GPU; the default fits a CPU budget.
    #[arg(long, default_value_t = defaults().iterations)]
    pub iterations: usize,
    /// Random rays per iteration.
    #[arg(long, default_value_t = defaults().rays_per_batch)]
    pub rays: usize,
    /// Correspondences per iteration (two rays each).
    #[arg(long, value_name = "N", default_value_t = defaults().matches_per_batch)]
    pub matches_per_batch: usize,
    /// σ of the se(3) pose noise (0 = ground-truth poses; at most π).
    #[arg(long, default_value_t = DEFAULT_POSE_NOISE, value_parser = pose_noise)]
    pub pose_noise: f64,
    /// Start from noisy true poses or the dataset's.
    ///
    /// Start from the perturbed ground truth (`noisy`) or from the dataset's poses (`loaded`).
    #[arg(long, value_enum, default_value = "noisy")]
    pub initial_poses: InitialPoses,
    /// Pose schedule: the paper's, or `cpu`.
    ///
    /// Pose schedule (`cpu`: deviations from the surface paper's §B.1 that converge on a CPU
    /// budget).
    #[arg(long, value_enum, default_value_t)]
    pub schedule: Schedule,
    /// Pose learning rate at the start and end.
    ///
    /// Of its decay (default from `--schedule`).
    #[arg(long, value_name = "START,END", value_parser = pose_rates)]
    pub pose_lr: Option<ExpSchedule>,
    /// Keep the poses fixed.
    ///
    /// Before training too: the warm-up and the bundle and patch adjustments are off unless
    /// switched on by their own flags.
    #[arg(long)]
    pub no_pose_refinement: bool,
    /// Downscale factor of the matcher's images.
    ///
    /// Downscale factor of the images the matcher sees; must divide `--downscale`.
    #[arg(long, default_value_t = 1, value_name = "K")]
    pub match_downscale: u32,
    /// Largest angle (°) between matched views.
    ///
    /// Match only views whose optical axes are at most this many degrees apart (180: all).
    #[arg(long, default_value_t = defaults().max_pair_angle_deg, value_name = "DEG")]
    pub max_pair_angle: f64,
    /// Matcher: classical, xfeat, xfeat-star, lighterglue.
    ///
    /// Which matcher finds the correspondences: `classical` (SIFT), or the learned XFeat with
    /// mutual nearest neighbours (`xfeat`), semi-dense and refined (`xfeat-star`), or matched by
    /// LighterGlue (`lighterglue`); their weights come from `scripts/setup.sh`, and without
    /// them the run says so and uses the classical matcher.
    #[arg(long, value_enum, default_value_t = defaults().matcher)]
    pub matcher: MatcherKind,
    /// Sub-pixel refinement of the matches.
    ///
    /// By Lucas–Kanade (a deviation from the surface paper).
    ///
    /// `affine` (default), `quadratic` or `none`.
    #[arg(long, default_value = "affine", value_parser = match_refine)]
    pub match_refine: MatchRefine,
    /// Largest bend (px) of a quadratic refinement.
    ///
    /// With `--match-refine quadratic`: drop matches whose second-order term moves a window
    /// point by more than this many pixels.
    #[arg(long, value_name = "PX", value_parser = crate::commands::number_args::positive)]
    pub match_max_bend: Option<f64>,
    /// Grow dense matches on a grid of this spacing.
    ///
    /// A deviation; `auto`: only when the sparse ones cannot tie the views together for the
    /// warm-up.
    #[arg(long, default_value = "auto", value_name = "PX|auto|off")]
    pub densify: Densify,
    /// Refine the poses on epipolar constraints first.
    ///
    /// Refine the initial poses on the matches' epipolar constraints before training (default
    /// from `--schedule`).
    #[arg(long, value_name = "on|off")]
    pub pose_warmup: Option<Toggle>,
    /// Fewest matches of a pair in the warm-up.
    ///
    /// The warm-up uses only the pairs of views with at least this many matches.
    #[arg(long, default_value_t = defaults().warmup_min_matches, value_name = "N")]
    pub warmup_min_matches: usize,
    /// Final scale (px) of the warm-up's Cauchy loss.
    ///
    /// Final scale (pixels) of the warm-up's Cauchy loss on the Sampson distances.
    #[arg(long, default_value_t = defaults().warmup_cauchy_px, value_name = "PX",
          value_parser = crate::commands::number_args::positive)]
    pub warmup_cauchy: f64,
    /// Weight dense matches by their covariance.
    ///
    /// Polish the warmed-up poses with each dense match weighted by its Lucas–Kanade
    /// covariance (default from `--schedule`).
    #[arg(long, value_name = "on|off")]
    pub warmup_covariance: Option<Toggle>,
    /// Warm up without the global start.
    ///
    /// Start the warm-up from the initial poses, without the global start from the matches.
    #[arg(long)]
    pub no_global_start: bool,
    /// Refine the poses photometrically on patches.
    ///
    /// After a warm-up on dense matches, refine the poses photometrically on small planes
    /// seeded by the matches (default from `--schedule`).
    #[arg(long, value_name = "on|off")]
    pub patch_adjustment: Option<Toggle>,
    /// Bundle-adjust the tracks after the warm-up.
    ///
    /// Bundle-adjust the matches' tracks after the warm-up (default from `--schedule`).
    #[arg(long, value_name = "on|off")]
    pub bundle_adjustment: Option<Toggle>,
    /// What the warm-up's pairs must form.
    #[arg(long, value_name = "KIND", value_enum, default_value_t)]
    pub warmup_connectivity: Connectivity,
    /// Fraction of iterations with fixed poses.
    ///
    /// Hold the poses fixed for this fraction of the iterations (default from `--schedule`).
    #[arg(long, value_name = "FRACTION")]
    pub pose_start: Option<f64>,
    /// Seed of the noise, sampling and initialisation.
    #[arg(long, default_value_t = defaults().seed)]
    pub seed: u64,
    /// Geometry encoder.
    ///
    /// `neus-mlp`: the paper's 8×256 MLP, slow on a CPU.
    #[arg(long, value_enum, default_value_t = defaults().encoder)]
    pub encoder: EncoderKind,
    /// Finite-difference stencil of the normals (4 or 6 taps).
    #[arg(long, value_enum, default_value_t = defaults().fd_scheme)]
    pub fd: FdScheme,
    /// Coarse samples per ray.
    #[arg(long, default_value_t = defaults().n_coarse)]
    pub coarse: usize,
    /// Importance samples per ray.
    #[arg(long, default_value_t = defaults().n_importance)]
    pub importance: usize,
    /// Switch loss terms off, e.g. `ncc,gc`.
    ///
    /// Switch loss terms off for ablations, e.g. `--no-loss ncc,gc`.
    #[arg(long, value_name = "TERM,...", value_delimiter = ',')]
    pub no_loss: Vec<LossTerm>,
    /// Do not use object masks.
    ///
    /// Colour loss on all pixels, no mask loss, no culling.
    #[arg(long)]
    pub no_masks: bool,
    /// Loss weights λ, e.g. `u=0.02,gc=0`.
    ///
    /// Loss weights λ (mc, u, gc, geo, psdf), finite and ≥ 0, e.g. `--lambda u=0.02,gc=0`
    /// (defaults: the surface paper §B.1).
    #[arg(long, value_name = "NAME=VALUE,...", value_delimiter = ',', value_parser = loss_weight)]
    pub lambda: Vec<(WeightName, f32)>,
    /// Coarse-to-fine window (α₁, α₂).
    ///
    /// As fractions of the iterations, e.g. `0.4,0.7`.
    #[arg(long, value_name = "A1,A2", value_parser = c2f_window)]
    pub c2f: Option<(f64, f64)>,
    /// Marching-cubes resolution over [−1, 1]³ (2 to 2048).
    #[arg(long, value_name = "N", default_value_t = defaults().mesh_resolution as u32,
          value_parser = clap::value_parser!(u32).range(2..=MAX_MESH_RESOLUTION))]
    pub mesh_resolution: u32,
    /// Test views rendered and scored.
    #[arg(long, default_value_t = defaults().eval_views)]
    pub eval_views: usize,
    /// Render test views at 1/K of their size.
    #[arg(long, default_value_t = defaults().eval_scale, value_parser = clap::value_parser!(u32).range(1..))]
    pub eval_scale: u32,
    /// Reference surface for Chamfer.
    ///
    /// Reference surface (PLY/OBJ, in the dataset's normalised frame) for Chamfer.
    #[arg(long, value_name = "FILE")]
    pub reference: Option<PathBuf>,
    /// Iterations between checkpoints.
    #[arg(long, value_name = "N", default_value_t = defaults().checkpoint_every)]
    pub checkpoint_every: usize,
}

impl Args {
    pub(super) fn loss_switches(&self) -> LossSwitches {
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
    pub(super) fn loss_weights(&self) -> LossWeights {
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
            initial_poses: self.initial_poses.clone().with_noise(self.pose_noise),
            pose_lr: self.pose_lr,
            pose_start: self.pose_start,
            refine_poses: !self.no_pose_refinement,
            max_pair_angle_deg: self.max_pair_angle,
            matcher: self.matcher,
            match_refine: self.match_refine.0,
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
    pub(super) fn scene(&self) -> anyhow::Result<Scene<'_>> {
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
