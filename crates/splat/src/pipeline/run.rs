//! One training run from start to end: check the data, start (or resume), write the run's
//! header files, train with checkpoints, then write the Gaussians, the held-out renders and
//! `metrics.json`.

use std::path::Path;
use std::time::Instant;

use burn::tensor::Device;
use fewview_scene::memory::StagePeaks;
use fewview_scene::{Dataset, SceneError};

use super::checkpoint::{load_checkpoint, save_checkpoint};
use super::config::{InitStrategy, RunConfig};
use super::error::PipelineError;
use super::run_dir::{ResolvedConfig, RunData, RunDir, RunSummary, write_appearance};
use super::start::{initial_model_and_start, resolve_init};
use crate::eval::{check_scorable, evaluate};
use crate::floaters::FloaterTerm;
use crate::model::GaussianModel;
use crate::ply::write_ply;
use crate::pseudo_depth::PseudoDepthTerm;
use crate::raster::{RenderCamera, RenderSettings};
use crate::stereo_depth::StereoDepthTerm;
use crate::stereo_start::{StereoStart, stereo_start};
use crate::surface_start::{SurfaceDepthTerm, SurfaceRun};
use crate::train::pair::{TrainerPair, second_seed};
use crate::train::{AlphaImage, LossTerm, Progress, TrainConfig, TrainState, TrainView, Trainer};

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

/// [`train_run`] with extra loss terms added to the photometric loss (the fusion method of the
/// fusion paper and its alternatives). The terms must be pure functions of the iteration and the
/// model for a resumed run to repeat an uninterrupted one.
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
    let mut memory = StagePeaks::default();
    let mut begun = if resume {
        Begun::resumed(ds, &run, &resolved)?
    } else {
        memory.measure("initialisation", || Begun::started(ds, cfg))?
    };
    // The run folder is made only now, once the initial Gaussians exist: an `--init` the
    // dataset cannot serve (a missing PLY, `points` without sparse points) fails with nothing
    // written.
    write_header(ds, &run, &resolved, begun.start.as_ref())?;

    let views = train_views(ds, &device);
    let second_start = second_start(cfg, &run, &begun)?;
    let mut trainer = begun.trainer(cfg, views.clone(), extent as f32, device)?;
    for term in terms {
        trainer.add_term(term);
    }
    let configured = ConfiguredTerms::new(ds, cfg, &begun)?;
    configured.add_to(&mut trainer);
    let resumed_from = (trainer.iteration() > 0).then_some(trainer.iteration());
    let clock = Instant::now();
    let trainer = train_to_end(
        ds,
        cfg,
        &configured,
        (trainer, second_start.map(|s| (s, views))),
        |first, second, config| {
            if let Some(second) = second {
                let config = second_config(config);
                save_checkpoint(&run.checkpoint_second(), &config, &resolved.data, second)?;
            }
            save_checkpoint(&run.checkpoint(), config, &resolved.data, first)
        },
        &mut memory,
        on_progress,
    )?;
    let trained = Trained {
        train_seconds: clock.elapsed().as_secs_f64(),
        iterations: trainer.iteration(),
        resumed_from,
        state: trainer.into_state()?,
        init: begun.used,
        init_notes: begun.notes,
        memory,
    };
    finish(ds, cfg, &run, trained)
}

/// The first field's trainer and, for CoR-GS, the second's start and views.
type Fields = (Trainer, Option<(Begun, Vec<TrainView>)>);

/// Trains to the end: one field, or CoR-GS's pair when the run has a second field, saving
/// checkpoints through `save(first, second, config)`; returns the first field's trainer.
fn train_to_end(
    ds: &Dataset,
    cfg: &RunConfig,
    configured: &ConfiguredTerms,
    (mut trainer, second): Fields,
    mut save: impl FnMut(&TrainState, Option<&TrainState>, &TrainConfig) -> Result<(), PipelineError>,
    memory: &mut StagePeaks,
    on_progress: impl FnMut(&Progress),
) -> Result<Trainer, PipelineError> {
    let (Some(co), Some((mut start, views))) = (cfg.co_reg, second) else {
        memory.measure("training", || {
            trainer.run(on_progress, |state, config| {
                save(state, None, config).map_err(|e| e.to_string())
            })
        })?;
        return Ok(trainer);
    };
    let device = trainer.device.clone();
    let mut second = start.trainer(cfg, views, trainer.extent, device)?;
    configured.add_to(&mut second);
    let cameras = ds.train_views().map(|v| v.camera.clone()).collect();
    let mut pair = TrainerPair::new(trainer, second, cameras, co)?;
    memory.measure("training", || {
        pair.run(on_progress, |first, second, config| {
            save(first, Some(second), config).map_err(|e| e.to_string())
        })
    })?;
    Ok(pair.first)
}

/// The training views of `ds` on `device`, with their valid-pixel masks and, for photos with
/// alpha, the alpha to composite them over another background.
fn train_views(ds: &Dataset, device: &Device) -> Vec<TrainView> {
    ds.train_views()
        .map(|v| {
            let view = TrainView::new(&v.name, RenderCamera::from(&v.camera), &v.image, device);
            let view = match &v.valid {
                Some(valid) => view.with_valid(valid, device),
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
        .collect()
}

/// Where training begins: fresh initial Gaussians or a checkpoint's state.
struct Begun {
    /// Whether this is the start of CoR-GS's second field.
    second: bool,
    model: Option<GaussianModel>,
    resumed: Option<TrainState>,
    start: Option<StereoStart>,
    used: InitStrategy,
    notes: Vec<String>,
}

impl Begun {
    /// The initial Gaussians of `ds` as `cfg` says.
    fn started(ds: &Dataset, cfg: &RunConfig) -> Result<Self, PipelineError> {
        let init = initial_model_and_start(ds, cfg)?;
        Ok(Self {
            second: false,
            model: Some(init.model),
            resumed: None,
            start: init.start,
            used: init.used,
            notes: init.notes,
        })
    }

    /// The state of the run's checkpoint, refused when it belongs to another dataset, split,
    /// size or training configuration.
    fn resumed(
        ds: &Dataset,
        run: &RunDir,
        resolved: &ResolvedConfig,
    ) -> Result<Self, PipelineError> {
        let refuse = |message: String| PipelineError::Checkpoint {
            path: run.checkpoint(),
            message,
        };
        if !run.checkpoint().exists() {
            return Err(refuse(if run.finished() {
                "nothing to resume: the run already finished".into()
            } else {
                "no checkpoint to resume from".into()
            }));
        }
        let saved = load_checkpoint(&run.checkpoint())?;
        if let Some(difference) = saved.data.difference(&resolved.data) {
            return Err(refuse(format!(
                "the checkpoint belongs to another run: {difference}"
            )));
        }
        if saved.config != resolved.run.train {
            return Err(refuse(
                "the checkpoint was written with a different training configuration".into(),
            ));
        }
        Ok(Self {
            second: false,
            model: None,
            resumed: Some(saved.state),
            start: None,
            used: resolve_init(ds, &resolved.run.init),
            notes: Vec::new(),
        })
    }

    /// The trainer, from the initial Gaussians or with the checkpoint's state set.
    fn trainer(
        &mut self,
        cfg: &RunConfig,
        views: Vec<TrainView>,
        extent: f32,
        device: Device,
    ) -> Result<Trainer, PipelineError> {
        let resumed = self.resumed.take();
        let model = match (self.model.take(), &resumed) {
            (Some(m), _) => m,
            (None, Some(state)) => state.model.clone(),
            (None, None) => unreachable!("one of model or state"),
        };
        let config = match self.second {
            true => second_config(&cfg.train),
            false => cfg.train.clone(),
        };
        let mut trainer = Trainer::new(config, model, views, extent, device)?;
        if let Some(state) = resumed {
            trainer.set_state(state);
        }
        Ok(trainer)
    }
}

/// Creates the run folder and writes `config.json`, `cameras.json` and the stereo start's files.
fn write_header(
    ds: &Dataset,
    run: &RunDir,
    resolved: &ResolvedConfig,
    start: Option<&StereoStart>,
) -> Result<(), PipelineError> {
    let dir = &run.0;
    std::fs::create_dir_all(dir).map_err(|e| SceneError::io(dir, e))?;
    // A run interrupted while writing (SIGINT during a checkpoint) leaves a partial file.
    fewview_scene::atomic::remove_partial_files(dir)?;
    let json =
        serde_json::to_vec_pretty(resolved).map_err(|e| PipelineError::Eval(e.to_string()))?;
    fewview_scene::atomic::write_bytes(&run.config(), &json)?;
    let cameras: Vec<serde_json::Value> = ds
        .train_views()
        .chain(ds.test_views())
        .map(|v| fewview_geom::io::cameras::camera_to_json(&v.camera))
        .collect();
    let json =
        serde_json::to_vec_pretty(&cameras).map_err(|e| PipelineError::Eval(e.to_string()))?;
    fewview_scene::atomic::write_bytes(&run.cameras(), &json)?;
    if let Some(s) = start {
        s.write(ds, &run.init())
            .map_err(|e| PipelineError::Init(e.to_string()))?;
    }
    Ok(())
}

/// The loss terms the run's configuration adds beside the caller's, built once: the surface
/// start's depth ([`SurfaceDepthTerm`]) and the terms on the stereo start's depth
/// ([`StereoDepthTerm`], [`PseudoDepthTerm`], [`FloaterTerm`]), those the run weighs. A co-regularised run gives each
/// field its own copy.
#[derive(Clone, Default)]
struct ConfiguredTerms {
    surface_depth: Option<SurfaceDepthTerm>,
    stereo_depth: Option<StereoDepthTerm>,
    pseudo_depth: Option<PseudoDepthTerm>,
    floaters: Option<FloaterTerm>,
}

impl ConfiguredTerms {
    /// The terms of `cfg` on `ds`. A resumed run builds its stereo start again (the same, from
    /// the same seed) when a stereo term needs it: the checkpoint keeps only the Gaussians.
    fn new(ds: &Dataset, cfg: &RunConfig, begun: &Begun) -> Result<Self, PipelineError> {
        let mut terms = Self::default();
        if let InitStrategy::Surface(surface_dir) = &cfg.init
            && cfg.surface_depth_weight > 0.0
        {
            let surface = SurfaceRun::load(surface_dir, ds)?;
            let term = SurfaceDepthTerm::new(ds, &surface.mesh, cfg.surface_depth_weight)?;
            terms.surface_depth = Some(term);
        }
        let wanted = cfg.stereo_depth_weight > 0.0
            || cfg.pseudo_depth_weight > 0.0
            || cfg.floater_weight > 0.0;
        if !wanted || begun.used != InitStrategy::Stereo {
            return Ok(terms);
        }
        let rebuilt;
        let start = match &begun.start {
            Some(start) => start,
            None => {
                rebuilt = stereo_start(ds, &cfg.stereo, cfg.train.seed, &mut |_, _| {})
                    .map_err(|e| PipelineError::Init(e.to_string()))?;
                &rebuilt
            }
        };
        if cfg.stereo_depth_weight > 0.0 {
            let term = StereoDepthTerm::new(&start.cloud, cfg.stereo_depth_weight);
            terms.stereo_depth = Some(term);
        }
        let cameras: Vec<_> = ds.train_views().map(|v| v.camera.clone()).collect();
        if cfg.pseudo_depth_weight > 0.0 {
            let (w, seed) = (cfg.pseudo_depth_weight, cfg.train.seed);
            let term = PseudoDepthTerm::new(cameras.clone(), &start.cloud, w, seed);
            terms.pseudo_depth = Some(term);
        }
        if cfg.floater_weight > 0.0 {
            terms.floaters = Some(FloaterTerm::new(cameras, &start.cloud, cfg.floater_weight));
        }
        Ok(terms)
    }

    /// Adds a copy of each term to `trainer`.
    fn add_to(&self, trainer: &mut Trainer) {
        if let Some(t) = &self.surface_depth {
            trainer.add_term(Box::new(t.clone()));
        }
        if let Some(t) = &self.stereo_depth {
            trainer.add_term(Box::new(t.clone()));
        }
        if let Some(t) = &self.pseudo_depth {
            trainer.add_term(Box::new(t.clone()));
        }
        if let Some(t) = &self.floaters {
            trainer.add_term(Box::new(t.clone()));
        }
    }
}

/// The training configuration of CoR-GS's second field: the first's with another seed.
fn second_config(first: &TrainConfig) -> TrainConfig {
    TrainConfig {
        seed: second_seed(first.seed),
        ..first.clone()
    }
}

/// Where the second field of a co-regularised run begins: the first's initial Gaussians, or its
/// own checkpoint when the run resumes; `None` for a run of one field.
fn second_start(
    cfg: &RunConfig,
    run: &RunDir,
    begun: &Begun,
) -> Result<Option<Begun>, PipelineError> {
    if cfg.co_reg.is_none() {
        return Ok(None);
    }
    let (model, resumed) = match &begun.model {
        Some(model) => (Some(model.clone()), None),
        None => {
            let saved = load_checkpoint(&run.checkpoint_second())?;
            let first = begun.resumed.as_ref().map_or(0, |s| s.iteration);
            if saved.state.iteration != first {
                return Err(PipelineError::Checkpoint {
                    path: run.checkpoint_second(),
                    message: format!(
                        "the second field stopped at iteration {}, the first at {first}; start \
                         the run again without --resume",
                        saved.state.iteration
                    ),
                });
            }
            (None, Some(saved.state))
        }
    };
    Ok(Some(Begun {
        second: true,
        model,
        resumed,
        start: None,
        used: begun.used.clone(),
        notes: Vec::new(),
    }))
}

/// What training leaves for [`finish`].
struct Trained {
    train_seconds: f64,
    iterations: usize,
    resumed_from: Option<usize>,
    state: TrainState,
    init: InitStrategy,
    init_notes: Vec<String>,
    memory: StagePeaks,
}

/// Writes the trained Gaussians, the colour transforms, the held-out renders and
/// `metrics.json`, then removes the checkpoint: the run is complete.
fn finish(
    ds: &Dataset,
    cfg: &RunConfig,
    run: &RunDir,
    trained: Trained,
) -> Result<RunSummary, PipelineError> {
    let model = &trained.state.model;
    write_ply(&run.ply(), model)?;
    if !trained.state.appearance.transforms.is_empty() {
        write_appearance(&run.appearance(), ds, &trained.state.appearance.transforms)?;
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
        init: trained.init.name().to_string(),
        init_notes: trained.init_notes,
        memory: trained.memory,
        iterations: trained.iterations,
        gaussians: model.len(),
        train_seconds: trained.train_seconds,
        resumed_from: trained.resumed_from,
        test: report,
    };
    let json =
        serde_json::to_vec_pretty(&summary).map_err(|e| PipelineError::Eval(e.to_string()))?;
    fewview_scene::atomic::write_bytes(&run.metrics(), &json)?;
    for path in [run.checkpoint_second(), run.checkpoint()] {
        if path.exists() {
            std::fs::remove_file(&path).map_err(|e| SceneError::io(&path, e))?;
        }
    }
    Ok(summary)
}
