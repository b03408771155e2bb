//! The surface paper's Table 1 protocol as a table of finished `surface` runs: for each scan, triplet
//! and seed the rotation and translation errors of the initial poses, after the warm-up and at
//! the end, the masked PSNR and the wall time, beside the paper's row for that scan and
//! triplet, with whether the run meets the targets (rotation ≤ 0.1°, translation ×100 ≤ 1.25 ×
//! the paper's).

use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::error::{Result, SurfaceError};

/// The surface paper Table 1, "Ours", translation ×100 per DTU scan: (scan, narrow, wide). The paper's
/// rotation error is 0.03° on every scan and triplet (the floor of its alignment's ε = 10⁻⁶).
pub const PAPER_TRANSLATION: [(u32, f64, f64); 15] = [
    (24, 0.19, 0.62),
    (37, 1.18, 1.65),
    (40, 0.21, 0.29),
    (55, 0.23, 0.24),
    (63, 0.26, 1.00),
    (65, 0.47, 0.48),
    (69, 0.34, 0.34),
    (83, 0.44, 0.81),
    (97, 0.09, 0.18),
    (105, 0.32, 0.28),
    (106, 0.29, 0.12),
    (110, 0.21, 0.28),
    (114, 0.35, 0.20),
    (118, 0.34, 0.36),
    (122, 0.32, 0.33),
];

/// The surface paper's rotation error on every scan (degrees).
pub const PAPER_ROTATION_DEG: f64 = 0.03;
/// The acceptance's rotation target (degrees) and its translation target relative to the paper.
pub const TARGET_ROTATION_DEG: f64 = 0.1;
pub const TARGET_TRANSLATION_FACTOR: f64 = 1.25;

/// The two triplets of the surface paper's DTU protocol.
pub const NARROW: [usize; 3] = [22, 23, 24];
pub const WIDE: [usize; 3] = [22, 25, 28];

/// One run's figures; rotations in degrees, translations ×100.
#[derive(Clone, Debug, PartialEq)]
pub struct Table1Row {
    pub run: PathBuf,
    pub dataset: String,
    /// `narrow`, `wide`, or the training views' numbers.
    pub triplet: String,
    pub seed: u64,
    pub size: [usize; 2],
    pub initial: (f64, f64),
    pub warmup: Option<(f64, f64)>,
    pub last: (f64, f64),
    pub masked_psnr: Option<f64>,
    pub seconds: f64,
    /// The paper's translation ×100 for this scan and triplet, when it has one.
    pub paper_translation: Option<f64>,
}

impl Table1Row {
    /// Whether the final poses meet the targets (`None` without a paper row to compare with).
    pub fn meets_targets(&self) -> Option<bool> {
        let paper = self.paper_translation?;
        Some(self.last.0 <= TARGET_ROTATION_DEG && self.last.1 <= TARGET_TRANSLATION_FACTOR * paper)
    }
}

fn invalid(file: &Path, message: impl Into<String>) -> SurfaceError {
    SurfaceError::invalid(file.display().to_string(), message)
}

/// A pose error's (rotation °, translation ×100) at `key`, or an error naming file and field.
fn pose_error(metrics: &Value, key: &str, file: &Path) -> Result<(f64, f64)> {
    let r = metrics.pointer(&format!("/{key}/rotation_deg"));
    let t = metrics.pointer(&format!("/{key}/translation"));
    match (r.and_then(Value::as_f64), t.and_then(Value::as_f64)) {
        (Some(r), Some(t)) => Ok((r, 100.0 * t)),
        _ => Err(invalid(file, format!("no pose error at {key}"))),
    }
}

/// The paper's translation ×100 for a dataset named `scan<N>` and a triplet.
fn paper_row(dataset: &str, triplet: &str) -> Option<f64> {
    let scan: u32 = dataset.strip_prefix("scan")?.parse().ok()?;
    let &(_, narrow, wide) = PAPER_TRANSLATION.iter().find(|r| r.0 == scan)?;
    match triplet {
        "narrow" => Some(narrow),
        "wide" => Some(wide),
        _ => None,
    }
}

/// The row of the finished run in `dir` (its `metrics.json`).
pub fn read_row(dir: &Path) -> Result<Table1Row> {
    let file = dir.join("metrics.json");
    let bytes = std::fs::read(&file)
        .map_err(|e| invalid(&file, format!("{e} (is this a finished surface run?)")))?;
    let m: Value = serde_json::from_slice(&bytes).map_err(|e| invalid(&file, e.to_string()))?;
    let dataset = m["dataset"]
        .as_str()
        .filter(|s| !s.is_empty())
        .ok_or_else(|| invalid(&file, "no dataset name (a run from before tables existed?)"))?
        .to_string();
    let views: Vec<usize> = m["train_views"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(Value::as_u64)
                .map(|v| v as usize)
                .collect()
        })
        .ok_or_else(|| invalid(&file, "no train_views"))?;
    let triplet = match views.as_slice() {
        v if v == NARROW => "narrow".to_string(),
        v if v == WIDE => "wide".to_string(),
        v => v.iter().map(usize::to_string).collect::<Vec<_>>().join(","),
    };
    let size = match m["image_size"].as_array().map(std::vec::Vec::as_slice) {
        Some([w, h]) => match (w.as_u64(), h.as_u64()) {
            (Some(w), Some(h)) => [w as usize, h as usize],
            _ => return Err(invalid(&file, "image_size is not two whole numbers")),
        },
        _ => return Err(invalid(&file, "no image_size")),
    };
    let seed = m["seed"]
        .as_u64()
        .ok_or_else(|| invalid(&file, "no seed"))?;
    Ok(Table1Row {
        run: dir.to_path_buf(),
        paper_translation: paper_row(&dataset, &triplet),
        dataset,
        triplet,
        seed,
        size,
        initial: pose_error(&m, "initial_pose_error", &file)?,
        warmup: pose_error(&m, "warmup_pose_error", &file).ok(),
        last: pose_error(&m, "final_pose_error", &file)?,
        masked_psnr: m["mean_psnr_masked"].as_f64(),
        seconds: m["run_seconds_wall"]
            .as_f64()
            .or_else(|| m["train_seconds_wall"].as_f64())
            .unwrap_or(f64::NAN),
    })
}

/// The rows as a Markdown table, each with the paper's row and whether it meets the targets.
pub fn markdown(rows: &[Table1Row]) -> String {
    let mut out = String::from(
        "| scan | triplet | size | seed | initial R° / t×100 | warm-up R° / t×100 | final R° / t×100 \
         | masked PSNR | wall min | paper R° / t×100 | target met |\n\
         |---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let pair = |(r, t): (f64, f64)| format!("{r:.3} / {t:.2}");
    for row in rows {
        out.push_str(&format!(
            "| {} | {} | {}×{} | {} | {} | {} | {} | {} | {:.1} | {} | {} |\n",
            row.dataset,
            row.triplet,
            row.size[0],
            row.size[1],
            row.seed,
            pair(row.initial),
            row.warmup.map_or("–".into(), pair),
            pair(row.last),
            row.masked_psnr.map_or("–".into(), |p| format!("{p:.2}")),
            row.seconds / 60.0,
            row.paper_translation
                .map_or("–".into(), |t| format!("{PAPER_ROTATION_DEG} / {t:.2}")),
            match row.meets_targets() {
                Some(true) => "yes",
                Some(false) => "no",
                None => "–",
            }
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_run(dir: &Path, views: &[usize], r: f64, t: f64) {
        let metrics = serde_json::json!({
            "dataset": "scan37",
            "train_views": views,
            "image_size": [400, 300],
            "seed": 2,
            "run_seconds_wall": 1500.0,
            "initial_pose_error": {"rotation_deg": 12.4, "translation": 0.43},
            "warmup_pose_error": {"rotation_deg": 0.19, "translation": 0.0057},
            "final_pose_error": {"rotation_deg": r, "translation": t},
            "mean_psnr_masked": 15.5,
        });
        std::fs::create_dir_all(dir).unwrap();
        std::fs::write(dir.join("metrics.json"), metrics.to_string()).unwrap();
    }

    #[test]
    fn rows_carry_the_paper_row_and_the_verdict() {
        let tmp = tempfile::tempdir().unwrap();
        let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
        write_run(&a, &WIDE, 0.09, 0.02);
        write_run(&b, &NARROW, 0.2, 0.01);
        let (ra, rb) = (read_row(&a).unwrap(), read_row(&b).unwrap());
        assert_eq!(
            (ra.triplet.as_str(), ra.paper_translation),
            ("wide", Some(1.65))
        );
        assert_eq!(ra.last, (0.09, 2.0));
        // 2.0 ≤ 1.25 × 1.65 and 0.09° ≤ 0.1°.
        assert_eq!(ra.meets_targets(), Some(true));
        assert_eq!(
            (rb.paper_translation, rb.meets_targets()),
            (Some(1.18), Some(false))
        );
        let table = markdown(&[ra, rb]);
        assert!(table.contains("| scan37 | wide | 400×300 | 2 | 12.400 / 43.00 | 0.190 / 0.57 | 0.090 / 2.00 | 15.50 | 25.0 | 0.03 / 1.65 | yes |"), "{table}");
    }

    #[test]
    fn a_folder_that_is_not_a_run_is_named_in_the_error() {
        let tmp = tempfile::tempdir().unwrap();
        let err = read_row(tmp.path()).unwrap_err().to_string();
        assert!(
            err.contains("metrics.json") && err.contains("finished surface run"),
            "{err}"
        );
        let partial = serde_json::json!({
            "dataset": "scan37", "train_views": [22, 25, 28], "image_size": [400, 300], "seed": 0
        });
        std::fs::write(tmp.path().join("metrics.json"), partial.to_string()).unwrap();
        let err = read_row(tmp.path()).unwrap_err().to_string();
        assert!(err.contains("initial_pose_error"), "{err}");
    }
}
