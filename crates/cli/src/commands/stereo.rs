//! `fewview stereo`: two-view stereo of one pair of a dataset (paper 000 §2), with everything it
//! computes written out for inspection.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args as ClapArgs;
use fewview_geom::colormap::colorize;
use fewview_geom::io::{write_npy, write_points};
use fewview_geom::stereo::hierarchy::{HierarchyOptions, hierarchical_cloud};
use fewview_geom::stereo::pairs::{OverlapRule, StereoView, check_overlap, with_depth_bounds};
use fewview_geom::stereo::source::{
    DepthSource, DisparityRange, PairDepths, PairStereo, match_pair,
};
use fewview_scene::Dataset;
use fewview_scene::synthetic::{DemoOptions, demo_dataset};
use fewview_splat::stereo_start::StereoInit;

use super::dataset_args::ViewList;
use super::output_paths::check_folder;
use super::progress;

/// Rectify two views, match them with Semi-Global Matching both ways, and build their
/// hierarchical point cloud (paper 000 §2).
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
    /// Use the demo scene built in-process instead of a dataset.
    #[arg(long)]
    pub demo: bool,
    /// Downscale images by this integer factor on load.
    #[arg(long, default_value_t = 1, value_name = "K")]
    pub downscale: u32,
    /// The two views, as indices in the dataset's view order (e.g. `1,10`).
    #[arg(long, value_name = "A,B", value_parser = super::dataset_args::parse_views)]
    pub views: ViewList,
    /// Disparity search range `MIN:COUNT` (default: from the views' depth bounds).
    #[arg(long, value_name = "MIN:COUNT", value_parser = parse_range)]
    pub disparities: Option<(i32, usize)>,
    /// Keep SGM's own sub-pixel disparities (no Lucas–Kanade refinement).
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
    for v in [a, b] {
        if v >= ds.views.len() {
            bail!(
                "--views: view {v} is out of range ({} has {} views)",
                ds.name,
                ds.views.len()
            );
        }
    }
    let listed: Vec<StereoView> = [a, b]
        .iter()
        .map(|&i| StereoView::of(&ds.views[i]))
        .collect();
    let views = with_depth_bounds(&listed);
    let look_at = fewview_scene::axes_meeting_point(&[
        views[0].camera.world_to_camera,
        views[1].camera.world_to_camera,
    ]);
    check_overlap(&views[0], &views[1], &look_at, &OverlapRule::default())?;
    let init = StereoInit::default();
    let range = match args.disparities {
        Some((min, count)) => DisparityRange::Fixed { min, count },
        None => init.range,
    };
    let refine = (!args.no_refine).then_some(init.refine).flatten();
    let bar = progress::iterations(2, "stereo");
    let start = std::time::Instant::now();
    let pair = match_pair(&views[0], &views[1], &init.sgm, range, refine.as_ref())?;
    let match_seconds = start.elapsed().as_secs_f64();
    bar.inc(1);
    let source = OnePair(pair.depths.clone());
    let cloud = hierarchical_cloud(
        &views,
        &[(0, 1)],
        &source,
        &HierarchyOptions {
            contraction: None,
            ..init.hierarchy.clone()
        },
        &mut |_, _| {},
    )?;
    bar.inc(1);
    bar.finish_and_clear();
    write_outputs(&args.out, &views, &pair, &cloud, match_seconds)?;
    let c = &cloud.counts;
    println!(
        "views            {} and {}{}",
        views[0].name,
        views[1].name,
        if pair.swapped {
            " (matched right to left)"
        } else {
            ""
        }
    );
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
        cloud.points.len(),
        c.accepted[0],
        c.accepted[1],
        c.accepted[2]
    );
    println!("matching         {match_seconds:.2} s");
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

/// The depth of the one pair already matched.
struct OnePair(PairDepths);

impl DepthSource for OnePair {
    fn name(&self) -> &str {
        "sgm"
    }
    fn pair_depths(&self, _: usize, _: usize) -> fewview_geom::Result<PairDepths> {
        Ok(self.0.clone())
    }
}

fn write_outputs(
    out: &Path,
    views: &[StereoView],
    pair: &PairStereo,
    cloud: &fewview_geom::stereo::hierarchy::HierarchicalCloud,
    match_seconds: f64,
) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    pair.left.image.save_png(&out.join("rectified_left.png"))?;
    pair.right
        .image
        .save_png(&out.join("rectified_right.png"))?;
    for (side, disp) in [
        ("left", &pair.left_disparity),
        ("right", &pair.right_disparity),
    ] {
        let values: Vec<f32> = disp
            .to_f32()
            .iter()
            .map(|v| if v.is_finite() { *v } else { 0.0 })
            .collect();
        write_npy(
            &out.join(format!("disparity_{side}.npy")),
            &[disp.height, disp.width],
            &values,
        )?;
        colorize(&values, disp.width, disp.height, false)
            .save_png(&out.join(format!("disparity_{side}.png")))?;
    }
    for (k, (view, depth)) in views
        .iter()
        .zip([&pair.depths.first, &pair.depths.second])
        .enumerate()
    {
        let (w, h) = (view.camera.width() as usize, view.camera.height() as usize);
        write_npy(
            &out.join(format!("depth_{}.npy", view.name)),
            &[h, w],
            &depth.depth,
        )?;
        colorize(&depth.depth, w, h, true)
            .save_png(&out.join(format!("depth_{}.png", view.name)))?;
        cloud
            .region_map(k, w, h)
            .save_png(&out.join(format!("regions_{}.png", view.name)))?;
    }
    write_points(&out.join("cloud.ply"), &cloud.points)?;
    write_points(&out.join("cloud_regions.ply"), &cloud.region_colored())?;
    let rect = &pair.rectification;
    let json = serde_json::json!({
        "views": [views[0].name, views[1].name],
        "swapped": pair.swapped,
        "focal_px": rect.intrinsics.fx,
        "baseline": rect.baseline,
        "params": pair.params,
        "valid_left": pair.left_disparity.valid_fraction(),
        "valid_right": pair.right_disparity.valid_fraction(),
        "candidates": cloud.counts.candidates,
        "accepted": cloud.counts.accepted,
        "match_seconds": match_seconds,
    });
    fewview_scene::atomic::write_bytes(
        &out.join("stereo.json"),
        &serde_json::to_vec_pretty(&json)?,
    )?;
    Ok(())
}
