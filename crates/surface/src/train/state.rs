//! What the trainer holds and reports: its views, its state (what a checkpoint stores) and
//! the statistics of a step.

use fewview_scene::{Image, Intrinsics, View};
use serde::{Deserialize, Serialize};

use fewview_optim::AdamState;

/// A training view as the trainer uses it.
#[derive(Clone, Debug)]
pub struct TrainView {
    pub image: Image,
    pub mask: Option<Image>,
    pub intrinsics: Intrinsics,
}

impl TrainView {
    /// A dataset view's image, mask and intrinsics (its pose is trained separately).
    pub fn of(view: &View) -> Self {
        Self {
            image: view.image.clone(),
            mask: view.mask.clone(),
            intrinsics: view.camera.intrinsics,
        }
    }
}

/// Everything that changes during training (what a checkpoint stores).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainState {
    /// Iterations done.
    pub iteration: usize,
    pub params: Vec<Vec<f32>>,
    pub adam: Vec<AdamState>,
    /// `[V × 9]` pose parameters (SPARF's translation + two rotation rows).
    pub poses: Vec<f32>,
    pub pose_adam: AdamState,
}

impl TrainState {
    /// The bit pattern of every parameter and pose value, for exact comparisons (`==` on
    /// floats takes -0.0 for 0.0).
    pub fn float_bits(&self) -> Vec<u32> {
        self.params
            .iter()
            .flatten()
            .chain(&self.poses)
            .map(|v| v.to_bits())
            .collect()
    }
}

/// Losses of one iteration.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StepStats {
    pub iteration: usize,
    pub total: f32,
    pub color: f32,
    pub psnr: f32,
    pub mask: f32,
    pub matching: f32,
    pub ncc: f32,
    pub geometric: f32,
    pub eikonal: f32,
    pub psdf: f32,
    pub inv_s: f32,
    /// The pose gradient was not finite, so this iteration left the poses alone (the field
    /// still stepped). The pipeline counts these in [`crate::pipeline::RunReport`].
    #[serde(default)]
    pub pose_step_skipped: bool,
}
