//! The comparison table of finished fusion runs (the variants side by side), read from their
//! `metrics.json`, `fusion.json` and `transition.json`.

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
    pub held_out_psnr: f64,
    pub held_out_ssim: f64,
    pub held_out_lpips: Option<f64>,
    pub warping_error: f64,
    /// Mean `|Δ|` of the warp PSNR along the path.
    pub warp_psnr_delta: f64,
    pub path_psnr: Option<f64>,
    pub path_psnr_delta: Option<f64>,
    pub path_lpips: Option<f64>,
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
    let (m, f, t) = (
        dir.join("metrics.json"),
        dir.join("fusion.json"),
        dir.join("transition.json"),
    );
    let (metrics, fusion, transition) = (read_json(&m)?, read_json(&f)?, read_json(&t)?);
    let optional = |p: &str| transition.pointer(p).and_then(Value::as_f64);
    Ok(TableRow {
        run: dir.to_path_buf(),
        dataset: text(&metrics, "/dataset", &m)?,
        variant: text(&fusion, "/config/variant", &f)?,
        held_out_psnr: number(&metrics, "/test/mean_psnr", &m)?,
        held_out_ssim: number(&metrics, "/test/mean_ssim", &m)?,
        held_out_lpips: optional("/held_out_lpips"),
        warping_error: number(&transition, "/warping_error/mean", &t)?,
        warp_psnr_delta: number(&transition, "/warp_psnr/delta/mean", &t)?,
        path_psnr: optional("/truth/psnr/mean"),
        path_psnr_delta: optional("/truth/psnr/delta/mean"),
        path_lpips: optional("/truth/lpips/mean"),
        train_seconds: number(&metrics, "/train_seconds", &m)?,
    })
}

/// The rows as a Markdown table (one dataset per table is the caller's choice).
pub fn markdown(rows: &[TableRow]) -> String {
    let opt = |v: Option<f64>, digits: usize| {
        v.map(|x| format!("{x:.digits$}"))
            .unwrap_or_else(|| "–".into())
    };
    let mut out = String::from(
        "| dataset | variant | held-out PSNR | SSIM | LPIPS (ST-Alex) | path warping error ×10³ \
         | warp ΔPSNR | path PSNR vs truth | path ΔPSNR | path LPIPS | train s |\n\
         |---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        out.push_str(&format!(
            "| {} | {} | {:.2} | {:.4} | {} | {:.4} | {:.3} | {} | {} | {} | {:.0} |\n",
            r.dataset,
            r.variant,
            r.held_out_psnr,
            r.held_out_ssim,
            opt(r.held_out_lpips, 4),
            r.warping_error * 1e3,
            r.warp_psnr_delta,
            opt(r.path_psnr, 2),
            opt(r.path_psnr_delta, 3),
            opt(r.path_lpips, 4),
            r.train_seconds,
        ));
    }
    out
}
