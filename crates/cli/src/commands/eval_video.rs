//! `fewview eval-video`: temporal-coherence metrics of a rendered sequence against ground truth
//! (per-frame PSNR/SSIM/LPIPS, their frame-to-frame Δ as in the PoseGaussian paper's tables, TecoGAN's tLP,
//! and the warping error with a caller-supplied flow). Inputs are videos (`.mp4`, `.gif`) or
//! folders of PNG/JPEG frames, read by `fewview_video`.

use std::path::PathBuf;

use anyhow::{Context, bail};
use fewview_metrics::lpips::{LoadOptions, Lpips, LpipsNet};
use fewview_metrics::temporal::{self, Flow, MetricSeries, PerceptualDistance};
use fewview_metrics::{SsimBorder, SsimOptions};
use fewview_video as video;

use super::output_paths::check_optional_file;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Rendered sequence (.mp4, .gif or frames).
    ///
    /// Rendered sequence: an .mp4 or .gif file, or a folder of PNG/JPEG frames (natural order).
    #[arg(long)]
    output: PathBuf,
    /// Ground-truth sequence.
    ///
    /// The same forms, frame count and size.
    #[arg(long)]
    ground_truth: PathBuf,
    /// LPIPS network (default: st-alex, built in).
    ///
    /// LPIPS network: st-alex (default: ST-LPIPS AlexNet, weights built in), alex, vgg,
    /// squeeze (lpips v0.1; need --lpips-weights), st-vgg, or none.
    #[arg(long, default_value = "st-alex")]
    lpips: String,
    /// Weight files of the LPIPS network.
    ///
    /// PyTorch weight files for the LPIPS network (e.g. the torchvision backbone and the
    /// lpips v0.1 linear heads, or a full ST-LPIPS file).
    #[arg(long, value_name = "FILE", num_args = 1..)]
    lpips_weights: Vec<PathBuf>,
    /// Backward flows for the warping error.
    ///
    /// Folder of Middlebury .flo backward flows, one per transition (T − 1 files, file-name
    /// order): enables the warping error.
    #[arg(long)]
    flow_dir: Option<PathBuf>,
    /// SSIM border: reflect or zero.
    ///
    /// SSIM border convention: reflect (scikit-image, default) or zero (3DGS loss).
    #[arg(long, default_value = "reflect")]
    ssim_border: String,
    /// Background of transparent pixels.
    ///
    /// Background for transparent GIF/PNG pixels (white or black).
    #[arg(long, default_value = "white")]
    background: String,
    /// Also write the full report as JSON.
    ///
    /// Write the full report (per-frame values included) as JSON here; JSON has no infinity,
    /// so the PSNR of an exact frame (+∞) is written as null.
    #[arg(long)]
    json: Option<PathBuf>,
}

fn load_flows(dir: &std::path::Path) -> anyhow::Result<Vec<Flow>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("{}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("flo")))
        .collect();
    files.sort();
    if files.is_empty() {
        bail!("{}: no .flo files", dir.display());
    }
    files.iter().map(|f| Ok(temporal::read_flo(f)?)).collect()
}

fn row(s: &MetricSeries) -> String {
    format!(
        "| {} | {:.4} | {:.4} | {:.4} |",
        s.name, s.mean, s.delta.mean, s.delta.std
    )
}

pub fn run(args: Args) -> anyhow::Result<()> {
    check_optional_file(args.json.as_deref(), "--json")?;
    let background = match args.background.as_str() {
        "white" => [1.0; 3],
        "black" => [0.0; 3],
        other => bail!("--background must be white or black, not {other:?}"),
    };
    let border = match args.ssim_border.as_str() {
        "reflect" => SsimBorder::ReflectCrop,
        "zero" => SsimBorder::ZeroSame,
        other => bail!("--ssim-border must be reflect or zero, not {other:?}"),
    };
    let read = |path: &std::path::Path| -> anyhow::Result<Vec<fewview_scene::Image>> {
        let (frames, _fps) = video::read_video_with(path, &video::ReadOptions { background })?;
        Ok(frames)
    };
    let output = read(&args.output)?;
    let truth = read(&args.ground_truth)?;
    let lpips: Option<Lpips> = match args.lpips.as_str() {
        "none" => None,
        "st-alex" if args.lpips_weights.is_empty() => Some(Lpips::default_st_alex()?),
        name => {
            let net = LpipsNet::parse(name)?;
            if args.lpips_weights.is_empty() {
                bail!("--lpips {name} needs --lpips-weights (only st-alex is built in)");
            }
            Some(Lpips::load(
                net,
                &args.lpips_weights,
                LoadOptions::default(),
            )?)
        }
    };
    let flows = args.flow_dir.as_deref().map(load_flows).transpose()?;
    let report = temporal::evaluate_sequence(
        &output,
        &truth,
        &SsimOptions {
            border,
            ..SsimOptions::default()
        },
        lpips.as_ref().map(|l| l as &dyn PerceptualDistance),
        flows.as_deref(),
    )
    .with_context(|| {
        format!(
            "{} against {}",
            args.output.display(),
            args.ground_truth.display()
        )
    })?;
    println!(
        "{} frames; Δ = |m_t − m_(t−1)| over consecutive frames (mean, std)",
        report.frames
    );
    if let Some(l) = &lpips {
        println!("LPIPS variant: {} ({})", l.net().name(), l.source());
    }
    println!("| metric | mean | Δ mean | Δ std |\n|---|---:|---:|---:|");
    for s in [
        Some(&report.psnr),
        Some(&report.ssim),
        report.lpips.as_ref(),
        report.tlp.as_ref(),
        report.warping_error.as_ref(),
    ]
    .into_iter()
    .flatten()
    {
        println!("{}", row(s));
    }
    if let Some(path) = args.json {
        let text = serde_json::to_string_pretty(&report)?;
        fewview_scene::atomic::write_bytes(&path, text.as_bytes())?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
