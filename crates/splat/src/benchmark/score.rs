//! One run's scores under a protocol: PSNR and SSIM from its `metrics.json` and ST-LPIPS of its
//! held-out renders, or, where the protocol scores inside object masks, all three from its
//! renders as the peers take them ([`super::masked`]); its size and time.

use std::path::Path;

use fewview_metrics::lpips::Lpips;
use fewview_scene::Dataset;
use serde::{Deserialize, Serialize};

use super::error::BenchmarkError;
use super::masked::held_out_masked_scores;
use super::protocol::Protocol;
use crate::model::GaussianModel;
use crate::pipeline::{ResolvedConfig, RunDir};
use crate::ply::read_ply;
use crate::raster::RenderSettings;

/// The scores of one seed's run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SeedScore {
    pub seed: u64,
    pub psnr: f64,
    pub ssim: f64,
    /// ST-LPIPS (AlexNet), when scored.
    pub lpips: Option<f64>,
    pub gaussians: usize,
    pub train_seconds: f64,
}

const SCORE_FILE: &str = "score.json";

impl SeedScore {
    /// The scores of the finished run in `dir` on `ds`'s held-out views.
    pub fn of_run(
        ds: &Dataset,
        dir: &Path,
        seed: u64,
        protocol: Protocol,
        lpips: Option<&Lpips>,
    ) -> Result<Self, BenchmarkError> {
        let run = RunDir(dir.to_path_buf());
        let bad = |message: String| BenchmarkError::Run {
            run: dir.to_path_buf(),
            message,
        };
        let metrics: serde_json::Value = read_json(&run.metrics()).map_err(bad)?;
        let number = |v: &serde_json::Value, what: &str| {
            v.as_f64()
                .ok_or_else(|| bad(format!("metrics.json has no {what}")))
        };
        let (psnr, ssim, lpips) = if protocol.masked() {
            let (model, settings) = load_run(&run).map_err(bad)?;
            let s = held_out_masked_scores(ds, &model, &settings, lpips).map_err(bad)?;
            (s.psnr, s.ssim, s.lpips)
        } else {
            let test = &metrics["test"];
            let lpips = match lpips {
                Some(net) => Some(held_out_lpips(ds, &run, net).map_err(bad)?),
                None => None,
            };
            (
                number(&test["mean_psnr"], "PSNR")?,
                number(&test["mean_ssim"], "SSIM")?,
                lpips,
            )
        };
        Ok(Self {
            seed,
            psnr,
            ssim,
            lpips,
            gaussians: number(&metrics["gaussians"], "Gaussian count")? as usize,
            train_seconds: number(&metrics["train_seconds"], "training time")?,
        })
    }

    /// The scores written in `dir` by an earlier run, if any.
    pub fn read(dir: &Path) -> Result<Option<Self>, BenchmarkError> {
        let path = dir.join(SCORE_FILE);
        if !path.is_file() {
            return Ok(None);
        }
        read_json(&path)
            .map(Some)
            .map_err(|message| BenchmarkError::Run {
                run: dir.to_path_buf(),
                message,
            })
    }

    /// Writes `score.json` in `dir`, atomically.
    pub fn write(&self, dir: &Path) -> Result<(), BenchmarkError> {
        let json = serde_json::to_vec_pretty(self).expect("scores serialise");
        fewview_scene::atomic::write_bytes(&dir.join(SCORE_FILE), &json)
            .map_err(|e| BenchmarkError::Pipeline(e.into()))
    }
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))
}

/// The run's Gaussians and the settings it renders with.
fn load_run(run: &RunDir) -> Result<(GaussianModel, RenderSettings), String> {
    let config: ResolvedConfig = read_json(&run.config())?;
    let model = read_ply(&run.ply()).map_err(|e| e.to_string())?;
    let settings = RenderSettings {
        background: config.run.train.background,
        sh_degree: config.run.train.sh_degree,
        near_plane: config.run.train.near_plane,
    };
    Ok((model, settings))
}

/// Mean ST-LPIPS of the run's Gaussians rendered at `ds`'s held-out views, whole images.
fn held_out_lpips(ds: &Dataset, run: &RunDir, net: &Lpips) -> Result<f64, String> {
    let (model, settings) = load_run(run)?;
    let (raw, _) = crate::eval::held_out_lpips(ds, &model, &settings, net)
        .map_err(|e| format!("LPIPS of the held-out views: {e}"))?;
    Ok(raw)
}
