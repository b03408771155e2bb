//! `fewview human depth`.

use anyhow::{Context, bail};
use clap::Args as ClapArgs;
use fewview_human::Split;
use fewview_human::train::{Preset, TrainConfig};

use super::shared::{CaptureArgs, StereoArgs, parse_frames};

/// Compare the input depths of the input cameras over frames: writes `depth_report.json` (each
/// depth's flicker between frames, its flicker beyond the person's motion and its error against
/// the capture's depth) and `depth_strip.png` (one camera's frames: image, hull, stereo, truth).
#[derive(Debug, ClapArgs)]
pub struct DepthArgs {
    #[command(flatten)]
    pub capture: CaptureArgs,
    /// Frames `A..=B` (default: all).
    #[arg(long, value_name = "A..=B")]
    pub frames: Option<String>,
    /// The crops' size, as the network preset reads them.
    #[arg(long, value_enum, default_value_t = TrainConfig::default().preset)]
    pub preset: Preset,
    /// Input cameras, spread uniformly over the rig (as `train`).
    #[arg(long, default_value_t = fewview_human::split::PAPER_INPUT_CAMERAS)]
    pub input_cameras: usize,
    /// The camera of `depth_strip.png`.
    ///
    /// Default: the first input camera.
    #[arg(long)]
    pub camera: Option<usize>,
    #[command(flatten)]
    pub stereo: StereoArgs,
}

pub(super) fn depth(args: DepthArgs) -> anyhow::Result<()> {
    use fewview_human::depth_report::{DepthReportConfig, measure, strip};
    use fewview_human::train::prepare::InferenceInputs;
    let (_, capture) = fewview_human::capture::open(&args.capture.data, &args.capture.sequence)?;
    let split = Split::for_capture(&*capture, args.input_cameras, None)?;
    let frames = match &args.frames {
        Some(t) => parse_frames(t)?,
        None => split.all_frames(),
    };
    if frames.end > capture.frame_count() {
        bail!("--frames: the capture has {} frames", capture.frame_count());
    }
    let camera = args.camera.unwrap_or(split.input_cameras[0]);
    if !split.input_cameras.contains(&camera) {
        bail!(
            "--camera {camera} is not an input camera ({:?})",
            split.input_cameras
        );
    }
    let train = TrainConfig {
        preset: args.preset,
        ..TrainConfig::default()
    };
    let net = fewview_human::train::trainer::net_config(&train, &capture.joint_parents()?);
    let config = DepthReportConfig {
        frames: frames.clone(),
        size: [net.input[1], net.input[0]],
        crop_margin: train.crop_margin,
        hull_voxel: train.hull_voxel,
        stereo: args.stereo.settings()?,
    };
    let inputs = InferenceInputs {
        source: &*capture,
        split: &split,
        depth_maps: true,
    };
    eprintln!(
        "human depth: hull and stereo depth of {} input cameras over frames {}..={}…",
        split.input_cameras.len(),
        frames.start,
        frames.end - 1
    );
    let (report, prepared) = measure(&inputs, &config)?;
    let out = &args.capture.out;
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    let shown: Vec<usize> = frames.clone().take(4).collect();
    strip(&prepared, camera, &shown)?.save_png(&out.join("depth_strip.png"))?;
    let json = out.join("depth_report.json");
    std::fs::write(&json, serde_json::to_string_pretty(&report)?)
        .with_context(|| format!("{}: cannot write", json.display()))?;
    let mm = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{:.1} mm", 1e3 * v));
    for (name, s) in [("hull", &report.hull), ("stereo", &report.stereo)]
        .into_iter()
        .chain(report.truth.as_ref().map(|t| ("truth", t)))
    {
        println!(
            "{name:>6}: flicker {}, beyond the motion {}, error {}",
            mm(s.flicker_m),
            mm(s.flicker_beyond_truth_m),
            mm(s.error_m)
        );
    }
    println!(
        "stereo matched {:.0} % of the masked pixels; flicker stereo/hull {}; written to {}",
        100.0 * report.stereo_matched,
        report
            .flicker_ratio
            .map_or("–".to_string(), |r| format!("{r:.2}×")),
        out.display()
    );
    Ok(())
}
