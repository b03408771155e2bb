//! `fewview depth-points`: point clouds from depth maps (the fusion paper §2): Eq. (1) filter,
//! contraction of Eq. (2), random subsampling for Gaussian initialisation.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args as ClapArgs;
use fewview_geom::contract::{ContractionKind, contraction_reference, subsample};
use fewview_geom::depth::{DepthOptions, depth_to_points_with};
use fewview_geom::io::write_points;
use fewview_geom::mesh::{Points, f3, v3};

use super::depth_mesh::{DepthInput, load_depth_view};
use super::number_args::fraction;
use super::output_paths::check_file;

/// Back-project depth maps to a coloured point cloud.
///
/// Give one or more --depth with as many --cameras (or one camera file listing a camera per
/// depth map, in order) and optionally as many --images. With --contract, B_near is the depth at
/// --quantile of all valid depths (our reading of "largest depth within the top 10 %"), B_far =
/// 2·B_near, and T is the centre of the view holding that depth.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Depth maps (.npy or .png), repeatable.
    #[arg(long, required = true)]
    pub depth: Vec<PathBuf>,
    /// Camera files, one per depth map.
    ///
    /// The first camera of each file, or one file listing a camera per depth map.
    #[arg(long = "cameras", value_name = "FILE", required = true)]
    pub cameras: Vec<PathBuf>,
    /// Colour images, one per depth map.
    #[arg(long = "images")]
    pub images: Vec<PathBuf>,
    #[command(flatten)]
    pub input: DepthInput,
    /// Contract far points (none when left out).
    #[arg(long, value_enum)]
    pub contract: Option<ContractionKind>,
    /// Quantile of the depths taken as B_near.
    ///
    /// Quantile of the pooled depths taken as B_near (1.0 = the maximum depth).
    #[arg(long, default_value_t = 0.9)]
    pub quantile: f64,
    /// Random fraction of the points kept.
    ///
    /// Keep this random fraction of the points (0.1 for Gaussian initialisation, 0.01 for the
    /// sparse alternative (a)); 1 keeps all.
    #[arg(long, default_value_t = 1.0, value_parser = fraction)]
    pub subsample: f64,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output point cloud (.ply, .obj or .off).
    #[arg(long, short)]
    pub out: PathBuf,
}

pub fn run(args: Args) -> Result<()> {
    check_file(&args.out, "--out")?;
    let n = args.depth.len();
    if !(args.cameras.len() == n || args.cameras.len() == 1) {
        bail!("{n} depth maps but {} camera files", args.cameras.len());
    }
    if !(args.images.is_empty() || args.images.len() == n) {
        bail!("{n} depth maps but {} images", args.images.len());
    }
    let mut views = Vec::with_capacity(n);
    for (k, depth) in args.depth.iter().enumerate() {
        let (cam_file, view) = if args.cameras.len() == 1 && n > 1 {
            (&args.cameras[0], k)
        } else {
            (&args.cameras[k], 0)
        };
        views.push(load_depth_view(
            depth,
            &args.input,
            cam_file,
            view,
            args.images.get(k).map(std::path::PathBuf::as_path),
        )?);
    }
    let opts = DepthOptions {
        tau: args.input.tau,
        test: args.input.edge_test,
    };
    let mut all = Points::default();
    let coloured = !args.images.is_empty();
    if coloured {
        all.colors = Some(Vec::new());
    }
    for (k, (depth, cam, img)) in views.iter().enumerate() {
        let p = depth_to_points_with(depth, cam, img.as_ref(), &opts)
            .with_context(|| format!("back-projecting {}", args.depth[k].display()))?;
        all.positions.extend(p.positions);
        if let (Some(a), Some(c)) = (all.colors.as_mut(), p.colors) {
            a.extend(c);
        }
    }
    let mut report = serde_json::json!({ "points": all.len() });
    if let Some(kind) = args.contract {
        let refs: Vec<(&[f32], &fewview_scene::Camera)> =
            views.iter().map(|(d, c, _)| (d.as_slice(), c)).collect();
        let c = contraction_reference(&refs, &opts, args.quantile, kind).with_context(|| {
            let names: Vec<String> = args.depth.iter().map(|d| d.display().to_string()).collect();
            format!("--contract over {}", names.join(", "))
        })?;
        all.positions = all.positions.iter().map(|p| f3(&c.apply(&v3(p)))).collect();
        report["contraction"] = serde_json::json!({
            "view": c.view, "b_near": c.b_near, "b_far": c.b_far,
            "center": [c.center.x, c.center.y, c.center.z],
        });
    }
    let out = if args.subsample < 1.0 {
        subsample(&all, args.subsample, args.seed)?
    } else {
        all
    };
    report["written"] = out.len().into();
    write_points(&args.out, &out)?;
    println!("{report}");
    Ok(())
}
