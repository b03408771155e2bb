//! Photometric losses as Burn tensors: L1 and the structural-similarity term of 3DGS,
//! `L = (1 − λ) L1 + λ (1 − SSIM)` with λ = 0.2 (3DGS Eq. 7).
//!
//! SSIM comes from `fewview-metrics` (one implementation for the metric and the loss) through a
//! custom op whose backward is that crate's exact SSIM gradient.

use std::cell::RefCell;

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Dispatch, Flex, TensorMetadata, backend_extension};
use burn::tensor::module::conv2d;
use burn::tensor::ops::ConvOptions;
use burn::tensor::{Shape, Tensor, TensorData};
use fewview_metrics::ssim::{SsimBorder, SsimOptions, SsimWorkspace};
use fewview_optim::flex_f32;
use fewview_scene::Image;

/// Mean SSIM of two `[H, W, C]` images as a differentiable op (gradient to the first argument
/// only; the target is treated as a constant).
#[backend_extension(Flex, Autodiff)]
pub trait SsimBackend: Backend {
    fn ssim_mean(
        rendered: FloatTensor<Self>,
        target: FloatTensor<Self>,
        opts: SsimOptions,
    ) -> FloatTensor<Self>;
}

/// The non-dispatched half: value (and, when asked, the gradient kept for the backward pass).
pub trait SsimKernels: Backend {
    fn ssim_forward(
        rendered: &FloatTensor<Self>,
        target: &FloatTensor<Self>,
        opts: &SsimOptions,
        want_grad: bool,
    ) -> (FloatTensor<Self>, Option<SsimGrad>);

    /// `upstream · ∂SSIM/∂rendered`.
    fn ssim_backward(grad: &SsimGrad, upstream: FloatTensor<Self>) -> FloatTensor<Self>;
}

/// The SSIM gradient with respect to the rendered image, computed in the forward pass.
#[derive(Clone, Debug)]
pub struct SsimGrad {
    pub values: std::sync::Arc<Vec<f32>>,
    pub shape: Shape,
}

thread_local! {
    static WORKSPACE: RefCell<SsimWorkspace> = RefCell::new(SsimWorkspace::new());
}

fn to_image(t: &FlexTensor) -> Image {
    let shape = t.shape();
    let dims = shape.dims::<3>();
    Image::from_vec(dims[1], dims[0], dims[2], flex_f32(t).into_owned())
}

impl SsimKernels for Flex {
    fn ssim_forward(
        rendered: &FlexTensor,
        target: &FlexTensor,
        opts: &SsimOptions,
        want_grad: bool,
    ) -> (FlexTensor, Option<SsimGrad>) {
        let (a, b) = (to_image(rendered), to_image(target));
        let (value, grad) = WORKSPACE.with(|ws| {
            let mut ws = ws.borrow_mut();
            match ws.value_and_grad(&a, &b, None, opts) {
                Ok((v, g)) => (v, want_grad.then(|| g.to_vec())),
                // Shapes are checked by `ssim_loss`; a failure here means NaN-free garbage in,
                // which the trainer reports through the loss value.
                Err(_) => (f64::NAN, None),
            }
        });
        let out = FlexTensor::from_data(TensorData::new(vec![value as f32], [1]));
        let grad = grad.map(|g| SsimGrad {
            values: std::sync::Arc::new(g),
            shape: rendered.shape(),
        });
        (out, grad)
    }

    fn ssim_backward(grad: &SsimGrad, upstream: FlexTensor) -> FlexTensor {
        let u = *flex_f32(&upstream)
            .first()
            .expect("the upstream gradient of the scalar SSIM has one value");
        let data: Vec<f32> = grad.values.iter().map(|g| g * u).collect();
        FlexTensor::from_data(TensorData::new(data, grad.shape.clone()))
    }
}

impl SsimBackend for Flex {
    fn ssim_mean(rendered: FlexTensor, target: FlexTensor, opts: SsimOptions) -> FlexTensor {
        Self::ssim_forward(&rendered, &target, &opts, false).0
    }
}

#[derive(Debug)]
struct SsimBackwardStep;

impl<B: SsimKernels> Backward<B, 2> for SsimBackwardStep {
    type State = SsimGrad;

    fn backward(
        self,
        ops: Ops<Self::State, 2>,
        grads: &mut Gradients,
        _checkpointer: &mut Checkpointer,
    ) {
        let upstream = grads.consume::<B>(&ops.node);
        let [rendered, _target] = ops.parents;
        if let Some(node) = rendered {
            grads.register::<B>(node.id, B::ssim_backward(&ops.state, upstream));
        }
    }
}

impl<B: SsimKernels, C: CheckpointStrategy> SsimBackend for Autodiff<B, C> {
    fn ssim_mean(
        rendered: FloatTensor<Self>,
        target: FloatTensor<Self>,
        opts: SsimOptions,
    ) -> FloatTensor<Self> {
        let nodes = [rendered.node(), target.node()];
        let (r, t) = (rendered.into_primitive(), target.into_primitive());
        match SsimBackwardStep
            .prepare::<C>(nodes)
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                let (value, grad) = B::ssim_forward(&r, &t, &opts, true);
                let grad = grad.unwrap_or_else(|| SsimGrad {
                    values: std::sync::Arc::new(vec![0.0; r.shape().num_elements()]),
                    shape: r.shape(),
                });
                prep.finish(grad, value)
            }
            OpsKind::UnTracked(prep) => prep.finish(B::ssim_forward(&r, &t, &opts, false).0),
        }
    }
}

/// Mean SSIM of `[H, W, C]` tensors (`opts` chooses the metric or the 3DGS-loss border variant).
///
/// On the CPU this is the custom op above (the metrics crate's exact gradient); on other
/// devices, the training-loss variant composed from Burn convolutions ([`ssim_mean_composed`]),
/// differentiated by Burn.
pub fn ssim_mean(rendered: Tensor<3>, target: Tensor<3>, opts: SsimOptions) -> Tensor<1> {
    if rendered.device() != burn::tensor::Device::flex() && opts.border == SsimBorder::ZeroSame {
        return ssim_mean_composed(rendered, target, &opts);
    }
    Tensor::from_dispatch(<Dispatch as SsimBackend>::ssim_mean(
        rendered.into_dispatch(),
        target.into_dispatch(),
        opts,
    ))
}

/// The zero-padded ("same") separable Gaussian filter of each channel of `x` (`[1, C, H, W]`).
fn gaussian_filter(x: Tensor<4>, opts: &SsimOptions) -> Tensor<4> {
    let [_, c, _, _] = x.dims();
    let r = opts.radius();
    let taps = 2 * r + 1;
    let window: Vec<f32> = (0..taps)
        .map(|i| {
            let k = i as f64 - r as f64;
            (-k * k / (2.0 * opts.sigma * opts.sigma)).exp()
        })
        .collect::<Vec<f64>>()
        .iter()
        .map(|&w| w as f32)
        .collect();
    let sum: f32 = window.iter().sum();
    let weights: Vec<f32> = (0..c)
        .flat_map(|_| window.iter().map(move |w| w / sum))
        .collect();
    let device = x.device();
    let row = Tensor::<4>::from_data(TensorData::new(weights.clone(), [c, 1, 1, taps]), &device);
    let col = Tensor::<4>::from_data(TensorData::new(weights, [c, 1, taps, 1]), &device);
    let opt = |pad: [usize; 2]| ConvOptions::new([1, 1], pad, [1, 1], c);
    let x = conv2d(x, row, None, opt([0, r]));
    conv2d(x, col, None, opt([r, 0]))
}

/// Mean SSIM with zero padding over all pixels (the 3DGS training loss, [`SsimBorder::ZeroSame`])
/// from Burn convolutions: the same definition as `fewview_metrics::ssim`, on any device, with
/// Burn's autodiff for the gradient (to both images).
pub fn ssim_mean_composed(rendered: Tensor<3>, target: Tensor<3>, opts: &SsimOptions) -> Tensor<1> {
    let to_nchw = |t: Tensor<3>| t.permute([2, 0, 1]).unsqueeze::<4>();
    let (x, y) = (to_nchw(rendered), to_nchw(target.detach()));
    let c1 = ((opts.k1 * opts.data_range).powi(2)) as f32;
    let c2 = ((opts.k2 * opts.data_range).powi(2)) as f32;
    let mu_x = gaussian_filter(x.clone(), opts);
    let mu_y = gaussian_filter(y.clone(), opts);
    let xx = gaussian_filter(x.clone() * x.clone(), opts) - mu_x.clone() * mu_x.clone();
    let yy = gaussian_filter(y.clone() * y.clone(), opts) - mu_y.clone() * mu_y.clone();
    let xy = gaussian_filter(x * y, opts) - mu_x.clone() * mu_y.clone();
    let a1 = mu_x.clone() * mu_y.clone() * 2.0 + c1;
    let a2 = xy * 2.0 + c2;
    let b1 = mu_x.clone() * mu_x + mu_y.clone() * mu_y + c1;
    let b2 = xx + yy + c2;
    ((a1 * a2) / (b1 * b2)).mean()
}

/// The 3DGS photometric loss `(1 − λ)·L1 + λ·(1 − SSIM)` (Eq. 7 of Kerbl et al., λ = 0.2),
/// with SSIM in its training-loss variant (zero padding, mean over all pixels).
pub fn photometric_loss(rendered: Tensor<3>, target: Tensor<3>, lambda_dssim: f32) -> Tensor<1> {
    let l1 = (rendered.clone() - target.clone()).abs().mean();
    let ssim = ssim_mean(rendered, target, SsimOptions::training_loss());
    l1 * (1.0 - lambda_dssim) + (ssim.neg() + 1.0) * lambda_dssim
}

#[cfg(test)]
mod tests {
    use burn::tensor::Device;

    use super::*;

    /// Two `h×w` RGB test images, their SSIM by `ssim` on the CPU backend and the gradient of
    /// `grad_scale ×` that SSIM, beside the metrics crate's value and exact gradient for the same
    /// pair: `(got, want, got_grad, want_grad)`.
    fn against_metrics(
        (h, w): (usize, usize),
        ssim: impl Fn(Tensor<3>, Tensor<3>, &SsimOptions) -> Tensor<1>,
        grad_scale: f32,
    ) -> (f64, f64, Vec<f32>, Vec<f32>) {
        let a: Vec<f32> = (0..h * w * 3)
            .map(|i| ((i * 7919) % 101) as f32 / 100.0)
            .collect();
        let b: Vec<f32> = (0..h * w * 3)
            .map(|i| ((i * 104_729) % 97) as f32 / 96.0)
            .collect();
        let device = Device::flex().autodiff();
        let ta =
            Tensor::<3>::from_data(TensorData::new(a.clone(), [h, w, 3]), &device).require_grad();
        let tb = Tensor::<3>::from_data(TensorData::new(b.clone(), [h, w, 3]), &device);
        let opts = SsimOptions::training_loss();
        let s = ssim(ta.clone(), tb, &opts);
        let grads = (s.clone() * grad_scale).backward();
        let (ia, ib) = (Image::from_vec(w, h, 3, a), Image::from_vec(w, h, 3, b));
        let (want, want_grad) = fewview_metrics::ssim::ssim_with_grad(&ia, &ib, &opts).unwrap();
        let got = s.into_data().try_to_vec::<f32>().unwrap()[0];
        let got_grad = ta.grad(&grads).unwrap().into_data().try_to_vec().unwrap();
        (got as f64, want, got_grad, want_grad)
    }

    #[test]
    fn ssim_op_value_and_gradient_match_the_metrics_crate() {
        // The loss is scaled by 3 so that the op's backward must use the incoming gradient.
        let (got, want, g, want_grad) =
            against_metrics((23, 31), |a, b, opts| ssim_mean(a, b, *opts), 3.0);
        assert!((got - want).abs() < 1e-6, "{got} vs {want}");
        for (x, y) in g.iter().zip(&want_grad) {
            assert!((x - 3.0 * y).abs() < 1e-7, "{x} vs {}", 3.0 * y);
        }
    }

    /// The convolution form used off the CPU, run on the CPU backend: the metrics crate's value
    /// and exact gradient are the reference.
    #[test]
    fn composed_ssim_matches_the_metrics_crate() {
        let (got, want, g, want_grad) = against_metrics((19, 26), ssim_mean_composed, 1.0);
        assert!((got - want).abs() < 1e-5, "{got} vs {want}");
        let scale = want_grad.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        for (x, y) in g.iter().zip(&want_grad) {
            assert!((x - y).abs() < 1e-3 * scale, "{x} vs {y}");
        }
    }

    #[test]
    fn photometric_loss_of_identical_images_is_zero() {
        let device = Device::flex().autodiff();
        let a = Tensor::<3>::from_data(
            TensorData::new(
                (0..4 * 5 * 3).map(|i| i as f32 / 60.0).collect::<Vec<_>>(),
                [4, 5, 3],
            ),
            &device,
        );
        let l = photometric_loss(a.clone(), a, 0.2)
            .into_data()
            .try_to_vec::<f32>()
            .unwrap()[0];
        assert!(l.abs() < 1e-6, "{l}");
    }
}
