//! The comparison table of finished fusion runs (the variants side by side), read from their
//! `metrics.json`, `fusion.json`, `config.json` and `transition.json`. Held-out figures are given
//! raw and gain-matched ([`fewview_metrics::gain`]); a variant trained with a per-photo
//! appearance model is named `…+affine`.

use std::path::{Path, PathBuf};

use serde::Serialize;
use serde_json::Value;

use crate::error::FusionError;

/// One run's figures.
#[derive(Clone, Debug, Serialize)]
pub struct TableRow {
    pub run: PathBuf,
    pub dataset: String,
    pub variant: String,
    pub seed: u64,
    pub held_out_psnr: f64,
    pub held_out_ssim: f64,
    pub held_out_lpips: Option<f64>,
    pub gain_matched_psnr: f64,
    pub gain_matched_ssim: f64,
    pub gain_matched_lpips: Option<f64>,
    pub warping_error: f64,
    /// Mean `|Δ|` of the warp PSNR along the path.
    pub warp_psnr_delta: f64,
    /// Local popping ([`fewview_metrics::popping`]).
    pub popping: f64,
    /// Local popping where two training photos overlap (runs scored before it: none).
    pub popping_overlap: Option<f64>,
    pub path_psnr: Option<f64>,
    /// Path PSNR after one gain per channel for the whole clip.
    pub path_psnr_gain_matched: Option<f64>,
    pub path_psnr_delta: Option<f64>,
    pub path_lpips: Option<f64>,
    /// The ground truth's own local popping along the path.
    pub truth_popping: Option<f64>,
    /// The run's local popping in excess of the truth's (runs scored before it: none).
    pub popping_excess: Option<f64>,
    pub train_seconds: f64,
}

fn read_json(path: &Path) -> Result<Value, FusionError> {
    let bytes = std::fs::read(path).map_err(|e| {
        FusionError::Invalid(format!(
            "{}: {e} (is this a finished fusion run?)",
            path.display()
        ))
    })?;
    serde_json::from_slice(&bytes)
        .map_err(|e| FusionError::Invalid(format!("{}: {e}", path.display())))
}

/// A number at a JSON pointer, or an error naming the file and the field.
fn number(v: &Value, pointer: &str, file: &Path) -> Result<f64, FusionError> {
    v.pointer(pointer)
        .and_then(Value::as_f64)
        .ok_or_else(|| FusionError::Invalid(format!("{}: no number at {pointer}", file.display())))
}

/// A string at a JSON pointer, or an error naming the file and the field.
fn text(v: &Value, pointer: &str, file: &Path) -> Result<String, FusionError> {
    v.pointer(pointer)
        .and_then(Value::as_str)
        .map(str::to_string)
        .ok_or_else(|| FusionError::Invalid(format!("{}: no text at {pointer}", file.display())))
}

/// The row of the finished run in `dir`.
pub fn read_row(dir: &Path) -> Result<TableRow, FusionError> {
    let (m, f, t, c) = (
        dir.join("metrics.json"),
        dir.join("fusion.json"),
        dir.join("transition.json"),
        dir.join("config.json"),
    );
    let (metrics, fusion, transition, config) = (
        read_json(&m)?,
        read_json(&f)?,
        read_json(&t)?,
        read_json(&c)?,
    );
    let optional = |p: &str| transition.pointer(p).and_then(Value::as_f64);
    let mut variant = text(&fusion, "/config/variant", &f)?;
    let appearance = config
        .pointer("/run/train/appearance/model")
        .and_then(Value::as_str)
        .unwrap_or("none");
    if appearance != "none" {
        variant = if variant == "plain" {
            appearance.to_string()
        } else {
            format!("{variant}+{appearance}")
        };
    }
    Ok(TableRow {
        run: dir.to_path_buf(),
        dataset: text(&metrics, "/dataset", &m)?,
        variant,
        seed: number(&config, "/run/train/seed", &c)? as u64,
        held_out_psnr: number(&metrics, "/test/mean_psnr", &m)?,
        held_out_ssim: number(&metrics, "/test/mean_ssim", &m)?,
        held_out_lpips: optional("/held_out_lpips"),
        gain_matched_psnr: number(&metrics, "/test/mean_gain_matched_psnr", &m)?,
        gain_matched_ssim: number(&metrics, "/test/mean_gain_matched_ssim", &m)?,
        gain_matched_lpips: optional("/held_out_lpips_gain_matched"),
        warping_error: number(&transition, "/warping_error/mean", &t)?,
        warp_psnr_delta: number(&transition, "/warp_psnr/delta/mean", &t)?,
        popping: number(&transition, "/popping/p99", &t)?,
        popping_overlap: optional("/popping_overlap/p99"),
        path_psnr: optional("/truth/psnr/mean"),
        path_psnr_gain_matched: optional("/truth/psnr_gain_matched/mean"),
        path_psnr_delta: optional("/truth/psnr/delta/mean"),
        path_lpips: optional("/truth/lpips/mean"),
        truth_popping: optional("/truth/truth_popping/p99"),
        popping_excess: optional("/truth/popping_excess/p99"),
        train_seconds: number(&metrics, "/train_seconds", &m)?,
    })
}

/// A run's folder and its parent's name (`jitter/gf`), which tell runs of one dataset apart.
fn run_label(run: &Path) -> String {
    let name = |p: Option<&Path>| {
        p.and_then(Path::file_name)
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    match name(run.parent()) {
        parent if parent.is_empty() => name(Some(run)),
        parent => format!("{parent}/{}", name(Some(run))),
    }
}

/// The rows as a Markdown table (one dataset per table is the caller's choice). Popping is in
/// 8-bit levels (× 255), over the whole frame and where two training photos overlap; the path
/// PSNR raw and after one gain for the clip. The path's ΔPSNR stays in the JSON form: it ranks
/// variants by how sharp they are at the training views, not by how smooth they are between.
pub fn markdown(rows: &[TableRow]) -> String {
    let opt = |v: Option<f64>, digits: usize| {
        v.map(|x| format!("{x:.digits$}"))
            .unwrap_or_else(|| "–".into())
    };
    let mut out = String::from(
        "| run | dataset | variant | seed | held-out PSNR raw / gain-matched | SSIM raw / g.-m. \
         | LPIPS (ST-Alex) raw / g.-m. | local popping all / overlap (levels) \
         | path warping error ×10³ | path PSNR vs truth raw / g.-m. | path LPIPS \
         | truth's popping / excess over it | train s |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        out.push_str(&format!(
            "| {} | {} | {} | {} | {:.2} / {:.2} | {:.4} / {:.4} | {} / {} | {:.1} / {} | {:.4} | {} / {} | {} | {} / {} | {:.0} |\n",
            run_label(&r.run),
            r.dataset,
            r.variant,
            r.seed,
            r.held_out_psnr,
            r.gain_matched_psnr,
            r.held_out_ssim,
            r.gain_matched_ssim,
            opt(r.held_out_lpips, 4),
            opt(r.gain_matched_lpips, 4),
            r.popping * 255.0,
            opt(r.popping_overlap.map(|p| p * 255.0), 1),
            r.warping_error * 1e3,
            opt(r.path_psnr, 2),
            opt(r.path_psnr_gain_matched, 2),
            opt(r.path_lpips, 4),
            opt(r.truth_popping.map(|p| p * 255.0), 1),
            opt(r.popping_excess.map(|p| p * 255.0), 1),
            r.train_seconds,
        ));
    }
    out
}
