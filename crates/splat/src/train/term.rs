//! The interface of an extra loss term: what it sees of an iteration ([`LossContext`]) and what
//! it returns ([`LossTerm`]). The fusion method, the surface start's depth and the geometry
//! regularisers are each one such term.

use std::cell::OnceCell;

use burn::tensor::Tensor;
use fewview_optim::ReadbackError;

use super::appearance::Affine;
use super::state::TrainError;
use super::view::TrainView;
use crate::model::GaussianModel;
use crate::op::{GaussianTensors, RenderTensors, RenderView, render};
use crate::raster::{RenderCamera, RenderSettings};

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
    /// The photometric render of this iteration (with the dropout of [`super::dropout`] when
    /// the run drops; `gaussians` are all of them).
    pub render: &'a RenderTensors,
    /// The training photos' colour transforms, when the run learns them (by view index).
    pub appearance: &'a [Affine],
    pub(super) host: HostModel<'a>,
}

/// The parameters on the host: at hand when training keeps them there, read back from the
/// device on first use when it does not.
pub(super) enum HostModel<'a> {
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
