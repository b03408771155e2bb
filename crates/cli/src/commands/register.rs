//! `fewview register`: the surface paper Alg. 3 — pre-align, FPFH + RANSAC, ICP.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args as ClapArgs;
use fewview_geom::io::{cameras::read_poses, read_points, write_points};
use fewview_geom::registration::{
    DenoiseOptions, IcpMethod, IcpStarts, RegistrationOptions, register,
};
use fewview_geom::similarity::Similarity;
use fewview_metrics::pose_error::{PoseErrorOptions, pose_error_pairwise};

use super::geom_common::write_json;
use super::output_paths::check_optional_file;

/// Register a reconstructed point cloud (or mesh vertices) onto a ground-truth cloud.
///
/// Pre-alignment (Alg. 3): either a 4×4 similarity (--prealign, JSON row-major [[...]]) or the
/// alignment of Alg. 1 between estimated and ground-truth camera poses (--est-poses/--gt-poses).
/// Then Open3D's pipeline with voxel size v: normals (2v, 30 nn), FPFH (5v, 100 nn), RANSAC
/// (1.5v, edge-length 0.9, 100000 iterations, confidence 0.999), ICP (--icp-threshold, default
/// 0.4v; give several for coarse-to-fine).
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Cloud to move (.ply/.obj/.off; mesh files use their vertices).
    #[arg(long)]
    pub source: PathBuf,
    /// Reference cloud.
    #[arg(long)]
    pub target: PathBuf,
    /// Voxel size v (units of the target).
    #[arg(long)]
    pub voxel: f64,
    /// Pre-alignment similarity (JSON 4×4).
    ///
    /// Pre-alignment similarity, JSON: a row-major 4×4 [[sR | t], [0 0 0 1]].
    #[arg(long, conflicts_with_all = ["est_poses", "gt_poses"])]
    pub prealign: Option<PathBuf>,
    /// Estimated camera poses (source frame).
    ///
    /// Estimated camera poses in the source's frame (camera JSON or list of 4×4 world-to-camera).
    #[arg(long, requires = "gt_poses")]
    pub est_poses: Option<PathBuf>,
    /// Ground-truth camera poses in the target's frame.
    #[arg(long, requires = "est_poses")]
    pub gt_poses: Option<PathBuf>,
    /// ICP correspondence distances, coarse to fine.
    ///
    /// ICP correspondence distance(s) thr_icp, coarse to fine; default 0.4·voxel.
    #[arg(long)]
    pub icp_threshold: Vec<f64>,
    #[arg(long, value_enum, default_value = "point-to-point")]
    pub icp: IcpMethod,
    /// Plane-projection radius for noisy scans.
    ///
    /// Deviation from Alg. 3 for noisy scans: project both clouds onto their local planes
    /// (≤ 100 neighbours within this radius, e.g. 2·voxel) and run point-to-plane ICP on them.
    /// Off by default (the paper's Open3D pipeline).
    #[arg(long, value_name = "R")]
    pub denoise_radius: Option<f64>,
    /// ICP start: `best` of two, or `ransac`.
    ///
    /// `best` (default; a deviation from Alg. 3): run ICP from RANSAC's result and from the
    /// pre-alignment and keep the better fit (higher fitness, then lower RMSE), so that RANSAC
    /// failing on a near-symmetric or rough reconstruction cannot undo a good pre-alignment.
    /// `ransac`: from RANSAC's result only, as the paper.
    #[arg(long, value_enum, default_value = "best")]
    pub icp_start: IcpStarts,
    /// Estimate a scale in point-to-point ICP too.
    #[arg(long)]
    pub with_scaling: bool,
    /// Seed of RANSAC's sampling.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Write the moved source here.
    #[arg(long, short)]
    pub out: Option<PathBuf>,
    /// Write the transforms and figures as JSON.
    #[arg(long)]
    pub report: Option<PathBuf>,
}

fn read_similarity(path: &std::path::Path) -> Result<Similarity> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{}: not JSON", path.display()))?;
    let rows = v.get("matrix").unwrap_or(&v);
    let m = (|| {
        let r = rows.as_array()?;
        if r.len() != 4 {
            return None;
        }
        let mut m = [[0.0f64; 4]; 4];
        for (i, row) in r.iter().enumerate() {
            let row = row.as_array()?;
            if row.len() != 4 {
                return None;
            }
            for (j, x) in row.iter().enumerate() {
                m[i][j] = x.as_f64()?;
            }
        }
        Some(m)
    })()
    .with_context(|| format!("{}: expected a row-major 4×4 matrix", path.display()))?;
    Similarity::from_rows(&m).with_context(|| format!("{}", path.display()))
}

pub fn run(args: Args) -> Result<()> {
    check_optional_file(args.out.as_deref(), "--out")?;
    check_optional_file(args.report.as_deref(), "--report")?;
    let source = read_points(&args.source)?;
    let target = read_points(&args.target)?;
    let pre = match (&args.prealign, &args.est_poses, &args.gt_poses) {
        (Some(p), _, _) => Some(read_similarity(p)?),
        (None, Some(e), Some(g)) => {
            let est = read_poses(e)?;
            let gt = read_poses(g)?;
            let r = pose_error_pairwise(&est, &gt, &PoseErrorOptions::default())
                .with_context(|| format!("aligning {} to {}", e.display(), g.display()))?;
            Some(r.alignment)
        }
        _ => None,
    };
    if args.voxel.is_nan() || args.voxel <= 0.0 {
        bail!("--voxel must be positive");
    }
    let mut options = RegistrationOptions::for_voxel(args.voxel);
    if !args.icp_threshold.is_empty() {
        options.icp_thresholds = args.icp_threshold.clone();
    }
    options.icp_method = args.icp.with_scaling(args.with_scaling);
    if let Some(radius) = args.denoise_radius {
        if !(radius > 0.0 && radius.is_finite()) {
            bail!("--denoise-radius must be positive, got {radius}");
        }
        options.icp_denoise = Some(DenoiseOptions {
            radius,
            max_nn: DenoiseOptions::DEFAULT_MAX_NN,
        });
    }
    options.icp_starts = args.icp_start;
    options.ransac.seed = args.seed;
    let result = register(&source, &target, pre.as_ref(), &options).with_context(|| {
        format!(
            "registering {} onto {}",
            args.source.display(),
            args.target.display()
        )
    })?;
    if let Some(out) = &args.out {
        let mut moved = source.clone();
        moved.positions = result.transformation.apply_points(&source.positions);
        moved.normals = None;
        write_points(out, &moved)?;
    }
    let report = serde_json::json!({
        "transformation": result.transformation.matrix_rows(),
        "scale": result.transformation.scale,
        "prealignment": result.prealignment.matrix_rows(),
        "ransac": result.global.as_ref().map(|g| serde_json::json!({
            "fitness": g.evaluation.fitness, "inlier_rmse": g.evaluation.inlier_rmse,
            "iterations": g.iterations, "matches": g.matches })),
        "icp": { "fitness": result.refined.evaluation.fitness, "inlier_rmse": result.refined.evaluation.inlier_rmse,
                 "iterations": result.refined.iterations,
                 "start": if result.refined_from_ransac { "ransac" } else { "prealignment" } },
        "downsampled": [result.downsampled.0, result.downsampled.1],
    });
    if let Some(p) = &args.report {
        write_json(p, &report)?;
    }
    println!("{report}");
    Ok(())
}
