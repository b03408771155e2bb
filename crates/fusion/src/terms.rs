//! The fusion method and its alternatives as loss terms of the splat trainer
//! ([`fewview_splat::train::LossTerm`]).

use std::time::Instant;

use burn::tensor::{Int, Tensor, TensorData};
use fewview_geom::blend::{Weights, occlusion_aware_poisson};
use fewview_geom::knn::PointTree;
use fewview_geom::mesh::Mesh;
use fewview_scene::{Camera, Image};
use fewview_splat::eval::render_model;
use fewview_splat::raster::RenderCamera;
use fewview_splat::train::appearance::{self, Affine};
use fewview_splat::train::{LossContext, LossTerm, TrainConfig, TrainError};
use rand::SeedableRng;
use rand::rngs::StdRng;

use crate::guidance::{exposure_matched, guidance_field};
use crate::losses::{gradient_fusion_loss, masked_l1, total_variation};
use crate::reproject::{Reference, reference_mesh, reproject_pair, surface_depth};
use crate::variant::{FusionConfig, KnnColorOptions, Variant};
use crate::virtual_view::{Neighbours, VirtualView, sample_virtual};

/// A training view as the fusion terms see it.
#[derive(Clone, Debug)]
pub struct FusionView {
    pub camera: Camera,
    pub photo: Image,
}

/// Counts and time spent, for the run's report.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct TermStats {
    /// Iterations the term added a loss.
    pub applied: usize,
    /// Iterations it rendered a virtual view but had nothing to compare (no reference reached it).
    pub empty: usize,
    /// Re-meshings of the training views.
    pub refreshes: usize,
    /// Mean fraction of the virtual view's pixels where the guidance (or pseudo ground truth)
    /// is defined.
    pub mean_coverage: f64,
    pub seconds: f64,
    /// The first failure (a degenerate mesh, a solver error), when iterations failed.
    pub first_error: Option<String>,
}

/// Iterations after an opacity reset during which the virtual-view terms pause: every
/// Gaussian is nearly transparent then, so rendered depth (alpha below 0.5 everywhere) gives no
/// mesh and no reference until the opacities have grown back.
pub const RECOVERY: usize = 100;

/// The virtual-view regularisers (c)–(f): every `every` iterations from `start_fraction` of the
/// run, a virtual camera between two adjacent training views is rendered and its loss added.
pub struct VirtualViewTerm {
    config: FusionConfig,
    views: Vec<FusionView>,
    /// The views' cameras, for drawing virtual cameras between them.
    cameras: Vec<Camera>,
    pairs: Vec<Neighbours>,
    start: usize,
    seed: u64,
    /// Iterations at which training resets the opacities (see [`RECOVERY`]).
    resets: Vec<usize>,
    meshes: Vec<Mesh>,
    /// The iteration whose model the meshes were built for ([`Self::mesh_source`]).
    meshed_for: Option<usize>,
    pub stats: SharedStats,
}

/// Statistics a term keeps while the trainer owns it.
pub type SharedStats = std::sync::Arc<std::sync::Mutex<TermStats>>;

impl VirtualViewTerm {
    /// `views` are the run's training views in the trainer's order; `pairs` index them.
    pub fn new(
        config: FusionConfig,
        views: Vec<FusionView>,
        pairs: Vec<Neighbours>,
        train: &TrainConfig,
    ) -> Self {
        let start = ((train.iterations as f64 * config.start_fraction).round() as usize).max(1);
        let d = &train.densify;
        let resets = (1..d.until_iter)
            .filter(|it| it.is_multiple_of(d.opacity_reset_interval))
            .collect();
        Self {
            config,
            cameras: views.iter().map(|v| v.camera.clone()).collect(),
            views,
            pairs,
            start,
            seed: train.seed,
            resets,
            meshes: Vec::new(),
            meshed_for: None,
            stats: Default::default(),
        }
    }

    /// Whether the term adds its loss at `iteration`: every `every` iterations from the start,
    /// except while the Gaussians recover from an opacity reset.
    fn active(&self, iteration: usize) -> bool {
        let recovering = self
            .resets
            .iter()
            .any(|&r| r < iteration && iteration <= r + RECOVERY);
        iteration >= self.start
            && (iteration - self.start).is_multiple_of(self.config.every)
            && !recovering
    }

    /// The iteration the references of `iteration` are built after: the last multiple of the
    /// refresh interval, or the end of the last opacity reset's recovery when that is later.
    fn mesh_source(&self, iteration: usize) -> usize {
        let done = iteration - 1;
        let periodic = done / self.config.refresh_interval * self.config.refresh_interval;
        let recovered = self
            .resets
            .iter()
            .map(|r| r + RECOVERY)
            .filter(|&r| r <= done)
            .max()
            .unwrap_or(0);
        periodic.max(recovered)
    }

    /// Re-meshes the training views from the current Gaussians when [`Self::mesh_source`]
    /// moves on. It is a pure function of the iteration, so a resumed run meshes the same model
    /// as an uninterrupted one when checkpoints fall on refresh boundaries.
    fn refresh(&mut self, ctx: &LossContext<'_>) -> Result<(), String> {
        let source = self.mesh_source(ctx.iteration);
        if self.meshed_for == Some(source) {
            return Ok(());
        }
        let min_alpha = self.config.reproject.min_alpha;
        self.meshes = self
            .views
            .iter()
            .enumerate()
            .map(|(i, v)| {
                let model = ctx.model().map_err(|e| e.to_string())?;
                let r = render_model(model, &RenderCamera::from(&v.camera), ctx.settings);
                let depth = surface_depth(&r.depth.data, &r.alpha.data, min_alpha);
                let photo = in_model_colours(&v.photo, ctx.appearance.get(i))?;
                reference_mesh(&depth, &v.camera, &photo).map_err(|e| e.to_string())
            })
            .collect::<Result<_, _>>()?;
        self.meshed_for = Some(source);
        self.stats_mut().refreshes += 1;
        Ok(())
    }

    fn stats_mut(&self) -> std::sync::MutexGuard<'_, TermStats> {
        self.stats
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// The two neighbours reprojected into the virtual view whose own surface depth is `depth`.
    fn references(&self, v: &VirtualView, depth: &[f32]) -> Result<[Reference; 2], String> {
        let meshes = [
            &self.meshes[v.neighbours.first],
            &self.meshes[v.neighbours.second],
        ];
        let [f, g] = reproject_pair(meshes, &v.camera, depth, &self.config.reproject)
            .map_err(|e| e.to_string())?;
        Ok(if self.config.match_exposure {
            let (f, g) = exposure_matched(&f, &g, v.t as f32);
            [f, g]
        } else {
            [f, g]
        })
    }

    /// The variant's loss on the rendered virtual view, and the fraction of pixels it covers.
    fn variant_loss(
        &self,
        rgb: Tensor<3>,
        v: &VirtualView,
        depth: &[f32],
    ) -> Result<Option<(Tensor<1>, f64)>, String> {
        let pixels = depth.len().max(1) as f64;
        if self.config.variant == Variant::Tv {
            return Ok(Some((total_variation(rgb) * self.config.tv_weight, 1.0)));
        }
        let [f, g] = self.references(v, depth)?;
        let t = v.t as f32;
        let weight = self.config.weight;
        let loss = match self.config.variant {
            Variant::Gf => {
                let field = guidance_field(&f, &g, t);
                let coverage = field.defined() as f64 / (2.0 * pixels);
                gradient_fusion_loss(rgb, &field).map(|l| (l * weight, coverage))
            }
            Variant::L1Virtual | Variant::Poisson => {
                let truth = if self.config.variant == Variant::Poisson {
                    poisson_target(&f, &g, t)?
                } else {
                    Some(weighted_mean(&f, &g, t))
                };
                let Some(truth) = truth else {
                    return Ok(None);
                };
                let coverage = truth.valid.iter().filter(|&&b| b).count() as f64 / pixels;
                masked_l1(rgb, &truth.image, &truth.valid).map(|l| (l * weight, coverage))
            }
            _ => None,
        };
        Ok(loss)
    }
}

/// A training photo in the colours the Gaussians learn: with a per-photo appearance model
/// ([`fewview_splat::train::appearance`]) the render's colours pass through the photo's transform
/// before they meet the photo, so the references of the virtual views take the inverse
/// transform (as it stands when they are re-meshed).
fn in_model_colours(photo: &Image, transform: Option<&Affine>) -> Result<Image, String> {
    let Some(m) = transform else {
        return Ok(photo.clone());
    };
    if photo.channels != 3 {
        return Err(format!(
            "a colour transform needs an RGB photo, not {} channels",
            photo.channels
        ));
    }
    let inverse = appearance::inverse(m)
        .ok_or_else(|| "a photo's colour transform became singular".to_string())?;
    let data = appearance::apply_host(&inverse, &photo.data)
        .into_iter()
        .map(|v| v.clamp(0.0, 1.0))
        .collect();
    Ok(Image::from_vec(photo.width, photo.height, 3, data))
}

/// A pseudo ground truth of a virtual view: colours (`[H, W, 3]`) and where they hold.
struct PseudoTruth {
    image: Vec<f32>,
    valid: Vec<bool>,
}

/// Variant (d)'s target: `(1 − t)·f* + t·g*` where both are valid, the valid one elsewhere.
fn weighted_mean(f: &Reference, g: &Reference, t: f32) -> PseudoTruth {
    let mut target = vec![0.0; f.image.len()];
    let mut valid = vec![false; f.valid.len()];
    for p in 0..f.valid.len() {
        let (wf, wg) = match (f.valid[p], g.valid[p]) {
            (true, true) => (1.0 - t, t),
            (true, false) => (1.0, 0.0),
            (false, true) => (0.0, 1.0),
            (false, false) => continue,
        };
        valid[p] = true;
        for c in 0..3 {
            target[p * 3 + c] = wf * f.image[p * 3 + c] + wg * g.image[p * 3 + c];
        }
    }
    PseudoTruth {
        image: target,
        valid,
    }
}

/// Variant (e)'s target: the occlusion-aware Poisson blend of Eq. (3) over the union of the
/// masks, the overlap's guidance weighted `1 − t` for `f*`. `None` when a mask is empty (then
/// there is nothing to blend; the term skips the iteration).
fn poisson_target(f: &Reference, g: &Reference, t: f32) -> Result<Option<PseudoTruth>, String> {
    if !f.valid.iter().any(|&v| v) || !g.valid.iter().any(|&v| v) {
        return Ok(None);
    }
    let image = |r: &Reference| Image::from_vec(r.width, r.height, 3, r.image.clone());
    let blended = occlusion_aware_poisson(
        &image(f),
        &image(g),
        &f.valid,
        &g.valid,
        Weights::Constant(1.0 - t),
    )
    .map_err(|e| e.to_string())?;
    let valid = f
        .valid
        .iter()
        .zip(&g.valid)
        .map(|(a, b)| *a || *b)
        .collect();
    Ok(Some(PseudoTruth {
        image: blended.data,
        valid,
    }))
}

impl LossTerm for VirtualViewTerm {
    fn name(&self) -> &str {
        self.config.variant.name()
    }

    fn loss(&mut self, ctx: &LossContext<'_>) -> Result<Option<Tensor<1>>, TrainError> {
        if !self.active(ctx.iteration) {
            return Ok(None);
        }
        let started = Instant::now();
        let result = self.virtual_loss(ctx);
        let mut stats = self.stats_mut();
        stats.seconds += started.elapsed().as_secs_f64();
        Ok(match result {
            Ok(Some((loss, coverage))) => {
                stats.mean_coverage +=
                    (coverage - stats.mean_coverage) / (stats.applied + 1) as f64;
                stats.applied += 1;
                Some(loss)
            }
            Ok(None) => {
                stats.empty += 1;
                None
            }
            Err(message) => {
                // A failure here must not pass unseen: it is counted and the first message kept
                // for the run's report.
                stats.empty += 1;
                stats.first_error.get_or_insert(message);
                None
            }
        })
    }
}

impl VirtualViewTerm {
    fn virtual_loss(&mut self, ctx: &LossContext<'_>) -> Result<Option<(Tensor<1>, f64)>, String> {
        if self.config.variant.uses_references() {
            self.refresh(ctx)?;
        }
        let mut rng = StdRng::seed_from_u64(
            self.seed ^ (ctx.iteration as u64).wrapping_mul(0xA24B_AED4_963E_E407),
        );
        let Some(v) = sample_virtual(&self.cameras, &self.pairs, &mut rng) else {
            return Ok(None);
        };
        let out = ctx.render(&RenderCamera::from(&v.camera));
        let [h, w, _] = out.image.dims();
        let rgb = out.image.clone().slice([0..h, 0..w, 0..3]);
        let host = |c: usize| -> Result<Vec<f32>, String> {
            out.image
                .clone()
                .slice([0..h, 0..w, c..c + 1])
                .into_data()
                .try_to_vec::<f32>()
                .map_err(|e| format!("reading the virtual render: {e:?}"))
        };
        let depth = surface_depth(&host(3)?, &host(4)?, self.config.reproject.min_alpha);
        self.variant_loss(rgb, &v, &depth)
    }
}

/// Alternative (b): an L2 pull of each Gaussian's diffuse colour towards the mean of its 50
/// nearest neighbours (found again every 100 iterations, and whenever densification changed the
/// set), weight 10, throughout training. The neighbours' mean is held constant in the gradient.
pub struct KnnColorTerm {
    options: KnnColorOptions,
    /// The last search's `(period, Gaussian count)` and its neighbours, row by row (`[n·k]`),
    /// on the compute device.
    found: Option<((usize, usize), Tensor<1, Int>)>,
}

impl KnnColorTerm {
    pub fn new(options: KnnColorOptions) -> Self {
        Self {
            options,
            found: None,
        }
    }

    /// The `k` nearest other Gaussians of each Gaussian, row by row.
    fn find(&self, means: &[[f32; 3]]) -> Vec<i64> {
        let k = self
            .options
            .neighbours
            .min(means.len().saturating_sub(1))
            .max(1);
        let tree = PointTree::new(means);
        means
            .iter()
            .enumerate()
            .flat_map(|(i, p)| {
                let q = [p[0] as f64, p[1] as f64, p[2] as f64];
                let mut found: Vec<i64> = tree
                    .knn(&q, k + 1)
                    .into_iter()
                    .map(|(j, _)| j as i64)
                    .filter(|&j| j != i as i64)
                    .collect();
                found.resize(k, i as i64);
                found
            })
            .collect()
    }
}

impl LossTerm for KnnColorTerm {
    fn name(&self) -> &str {
        "knn-color"
    }

    fn loss(&mut self, ctx: &LossContext<'_>) -> Result<Option<Tensor<1>>, TrainError> {
        let n = ctx.len();
        if n < 2 {
            return Ok(None);
        }
        let period = (ctx.iteration - 1) / self.options.interval;
        let dc = ctx
            .gaussians
            .sh
            .clone()
            .slice([0..n, 0..1, 0..3])
            .reshape([n, 3]);
        let index = match &self.found {
            Some((key, index)) if *key == (period, n) => index.clone(),
            _ => {
                let means: Vec<[f32; 3]> = ctx
                    .model()?
                    .means
                    .chunks_exact(3)
                    .map(|p| [p[0], p[1], p[2]])
                    .collect();
                let found = self.find(&means);
                let len = found.len();
                let index =
                    Tensor::<1, Int>::from_data(TensorData::new(found, [len]), &dc.device());
                self.found = Some(((period, n), index.clone()));
                index
            }
        };
        let k = index.dims()[0] / n;
        let mean = dc
            .clone()
            .select(0, index)
            .reshape([n, k, 3])
            .mean_dim(1)
            .reshape([n, 3])
            .detach();
        let loss = (dc - mean).powi_scalar(2).sum_dim(1).mean();
        Ok(Some(loss * self.options.weight))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn term(iterations: usize) -> VirtualViewTerm {
        VirtualViewTerm::new(
            FusionConfig::default(),
            Vec::new(),
            Vec::new(),
            &TrainConfig::sparse_view(iterations),
        )
    }

    #[test]
    fn the_term_pauses_after_an_opacity_reset_and_remeshes_once_recovered() {
        // 2000 iterations: start at 400, every 3rd; opacities reset at 1000 (densifying until 1200).
        let t = term(2000);
        assert_eq!(t.resets, vec![1000]);
        assert!(!t.active(399) && t.active(400) && !t.active(401) && t.active(403));
        assert!(t.active(997) && !t.active(1003) && !t.active(1099));
        assert!((1101..1104).any(|i| t.active(i)));
        assert_eq!(t.mesh_source(400), 0);
        assert_eq!(t.mesh_source(501), 500);
        assert_eq!(t.mesh_source(1101), 1100);
        assert_eq!(t.mesh_source(1500), 1100);
        assert_eq!(t.mesh_source(1501), 1500);
        // 1000 iterations: no reset, refreshes every 500.
        let t = term(1000);
        assert!(t.resets.is_empty());
        assert_eq!(t.mesh_source(1000), 500);
    }
}
