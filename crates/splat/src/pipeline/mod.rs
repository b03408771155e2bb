//! One training run on a dataset, as `fewview train` and `fewview demo` do it: a run directory
//! holding the resolved configuration, checkpoints (resumable), the trained Gaussians as an
//! Inria PLY, held-out renders and `metrics.json`.
//!
//! ```text
//! <run>/config.json        resolved configuration and split
//! <run>/cameras.json       the training cameras, then the held-out ones, in config.json's
//!                          order (the camera-file form of `fewview_geom::io::cameras`)
//! <run>/checkpoint.bin     latest checkpoint (removed when the run completes)
//! <run>/point_cloud.ply    trained Gaussians (Inria layout)
//! <run>/metrics.json       held-out PSNR/SSIM per view and means, Gaussian count, timings
//! <run>/appearance.json    the training photos' colour transforms (with an appearance model)
//! <run>/renders/test/      held-out renders (PNG)
//! ```

mod checkpoint;
mod config;
mod error;
mod run;
mod run_dir;
mod start;

use crate::eval::render_model;
use crate::model::GaussianModel;
use crate::raster::{RenderCamera, RenderSettings};
use fewview_scene::{Camera, Image};

pub use checkpoint::{Checkpoint, load_checkpoint, save_checkpoint};
pub use config::{InitStrategy, MAX_INIT_POINTS, RunConfig};
pub use error::PipelineError;
pub use run::{train_run, train_run_with};
pub use run_dir::{ResolvedConfig, RunData, RunDir, RunSummary};
pub use start::{
    InitialModel, MAX_STEREO_START_VIEWS, adopt_init_poses, default_iterations, initial_model,
    initial_model_and_start, look_at_point, resolve_init,
};

pub fn render_path(
    model: &GaussianModel,
    keys: &[Camera],
    frames_per_segment: usize,
    settings: &RenderSettings,
) -> Vec<Image> {
    fewview_scene::camera_path(keys, frames_per_segment)
        .iter()
        .map(|c| render_model(model, &RenderCamera::from(c), settings).rgb)
        .collect()
}
