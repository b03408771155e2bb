//! `fewview poses`: camera poses from a folder of photos, written as a COLMAP model.

use std::path::PathBuf;

use clap::Args as ClapArgs;
use fewview_match::learned::MatcherKind;
use fewview_match::retrieval::RetrievalOptions;
use std::sync::Mutex;

use fewview_sfm::{
    BundleOptions, EXIF_FOCAL_SD, FolderOptions, PoseModel, PoseOptions, PoseProgress, PoseStage,
    poses_for_folder,
};

use super::output_paths::check_folder;
use super::progress;

/// Estimate camera poses from a few photos, without COLMAP: SIFT matches between every pair
/// (with more than 20 photos, between each and the photos most like it; dense matches where
/// SIFT finds few), relative poses by the five-point algorithm, rotation
/// averaging, camera centres from the baselines, and a bundle adjustment of poses and points.
///
/// Writes `OUT/sparse/0/{cameras,images,points3D}.txt` (a COLMAP text model), `OUT/transforms.json`
/// (nerfstudio), `OUT/cameras.json` (for `fewview pose-error`), `OUT/poses_report.json`,
/// `OUT/cameras.png` (the cameras and points seen from above), and the
/// registered photos in `OUT/images/`, so that `fewview train --data OUT` trains on them. The model is fixed up to a similarity: the first
/// registered photo is at the origin, and the median depth of the points is 1. The focal length
/// starts from the EXIF 35 mm one, else `--fov` across the width, and is refined by the bundle
/// adjustment when all photos share one camera.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Folder of photos (`.jpg`, `.jpeg`, `.png`).
    #[arg(long, value_name = "DIR")]
    pub images: PathBuf,
    /// Output folder.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Field of view (°) without an EXIF focal length.
    ///
    /// Horizontal field of view (degrees) of photos without an EXIF focal length.
    #[arg(long, value_name = "DEG", default_value_t = FolderOptions::default().fov_deg)]
    pub fov: f64,
    /// Longest side (px) of the photos as matched.
    ///
    /// Photos are matched with their longer side scaled down to at most this many pixels.
    #[arg(long, value_name = "PX", default_value_t = FolderOptions::default().max_side)]
    pub max_side: usize,
    /// Fewest matches for two photos to count as overlapping.
    #[arg(long, value_name = "N", default_value_t = PoseOptions::default().min_matches)]
    pub min_matches: usize,
    /// Matcher: classical, xfeat, xfeat-star, lighterglue.
    ///
    /// Matcher of the sparse correspondences: `classical` (SIFT), `xfeat`, `xfeat-star` or
    /// `lighterglue` (weights from `scripts/setup.sh`; without them SIFT runs, and says so).
    #[arg(long, value_enum, default_value_t = PoseOptions::default().matcher)]
    pub matcher: MatcherKind,
    /// Also fit a shared radial distortion k1.
    ///
    /// Also fit one radial distortion coefficient shared by the photos (COLMAP's
    /// `SIMPLE_RADIAL`; only when all photos share one camera). The model then says
    /// `SIMPLE_RADIAL` in `cameras.txt` and `k1` in `transforms.json`, and `train` undistorts
    /// the photos on loading.
    #[arg(long)]
    pub radial: bool,
    /// Also fit a shared principal point.
    ///
    /// Also fit one principal point shared by the photos (only when all photos share one
    /// camera), for cameras whose principal point is not the image centre. Off by default, as
    /// in COLMAP: with few photos it trades off against their rotations.
    #[arg(long)]
    pub refine_principal_point: bool,
    /// Let the bundle move an EXIF focal length freely.
    ///
    /// By default a focal length read from EXIF is held near its value by a prior of 1 % (in
    /// log scale), as OpenSfM holds it: photos of a camera walking forward cannot tell zooming
    /// from moving, and a free focal drifts. Photos without EXIF refine their guess freely.
    #[arg(long)]
    pub free_focal: bool,
    /// Neighbours each photo is matched with (0: all).
    ///
    /// With more than 20 photos, each is matched only with the K photos most like it (VLAD
    /// global descriptors of their SIFT features) and along their maximum spanning tree; 0
    /// matches every pair.
    #[arg(long, value_name = "K", default_value_t = RetrievalOptions::default().neighbours)]
    pub neighbours: usize,
    /// Seed of RANSAC and of the retrieval's vocabulary.
    #[arg(long, default_value_t = PoseOptions::default().seed)]
    pub seed: u64,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if !(args.fov > 1.0 && args.fov < 179.0) {
        anyhow::bail!("--fov {}: expected degrees between 1 and 179", args.fov);
    }
    if args.max_side < 64 {
        anyhow::bail!("--max-side {}: expected at least 64 pixels", args.max_side);
    }
    check_folder(&args.out, "--out")?;
    let options = folder_options(&args);
    warn_other_files(&args.images)?;
    let model = with_progress(|on| poses_for_folder(&args.images, &args.out, &options, on))?;
    print_model(&model, args.fov);
    println!(
        "wrote {} (COLMAP text), transforms.json, cameras.json, cameras.png, poses_report.json and images/ in {}",
        args.out.join("sparse/0").display(),
        args.out.display()
    );
    Ok(())
}

/// The flags as the library's options.
fn folder_options(args: &Args) -> FolderOptions {
    FolderOptions {
        max_side: args.max_side,
        fov_deg: args.fov,
        poses: PoseOptions {
            min_matches: args.min_matches,
            matcher: args.matcher,
            seed: args.seed,
            exif_focal_sd: (!args.free_focal).then_some(EXIF_FOCAL_SD),
            bundle: BundleOptions {
                refine_radial: args.radial,
                refine_principal_point: args.refine_principal_point,
                ..BundleOptions::default()
            },
            retrieval: RetrievalOptions {
                neighbours: args.neighbours,
                ..RetrievalOptions::default()
            },
            ..PoseOptions::default()
        },
    }
}

/// What a person wants to know of a model: assumed focal lengths, photos left out, the fit.
/// A warning line for each file of `dir` that the poses step leaves out (not a photo).
pub fn warn_other_files(dir: &std::path::Path) -> anyhow::Result<()> {
    for file in fewview_sfm::photos::other_files(dir)? {
        eprintln!(
            "warning: {}: skipped, not a photo (.jpg, .jpeg or .png)",
            file.display()
        );
    }
    Ok(())
}

pub fn print_model(model: &PoseModel, fov_deg: f64) {
    let assumed = model
        .photos
        .iter()
        .filter(|p| p.focal_from == fewview_sfm::photos::FocalSource::AssumedFov)
        .count();
    if assumed > 0 {
        println!(
            "{assumed} of {} registered photos have no EXIF focal length: a {fov_deg}° field of view was assumed",
            model.photos.len()
        );
    }
    if let Some(why) = &model.report.matcher_fallback {
        println!("{why}");
    }
    for u in &model.unregistered {
        println!("not registered: {}: {}", u.name, u.reason);
    }
    let r = &model.report;
    if r.matched_pairs.chosen_by_retrieval {
        println!(
            "matched {} of the {} pairs of photos, chosen by retrieval (--neighbours)",
            r.matched_pairs.pairs,
            r.photos * (r.photos - 1) / 2
        );
    }
    println!(
        "registered {} of {} photos; {} points, median reprojection error {:.3} px",
        r.registered, r.photos, r.points, r.median_error_px
    );
    if let Some(k1) = r.bundle.radial_k1 {
        println!("radial distortion k1 {k1:.5} (SIMPLE_RADIAL)");
    }
    if let Some([dx, dy]) = r.bundle.principal_shift_px {
        println!(
            "principal point moved by ({dx:+.2}, {dy:+.2}) px of the matched images from their centre"
        );
    }
}

/// Runs `f` with a progress callback that shows a bar per stage of pose estimation.
pub fn with_progress<T>(f: impl FnOnce(&(dyn Fn(&PoseProgress) + Sync)) -> T) -> T {
    let current: Mutex<Option<(PoseStage, progress::Bar)>> = Mutex::new(None);
    let on = |p: &PoseProgress| {
        let mut current = current
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if current.as_ref().map(|(stage, _)| *stage) != Some(p.stage) {
            if let Some((_, bar)) = current.take() {
                bar.finish_and_clear();
            }
            *current = Some((
                p.stage,
                progress::iterations(p.total as u64, p.stage.name()),
            ));
        }
        if let Some((_, bar)) = current.as_ref() {
            bar.set_position(p.done as u64);
        }
    };
    let out = f(&on);
    if let Some((_, bar)) = current
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .take()
    {
        bar.finish_and_clear();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::commands::parse_for_tests::parse;

    /// Every flag's default is the library's: an empty command line gives `FolderOptions`'s
    /// defaults.
    #[test]
    fn an_empty_command_line_gives_the_librarys_defaults() {
        let args: Args = parse(&["poses", "--images", "i", "--out", "o"]);
        assert_eq!(folder_options(&args), FolderOptions::default());
    }
}
