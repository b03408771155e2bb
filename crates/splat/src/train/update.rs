//! The second half of an iteration: densification and the Adam step, on the host state or on
//! the device state, with the same random draws on both.

use burn::tensor::Tensor;
use fewview_optim::{ReadbackError, f32_values};
use rand::rngs::StdRng;

use super::densify::{DensifyReport, clone_and_split, densify_and_prune, plan, reset_opacity};
use super::resident::{Gradients, StepRates};
use super::state::TrainError;
use super::trainer::Trainer;
use crate::model::inverse_sigmoid;

impl Trainer {
    /// Densification and Adam on the host state. A gradient that is not finite stops training.
    pub(super) fn update_on_host(
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
    pub(super) fn update_on_device(
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
