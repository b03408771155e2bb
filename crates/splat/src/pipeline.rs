//! One training run on a dataset, as `fewview train` and `fewview demo` do it: a run directory
//! holding the resolved configuration, checkpoints (resumable), the trained Gaussians as an
//! Inria PLY, held-out renders and `metrics.json`.
//!
//! ```text
//! <run>/config.json        resolved configuration and split
//! <run>/cameras.json       the training cameras, then the held-out ones, in config.json's
//!                          order (the camera-file form of `fewview_geom::io::cameras`)
//! <run>/checkpoint.bin     latest checkpoint (removed when the run completes)
//! <run>/point_cloud.ply    trained Gaussians (Inria layout)
//! <run>/metrics.json       held-out PSNR/SSIM per view and means, Gaussian count, timings
//! <run>/appearance.json    the training photos' colour transforms (with an appearance model)
//! <run>/renders/test/      held-out renders (PNG)
//! ```

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::device::{ComputeDevice, DeviceError};
use fewview_scene::{Camera, Dataset, Image, SceneError};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::eval::{EvalReport, check_scorable, evaluate, render_model};
use fewview_scene::memory::StagePeaks;

use crate::init::{
    FrustumView, PATCH_SCALE_CAP, from_points, from_stereo_points, random_in_box,
    random_in_frustums,
};
use crate::model::GaussianModel;
use crate::ply::{read_ply, write_ply};
use crate::raster::{RenderCamera, RenderSettings};
use crate::stereo_start::{PointAgreement, StereoInit, StereoStart, stereo_start};
use crate::train::{
    AlphaImage, LossTerm, Progress, TrainConfig, TrainError, TrainState, TrainView, Trainer,
};

/// How to place the initial Gaussians.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InitStrategy {
    /// The dataset's sparse points if it has them; else the stereo start when at least two
    /// training views overlap (see [`fewview_geom::stereo::pairs::stereo_pairs`]); else random
    /// points in the training frustums if the views have depth bounds, else random points in a
    /// box around the point the cameras look at.
    Auto,
    /// The dataset's sparse points (COLMAP `points3D`).
    DatasetPoints,
    /// Random points in the training frustums between each view's depth bounds.
    RandomFrustum,
    /// Random points in a cube of half-size `half_size` (default: 0.35 × the median camera
    /// distance) around the point the cameras look at.
    RandomBox { half_size: Option<f64> },
    /// Gaussians read from an Inria-layout PLY.
    Ply(PathBuf),
    /// The stereo start of the fusion paper §2: a sample of the hierarchical point cloud of the
    /// training views' stereo pairs ([`crate::stereo_start`]), built as [`RunConfig::stereo`]
    /// says.
    Stereo,
    /// Gaussians on the mesh of the surface run in this folder ([`crate::surface_start`]).
    Surface(PathBuf),
}

/// Everything that defines a run besides the data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunConfig {
    pub train: TrainConfig,
    pub init: InitStrategy,
    /// Number of random initial points (random strategies).
    pub init_points: usize,
    /// How the stereo start is built, when the run uses it.
    pub stereo: StereoInit,
    /// Where training runs. Not part of a checkpoint's identity: a run may resume on another
    /// device.
    #[serde(default)]
    pub device: ComputeDevice,
    /// Weight of the surface mesh's depth in the training views
    /// ([`crate::surface_start::SurfaceDepthTerm`]) when the run starts from a surface run;
    /// 0: none.
    #[serde(default = "default_surface_depth_weight")]
    pub surface_depth_weight: f32,
}

fn default_surface_depth_weight() -> f32 {
    crate::surface_start::SURFACE_DEPTH_WEIGHT
}

/// The most random initial points a run accepts. Each Gaussian costs about 1 KB while training
/// (parameters, gradients and Adam moments at SH degree 3), so this is ~10 GB; sparse-view scenes
/// use 10⁴–10⁵. A larger count is refused up front instead of aborting on allocation.
pub const MAX_INIT_POINTS: usize = 10_000_000;

impl RunConfig {
    pub fn new(train: TrainConfig) -> Self {
        Self {
            train,
            init: InitStrategy::Auto,
            init_points: 20_000,
            stereo: StereoInit::default(),
            device: ComputeDevice::Cpu,
            surface_depth_weight: default_surface_depth_weight(),
        }
    }
}

/// Errors of a run, each naming what failed.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Train(#[from] TrainError),
    #[error("{path}: {message}")]
    Checkpoint { path: PathBuf, message: String },
    #[error("initialisation: {0}")]
    Init(String),
    #[error("surface start: {0}")]
    SurfaceStart(#[from] crate::surface_start::SurfaceStartError),
    #[error("evaluation: {0}")]
    Eval(String),
    #[error(transparent)]
    Device(#[from] DeviceError),
}

/// Paths inside a run directory.
#[derive(Clone, Debug)]
pub struct RunDir(pub PathBuf);

impl RunDir {
    pub fn config(&self) -> PathBuf {
        self.0.join("config.json")
    }
    pub fn checkpoint(&self) -> PathBuf {
        self.0.join("checkpoint.bin")
    }
    pub fn ply(&self) -> PathBuf {
        self.0.join("point_cloud.ply")
    }
    /// Whether the run trained to its end: its model written and no checkpoint left.
    pub fn finished(&self) -> bool {
        self.ply().is_file() && !self.checkpoint().exists()
    }
    pub fn metrics(&self) -> PathBuf {
        self.0.join("metrics.json")
    }
    pub fn appearance(&self) -> PathBuf {
        self.0.join("appearance.json")
    }
    /// The cameras of the split, so that a viewer or `fewview render --cameras` can show the
    /// run from its own views without the dataset.
    pub fn cameras(&self) -> PathBuf {
        self.0.join("cameras.json")
    }
    pub fn renders(&self, split: &str) -> PathBuf {
        self.0.join("renders").join(split)
    }
    /// Where the stereo start writes its cloud, region render and summary.
    pub fn init(&self) -> PathBuf {
        self.0.join("init")
    }
}

/// What a run trains on: the dataset, its split and the image size. A checkpoint records it, so
/// that `--resume` refuses another dataset, other views or another downscale instead of
/// continuing one run's Gaussians on another's images.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunData {
    pub dataset: String,
    pub train_views: Vec<String>,
    pub test_views: Vec<String>,
    pub width: usize,
    pub height: usize,
}

impl RunData {
    /// The dataset, split and size of `ds` (its first training view's size).
    pub fn of(ds: &Dataset) -> Result<Self, PipelineError> {
        let first = ds
            .train_views()
            .next()
            .ok_or_else(|| PipelineError::Init("the split has no training views".into()))?;
        Ok(Self {
            dataset: ds.name.clone(),
            train_views: ds.train_views().map(|v| v.name.clone()).collect(),
            test_views: ds.test_views().map(|v| v.name.clone()).collect(),
            width: first.image.width,
            height: first.image.height,
        })
    }

    /// A one-line description of how `self` (the checkpoint's) differs from `now`, or `None`.
    pub fn difference(&self, now: &RunData) -> Option<String> {
        if self.dataset != now.dataset {
            Some(format!("dataset {} (now {})", self.dataset, now.dataset))
        } else if (self.width, self.height) != (now.width, now.height) {
            Some(format!(
                "images {}x{} (now {}x{}: another --downscale?)",
                self.width, self.height, now.width, now.height
            ))
        } else if self.train_views != now.train_views {
            Some(format!(
                "training views {} (now {})",
                self.train_views.join(","),
                now.train_views.join(",")
            ))
        } else if self.test_views != now.test_views {
            Some(format!(
                "test views {} (now {})",
                self.test_views.join(","),
                now.test_views.join(",")
            ))
        } else {
            None
        }
    }
}

/// The `config.json` of a run.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ResolvedConfig {
    #[serde(flatten)]
    pub data: RunData,
    pub extent: f64,
    pub run: RunConfig,
}

/// What a finished run reports (also written to `metrics.json`).
#[derive(Clone, Debug, Serialize)]
pub struct RunSummary {
    pub dataset: String,
    /// The initialisation used (`auto` resolved, a fallback taken).
    pub init: String,
    /// What the initialisation reports besides: stereo pairs skipped or swept and why, a
    /// fallback taken.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub init_notes: Vec<String>,
    /// The peak resident memory (MiB) of the initialisation and of training.
    pub memory: StagePeaks,
    pub iterations: usize,
    pub gaussians: usize,
    pub train_seconds: f64,
    pub resumed_from: Option<usize>,
    pub test: EvalReport,
}

/// Header of the current checkpoint format: the payload is postcard of
/// `(TrainConfig, RunData, TrainState)`, sealed with a CRC-32 ([`fewview_scene::sealed`]).
const CHECKPOINT_MAGIC: &[u8; 8] = b"FVCKPT03";
/// Earlier formats: `FVCKPT01` had neither the run's data nor a checksum, `FVCKPT02` no
/// appearance model.
const OLDER_CHECKPOINT_MAGICS: [&[u8]; 2] = [b"FVCKPT01", b"FVCKPT02"];

/// What a checkpoint holds: the training configuration, the data it trains on and the state.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint {
    pub config: TrainConfig,
    pub data: RunData,
    pub state: TrainState,
}

/// Saves a checkpoint, atomically.
pub fn save_checkpoint(
    path: &Path,
    config: &TrainConfig,
    data: &RunData,
    state: &TrainState,
) -> Result<(), PipelineError> {
    let body =
        postcard::to_allocvec(&(config, data, state)).map_err(|e| PipelineError::Checkpoint {
            path: path.to_path_buf(),
            message: format!("cannot encode: {e}"),
        })?;
    fewview_scene::sealed::write(path, CHECKPOINT_MAGIC, &body)?;
    Ok(())
}

/// Loads a checkpoint written by [`save_checkpoint`]; a truncated or altered file is an error.
pub fn load_checkpoint(path: &Path) -> Result<Checkpoint, PipelineError> {
    let body = fewview_scene::sealed::read(
        path,
        CHECKPOINT_MAGIC,
        &OLDER_CHECKPOINT_MAGICS,
        "a fewview checkpoint",
    )?;
    let bad = |m: String| PipelineError::Checkpoint {
        path: path.to_path_buf(),
        message: m,
    };
    let (config, data, state): (TrainConfig, RunData, TrainState) =
        postcard::from_bytes(&body).map_err(|e| bad(format!("corrupt checkpoint: {e}")))?;
    state
        .model
        .validate()
        .map_err(|m| bad(format!("corrupt checkpoint: {m}")))?;
    Ok(Checkpoint {
        config,
        data,
        state,
    })
}

/// The point closest (least squares) to every camera's optical axis: where the cameras look.
pub fn look_at_point(cameras: &[&Camera]) -> Vector3<f64> {
    let poses: Vec<fewview_scene::Se3> = cameras.iter().map(|c| c.world_to_camera).collect();
    fewview_scene::axes_meeting_point(&poses)
}

/// The default run length of `fewview train` on `ds`: 1000 iterations on forward-facing scenes
/// whose views have depth bounds (LLFF: initialised in the training frustums; with 3 views
/// longer runs overfit), otherwise 3000 or 50 per training view, whichever is more (360° scenes
/// from a random box form their geometry only after the first opacity reset has pruned the
/// floaters; dense captures need each view seen about 50 times). The runs behind these lengths
/// are in `docs/guide/splatting.md`, "Schedule for short sparse-view runs".
pub fn default_iterations(ds: &Dataset) -> usize {
    if ds.train_views().all(|v| v.depth_bounds.is_some()) {
        1000
    } else {
        3000.max(ITERATIONS_PER_VIEW * ds.train.len())
    }
}

/// Iterations per training view of the default run on scenes without depth bounds.
const ITERATIONS_PER_VIEW: usize = 50;

/// What [`InitStrategy::Auto`] means for `ds` (any other strategy is returned as it is): the
/// fusion paper's stereo start where training views overlap (with at most
/// [`MAX_STEREO_START_VIEWS`] of them; its pairs take their depth range from the dataset's
/// sparse points, and a start whose pairs all fail falls back to those points), else the
/// sparse points, else random points in the training frustums (views with depth bounds), else
/// in a box where the cameras look.
pub fn resolve_init(ds: &Dataset, init: &InitStrategy) -> InitStrategy {
    let has_points = ds.points.as_ref().is_some_and(|p| !p.is_empty());
    match init {
        InitStrategy::Auto if ds.train.len() <= MAX_STEREO_START_VIEWS && views_overlap(ds) => {
            InitStrategy::Stereo
        }
        InitStrategy::Auto if has_points => InitStrategy::DatasetPoints,
        InitStrategy::Auto if ds.train_views().all(|v| v.depth_bounds.is_some()) => {
            InitStrategy::RandomFrustum
        }
        InitStrategy::Auto => InitStrategy::RandomBox { half_size: None },
        s => s.clone(),
    }
}

/// The most training views [`InitStrategy::Auto`] starts from stereo: a dense capture has its
/// structure-from-motion points, and its consecutive pairs would take long to match.
pub const MAX_STEREO_START_VIEWS: usize = 40;

/// Whether at least two training views overlap enough for stereo.
fn views_overlap(ds: &Dataset) -> bool {
    let views = crate::stereo_start::stereo_views(ds);
    let rule = StereoInit::default().overlap;
    fewview_geom::stereo::pairs::stereo_pairs(&views, &rule).is_ok()
}

impl InitStrategy {
    /// A short name for reports.
    pub fn name(&self) -> &'static str {
        match self {
            InitStrategy::Auto => "auto",
            InitStrategy::DatasetPoints => "points",
            InitStrategy::RandomFrustum => "frustum",
            InitStrategy::RandomBox { .. } => "box",
            InitStrategy::Ply(_) => "ply",
            InitStrategy::Stereo => "stereo",
            InitStrategy::Surface(_) => "surface",
        }
    }
}

/// When `cfg` starts from a surface run, gives `ds`'s training views the poses `choice` names
/// ([`crate::surface_start::adopt_surface_poses`]) and returns a line saying which; `None` for
/// other starts.
pub fn adopt_init_poses(
    ds: &mut Dataset,
    cfg: &RunConfig,
    choice: crate::surface_start::SurfacePoses,
) -> Result<Option<String>, PipelineError> {
    match &cfg.init {
        InitStrategy::Surface(dir) => Ok(Some(crate::surface_start::adopt_surface_poses(
            ds, dir, choice,
        )?)),
        _ => Ok(None),
    }
}

/// The initial Gaussians for a dataset.
pub fn initial_model(ds: &Dataset, cfg: &RunConfig) -> Result<GaussianModel, PipelineError> {
    Ok(initial_model_and_start(ds, cfg)?.model)
}

/// The initial Gaussians of a run and how they came about.
pub struct InitialModel {
    pub model: GaussianModel,
    /// The stereo start the Gaussians came from, for [`InitStrategy::Stereo`].
    pub start: Option<StereoStart>,
    /// The strategy that made them (`auto` resolved, a fallback taken).
    pub used: InitStrategy,
    /// Lines for the user: stereo pairs skipped and why, a fallback taken.
    pub notes: Vec<String>,
}

/// The initial Gaussians of `ds` from the resolved strategy; an automatic
/// stereo start that fails on every pair falls back to the dataset's sparse points, saying so.
pub fn initial_model_and_start(
    ds: &Dataset,
    cfg: &RunConfig,
) -> Result<InitialModel, PipelineError> {
    let strategy = resolve_init(ds, &cfg.init);
    let has_points = ds.points.as_ref().is_some_and(|p| !p.is_empty());
    match initial_model_with(ds, cfg, &strategy) {
        Err(e)
            if cfg.init == InitStrategy::Auto && strategy == InitStrategy::Stereo && has_points =>
        {
            let mut init = initial_model_with(ds, cfg, &InitStrategy::DatasetPoints)?;
            init.notes.push(format!(
                "the stereo start failed ({e}); started from the dataset's sparse points instead"
            ));
            Ok(init)
        }
        found => found,
    }
}

/// The initial Gaussians of `ds` from `strategy` (already resolved) and, for
/// [`InitStrategy::Stereo`], the stereo start they came from.
fn initial_model_with(
    ds: &Dataset,
    cfg: &RunConfig,
    strategy: &InitStrategy,
) -> Result<InitialModel, PipelineError> {
    let degree = cfg.train.sh_degree;
    let seed = cfg.train.seed;
    if cfg.init_points > MAX_INIT_POINTS {
        return Err(PipelineError::Init(format!(
            "{} initial points is more than the {MAX_INIT_POINTS} allowed",
            cfg.init_points
        )));
    }
    let mut start = None;
    let mut notes = Vec::new();
    let model = match strategy.clone() {
        InitStrategy::Stereo => {
            let s = stereo_start(ds, &cfg.stereo, seed, &mut |_, _| {})
                .map_err(|e| PipelineError::Init(e.to_string()))?;
            notes.extend(
                s.skipped
                    .iter()
                    .map(|(a, b, why)| format!("stereo start: views {a} and {b} skipped: {why}")),
            );
            notes.extend(s.swept.iter().map(|(a, b, why)| {
                format!("stereo start: views {a} and {b} matched by plane sweep: {why}")
            }));
            notes.extend(s.agreement.iter().map(PointAgreement::note));
            if s.fraction < cfg.stereo.fraction {
                notes.push(format!(
                    "stereo start: {} points, sampled {:.2} % of them (not {:.0} %) to stay \
                     within {} Gaussians (--stereo-max-points)",
                    s.cloud.points.len(),
                    100.0 * s.fraction,
                    100.0 * cfg.stereo.fraction,
                    cfg.stereo.max_points
                ));
            }
            let spacing = (1.0 / s.fraction.sqrt()) as f32;
            let (mut model, capped) =
                from_stereo_points(&s.sample, degree, &s.sample_footprints, spacing);
            if let Some(shell) = &s.shell {
                for ((p, c), scale) in shell.positions.iter().zip(&shell.colors).zip(&shell.scales)
                {
                    model.push_isotropic(*p, *scale, *c, crate::init::INITIAL_OPACITY);
                }
                notes.push(format!(
                    "stereo start: {} Gaussians for the sky and far background, {:.3} from T \
                     (blocks of {} px without a stereo point)",
                    shell.positions.len(),
                    shell.radius,
                    crate::sky_shell::SHELL_BLOCK_PX
                ));
            }
            if let Some((before, after)) = capped {
                notes.push(format!(
                    "stereo start: initial scales capped at {PATCH_SCALE_CAP} patches (a render \
                     would have cost {before:.0} Gaussian-pixel pairs per pixel, now {after:.0})"
                ));
            }
            start = Some(s);
            model
        }
        InitStrategy::DatasetPoints => {
            let pts = ds
                .points
                .as_ref()
                .filter(|p| !p.is_empty())
                .ok_or_else(|| {
                    PipelineError::Init(format!("dataset `{}` has no sparse points", ds.name))
                })?;
            from_points(pts, degree)
        }
        InitStrategy::RandomFrustum => {
            let views: Vec<FrustumView<'_>> = ds
                .train_views()
                .map(|v| {
                    let (near, far) = v.depth_bounds.ok_or_else(|| {
                        PipelineError::Init(format!(
                            "view `{}` has no depth bounds for frustum sampling",
                            v.name
                        ))
                    })?;
                    Ok(FrustumView {
                        camera: &v.camera,
                        image: &v.image,
                        near,
                        far,
                    })
                })
                .collect::<Result<_, PipelineError>>()?;
            from_points(&random_in_frustums(&views, cfg.init_points, seed), degree)
        }
        InitStrategy::RandomBox { half_size } => {
            let cams: Vec<&Camera> = ds.train_views().map(|v| &v.camera).collect();
            let center = look_at_point(&cams);
            let mut dists: Vec<f64> = cams.iter().map(|c| (c.center() - center).norm()).collect();
            dists.sort_by(f64::total_cmp);
            let half = half_size.unwrap_or(0.35 * dists[dists.len() / 2]);
            let lo = [center.x - half, center.y - half, center.z - half];
            let hi = [center.x + half, center.y + half, center.z + half];
            let views: Vec<(&Camera, &Image)> =
                ds.train_views().map(|v| (&v.camera, &v.image)).collect();
            from_points(
                &random_in_box(lo, hi, cfg.init_points, seed, &views),
                degree,
            )
        }
        InitStrategy::Ply(path) => {
            let m = read_ply(&path)?;
            if m.sh_degree() != degree {
                return Err(PipelineError::Init(format!(
                    "{}: SH degree {} but the run uses degree {degree}",
                    path.display(),
                    m.sh_degree()
                )));
            }
            m
        }
        InitStrategy::Surface(dir) => {
            let run = crate::surface_start::SurfaceRun::load(&dir, ds)?;
            crate::surface_start::surface_model(ds, &run, degree, seed)?
        }
        InitStrategy::Auto => unreachable!("resolved above"),
    };
    if model.is_empty() {
        return Err(PipelineError::Init("no initial Gaussians".into()));
    }
    Ok(InitialModel {
        model,
        start,
        used: strategy.clone(),
        notes,
    })
}

/// Trains on `ds` in `dir` (resuming from its checkpoint when `resume`), writes the PLY, held-out
/// renders and `metrics.json`, and returns the summary.
pub fn train_run(
    ds: &Dataset,
    cfg: &RunConfig,
    dir: &Path,
    resume: bool,
    on_progress: impl FnMut(&Progress),
) -> Result<RunSummary, PipelineError> {
    train_run_with(ds, cfg, dir, resume, Vec::new(), on_progress)
}

/// [`train_run`] with extra loss terms added to the photometric loss (the fusion method of paper
/// 000 and its alternatives). The terms must be pure functions of the iteration and the model
/// for a resumed run to repeat an uninterrupted one.
pub fn train_run_with(
    ds: &Dataset,
    cfg: &RunConfig,
    dir: &Path,
    resume: bool,
    terms: Vec<Box<dyn LossTerm>>,
    on_progress: impl FnMut(&Progress),
) -> Result<RunSummary, PipelineError> {
    let run = RunDir(dir.to_path_buf());
    // Before anything is written: a run that cannot score its held-out views would otherwise
    // leave config.json and point_cloud.ply behind and fail only after training.
    for v in ds.test_views() {
        check_scorable(v).map_err(PipelineError::Eval)?;
    }
    let device = cfg.device.open()?.autodiff();
    let (_, extent) = ds.camera_extent();
    let resolved = ResolvedConfig {
        data: RunData::of(ds)?,
        extent,
        run: cfg.clone(),
    };
    let views: Vec<TrainView> = ds
        .train_views()
        .map(|v| {
            let view = TrainView::new(&v.name, RenderCamera::from(&v.camera), &v.image, &device);
            let view = match &v.valid {
                Some(valid) => view.with_valid(valid, &device),
                None => view,
            };
            match v.mask.as_ref().filter(|_| v.mask_is_alpha) {
                Some(a) => match AlphaImage::new(&v.image, a, ds.background) {
                    Some(alpha) => view.with_alpha(alpha),
                    None => view,
                },
                None => view,
            }
        })
        .collect();

    if resume && !run.checkpoint().exists() {
        return Err(PipelineError::Checkpoint {
            path: run.checkpoint(),
            message: if run.finished() {
                "nothing to resume: the run already finished".into()
            } else {
                "no checkpoint to resume from".into()
            },
        });
    }
    let mut memory = StagePeaks::default();
    let mut start = None;
    let mut init_used = resolve_init(ds, &cfg.init);
    let mut init_notes = Vec::new();
    let (model, resumed) = if resume {
        let saved = load_checkpoint(&run.checkpoint())?;
        if let Some(difference) = saved.data.difference(&resolved.data) {
            return Err(PipelineError::Checkpoint {
                path: run.checkpoint(),
                message: format!("the checkpoint belongs to another run: {difference}"),
            });
        }
        if saved.config != cfg.train {
            return Err(PipelineError::Checkpoint {
                path: run.checkpoint(),
                message: "the checkpoint was written with a different training configuration"
                    .into(),
            });
        }
        (None, Some(saved.state))
    } else {
        let init = memory.measure("initialisation", || initial_model_and_start(ds, cfg))?;
        (start, init_used, init_notes) = (init.start, init.used, init.notes);
        (Some(init.model), None)
    };
    // The run folder is made only now, once the initial Gaussians exist: an `--init` the
    // dataset cannot serve (a missing PLY, `points` without sparse points) fails with nothing
    // written.
    std::fs::create_dir_all(dir).map_err(|e| SceneError::io(dir, e))?;
    // A run interrupted while writing (SIGINT during a checkpoint) leaves a partial file.
    fewview_scene::atomic::remove_partial_files(dir)?;
    let json =
        serde_json::to_vec_pretty(&resolved).map_err(|e| PipelineError::Eval(e.to_string()))?;
    fewview_scene::atomic::write_bytes(&run.config(), &json)?;
    let cameras: Vec<serde_json::Value> = ds
        .train_views()
        .chain(ds.test_views())
        .map(|v| fewview_geom::io::cameras::camera_to_json(&v.camera))
        .collect();
    let json =
        serde_json::to_vec_pretty(&cameras).map_err(|e| PipelineError::Eval(e.to_string()))?;
    fewview_scene::atomic::write_bytes(&run.cameras(), &json)?;
    if let Some(s) = &start {
        s.write(ds, &run.init())
            .map_err(|e| PipelineError::Init(e.to_string()))?;
    }

    let mut trainer = match (model, resumed) {
        (Some(m), _) => Trainer::new(cfg.train.clone(), m, views, extent as f32, device)?,
        (None, Some(state)) => {
            let mut t = Trainer::new(
                cfg.train.clone(),
                state.model.clone(),
                views,
                extent as f32,
                device,
            )?;
            t.set_state(state);
            t
        }
        (None, None) => unreachable!("one of model or state"),
    };
    for term in terms {
        trainer.add_term(term);
    }
    if let InitStrategy::Surface(surface_dir) = &cfg.init
        && cfg.surface_depth_weight > 0.0
    {
        let surface = crate::surface_start::SurfaceRun::load(surface_dir, ds)?;
        trainer.add_term(Box::new(crate::surface_start::SurfaceDepthTerm::new(
            ds,
            &surface.mesh,
            cfg.surface_depth_weight,
        )?));
    }
    let resumed_from = (trainer.iteration() > 0).then_some(trainer.iteration());
    let start = Instant::now();
    let ckpt_path = run.checkpoint();
    memory.measure("training", || {
        trainer.run(on_progress, |state, config| {
            save_checkpoint(&ckpt_path, config, &resolved.data, state).map_err(|e| e.to_string())
        })
    })?;
    let train_seconds = start.elapsed().as_secs_f64();
    let iterations = trainer.iteration();
    let state = trainer.into_state()?;
    let model = &state.model;
    write_ply(&run.ply(), model)?;
    if !state.appearance.transforms.is_empty() {
        write_appearance(&run.appearance(), ds, &state.appearance.transforms)?;
    }

    let settings = RenderSettings {
        background: cfg.train.background,
        sh_degree: cfg.train.sh_degree,
        near_plane: cfg.train.near_plane,
    };
    let test: Vec<_> = ds.test_views().collect();
    let (report, renders) =
        evaluate(model, &test, &settings).map_err(|e| PipelineError::Eval(e.to_string()))?;
    let out = run.renders("test");
    std::fs::create_dir_all(&out).map_err(|e| SceneError::io(&out, e))?;
    for (v, r) in test.iter().zip(&renders) {
        r.rgb.save_png(&out.join(format!("{}.png", v.name)))?;
    }
    let summary = RunSummary {
        dataset: ds.name.clone(),
        init: init_used.name().to_string(),
        init_notes,
        memory,
        iterations,
        gaussians: model.len(),
        train_seconds,
        resumed_from,
        test: report,
    };
    let json =
        serde_json::to_vec_pretty(&summary).map_err(|e| PipelineError::Eval(e.to_string()))?;
    fewview_scene::atomic::write_bytes(&run.metrics(), &json)?;
    if run.checkpoint().exists() {
        // The run is complete; its result is the PLY.
        std::fs::remove_file(run.checkpoint()).map_err(|e| SceneError::io(run.checkpoint(), e))?;
    }
    Ok(summary)
}

/// `appearance.json`: each training photo's name and its colour transform `[A | b]` (3×4, row
/// by row).
fn write_appearance(
    path: &Path,
    ds: &Dataset,
    transforms: &[crate::train::appearance::Affine],
) -> Result<(), PipelineError> {
    let rows: Vec<serde_json::Value> = ds
        .train_views()
        .zip(transforms)
        .map(|(v, m)| {
            let matrix: Vec<&[f32]> = m.chunks(4).collect();
            serde_json::json!({ "view": v.name, "transform": matrix })
        })
        .collect();
    let json = serde_json::to_vec_pretty(&rows).map_err(|e| PipelineError::Eval(e.to_string()))?;
    fewview_scene::atomic::write_bytes(path, &json)?;
    Ok(())
}

/// Renders `model` along a smooth path through `keys` (SLERP rotations, linear centres).
pub fn render_path(
    model: &GaussianModel,
    keys: &[Camera],
    frames_per_segment: usize,
    settings: &RenderSettings,
) -> Vec<Image> {
    fewview_scene::camera_path(keys, frames_per_segment)
        .iter()
        .map(|c| render_model(model, &RenderCamera::from(c), settings).rgb)
        .collect()
}
