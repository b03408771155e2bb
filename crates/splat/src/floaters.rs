//! Floater control: a Gaussian that only one training view sees, and that sits in front of the
//! depth stereo confirmed at its pixel in that view, is a floater — it paints that view's colour
//! onto empty space, which any other view sees as a smear. Its opacity is pulled down by a loss
//! (`λ · mean σ(oᵢ)` over the floaters of the iteration), so that densification's opacity prune
//! removes it, while a Gaussian that more views constrain, or that lies on or behind the stereo
//! surface, is left alone.
//!
//! The stereo depth is the stereo start's accepted depth at R^c and R^o pixels (the fusion
//! paper's hierarchy, §2); R^s pixels, seen by one view of a pair, are not trusted to call
//! anything a floater.

use burn::tensor::{Bool, Tensor, TensorData};
use fewview_geom::stereo::hierarchy::{HierarchicalCloud, Region};
use fewview_scene::Camera;
use nalgebra::Vector3;

use crate::train::{LossContext, LossTerm, TrainError};

/// How far in front of the stereo depth (a fraction of it) a Gaussian must be to count.
pub const FLOATER_MARGIN: f32 = 0.1;

/// One training view as the floater test sees it.
#[derive(Clone)]
struct ViewDepth {
    camera: Camera,
    /// The stereo depth at R^c and R^o pixels, 0 elsewhere (row-major).
    depth: Vec<f32>,
}

/// The floater loss (see the module docs).
#[derive(Clone)]
pub struct FloaterTerm {
    views: Vec<ViewDepth>,
    weight: f32,
}

impl FloaterTerm {
    /// The term for training views with these cameras (in training order) and the stereo
    /// start's cloud of them.
    pub fn new(cameras: Vec<Camera>, cloud: &HierarchicalCloud, weight: f32) -> Self {
        let views = cameras
            .into_iter()
            .zip(cloud.pixel_depths.iter().zip(&cloud.pixel_regions))
            .map(|(camera, (depths, regions))| ViewDepth {
                camera,
                depth: depths
                    .iter()
                    .zip(regions)
                    .map(|(&d, r)| match r {
                        Some(Region::Consistent | Region::Overlap) => d,
                        _ => 0.0,
                    })
                    .collect(),
            })
            .collect();
        Self { views, weight }
    }

    /// Which of the Gaussians at `means` (`N×3`) are floaters.
    pub fn floaters(&self, means: &[f32]) -> Vec<bool> {
        means
            .chunks_exact(3)
            .map(|p| {
                let p = Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
                let mut seen = self
                    .views
                    .iter()
                    .filter_map(|v| v.camera.pixel_of(&p).map(|px| (v, px)));
                match (seen.next(), seen.next()) {
                    (Some((v, (index, z))), None) => {
                        let d = v.depth[index];
                        d > 0.0 && (z as f32) < (1.0 - FLOATER_MARGIN) * d
                    }
                    _ => false,
                }
            })
            .collect()
    }
}

impl LossTerm for FloaterTerm {
    fn name(&self) -> &str {
        "floaters"
    }

    fn loss(&mut self, ctx: &LossContext<'_>) -> Result<Option<Tensor<1>>, TrainError> {
        let model = ctx.model()?;
        let floaters = self.floaters(&model.means);
        let count = floaters.iter().filter(|f| **f).count();
        if count == 0 {
            return Ok(None);
        }
        let n = floaters.len();
        let device = ctx.gaussians.opacity_logits.device();
        let mask = Tensor::<1, Bool>::from_data(TensorData::new(floaters, [n]), &device);
        let opacity = burn::tensor::activation::sigmoid(ctx.gaussians.opacity_logits.clone());
        let zeros = Tensor::<1>::zeros([n], &device);
        let picked = zeros.mask_where(mask, opacity);
        Ok(Some(picked.sum() * (self.weight / count as f32)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fewview_scene::Intrinsics;

    /// Two cameras side by side looking down +z at a wall 4 away, each seeing its own half of
    /// the scene beyond what the other sees.
    fn term() -> FloaterTerm {
        let k = Intrinsics::centered(10.0, 20, 20);
        let camera = |x: f64| {
            Camera::look_at(
                k,
                Vector3::new(x, 0.0, 0.0),
                Vector3::new(x, 0.0, 4.0),
                -Vector3::y(),
            )
        };
        let wall = vec![4.0f32; 400];
        FloaterTerm {
            views: vec![
                ViewDepth {
                    camera: camera(0.0),
                    depth: wall.clone(),
                },
                ViewDepth {
                    camera: camera(3.0),
                    depth: wall,
                },
            ],
            weight: 1.0,
        }
    }

    #[test]
    fn only_single_view_gaussians_in_front_of_the_stereo_depth_are_floaters() {
        let t = term();
        let means = [
            -0.5, 0.0, 2.0, // seen by the first camera only, halfway to the wall: floater
            -1.5, 0.0, 3.9, // seen by the first only, within the margin of the wall: kept
            1.5, 0.0, 2.0, // seen by both cameras: kept
            -4.0, 0.0, 6.0, // seen by the first only, behind the wall: kept
            -9.0, 0.0, 2.0, // seen by none: kept
        ];
        assert_eq!(t.floaters(&means), vec![true, false, false, false, false]);
    }
}
