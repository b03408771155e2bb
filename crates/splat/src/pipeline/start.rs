//! The initial Gaussians of a run: what [`InitStrategy::Auto`] resolves to on a dataset, and each
//! strategy's Gaussians (the stereo start of the fusion paper §2, sparse points, random points,
//! a PLY, a surface run's mesh).

use fewview_scene::{Camera, Dataset, Image};
use nalgebra::Vector3;

use super::config::{InitStrategy, MAX_INIT_POINTS, RunConfig};
use super::error::PipelineError;
use crate::init::{
    FrustumView, PATCH_SCALE_CAP, from_points, from_stereo_points, random_in_box,
    random_in_frustums,
};
use crate::model::GaussianModel;
use crate::ply::read_ply;
use crate::stereo_start::{PointAgreement, StereoInit, StereoStart, stereo_start};

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
            let (model, s) = from_stereo_start(ds, cfg, &mut notes)?;
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
        InitStrategy::RandomFrustum => in_frustums(ds, cfg)?,
        InitStrategy::RandomBox { half_size } => in_box(ds, cfg, half_size),
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

/// Gaussians from the stereo start's sampled points (and its sky shell), with a line in `notes`
/// for each pair skipped or swept, each agreement check, a sample cap and a scale cap.
fn from_stereo_start(
    ds: &Dataset,
    cfg: &RunConfig,
    notes: &mut Vec<String>,
) -> Result<(GaussianModel, StereoStart), PipelineError> {
    let s = stereo_start(ds, &cfg.stereo, cfg.train.seed, &mut |_, _| {})
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
    let (mut model, capped) = from_stereo_points(
        &s.sample,
        cfg.train.sh_degree,
        &s.sample_footprints,
        spacing,
    );
    if let Some(shell) = &s.shell {
        for ((p, c), scale) in shell.positions.iter().zip(&shell.colors).zip(&shell.scales) {
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
    Ok((model, s))
}

/// Random points in the training frustums between each view's depth bounds.
fn in_frustums(ds: &Dataset, cfg: &RunConfig) -> Result<GaussianModel, PipelineError> {
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
    let points = random_in_frustums(&views, cfg.init_points, cfg.train.seed);
    Ok(from_points(&points, cfg.train.sh_degree))
}

/// Random points in a cube around the point the training cameras look at, of half-size
/// `half_size` or 0.35 × the median camera distance to it.
fn in_box(ds: &Dataset, cfg: &RunConfig, half_size: Option<f64>) -> GaussianModel {
    let cams: Vec<&Camera> = ds.train_views().map(|v| &v.camera).collect();
    let center = look_at_point(&cams);
    let mut dists: Vec<f64> = cams.iter().map(|c| (c.center() - center).norm()).collect();
    dists.sort_by(f64::total_cmp);
    let half = half_size.unwrap_or(0.35 * dists[dists.len() / 2]);
    let lo = [center.x - half, center.y - half, center.z - half];
    let hi = [center.x + half, center.y + half, center.z + half];
    let views: Vec<(&Camera, &Image)> = ds.train_views().map(|v| (&v.camera, &v.image)).collect();
    let points = random_in_box(lo, hi, cfg.init_points, cfg.train.seed, &views);
    from_points(&points, cfg.train.sh_degree)
}
