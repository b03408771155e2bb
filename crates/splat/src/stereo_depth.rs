//! Depth from our own stereo as a training loss: each training view's render is pulled to the
//! depth the stereo start accepted at its pixels, weighted by the pixel's tier of the fusion
//! paper's hierarchy (§2: R^c consistent between the views of a pair, R^o seen by both but not
//! consistent, R^s seen by one).
//!
//! Sparse-view methods such as FSGS ("FSGS: Real-Time Few-shot View Synthesis using Gaussian
//! Splatting") and MVPGS add depth from a monocular network, whose weights cannot be fetched
//! here; the stereo start's R^c depth is a metric depth of the scene itself (its accuracy is in
//! docs/experiments.md). The loss is the relative L1 of the surface start's depth term
//! ([`crate::surface_start::SurfaceDepthTerm`]), which follows DN-Splatter, with a weight per
//! pixel:
//!
//! `L = λ · Σ_p w_p |D̂_p − D_p| / D_p / Σ_p w_p`
//!
//! where `D̂` is the rendered depth `Σ wᵢ zᵢ` and `w_p` is [`TIER_WEIGHTS`] of the pixel's tier.

use burn::tensor::{Tensor, TensorData};
use fewview_geom::stereo::hierarchy::{HierarchicalCloud, Region};

use crate::train::{LossContext, LossTerm, TrainError};

/// The weight of a pixel of each tier, in [`Region::ALL`]'s order: R^c counts fully, R^o half
/// (its depth was seen from both views but not confirmed), R^s not at all (one view's depth,
/// unchecked, is where stereo's floaters come from).
pub const TIER_WEIGHTS: [f32; 3] = [1.0, 0.5, 0.0];

/// The stereo depth loss on the training views (see the module docs).
#[derive(Clone)]
pub struct StereoDepthTerm {
    /// Per training view: the stereo depth and the pixel's weight, 0 where there is none.
    targets: Vec<(Vec<f32>, Vec<f32>)>,
    weight: f32,
}

impl StereoDepthTerm {
    /// The term from a stereo start's cloud (its per-view depths and tiers, in training-view
    /// order) with weight `weight`.
    pub fn new(cloud: &HierarchicalCloud, weight: f32) -> Self {
        let targets = cloud
            .pixel_depths
            .iter()
            .zip(&cloud.pixel_regions)
            .map(|(depths, regions)| {
                let weights = depths
                    .iter()
                    .zip(regions)
                    .map(|(&d, &r)| pixel_weight(d, r))
                    .collect();
                (depths.clone(), weights)
            })
            .collect();
        Self { targets, weight }
    }
}

/// The weight of a stereo pixel of depth `depth` (0: none) and tier `region`: its tier's
/// [`TIER_WEIGHTS`] where it has depth, 0 elsewhere.
pub fn pixel_weight(depth: f32, region: Option<Region>) -> f32 {
    match region {
        Some(r) if depth > 0.0 => {
            let tier = Region::ALL.iter().position(|x| *x == r);
            TIER_WEIGHTS[tier.expect("every region is in ALL")]
        }
        _ => 0.0,
    }
}

/// `Σ w |rendered − d| / d / Σ w` over the pixels with `w > 0` and `d > 0` (`rendered` is
/// `[H, W, 1]`; `depth` and `weights` row-major `H·W`); `None` when no pixel counts.
pub fn weighted_relative_depth_l1(
    rendered: Tensor<3>,
    depth: &[f32],
    weights: &[f32],
) -> Option<Tensor<1>> {
    let [h, w, _] = rendered.dims();
    assert_eq!(depth.len(), h * w, "one depth per pixel");
    assert_eq!(weights.len(), h * w, "one weight per pixel");
    let scale: Vec<f32> = depth
        .iter()
        .zip(weights)
        .map(|(&d, &w)| if d > 0.0 && w > 0.0 { w / d } else { 0.0 })
        .collect();
    let total: f64 = depth
        .iter()
        .zip(weights)
        .filter(|(d, w)| **d > 0.0 && **w > 0.0)
        .map(|(_, w)| *w as f64)
        .sum();
    if total == 0.0 {
        return None;
    }
    let device = rendered.device();
    let target = Tensor::<3>::from_data(TensorData::new(depth.to_vec(), [h, w, 1]), &device);
    let scale = Tensor::<3>::from_data(TensorData::new(scale, [h, w, 1]), &device);
    Some(((rendered - target).abs() * scale).sum() / total as f32)
}

impl LossTerm for StereoDepthTerm {
    fn name(&self) -> &str {
        "stereo-depth"
    }

    fn loss(&mut self, ctx: &LossContext<'_>) -> Result<Option<Tensor<1>>, TrainError> {
        let Some((depth, weights)) = self.targets.get(ctx.view_index) else {
            return Ok(None);
        };
        depth_loss_of_render(ctx, "stereo", depth, weights, self.weight)
    }
}

/// `weight ×` [`weighted_relative_depth_l1`] of the iteration's rendered depth against one
/// view's target; a target of another size than the render is an error naming `what`.
pub fn depth_loss_of_render(
    ctx: &LossContext<'_>,
    what: &str,
    depth: &[f32],
    weights: &[f32],
    weight: f32,
) -> Result<Option<Tensor<1>>, TrainError> {
    let [h, w, _] = ctx.render.image.dims();
    if depth.len() != h * w || weights.len() != h * w {
        return Err(TrainError::Invalid(format!(
            "{what} depth of {} pixels for a {w}×{h} render",
            depth.len()
        )));
    }
    let rendered = ctx.render.image.clone().slice([0..h, 0..w, 3..4]);
    Ok(weighted_relative_depth_l1(rendered, depth, weights).map(|l| l * weight))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::GaussianModel;
    use crate::op::GaussianTensors;
    use burn::tensor::Device;

    /// Two overlapping splats in front of `camera()`, the far one partly behind the near one.
    fn splats() -> GaussianModel {
        let mut m = GaussianModel::new(0);
        m.push_isotropic([0.05, 0.02, 2.6], 0.25, [0.8, 0.3, 0.2], 0.6);
        m.push_isotropic([-0.1, -0.05, 3.4], 0.35, [0.2, 0.5, 0.9], 0.7);
        m
    }

    /// A target of 3.0, weighted 1, ½ and 0 in three bands of rows of a window where both
    /// splats are well inside their footprints: outside it a splat's edge (its 3σ box, the skip
    /// of α < 1/255) moves in steps that finite differences cannot follow.
    fn target() -> (Vec<f32>, Vec<f32>) {
        let camera = crate::raster::tests::camera();
        let (w, h) = (camera.width, camera.height);
        let depth = vec![3.0; w * h];
        let weights = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                if (15..26).contains(&x) && (10..19).contains(&y) {
                    TIER_WEIGHTS[(y - 10) / 3]
                } else {
                    0.0
                }
            })
            .collect();
        (depth, weights)
    }

    fn loss_of(g: &GaussianTensors) -> Tensor<1> {
        let out = crate::raster::tests::render_from_camera(g);
        let [h, w, _] = out.image.dims();
        let (depth, weights) = target();
        weighted_relative_depth_l1(out.image.slice([0..h, 0..w, 3..4]), &depth, &weights).unwrap()
    }

    fn value(t: Tensor<1>) -> f64 {
        fewview_optim::f32_values(t, "loss").unwrap()[0] as f64
    }

    /// The gradient of the loss through the rasterizer to the splats' depths, positions across
    /// the image and opacities, against central differences of the loss itself.
    #[test]
    fn the_gradient_matches_finite_differences() {
        let device = Device::flex().autodiff();
        let model = splats();
        let g = model.to_tensors(&device, true);
        let grads = loss_of(&g).backward();
        let means = g.means.grad(&grads).unwrap().into_data();
        let means: Vec<f32> = means.try_to_vec().unwrap();
        let opacity: Vec<f32> = g
            .opacity_logits
            .grad(&grads)
            .unwrap()
            .into_data()
            .try_to_vec()
            .unwrap();
        let plain = Device::flex();
        let at = |m: &GaussianModel| value(loss_of(&m.to_tensors(&plain, false)));
        let h = 1e-3f32;
        for k in 0..2 {
            for axis in 0..3 {
                let (mut up, mut down) = (model.clone(), model.clone());
                up.means[3 * k + axis] += h;
                down.means[3 * k + axis] -= h;
                let fd = (at(&up) - at(&down)) / (2.0 * h as f64);
                let an = means[3 * k + axis] as f64;
                assert!(
                    (fd - an).abs() < 0.02 * fd.abs().max(an.abs()) + 1e-4,
                    "splat {k} axis {axis}: analytic {an} vs differences {fd}"
                );
            }
            let (mut up, mut down) = (model.clone(), model.clone());
            up.opacity_logits[k] += h;
            down.opacity_logits[k] -= h;
            let fd = (at(&up) - at(&down)) / (2.0 * h as f64);
            let an = opacity[k] as f64;
            assert!(
                (fd - an).abs() < 0.02 * fd.abs().max(an.abs()) + 1e-4,
                "splat {k} opacity: analytic {an} vs differences {fd}"
            );
        }
        assert!(means[2].abs() > 1e-3, "the depth pulls: {means:?}");
    }

    /// The weighted mean, by hand, on four pixels.
    #[test]
    fn the_loss_is_the_weighted_mean_relative_distance() {
        let device = Device::flex();
        let rendered = Tensor::<3>::from_data(
            TensorData::new(vec![1.0f32, 3.0, 2.5, 9.0], [2, 2, 1]),
            &device,
        );
        // Targets 2, 2, none, 10 with weights 1, ½, 1, 0: (½ + ½·½) / 1.5.
        let loss = weighted_relative_depth_l1(
            rendered.clone(),
            &[2.0, 2.0, 0.0, 10.0],
            &[1.0, 0.5, 1.0, 0.0],
        );
        assert!((value(loss.unwrap()) - 0.75 / 1.5).abs() < 1e-6);
        assert!(weighted_relative_depth_l1(rendered, &[2.0; 4], &[0.0; 4]).is_none());
    }
}
