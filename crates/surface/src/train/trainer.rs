//! The trainer: batches of pixels and correspondences, the rendered losses, and the steps of
//! the field's and the poses' optimisers.

use super::config::TrainConfig;
use super::state::{StepStats, TrainState, TrainView};
use burn::tensor::{Device, Tensor, TensorData};
use fewview_optim::f32_values;
use fewview_scene::{Image, Intrinsics, Se3};
use rand::{RngExt, SeedableRng};

use crate::error::{Result, SurfaceError};
use crate::field::Field;
use crate::losses::{self, CorrespondenceBatch, GrayStack};
use crate::matching::Match;
use crate::pose::{d9_to_pose, d9_to_rows, pose_to_d9};
use crate::rays::{camera_dirs, intrinsics_rows, select_rows, world_rays};
use crate::render::{Rendered, eikonal_loss, render_rays, sample_rays};
use fewview_optim::AdamState;

/// A correspondence in the direction the losses read it: pixel `p` of the target view and
/// pixel `q` of the source view.
#[derive(Clone, Copy, Debug)]
struct Directed {
    target_view: usize,
    p: [f32; 2],
    source_view: usize,
    q: [f32; 2],
    confidence: f32,
}

impl Directed {
    /// From view `a` to view `b` of the match.
    fn from_to(m: &Match) -> Self {
        Self {
            target_view: m.view_a,
            p: m.a,
            source_view: m.view_b,
            q: m.b,
            confidence: m.confidence,
        }
    }

    /// From view `b` to view `a` of the match.
    fn to_from(m: &Match) -> Self {
        Self {
            target_view: m.view_b,
            p: m.b,
            source_view: m.view_a,
            q: m.a,
            confidence: m.confidence,
        }
    }
}

/// One step's rays: `n_random` random pixels, then the target ends of the correspondences,
/// then their source ends (`views` and `uv` per ray, pixel centres at half-integers).
struct Batch {
    views: Vec<usize>,
    uv: Vec<[f32; 2]>,
    n_random: usize,
    correspondences: Vec<Directed>,
    /// The sampler's jitter of each ray.
    jitter: Vec<f32>,
}

/// What a batch's rays should render.
struct Targets {
    /// RGB per ray.
    colour: Vec<f32>,
    /// The object mask per ray (1 without masks).
    mask: Vec<f32>,
    /// Whether the colour loss is masked: masks asked for and every view has one.
    masked: bool,
}

/// A rendered batch with what its loss terms read.
struct BatchRays<'a> {
    batch: &'a Batch,
    targets: &'a Targets,
    /// The poses' rows (tracked when the poses step).
    rows: &'a Tensor<2>,
    intrinsics: &'a [Intrinsics],
    origins: &'a Tensor<2>,
    dirs: &'a Tensor<2>,
    out: &'a Rendered,
    device: &'a Device,
}

/// The rays of a batch's correspondences: indices of their target (`p`) and source (`q`) ends
/// among the batch's rays, and each end's view.
struct CorrespondenceEnds {
    p: Vec<usize>,
    q: Vec<usize>,
    views_t: Vec<usize>,
    views_s: Vec<usize>,
}

impl CorrespondenceEnds {
    fn of(rays: &BatchRays) -> Self {
        let (n, nb) = (rays.batch.n_random, rays.batch.correspondences.len());
        let corr = &rays.batch.correspondences;
        Self {
            p: (n..n + nb).collect(),
            q: (n + nb..n + 2 * nb).collect(),
            views_t: corr.iter().map(|c| c.target_view).collect(),
            views_s: corr.iter().map(|c| c.source_view).collect(),
        }
    }

    /// The rows `idx` of `t`.
    fn take(&self, t: &Tensor<2>, idx: &[usize], device: &Device) -> Tensor<2> {
        let ids: Vec<i64> = idx.iter().map(|v| *v as i64).collect();
        t.clone().select(
            0,
            Tensor::<1, burn::tensor::Int>::from_data(TensorData::new(ids, [idx.len()]), device),
        )
    }

    /// The losses' view of the correspondences: both ends' cameras, pixels and surface points
    /// at the rendered depth.
    fn batch(&self, rays: &BatchRays) -> CorrespondenceBatch {
        let (o, d, depth, device) = (rays.origins, rays.dirs, &rays.out.depth, rays.device);
        let point = |idx: &[usize]| {
            self.take(o, idx, device) + self.take(d, idx, device) * self.take(depth, idx, device)
        };
        // The points first, then the cameras: the order the autodiff graph has always been
        // built in.
        let (x_p, x_q) = (point(&self.p), point(&self.q));
        let corr = &rays.batch.correspondences;
        CorrespondenceBatch {
            rows_t: select_rows(rays.rows, &self.views_t),
            rows_s: select_rows(rays.rows, &self.views_s),
            k_t: intrinsics_rows(rays.intrinsics, &self.views_t, device),
            k_s: intrinsics_rows(rays.intrinsics, &self.views_s, device),
            p: corr.iter().map(|c| c.p).collect(),
            q: corr.iter().map(|c| c.q).collect(),
            confidence: corr.iter().map(|c| c.confidence).collect(),
            x_p,
            x_q,
        }
    }
}

/// The trainer.
pub struct Trainer {
    pub config: TrainConfig,
    pub field: Field,
    pub views: Vec<TrainView>,
    pub matches: Vec<Match>,
    pub state: TrainState,
    gray: Vec<f32>,
    width: usize,
    height: usize,
    offsets: Vec<[f32; 2]>,
}

/// The `expected` values of a gradient read back from the device, or an error naming the
/// parameter: a gradient of another size or type is a defect, never a skipped step.
fn gradient_values<const D: usize>(
    gradient: Tensor<D>,
    name: &str,
    expected: usize,
) -> Result<Vec<f32>> {
    let what = format!("gradient of {name}");
    let values = f32_values(gradient, &what)?;
    if values.len() != expected {
        return Err(SurfaceError::invalid(
            what,
            format!("{} values, expected {expected}", values.len()),
        ));
    }
    Ok(values)
}

/// The value of a one-element loss tensor.
fn value(t: &Tensor<1>, what: &str) -> Result<f32> {
    f32_values(t.clone(), what)?
        .first()
        .copied()
        .ok_or_else(|| SurfaceError::invalid(what, "no value"))
}

fn bilinear_rgb(img: &Image, u: f32, v: f32) -> [f32; 3] {
    let (x, y) = ((u - 0.5).max(0.0), (v - 0.5).max(0.0));
    let x0 = (x.floor() as usize).min(img.width - 1);
    let y0 = (y.floor() as usize).min(img.height - 1);
    let x1 = (x0 + 1).min(img.width - 1);
    let y1 = (y0 + 1).min(img.height - 1);
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let mut out = [0.0f32; 3];
    for c in 0..3 {
        out[c] = img.get(x0, y0, c) * (1.0 - fx) * (1.0 - fy)
            + img.get(x1, y0, c) * fx * (1.0 - fy)
            + img.get(x0, y1, c) * (1.0 - fx) * fy
            + img.get(x1, y1, c) * fx * fy;
    }
    out
}

impl Trainer {
    /// A trainer starting from `initial_poses` (world-to-camera, one per view).
    pub fn new(
        config: TrainConfig,
        views: Vec<TrainView>,
        initial_poses: &[Se3],
        matches: Vec<Match>,
    ) -> Result<Self> {
        if views.is_empty() || views.len() != initial_poses.len() {
            return Err(SurfaceError::invalid(
                "training views",
                format!("{} views but {} poses", views.len(), initial_poses.len()),
            ));
        }
        let (width, height) = (views[0].image.width, views[0].image.height);
        for (i, v) in views.iter().enumerate() {
            if (v.image.width, v.image.height) != (width, height) || v.image.channels < 3 {
                return Err(SurfaceError::invalid(
                    format!("training view {i}"),
                    format!(
                        "is {}×{}×{}; all views must be RGB of the first view's size {width}×{height}",
                        v.image.width, v.image.height, v.image.channels
                    ),
                ));
            }
            if !v.image.is_finite() {
                return Err(SurfaceError::invalid(
                    format!("training view {i}"),
                    "image has NaN or Inf",
                ));
            }
            if let Some(m) = &v.mask
                && (m.width, m.height) != (width, height)
            {
                return Err(SurfaceError::invalid(
                    format!("mask of view {i}"),
                    "size differs from its image",
                ));
            }
        }
        for m in &matches {
            if m.view_a >= views.len() || m.view_b >= views.len() {
                return Err(SurfaceError::invalid(
                    "matches",
                    format!("view index {} or {} out of range", m.view_a, m.view_b),
                ));
            }
        }
        let field = config.checked_field()?;
        let params = field.init_params(config.seed);
        let adam = params.iter().map(|p| AdamState::new(1, p.len())).collect();
        let poses: Vec<f32> = initial_poses
            .iter()
            .flat_map(|p| pose_to_d9(p).map(|v| v as f32))
            .collect();
        let pose_adam = AdamState::new(1, poses.len());
        let mut gray = Vec::with_capacity(views.len() * width * height);
        for v in &views {
            for p in 0..width * height {
                let px = &v.image.data[p * v.image.channels..];
                gray.push(0.299 * px[0] + 0.587 * px[1] + 0.114 * px[2]);
            }
        }
        let offsets = losses::patch_offsets(config.losses.patch_half, config.losses.patch_step);
        Ok(Self {
            field,
            views,
            matches,
            state: TrainState {
                iteration: 0,
                params,
                adam,
                poses,
                pose_adam,
            },
            gray,
            width,
            height,
            offsets,
            config,
        })
    }

    /// The current world-to-camera poses.
    pub fn poses(&self) -> Vec<Se3> {
        self.state
            .poses
            .chunks(9)
            .map(|d| d9_to_pose(&d.iter().map(|v| *v as f64).collect::<Vec<_>>()))
            .collect()
    }

    /// Progress `k / K` of the current iteration.
    fn progress(&self) -> f64 {
        self.state.iteration as f64 / self.config.iterations as f64
    }

    /// Coarse-to-fine progress in `[0, 1]` over the window `(α₁, α₂)`.
    pub fn c2f_alpha(&self) -> f64 {
        let (a1, a2) = self.config.c2f;
        if a2 <= a1 {
            return 1.0;
        }
        ((self.progress() - a1) / (a2 - a1)).clamp(0.0, 1.0)
    }

    /// Replaces the state (resume from a checkpoint).
    pub fn restore(&mut self, state: TrainState) -> Result<()> {
        let shapes = self.field.param_shapes();
        let ok = state.params.len() == shapes.len()
            && state
                .params
                .iter()
                .zip(&shapes)
                .all(|(p, s)| p.len() == s.1)
            && state.adam.len() == shapes.len()
            && state.poses.len() == self.views.len() * 9;
        if !ok {
            return Err(SurfaceError::invalid(
                "checkpoint",
                "parameter shapes do not match this configuration and these views",
            ));
        }
        self.state = state;
        Ok(())
    }

    /// Whether iteration `it` steps the poses: refinement is on and `pose_start` has passed.
    pub fn steps_poses(&self, it: usize) -> bool {
        self.config.refine_poses
            && (it as f64) >= self.config.pose_start * self.config.iterations as f64
    }

    /// One optimisation step: a batch of random rays and correspondences
    /// (`sample_batch`), rendered through the current poses, the loss terms on it
    /// (`loss_terms`), then the Adam updates (`update`).
    pub fn step(&mut self) -> Result<StepStats> {
        let it = self.state.iteration;
        let cfg = self.config.clone();
        let mut rng = rand::rngs::StdRng::seed_from_u64(
            cfg.seed ^ (it as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
        );
        let alpha = self.c2f_alpha();
        self.field.sdf.set_progress(alpha);
        let progress = self.progress();
        let cos_anneal = if cfg.cos_anneal_end > 0.0 {
            (progress / cfg.cos_anneal_end).min(1.0) as f32
        } else {
            1.0
        };
        let nv = self.views.len();
        let batch = self.sample_batch(&mut rng);
        let targets = self.targets(&batch);

        // --- Tensors with gradients.
        let device = Device::flex().autodiff();
        let params: Vec<Tensor<1>> = self
            .state
            .params
            .iter()
            .map(|p| {
                Tensor::<1>::from_data(TensorData::new(p.clone(), [p.len()]), &device)
                    .require_grad()
            })
            .collect();
        let d9 =
            Tensor::<2>::from_data(TensorData::new(self.state.poses.clone(), [nv, 9]), &device);
        // Poses are tracked only in the iterations that step them: while they are held the
        // rays are constants, and the hash grid's backward skips the gradient with respect to
        // the sample positions, which nothing else reads.
        let step_poses = self.steps_poses(it);
        let d9 = if step_poses { d9.require_grad() } else { d9 };
        let rows = d9_to_rows(d9.clone());
        let intr: Vec<Intrinsics> = self.views.iter().map(|v| v.intrinsics).collect();
        let sel = select_rows(&rows, &batch.views);
        let dcam = camera_dirs(&intr, &batch.views, &batch.uv);
        let (origins, dirs) = world_rays(&sel, &dcam);

        // --- Sampling on host values.
        let o_host: Vec<[f32; 3]> = f32_values(origins.clone(), "ray origins")?
            .chunks(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        let d_host: Vec<[f32; 3]> = f32_values(dirs.clone(), "ray directions")?
            .chunks(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        let field = &self.field;
        let host_params = &self.state.params;
        let sdf_fn = |p: &[f32]| field.sdf_host(host_params, p);
        let z = sample_rays(&sdf_fn, &o_host, &d_host, &cfg.sample, Some(&batch.jitter))?;

        // --- Render.
        let out = render_rays(
            &self.field,
            &params,
            origins.clone(),
            dirs.clone(),
            &z,
            cos_anneal,
            cfg.background,
        )?;
        let rays = BatchRays {
            batch: &batch,
            targets: &targets,
            rows: &rows,
            intrinsics: &intr,
            origins: &origins,
            dirs: &dirs,
            out: &out,
            device: &device,
        };
        let mut stats = StepStats {
            iteration: it,
            ..Default::default()
        };
        let total = self.loss_terms(&rays, progress, &mut stats)?;
        stats.total = value(&total, "total loss")?;
        stats.inv_s = (self.state.params[self.field.index().variance][0] * 10.0).exp();
        if !stats.total.is_finite() {
            return Err(SurfaceError::Diverged {
                iteration: it,
                message: format!("loss is {}", stats.total),
            });
        }
        let tracked_poses = step_poses.then_some(&d9);
        stats.pose_step_skipped = self.update(total, &params, tracked_poses)?;
        self.state.iteration += 1;
        Ok(stats)
    }

    /// Random pixels of random views, then correspondences (each in a random direction), then
    /// one sampling jitter per ray, all drawn from `rng` in that order.
    fn sample_batch(&self, rng: &mut rand::rngs::StdRng) -> Batch {
        let cfg = &self.config;
        let lc = &cfg.losses;
        let nv = self.views.len();
        let (w, h) = (self.width, self.height);
        let mut views = Vec::new();
        let mut uv = Vec::new();
        for _ in 0..cfg.rays_per_batch {
            let v = rng.random_range(0..nv);
            let x = rng.random_range(0..w);
            let y = rng.random_range(0..h);
            views.push(v);
            uv.push([x as f32 + 0.5, y as f32 + 0.5]);
        }
        let use_corr = !self.matches.is_empty()
            && cfg.matches_per_batch > 0
            && (lc.matching || lc.ncc || lc.geometric_consistency);
        let mut correspondences: Vec<Directed> = Vec::new();
        if use_corr {
            for _ in 0..cfg.matches_per_batch {
                let m = self.matches[rng.random_range(0..self.matches.len())];
                // Either direction, so every view is a target as often as a source.
                correspondences.push(if rng.random_bool(0.5) {
                    Directed::from_to(&m)
                } else {
                    Directed::to_from(&m)
                });
            }
        }
        let n_random = views.len();
        for c in &correspondences {
            views.push(c.target_view);
            uv.push(c.p);
        }
        for c in &correspondences {
            views.push(c.source_view);
            uv.push(c.q);
        }
        let jitter: Vec<f32> = (0..views.len())
            .map(|_| rng.random_range(-0.5f32..0.5))
            .collect();
        Batch {
            views,
            uv,
            n_random,
            correspondences,
            jitter,
        }
    }

    /// The colours the batch's rays should render and their mask values (1 without a mask).
    fn targets(&self, batch: &Batch) -> Targets {
        let use_masks = self.config.use_masks;
        let (w, h) = (self.width, self.height);
        let r = batch.views.len();
        let mut colour = Vec::with_capacity(r * 3);
        let mut mask = Vec::with_capacity(r);
        for (&v, p) in batch.views.iter().zip(&batch.uv) {
            colour.extend(bilinear_rgb(&self.views[v].image, p[0], p[1]));
            let m = match &self.views[v].mask {
                Some(m) if use_masks => {
                    let x = ((p[0] - 0.5).round().max(0.0) as usize).min(w - 1);
                    let y = ((p[1] - 0.5).round().max(0.0) as usize).min(h - 1);
                    (m.get(x, y, 0) > 0.5) as u8 as f32
                }
                _ => 1.0,
            };
            mask.push(m);
        }
        let masked = use_masks && self.views.iter().all(|v| v.mask.is_some());
        Targets {
            colour,
            mask,
            masked,
        }
    }

    /// The total loss of a rendered batch: colour and mask, then the geometry terms, then the
    /// correspondence terms, each weighted and recorded in `stats`.
    fn loss_terms(
        &self,
        rays: &BatchRays,
        progress: f64,
        stats: &mut StepStats,
    ) -> Result<Tensor<1>> {
        let lc = &self.config.losses;
        let (out, targets) = (rays.out, rays.targets);
        let r = rays.batch.views.len();
        let color_w: Vec<f32> = if targets.masked {
            targets.mask.clone()
        } else {
            vec![1.0; r]
        };
        let l_color = losses::color_loss(&out.color, &targets.colour, &color_w);
        stats.color = value(&l_color, "colour loss")?;
        stats.psnr = -10.0 * stats.color.max(1e-10).log10();
        let mut total = l_color;
        if targets.masked && lc.lambda_mask > 0.0 {
            let l = losses::mask_loss(&out.weight_sum, &targets.mask);
            stats.mask = value(&l, "mask loss")?;
            total = total + l * lc.lambda_mask;
        }
        if let Some(g) = self.geometry_loss(rays, progress, stats)? {
            total = total + g * lc.lambda_geo;
        }
        if !rays.batch.correspondences.is_empty() {
            total = self.correspondence_losses(rays, total, stats)?;
        }
        Ok(total)
    }

    /// The Eikonal term and the progressive SDF term (weighted by `lambda_psdf`), unweighted
    /// by `lambda_geo`; `None` when both are off.
    fn geometry_loss(
        &self,
        rays: &BatchRays,
        progress: f64,
        stats: &mut StepStats,
    ) -> Result<Option<Tensor<1>>> {
        let cfg = &self.config;
        let lc = &cfg.losses;
        let (out, targets) = (rays.out, rays.targets);
        let depth_host = f32_values(out.depth.clone(), "rendered depth")?;
        let wsum_host = f32_values(out.weight_sum.clone(), "rendered opacity")?;
        let mut l_geo: Option<Tensor<1>> = None;
        if lc.eikonal {
            let l = eikonal_loss(out);
            stats.eikonal = value(&l, "Eikonal loss")?;
            l_geo = Some(l);
        }
        if lc.psdf && lc.lambda_psdf > 0.0 {
            let ray_ok: Vec<bool> = (0..rays.batch.views.len())
                .map(|i| (!targets.masked || targets.mask[i] > 0.5) && wsum_host[i] > 0.5)
                .collect();
            let lb = lc.lambda_b as f64;
            let window = cfg.c2f;
            let band = move |d: f32| losses::psdf_band(progress, window, lb, d as f64) as f32;
            if let Some(l) = losses::psdf_loss(
                &out.sdf,
                &out.mid_z,
                out.samples,
                &depth_host,
                &ray_ok,
                &band,
            ) {
                stats.psdf = value(&l, "pSDF loss")?;
                let l = l * lc.lambda_psdf;
                l_geo = Some(match l_geo {
                    Some(g) => g + l,
                    None => l,
                });
            }
        }
        Ok(l_geo)
    }

    /// `total` plus the matching term and the uncertainty-weighted NCC and geometric
    /// consistency terms of the batch's correspondences.
    fn correspondence_losses(
        &self,
        rays: &BatchRays,
        mut total: Tensor<1>,
        stats: &mut StepStats,
    ) -> Result<Tensor<1>> {
        let lc = &self.config.losses;
        let ends = CorrespondenceEnds::of(rays);
        let batch = ends.batch(rays);
        if lc.matching && lc.lambda_mc > 0.0 {
            let l = losses::matching_loss(&batch)?;
            stats.matching = value(&l, "matching loss")?;
            total = total + l * lc.lambda_mc;
        }
        if !((lc.ncc || lc.geometric_consistency) && lc.lambda_u > 0.0) {
            return Ok(total);
        }
        let dist = losses::backprojection_distances(&batch);
        let dh = f32_values(dist.clone(), "back-projection distances")?;
        let gamma = if lc.uncertainty {
            losses::uncertainty_weights(&dh)
        } else {
            vec![1.0; ends.p.len()]
        };
        let mut l_u: Option<Tensor<1>> = None;
        if lc.ncc {
            let gray = GrayStack {
                values: Tensor::from_data(
                    TensorData::new(self.gray.clone(), [self.gray.len()]),
                    rays.device,
                ),
                host: self.gray.clone(),
                width: self.width,
                height: self.height,
            };
            let l = losses::ncc_loss(
                &gray,
                &batch,
                &ends.views_t,
                &ends.views_s,
                &ends.take(rays.origins, &ends.p, rays.device),
                &ends.take(&rays.out.normal, &ends.p, rays.device),
                &self.offsets,
                &gamma,
            )?;
            stats.ncc = value(&l, "NCC loss")?;
            l_u = Some(l);
        }
        if lc.geometric_consistency {
            let l = losses::geometric_consistency_loss(&dist, &gamma);
            stats.geometric = value(&l, "geometric consistency loss")?;
            let l = l * lc.lambda_gc;
            l_u = Some(match l_u {
                Some(a) => a + l,
                None => l,
            });
        }
        if let Some(l) = l_u {
            total = total + l * lc.lambda_u;
        }
        Ok(total)
    }

    /// Back-propagates `total` and takes the Adam steps of the field's parameters and, when
    /// `poses` is tracked, of the poses. Returns whether the pose step was skipped for a
    /// non-finite gradient.
    fn update(
        &mut self,
        total: Tensor<1>,
        params: &[Tensor<1>],
        poses: Option<&Tensor<2>>,
    ) -> Result<bool> {
        let cfg = &self.config;
        let it = self.state.iteration;
        let grads = total.backward();
        let lr = cfg.lr.at(it, cfg.iterations);
        let names = self.field.param_shapes();
        for (k, p) in params.iter().enumerate() {
            // A parameter the losses did not reach has no gradient: a zero step.
            let g = match p.grad(&grads) {
                Some(g) => gradient_values(g, names[k].0, self.state.params[k].len())?,
                None => vec![0.0; self.state.params[k].len()],
            };
            let f = if names[k].0 == "hash_table" {
                cfg.hash_lr_factor
            } else {
                1.0
            };
            self.state.adam[k].step(&mut self.state.params[k], &g, lr * f, &cfg.adam);
        }
        let mut pose_step_skipped = false;
        if let Some(g) = poses.and_then(|d9| d9.grad(&grads)) {
            let g = gradient_values(g, "poses", self.state.poses.len())?;
            pose_step_skipped = !self.step_poses_with(&g);
        }
        if self
            .state
            .params
            .iter()
            .any(|p| p.iter().any(|v| !v.is_finite()))
        {
            return Err(SurfaceError::Diverged {
                iteration: it,
                message: "a parameter became NaN or Inf".into(),
            });
        }
        Ok(pose_step_skipped)
    }

    /// The Adam step of the poses at the current iteration with gradient `g`, when `g` is
    /// finite (`true`). A non-finite one leaves the poses and their Adam state alone (`false`):
    /// counted in [`StepStats::pose_step_skipped`], not fatal, since one ray batch behind a
    /// camera can give a non-finite pose gradient while the field's stay finite.
    fn step_poses_with(&mut self, g: &[f32]) -> bool {
        if !g.iter().all(|v| v.is_finite()) {
            return false;
        }
        let cfg = &self.config;
        let lr = cfg.pose_lr.at(self.state.iteration, cfg.iterations);
        self.state
            .pose_adam
            .step(&mut self.state.poses, g, lr, &cfg.adam);
        true
    }

    /// Sets the field's coarse-to-fine state to the current iteration (after a restore).
    pub fn sync_progress(&mut self) {
        let a = self.c2f_alpha();
        self.field.sdf.set_progress(a);
    }

    /// Shares the field for evaluation.
    pub fn field_params(&self) -> (&Field, &[Vec<f32>]) {
        (&self.field, &self.state.params)
    }
}

#[cfg(test)]
mod tests {
    use super::Trainer;
    use crate::sdf_scene::{SdfSceneOptions, sdf_dataset};
    use crate::train::config::TrainConfig;
    use crate::train::state::TrainView;

    /// A small trainer on the analytic scene (three 48 × 36 views at their true poses, no
    /// matches).
    fn small_trainer() -> Trainer {
        let ds = sdf_dataset(&SdfSceneOptions {
            width: 48,
            height: 36,
            views: 3,
            train: vec![0, 1, 2],
            supersample: 1,
            ..Default::default()
        });
        let views: Vec<TrainView> = ds.train_views().map(TrainView::of).collect();
        let poses: Vec<_> = ds.train_views().map(|v| v.camera.world_to_camera).collect();
        let mut config = TrainConfig {
            iterations: 10,
            rays_per_batch: 64,
            ..Default::default()
        };
        config.sample.n_coarse = 16;
        config.sample.n_importance = 16;
        Trainer::new(config, views, &poses, Vec::new()).unwrap()
    }

    /// A NaN in the field (the bias of the SDF network's distance output, so every SDF value is
    /// NaN) stops training with an error naming the iteration, and that iteration changes
    /// nothing: no step of any parameter is taken or skipped in silence.
    #[test]
    fn a_nan_in_the_field_is_an_error_naming_the_iteration() {
        let mut trainer = small_trainer();
        for _ in 0..2 {
            trainer.step().unwrap();
        }
        let names = trainer.field.param_shapes();
        let k = names.iter().position(|(n, _)| *n == "sdf_mlp").unwrap();
        // The output layer's bias is the last `1 + feature_dim` values; the distance is first.
        let out = 1 + trainer.config.field.feature_dim;
        let len = trainer.state.params[k].len();
        trainer.state.params[k][len - out] = f32::NAN;
        let before = trainer.state.clone();
        let err = trainer.step().unwrap_err().to_string();
        assert_eq!(err, "training diverged at iteration 2: loss is NaN");
        assert!(!err.contains('\n'), "{err}");
        assert_eq!(trainer.state.iteration, 2);
        assert_eq!(trainer.state.float_bits(), before.float_bits());
    }

    /// A non-finite pose gradient skips the pose step (poses and their Adam moments untouched)
    /// and says so; a finite one steps.
    #[test]
    fn a_non_finite_pose_gradient_skips_the_pose_step_and_says_so() {
        let mut trainer = small_trainer();
        let (poses, adam) = (trainer.state.poses.clone(), trainer.state.pose_adam.clone());
        let mut g = vec![0.01f32; poses.len()];
        g[4] = f32::INFINITY;
        assert!(!trainer.step_poses_with(&g));
        assert_eq!(trainer.state.poses, poses);
        assert_eq!(trainer.state.pose_adam, adam);
        g[4] = 0.01;
        assert!(trainer.step_poses_with(&g));
        assert_ne!(trainer.state.poses, poses);
    }
}
