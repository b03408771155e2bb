//! The training loop: render a training view through the Burn op, photometric loss plus any
//! pluggable [`LossTerm`]s, backward, then densification and Adam (`update`) — and checkpoints
//! that resume to the same result.

use std::cell::OnceCell;

use burn::tensor::{Device, Tensor};
use fewview_optim::f32_values;
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::{RngExt, SeedableRng};

use super::appearance::{self, AppearanceState};
use super::config::TrainConfig;
use super::densify::{DensifyStats, ModelAdam};
use super::dropout;
use super::resident::{Gradients, ResidentState};
use super::state::{Progress, TrainError, TrainState};
use super::term::{HostModel, LossContext, LossTerm};
use super::view::TrainView;
use crate::loss::photometric_loss;
use crate::model::GaussianModel;
use crate::op::{GaussianTensors, RenderView, render_deferred};
use crate::raster::RenderSettings;

/// A training run.
///
/// Between iterations the state lives either on the host ([`TrainState`], the CPU default: the
/// host kernels read it directly) or on the compute device (the GPU default: parameters, Adam
/// moments and densification statistics stay in device memory and an iteration reads back only
/// its loss; see [`Trainer::keep_state_on_device`]). [`Trainer::state`] reads it back either way.
pub struct Trainer {
    pub config: TrainConfig,
    pub views: Vec<TrainView>,
    /// Scene extent (3DGS: 1.1 × the largest camera distance from their mean).
    pub extent: f32,
    pub device: Device,
    /// The host copy: current unless `resident` is ahead of it.
    pub(super) state: TrainState,
    /// The device copy, when the state is kept on the device.
    pub(super) resident: Option<ResidentState>,
    keep_on_device: bool,
    terms: Vec<Box<dyn LossTerm>>,
}

impl Trainer {
    pub fn new(
        config: TrainConfig,
        model: GaussianModel,
        views: Vec<TrainView>,
        extent: f32,
        device: Device,
    ) -> Result<Self, TrainError> {
        config.validate().map_err(TrainError::Invalid)?;
        model.validate().map_err(TrainError::Invalid)?;
        if views.is_empty() {
            return Err(TrainError::Invalid("no training views".into()));
        }
        if model.is_empty() {
            return Err(TrainError::Invalid(
                "the initial model has no Gaussians".into(),
            ));
        }
        if model.sh_degree() != config.sh_degree {
            return Err(TrainError::Invalid(format!(
                "model has SH degree {} but the config asks for {}",
                model.sh_degree(),
                config.sh_degree
            )));
        }
        let state = TrainState {
            iteration: 0,
            adam: ModelAdam::new(&model),
            stats: DensifyStats::new(model.len()),
            appearance: AppearanceState::new(config.appearance.model, views.len()),
            model,
        };
        Ok(Self {
            config,
            state,
            views,
            extent,
            keep_on_device: device != Device::flex(),
            device,
            resident: None,
            terms: Vec::new(),
        })
    }

    /// Keeps the state on the compute device between iterations (`true`) or on the host
    /// (`false`). The default is the device for a GPU and the host for the CPU, where the two
    /// compute the same bits.
    pub fn keep_state_on_device(&mut self, on: bool) -> Result<(), TrainError> {
        if !on {
            self.sync_host()?;
            self.resident = None;
        }
        self.keep_on_device = on;
        Ok(())
    }

    /// Iterations completed.
    pub fn iteration(&self) -> usize {
        self.state.iteration
    }

    /// The training state, read back from the device first when it is kept there.
    pub fn state(&mut self) -> Result<&TrainState, TrainError> {
        self.sync_host()?;
        Ok(&self.state)
    }

    /// The training state to change in place (a device copy is uploaded again afterwards).
    pub fn state_mut(&mut self) -> Result<&mut TrainState, TrainError> {
        self.sync_host()?;
        self.resident = None;
        Ok(&mut self.state)
    }

    /// Replaces the training state (resuming from a checkpoint).
    pub fn set_state(&mut self, state: TrainState) {
        self.state = state;
        self.resident = None;
    }

    /// The state without the trainer.
    pub fn into_state(mut self) -> Result<TrainState, TrainError> {
        self.sync_host()?;
        Ok(self.state)
    }

    /// Brings the host copy up to date with the device copy.
    pub(super) fn sync_host(&mut self) -> Result<(), TrainError> {
        if let Some(resident) = self.resident.as_mut().filter(|r| r.ahead_of_host) {
            let (model, adam, stats) = resident.download()?;
            self.state.model = model;
            self.state.adam = adam;
            self.state.stats = stats;
            resident.ahead_of_host = false;
        }
        Ok(())
    }

    pub fn add_term(&mut self, term: Box<dyn LossTerm>) {
        self.terms.push(term);
    }

    pub fn is_done(&self) -> bool {
        self.state.iteration >= self.config.iterations
    }

    /// Render settings at an iteration (the active SH degree grows during training).
    pub fn settings(&self, iteration: usize) -> RenderSettings {
        RenderSettings {
            background: self.config.background,
            sh_degree: self.config.active_sh_degree(iteration),
            near_plane: self.config.near_plane,
        }
    }

    /// The background of an iteration on `view` and the target composited over it: a random
    /// colour when `random_background` is on and the view has alpha, else the configured one.
    fn background_and_target(&self, iteration: usize, view: &TrainView) -> ([f32; 3], Tensor<3>) {
        match &view.alpha {
            Some(alpha) if self.config.random_background => {
                let mut rng = self.rng(iteration, 3);
                let bg = [0; 3].map(|_| rng.random::<f32>());
                (bg, alpha.over(bg))
            }
            _ => (self.config.background, view.target.clone()),
        }
    }

    /// The random generator of one iteration: a pure function of the seed and the iteration, so
    /// a resumed run makes the same choices as an uninterrupted one.
    pub(super) fn rng(&self, iteration: usize, stream: u64) -> StdRng {
        let mix = self.config.seed
            ^ (iteration as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ stream.rotate_left(32);
        StdRng::seed_from_u64(mix)
    }

    /// The training view of an iteration: views in a fresh random order every epoch (as the
    /// reference code's shuffled stack).
    pub fn view_of(&self, iteration: usize) -> usize {
        let n = self.views.len();
        let epoch = (iteration - 1) / n;
        let mut order: Vec<usize> = (0..n).collect();
        order.shuffle(&mut self.rng(epoch, 1));
        order[(iteration - 1) % n]
    }

    /// Runs one iteration.
    pub fn step(&mut self) -> Result<Progress, TrainError> {
        let it = self.state.iteration + 1;
        if self.keep_on_device && self.resident.is_none() {
            let s = &self.state;
            let resident = ResidentState::upload(&s.model, &s.adam, &s.stats, &self.device);
            self.resident = Some(resident);
        }
        let gaussians = match &self.resident {
            Some(resident) => resident.tracked(),
            None => self.state.model.to_tensors(&self.device, true),
        };
        let n = gaussians.opacity_logits.dims()[0];
        let probe = Tensor::<2>::zeros([n, 2], &self.device).require_grad();
        let (loss, loss_value, radii, transform) = self.loss(it, &gaussians, &probe)?;
        let grads = loss.backward();
        if let Some((view, m)) = transform {
            self.step_appearance(it, view, m.grad(&grads))?;
        }
        let grads = Gradients::of(&gaussians, &probe, &grads);
        drop(gaussians);
        let densified = if self.resident.is_some() {
            self.update_on_device(it, grads, radii)?
        } else {
            self.update_on_host(it, grads, radii)?
        };
        let left = self
            .resident
            .as_ref()
            .map_or(self.state.model.len(), super::resident::ResidentState::len);
        if left == 0 {
            return Err(TrainError::NoGaussiansLeft {
                iteration: it,
                before: n,
            });
        }
        self.state.iteration = it;
        Ok(Progress {
            iteration: it,
            iterations: self.config.iterations,
            loss: loss_value,
            gaussians: left,
            densified,
        })
    }

    /// One Adam step of the colour transform of `view` (see [`super::appearance`]). A gradient
    /// that is not finite stops training.
    fn step_appearance(
        &mut self,
        it: usize,
        view: usize,
        grad: Option<Tensor<2>>,
    ) -> Result<(), TrainError> {
        let Some(grad) = grad else {
            return Ok(());
        };
        let grad = f32_values(grad, "gradient of the colour transform")?;
        if grad.iter().any(|g| !g.is_finite()) {
            return Err(TrainError::Diverged {
                iteration: it,
                loss: f32::NAN,
            });
        }
        let lr = self.config.appearance.lr;
        self.state
            .appearance
            .step(view, &grad, lr, &self.config.adam);
        Ok(())
    }

    /// The Gaussians of iteration `it`'s photometric render with DropGaussian's dropout applied
    /// ([`super::dropout`]); `None` when the run does not drop.
    fn dropped(&self, it: usize, gaussians: &GaussianTensors) -> Option<GaussianTensors> {
        let rate = dropout::rate_at(self.config.dropout, it, self.config.iterations);
        (rate > 0.0).then(|| {
            let n = gaussians.opacity_logits.dims()[0];
            let keep = dropout::keep_mask(n, rate, &mut self.rng(it, 4));
            dropout::drop_gaussians(gaussians, &keep, rate)
        })
    }

    /// The iteration's loss (photometric plus the terms), its value, the render's screen
    /// radii, and the trained view's colour transform when the run learns one. A loss that is
    /// not finite stops training.
    ///
    /// On a GPU the render does not wait for its pair count (see [`render_deferred`]): the loss
    /// read-back is where a render that ran out of pair slots shows (its loss is NaN), and the
    /// check that tells it from a divergence makes room, so the loss computed again fits.
    #[allow(clippy::type_complexity)]
    fn loss(
        &mut self,
        it: usize,
        gaussians: &GaussianTensors,
        probe: &Tensor<2>,
    ) -> Result<(Tensor<1>, f32, Tensor<1>, Option<(usize, Tensor<2>)>), TrainError> {
        let view_index = self.view_of(it);
        let mut settings = self.settings(it);
        let (background, target) = self.background_and_target(it, &self.views[view_index]);
        settings.background = background;
        let view = &self.views[view_index];
        let dropped = self.dropped(it, gaussians);
        let (out, pairs) = render_deferred(
            dropped.as_ref().unwrap_or(gaussians),
            probe.clone(),
            &RenderView {
                camera: view.camera.clone(),
                settings: settings.clone(),
            },
        );
        let [h, w, _] = out.image.dims();
        let mut rgb = out.image.clone().slice([0..h, 0..w, 0..3]);
        let transform = self
            .state
            .appearance
            .transform(view_index)
            .map(|m| (view_index, appearance::tracked(m, &self.device)));
        if let Some((_, m)) = &transform {
            rgb = appearance::apply(rgb, m.clone());
        }
        let (rgb, target) = match &view.valid {
            Some(valid) => (rgb * valid.clone(), target * valid.clone()),
            None => (rgb, target),
        };
        let mut loss = photometric_loss(rgb, target, self.config.lambda_dssim);
        if let Some((_, m)) = &transform {
            loss = loss + appearance::regularization(m.clone(), self.config.appearance.weight);
        }
        let ctx = LossContext {
            iteration: it,
            view_index,
            views: &self.views,
            gaussians,
            settings: &settings,
            extent: self.extent,
            render: &out,
            appearance: &self.state.appearance.transforms,
            host: match self.resident {
                Some(_) => HostModel::OnDemand(OnceCell::new()),
                None => HostModel::Ready(&self.state.model),
            },
        };
        for term in &mut self.terms {
            if let Some(extra) = term.loss(&ctx)? {
                loss = loss + extra;
            }
        }
        let loss_value = f32_values(loss.clone(), "loss")?
            .first()
            .copied()
            .unwrap_or(f32::NAN);
        if !loss_value.is_finite() {
            if pairs.overflowed() {
                return self.loss(it, gaussians, probe);
            }
            return Err(TrainError::Diverged {
                iteration: it,
                loss: loss_value,
            });
        }
        Ok((loss, loss_value, out.radii, transform))
    }

    /// Trains to the end (or until `should_stop` says so), reporting progress and saving
    /// checkpoints through `checkpoint` every `checkpoint_interval` iterations.
    pub fn run(
        &mut self,
        mut on_progress: impl FnMut(&Progress),
        mut checkpoint: impl FnMut(&TrainState, &TrainConfig) -> Result<(), String>,
    ) -> Result<(), TrainError> {
        while !self.is_done() {
            let p = self.step()?;
            on_progress(&p);
            let every = self.config.checkpoint_interval;
            if every > 0 && p.iteration % every == 0 && !self.is_done() {
                self.sync_host()?;
                checkpoint(&self.state, &self.config).map_err(TrainError::Invalid)?;
            }
        }
        self.sync_host()
    }
}
