//! Checkpoints: the trainer's whole state (parameters, Adam moments, poses, iteration) with the
//! configuration and the run it belongs to, in one binary file written atomically and sealed
//! with a CRC-32 ([`fewview_scene::sealed`]). Since every random draw is derived from
//! `(seed, iteration)`, resuming repeats the uninterrupted run exactly — provided it is the same
//! run, which [`Saved::check_run`] makes sure of before anything is written.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Result, SurfaceError};
use crate::train::config::TrainConfig;
use crate::train::state::TrainState;

/// Header of the current format.
const MAGIC: &[u8] = b"fewview-surface-checkpoint-v3\0";
/// Version 2 recorded no cameras in its run identity.
const MAGIC_V2: &[u8] = b"fewview-surface-checkpoint-v2\0";
/// Version 1 (no run identity, no checksum) began with postcard's encoding of this string: its
/// length, 29, then the bytes.
const MAGIC_V1: &[u8] = b"\x1dfewview-surface-checkpoint-v1";

/// What a run trains on and how, beyond the training configuration: resuming a checkpoint under
/// another dataset, other views, another `--downscale` or another pose noise would continue one
/// run's field and poses on another's images and matches.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunIdentity {
    pub dataset: String,
    /// Names of the training views, in order.
    pub train_views: Vec<String>,
    /// `[width, height]` of each training view as trained on.
    pub image_sizes: Vec<[usize; 2]>,
    /// `[width, height]` of the views the matcher saw, when not the training images
    /// (`--match-downscale`).
    pub matching_sizes: Option<Vec<[usize; 2]>>,
    /// Each training view's camera as loaded ([`camera_record`]): the poses the run starts
    /// from (before any seeded noise) come from the camera file, which the settings name only
    /// by option (`--cameras-file`, `--initial-poses loaded`).
    pub cameras: Vec<CameraRecord>,
    /// The same for the ground-truth cameras the poses are scored against, when they come from
    /// another file than the starting ones.
    pub truth_cameras: Option<Vec<CameraRecord>>,
    /// The run configuration as JSON, with the settings a resume may change removed (see
    /// [`crate::pipeline::run_identity`]).
    pub settings_json: String,
}

impl RunIdentity {
    /// A one-line description of how `self` (the checkpoint's) differs from `now`, or `None`.
    pub fn difference(&self, now: &RunIdentity) -> Option<String> {
        if self.dataset != now.dataset {
            return Some(format!("dataset {} (now {})", self.dataset, now.dataset));
        }
        if self.train_views != now.train_views {
            return Some(format!(
                "training views {} (now {})",
                self.train_views.join(","),
                now.train_views.join(",")
            ));
        }
        if self.image_sizes != now.image_sizes || self.matching_sizes != now.matching_sizes {
            let size = |s: &[[usize; 2]]| s.first().map_or("-".into(), |[w, h]| format!("{w}x{h}"));
            return Some(format!(
                "image size {} (now {}: another --downscale or --match-downscale?)",
                size(&self.image_sizes),
                size(&now.image_sizes)
            ));
        }
        if let Some(view) = first_differing_camera(&self.cameras, &now.cameras, &now.train_views) {
            return Some(format!(
                "camera of training view {view} (another camera file?)"
            ));
        }
        match (&self.truth_cameras, &now.truth_cameras) {
            (None, None) => {}
            (Some(a), Some(b)) => {
                if let Some(view) = first_differing_camera(a, b, &now.train_views) {
                    return Some(format!(
                        "ground-truth camera of training view {view} (another camera file?)"
                    ));
                }
            }
            _ => return Some("ground-truth cameras (another --initial-poses?)".into()),
        }
        let parse = |s: &str| serde_json::from_str::<serde_json::Value>(s).ok();
        match (parse(&self.settings_json), parse(&now.settings_json)) {
            (Some(a), Some(b)) if a == b => None,
            (Some(a), Some(b)) => {
                let mut paths = Vec::new();
                differing_paths(&a, &b, String::new(), &mut paths);
                let shown: Vec<&str> = paths.iter().take(4).map(String::as_str).collect();
                Some(format!(
                    "settings {}{}",
                    shown.join(", "),
                    if paths.len() > shown.len() {
                        ", …"
                    } else {
                        ""
                    }
                ))
            }
            _ => Some("settings (unreadable)".into()),
        }
    }
}

/// Dotted paths at which two JSON values differ (a whole object where only one side has it).
fn differing_paths(
    a: &serde_json::Value,
    b: &serde_json::Value,
    at: String,
    out: &mut Vec<String>,
) {
    use serde_json::Value::Object;
    match (a, b) {
        (Object(x), Object(y)) => {
            let mut keys: Vec<&String> = x.keys().chain(y.keys()).collect();
            keys.sort();
            keys.dedup();
            for k in keys {
                let path = if at.is_empty() {
                    k.clone()
                } else {
                    format!("{at}.{k}")
                };
                match (x.get(k), y.get(k)) {
                    (Some(u), Some(v)) => differing_paths(u, v, path, out),
                    _ => out.push(path),
                }
            }
        }
        _ if a != b => out.push(if at.is_empty() { "(all)".into() } else { at }),
        _ => {}
    }
}

/// A camera as numbers: `fx, fy, cx, cy`, the world-to-camera rotation (row-major) and
/// translation.
pub type CameraRecord = [f64; 16];

/// The record of `camera` compared by [`RunIdentity::difference`].
pub fn camera_record(camera: &fewview_scene::Camera) -> CameraRecord {
    let k = &camera.intrinsics;
    let pose = &camera.world_to_camera;
    let mut record = [0.0; 16];
    for (slot, (_, value)) in record.iter_mut().zip(k.named_values()) {
        *slot = value;
    }
    for r in 0..3 {
        for c in 0..3 {
            record[4 + 3 * r + c] = pose.rotation[(r, c)];
        }
        record[13 + r] = pose.translation[r];
    }
    record
}

/// The name (from `names`) of the first view whose record differs between `a` and `b`; the
/// first name when their counts differ.
fn first_differing_camera<'a>(
    a: &[CameraRecord],
    b: &[CameraRecord],
    names: &'a [String],
) -> Option<&'a str> {
    let first = names.first().map_or("?", String::as_str);
    if a.len() != b.len() {
        return Some(first);
    }
    let i = a.iter().zip(b).position(|(x, y)| x != y)?;
    Some(names.get(i).map_or(first, String::as_str))
}

#[derive(Serialize, Deserialize)]
struct File {
    run: RunIdentity,
    /// The training configuration as JSON (so a mismatch can be reported readably).
    config_json: String,
    state: TrainState,
}

/// Writes `state`, its training `config` and the `run` it belongs to to `path` (temp file +
/// rename).
pub fn save(
    path: &Path,
    run: &RunIdentity,
    config: &TrainConfig,
    state: &TrainState,
) -> Result<()> {
    let file = File {
        run: run.clone(),
        config_json: serde_json::to_string(config)
            .map_err(|e| SurfaceError::invalid("checkpoint", e.to_string()))?,
        state: state.clone(),
    };
    let body = postcard::to_stdvec(&file)
        .map_err(|e| SurfaceError::invalid("checkpoint", e.to_string()))?;
    fewview_scene::sealed::write(path, MAGIC, &body).map_err(SurfaceError::Scene)
}

/// A checkpoint as read, before it is checked against the run that resumes it.
pub struct Saved {
    run: RunIdentity,
    config: TrainConfig,
    state: TrainState,
}

/// Reads a checkpoint; a truncated or altered file is an error naming it.
pub fn read(path: &Path) -> Result<Saved> {
    let body =
        fewview_scene::sealed::read(path, MAGIC, &[MAGIC_V2, MAGIC_V1], "a surface checkpoint")?;
    let file: File = postcard::from_bytes(&body)
        .map_err(|e| SurfaceError::format(path, format!("corrupt surface checkpoint ({e})")))?;
    let config: TrainConfig = serde_json::from_str(&file.config_json)
        .map_err(|e| SurfaceError::format(path, format!("unreadable configuration ({e})")))?;
    Ok(Saved {
        run: file.run,
        config,
        state: file.state,
    })
}

impl Saved {
    /// Refuses a checkpoint of another run (other data, views, sizes or settings) or one
    /// already past `iterations` (a run may be extended, not cut short).
    pub fn check_run(&self, path: &Path, now: &RunIdentity, iterations: usize) -> Result<()> {
        if let Some(d) = self.run.difference(now) {
            return Err(SurfaceError::format(
                path,
                format!(
                    "belongs to another run: {d}; only --iterations and the output settings may change on --resume"
                ),
            ));
        }
        if self.state.iteration > iterations {
            return Err(SurfaceError::format(
                path,
                format!(
                    "is at iteration {}, past --iterations {iterations}",
                    self.state.iteration
                ),
            ));
        }
        Ok(())
    }

    /// The state, once its training configuration equals `config` except for the iteration
    /// count.
    pub fn into_state(self, path: &Path, config: &TrainConfig) -> Result<TrainState> {
        let mut saved = self.config;
        saved.iterations = config.iterations;
        if &saved != config {
            return Err(SurfaceError::format(
                path,
                "was written with a different configuration (only the iteration count may change)",
            ));
        }
        Ok(self.state)
    }
}

/// Reads a checkpoint and returns its state for `config` ([`read`], then [`Saved::into_state`];
/// the run identity is not checked).
pub fn load(path: &Path, config: &TrainConfig) -> Result<TrainState> {
    read(path)?.into_state(path, config)
}
