//! What the `human` subcommands share: the capture's flags, TPS's flags, runs and frame ranges.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args as ClapArgs;
use fewview_human::depth::{StereoChecks, StereoPartner, StereoSettings};
use fewview_human::tps::TpsConfig;
use fewview_human::{MultiView, Split};

use crate::commands::number_args::number_pair;

/// The capture, its sequence and the output folder, shared by the subcommands.
#[derive(Debug, ClapArgs)]
pub struct CaptureArgs {
    /// The capture's folder (synthetic or ZJU-MoCap).
    ///
    /// The capture's folder: the synthetic layout (`cameras.json`, `joints.json`, `SEQ/`) or
    /// ZJU-MoCap's (`annots.npy`, `Camera_B*/`, `mask/`, here or in `SEQ/`; 2D pose from
    /// `joints3d/<n>.npy`).
    #[arg(long, value_name = "DIR")]
    pub data: PathBuf,
    /// The sequence inside `--data`.
    ///
    /// Ignored when `--data` itself holds `annots.npy`.
    #[arg(long, value_name = "NAME", default_value = "seq_a")]
    pub sequence: String,
    /// Output folder.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

/// How stereo depth is matched (`--depth stereo`), shared by `train` and `depth`.
#[derive(Debug, ClapArgs)]
pub struct StereoArgs {
    /// The input camera each view's stereo depth is matched with.
    #[arg(long, value_name = "WHICH", value_enum, default_value_t)]
    pub stereo_partner: StereoPartner,
    /// Which of Semi-Global Matching's disparities are kept.
    #[arg(long, value_enum, default_value_t)]
    pub stereo_checks: StereoChecks,
    /// Stereo search around the hull (m).
    ///
    /// How far in front of and behind the visual hull's depth stereo searches, in metres
    /// (default: the hull bracket the network refines within).
    #[arg(long, value_name = "FRONT,BEHIND", value_parser = parse_metres_pair)]
    pub stereo_search: Option<(f64, f64)>,
}

impl StereoArgs {
    /// The library's stereo settings with these flags, checked.
    pub fn settings(&self) -> anyhow::Result<StereoSettings> {
        let defaults = StereoSettings::default();
        let (hull_front, hull_behind) = self
            .stereo_search
            .unwrap_or((defaults.hull_front, defaults.hull_behind));
        let settings = StereoSettings {
            partner: self.stereo_partner,
            checks: self.stereo_checks,
            hull_front,
            hull_behind,
            ..defaults
        };
        settings.check()?;
        Ok(settings)
    }
}

/// `FRONT,BEHIND`: two distances in metres (the library checks their range).
pub fn parse_metres_pair(text: &str) -> Result<(f64, f64), String> {
    number_pair(text, "0.3,0.6")
}

/// The Temporal Pose Stabilizer's settings (our design; see `fewview_human::tps`).
#[derive(Debug, ClapArgs)]
pub struct TpsArgs {
    /// Stabiliser weight of the previous frame.
    ///
    /// Weight of the previous frame's (warped) maps where the body is still, in [0, 1].
    #[arg(long, value_name = "W", default_value_t = TpsConfig::default().max_weight)]
    pub tps_weight: f32,
    /// Joint speed (m/frame) where the TPS weight is 1/e.
    ///
    /// Joint speed (metres per frame) at which that weight falls to 1/e of itself.
    #[arg(long, value_name = "M", default_value_t = TpsConfig::default().speed_scale)]
    pub tps_speed: f32,
}

impl TpsArgs {
    pub fn config(&self) -> anyhow::Result<TpsConfig> {
        let config = TpsConfig {
            max_weight: self.tps_weight,
            speed_scale: self.tps_speed,
            ..TpsConfig::default()
        };
        config.check()?;
        Ok(config)
    }
}

/// The run in `dir`, rendering from `source_views` views per target when given.
pub fn load_model(
    dir: &std::path::Path,
    source_views: Option<usize>,
) -> anyhow::Result<fewview_human::infer::Model> {
    let mut model = fewview_human::infer::Model::load(dir)?;
    if let Some(n) = source_views {
        if n == 0 {
            bail!("--source-views must be at least 1");
        }
        model.config.source_views = n;
    }
    Ok(model)
}

/// The split `run` was trained with, or PoseGaussian's default protocol for runs without
/// `split.json`.
pub fn run_split(run: &std::path::Path, capture: &dyn MultiView) -> anyhow::Result<Split> {
    let split = match Split::load(run)? {
        Some(split) => split,
        None => Split::for_capture(capture, fewview_human::split::PAPER_INPUT_CAMERAS, None)?,
    };
    split.check_fits(capture)?;
    Ok(split)
}

pub fn parse_frames(text: &str) -> anyhow::Result<std::ops::Range<usize>> {
    let (a, b) = text
        .split_once("..=")
        .with_context(|| format!("--frames {text}: expected A..=B"))?;
    let (a, b): (usize, usize) = (a.trim().parse()?, b.trim().parse()?);
    if b <= a {
        bail!("--frames {text}: needs at least two frames");
    }
    Ok(a..b + 1)
}
