//! `fewview stereo`: two-view stereo of one pair of a dataset (the fusion paper §2), with everything it
//! computes written out for inspection.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args as ClapArgs;
use fewview_geom::stereo::source::DisparityRange;
use fewview_scene::Dataset;
use fewview_scene::synthetic::{DemoOptions, demo_dataset};
use fewview_splat::stereo_pair::inspect_pair;
use fewview_splat::stereo_start::StereoInit;

use super::dataset_args::ViewList;
use super::output_paths::check_folder;
use super::progress;

/// Rectify two views, match them with Semi-Global Matching both ways, and build their
/// hierarchical point cloud (the fusion paper's supplement §2).
///
/// Writes to `--out`: the rectified pair (`rectified_left.png`, `rectified_right.png`), the
/// disparity maps of both rectified images (`disparity_left.npy`/`.png`, `disparity_right…`;
/// float32 pixels, 0 where none), the depth of both views in their original cameras
/// (`depth_<view>.npy`/`.png`, z-depth, 0 where none), where the cloud's points came from
/// (`regions_<view>.png`: red pairwise consistent, green overlap with occlusion or mismatch, blue
/// seen by one view), the cloud (`cloud.ply` in the pixels' colours, `cloud_regions.ply` in the
/// regions' colours) and `stereo.json` (parameters, rectification, counts, timings).
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Dataset folder (any format `train` reads).
    #[arg(
        long,
        value_name = "DIR",
        required_unless_present = "demo",
        conflicts_with = "demo"
    )]
    pub data: Option<PathBuf>,
    /// Use the in-process demo scene.
    ///
    /// Use the demo scene built in-process instead of a dataset.
    #[arg(long)]
    pub demo: bool,
    /// Downscale images by this integer factor on load.
    #[arg(long, default_value_t = 1, value_name = "K")]
    pub downscale: u32,
    /// The two views, e.g. `1,10`.
    ///
    /// The two views, as indices in the dataset's view order (e.g. `1,10`).
    #[arg(long, value_name = "A,B", value_parser = super::dataset_args::parse_views)]
    pub views: ViewList,
    /// Disparity search range `MIN:COUNT`.
    ///
    /// Default: from the views' depth bounds.
    #[arg(long, value_name = "MIN:COUNT", value_parser = parse_range)]
    pub disparities: Option<(i32, usize)>,
    /// Keep SGM's own sub-pixel disparities.
    ///
    /// No Lucas–Kanade refinement.
    #[arg(long)]
    pub no_refine: bool,
    /// Output folder.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

fn parse_range(s: &str) -> Result<(i32, usize), String> {
    let (a, b) = s
        .split_once(':')
        .ok_or_else(|| format!("{s}: expected MIN:COUNT, e.g. 0:64"))?;
    let min = a
        .parse()
        .map_err(|_| format!("{s}: `{a}` is not an integer"))?;
    let count: usize = b
        .parse()
        .map_err(|_| format!("{s}: `{b}` is not a count"))?;
    if !(2..=1024).contains(&count) {
        return Err(format!("{s}: the count must be 2 to 1024"));
    }
    Ok((min, count))
}

pub fn run(args: Args) -> Result<()> {
    check_folder(&args.out, "--out")?;
    let [a, b] = args.views.0[..] else {
        bail!("--views: give exactly two views, e.g. 1,10");
    };
    let ds = load(&args)?;
    let mut init = StereoInit::default();
    if let Some((min, count)) = args.disparities {
        init.range = DisparityRange::Fixed { min, count };
    }
    if args.no_refine {
        init.refine = None;
    }
    let bar = progress::iterations(2, "stereo");
    let inspection = inspect_pair(&ds, (a, b), &init, &mut |done, _| {
        bar.set_position(done as u64);
    })?;
    bar.finish_and_clear();
    inspection.write(&args.out)?;
    let (pair, c) = (&inspection.pair, &inspection.cloud.counts);
    let [first, second] = &inspection.names;
    let swapped = if pair.swapped {
        " (matched right to left)"
    } else {
        ""
    };
    println!("views            {first} and {second}{swapped}");
    println!(
        "disparities      {} to {}",
        pair.params.min_disparity,
        pair.params.min_disparity + pair.params.num_disparities as i32 - 1
    );
    println!(
        "valid            left {:.1} %, right {:.1} %",
        100.0 * pair.left_disparity.valid_fraction(),
        100.0 * pair.right_disparity.valid_fraction()
    );
    println!(
        "points           {} (consistent {}, overlap {}, single view {})",
        inspection.cloud.points.len(),
        c.accepted[0],
        c.accepted[1],
        c.accepted[2]
    );
    println!("matching         {:.2} s", inspection.match_seconds);
    println!("outputs          {}", args.out.display());
    Ok(())
}

fn load(args: &Args) -> Result<Dataset> {
    if args.demo {
        return Ok(demo_dataset(&DemoOptions::default()));
    }
    let folder = args
        .data
        .as_deref()
        .expect("clap requires --data without --demo");
    let options = fewview_scene::load::LoadOptions {
        downscale: args.downscale,
        ..Default::default()
    };
    fewview_scene::load_dataset(folder, &options)
        .with_context(|| format!("cannot load dataset {}", folder.display()))
}
