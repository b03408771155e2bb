//! The whole method on a dataset, as the CLI runs it ([`run`]): training views and their ground-truth
//! poses → perturbed initial poses (BARF/SPARF protocol) → correspondences → joint training
//! with checkpoints → refined poses, mesh, renders and metrics in one run directory.
//!
//! Run directory:
//! - `config.json` — the resolved configuration;
//! - `checkpoint.bin` — the training state (resume with the same configuration);
//! - `matches.json` — the correspondences (pixel coordinates, training-view indices,
//!   confidences), their count and precision against the true poses;
//! - `poses_initial.json`, `poses_refined.json` — cameras (intrinsics + world-to-camera);
//!   `poses_refined_aligned.json` — the refined cameras mapped by the Alg. 1 alignment into the
//!   frame of the dataset's cameras as loaded (what a splat run on the same dataset trains in); and
//!   the input's camera file with the refined poses mapped into the input's frame by the Alg. 1
//!   alignment (`cameras_sphere_refined.npz`, `poses_bounds_refined.npy`,
//!   `transforms_refined.json`, `sparse_refined/`, …; see [`fewview_scene::pose_export`]) when
//!   the dataset came from a folder;
//! - `mesh.ply` — marching cubes of the SDF, culled by the training masks, coloured, in the
//!   reconstruction's frame (that of `poses_refined.json`); `mesh_input_frame.ply` — the same
//!   mesh in the input's own world, the frame of the refined camera file (DTU: millimetres);
//! - `renders/` — colour, depth and normals of the test views (ground-truth cameras mapped into
//!   the reconstruction's frame by the Alg. 1 alignment): PNGs to look at, and `NNN_depth.npy`,
//!   depth along the optical axis in the input world's units (0 on the background);
//! - `metrics.json` — pose errors (Alg. 1/2) before and after, masked PSNR/SSIM of the test
//!   views, Chamfer of the mesh against a reference surface (Alg. 3) when one is given.

mod outputs;
mod prepare;
mod report;

use std::path::{Path, PathBuf};

use fewview_geom::Mesh;
use fewview_metrics::pose_error::{
    PoseError, PoseErrorOptions, SPARF_CODE_EPS, pose_error_pairwise,
};
use fewview_scene::pose_export::{PoseSource, write_refined_poses};
use fewview_scene::{Dataset, Se3};
use serde::Serialize;

use self::outputs::{TrainedField, input_world, reference_scores, render_test_views, write_meshes};
pub use self::outputs::{camera_in_estimate_frame, chamfer_of, register_to_reference};
pub use self::prepare::{Prepared, prepare, prepare_with_matching};
use self::prepare::{check_masks, check_view_count};
pub use self::report::{
    ChamferReport, Event, PoseErrorAt, RunReport, SparfEpsRotation, TestViewMetrics,
};
use crate::checkpoint;
use crate::config::RunConfig;
use crate::error::{Result, SurfaceError};
use crate::schedule::PoseTiming;
use crate::train::config::TrainConfig;
use crate::train::state::StepStats;
use crate::train::trainer::Trainer;
use fewview_sfm::global_start::PairPose;

/// The angle (degrees) between each pair's relative rotation and the true one, `R_b R_aᵀ` of
/// the true world-to-camera rotations.
fn pair_rotation_errors(pairs: &[PairPose], truth: &[Se3]) -> Vec<f64> {
    pairs
        .iter()
        .filter_map(|p| {
            let (a, b) = (truth.get(p.view_a)?, truth.get(p.view_b)?);
            let found = nalgebra::Matrix3::from_fn(|i, j| p.rotation[i][j]);
            let true_rel = b.rotation * a.rotation.transpose();
            Some(crate::pose::rotation_angle_deg(&found, &true_rel))
        })
        .collect()
}

fn pose_error(est: &[Se3], gt: &[Se3]) -> Result<PoseError> {
    pose_error_at_eps(est, gt, fewview_metrics::pose_error::EPS)
}

fn pose_error_at_eps(est: &[Se3], gt: &[Se3], eps: f64) -> Result<PoseError> {
    let options = PoseErrorOptions {
        eps,
        ..Default::default()
    };
    pose_error_pairwise(est, gt, &options)
        .map_err(|e| SurfaceError::invalid("pose error", e.to_string()))
}

fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| SurfaceError::invalid("json", e.to_string()))?;
    fewview_scene::atomic::write_bytes(path, text.as_bytes()).map_err(SurfaceError::Scene)
}

/// What a run reads.
#[derive(Clone, Copy)]
pub struct RunInputs<'a> {
    /// Training and test views with the poses to start from.
    pub dataset: &'a Dataset,
    /// Ground-truth cameras of the same views when `dataset` carries other poses.
    pub truth: Option<&'a Dataset>,
    /// The same views at a finer resolution for the matcher ([`prepare_with_matching`]).
    pub matching: Option<&'a Dataset>,
    /// A surface in the dataset's (normalised) frame for Chamfer.
    pub reference: Option<&'a Mesh>,
    /// For each face of `reference`, whether a training view sees it: Chamfer is then also
    /// scored on the observed part (`RunReport::chamfer_observed`), as DTU's protocol does.
    pub reference_observed: Option<&'a [bool]>,
    /// The folder `dataset` was loaded from, to write the refined poses back in its format.
    pub source: Option<PoseSource<'a>>,
}

/// A reference surface Chamfer can score against: faces with some area, on which Chamfer
/// samples its points. An empty, line-only or degenerate mesh used to be found out only after
/// training, as "not scored".
pub fn check_reference(reference: &Mesh) -> Result<()> {
    let what = "reference surface";
    if reference.faces.is_empty() {
        return Err(SurfaceError::invalid(
            what,
            format!(
                "has no faces ({} vertices): Chamfer samples points on a surface",
                reference.vertices.len()
            ),
        ));
    }
    let area = reference.area();
    if !(area.is_finite() && area > 0.0) {
        return Err(SurfaceError::invalid(
            what,
            format!("none of its {} faces has any area", reference.faces.len()),
        ));
    }
    Ok(())
}

/// What a checkpoint of this run must match for `--resume` to continue it
/// ([`checkpoint::RunIdentity`]): the data and the whole configuration except the settings a
/// resume may change — the iteration count, the checkpoint interval and the outputs (mesh
/// resolution, evaluated views and their scale).
pub fn run_identity(
    dataset: &Dataset,
    truth: Option<&Dataset>,
    matching: Option<&Dataset>,
    config: &RunConfig,
) -> Result<checkpoint::RunIdentity> {
    let cameras = |ds: &Dataset| -> Vec<checkpoint::CameraRecord> {
        ds.train_views()
            .map(|v| checkpoint::camera_record(&v.camera))
            .collect()
    };
    let sizes = |ds: &Dataset| -> Vec<[usize; 2]> {
        ds.train_views()
            .map(|v| [v.image.width, v.image.height])
            .collect()
    };
    let mut settings = serde_json::to_value(config)
        .map_err(|e| SurfaceError::invalid("configuration", e.to_string()))?;
    if let Some(all) = settings.as_object_mut() {
        for resumable in [
            "checkpoint_every",
            "mesh_resolution",
            "eval_views",
            "eval_scale",
        ] {
            all.remove(resumable);
        }
        if let Some(train) = all.get_mut("train").and_then(|t| t.as_object_mut()) {
            train.remove("iterations");
        }
    }
    Ok(checkpoint::RunIdentity {
        dataset: dataset.name.clone(),
        train_views: dataset.train_views().map(|v| v.name.clone()).collect(),
        image_sizes: sizes(dataset),
        matching_sizes: matching.map(sizes),
        cameras: cameras(dataset),
        truth_cameras: truth.map(cameras),
        settings_json: settings.to_string(),
    })
}

/// Runs everything and writes the run directory. `resume` continues from `checkpoint.bin`
/// when it exists.
pub fn run(
    inputs: RunInputs,
    config: &RunConfig,
    out: &Path,
    resume: bool,
    on_event: &mut dyn FnMut(Event),
) -> Result<RunReport> {
    let started = std::time::Instant::now();
    crate::matching::learned::check_weights(config.matcher_kind)
        .map_err(|e| SurfaceError::invalid("--matcher", e.to_string()))?;
    let resumed = start_run(&inputs, config, on_event)?;
    let ResumedRun { identity, saved } = if resume {
        resumed.resume(out, config)?
    } else {
        resumed
    };
    std::fs::create_dir_all(out).map_err(|e| SurfaceError::io(out, e))?;
    write_json(&out.join("config.json"), config)?;
    on_event(Event::Stage("matching"));
    let prep = prepare_with_matching(inputs.dataset, inputs.truth, inputs.matching, config)?;
    write_prepared(&prep, out, on_event)?;
    let stages = StageErrors::report(&prep, on_event)?;
    let patches_adjusted = prep
        .patch_adjustment
        .as_ref()
        .is_some_and(|report| report.skipped.is_none());
    let (train_config, fell_back) = config.effective_train(prep.warmup.as_ref(), patches_adjusted);
    let pose_timing = PoseTiming::of(&train_config);
    if fell_back {
        on_event(Event::PoseTimingFallback(&pose_timing));
    }
    let mut trainer = Trainer::new(
        train_config.clone(),
        prep.views.clone(),
        &prep.start,
        prep.matches.clone(),
    )?;
    if let Some(saved) = saved {
        trainer.restore(saved.into_state(&checkpoint_path(out), &train_config)?)?;
        trainer.sync_progress();
    }
    let checkpoints = Checkpoints {
        path: checkpoint_path(out),
        identity: &identity,
        every: config.checkpoint_every,
    };
    let trained = train(&mut trainer, &train_config, &prep, &checkpoints, on_event)?;
    on_event(Event::Stage("evaluating"));
    let evaluated = evaluate(&inputs, config, &prep, &stages, &trainer, out)?;
    let first = inputs.dataset.train_views().next();
    let report = RunReport {
        dataset: inputs.dataset.name.clone(),
        train_views: inputs
            .dataset
            .train_views()
            .map(|v| v.source_index)
            .collect(),
        image_size: first.map_or([0, 0], |v| [v.image.width, v.image.height]),
        seed: config.train.seed,
        run_seconds_wall: started.elapsed().as_secs_f64(),
        iterations: trainer.state.iteration,
        train_seconds_wall: trained.wall,
        train_seconds_cpu: trained.cpu,
        iterations_per_second_wall: if trained.wall > 0.0 {
            trained.done as f64 / trained.wall
        } else {
            0.0
        },
        matches: prep.matches.len(),
        matcher: prep.matcher.clone(),
        matcher_fallback: prep.matcher_fallback.clone(),
        match_precision: prep.match_precision.clone(),
        densified_because: prep.densified_because.clone(),
        initial_pose_error: evaluated.initial_err,
        warmup: prep.warmup.clone(),
        warmup_pose_error: stages.warmup,
        global_start_rotation_errors_deg: stages.global_start_rotation_errors_deg,
        bundle_adjustment: prep.bundle_adjustment.as_ref().map(|(r, _)| r.clone()),
        bundle_adjustment_pose_error: stages.bundle_adjustment,
        patch_adjustment: prep.patch_adjustment.clone(),
        patch_adjustment_pose_error: stages.patch_adjustment,
        pose_timing,
        pose_timing_fell_back: fell_back,
        final_pose_error: evaluated.final_err,
        rotation_at_sparf_eps: evaluated.rotation_at_sparf_eps,
        last_step: trained.last,
        pose_steps_skipped: trained.pose_steps_skipped,
        pose_error_history: trained.history,
        mean_psnr_masked: mean_of(&evaluated.test_views, |m| m.psnr_masked),
        mean_ssim_masked: mean_of(&evaluated.test_views, |m| m.ssim_masked),
        test_views: evaluated.test_views,
        chamfer: evaluated.chamfer,
        chamfer_observed: evaluated.chamfer_observed,
        chamfer_error: evaluated.chamfer_error,
        mesh_vertices: evaluated.mesh.vertices.len(),
        mesh_faces: evaluated.mesh.faces.len(),
        refined_pose_files: evaluated.refined_pose_files,
    };
    write_json(&out.join("metrics.json"), &report)?;
    Ok(report)
}

/// The run's identity and, when resuming, the checkpoint it continues.
struct ResumedRun {
    identity: checkpoint::RunIdentity,
    saved: Option<checkpoint::Saved>,
}

impl ResumedRun {
    /// Reads `out`'s checkpoint, when there is one, refusing one of another run.
    fn resume(self, out: &Path, config: &RunConfig) -> Result<Self> {
        let ckpt = checkpoint_path(out);
        if !ckpt.exists() {
            return Ok(self);
        }
        let saved = checkpoint::read(&ckpt)?;
        saved.check_run(&ckpt, &self.identity, config.train.iterations)?;
        Ok(Self {
            saved: Some(saved),
            ..self
        })
    }
}

/// Refuses what is wrong before the run folder is touched (no half-written output), and says
/// what the run is for `--resume`.
fn start_run(
    inputs: &RunInputs,
    config: &RunConfig,
    on_event: &mut dyn FnMut(Event),
) -> Result<ResumedRun> {
    config.train.validate()?;
    check_view_count(inputs.dataset)?;
    if let Some(reference) = inputs.reference {
        check_reference(reference)?;
    }
    if let Some(notice) = check_masks(inputs.dataset, config.train.use_masks)? {
        on_event(Event::Notice(notice));
    }
    let identity = run_identity(inputs.dataset, inputs.truth, inputs.matching, config)?;
    Ok(ResumedRun {
        identity,
        saved: None,
    })
}

/// Reports the correspondences and writes `matches.json` and `poses_initial.json`.
fn write_prepared(prep: &Prepared, out: &Path, on_event: &mut dyn FnMut(Event)) -> Result<()> {
    on_event(Event::Matched {
        matches: prep.matches.len(),
        matcher: prep.matcher.as_deref(),
        fallback: prep.matcher_fallback.as_deref(),
        precision: prep.match_precision.as_ref(),
        densified_because: prep.densified_because.as_deref(),
    });
    write_json(
        &out.join("matches.json"),
        &serde_json::json!({
            "matches": prep.matches.len(),
            "precision": prep.match_precision,
            "views": prep.view_indices,
            "correspondences": prep.matches,
        }),
    )?;
    fewview_geom::io::cameras::write_cameras(
        &out.join("poses_initial.json"),
        &prep.cameras(&prep.initial),
    )?;
    Ok(())
}

/// The pose errors after the warm-up, the bundle adjustment and the patch adjustment, for
/// those that ran.
struct StageErrors {
    warmup: Option<PoseError>,
    global_start_rotation_errors_deg: Vec<f64>,
    bundle_adjustment: Option<PoseError>,
    patch_adjustment: Option<PoseError>,
}

impl StageErrors {
    /// Scores each stage that ran and reports it as an event.
    fn report(prep: &Prepared, on_event: &mut dyn FnMut(Event)) -> Result<Self> {
        let truth = &prep.ground_truth;
        let global_start_rotation_errors_deg = prep
            .warmup
            .as_ref()
            .map(|w| pair_rotation_errors(&w.global_start, truth))
            .unwrap_or_default();
        let warmup = match &prep.warmup {
            Some(report) => {
                let err = pose_error(&prep.warmup_poses, truth)?;
                on_event(Event::WarmedUp {
                    report,
                    pose_error: &err,
                    pair_errors_deg: &global_start_rotation_errors_deg,
                });
                Some(err)
            }
            None => None,
        };
        let bundle_adjustment = match &prep.bundle_adjustment {
            Some((report, poses)) => {
                let err = pose_error(poses, truth)?;
                on_event(Event::BundleAdjusted {
                    report,
                    pose_error: &err,
                });
                Some(err)
            }
            None => None,
        };
        let patch_adjustment = match &prep.patch_adjustment {
            Some(report) => {
                let err = pose_error(&prep.start, truth)?;
                on_event(Event::PatchesAdjusted {
                    report,
                    pose_error: &err,
                });
                Some(err)
            }
            None => None,
        };
        Ok(Self {
            warmup,
            global_start_rotation_errors_deg,
            bundle_adjustment,
            patch_adjustment,
        })
    }
}

/// Where and how often the training saves its state.
struct Checkpoints<'a> {
    path: PathBuf,
    identity: &'a checkpoint::RunIdentity,
    /// Iterations between checkpoints (0: none).
    every: usize,
}

/// What the training loop of this invocation measured.
struct Trained {
    last: StepStats,
    pose_steps_skipped: usize,
    history: Vec<PoseErrorAt>,
    wall: f64,
    cpu: f64,
    /// Iterations of this invocation (a resumed run counts only its own).
    done: usize,
}

/// Steps `trainer` to `train_config.iterations`, saving a checkpoint and scoring the poses
/// every `checkpoints.every` iterations and at the end.
fn train(
    trainer: &mut Trainer,
    train_config: &TrainConfig,
    prep: &Prepared,
    checkpoints: &Checkpoints,
    on_event: &mut dyn FnMut(Event),
) -> Result<Trained> {
    on_event(Event::Stage("training"));
    let wall = std::time::Instant::now();
    let cpu = fewview_scene::cputime::process_cpu_seconds();
    let start_it = trainer.state.iteration;
    let mut last = StepStats::default();
    let mut pose_steps_skipped = 0;
    let mut history = Vec::new();
    while trainer.state.iteration < train_config.iterations {
        last = trainer.step()?;
        pose_steps_skipped += usize::from(last.pose_step_skipped);
        on_event(Event::Step(&last));
        let it = trainer.state.iteration;
        let every = checkpoints.every;
        if every > 0 && (it.is_multiple_of(every) || it == train_config.iterations) {
            checkpoint::save(
                &checkpoints.path,
                checkpoints.identity,
                train_config,
                &trainer.state,
            )?;
            let err = pose_error(&trainer.poses(), &prep.ground_truth)?;
            history.push(PoseErrorAt {
                iteration: it,
                rotation_deg: err.rotation_deg,
                translation: err.translation,
            });
            on_event(Event::Checkpoint {
                iteration: it,
                pose_error: &err,
            });
        }
    }
    Ok(Trained {
        last,
        pose_steps_skipped,
        history,
        wall: wall.elapsed().as_secs_f64(),
        cpu: fewview_scene::cputime::process_cpu_seconds() - cpu,
        done: trainer.state.iteration - start_it,
    })
}

/// What the evaluation after training found and wrote.
struct Evaluated {
    initial_err: PoseError,
    final_err: PoseError,
    rotation_at_sparf_eps: SparfEpsRotation,
    refined_pose_files: Vec<String>,
    mesh: Mesh,
    test_views: Vec<TestViewMetrics>,
    chamfer: Option<ChamferReport>,
    chamfer_observed: Option<ChamferReport>,
    chamfer_error: Option<String>,
}

/// Scores the refined poses, writes them (also in the input's format), the mesh and the test
/// views' renders, and scores the mesh against the reference.
fn evaluate(
    inputs: &RunInputs,
    config: &RunConfig,
    prep: &Prepared,
    stages: &StageErrors,
    trainer: &Trainer,
    out: &Path,
) -> Result<Evaluated> {
    let refined = trainer.poses();
    let initial_err = pose_error(&prep.initial, &prep.ground_truth)?;
    let final_err = pose_error(&refined, &prep.ground_truth)?;
    let rotation_at_sparf_eps = sparf_rotations(prep, stages, &refined)?;
    let refined_cams = prep.cameras(&refined);
    fewview_geom::io::cameras::write_cameras(&out.join("poses_refined.json"), &refined_cams)?;
    fewview_geom::io::cameras::write_cameras(
        &out.join("poses_refined_aligned.json"),
        &prep.cameras(&final_err.aligned_world_to_camera),
    )?;
    // The cameras the poses are scored against, and whose file frame the outputs go back to.
    let scored = inputs.truth.unwrap_or(inputs.dataset);
    let refined_pose_files = match inputs.source {
        Some(source) => write_input_format(source, scored, prep, &final_err, out)?,
        None => Vec::new(),
    };
    let (field, params) = trainer.field_params();
    let trained = TrainedField {
        field,
        params,
        config,
    };
    let to_input = input_world(scored, &final_err.alignment)?;
    let mesh = write_meshes(&trained, &prep.views, &refined_cams, &to_input, out)?;
    let alignment = &final_err.alignment;
    let test_views =
        render_test_views(&trained, inputs.dataset, scored, alignment, &to_input, out)?;
    let scores = inputs
        .reference
        .map(|gt| reference_scores(&mesh, gt, inputs.reference_observed, alignment));
    let (chamfer, chamfer_observed, chamfer_error) = scores.unwrap_or_default();
    Ok(Evaluated {
        initial_err,
        final_err,
        rotation_at_sparf_eps,
        refined_pose_files,
        mesh,
        test_views,
        chamfer,
        chamfer_observed,
        chamfer_error,
    })
}

/// The rotation errors of every stage again at SPARF's code's ε ([`SparfEpsRotation`]).
fn sparf_rotations(
    prep: &Prepared,
    stages: &StageErrors,
    refined: &[Se3],
) -> Result<SparfEpsRotation> {
    let at_sparf_eps = |poses: &[Se3]| pose_error_at_eps(poses, &prep.ground_truth, SPARF_CODE_EPS);
    let final_at_sparf_eps = at_sparf_eps(refined)?;
    Ok(SparfEpsRotation {
        eps: SPARF_CODE_EPS,
        initial_deg: at_sparf_eps(&prep.initial)?.rotation_deg,
        warmup_deg: match &stages.warmup {
            Some(_) => Some(at_sparf_eps(&prep.warmup_poses)?.rotation_deg),
            None => None,
        },
        bundle_adjustment_deg: match &prep.bundle_adjustment {
            Some((_, poses)) => Some(at_sparf_eps(poses)?.rotation_deg),
            None => None,
        },
        patch_adjustment_deg: match &stages.patch_adjustment {
            Some(_) => Some(at_sparf_eps(&prep.start)?.rotation_deg),
            None => None,
        },
        final_deg: final_at_sparf_eps.rotation_deg,
        final_per_view_deg: final_at_sparf_eps.per_view_rotation_deg,
    })
}

/// Writes the refined poses back into the input's camera file format, in the input's frame,
/// and returns the files written, relative to `out`.
///
/// The estimate's gauge is wherever the anchor view's initial pose put it (away from the
/// input's cameras by the noise of that pose), so its poses are first
/// mapped by the Alg. 1 alignment onto the cameras they are scored against (`scored`), which
/// keeps them consistent with the file's untouched views. Those are the truth's when given: its
/// normalised frame (DTU: its own `scale_mat`, which differs between scan65's
/// `cameras_sphere.npz` and `cameras_linear_init.npz`) is the one that maps the aligned poses
/// back to the file's world.
fn write_input_format(
    source: PoseSource,
    scored: &Dataset,
    prep: &Prepared,
    final_err: &PoseError,
    out: &Path,
) -> Result<Vec<String>> {
    let poses: Vec<(usize, Se3)> = prep
        .view_indices
        .iter()
        .copied()
        .zip(final_err.aligned_world_to_camera.iter().copied())
        .collect();
    Ok(write_refined_poses(source, scored, &poses, out)?
        .iter()
        .map(|p| p.strip_prefix(out).unwrap_or(p).display().to_string())
        .collect())
}

/// The mean of `f` over the scored test views; `None` without any.
fn mean_of(views: &[TestViewMetrics], f: impl Fn(&TestViewMetrics) -> f64) -> Option<f64> {
    (!views.is_empty()).then(|| views.iter().map(f).sum::<f64>() / views.len() as f64)
}

/// The run directory's checkpoint path.
pub fn checkpoint_path(out: &Path) -> PathBuf {
    out.join("checkpoint.bin")
}

#[cfg(test)]
mod tests {
    use super::outputs::z_depth;
    use super::*;
    use fewview_scene::{Camera, Image, Intrinsics};
    use nalgebra::Vector3;

    /// An empty training mask stops the run before its folder exists; masks covering every
    /// pixel let it go on with a notice; ordinary masks, and no masks asked for, say nothing.
    #[test]
    fn empty_masks_stop_the_run_and_full_ones_are_noticed() {
        let mut ds = crate::sdf_scene::sdf_dataset(&crate::sdf_scene::SdfSceneOptions {
            width: 32,
            height: 24,
            views: 4,
            train: vec![0, 1, 2],
            supersample: 1,
            ..Default::default()
        });
        assert_eq!(check_masks(&ds, true).unwrap(), None);
        let fill = |ds: &mut Dataset, view: usize, value: f32| {
            if let Some(m) = ds.views[view].mask.as_mut() {
                m.data.iter_mut().for_each(|v| *v = value);
            }
        };
        for v in 0..3 {
            fill(&mut ds, v, 1.0);
        }
        let notice = check_masks(&ds, true).unwrap().expect("a notice");
        assert!(notice.contains("cover every pixel"), "{notice}");
        fill(&mut ds, 1, 0.0);
        let err = check_masks(&ds, true).unwrap_err().to_string();
        assert!(err.contains("view 1") && err.contains("empty"), "{err}");
        assert_eq!(check_masks(&ds, false).unwrap(), None, "--no-masks");
        let out = tempfile::tempdir().unwrap().path().join("run");
        let inputs = RunInputs {
            dataset: &ds,
            truth: None,
            matching: None,
            reference: None,
            reference_observed: None,
            source: None,
        };
        assert!(run(inputs, &RunConfig::default(), &out, false, &mut |_| {}).is_err());
        assert!(!out.exists(), "nothing written");
    }

    /// A tilted plane seen by a turned camera: where a pixel's opacity reaches one half, the
    /// written depth is the hit point's camera-frame z (computed by transforming the point, not
    /// by the projection onto the axis the function uses) times the units, also when the
    /// opacity is 0.8 and the rendered depth is the weights' unnormalised sum; below one half,
    /// 0.
    #[test]
    fn depth_maps_hold_z_along_the_optical_axis_in_the_input_units() {
        let (w, h) = (12usize, 9usize);
        let camera = Camera::look_at(
            Intrinsics::centered(10.0, w as u32, h as u32),
            Vector3::new(0.4, -0.3, 3.0),
            Vector3::new(0.1, 0.2, 0.0),
            Vector3::new(0.0, 0.0, 1.0),
        );
        let (normal, offset) = (Vector3::new(0.2, -0.1, 1.0).normalize(), -0.05);
        let opacity = |i: usize| [1.0f32, 0.8, 0.3][i % 3];
        let mut depth = Vec::new();
        let mut expected = Vec::new();
        for i in 0..w * h {
            let (o, d) = camera.ray((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
            let t = (offset - normal.dot(&o)) / normal.dot(&d);
            assert!(t > 0.0);
            depth.push(opacity(i) * t as f32);
            let z = camera.world_to_camera.transform_point(&(o + t * d)).z;
            expected.push(if opacity(i) >= 0.5 { 2.5 * z } else { 0.0 });
        }
        let blank = |c: usize| Image::from_vec(w, h, c, vec![0.0; w * h * c]);
        let render = crate::extract::ViewRender {
            rgb: blank(3),
            depth: Image::from_vec(w, h, 1, depth),
            normal: blank(3),
            alpha: Image::from_vec(w, h, 1, (0..w * h).map(opacity).collect()),
        };
        let got = z_depth(&render, &camera, 2.5);
        assert_eq!(got.shape, [h, w]);
        for (i, (g, e)) in got.data.iter().zip(&expected).enumerate() {
            assert!(
                (g - e).abs() < 1e-5 * e.abs().max(1.0),
                "pixel {i}: {g} vs {e}"
            );
        }
        assert!(expected.iter().filter(|&&e| e > 0.0).count() >= 2 * w * h / 3);
    }
}
