//! Checkpoints: the trainer's whole state (parameters, Adam moments, poses, iteration) with the
//! configuration it belongs to, in one binary file written atomically. Since every random draw
//! is derived from `(seed, iteration)`, resuming repeats the uninterrupted run exactly.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Result, SurfaceError};
use crate::train::{TrainConfig, TrainState};

const MAGIC: &str = "fewview-surface-checkpoint-v1";

#[derive(Serialize, Deserialize)]
struct File {
    magic: String,
    /// The configuration as JSON (so a mismatch can be reported readably).
    config_json: String,
    state: TrainState,
}

/// Writes `state` and `config` to `path` (temp file + rename).
pub fn save(path: &Path, config: &TrainConfig, state: &TrainState) -> Result<()> {
    let file = File {
        magic: MAGIC.into(),
        config_json: serde_json::to_string(config)
            .map_err(|e| SurfaceError::invalid("checkpoint", e.to_string()))?,
        state: state.clone(),
    };
    let bytes = postcard::to_stdvec(&file)
        .map_err(|e| SurfaceError::invalid("checkpoint", e.to_string()))?;
    fewview_scene::atomic::write_bytes(path, &bytes).map_err(SurfaceError::Scene)
}

/// Reads a checkpoint; its configuration must equal `config` except for the iteration count
/// (a run may be extended).
pub fn load(path: &Path, config: &TrainConfig) -> Result<TrainState> {
    let bytes = std::fs::read(path).map_err(|e| SurfaceError::io(path, e))?;
    let file: File = postcard::from_bytes(&bytes)
        .map_err(|e| SurfaceError::format(path, format!("not a surface checkpoint ({e})")))?;
    if file.magic != MAGIC {
        return Err(SurfaceError::format(
            path,
            "not a surface checkpoint (bad header)",
        ));
    }
    let saved: TrainConfig = serde_json::from_str(&file.config_json)
        .map_err(|e| SurfaceError::format(path, format!("unreadable configuration ({e})")))?;
    let mut a = saved.clone();
    a.iterations = config.iterations;
    if &a != config {
        return Err(SurfaceError::format(
            path,
            "was written with a different configuration (only the iteration count may change)",
        ));
    }
    Ok(file.state)
}
