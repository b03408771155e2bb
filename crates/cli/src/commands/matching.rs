//! `fewview match`: a matcher's correspondences between a dataset's training views, scored
//! against the dataset's cameras.

use std::path::PathBuf;

use clap::Args as ClapArgs;
use fewview_surface::matching::learned::MatcherKind;
use fewview_surface::matching::report::match_report;

use super::dataset_args::DatasetArgs;
use super::output_paths::check_folder;

/// Match every pair of a dataset's training views and score the matches against its cameras:
/// per pair, the count and the fractions within 1, 2 and 5 px of the true epipolar lines, as the
/// matcher gives them and after the surface method's Lucas–Kanade refinement.
#[derive(Debug, ClapArgs)]
pub struct Args {
    #[command(flatten)]
    pub dataset: DatasetArgs,
    /// Matcher: classical, xfeat, xfeat-star, lighterglue.
    ///
    /// `classical` (SIFT), `xfeat`, `xfeat-star` or `lighterglue` (weights from
    /// `scripts/setup.sh`; without them the classical matcher runs, and the report says so).
    #[arg(long, value_enum, default_value_t = MatcherKind::Classical)]
    pub matcher: MatcherKind,
    /// Match whole images, ignoring the dataset's foreground masks.
    #[arg(long)]
    pub no_masks: bool,
    /// Write the report (per pair, both stages) as JSON here.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(parent) = args.json.as_ref().and_then(|p| p.parent()) {
        check_folder(parent, "--json")?;
    }
    let dataset = args.dataset.load()?;
    let report = match_report(&dataset, args.matcher, !args.no_masks)?;
    if let Some(why) = &report.fallback {
        eprintln!("{why}");
    }
    println!(
        "{} by {} ({:.2} s of matching)",
        report.dataset, report.matcher, report.matching_seconds
    );
    println!(
        "{:<10} {:>8} {:>8} {:>8} {:>9}   {:>8} {:>8} {:>9}",
        "pair", "matches", "<1 px", "<2 px", "median", "refined", "<1 px", "median"
    );
    for p in &report.pairs {
        println!(
            "{:<10} {:>8} {:>7.1}% {:>7.1}% {:>7.3}px   {:>8} {:>7.1}% {:>7.3}px",
            format!("{}-{}", p.views[0], p.views[1]),
            p.raw.matches,
            100.0 * p.raw.precision_1px,
            100.0 * p.raw.precision_2px,
            p.raw.median_px,
            p.refined.matches,
            100.0 * p.refined.precision_1px,
            p.refined.median_px
        );
    }
    if let Some(path) = &args.json {
        fewview_scene::atomic::write_bytes(path, &serde_json::to_vec_pretty(&report)?)?;
        println!("JSON report: {}", path.display());
    }
    Ok(())
}
