//! `fewview pose-error`: camera pose error of the surface paper (Alg. 1 and 2, after SPARF).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args as ClapArgs, ValueEnum};
use fewview_geom::io::cameras::read_poses;
use fewview_metrics::pose_error::{
    EPS, PoseErrorOptions, pose_error_pairwise, pose_error_umeyama, rotation_floor_deg,
    rotation_floor_deg_f32,
};

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
/// list of row-major 4×4 world-to-camera matrices, in the same view order. Rotation errors use
/// arccos(clamp((tr − 1)/2, −1 + ε, 1 − ε)), so exactly aligned views report the floor
/// arccos(1 − ε) (0.081° for ε = 1e-6 in f64).
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Estimated poses.
    #[arg(long)]
    pub est: PathBuf,
    /// Ground-truth poses.
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
    let gt = read_poses(&args.gt)?;
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
    if let Some(p) = &args.json {
        write_json(p, &report)?;
    }
    println!("{report}");
    Ok(())
}
