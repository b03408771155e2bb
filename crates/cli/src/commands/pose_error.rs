//! `fewview pose-error`: camera pose error of the surface paper (Alg. 1 and 2, after SPARF).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::{Args as ClapArgs, ValueEnum};
use fewview_geom::io::cameras::read_poses;
use fewview_metrics::pose_error::{
    EPS, PoseErrorOptions, pose_error_pairwise, pose_error_umeyama, rotation_floor_deg,
    rotation_floor_deg_f32,
};
use fewview_metrics::relative_pose::relative_errors;
use fewview_scene::Se3;

use super::geom_common::write_json;
use super::output_paths::check_optional_file;

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Method {
    /// Alg. 1: best alignment over pairs of the first ≤ 10 views (scale from their centre
    /// distance, rigid map of the anchor view).
    Pairwise,
    /// Umeyama similarity of all camera centres (needs 3 non-collinear centres).
    Umeyama,
}

/// Rotation and translation error of estimated camera poses against ground truth.
///
/// Pose files: camera JSON (one or a list; intrinsics + row-major world_to_camera 4×4) or a JSON
/// list of row-major 4×4 world-to-camera matrices, in the same view order. The ground truth may
/// also be a dataset folder (any format `train` reads): the views the estimated cameras name
/// (`fewview poses` names each camera by its photo), else all its views in the loader's order. Rotation errors use
/// arccos(clamp((tr − 1)/2, −1 + ε, 1 − ε)), so exactly aligned views report the floor
/// arccos(1 − ε) (0.081° for ε = 1e-6 in f64). `relative` in the output: the errors of every
/// pair's relative rotation and baseline direction (median and maximum), which need no alignment.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Estimated poses.
    #[arg(long)]
    pub est: PathBuf,
    /// Ground-truth poses: a pose file or a dataset folder.
    #[arg(long)]
    pub gt: PathBuf,
    #[arg(long, value_enum, default_value = "pairwise")]
    pub method: Method,
    /// ε of the arccos clamp.
    #[arg(long, default_value_t = EPS)]
    pub eps: f64,
    /// Write the figures as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

pub fn run(args: Args) -> Result<()> {
    check_optional_file(args.json.as_deref(), "--json")?;
    let est = read_poses(&args.est)?;
    let gt = truth_poses(&args.gt, camera_names(&args.est).as_deref())?;
    let opts = PoseErrorOptions {
        eps: args.eps,
        ..Default::default()
    };
    let r = match args.method {
        Method::Pairwise => pose_error_pairwise(&est, &gt, &opts),
        Method::Umeyama => pose_error_umeyama(&est, &gt, &opts),
    }
    .with_context(|| {
        format!(
            "comparing {} with {}",
            args.est.display(),
            args.gt.display()
        )
    })?;
    let mut report = serde_json::to_value(&r)?;
    report["alignment_matrix"] = serde_json::to_value(r.alignment.matrix_rows())?;
    report["rotation_floor_deg_f64"] = rotation_floor_deg(args.eps).into();
    report["rotation_floor_deg_f32"] = rotation_floor_deg_f32(args.eps).into();
    report["relative"] = serde_json::to_value(relative_errors(&est, &gt)?)?;
    if let Some(p) = &args.json {
        write_json(p, &report)?;
    }
    println!("{report}");
    Ok(())
}

/// The poses of a pose file, or of a dataset folder's views: those named `names` (a view
/// matches a name or its file stem), else every view in the loader's order.
fn truth_poses(path: &Path, names: Option<&[String]>) -> Result<Vec<Se3>> {
    if !path.is_dir() {
        return Ok(read_poses(path)?);
    }
    let Some(names) = names else {
        let options = fewview_scene::load::LoadOptions::default();
        let dataset = fewview_scene::load::load_dataset(path, &options)?;
        return Ok(dataset
            .views
            .iter()
            .map(|v| v.camera.world_to_camera)
            .collect());
    };
    let dataset = fewview_scene::load::load_dataset(path, &every_view(path)?)?;
    names
        .iter()
        .map(|name| {
            let stem = Path::new(name).file_stem().and_then(|s| s.to_str());
            dataset
                .views
                .iter()
                .find(|v| v.name == *name || Some(v.name.as_str()) == stem)
                .map(|v| v.camera.world_to_camera)
                .with_context(|| format!("{}: no view named {name}", path.display()))
        })
        .collect()
}

/// Options that load every view of a dataset folder: NeRF-synthetic's loader otherwise keeps
/// the sparse split's 8 training views (and every test view, whose names repeat the training
/// views'), so there every training frame is asked for, before one test frame (the loader
/// refuses an empty split; names are looked up among the training views first).
fn every_view(path: &Path) -> Result<fewview_scene::load::LoadOptions> {
    let train = path.join("transforms_train.json");
    let mut options = fewview_scene::load::LoadOptions::default();
    if train.is_file() {
        let frames = fewview_scene::transforms::read_transforms(&train)?.len();
        options.train_views = Some((0..frames).collect());
        options.test_views = Some(vec![0]);
    }
    Ok(options)
}

/// The `name` of every camera in a camera file, when each has one (`fewview poses` writes
/// them).
fn camera_names(path: &Path) -> Option<Vec<String>> {
    fewview_geom::io::cameras::read_named_cameras(path)
        .ok()?
        .into_iter()
        .map(|(_, name)| name)
        .collect()
}
