//! The training loop: render a training view through the Burn op, photometric loss plus any
//! pluggable [`LossTerm`]s, backward, Adam, densification — and checkpoints that resume to the
//! same result.

use std::cell::OnceCell;

use burn::tensor::{Device, Tensor, TensorData};
use fewview_optim::{ReadbackError, f32_values};
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

use super::appearance::{self, Affine, AppearanceState};
use super::config::TrainConfig;
use super::densify::{
    DensifyReport, DensifyStats, ModelAdam, clone_and_split, densify_and_prune, plan, reset_opacity,
};
use super::resident::{Gradients, ResidentState, StepRates};
use crate::loss::photometric_loss;
use crate::model::{GaussianModel, inverse_sigmoid};
use crate::op::{GaussianTensors, RenderTensors, RenderView, render, render_deferred};
use crate::raster::{RenderCamera, RenderSettings};

/// A training image as the loop uses it.
#[derive(Clone, Debug)]
pub struct TrainView {
    pub name: String,
    pub camera: RenderCamera,
    /// `[H, W, 3]` target.
    pub target: Tensor<3>,
    /// The image's alpha, when it has one: lets the loop composite it over other backgrounds.
    alpha: Option<AlphaTensors>,
    /// `[H, W, 1]`, 1 where the image holds photo data and 0 in the blank border of an
    /// undistorted photo; the photometric loss sees neither render nor target there.
    pub valid: Option<Tensor<3>>,
}

/// An RGBA photograph stored composited over a known background, so that it can be
/// re-composited over any colour: `rgb·a + (1 − a)·new = image + (1 − a)·(new − old)`.
#[derive(Clone, Debug)]
pub struct AlphaImage {
    /// The composited image, `[H, W, 3]` row-major.
    composited: Vec<f32>,
    /// Alpha, `[H, W]`.
    alpha: Vec<f32>,
    /// The colour `composited` was composited over.
    background: [f32; 3],
    height: usize,
    width: usize,
}

impl AlphaImage {
    /// `image` (3 channels) composited over `background` with alpha `alpha` (1 channel, same
    /// size); `None` when the shapes disagree.
    pub fn new(
        image: &fewview_scene::Image,
        alpha: &fewview_scene::Image,
        background: [f32; 3],
    ) -> Option<Self> {
        let same = image.width == alpha.width && image.height == alpha.height;
        (same && image.channels == 3 && alpha.channels == 1).then(|| Self {
            composited: image.data.clone(),
            alpha: alpha.data.clone(),
            background,
            height: image.height,
            width: image.width,
        })
    }

    /// The image and `1 − alpha` on `device`.
    fn upload(&self, device: &Device) -> AlphaTensors {
        let (h, w) = (self.height, self.width);
        let one_minus: Vec<f32> = self.alpha.iter().map(|a| 1.0 - a).collect();
        AlphaTensors {
            composited: Tensor::<3>::from_data(
                TensorData::new(self.composited.clone(), [h, w, 3]),
                device,
            ),
            one_minus_alpha: Tensor::<3>::from_data(TensorData::new(one_minus, [h, w, 1]), device),
            background: self.background,
        }
    }
}

/// An [`AlphaImage`] on the compute device, so that compositing it over an iteration's
/// background is a tensor operation and uploads nothing but the colour.
#[derive(Clone, Debug)]
struct AlphaTensors {
    /// `[H, W, 3]`
    composited: Tensor<3>,
    /// `[H, W, 1]`
    one_minus_alpha: Tensor<3>,
    background: [f32; 3],
}

impl AlphaTensors {
    /// `image + (1 − a)·(new − old)`.
    fn over(&self, background: [f32; 3]) -> Tensor<3> {
        let shift = [0, 1, 2].map(|c| background[c] - self.background[c]);
        let device = self.composited.device();
        let shift = Tensor::<3>::from_data(TensorData::new(shift.to_vec(), [1, 1, 3]), &device);
        self.composited.clone() + self.one_minus_alpha.clone() * shift
    }
}

impl TrainView {
    pub fn new(
        name: impl Into<String>,
        camera: RenderCamera,
        image: &fewview_scene::Image,
        device: &Device,
    ) -> Self {
        let target = Tensor::<3>::from_data(
            TensorData::new(
                image.data.clone(),
                [image.height, image.width, image.channels],
            ),
            device,
        );
        Self {
            name: name.into(),
            camera,
            target,
            alpha: None,
            valid: None,
        }
    }

    /// Attaches a validity mask (1 channel, the image's size; see [`TrainView::valid`]).
    /// A mask of another shape is ignored.
    pub fn with_valid(mut self, valid: &fewview_scene::Image, device: &Device) -> Self {
        let [h, w, _] = self.target.dims();
        if valid.channels == 1 && valid.width == w && valid.height == h {
            let data = TensorData::new(valid.data.clone(), [h, w, 1]);
            self.valid = Some(Tensor::<3>::from_data(data, device));
        }
        self
    }

    /// Attaches the image's alpha (see [`AlphaImage`]).
    pub fn with_alpha(mut self, alpha: AlphaImage) -> Self {
        self.alpha = Some(alpha.upload(&self.target.device()));
        self
    }

    /// The target composited over `background`, when the image has alpha.
    pub fn target_over(&self, background: [f32; 3]) -> Option<Tensor<3>> {
        self.alpha.as_ref().map(|a| a.over(background))
    }
}

/// What a loss term sees at one iteration.
pub struct LossContext<'a> {
    /// 1-based iteration.
    pub iteration: usize,
    /// The training view rendered for the photometric loss this iteration.
    pub view_index: usize,
    pub views: &'a [TrainView],
    /// The parameters being optimised (tracked: losses built from them reach the optimiser).
    pub gaussians: &'a GaussianTensors,
    pub settings: &'a RenderSettings,
    /// Scene extent (radius of the training cameras).
    pub extent: f32,
    /// The photometric render of this iteration.
    pub render: &'a RenderTensors,
    /// The training photos' colour transforms, when the run learns them (by view index).
    pub appearance: &'a [Affine],
    host: HostModel<'a>,
}

/// The parameters on the host: at hand when training keeps them there, read back from the
/// device on first use when it does not.
enum HostModel<'a> {
    Ready(&'a GaussianModel),
    OnDemand(OnceCell<GaussianModel>),
}

impl LossContext<'_> {
    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.gaussians.opacity_logits.dims()[0]
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The same parameters on the host (for neighbour searches and the like). When training
    /// keeps its state on the device, the first call of an iteration reads them back.
    pub fn model(&self) -> Result<&GaussianModel, ReadbackError> {
        match &self.host {
            HostModel::Ready(model) => Ok(model),
            HostModel::OnDemand(cell) => {
                if let Some(model) = cell.get() {
                    return Ok(model);
                }
                let model = GaussianModel::from_tensors(self.gaussians)?;
                Ok(cell.get_or_init(|| model))
            }
        }
    }

    /// Renders the current Gaussians from any camera (e.g. a virtual camera between training
    /// views); gradients flow back to the parameters.
    pub fn render(&self, camera: &RenderCamera) -> RenderTensors {
        let device = self.gaussians.means.device();
        render(
            self.gaussians,
            Tensor::<2>::zeros([self.len(), 2], &device),
            &RenderView {
                camera: camera.clone(),
                settings: self.settings.clone(),
            },
        )
    }
}

/// An extra loss term (e.g. the fusion method of the fusion paper and its ablations).
pub trait LossTerm: Send {
    fn name(&self) -> &str;
    /// This term's (already weighted) loss at this iteration, `None` to skip, or an error that
    /// stops training.
    fn loss(&mut self, ctx: &LossContext<'_>) -> Result<Option<Tensor<1>>, TrainError>;
}

/// Progress of one iteration, for progress bars and logs.
#[derive(Clone, Debug, Serialize)]
pub struct Progress {
    pub iteration: usize,
    pub iterations: usize,
    pub loss: f32,
    pub gaussians: usize,
    pub densified: Option<DensifyReport>,
}

/// Why training stopped early.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error("training diverged at iteration {iteration}: loss is {loss}")]
    Diverged { iteration: usize, loss: f32 },
    #[error("invalid training setup: {0}")]
    Invalid(String),
    /// Densification and pruning removed every Gaussian: there is nothing left to train or save.
    #[error(
        "densification/pruning at iteration {iteration} removed every Gaussian ({before} before, 0 left); start from more points (e.g. a larger --init-points) or prune less"
    )]
    NoGaussiansLeft { iteration: usize, before: usize },
    /// A loss, gradient or render output whose values could not be read back (a defect).
    #[error(transparent)]
    Readback(#[from] ReadbackError),
}

/// Everything that changes during training; saved in checkpoints.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainState {
    /// Iterations completed.
    pub iteration: usize,
    pub model: GaussianModel,
    pub adam: ModelAdam,
    pub stats: DensifyStats,
    /// The training photos' colour transforms (empty without an appearance model).
    pub appearance: AppearanceState,
}

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
    state: TrainState,
    /// The device copy, when the state is kept on the device.
    resident: Option<ResidentState>,
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
    fn sync_host(&mut self) -> Result<(), TrainError> {
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
    fn rng(&self, iteration: usize, stream: u64) -> StdRng {
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
        let (out, pairs) = render_deferred(
            gaussians,
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

    /// Densification and Adam on the host state. A gradient that is not finite stops training.
    fn update_on_host(
        &mut self,
        it: usize,
        grads: Gradients,
        radii: Tensor<1>,
    ) -> Result<Option<DensifyReport>, TrainError> {
        let host = HostGradients::read(grads)?;
        if host.any_not_finite() {
            return Err(TrainError::Diverged {
                iteration: it,
                loss: f32::NAN,
            });
        }
        let radii = f32_values(radii, "screen radii")?;
        let d = &self.config.densify;
        let mut densified = None;
        if it < d.until_iter {
            self.state.stats.record(&radii, &host.means2d);
            densified = self.densify_on_host(it);
        }
        if densified.is_none() && !self.state.model.is_empty() {
            let rates = self.rates(it);
            let (m, a, cfg) = (
                &mut self.state.model,
                &mut self.state.adam,
                &self.config.adam,
            );
            a.means.step(&mut m.means, &host.means, rates.means, cfg);
            a.log_scales
                .step(&mut m.log_scales, &host.log_scales, rates.log_scales, cfg);
            a.quats.step(&mut m.quats, &host.quats, rates.quats, cfg);
            a.opacity_logits.step(
                &mut m.opacity_logits,
                &host.opacity_logits,
                rates.opacity_logits,
                cfg,
            );
            let sh_rate = |col: usize| if col < 3 { rates.sh_dc } else { rates.sh_rest };
            a.sh.step_per_column(&mut m.sh, &host.sh, sh_rate, cfg);
        }
        Ok(densified)
    }

    /// Densification and Adam on the device state; densification is decided on the host (see
    /// [`Self::densify_on_device`]). Gradients are not read back: one that is not finite makes the
    /// next iteration's loss non-finite, which stops training there.
    fn update_on_device(
        &mut self,
        it: usize,
        grads: Gradients,
        radii: Tensor<1>,
    ) -> Result<Option<DensifyReport>, TrainError> {
        let d = &self.config.densify;
        let mut densified = None;
        if it < d.until_iter {
            let resident = self.resident.as_mut().expect("called with a device state");
            resident.record(radii, grads.means2d.clone());
            if self.densifies_at(it) {
                densified = Some(self.densify_on_device(it)?);
            }
            if it.is_multiple_of(self.config.densify.opacity_reset_interval) {
                let resident = self.resident.as_mut().expect("called with a device state");
                resident.reset_opacity(inverse_sigmoid(0.01));
            }
        }
        if densified.is_none() {
            let rates = self.rates(it);
            let resident = self.resident.as_mut().expect("called with a device state");
            resident.adam_step(grads, &rates, &self.config.adam);
        }
        Ok(densified)
    }

    /// Clone, split and prune on the device state: the plan is made on the host from what it
    /// reads back (see [`super::resident`]), with the host path's random draws.
    fn densify_on_device(&mut self, it: usize) -> Result<DensifyReport, TrainError> {
        let d = &self.config.densify;
        let (screen, mut rng) = self.densify_draws(it);
        let resident = self.resident.as_mut().expect("called with a device state");
        let (stats, log_scales, opacity) = resident.densify_inputs()?;
        let (_, split) = clone_and_split(&stats, &log_scales, d, self.extent);
        let (means, quats) = resident.rows(&split)?;
        let rows = |i: usize| {
            let k = split
                .binary_search(&i)
                .expect("asked only for split Gaussians");
            let mean = std::array::from_fn(|a| means[3 * k + a]);
            (mean, std::array::from_fn(|a| quats[4 * k + a]))
        };
        let plan = plan(
            &stats,
            &log_scales,
            &opacity,
            rows,
            d,
            self.extent,
            screen,
            &mut rng,
        );
        if !plan.keep.contains(&true) {
            return Err(TrainError::NoGaussiansLeft {
                iteration: it,
                before: opacity.len(),
            });
        }
        resident.apply(&plan);
        Ok(plan.report())
    }

    /// The screen-size limit and the random generator of densification at iteration `it`, the
    /// same for the host and the device path.
    fn densify_draws(&self, it: usize) -> (Option<f32>, StdRng) {
        let d = &self.config.densify;
        let screen = (it > d.opacity_reset_interval).then_some(d.max_screen_size);
        (screen, self.rng(it, 2))
    }

    /// Whether iteration `it` clones, splits and prunes.
    fn densifies_at(&self, it: usize) -> bool {
        let d = &self.config.densify;
        it < d.until_iter && it > d.from_iter && it.is_multiple_of(d.interval)
    }

    /// Densification of the host state at iteration `it`: clone, split and prune when it is
    /// due, then the periodic opacity reset (before the optimiser step, as the reference code;
    /// an iteration that densifies skips the step because its gradients belong to the old set).
    fn densify_on_host(&mut self, it: usize) -> Option<DensifyReport> {
        let d = &self.config.densify;
        let mut densified = None;
        if self.densifies_at(it) {
            let (screen, mut rng) = self.densify_draws(it);
            let s = &mut self.state;
            densified = Some(densify_and_prune(
                &mut s.model,
                &mut s.adam,
                &mut s.stats,
                d,
                self.extent,
                screen,
                &mut rng,
            ));
        }
        if it.is_multiple_of(d.opacity_reset_interval) {
            reset_opacity(&mut self.state.model, &mut self.state.adam);
        }
        densified
    }

    /// The learning rates of iteration `it`.
    fn rates(&self, it: usize) -> StepRates {
        let lr = &self.config.lr;
        StepRates {
            means: self.config.position_lr(it, self.extent),
            log_scales: lr.scaling,
            quats: lr.rotation,
            opacity_logits: lr.opacity,
            sh_dc: lr.f_dc,
            sh_rest: lr.f_rest,
        }
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

/// One iteration's gradients read back to the host.
struct HostGradients {
    means: Vec<f32>,
    log_scales: Vec<f32>,
    quats: Vec<f32>,
    opacity_logits: Vec<f32>,
    sh: Vec<f32>,
    means2d: Vec<f32>,
}

impl HostGradients {
    /// Reads `grads`; one that cannot be read is an error, never a silently zeroed step.
    fn read(grads: Gradients) -> Result<Self, ReadbackError> {
        Ok(Self {
            means: f32_values(grads.means, "gradient of means")?,
            log_scales: f32_values(grads.log_scales, "gradient of scales")?,
            quats: f32_values(grads.quats, "gradient of rotations")?,
            opacity_logits: f32_values(grads.opacity_logits, "gradient of opacities")?,
            sh: f32_values(grads.sh, "gradient of SH")?,
            means2d: f32_values(grads.means2d, "screen-space gradient")?,
        })
    }

    fn any_not_finite(&self) -> bool {
        [
            &self.means,
            &self.log_scales,
            &self.quats,
            &self.opacity_logits,
            &self.sh,
        ]
        .iter()
        .any(|g| g.iter().any(|v| !v.is_finite()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alpha_image_recomposites_over_a_new_background() {
        // rgb, alpha and the old background per pixel; composite by the definition.
        let rgb = [[0.2f32, 0.4, 0.6], [0.9, 0.1, 0.5], [0.3, 0.3, 0.3]];
        let a = [1.0f32, 0.25, 0.0];
        let (old, new) = ([1.0f32, 1.0, 1.0], [0.1f32, 0.7, 0.3]);
        let over = |bg: [f32; 3]| -> Vec<f32> {
            (0..3)
                .flat_map(|p| (0..3).map(move |c| rgb[p][c] * a[p] + (1.0 - a[p]) * bg[c]))
                .collect()
        };
        let image = fewview_scene::Image::from_vec(3, 1, 3, over(old));
        let alpha = fewview_scene::Image::from_vec(3, 1, 1, a.to_vec());
        let device = Device::flex();
        // The camera plays no part in compositing.
        let view = TrainView::new("v", crate::raster::tests::camera(), &image, &device)
            .with_alpha(AlphaImage::new(&image, &alpha, old).unwrap());
        let got: Vec<f32> = view
            .target_over(new)
            .unwrap()
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        for (g, e) in got.iter().zip(over(new)) {
            assert!((g - e).abs() < 1e-6, "{got:?}");
        }
        assert!(AlphaImage::new(&image, &image, old).is_none());
    }
}
