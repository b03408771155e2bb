//! `fewview mcubes`: marching cubes of a scalar grid, with optional cleanup.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args as ClapArgs;
use fewview_geom::cleanup::{CullOptions, cull_by_mask_files, largest_component};
use fewview_geom::io::{cameras::read_cameras, read_npy, write_mesh};
use fewview_geom::mcubes::{GridSpec, marching_cubes};
use fewview_geom::topology::edge_report;

use super::geom_common::numbers;
use super::output_paths::check_file;

/// Extract the level set of a scalar grid as a watertight, outward-oriented triangle mesh.
///
/// The grid is a float32 .npy of shape (D0, D1, D2); sample [i, j, k] sits at
/// origin + voxel·(i, j, k). Values below --iso are inside (an SDF's negative side), and face
/// normals point towards increasing values.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Scalar grid (.npy, float32 or float64, 3-D).
    #[arg(long)]
    pub grid: PathBuf,
    /// Output mesh (.ply, .obj or .off).
    #[arg(long, short)]
    pub out: PathBuf,
    /// Level of the surface.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub iso: f32,
    /// Position of sample (0, 0, 0), "x,y,z".
    #[arg(long, default_value = "0,0,0", allow_hyphen_values = true)]
    pub origin: String,
    /// Sample spacing: one number, or "sx,sy,sz".
    #[arg(long, default_value = "1")]
    pub voxel: String,
    /// Keep only the largest connected component.
    #[arg(long)]
    pub largest_component: bool,
    /// Cameras for mask culling (JSON list).
    ///
    /// Cameras (JSON list) for mask culling; needs --masks, one per camera.
    #[arg(long, value_name = "FILE")]
    pub cameras: Option<PathBuf>,
    /// Object masks for culling, one per camera.
    ///
    /// Object masks (images, foreground above 0.5); vertices seen on background are removed.
    #[arg(long, num_args = 1..)]
    pub masks: Vec<PathBuf>,
}

pub fn run(args: Args) -> Result<()> {
    check_file(&args.out, "--out")?;
    let a = read_npy(&args.grid)?;
    let dims: [usize; 3] = match a.shape.as_slice() {
        [x, y, z] => [*x, *y, *z],
        s => bail!(
            "{}: grid must be 3-D, found shape {s:?}",
            args.grid.display()
        ),
    };
    let origin = numbers::<3>(&args.origin, "--origin")?;
    let voxel = if args.voxel.contains(',') {
        numbers::<3>(&args.voxel, "--voxel")?
    } else {
        [numbers::<1>(&args.voxel, "--voxel")?[0]; 3]
    };
    let spec = GridSpec {
        dims,
        origin,
        voxel,
    };
    let mut mesh = marching_cubes(&a.data, &spec, args.iso)
        .with_context(|| format!("marching cubes of {}", args.grid.display()))?;
    if let Some(cam_path) = &args.cameras {
        let cams = read_cameras(cam_path)?;
        if cams.len() != args.masks.len() {
            bail!(
                "{}: {} cameras but {} masks",
                cam_path.display(),
                cams.len(),
                args.masks.len()
            );
        }
        mesh = cull_by_mask_files(&mesh, &cams, &args.masks, &CullOptions::default())?;
    } else if !args.masks.is_empty() {
        bail!("--masks needs --cameras");
    }
    if args.largest_component {
        mesh = largest_component(&mesh);
    }
    write_mesh(&args.out, &mesh)?;
    let r = edge_report(&mesh);
    println!(
        "{}",
        serde_json::json!({
            "vertices": mesh.vertices.len(), "faces": mesh.faces.len(),
            "watertight": r.is_watertight(), "boundary_edges": r.boundary_edges,
            // Not the `PathBuf`: serde refuses a path that is not UTF-8.
            "out": args.out.display().to_string(),
        })
    );
    Ok(())
}
