//! `fewview surface`: neural implicit surface + pose refinement from a few views with noisy
//! poses (paper 001).

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args as ClapArgs;
use fewview_scene::pose_export::PoseSource;
use fewview_surface::field::{EncoderKind, FdScheme};
use fewview_surface::matching::densify::DensifyOptions;
use fewview_surface::matching::refine::{AffineRefineOptions, WarpModel};
use fewview_surface::matching::sift::SiftOptions;
use fewview_surface::patch_adjustment::PatchAdjustmentOptions;
use fewview_surface::pipeline::{
    Event, InitialPoses, RunConfig, RunInputs, RunReport, run as run_pipeline,
};
use fewview_surface::schedule::Schedule;
use fewview_surface::sdf_scene::{SdfSceneOptions, sdf_dataset};
use fewview_surface::warmup::{Connectivity, WarmupOptions};

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

/// Reconstruct a surface (NeuS SDF) and refine noisy camera poses from a few views.
///
/// The ground-truth poses of the training views are perturbed with se(3) noise N(0, σ²)
/// (`--pose-noise`, BARF/SPARF protocol) unless `--initial-poses loaded` keeps the loaded
/// poses (e.g. DTU `--cameras-file cameras_linear_init.npz`). Correspondences come from SIFT
/// (ratio + mutual check + RANSAC). Writes a run directory: `config.json`, `checkpoint.bin`
/// (resume with `--resume`), `matches.json`, `poses_initial.json`, `poses_refined.json`, the
/// input's camera file with the refined poses in its own format (`cameras_sphere_refined.npz`,
/// `poses_bounds_refined.npy`, `transforms_refined.json`, `sparse_refined/`…), `mesh.ply`
/// (the estimate's frame) and `mesh_input_frame.ply` (the input's world, e.g. DTU millimetres),
/// `renders/` (PNGs and `NNN_depth.npy` depth maps in the input's units), `metrics.json` (pose
/// errors by paper 001 Alg. 1/2, masked PSNR/SSIM of test views, Chamfer with `--reference`).
///
/// Without `--data`, `--synthetic` runs on the built-in analytic SDF scene and scores the mesh
/// against its exact surface.
#[derive(Debug, ClapArgs)]
#[command(mut_arg("data", |a| a.required(false)))]
pub struct Args {
    #[command(flatten)]
    pub dataset: DatasetArgs,
    /// Use the built-in sphere-traced analytic scene instead of `--data`.
    #[arg(long)]
    pub synthetic: bool,
    /// With `--synthetic`: add 16 training views on rings at 0° and −30° elevation, so that
    /// the underside, which the eight training views at 30° never see, is observed too.
    #[arg(long, requires = "synthetic")]
    pub synthetic_all_around: bool,
    /// Run directory. Default: `runs/surface-<dataset folder name>`.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Instead of a run: print paper 001's Table 1 for these finished runs (Markdown): the
    /// initial, warm-up and final rotation and translation errors, the masked PSNR and the wall
    /// time of each, beside the paper's row for its scan and triplet and whether it meets the
    /// targets (rotation ≤ 0.1°, translation ×100 ≤ 1.25 × the paper's).
    /// `scripts/surface_table1.sh` runs the whole protocol.
    #[arg(long, num_args = 1.., value_name = "RUN", conflicts_with_all = ["synthetic", "out", "resume"])]
    pub table: Vec<PathBuf>,
    /// Continue the run in `--out` from its checkpoint. Same data and flags as the first time;
    /// only --iterations (to extend), --checkpoint-every and the output settings (--mesh-resolution,
    /// --eval-views, --eval-scale) may change. A checkpoint of another run is refused.
    #[arg(long)]
    pub resume: bool,
    /// Training iterations (the paper: 100k on a GPU). The default fits the 40-minute CPU budget
    /// at about one CPU-second per iteration (scan65, 400×300); see crates/surface/README.md
    /// for what it reaches.
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
    /// `noisy` (perturbed ground truth) or `loaded` (the dataset's poses as the start).
    #[arg(long, default_value = "noisy")]
    pub initial_poses: String,
    /// Pose schedule: `cpu` (default; deviations from paper 001 that converge in the CPU
    /// budget, measured on DTU scan65's narrow triplet: 12° → 0.083–0.092°): the epipolar
    /// warm-up, then the poses held for the first 75 % of the iterations and refined at
    /// 1e-4 → 1e-5; dense matches are grown first when the sparse ones cannot tie the views
    /// together for the warm-up (`--densify auto`), and if it still declines, the poses are
    /// refined from the first iteration at the paper's rate instead. `paper`: no warm-up,
    /// refined from the first iteration at 1e-3 → 1e-4 (paper 001 §B.1).
    /// `--pose-warmup`/`--no-pose-warmup`, `--pose-start` and `--pose-lr` override it.
    #[arg(long, value_enum, default_value_t = ScheduleArg::Cpu)]
    pub schedule: ScheduleArg,
    /// Pose learning rate, start and end of the exponential decay over the run (default from
    /// `--schedule`; paper 001 §B.1: 1e-3,1e-4 over 100k iterations).
    #[arg(long, value_name = "START,END")]
    pub pose_lr: Option<String>,
    /// Keep the poses fixed.
    #[arg(long)]
    pub no_pose_refinement: bool,
    /// Downscale factor of the images the matcher (and the warm-up) sees; `--downscale` must be
    /// a multiple of it. Default 1: match on the images as stored even when training on smaller
    /// ones; on DTU scan65 this halves the warm-up's pose error against matching at 400×300.
    #[arg(long, default_value_t = 1, value_name = "K")]
    pub match_downscale: u32,
    /// Match only pairs of views whose optical axes, under the initial poses, are at most this
    /// many degrees apart (opposite views share no surface; their "matches" are look-alikes).
    /// 180 matches every pair, as paper 001 does for its three views.
    #[arg(long, default_value_t = 80.0, value_name = "DEG")]
    pub max_pair_angle: f64,
    /// Sub-pixel refinement of the matches (a deviation from paper 001): Lucas–Kanade moves
    /// each match's second end to where the two windows agree, dropping matches whose windows
    /// do not correlate. `affine` (default) warps the window affinely; `quadratic` adds
    /// second-order terms, which follow the bend of a window between views tens of degrees
    /// apart (the affine fit leaves a bias of a few tenths of a pixel along the epipolar line
    /// there; on DTU's wide triplet, seed 0, the quadratic warp gave 0.142° against 0.195°, but
    /// the published figures are measured with `affine`); `none` keeps the matcher's output.
    /// Dense matches (`--densify`) use the same warp.
    #[arg(long, default_value = "affine", value_name = "affine|quadratic|none")]
    pub match_refine: String,
    /// With `--match-refine quadratic`: drop matches whose fitted second-order term moves a
    /// point of the window by more than this many pixels (default: keep all).
    #[arg(long, value_name = "PX", value_parser = super::number_args::positive)]
    pub match_max_bend: Option<f64>,
    /// Deviation from paper 001 (which has PDC-Net's dense matches): grow dense matches from
    /// the sparse ones, on a grid of this spacing (pixels of the matching images), by affine
    /// Lucas–Kanade with forward–backward checks. `auto` (default): with `--schedule cpu`, on
    /// a 4-pixel grid only when the sparse matches cannot tie the views together for the
    /// warm-up (DTU's wide triplet, the analytic ring), also composing matches through a third
    /// view for the pairs `--max-pair-angle` left unmatched; else not at all. `off` or 0:
    /// sparse matches only.
    #[arg(long, default_value = "auto", value_name = "PX|auto|off")]
    pub densify: String,
    /// Deviation from paper 001 (on with `--schedule cpu`): before the joint optimisation,
    /// refine the initial poses on the correspondences' epipolar constraints alone (robust
    /// Sampson distance, Levenberg–Marquardt). Helps when the classical matcher finds too few
    /// matches to pull the poses back during training.
    #[arg(long, conflicts_with = "no_pose_warmup")]
    pub pose_warmup: bool,
    /// No epipolar warm-up, whatever `--schedule` says.
    #[arg(long)]
    pub no_pose_warmup: bool,
    /// The warm-up runs only on the pairs of views with at least this many matches.
    #[arg(long, default_value_t = 40, value_name = "N")]
    pub warmup_min_matches: usize,
    /// Final scale (pixels of the matching images) of the warm-up's Cauchy loss on the Sampson
    /// distances; the scale halves down to it. Sub-pixel matches allow a scale below a pixel,
    /// which lets the few matches a few tenths of a pixel off (windows across an occlusion)
    /// weigh less.
    #[arg(long, default_value_t = WarmupOptions::default().cauchy_px, value_name = "PX",
          value_parser = super::number_args::positive)]
    pub warmup_cauchy: f64,
    /// After the warm-up's annealing, polish the poses once more with each dense match's
    /// Sampson distance divided by its standard deviation across its epipolar line, from the
    /// Lucas–Kanade covariance of the grid match (a deviation: the paper has no warm-up; see
    /// crates/surface/README.md). On with `--schedule cpu`; affects only runs with dense
    /// matches (`--densify`, or grown by `--densify auto`).
    #[arg(long, conflicts_with = "no_warmup_covariance")]
    pub warmup_covariance: bool,
    /// No covariance polish after the warm-up, whatever `--schedule` says.
    #[arg(long)]
    pub no_warmup_covariance: bool,
    /// Start the warm-up from the initial poses only, without the global start the matches
    /// imply on their own (five-point relative poses of every matched pair, rotation averaging,
    /// baseline directions; the default, as structure from motion starts).
    #[arg(long)]
    pub no_global_start: bool,
    /// After a warm-up on dense matches, refine the poses photometrically: each match seeds a
    /// small plane in 3D (depth and normal), compared across every view that sees it through
    /// the homography it induces, in a bundle adjustment with the poses (a deviation: the paper
    /// has no warm-up; see crates/surface/README.md). On with `--schedule cpu`, after the
    /// bundle adjustment; affects only runs with dense matches (`--densify`, or grown by
    /// `--densify auto`). With `--schedule cpu` the adjusted poses are then held for the whole
    /// run unless `--pose-start` or `--pose-lr` is given.
    #[arg(long, conflicts_with = "no_patch_adjustment")]
    pub patch_adjustment: bool,
    /// No patch adjustment after the warm-up, whatever `--schedule` says.
    #[arg(long)]
    pub no_patch_adjustment: bool,
    /// No bundle adjustment after the warm-up, whatever `--schedule` says. With `--schedule
    /// cpu` the warmed-up poses and the matches' tracks (a grid point matched into two views is
    /// one 3D point seen three times) are adjusted on their reprojection errors, as structure
    /// from motion ends its start (a deviation: see crates/surface/README.md).
    #[arg(long)]
    pub no_bundle_adjustment: bool,
    /// What those pairs must form for the warm-up to run: `rigid` (their baseline directions fix
    /// every baseline's length up to one scale, e.g. chained triangles; default; `triangles` is
    /// the old name) or `connected` (any connected graph, e.g. the wide DTU triplet's chain
    /// 22–25–28: rotations and baseline directions are refined, lengths outside triangles keep
    /// their initial values).
    #[arg(long, default_value = "rigid", value_name = "rigid|connected")]
    pub warmup_connectivity: String,
    /// Hold the poses fixed for this fraction of the iterations while the field forms, then
    /// refine them (default from `--schedule`: 0.75 for `cpu`, a deviation, and 1, held for the
    /// whole run, after a patch adjustment; 0 for `paper`). Given, it applies whatever ran.
    #[arg(long, value_name = "FRACTION")]
    pub pose_start: Option<f64>,
    /// Seed of the noise, sampling and initialisation.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Geometry encoder: `hash-grid` (CPU default) or `neus-mlp` (the paper's 8×256 MLP, slow).
    #[arg(long, default_value = "hash-grid")]
    pub encoder: String,
    /// Finite-difference stencil of the normals: `tetrahedron` (4 taps) or `central` (6).
    #[arg(long, default_value = "tetrahedron")]
    pub fd: String,
    /// Samples per ray: coarse and importance.
    #[arg(long, default_value_t = 32)]
    pub coarse: usize,
    #[arg(long, default_value_t = 32)]
    pub importance: usize,
    /// Loss switches for ablations.
    #[arg(long)]
    pub no_matching: bool,
    #[arg(long)]
    pub no_ncc: bool,
    #[arg(long)]
    pub no_gc: bool,
    #[arg(long)]
    pub no_uncertainty: bool,
    #[arg(long)]
    pub no_psdf: bool,
    #[arg(long)]
    pub no_eikonal: bool,
    /// Do not use object masks (colour loss on all pixels, no mask loss, no culling).
    #[arg(long)]
    pub no_masks: bool,
    /// Loss weights, finite and ≥ 0 (defaults: paper 001 §B.1; `--lambda-geo` see the README).
    #[arg(long, value_parser = non_negative_f32)]
    pub lambda_mc: Option<f32>,
    #[arg(long, value_parser = non_negative_f32)]
    pub lambda_u: Option<f32>,
    #[arg(long, value_parser = non_negative_f32)]
    pub lambda_gc: Option<f32>,
    #[arg(long, value_parser = non_negative_f32)]
    pub lambda_geo: Option<f32>,
    #[arg(long, value_parser = non_negative_f32)]
    pub lambda_psdf: Option<f32>,
    /// Coarse-to-fine window (α₁, α₂) as fractions of the iterations, e.g. `0.4,0.7`.
    #[arg(long, value_name = "A1,A2")]
    pub c2f: Option<String>,
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

/// `--schedule` (see [`Schedule`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ScheduleArg {
    Cpu,
    Paper,
}

impl ScheduleArg {
    fn schedule(self) -> Schedule {
        match self {
            ScheduleArg::Cpu => Schedule::Cpu,
            ScheduleArg::Paper => Schedule::Paper,
        }
    }
}

fn parse_pair(s: &str) -> anyhow::Result<(f64, f64)> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--c2f {s:?}: expected two numbers like 0.4,0.7"))?;
    if v.len() != 2 || !(0.0..=1.0).contains(&v[0]) || !(0.0..=1.0).contains(&v[1]) || v[1] < v[0] {
        bail!("--c2f {s:?}: expected 0 ≤ α₁ ≤ α₂ ≤ 1");
    }
    Ok((v[0], v[1]))
}

fn parse_rates(s: &str) -> anyhow::Result<(f64, f64)> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--pose-lr {s:?}: expected two numbers like 1e-3,1e-4"))?;
    if v.len() != 2 || !v.iter().all(|r| r.is_finite() && *r > 0.0) {
        bail!("--pose-lr {s:?}: expected two positive rates like 1e-3,1e-4");
    }
    Ok((v[0], v[1]))
}

impl Args {
    pub fn config(&self) -> anyhow::Result<RunConfig> {
        let mut c = RunConfig::default();
        self.schedule.schedule().apply(&mut c);
        // An explicit pose timing is what the user asked for, warm-up or not.
        if let Some(start) = self.pose_start {
            if !(0.0..=1.0).contains(&start) {
                bail!("--pose-start {start}: expected a fraction in [0, 1]");
            }
            c.train.pose_start = start;
            c.pose_timing_without_warmup = None;
            c.hold_poses_after_patch_adjustment = false;
        }
        let t = &mut c.train;
        t.iterations = self.iterations;
        t.rays_per_batch = self.rays;
        t.matches_per_batch = self.matches_per_batch;
        t.seed = self.seed;
        t.refine_poses = !self.no_pose_refinement;
        t.use_masks = !self.no_masks;
        t.sample.n_coarse = self.coarse;
        t.sample.n_importance = self.importance;
        t.field.encoder = match self.encoder.as_str() {
            "hash-grid" => EncoderKind::HashGrid,
            "neus-mlp" => EncoderKind::NeusMlp,
            other => bail!("--encoder {other:?}: expected hash-grid or neus-mlp"),
        };
        t.field.fd_scheme = match self.fd.as_str() {
            "tetrahedron" => FdScheme::Tetrahedron,
            "central" => FdScheme::Central,
            other => bail!("--fd {other:?}: expected tetrahedron or central"),
        };
        let l = &mut t.losses;
        l.matching = !self.no_matching;
        l.ncc = !self.no_ncc;
        l.geometric_consistency = !self.no_gc;
        l.uncertainty = !self.no_uncertainty;
        l.psdf = !self.no_psdf;
        l.eikonal = !self.no_eikonal;
        if let Some(v) = self.lambda_mc {
            l.lambda_mc = v;
        }
        if let Some(v) = self.lambda_u {
            l.lambda_u = v;
        }
        if let Some(v) = self.lambda_gc {
            l.lambda_gc = v;
        }
        if let Some(v) = self.lambda_geo {
            l.lambda_geo = v;
        }
        if let Some(v) = self.lambda_psdf {
            l.lambda_psdf = v;
        }
        if let Some(s) = &self.c2f {
            t.c2f = parse_pair(s)?;
        }
        if let Some(s) = &self.pose_lr {
            let (start, end) = parse_rates(s)?;
            t.pose_lr = fewview_surface::adam::ExpSchedule {
                start: start as f32,
                end: end as f32,
            };
            c.pose_timing_without_warmup = None;
            c.hold_poses_after_patch_adjustment = false;
        }
        c.initial_poses = match self.initial_poses.as_str() {
            "noisy" => InitialPoses::NoisyGroundTruth {
                sigma: self.pose_noise,
            },
            "loaded" => InitialPoses::AsLoaded,
            other => bail!("--initial-poses {other:?}: expected noisy or loaded"),
        };
        let connectivity = match self.warmup_connectivity.as_str() {
            "rigid" | "triangles" => Connectivity::Rigid,
            "connected" => Connectivity::Connected,
            other => bail!("--warmup-connectivity {other:?}: expected rigid or connected"),
        };
        let scheduled = c.pose_warmup;
        let warm_up = (scheduled.is_some() || self.pose_warmup) && !self.no_pose_warmup;
        let covariance_polish = (scheduled.is_some_and(|w| w.covariance_polish)
            || self.warmup_covariance)
            && !self.no_warmup_covariance;
        let patch_adjustment =
            (c.patch_adjustment.is_some() || self.patch_adjustment) && !self.no_patch_adjustment;
        c.patch_adjustment = patch_adjustment.then(PatchAdjustmentOptions::default);
        if self.no_bundle_adjustment {
            c.bundle_adjustment = None;
        }
        c.pose_warmup = warm_up.then(|| WarmupOptions {
            min_matches_per_pair: self.warmup_min_matches,
            connectivity,
            cauchy_px: self.warmup_cauchy,
            covariance_polish,
            global_start: !self.no_global_start,
            ..Default::default()
        });
        let needs_matches = warm_up || !(self.no_matching && self.no_ncc && self.no_gc);
        c.matcher = needs_matches.then(|| SiftOptions {
            seed: self.seed,
            ..Default::default()
        });
        if !(self.max_pair_angle > 0.0 && self.max_pair_angle <= 180.0) {
            bail!(
                "--max-pair-angle {}: expected degrees in (0, 180]",
                self.max_pair_angle
            );
        }
        c.max_pair_angle_deg = self.max_pair_angle;
        let warp = match self.match_refine.as_str() {
            "affine" => Some(WarpModel::Affine),
            "quadratic" => Some(WarpModel::Quadratic),
            "none" => None,
            other => bail!("--match-refine {other:?}: expected affine, quadratic or none"),
        };
        if self.match_max_bend.is_some() && warp != Some(WarpModel::Quadratic) {
            bail!("--match-max-bend applies to --match-refine quadratic only");
        }
        c.match_refinement = warp.map(|warp| AffineRefineOptions {
            warp,
            max_bend_px: self.match_max_bend,
            ..Default::default()
        });
        match self.densify.as_str() {
            "auto" => {}
            "off" | "0" => c.densify_if_needed = None,
            px => {
                let spacing_px: usize = px.parse().ok().filter(|&v| v > 0).with_context(|| {
                    format!("--densify {px:?}: expected a grid spacing in pixels, auto or off")
                })?;
                c.densify = Some(DensifyOptions {
                    spacing_px,
                    ..Default::default()
                });
            }
        }
        c.mesh_resolution = self.mesh_resolution as usize;
        c.eval_views = self.eval_views;
        c.eval_scale = self.eval_scale;
        c.checkpoint_every = self.checkpoint_every;
        Ok(c)
    }
}

/// The training views at `--match-downscale` for the matcher, when that differs from the
/// training resolution.
fn matching_images(
    d: &DatasetArgs,
    match_downscale: u32,
) -> anyhow::Result<Option<fewview_scene::Dataset>> {
    if match_downscale == 0 || !d.downscale.is_multiple_of(match_downscale) {
        bail!(
            "--match-downscale {match_downscale} must be at least 1 and divide --downscale {}",
            d.downscale
        );
    }
    if match_downscale == d.downscale {
        return Ok(None);
    }
    let mut fine = d.clone();
    fine.downscale = match_downscale;
    Ok(Some(
        fine.load().context("loading the images for matching")?,
    ))
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
    if args.synthetic && args.dataset.data.is_some() {
        bail!("give either --data DIR or --synthetic, not both");
    }
    let (ds, truth, matching, name, reference) = if args.synthetic {
        let ds = sdf_dataset(&if args.synthetic_all_around {
            SdfSceneOptions::ring_of_eight_all_around()
        } else {
            SdfSceneOptions::ring_of_eight()
        });
        let reference = fewview_surface::sdf_scene::surface_mesh(256)?;
        (ds, None, None, "synthetic".to_string(), Some(reference))
    } else {
        let d = &args.dataset;
        let Some(folder) = d.data.as_deref() else {
            bail!("give --data DIR (or --synthetic)");
        };
        let matching = matching_images(d, args.match_downscale)?;
        let ds = d.load()?;
        // With other starting poses, the ground truth is the same folder's default cameras.
        let truth = if args.initial_poses == "loaded" && d.cameras_file.is_some() {
            let mut t = d.clone();
            t.cameras_file = None;
            Some(t.load().context("loading the ground-truth cameras")?)
        } else {
            None
        };
        let reference = match &args.reference {
            Some(p) => {
                let mesh = fewview_geom::io::read_mesh(p)
                    .with_context(|| format!("reading the reference surface {}", p.display()))?;
                // Checked again by the pipeline; here the error can name the file.
                fewview_surface::pipeline::check_reference(&mesh)
                    .with_context(|| p.display().to_string())?;
                Some(mesh)
            }
            None => None,
        };
        let name = folder
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "run".into());
        (ds, truth, matching, name, reference)
    };
    let cfg = args.config()?;
    // Every scored test view must keep a pixel at 1/--eval-scale: a larger factor used to fail
    // on the first render, after the mesh and the poses were written.
    let k = cfg.eval_scale as usize;
    for &vi in ds.test.iter().take(cfg.eval_views) {
        let v = &ds.views[vi];
        if v.image.width < k || v.image.height < k {
            bail!(
                "--eval-scale {k}: test view {} is {}×{}, which leaves no pixel at 1/{k}",
                v.name,
                v.image.width,
                v.image.height
            );
        }
    }
    // Where the refined poses go back in the input's format (`--data` is absent, checked
    // above, for the in-process scene).
    let load_options = args.dataset.load_options();
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs").join(format!("surface-{name}")));
    check_folder(&out, "--out")?;
    eprintln!(
        "surface on {} ({} train views, {}x{}, {} iterations) → {}",
        ds.name,
        ds.train.len(),
        ds.views[ds.train[0]].image.width,
        ds.views[ds.train[0]].image.height,
        cfg.train.iterations,
        out.display()
    );
    let bar = progress::iterations(cfg.train.iterations as u64, "surface");
    // The analytic scene knows which faces of its true surface the training views see.
    let observed = match (&reference, args.synthetic) {
        (Some(mesh), true) => {
            let cameras: Vec<_> = ds
                .train
                .iter()
                .map(|&i| ds.views[i].camera.clone())
                .collect();
            Some(fewview_surface::sdf_scene::observed_faces(mesh, &cameras))
        }
        _ => None,
    };
    let inputs = RunInputs {
        dataset: &ds,
        truth: truth.as_ref(),
        matching: matching.as_ref(),
        reference: reference.as_ref(),
        reference_observed: observed.as_deref(),
        source: args.dataset.data.as_deref().map(|root| PoseSource {
            root,
            options: &load_options,
        }),
    };
    let checkpoint = fewview_surface::pipeline::checkpoint_path(&out);
    if args.resume && !checkpoint.exists() {
        eprintln!(
            "note: --resume: no {} yet, starting from the first iteration",
            checkpoint.display()
        );
    }
    let report = run_pipeline(inputs, &cfg, &out, args.resume, &mut |e| match e {
        Event::Matched {
            matches,
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
            bar.suspend(|| {
                if let Some(why) = densified_because {
                    eprintln!(
                        "sparse matches cannot tie the views together ({why}): growing dense ones"
                    );
                }
                eprintln!("{matches} correspondences{p}")
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
        } => bar.suspend(|| {
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
        }),
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
    })
    .with_context(|| format!("surface run in {}", out.display()))?;
    bar.finish_and_clear();
    print_report(&report, &out);
    Ok(())
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
        "  at ε = {:.0e}     R {:.3}° → {}{:.3}° (SPARF's code; paper 001 Table 1's convention)",
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

    fn config(flags: &[&str]) -> fewview_surface::pipeline::RunConfig {
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
        let c = config(&["--schedule", "paper", "--pose-warmup"]);
        assert!(c.pose_warmup.is_some());
        assert_eq!(PoseTiming::of(&c.train), PoseTiming::PAPER);
    }

    #[test]
    fn explicit_flags_override_the_schedule_and_its_fallback() {
        let c = config(&["--no-pose-warmup"]);
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
        let err = Cli::try_parse_from(["surface", "--densify", "dense"])
            .unwrap()
            .args
            .config()
            .unwrap_err()
            .to_string();
        assert!(err.contains("--densify \"dense\""), "{err}");
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
        let c = config(&["--no-warmup-covariance"]);
        assert!(!c.pose_warmup.unwrap().covariance_polish);
        let c = config(&["--schedule", "paper", "--pose-warmup"]);
        assert!(!c.pose_warmup.unwrap().covariance_polish);
        let c = config(&[
            "--schedule",
            "paper",
            "--pose-warmup",
            "--warmup-covariance",
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
        assert!(err.contains("\"cubic\""), "{err}");
        assert!(refused(&["--warmup-cauchy", "0"]).contains("--warmup-cauchy"));
        assert!(refused(&["--match-max-bend", "NaN"]).contains("--match-max-bend"));
    }

    #[test]
    fn contradictory_or_bad_schedule_flags_are_refused() {
        let parse = |flags: &[&str]| {
            Cli::try_parse_from(std::iter::once("surface").chain(flags.iter().copied()))
        };
        assert!(parse(&["--pose-warmup", "--no-pose-warmup"]).is_err());
        assert!(parse(&["--schedule", "fast"]).is_err());
        let args = parse(&["--pose-start", "1.5"]).unwrap().args;
        let err = args.config().unwrap_err().to_string();
        assert!(err.contains("--pose-start 1.5"), "{err}");
    }
}
