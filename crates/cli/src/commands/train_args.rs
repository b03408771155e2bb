//! Training flags shared by `train` and `demo`.

use std::path::PathBuf;

use super::geometry_args::GeometryArgs;
use anyhow::bail;
use clap::{Args, ValueEnum};
use fewview_geom::stereo::source::Photometry;
use fewview_match::learned::MatcherKind;
use fewview_splat::ComputeDevice;
use fewview_splat::pipeline::{InitStrategy, MAX_INIT_POINTS, RunConfig};
use fewview_splat::sky_shell::SkyShell;
use fewview_splat::stereo_pair_check::PairCheck;
use fewview_splat::stereo_start::{DepthFrom, StereoInit};
use fewview_splat::surface_start::SurfacePoses;
use fewview_splat::train::{AppearanceConfig, AppearanceModel, TrainConfig};

/// What the Gaussians are composited over during training on images with alpha.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum TrainBackground {
    Random,
    Fixed,
}

impl TrainBackground {
    /// The choice a library `random_background` flag stands for.
    fn of(random: bool) -> Self {
        if random { Self::Random } else { Self::Fixed }
    }
}

#[derive(Debug, Clone, Args)]
pub struct TrainArgs {
    /// Training iterations (default: by scene).
    ///
    /// Training iterations (default for `train`: 1000 on forward-facing scenes with depth bounds, e.g. LLFF, otherwise 3000 or 50 per training view, whichever is more; `demo`: 2000). The densification
    /// schedule is rescaled to the run length (see `TrainConfig::sparse_view` and docs/guide/splatting.md).
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Iterations over which the position learning rate decays.
    ///
    /// The position learning rate falls log-linearly from 1.6e-4 to 1.6e-6 (times the scene
    /// extent) over this many iterations and stays there after (Inria's
    /// `position_lr_max_steps`, 30000). FSGS, DNGaussian and CoR-GS set it to their run length;
    /// a short run with the default keeps its early step sizes to the end.
    #[arg(long, value_name = "N", default_value_t = TrainConfig::sparse_view(1).lr.position_decay_steps,
          value_parser = super::number_args::positive_count)]
    pub position_lr_steps: usize,
    /// Seed of every random choice (initialisation, view order, splits of Gaussians).
    #[arg(long, default_value_t = TrainConfig::inria().seed)]
    pub seed: u64,
    /// Largest spherical-harmonics degree (0–3).
    #[arg(long, default_value_t = TrainConfig::inria().sh_degree)]
    pub sh_degree: usize,
    /// Initial Gaussians: auto, stereo, surface, …
    ///
    /// Initial Gaussians: `auto` (dataset points; else `stereo` when at least two training views
    /// overlap; else random in the training frustums when the views have depth bounds, else
    /// random in a box), `stereo` (the fusion paper's supplement §2: the hierarchical
    /// point cloud of the training views' stereo pairs, by Semi-Global Matching), `depth:DIR`
    /// (the same from your own depth maps, `DIR/<view>.npy` float z-depth or 16-bit `.png` in
    /// millimetres), `points`, `frustum`, `box`, `box:HALF_SIZE`, `ply:FILE`, or `surface:DIR`
    /// (Gaussians on the mesh of the `surface` run in DIR, flat along its normals, for views
    /// too far apart for stereo; the run must be of the same dataset and training views), or
    /// `surface` (the surface method runs first, from the input's poses, into `OUT/surface`;
    /// a finished one is reused, an interrupted one resumed).
    #[arg(long, default_value = "auto", value_name = "HOW")]
    pub init: String,
    /// With a surface start: whose poses to train with.
    ///
    /// With `--init surface:DIR`: train with the surface run's refined poses (`refined`), the
    /// dataset's (`dataset`), or the refined ones when the surface run started from poses other
    /// than the dataset's (`auto`; with a bare `--init surface`, which refines the input's own
    /// poses: the refined ones).
    #[arg(long, value_enum, default_value_t)]
    pub surface_poses: SurfacePoses,
    /// With a surface start: weight of its depth loss.
    ///
    /// With `--init surface:DIR`: weight of the L1 distance between the rendered depth and the
    /// mesh's depth in the training views, relative to the mesh's depth (0: none).
    #[arg(long, value_name = "W",
          default_value_t = fewview_splat::surface_start::SURFACE_DEPTH_WEIGHT,
          value_parser = super::number_args::non_negative_f32)]
    pub surface_depth_weight: f32,
    /// Fraction of the stereo points that become Gaussians.
    ///
    /// Fraction of the stereo point cloud that becomes Gaussians (the fusion paper: 0.1; its
    /// sparse alternative (a): 0.01), whenever the stereo start runs (`stereo`, `depth:DIR`, or
    /// `auto` choosing it).
    #[arg(long, value_name = "F", default_value_t = StereoInit::default().fraction,
          value_parser = super::number_args::fraction)]
    pub stereo_fraction: f64,
    /// The most Gaussians the stereo start gives (0: no cap).
    ///
    /// A stereo cloud larger than this over `--stereo-fraction` is sampled more sparsely, so that
    /// the start gives at most this many Gaussians (0: no cap, the fusion paper's fraction
    /// whatever the cloud). Many photos of a long scene give millions of points; each Gaussian
    /// costs training time on every iteration.
    #[arg(long, value_name = "N", default_value_t = StereoInit::default().max_points)]
    pub stereo_max_points: usize,
    /// Gaussians for the sky and far background: auto, on or off.
    ///
    /// A shell of Gaussians on the sphere beyond the stereo start's far bound (Eq. 2's `B_far`
    /// around `T`), one per 16-px block of a training view where the stereo found no depth, in
    /// the block's colour: the sky and far background then start where they are instead of
    /// being filled by floaters in front of the cameras. `auto`: on for a folder of photos and
    /// for `benchmark --protocol dtu` (its black curtain), off for other datasets with their own
    /// poses. Not in the fusion paper.
    #[arg(long, value_name = "HOW", value_enum, default_value_t)]
    pub sky_shell: SkyShell,
    /// How the stereo start evens the pairs' exposures.
    ///
    /// How the stereo start brings each pair's photos to one brightness before matching: `as-is`
    /// (OpenCV's matcher, robust to moderate exposure differences) or `gain-matched` (a gain per
    /// channel first; keeps more points when the photos' exposures differ by more than about
    /// one EV).
    #[arg(long, value_name = "HOW", value_enum, default_value_t)]
    pub stereo_photometry: Photometry,
    /// Check each stereo pair by this matcher's correspondences.
    ///
    /// A pair that overlaps by geometry is kept only when the matcher (`classical` SIFT, `xfeat`,
    /// `xfeat-star` or `lighterglue`) finds `--stereo-pair-matches` correspondences within 2 px
    /// of the epipolar lines its cameras draw; `stereo.json` lists each pair's counts. Off by
    /// default: the fusion paper matches every overlapping pair.
    #[arg(long, value_name = "MATCHER", value_enum)]
    pub stereo_pair_check: Option<MatcherKind>,
    /// Fewest consistent correspondences of a checked stereo pair.
    #[arg(long, value_name = "N", default_value_t = PairCheck::default().min_matches,
          requires = "stereo_pair_check")]
    pub stereo_pair_matches: usize,
    /// Number of random initial points.
    #[arg(long, default_value_t = RunConfig::new(TrainConfig::inria()).init_points)]
    pub init_points: usize,
    /// Weight λ of the SSIM term in `(1 − λ) L1 + λ (1 − SSIM)`.
    #[arg(long, default_value_t = TrainConfig::inria().lambda_dssim)]
    pub lambda_dssim: f32,
    /// Densification threshold on the mean screen-space position gradient.
    ///
    /// A Gaussian whose mean screen-space position gradient exceeds this is cloned or split
    /// (3DGS §5.2; Inria's 0.0002). Raising it densifies less: FSGS and CoR-GS train their
    /// sparse-view runs at 0.0005.
    #[arg(long, value_name = "G", default_value_t = TrainConfig::sparse_view(1).densify.grad_threshold,
          value_parser = super::number_args::non_negative_f32)]
    pub densify_grad_threshold: f32,
    /// Background of training images with alpha.
    ///
    /// Background behind the Gaussians while training on images with alpha (NeRF-synthetic
    /// RGBA): `random` (a random colour each iteration, the target re-composited over it, as
    /// nerfstudio's splatfacto; a deviation from the fusion paper, it removes floaters that a
    /// fixed background hides) or `fixed` (the dataset's background, as the fusion paper and
    /// Inria 3DGS). Opaque photos always train over the fixed background.
    #[arg(long, value_name = "HOW", value_enum,
          default_value_t = TrainBackground::of(TrainConfig::sparse_view(1).random_background))]
    pub train_background: TrainBackground,
    /// Largest opacity-dropout rate (DropGaussian), 0: off [default: 0.2; fusion, demo: 0].
    ///
    /// DropGaussian's opacity dropout: each training render leaves out this share of the
    /// Gaussians at the last iteration (growing linearly from 0) and scales the others' opacity to
    /// compensate, so that a few views cannot be fitted by Gaussians leaning on each other.
    /// Default: DropGaussian's γ = 0.2 for `train` and `benchmark` (`TrainConfig::sparse_view`),
    /// none for `fusion` and `demo`, whose transitions it did not improve
    /// (`fewview_fusion::FUSION_DROPOUT`).
    #[arg(long, value_name = "GAMMA", value_parser = super::number_args::non_negative_f32)]
    pub dropout: Option<f32>,
    #[command(flatten)]
    pub geometry: GeometryArgs,
    /// Save a checkpoint every N iterations (0: never).
    #[arg(long, value_name = "N", default_value_t = 500)]
    pub checkpoint_every: usize,
    /// Where to train: cpu, or gpu (`--features gpu`).
    ///
    /// Where to train: `cpu` (every build) or `gpu` (the first GPU wgpu finds: Vulkan, Metal or
    /// DX12; builds with `--features gpu`). The two agree to rounding, not bit for bit.
    #[arg(long, value_enum, default_value_t)]
    pub device: ComputeDevice,
    /// Per-photo colour transform learned in training.
    ///
    /// Per-photo appearance: `affine` learns a 3×4 colour transform per training photo, applied
    /// to the render before the loss (identity at the start, pulled towards it), so photos whose
    /// exposure or white balance differ need not be explained by the Gaussians' colours; new
    /// views are rendered without it (gsplat's appearance optimisation, a bilateral grid of one
    /// cell). `none` compares renders with the photos as they are.
    #[arg(long, value_enum, default_value_t)]
    pub appearance: AppearanceModel,
    /// Adam learning rate of the colour transforms.
    #[arg(long, value_name = "LR", default_value_t = AppearanceConfig::default().lr,
          value_parser = super::number_args::non_negative_f32)]
    pub appearance_lr: f32,
    /// Pull of each colour transform to the identity.
    ///
    /// Weight of the squared distance of each colour transform to the identity.
    #[arg(long, value_name = "W", default_value_t = AppearanceConfig::default().weight,
          value_parser = super::number_args::non_negative_f32)]
    pub appearance_weight: f32,
}

impl TrainArgs {
    /// [`Self::run_config`] for a run whose product is a transition (`fusion`, `demo`): without
    /// `--dropout`, the fusion method's own rate ([`fewview_fusion::FUSION_DROPOUT`]).
    pub fn transition_run_config(
        &self,
        background: [f32; 3],
        default_iterations: usize,
        photos: bool,
    ) -> anyhow::Result<RunConfig> {
        let mut cfg = self.run_config(background, default_iterations, photos)?;
        if self.dropout.is_none() {
            cfg.train.dropout = fewview_fusion::FUSION_DROPOUT;
        }
        Ok(cfg)
    }

    /// The run's configuration; `photos` says the data is a folder of photos whose poses the
    /// run estimated (it decides `--sky-shell auto`).
    pub fn run_config(
        &self,
        background: [f32; 3],
        default_iterations: usize,
        photos: bool,
    ) -> anyhow::Result<RunConfig> {
        let mut train = TrainConfig::sparse_view(self.iterations.unwrap_or(default_iterations));
        train.seed = self.seed;
        train.lr.position_decay_steps = self.position_lr_steps;
        train.sh_degree = self.sh_degree;
        train.lambda_dssim = self.lambda_dssim;
        train.densify.grad_threshold = self.densify_grad_threshold;
        train.background = background;
        train.random_background = self.train_background == TrainBackground::Random;
        train.checkpoint_interval = self.checkpoint_every;
        train.dropout = self.dropout.unwrap_or(train.dropout);
        train.appearance = AppearanceConfig {
            model: self.appearance,
            lr: self.appearance_lr,
            weight: self.appearance_weight,
        };
        if let Err(m) = train.validate() {
            bail!("invalid training options: {m}");
        }
        let (init, depth) = parse_init(&self.init)?;
        let stereo = StereoInit {
            depth,
            fraction: self.stereo_fraction,
            max_points: self.stereo_max_points,
            sky_shell: self.sky_shell.resolve(photos),
            photometry: self.stereo_photometry,
            pair_check: PairCheck {
                matcher: self.stereo_pair_check,
                min_matches: self.stereo_pair_matches,
                ..PairCheck::default()
            },
            ..StereoInit::default()
        };
        if self.init_points == 0 {
            bail!("--init-points must be at least 1");
        }
        if self.init_points > MAX_INIT_POINTS {
            bail!(
                "--init-points {}: more than the {MAX_INIT_POINTS} initial Gaussians allowed \
                 (each needs about 1 KB while training)",
                self.init_points
            );
        }
        Ok(RunConfig {
            train,
            init,
            init_points: self.init_points,
            stereo,
            device: self.device,
            surface_depth_weight: self.surface_depth_weight,
            stereo_depth_weight: self.geometry.stereo_depth_weight,
            pseudo_depth_weight: self.geometry.pseudo_depth_weight.unwrap_or(0.0),
            floater_weight: self.geometry.floater_weight,
            co_reg: self.geometry.co_reg(),
        })
    }
}

/// The largest `--init box:HALF_SIZE`. Gaussian positions, scales and their squares are single
/// precision: 1e300 became an infinite position and failed only once the run folder existed.
/// 10⁶ units is beyond any scene a camera rig sees (LLFF and COLMAP scenes span units to
/// hundreds, DTU's millimetres about a thousand) while the scales' squares (about (half/15)²)
/// and their projections stay far inside single precision.
const MAX_BOX_HALF_SIZE: f64 = 1e6;

/// The strategy of `--init`, and where the stereo start's depth comes from.
fn parse_init(s: &str) -> anyhow::Result<(InitStrategy, DepthFrom)> {
    if let Some(dir) = s.strip_prefix("depth:") {
        return Ok((InitStrategy::Stereo, DepthFrom::Maps(PathBuf::from(dir))));
    }
    let strategy = match s {
        "auto" => InitStrategy::Auto,
        "points" => InitStrategy::DatasetPoints,
        "frustum" => InitStrategy::RandomFrustum,
        "box" => InitStrategy::RandomBox { half_size: None },
        _ if s.starts_with("box:") => {
            let v: f64 = s[4..]
                .parse()
                .map_err(|_| anyhow::anyhow!("--init {s}: `{}` is not a number", &s[4..]))?;
            if !(v.is_finite() && v > 0.0) {
                bail!("--init {s}: the half-size must be positive");
            }
            if v > MAX_BOX_HALF_SIZE {
                bail!(
                    "--init {s}: the half-size must be at most {MAX_BOX_HALF_SIZE:e} scene units"
                );
            }
            InitStrategy::RandomBox { half_size: Some(v) }
        }
        _ if s.starts_with("ply:") => InitStrategy::Ply(PathBuf::from(&s[4..])),
        _ if s.starts_with("surface:") => InitStrategy::Surface(PathBuf::from(&s[8..])),
        "surface" => bail!(
            "--init surface: runs the surface method on a dataset first (`train` or `fusion` with \
             --data); give surface:DIR to start from a finished surface run"
        ),
        "stereo" => InitStrategy::Stereo,
        _ => bail!(
            "--init {s}: expected auto, stereo, depth:DIR, points, frustum, box, box:HALF_SIZE, ply:FILE, surface or surface:DIR"
        ),
    };
    Ok((strategy, DepthFrom::Sgm))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::commands::parse_for_tests::parse;

    /// The flags' defaults are the library's (the Inria schedule's, which the sparse-view one
    /// keeps): an empty command line gives the sparse-view schedule's training settings and
    /// the library's start, but for the command's own choice of a checkpoint every 500
    /// iterations.
    #[test]
    fn an_empty_command_line_gives_the_librarys_defaults() {
        let args: TrainArgs = parse(&["train"]);
        let run = args.run_config([0.0; 3], 1000, false).unwrap();
        let library = RunConfig::new(TrainConfig::sparse_view(1000));
        let mut train = run.train.clone();
        assert_eq!(train.checkpoint_interval, 500);
        assert!(train.random_background);
        train.checkpoint_interval = library.train.checkpoint_interval;
        assert_eq!(train, library.train);
        assert_eq!(run.init_points, library.init_points);
        assert_eq!(run.stereo, library.stereo);
        assert_eq!(run.surface_depth_weight, library.surface_depth_weight);
        assert_eq!(run.stereo_depth_weight, library.stereo_depth_weight);
        assert_eq!(run.pseudo_depth_weight, library.pseudo_depth_weight);
        assert_eq!(run.co_reg, library.co_reg);
        assert_eq!(run.floater_weight, library.floater_weight);
    }

    /// `train` drops Gaussians as the library's sparse-view schedule does, a transition run
    /// as the fusion method does, and `--dropout` sets both.
    #[test]
    fn dropout_defaults_by_product_and_the_flag_sets_it() {
        let args: TrainArgs = parse(&["train"]);
        let library = TrainConfig::sparse_view(1000).dropout;
        assert_eq!(
            args.run_config([0.0; 3], 1000, false)
                .unwrap()
                .train
                .dropout,
            library
        );
        let transition = args.transition_run_config([0.0; 3], 1000, false).unwrap();
        assert_eq!(transition.train.dropout, fewview_fusion::FUSION_DROPOUT);
        let args: TrainArgs = parse(&["train", "--dropout", "0.3"]);
        assert_eq!(
            args.run_config([0.0; 3], 1000, false)
                .unwrap()
                .train
                .dropout,
            0.3
        );
        let transition = args.transition_run_config([0.0; 3], 1000, false).unwrap();
        assert_eq!(transition.train.dropout, 0.3);
    }
}
