//! The files of a run directory ([`RunDir`]), what a run trains on ([`RunData`]) and what it
//! writes: `config.json`, `cameras.json`, `appearance.json` and `metrics.json`.

use std::path::{Path, PathBuf};

use fewview_scene::Dataset;
use fewview_scene::memory::StagePeaks;
use serde::{Deserialize, Serialize};

use super::config::RunConfig;
use super::error::PipelineError;
use crate::eval::EvalReport;

/// Paths inside a run directory.
#[derive(Clone, Debug)]
pub struct RunDir(pub PathBuf);

impl RunDir {
    pub fn config(&self) -> PathBuf {
        self.0.join("config.json")
    }
    pub fn checkpoint(&self) -> PathBuf {
        self.0.join("checkpoint.bin")
    }
    /// The second field's checkpoint of a co-regularised run (CoR-GS).
    pub fn checkpoint_second(&self) -> PathBuf {
        self.0.join("checkpoint_second.bin")
    }
    pub fn ply(&self) -> PathBuf {
        self.0.join("point_cloud.ply")
    }
    /// Whether the run trained to its end: its model written and no checkpoint left.
    pub fn finished(&self) -> bool {
        self.ply().is_file() && !self.checkpoint().exists()
    }
    pub fn metrics(&self) -> PathBuf {
        self.0.join("metrics.json")
    }
    pub fn appearance(&self) -> PathBuf {
        self.0.join("appearance.json")
    }
    /// The cameras of the split, so that a viewer or `fewview render --cameras` can show the
    /// run from its own views without the dataset.
    pub fn cameras(&self) -> PathBuf {
        self.0.join("cameras.json")
    }
    pub fn renders(&self, split: &str) -> PathBuf {
        self.0.join("renders").join(split)
    }
    /// Where the stereo start writes its cloud, region render and summary.
    pub fn init(&self) -> PathBuf {
        self.0.join("init")
    }
}

/// What a run trains on: the dataset, its split and the image size. A checkpoint records it, so
/// that `--resume` refuses another dataset, other views or another downscale instead of
/// continuing one run's Gaussians on another's images.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunData {
    pub dataset: String,
    pub train_views: Vec<String>,
    pub test_views: Vec<String>,
    pub width: usize,
    pub height: usize,
}

impl RunData {
    /// The dataset, split and size of `ds` (its first training view's size).
    pub fn of(ds: &Dataset) -> Result<Self, PipelineError> {
        let first = ds
            .train_views()
            .next()
            .ok_or_else(|| PipelineError::Init("the split has no training views".into()))?;
        Ok(Self {
            dataset: ds.name.clone(),
            train_views: ds.train_views().map(|v| v.name.clone()).collect(),
            test_views: ds.test_views().map(|v| v.name.clone()).collect(),
            width: first.image.width,
            height: first.image.height,
        })
    }

    /// A one-line description of how `self` (the checkpoint's) differs from `now`, or `None`.
    pub fn difference(&self, now: &RunData) -> Option<String> {
        if self.dataset != now.dataset {
            Some(format!("dataset {} (now {})", self.dataset, now.dataset))
        } else if (self.width, self.height) != (now.width, now.height) {
            Some(format!(
                "images {}x{} (now {}x{}: another --downscale?)",
                self.width, self.height, now.width, now.height
            ))
        } else if self.train_views != now.train_views {
            Some(format!(
                "training views {} (now {})",
                self.train_views.join(","),
                now.train_views.join(",")
            ))
        } else if self.test_views != now.test_views {
            Some(format!(
                "test views {} (now {})",
                self.test_views.join(","),
                now.test_views.join(",")
            ))
        } else {
            None
        }
    }
}

/// The `config.json` of a run.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ResolvedConfig {
    #[serde(flatten)]
    pub data: RunData,
    pub extent: f64,
    pub run: RunConfig,
}

/// What a finished run reports (also written to `metrics.json`).
#[derive(Clone, Debug, Serialize)]
pub struct RunSummary {
    pub dataset: String,
    /// The initialisation used (`auto` resolved, a fallback taken).
    pub init: String,
    /// What the initialisation reports besides: stereo pairs skipped or swept and why, a
    /// fallback taken.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub init_notes: Vec<String>,
    /// The peak resident memory (MiB) of the initialisation and of training.
    pub memory: StagePeaks,
    pub iterations: usize,
    pub gaussians: usize,
    pub train_seconds: f64,
    pub resumed_from: Option<usize>,
    pub test: EvalReport,
}

/// `appearance.json`: each training photo's name and its colour transform `[A | b]` (3×4, row
/// by row).
pub(super) fn write_appearance(
    path: &Path,
    ds: &Dataset,
    transforms: &[crate::train::appearance::Affine],
) -> Result<(), PipelineError> {
    let rows: Vec<serde_json::Value> = ds
        .train_views()
        .zip(transforms)
        .map(|(v, m)| {
            let matrix: Vec<&[f32]> = m.chunks(4).collect();
            serde_json::json!({ "view": v.name, "transform": matrix })
        })
        .collect();
    let json = serde_json::to_vec_pretty(&rows).map_err(|e| PipelineError::Eval(e.to_string()))?;
    fewview_scene::atomic::write_bytes(path, &json)?;
    Ok(())
}
