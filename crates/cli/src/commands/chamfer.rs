//! `fewview chamfer`: the DTU Chamfer protocol, or Chamfer-L1 / F-score / normal consistency
//! against a synthetic ground-truth mesh.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::{Args as ClapArgs, ValueEnum};
use fewview_geom::chamfer::{
    DtuOptions, ObservationMask, dtu_chamfer, dtu_chamfer_points, surface_metrics,
};
use fewview_geom::io::{read_mesh, read_npy};
use fewview_geom::topology::require_edge_manifold;

use super::geom_common::{numbers, write_json};
use super::number_args::positive;
use super::output_paths::check_optional_file;

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Protocol {
    /// DTU: sample the mesh at --density, radius down-sample, optional observation mask or
    /// bounding box, accuracy/completeness below --max-dist, Chamfer = their mean.
    Dtu,
    /// Synthetic meshes: --samples uniform points per mesh, Chamfer-L1, F-score@τ, normal
    /// consistency.
    Synthetic,
}

/// Compare a reconstructed mesh with the ground truth.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Reconstructed mesh or points.
    ///
    /// Reconstructed mesh (.ply/.obj/.off); for --protocol dtu a face-less point cloud is used
    /// as already-sampled points.
    #[arg(long)]
    pub pred: PathBuf,
    /// Ground truth: points (DTU's stl*.ply) or a mesh (synthetic).
    #[arg(long)]
    pub gt: PathBuf,
    #[arg(long, value_enum, default_value = "dtu")]
    pub protocol: Protocol,
    /// DTU sampling density and down-sampling radius.
    #[arg(long, default_value_t = DtuOptions::default().density)]
    pub density: f64,
    /// DTU: distances at or above this are left out.
    #[arg(long, default_value_t = DtuOptions::default().max_dist)]
    pub max_dist: f64,
    /// DTU: bounding box of the kept points.
    ///
    /// DTU: keep predicted points in "minx,miny,minz,maxx,maxy,maxz" (without an observation mask).
    #[arg(long, allow_hyphen_values = true)]
    pub bbox: Option<String>,
    /// DTU observation mask (.npy voxel grid).
    ///
    /// DTU observation mask: a boolean/uint8/float .npy voxel grid (ObsMask converted from .mat).
    #[arg(long, requires_all = ["obs_bb_min", "obs_bb_max", "obs_res"])]
    pub obs_mask: Option<PathBuf>,
    /// Lower corner of the observation mask.
    ///
    /// The observation mask's lower corner "x,y,z" (the first row of `BB` in ObsMask*.mat).
    #[arg(long, allow_hyphen_values = true)]
    pub obs_bb_min: Option<String>,
    /// Upper corner of the observation mask.
    ///
    /// The observation mask's upper corner "x,y,z" (the second row of `BB` in ObsMask*.mat).
    #[arg(long, allow_hyphen_values = true)]
    pub obs_bb_max: Option<String>,
    /// The observation mask's voxel size (`Res` in ObsMask*.mat).
    #[arg(long)]
    pub obs_res: Option<f64>,
    /// DTU ground plane "a,b,c,d".
    ///
    /// Only ground truth with a·x + b·y + c·z + d > 0 counts.
    #[arg(long, allow_hyphen_values = true)]
    pub ground_plane: Option<String>,
    /// Synthetic: samples per mesh.
    #[arg(long, default_value_t = 100_000)]
    pub samples: usize,
    /// Synthetic: F-score thresholds (repeatable).
    #[arg(long, default_values_t = [0.01], value_parser = positive)]
    pub tau: Vec<f64>,
    #[arg(long, default_value_t = DtuOptions::default().seed)]
    pub seed: u64,
    /// Write the figures as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

pub fn run(args: Args) -> Result<()> {
    check_optional_file(args.json.as_deref(), "--json")?;
    let pred = read_mesh(&args.pred)?;
    let gt = read_mesh(&args.gt)?;
    let report = match args.protocol {
        Protocol::Dtu => {
            let obs_mask = match &args.obs_mask {
                Some(p) => {
                    let a = read_npy(p)?;
                    let dims: [usize; 3] = match a.shape.as_slice() {
                        [x, y, z] => [*x, *y, *z],
                        s => bail!("{}: observation mask must be 3-D, found {s:?}", p.display()),
                    };
                    Some(ObservationMask {
                        mask: a.data.iter().map(|&v| v > 0.5).collect(),
                        dims,
                        bb_min: numbers::<3>(
                            args.obs_bb_min.as_deref().unwrap_or(""),
                            "--obs-bb-min",
                        )?,
                        bb_max: numbers::<3>(
                            args.obs_bb_max.as_deref().unwrap_or(""),
                            "--obs-bb-max",
                        )?,
                        res: args.obs_res.unwrap_or(0.0),
                    })
                }
                None => None,
            };
            let bbox = args
                .bbox
                .as_deref()
                .map(|s| {
                    numbers::<6>(s, "--bbox").map(|b| ([b[0], b[1], b[2]], [b[3], b[4], b[5]]))
                })
                .transpose()?;
            let options = DtuOptions {
                density: args.density,
                max_dist: args.max_dist,
                obs_mask,
                bbox,
                ground_plane: args
                    .ground_plane
                    .as_deref()
                    .map(|s| numbers::<4>(s, "--ground-plane"))
                    .transpose()?,
                seed: args.seed,
                ..Default::default()
            };
            let r = if pred.faces.is_empty() {
                dtu_chamfer_points(&pred.vertices, &gt.vertices, &options)
            } else {
                dtu_chamfer(&pred, &gt.vertices, &options)
            }
            .with_context(|| {
                format!(
                    "DTU Chamfer of {} against {}",
                    args.pred.display(),
                    args.gt.display()
                )
            })?;
            serde_json::to_value(&r)?
        }
        Protocol::Synthetic => {
            for (m, p) in [(&pred, &args.pred), (&gt, &args.gt)] {
                if m.faces.is_empty() {
                    bail!(
                        "{}: the synthetic protocol needs a mesh with faces",
                        p.display()
                    );
                }
                require_edge_manifold(m, &p.display().to_string())?;
            }
            let r = surface_metrics(&pred, &gt, args.samples, &args.tau, args.seed).with_context(
                || {
                    format!(
                        "synthetic metrics of {} against {}",
                        args.pred.display(),
                        args.gt.display()
                    )
                },
            )?;
            serde_json::to_value(&r)?
        }
    };
    if let Some(p) = &args.json {
        write_json(p, &report)?;
    }
    println!("{report}");
    Ok(())
}
