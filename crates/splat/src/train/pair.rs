//! Two fields trained side by side and regularised by their disagreement, as "CoR-GS: Sparse-View
//! 3D Gaussian Splatting via Co-Regularization" (Zhang et al., ECCV 2024) does: co-pruning
//! ([`super::co_prune`], §4.1) and pseudo-view co-regularisation (§4.2, Eq. 9–10: each field's
//! render of a view between the training cameras is pulled to the other's by
//! `λ_p ((1 − λ) L1 + λ D-SSIM)`).
//!
//! The two fields start from the same Gaussians and differ by their random draws (view order,
//! densification, dropout): the second trains with another seed. The first is the run's result.
//! The pseudo views are [`super::pseudo::pseudo_camera`]'s, between a training camera and its
//! nearest neighbour.

use std::sync::{Arc, Mutex};

use burn::tensor::{Tensor, TensorData};
use fewview_scene::Camera;
use serde::{Deserialize, Serialize};

use super::co_prune::{co_prune, depth_scale};
use super::config::TrainConfig;
use super::pseudo::pseudo_camera;
use super::state::{Progress, TrainError, TrainState};
use super::term::{LossContext, LossTerm};
use super::trainer::Trainer;
use crate::eval::render_model;
use crate::loss::photometric_loss;
use crate::model::GaussianModel;
use crate::raster::RenderCamera;

/// CoR-GS's settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CoRegConfig {
    /// τ of co-pruning as a fraction of the scene's depth scale ([`depth_scale`] of the first
    /// field when it prunes).
    pub tau: f32,
    /// Co-pruning every this many densification steps (the paper's 5).
    pub every: usize,
    /// λ_p of the pseudo-view term (the paper's 1.0); 0: co-pruning only.
    pub pseudo_weight: f32,
}

impl Default for CoRegConfig {
    fn default() -> Self {
        Self {
            tau: 0.1,
            every: 5,
            pseudo_weight: 1.0,
        }
    }
}

/// The seed of the second field: the first's, with its bits mixed, so that the pair of seed 0
/// does not share a field with the pair of seed 1.
pub fn second_seed(seed: u64) -> u64 {
    seed ^ 0xC0_4E55_0C0F_1E1D
}

/// The latest parameters of one field, shared with the other's pseudo-view term.
type Snapshot = Arc<Mutex<GaussianModel>>;

/// Two trainers stepped in lockstep with CoR-GS's regularisation between them.
pub struct TrainerPair {
    pub first: Trainer,
    pub second: Trainer,
    config: CoRegConfig,
    snapshots: [Snapshot; 2],
    /// The training cameras' centres, for the scale τ is a fraction of.
    centres: Vec<[f64; 3]>,
}

impl TrainerPair {
    /// The pair from two trainers on the same views (`cameras` are the training views' cameras,
    /// for the pseudo views); adds each one's pseudo-view term when `config` weighs it.
    pub fn new(
        mut first: Trainer,
        mut second: Trainer,
        cameras: Vec<Camera>,
        config: CoRegConfig,
    ) -> Result<Self, TrainError> {
        let centres = cameras.iter().map(|c| c.center().into()).collect();
        let snapshots = [
            Arc::new(Mutex::new(first.state()?.model.clone())),
            Arc::new(Mutex::new(second.state()?.model.clone())),
        ];
        if config.pseudo_weight > 0.0 {
            let seed = first.config.seed;
            for (trainer, other) in [(&mut first, &snapshots[1]), (&mut second, &snapshots[0])] {
                trainer.add_term(Box::new(PseudoViewTerm {
                    cameras: cameras.clone(),
                    other: other.clone(),
                    weight: config.pseudo_weight,
                    lambda_dssim: trainer.config.lambda_dssim,
                    seed,
                }));
            }
        }
        Ok(Self {
            first,
            second,
            config,
            snapshots,
            centres,
        })
    }

    /// One iteration of both fields, then co-pruning when it is due.
    pub fn step(&mut self) -> Result<Progress, TrainError> {
        let progress = self.first.step()?;
        self.second.step()?;
        let d = &self.first.config.densify;
        let it = progress.iteration;
        let due = it > d.from_iter
            && it < d.until_iter
            && it.is_multiple_of(d.interval * self.config.every.max(1));
        if due {
            let (a, b) = (self.first.state_mut()?, self.second.state_mut()?);
            let tau = self.config.tau * depth_scale(&a.model.means, &self.centres);
            co_prune(a, b, tau);
        }
        if self.config.pseudo_weight > 0.0 {
            *self.snapshots[0].lock().expect("not poisoned") = self.first.state()?.model.clone();
            *self.snapshots[1].lock().expect("not poisoned") = self.second.state()?.model.clone();
        }
        Ok(progress)
    }

    /// Trains both to the end, reporting the first's progress and saving both states through
    /// `checkpoint` every `checkpoint_interval` iterations.
    pub fn run(
        &mut self,
        mut on_progress: impl FnMut(&Progress),
        mut checkpoint: impl FnMut(&TrainState, &TrainState, &TrainConfig) -> Result<(), String>,
    ) -> Result<(), TrainError> {
        while !self.first.is_done() {
            let p = self.step()?;
            on_progress(&p);
            let every = self.first.config.checkpoint_interval;
            if every > 0 && p.iteration % every == 0 && !self.first.is_done() {
                let config = self.first.config.clone();
                let second = self.second.state()?.clone();
                checkpoint(self.first.state()?, &second, &config).map_err(TrainError::Invalid)?;
            }
        }
        Ok(())
    }
}

/// Eq. 9 for one field: its render of the iteration's pseudo view against the other field's,
/// both with the iteration's render settings. On views with alpha each iteration trains over a
/// random background ([`TrainConfig::random_background`]); the other field's render takes the
/// same one, so that the two disagree where their opacities do, not where their backgrounds do.
struct PseudoViewTerm {
    cameras: Vec<Camera>,
    other: Snapshot,
    weight: f32,
    lambda_dssim: f32,
    seed: u64,
}

impl PseudoViewTerm {
    /// The pseudo view of `iteration`, the same for both fields ([`pseudo_camera`]).
    fn camera(&self, iteration: usize) -> Option<Camera> {
        pseudo_camera(&self.cameras, self.seed, iteration)
    }
}

impl LossTerm for PseudoViewTerm {
    fn name(&self) -> &str {
        "pseudo-view"
    }

    fn loss(&mut self, ctx: &LossContext<'_>) -> Result<Option<Tensor<1>>, TrainError> {
        let Some(camera) = self.camera(ctx.iteration) else {
            return Ok(None);
        };
        let camera = RenderCamera::from(&camera);
        let target = {
            let other = self.other.lock().expect("not poisoned");
            render_model(&other, &camera, ctx.settings).rgb
        };
        let own = ctx.render(&camera).image;
        let [h, w, _] = own.dims();
        let own = own.slice([0..h, 0..w, 0..3]);
        let device = own.device();
        let target = Tensor::<3>::from_data(TensorData::new(target.data, [h, w, 3]), &device);
        Ok(Some(
            photometric_loss(own, target, self.lambda_dssim) * self.weight,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::RenderSettings;
    use crate::train::pseudo::tests::camera_on_x_axis;
    use crate::train::term::HostModel;

    /// With two equal fields the pseudo-view term is zero whatever the iteration's background:
    /// the other field's render takes the iteration's (here not the configured black), so a
    /// random background shows where the fields' opacities differ and nowhere else.
    #[test]
    fn equal_fields_agree_over_the_iterations_background() {
        let mut model = GaussianModel::new(0);
        model.push_isotropic([0.5, 0.0, 3.0], 0.3, [0.8, 0.3, 0.2], 0.6);
        let cameras = vec![camera_on_x_axis(0.0, 50.0), camera_on_x_axis(1.0, 50.0)];
        let mut term = PseudoViewTerm {
            cameras,
            other: Arc::new(Mutex::new(model.clone())),
            weight: 1.0,
            lambda_dssim: 0.2,
            seed: 0,
        };
        let gaussians = model.to_tensors(&Default::default(), false);
        let settings = RenderSettings {
            background: [0.3, 0.6, 0.9],
            sh_degree: 0,
            near_plane: 0.2,
        };
        let ctx = LossContext {
            iteration: 1,
            view_index: 0,
            views: &[],
            gaussians: &gaussians,
            settings: &settings,
            extent: 1.0,
            render: &crate::raster::tests::render_from_camera(&gaussians),
            appearance: &[],
            host: HostModel::Ready(&model),
        };
        let loss = term
            .loss(&ctx)
            .unwrap()
            .expect("a pseudo view between two cameras");
        let value = fewview_optim::f32_values(loss, "loss").unwrap()[0];
        assert!(value.abs() < 1e-5, "{value}");
    }
}
