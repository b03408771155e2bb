//! One source view's Gaussian parameter maps, `[C, H, W]` tensors on one device: what
//! [`super::pixel_gaussians`] reads at the foreground pixels.
//!
//! They come from the network's heads ([`PixelMaps::from_heads`]) or are given directly, e.g.
//! the capture's exact depth in place of the depth head (the method's oracle-depth ceiling) or
//! fixed scales in tests.

use burn::tensor::Tensor;

use crate::error::{HumanError, Result};
use crate::net::HeadOutputs;

/// Gaussian parameters per pixel of one source view.
#[derive(Clone, Debug)]
pub struct PixelMaps {
    /// Metric z-depth in the source camera (metres), `[1, H, W]`.
    pub depth: Tensor<3>,
    /// Standard deviations along the Gaussian's own axes (metres, positive), `[3, H, W]`.
    pub scale: Tensor<3>,
    /// Unit quaternion, w first, in the source camera's frame, `[4, H, W]`.
    pub rotation: Tensor<3>,
    /// Opacity in `(0, 1)`, `[1, H, W]`.
    pub opacity: Tensor<3>,
}

impl PixelMaps {
    /// The maps of batch item `index` of the heads' outputs, depth made metric over the
    /// `near`/`far` range the depth head is normalised to and opacity the render opacity.
    pub fn from_heads(heads: &HeadOutputs, index: usize, near: f32, far: f32) -> Result<Self> {
        let [n, _, _, _] = heads.depth.dims();
        if index >= n {
            let m = format!("batch item {index} of a batch of {n}");
            return Err(HumanError::argument("pixel maps", m));
        }
        if !(near > 0.0 && far > near) {
            let m = format!("near {near} and far {far} must satisfy 0 < near < far");
            return Err(HumanError::argument("pixel maps", m));
        }
        Ok(Self {
            depth: item(heads.metric_depth(near, far), index),
            scale: item(heads.scale.clone(), index),
            rotation: item(heads.rotation.clone(), index),
            opacity: item(heads.render_opacity(), index),
        })
    }

    /// `(width, height)` of the depth map.
    pub fn size(&self) -> (usize, usize) {
        let [_, h, w] = self.depth.dims();
        (w, h)
    }

    /// An error unless every map is `[C, H, W]` with its channel count and the depth's size.
    pub fn check(&self) -> Result<()> {
        let (w, h) = self.size();
        let maps = [
            ("depth", &self.depth, 1),
            ("scale", &self.scale, 3),
            ("rotation", &self.rotation, 4),
            ("opacity", &self.opacity, 1),
        ];
        for (name, t, c) in maps {
            if t.dims() != [c, h, w] {
                let m = format!(
                    "{name} is {:?}, expected {:?} (C, H, W)",
                    t.dims(),
                    [c, h, w]
                );
                return Err(HumanError::argument("pixel maps", m));
            }
        }
        Ok(())
    }
}

/// Batch item `index` of `[N, C, H, W]` as `[C, H, W]`.
fn item(t: Tensor<4>, index: usize) -> Tensor<3> {
    let [_, c, h, w] = t.dims();
    t.narrow(0, index, 1).reshape([c, h, w])
}
