//! `fewview eval`: score a trained model on a dataset's held-out views.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args as ClapArgs;
use fewview_splat::eval::evaluate;
use fewview_splat::ply::read_ply;
use fewview_splat::raster::RenderSettings;

use super::dataset_args::DatasetArgs;
use super::output_paths::check_optional_file;

/// Score a trained model on a dataset's held-out views.
///
/// Renders a trained model (Inria PLY) at a dataset's held-out views and reports PSNR and SSIM
/// (scikit-image SSIM: 11×11 Gaussian window, σ = 1.5, data range 1), masked too when the
/// dataset has masks.
#[derive(Debug, ClapArgs)]
pub struct Args {
    /// Trained Gaussians (Inria PLY layout).
    #[arg(long, value_name = "FILE")]
    pub ply: PathBuf,
    #[command(flatten)]
    pub dataset: DatasetArgs,
    /// Write the scores as JSON here.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    check_optional_file(args.json.as_deref(), "--json")?;
    let model = read_ply(&args.ply).context("cannot read the model")?;
    let ds = args.dataset.load()?;
    let settings = RenderSettings {
        background: ds.background,
        sh_degree: model.sh_degree(),
        ..RenderSettings::default()
    };
    let test: Vec<_> = ds.test_views().collect();
    let (report, _) = evaluate(&model, &test, &settings)?;
    println!("{:<16} {:>10} {:>8}", "view", "PSNR (dB)", "SSIM");
    for v in &report.views {
        println!("{:<16} {:>10.3} {:>8.4}", v.name, v.psnr, v.ssim);
    }
    println!(
        "{:<16} {:>10.3} {:>8.4}",
        "mean", report.mean_psnr, report.mean_ssim
    );
    if let (Some(p), Some(s)) = (report.mean_masked_psnr, report.mean_masked_ssim) {
        println!("{:<16} {:>10.3} {:>8.4}", "mean (masked)", p, s);
    }
    if let Some(path) = &args.json {
        let json = serde_json::to_vec_pretty(&report)?;
        fewview_scene::atomic::write_bytes(path, &json)?;
    }
    Ok(())
}
