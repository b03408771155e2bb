//! The training loop: render a training view through the Burn op, photometric loss plus any
//! pluggable [`LossTerm`]s, backward, Adam, densification — and checkpoints that resume to the
//! same result.

use burn::tensor::{Device, Tensor, TensorData};
use fewview_optim::{ReadbackError, f32_values};
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

use super::adam::AdamState;
use super::config::TrainConfig;
use super::densify::{DensifyReport, DensifyStats, ModelAdam, densify_and_prune, reset_opacity};
use crate::loss::photometric_loss;
use crate::model::GaussianModel;
use crate::op::{GaussianTensors, RenderTensors, RenderView, render};
use crate::raster::{RenderCamera, RenderSettings};

/// A training image as the loop uses it.
#[derive(Clone, Debug)]
pub struct TrainView {
    pub name: String,
    pub camera: RenderCamera,
    /// `[H, W, 3]` target.
    pub target: Tensor<3>,
    /// The image's alpha, when it has one: lets the loop composite it over other backgrounds.
    pub alpha: Option<AlphaImage>,
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

    /// The image composited over `background` instead, as a `[H, W, 3]` tensor.
    pub fn over(&self, background: [f32; 3], device: &Device) -> Tensor<3> {
        let shift = [0, 1, 2].map(|c| background[c] - self.background[c]);
        let data: Vec<f32> = self
            .composited
            .iter()
            .enumerate()
            .map(|(i, &v)| v + (1.0 - self.alpha[i / 3]) * shift[i % 3])
            .collect();
        Tensor::<3>::from_data(TensorData::new(data, [self.height, self.width, 3]), device)
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
        self.alpha = Some(alpha);
        self
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
    /// The same parameters on the host (for neighbour searches and the like).
    pub model: &'a GaussianModel,
    pub settings: &'a RenderSettings,
    /// Scene extent (radius of the training cameras).
    pub extent: f32,
    /// The photometric render of this iteration.
    pub render: &'a RenderTensors,
}

impl LossContext<'_> {
    /// Renders the current Gaussians from any camera (e.g. a virtual camera between training
    /// views); gradients flow back to the parameters.
    pub fn render(&self, camera: &RenderCamera) -> RenderTensors {
        let n = self.model.len();
        let device = self.gaussians.means.device();
        render(
            self.gaussians,
            Tensor::<2>::zeros([n, 2], &device),
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
    /// This term's (already weighted) loss at this iteration, or `None` to skip.
    fn loss(&mut self, ctx: &LossContext<'_>) -> Option<Tensor<1>>;
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
}

/// A training run.
pub struct Trainer {
    pub config: TrainConfig,
    pub state: TrainState,
    pub views: Vec<TrainView>,
    /// Scene extent (3DGS: 1.1 × the largest camera distance from their mean).
    pub extent: f32,
    pub device: Device,
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
            model,
        };
        Ok(Self {
            config,
            state,
            views,
            extent,
            device,
            terms: Vec::new(),
        })
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
                (bg, alpha.over(bg, &self.device))
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
        let cfg = self.config.clone();
        let view_index = self.view_of(it);
        let mut settings = self.settings(it);
        let (background, target) = self.background_and_target(it, &self.views[view_index]);
        settings.background = background;
        let n = self.state.model.len();

        let gaussians = self.state.model.to_tensors(&self.device, true);
        let probe = Tensor::<2>::zeros([n, 2], &self.device).require_grad();
        let view = &self.views[view_index];
        let out = render(
            &gaussians,
            probe.clone(),
            &RenderView {
                camera: view.camera.clone(),
                settings: settings.clone(),
            },
        );
        let [h, w, _] = out.image.dims();
        let rgb = out.image.clone().slice([0..h, 0..w, 0..3]);
        let (rgb, target) = match &view.valid {
            Some(valid) => (rgb * valid.clone(), target * valid.clone()),
            None => (rgb, target),
        };
        let mut loss = photometric_loss(rgb, target, cfg.lambda_dssim);
        {
            let ctx = LossContext {
                iteration: it,
                view_index,
                views: &self.views,
                gaussians: &gaussians,
                model: &self.state.model,
                settings: &settings,
                extent: self.extent,
                render: &out,
            };
            for term in &mut self.terms {
                if let Some(extra) = term.loss(&ctx) {
                    loss = loss + extra;
                }
            }
        }
        let loss_value = f32_values(loss.clone(), "loss")?
            .first()
            .copied()
            .unwrap_or(f32::NAN);
        if !loss_value.is_finite() {
            return Err(TrainError::Diverged {
                iteration: it,
                loss: loss_value,
            });
        }
        let grads = loss.backward();
        // A parameter the loss did not reach has no gradient: zeros. One that cannot be read
        // is an error, never a silently zeroed step.
        fn gradient<const D: usize>(
            t: Option<Tensor<D>>,
            len: usize,
            what: &str,
        ) -> Result<Vec<f32>, ReadbackError> {
            match t {
                Some(t) => f32_values(t, what),
                None => Ok(vec![0.0; len]),
            }
        }
        let g_means = gradient(gaussians.means.grad(&grads), n * 3, "gradient of means")?;
        let g_scales = gradient(
            gaussians.log_scales.grad(&grads),
            n * 3,
            "gradient of scales",
        )?;
        let g_quats = gradient(gaussians.quats.grad(&grads), n * 4, "gradient of rotations")?;
        let g_opacity = gradient(
            gaussians.opacity_logits.grad(&grads),
            n,
            "gradient of opacities",
        )?;
        let k3 = self.state.model.sh_coeffs * 3;
        let g_sh = gradient(gaussians.sh.grad(&grads), n * k3, "gradient of SH")?;
        let g_probe = gradient(probe.grad(&grads), n * 2, "screen-space gradient")?;
        let radii = f32_values(out.radii, "screen radii")?;
        if [&g_means, &g_scales, &g_quats, &g_opacity, &g_sh]
            .iter()
            .any(|g| g.iter().any(|v| !v.is_finite()))
        {
            return Err(TrainError::Diverged {
                iteration: it,
                loss: f32::NAN,
            });
        }

        // Densification (before the optimiser step, as the reference code; an iteration that
        // densifies skips the step because its gradients belong to the old set).
        let d = &cfg.densify;
        let mut densified = None;
        if it < d.until_iter {
            self.state.stats.record(&radii, &g_probe);
            if it > d.from_iter && it.is_multiple_of(d.interval) {
                let screen = (it > d.opacity_reset_interval).then_some(d.max_screen_size);
                let mut rng = self.rng(it, 2);
                densified = Some(densify_and_prune(
                    &mut self.state.model,
                    &mut self.state.adam,
                    &mut self.state.stats,
                    d,
                    self.extent,
                    screen,
                    &mut rng,
                ));
            }
            if it.is_multiple_of(d.opacity_reset_interval) {
                reset_opacity(&mut self.state.model, &mut self.state.adam);
            }
        }
        if self.state.model.is_empty() {
            return Err(TrainError::NoGaussiansLeft {
                iteration: it,
                before: n,
            });
        }
        if densified.is_none() {
            self.adam_step(it, &g_means, &g_scales, &g_quats, &g_opacity, &g_sh);
        }
        self.state.iteration = it;
        Ok(Progress {
            iteration: it,
            iterations: cfg.iterations,
            loss: loss_value,
            gaussians: self.state.model.len(),
            densified,
        })
    }

    fn adam_step(
        &mut self,
        it: usize,
        gm: &[f32],
        gs: &[f32],
        gq: &[f32],
        go: &[f32],
        gsh: &[f32],
    ) {
        let cfg = &self.config;
        let lr = &cfg.lr;
        let m = &mut self.state.model;
        let a = &mut self.state.adam;
        let pos_lr = cfg.position_lr(it, self.extent);
        a.means.step(&mut m.means, gm, pos_lr, &cfg.adam);
        a.log_scales
            .step(&mut m.log_scales, gs, lr.scaling, &cfg.adam);
        a.quats.step(&mut m.quats, gq, lr.rotation, &cfg.adam);
        a.opacity_logits
            .step(&mut m.opacity_logits, go, lr.opacity, &cfg.adam);
        step_sh(&mut a.sh, &mut m.sh, gsh, lr.f_dc, lr.f_rest, cfg);
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
                checkpoint(&self.state, &self.config).map_err(TrainError::Invalid)?;
            }
        }
        Ok(())
    }
}

/// Adam on the SH coefficients with the DC band and the higher bands at their own rates.
fn step_sh(
    state: &mut AdamState,
    params: &mut [f32],
    grads: &[f32],
    lr_dc: f32,
    lr_rest: f32,
    cfg: &TrainConfig,
) {
    state.step_per_column(
        params,
        grads,
        |col| if col < 3 { lr_dc } else { lr_rest },
        &cfg.adam,
    );
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
        let got: Vec<f32> = AlphaImage::new(&image, &alpha, old)
            .unwrap()
            .over(new, &device)
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        for (g, e) in got.iter().zip(over(new)) {
            assert!((g - e).abs() < 1e-6, "{got:?}");
        }
        assert!(AlphaImage::new(&image, &image, old).is_none());
    }
}
