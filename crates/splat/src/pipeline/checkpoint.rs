//! Checkpoints: the training configuration, the data and the state, sealed so that a truncated
//! or altered file is refused.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::error::PipelineError;
use super::run_dir::RunData;
use crate::train::{TrainConfig, TrainState};

/// Header of the current checkpoint format: the payload is postcard of
/// `(TrainConfig, RunData, TrainState)`, sealed with a CRC-32 ([`fewview_scene::sealed`]).
const CHECKPOINT_MAGIC: &[u8; 8] = b"FVCKPT04";
/// Earlier formats: `FVCKPT01` had neither the run's data nor a checksum, `FVCKPT02` no
/// appearance model, `FVCKPT03` no dropout rate.
const OLDER_CHECKPOINT_MAGICS: [&[u8]; 3] = [b"FVCKPT01", b"FVCKPT02", b"FVCKPT03"];

/// What a checkpoint holds: the training configuration, the data it trains on and the state.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint {
    pub config: TrainConfig,
    pub data: RunData,
    pub state: TrainState,
}

/// Saves a checkpoint, atomically.
pub fn save_checkpoint(
    path: &Path,
    config: &TrainConfig,
    data: &RunData,
    state: &TrainState,
) -> Result<(), PipelineError> {
    let body =
        postcard::to_allocvec(&(config, data, state)).map_err(|e| PipelineError::Checkpoint {
            path: path.to_path_buf(),
            message: format!("cannot encode: {e}"),
        })?;
    fewview_scene::sealed::write(path, CHECKPOINT_MAGIC, &body)?;
    Ok(())
}

/// Loads a checkpoint written by [`save_checkpoint`]; a truncated or altered file is an error.
pub fn load_checkpoint(path: &Path) -> Result<Checkpoint, PipelineError> {
    let body = fewview_scene::sealed::read(
        path,
        CHECKPOINT_MAGIC,
        &OLDER_CHECKPOINT_MAGICS,
        "a fewview checkpoint",
    )?;
    let bad = |m: String| PipelineError::Checkpoint {
        path: path.to_path_buf(),
        message: m,
    };
    let (config, data, state): (TrainConfig, RunData, TrainState) =
        postcard::from_bytes(&body).map_err(|e| bad(format!("corrupt checkpoint: {e}")))?;
    state
        .model
        .validate()
        .map_err(|m| bad(format!("corrupt checkpoint: {m}")))?;
    Ok(Checkpoint {
        config,
        data,
        state,
    })
}
