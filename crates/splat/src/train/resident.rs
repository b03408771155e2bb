//! The training state kept on the compute device between iterations: parameters, Adam moments
//! and densification statistics as Burn tensors, so that a GPU iteration uploads nothing and
//! reads back only the loss.
//!
//! The arithmetic is the host code's, operation for operation ([`fewview_optim::adam`] and
//! [`DensifyStats::record`]), so on the CPU backend the two give the same bits. Densification
//! (clone, split, prune) is decided on the host by [`super::densify::plan`] from what it reads:
//! the statistics, the log-scales and opacities, and the split Gaussians' centres and rotations
//! (the same random draws as the host path); the plan is applied here by gathering rows.

use burn::tensor::{Device, Int, Tensor, TensorData};
use fewview_optim::adam::{AdamConfig, AdamState};
use fewview_optim::{ReadbackError, f32_values};

use super::densify::{DensifyPlan, DensifyStats, ModelAdam};
use crate::model::GaussianModel;
use crate::op::GaussianTensors;

/// Adam moments of one parameter group on the device.
struct Moments<const D: usize> {
    m: Tensor<D>,
    v: Tensor<D>,
    /// Steps taken, for bias correction (as [`AdamState::step`]).
    step: u64,
}

impl<const D: usize> Moments<D> {
    fn upload(state: &AdamState, shape: [usize; D], device: &Device) -> Self {
        Self {
            m: tensor(&state.m, shape, device),
            v: tensor(&state.v, shape, device),
            step: state.step,
        }
    }

    fn download(&self, width: usize, what: &str) -> Result<AdamState, ReadbackError> {
        Ok(AdamState {
            width,
            m: f32_values(self.m.clone(), &format!("Adam first moment of {what}"))?,
            v: f32_values(self.v.clone(), &format!("Adam second moment of {what}"))?,
            step: self.step,
        })
    }

    /// One Adam step of `param` (in place) with gradient `grad`, written as
    /// [`AdamState::step_per_column`] writes it so that the rounding is the same:
    /// `m ← β₁m + (1−β₁)g`, `v ← β₂v + ((1−β₂)g)g`, `p ← p − (lr/bc₁)·m / (√v/√bc₂ + ε)`.
    /// `scale(m, bc₁)` gives `(lr/bc₁)·m` (one rate, or one per column).
    fn step(
        &mut self,
        param: &mut Tensor<D>,
        grad: Tensor<D>,
        scale: impl FnOnce(Tensor<D>, f32) -> Tensor<D>,
        cfg: &AdamConfig,
    ) {
        self.step += 1;
        let t = self.step as i32;
        let bc1 = 1.0 - cfg.beta1.powi(t);
        let bc2_sqrt = (1.0 - cfg.beta2.powi(t)).sqrt();
        let m = self.m.clone() * cfg.beta1 + grad.clone() * (1.0 - cfg.beta1);
        let v = self.v.clone() * cfg.beta2 + grad.clone() * (1.0 - cfg.beta2) * grad;
        let denom = v.clone().sqrt() / bc2_sqrt + cfg.eps;
        let scaled = scale(m.clone(), bc1);
        self.m = m;
        self.v = v;
        *param = param.clone() - scaled / denom;
    }

    /// Appends `rows` rows of zero moments, then keeps the rows of `keep` (all when `None`).
    fn grow_zeros(&mut self, rows: usize, keep: &Option<Tensor<1, Int>>) {
        let zeros = |t: &Tensor<D>| {
            let mut shape = t.dims();
            shape[0] = rows;
            (rows > 0).then(|| Tensor::<D>::zeros(shape, &t.device()))
        };
        let (m, v) = (zeros(&self.m), zeros(&self.v));
        self.m = kept(append(self.m.clone(), m), keep);
        self.v = kept(append(self.v.clone(), v), keep);
    }

    fn reset(&mut self) {
        self.m = self.m.zeros_like();
        self.v = self.v.zeros_like();
    }
}

/// The gradients of one iteration, shaped as the parameters.
pub(crate) struct Gradients {
    pub means: Tensor<2>,
    pub log_scales: Tensor<2>,
    pub quats: Tensor<2>,
    pub opacity_logits: Tensor<1>,
    pub sh: Tensor<3>,
    /// `[N, 2]`: the loss gradient at each projected centre (see [`crate::op::SplatInputs`]).
    pub means2d: Tensor<2>,
}

/// Learning rates of one Adam step.
pub(crate) struct StepRates {
    pub means: f32,
    pub log_scales: f32,
    pub quats: f32,
    pub opacity_logits: f32,
    pub sh_dc: f32,
    pub sh_rest: f32,
}

/// Parameters, Adam moments and densification statistics on the device.
pub(crate) struct ResidentState {
    params: GaussianTensors,
    means: Moments<2>,
    log_scales: Moments<2>,
    quats: Moments<2>,
    opacity_logits: Moments<1>,
    sh: Moments<3>,
    grad_accum: Tensor<1>,
    denom: Tensor<1>,
    max_radii: Tensor<1>,
    sh_coeffs: usize,
    /// Whether the device holds steps the host copy has not seen.
    pub ahead_of_host: bool,
}

impl ResidentState {
    /// Uploads the host state.
    pub fn upload(
        model: &GaussianModel,
        adam: &ModelAdam,
        stats: &DensifyStats,
        device: &Device,
    ) -> Self {
        let (n, k) = (model.len(), model.sh_coeffs);
        Self {
            params: model.to_tensors(device, false),
            means: Moments::upload(&adam.means, [n, 3], device),
            log_scales: Moments::upload(&adam.log_scales, [n, 3], device),
            quats: Moments::upload(&adam.quats, [n, 4], device),
            opacity_logits: Moments::upload(&adam.opacity_logits, [n], device),
            sh: Moments::upload(&adam.sh, [n, k, 3], device),
            grad_accum: tensor(&stats.grad_accum, [n], device),
            denom: tensor(&stats.denom, [n], device),
            max_radii: tensor(&stats.max_radii, [n], device),
            sh_coeffs: k,
            ahead_of_host: false,
        }
    }

    /// Reads everything back into host form.
    pub fn download(&self) -> Result<(GaussianModel, ModelAdam, DensifyStats), ReadbackError> {
        let model = GaussianModel::from_tensors(&self.params)?;
        let k3 = self.sh_coeffs * 3;
        let adam = ModelAdam {
            means: self.means.download(3, "means")?,
            log_scales: self.log_scales.download(3, "scales")?,
            quats: self.quats.download(4, "rotations")?,
            opacity_logits: self.opacity_logits.download(1, "opacities")?,
            sh: self.sh.download(k3, "SH")?,
        };
        let stats = self.stats()?;
        Ok((model, adam, stats))
    }

    /// The densification statistics read back.
    fn stats(&self) -> Result<DensifyStats, ReadbackError> {
        Ok(DensifyStats {
            grad_accum: f32_values(self.grad_accum.clone(), "densification gradient sums")?,
            denom: f32_values(self.denom.clone(), "densification view counts")?,
            max_radii: f32_values(self.max_radii.clone(), "largest screen radii")?,
        })
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.params.opacity_logits.dims()[0]
    }

    /// The parameters as leaves of a new autodiff graph.
    pub fn tracked(&self) -> GaussianTensors {
        let p = &self.params;
        GaussianTensors {
            means: p.means.clone().require_grad(),
            log_scales: p.log_scales.clone().require_grad(),
            quats: p.quats.clone().require_grad(),
            opacity_logits: p.opacity_logits.clone().require_grad(),
            sh: p.sh.clone().require_grad(),
        }
    }

    /// [`DensifyStats::record`] on the device: for each Gaussian with a positive radius, the
    /// largest radius, the sum of `‖∂L/∂μ₂ᴰ‖` and the count of renders.
    pub fn record(&mut self, radii: Tensor<1>, means2d_grad: Tensor<2>) {
        let visible = radii.clone().greater_elem(0.0);
        let n = self.len();
        let norm = (means2d_grad.clone() * means2d_grad)
            .sum_dim(1)
            .reshape([n])
            .sqrt();
        let accum = self.grad_accum.clone();
        self.grad_accum = accum.clone().mask_where(visible.clone(), accum + norm);
        let denom = self.denom.clone();
        self.denom = denom.clone().mask_where(visible, denom + 1.0);
        self.max_radii = self.max_radii.clone().max_pair(radii);
        self.ahead_of_host = true;
    }

    /// One Adam step of every group; the SH DC band and the higher bands at their own rates.
    pub fn adam_step(&mut self, grads: Gradients, rates: &StepRates, cfg: &AdamConfig) {
        let p = &mut self.params;
        let device = p.means.device();
        self.means
            .step(&mut p.means, grads.means, by(rates.means), cfg);
        let scales = by(rates.log_scales);
        self.log_scales
            .step(&mut p.log_scales, grads.log_scales, scales, cfg);
        self.quats
            .step(&mut p.quats, grads.quats, by(rates.quats), cfg);
        let opacities = by(rates.opacity_logits);
        self.opacity_logits
            .step(&mut p.opacity_logits, grads.opacity_logits, opacities, cfg);
        let k = self.sh_coeffs;
        let band_rates: Vec<f32> = (0..k)
            .flat_map(|c| [if c == 0 { rates.sh_dc } else { rates.sh_rest }; 3])
            .collect();
        let band_rates = tensor(&band_rates, [1, k, 3], &device);
        let bands = |m: Tensor<3>, bc1| m * band_rates.div_scalar(bc1);
        self.sh.step(&mut p.sh, grads.sh, bands, cfg);
        self.ahead_of_host = true;
    }

    /// What densification reads: the statistics, all log-scales and opacity logits.
    pub fn densify_inputs(&self) -> Result<(DensifyStats, Vec<f32>, Vec<f32>), ReadbackError> {
        let stats = self.stats()?;
        let p = &self.params;
        let log_scales = f32_values(p.log_scales.clone(), "log-scales")?;
        let opacity = f32_values(p.opacity_logits.clone(), "opacity logits")?;
        Ok((stats, log_scales, opacity))
    }

    /// The centres and quaternions of Gaussians `rows`, in order.
    pub fn rows(&self, rows: &[usize]) -> Result<(Vec<f32>, Vec<f32>), ReadbackError> {
        if rows.is_empty() {
            return Ok((Vec::new(), Vec::new()));
        }
        let index = indices(rows, &self.params.means.device());
        let means = self.params.means.clone().select(0, index.clone());
        let quats = self.params.quats.clone().select(0, index);
        Ok((
            f32_values(means, "centres of split Gaussians")?,
            f32_values(quats, "rotations of split Gaussians")?,
        ))
    }

    /// Applies a densification plan that keeps at least one Gaussian: the new rows are gathered
    /// from their sources (the split samples with their own centres and log-scales), with zero
    /// Adam moments; the unkept rows go; the statistics start again.
    pub fn apply(&mut self, plan: &DensifyPlan) {
        let device = self.params.means.device();
        let index = |rows: &[usize]| (!rows.is_empty()).then(|| indices(rows, &device));
        let sources = plan.sources();
        let kept_rows: Vec<usize> = (0..plan.keep.len()).filter(|&i| plan.keep[i]).collect();
        let keep = (kept_rows.len() < plan.keep.len()).then(|| indices(&kept_rows, &device));
        let (clones, from) = (index(&plan.clone), index(&sources));
        let samples = sources.len() - plan.clone.len();
        let sampled = |values: &[f32]| (samples > 0).then(|| tensor(values, [samples, 3], &device));
        let p = &mut self.params;
        // Centres and log-scales: originals, clones, then the split samples' own values.
        let with_samples = |t: &Tensor<2>, values: &[f32]| {
            let grown = append(t.clone(), gather(t, &clones));
            kept(append(grown, sampled(values)), &keep)
        };
        p.means = with_samples(&p.means, &plan.split_means);
        p.log_scales = with_samples(&p.log_scales, &plan.split_log_scales);
        p.quats = kept(append(p.quats.clone(), gather(&p.quats, &from)), &keep);
        let opacity = append(p.opacity_logits.clone(), gather(&p.opacity_logits, &from));
        p.opacity_logits = kept(opacity, &keep);
        p.sh = kept(append(p.sh.clone(), gather(&p.sh, &from)), &keep);
        let rows = sources.len();
        self.means.grow_zeros(rows, &keep);
        self.log_scales.grow_zeros(rows, &keep);
        self.quats.grow_zeros(rows, &keep);
        self.opacity_logits.grow_zeros(rows, &keep);
        self.sh.grow_zeros(rows, &keep);
        let n = kept_rows.len();
        self.grad_accum = Tensor::<1>::zeros([n], &device);
        self.denom = Tensor::<1>::zeros([n], &device);
        self.max_radii = Tensor::<1>::zeros([n], &device);
        self.ahead_of_host = true;
    }

    /// [`super::densify::reset_opacity`] on the device.
    pub fn reset_opacity(&mut self, cap: f32) {
        let o = self.params.opacity_logits.clone();
        self.params.opacity_logits = o.clamp_max(cap);
        self.opacity_logits.reset();
        self.ahead_of_host = true;
    }
}

impl Gradients {
    /// The gradients of `gaussians` and of the screen-space probe in `grads`; zeros for a
    /// parameter the loss did not reach.
    pub fn of(
        gaussians: &GaussianTensors,
        means2d: &Tensor<2>,
        grads: &burn::tensor::Gradients,
    ) -> Self {
        fn or_zeros<const D: usize>(g: Option<Tensor<D>>, like: &Tensor<D>) -> Tensor<D> {
            g.unwrap_or_else(|| like.clone().detach().zeros_like())
        }
        let g = gaussians;
        Self {
            means: or_zeros(g.means.grad(grads), &g.means),
            log_scales: or_zeros(g.log_scales.grad(grads), &g.log_scales),
            quats: or_zeros(g.quats.grad(grads), &g.quats),
            opacity_logits: or_zeros(g.opacity_logits.grad(grads), &g.opacity_logits),
            sh: or_zeros(g.sh.grad(grads), &g.sh),
            means2d: or_zeros(means2d.grad(grads), means2d),
        }
    }
}

/// `t` with the rows of `extra` appended.
fn append<const D: usize>(t: Tensor<D>, extra: Option<Tensor<D>>) -> Tensor<D> {
    match extra {
        Some(extra) => Tensor::cat(vec![t, extra], 0),
        None => t,
    }
}

/// The rows of `keep` (all when `None`).
fn kept<const D: usize>(t: Tensor<D>, keep: &Option<Tensor<1, Int>>) -> Tensor<D> {
    match keep {
        Some(index) => t.select(0, index.clone()),
        None => t,
    }
}

/// The rows `index` of `t` (none when `None`).
fn gather<const D: usize>(t: &Tensor<D>, index: &Option<Tensor<1, Int>>) -> Option<Tensor<D>> {
    index.as_ref().map(|i| t.clone().select(0, i.clone()))
}

/// `rows` as an index tensor.
fn indices(rows: &[usize], device: &Device) -> Tensor<1, Int> {
    let rows: Vec<i64> = rows.iter().map(|&i| i as i64).collect();
    let len = rows.len();
    Tensor::<1, Int>::from_data(TensorData::new(rows, [len]), device)
}

/// `(lr/bc₁)·m` for a group with one learning rate.
fn by<const D: usize>(lr: f32) -> impl FnOnce(Tensor<D>, f32) -> Tensor<D> {
    move |m, bc1| m * (lr / bc1)
}

fn tensor<const D: usize>(values: &[f32], shape: [usize; D], device: &Device) -> Tensor<D> {
    Tensor::<D>::from_data(TensorData::new(values.to_vec(), shape), device)
}
