//! Loading what a run reads ([`LoadedInputs`]) from a dataset folder or the built-in analytic
//! scene ([`Scene`]), with the checks that need the loaded views, before anything is written.

use std::path::{Path, PathBuf};

use fewview_geom::Mesh;
use fewview_scene::Dataset;
use fewview_scene::load::{LoadOptions, load_dataset};
use fewview_scene::pose_export::PoseSource;

use crate::config::{InitialPoses, RunConfig};
use crate::error::{Result, SurfaceError};
use crate::pipeline::{RunInputs, check_reference};
use crate::sdf_scene::{SdfSceneOptions, observed_faces, sdf_dataset, surface_mesh};

/// Where a run's views come from.
#[derive(Clone, Debug)]
pub enum Scene<'a> {
    /// The built-in sphere-traced analytic scene, scored against its exact surface.
    Synthetic {
        /// Add training views on rings at 0° and −30° elevation, so that the underside is
        /// observed too ([`SdfSceneOptions::ring_of_eight_all_around`]).
        all_around: bool,
    },
    /// A dataset folder.
    Folder {
        root: &'a Path,
        options: LoadOptions,
        /// Downscale factor of the images the matcher sees; `options.downscale` must be a
        /// multiple of it.
        match_downscale: u32,
        /// A surface in the dataset's normalised frame to score the mesh against (PLY/OBJ).
        reference: Option<&'a Path>,
    },
}

/// Everything a run reads, loaded; [`Self::run_inputs`] lends it to [`crate::pipeline::run`].
pub struct LoadedInputs {
    pub dataset: Dataset,
    /// The same folder's default cameras, when the run starts from other loaded poses.
    pub truth: Option<Dataset>,
    /// The training views at the matcher's resolution, when that differs.
    pub matching: Option<Dataset>,
    pub reference: Option<Mesh>,
    /// Which faces of `reference` a training view sees (known for the analytic scene).
    pub reference_observed: Option<Vec<bool>>,
    /// The folder and options the dataset was loaded with, to write the refined poses back.
    source: Option<(PathBuf, LoadOptions)>,
    /// The dataset folder's name (`synthetic` for the analytic scene), for a run folder's name.
    pub name: String,
}

impl LoadedInputs {
    /// Loads `scene` as the resolved `config` needs it, and checks that every scored test view
    /// keeps a pixel at 1/[`RunConfig::eval_scale`].
    pub fn load(scene: &Scene, config: &RunConfig) -> Result<Self> {
        let inputs = match scene {
            Scene::Synthetic { all_around } => Self::synthetic(*all_around)?,
            Scene::Folder {
                root,
                options,
                match_downscale,
                reference,
            } => Self::folder(root, options, *match_downscale, *reference, config)?,
        };
        check_eval_scale(&inputs.dataset, config)?;
        Ok(inputs)
    }

    fn synthetic(all_around: bool) -> Result<Self> {
        let dataset = sdf_dataset(&if all_around {
            SdfSceneOptions::ring_of_eight_all_around()
        } else {
            SdfSceneOptions::ring_of_eight()
        });
        let reference = surface_mesh(256)?;
        let cameras: Vec<_> = dataset
            .train
            .iter()
            .map(|&i| dataset.views[i].camera.clone())
            .collect();
        let observed = observed_faces(&reference, &cameras);
        Ok(Self {
            dataset,
            truth: None,
            matching: None,
            reference: Some(reference),
            reference_observed: Some(observed),
            source: None,
            name: "synthetic".into(),
        })
    }

    fn folder(
        root: &Path,
        options: &LoadOptions,
        match_downscale: u32,
        reference: Option<&Path>,
        config: &RunConfig,
    ) -> Result<Self> {
        let matching = matching_images(root, options, match_downscale)?;
        let dataset = load_folder(root, options)?;
        // With other starting poses, the ground truth is the same folder's default cameras.
        let truth = match (&config.initial_poses, &options.cameras_file) {
            (InitialPoses::AsLoaded, Some(_)) => {
                let defaults = LoadOptions {
                    cameras_file: None,
                    ..options.clone()
                };
                let truth = load_folder(root, &defaults)
                    .map_err(|e| SurfaceError::input("loading the ground-truth cameras", e))?;
                Some(truth)
            }
            _ => None,
        };
        let reference = reference.map(read_reference).transpose()?;
        let name = root
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "run".into());
        Ok(Self {
            dataset,
            truth,
            matching,
            reference,
            reference_observed: None,
            source: Some((root.to_path_buf(), options.clone())),
            name,
        })
    }

    /// The loaded inputs as [`crate::pipeline::run`] reads them.
    pub fn run_inputs(&self) -> RunInputs<'_> {
        RunInputs {
            dataset: &self.dataset,
            truth: self.truth.as_ref(),
            matching: self.matching.as_ref(),
            reference: self.reference.as_ref(),
            reference_observed: self.reference_observed.as_deref(),
            source: self
                .source
                .as_ref()
                .map(|(root, options)| PoseSource { root, options }),
        }
    }
}

fn load_folder(root: &Path, options: &LoadOptions) -> Result<Dataset> {
    load_dataset(root, options).map_err(|e| {
        SurfaceError::input(format!("cannot load dataset {}", root.display()), e.into())
    })
}

/// The training views at `match_downscale` for the matcher, when that differs from the
/// training resolution.
fn matching_images(
    root: &Path,
    options: &LoadOptions,
    match_downscale: u32,
) -> Result<Option<Dataset>> {
    let downscale = options.downscale;
    if match_downscale == 0 || !downscale.is_multiple_of(match_downscale) {
        return Err(SurfaceError::invalid(
            format!("--match-downscale {match_downscale}"),
            format!("must be at least 1 and divide --downscale {downscale}"),
        ));
    }
    if match_downscale == downscale {
        return Ok(None);
    }
    let fine = LoadOptions {
        downscale: match_downscale,
        ..options.clone()
    };
    let dataset = load_folder(root, &fine)
        .map_err(|e| SurfaceError::input("loading the images for matching", e))?;
    Ok(Some(dataset))
}

/// The reference surface at `path`, refused when Chamfer cannot score against it.
fn read_reference(path: &Path) -> Result<Mesh> {
    let mesh = fewview_geom::io::read_mesh(path).map_err(|e| {
        let what = format!("reading the reference surface {}", path.display());
        SurfaceError::input(what, e.into())
    })?;
    // Checked again by the pipeline; here the error can name the file.
    check_reference(&mesh).map_err(|e| SurfaceError::input(path.display().to_string(), e))?;
    Ok(mesh)
}

/// Every scored test view must keep a pixel at 1/`eval_scale`: a larger factor used to fail on
/// the first render, after the mesh and the poses were written.
fn check_eval_scale(dataset: &Dataset, config: &RunConfig) -> Result<()> {
    let k = config.eval_scale as usize;
    for &vi in dataset.test.iter().take(config.eval_views) {
        let v = &dataset.views[vi];
        if v.image.width < k || v.image.height < k {
            return Err(SurfaceError::invalid(
                format!("--eval-scale {k}"),
                format!(
                    "test view {} is {}×{}, which leaves no pixel at 1/{k}",
                    v.name, v.image.width, v.image.height
                ),
            ));
        }
    }
    Ok(())
}
