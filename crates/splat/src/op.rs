//! The rasterizer as a Burn custom operation with its own backward pass, so losses written with
//! Burn tensors compose with it and `loss.backward()` reaches every Gaussian parameter.
//!
//! [`SplatBackend`] is the backend extension (routed by Burn's runtime `Dispatch`); it is
//! implemented for the CPU `Flex` backend (host kernels in [`crate::raster`]) and for
//! `Autodiff<B>` over any backend with [`SplatKernels`]. A GPU twin implements `SplatKernels` (and
//! `SplatBackend`) for its backend behind the same op.

use std::any::Any;
use std::sync::Arc;

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{
    Autodiff, AutodiffBackend, Backend, Dispatch, ExtensionType, Flex, backend_extension,
};
use burn::tensor::{Shape, Tensor, TensorData};
use fewview_optim::flex_f32;

use crate::raster::render::{ForwardContext, OUT_CHANNELS, backward, forward};
use crate::raster::{GaussianRefs, RenderCamera, RenderSettings};

/// The Gaussian parameters of one render, pre-activation (Inria layout).
#[derive(ExtensionType)]
pub struct SplatInputs<B: Backend> {
    /// `[N, 3]`
    pub means: FloatTensor<B>,
    /// `[N, 3]`
    pub log_scales: FloatTensor<B>,
    /// `[N, 4]`, `(w, x, y, z)`, need not be normalised.
    pub quats: FloatTensor<B>,
    /// `[N]`
    pub opacity_logits: FloatTensor<B>,
    /// `[N, K, 3]`, K = (degree + 1)².
    pub sh: FloatTensor<B>,
    /// `[N, 2]` zeros. Not used by the forward pass: its gradient is the loss gradient with
    /// respect to each projected centre in NDC units (the reference code's `means2D` trick), which
    /// densification accumulates.
    pub means2d: FloatTensor<B>,
}

/// What a render returns.
#[derive(ExtensionType)]
pub struct SplatOutput<B: Backend> {
    /// `[H, W, 5]`: R, G, B (+ background), expected depth `Σ wᵢ zᵢ`, alpha `1 − T`.
    pub image: FloatTensor<B>,
    /// `[N]`: screen radius in pixels (3σ), 0 where the Gaussian is not visible. Constant
    /// (no gradient).
    pub radii: FloatTensor<B>,
}

/// Camera and options of one render.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderView {
    pub camera: RenderCamera,
    pub settings: RenderSettings,
}

/// The differentiable Gaussian rasterizer as a Burn backend extension.
#[backend_extension(Flex, Cube: cfg(feature = "gpu"), Autodiff)]
pub trait SplatBackend: Backend {
    fn splat_render(
        #[extension_type] inputs: SplatInputs<Self>,
        view: RenderView,
    ) -> SplatOutput<Self>;
}

/// Saved forward state of one render, opaque to Burn (each backend keeps what its backward needs).
#[derive(Clone)]
pub struct SplatState(pub Arc<dyn Any + Send + Sync>);

impl std::fmt::Debug for SplatState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SplatState")
    }
}

/// Forward and backward kernels of a backend (the non-dispatched half of the op).
pub trait SplatKernels: Backend {
    /// Renders and returns `(image [H,W,5], radii [N], state for the backward pass)`.
    fn splat_forward(
        inputs: SplatInputs<Self>,
        view: &RenderView,
    ) -> (FloatTensor<Self>, FloatTensor<Self>, SplatState);

    /// Gradients of `means, log_scales, quats, opacity_logits, sh, means2d` given the gradient
    /// of the image.
    fn splat_backward(state: &SplatState, grad_image: FloatTensor<Self>) -> [FloatTensor<Self>; 6];
}

/// Host copies of the parameters and the rasterizer context, kept for the backward pass.
struct CpuState {
    params: [Vec<f32>; 5],
    sh_coeffs: usize,
    ctx: ForwardContext<f32>,
    /// Shapes of the six inputs, so gradients come back with the same shapes.
    shapes: [Shape; 6],
}

impl CpuState {
    fn refs(&self) -> GaussianRefs<'_, f32> {
        GaussianRefs {
            means: &self.params[0],
            log_scales: &self.params[1],
            quats: &self.params[2],
            opacity_logits: &self.params[3],
            sh: &self.params[4],
            sh_coeffs: self.sh_coeffs,
        }
    }
}

fn flex(data: Vec<f32>, shape: Shape) -> FlexTensor {
    FlexTensor::from_data(TensorData::new(data, shape))
}

impl SplatKernels for Flex {
    fn splat_forward(
        inputs: SplatInputs<Self>,
        view: &RenderView,
    ) -> (FlexTensor, FlexTensor, SplatState) {
        let tensors = [
            &inputs.means,
            &inputs.log_scales,
            &inputs.quats,
            &inputs.opacity_logits,
            &inputs.sh,
            &inputs.means2d,
        ];
        let shapes = tensors.map(burn::backend::TensorMetadata::shape);
        let n = shapes[3].num_elements();
        let sh_coeffs = if n == 0 {
            1
        } else {
            shapes[4].num_elements() / (n * 3)
        };
        let params = [0, 1, 2, 3, 4].map(|i| flex_f32(tensors[i]).into_owned());
        let state = {
            let refs = GaussianRefs {
                means: &params[0],
                log_scales: &params[1],
                quats: &params[2],
                opacity_logits: &params[3],
                sh: &params[4],
                sh_coeffs,
            };
            let (out, ctx) = forward(&refs, &view.camera, &view.settings);
            let (w, h) = (out.width, out.height);
            let image = flex(out.data, Shape::new([h, w, OUT_CHANNELS]));
            let radii = flex(out.radii, Shape::new([n]));
            (image, radii, ctx)
        };
        let (image, radii, ctx) = state;
        let saved = CpuState {
            params,
            sh_coeffs,
            ctx,
            shapes,
        };
        (image, radii, SplatState(Arc::new(saved)))
    }

    fn splat_backward(state: &SplatState, grad_image: FlexTensor) -> [FlexTensor; 6] {
        let s = state
            .0
            .downcast_ref::<CpuState>()
            .expect("Flex splat state comes from the Flex forward");
        let g = backward(&s.refs(), &s.ctx, &flex_f32(&grad_image));
        let sh = s.shapes.clone();
        let [s0, s1, s2, s3, s4, s5] = sh;
        [
            flex(g.means, s0),
            flex(g.log_scales, s1),
            flex(g.quats, s2),
            flex(g.opacity_logits, s3),
            flex(g.sh, s4),
            flex(g.means2d, s5),
        ]
    }
}

impl SplatBackend for Flex {
    fn splat_render(inputs: SplatInputs<Self>, view: RenderView) -> SplatOutput<Self> {
        let (image, radii, _) = Self::splat_forward(inputs, &view);
        SplatOutput { image, radii }
    }
}

#[cfg(feature = "gpu")]
mod cube {
    //! The op on Burn's cube backend (feature `gpu`): the kernels of [`crate::gpu`].
    use std::sync::Arc;

    use burn::backend::Cube;
    use burn_cubecl::tensor::CubeTensor;

    use super::{RenderView, SplatBackend, SplatInputs, SplatKernels, SplatOutput, SplatState};
    use crate::gpu::{self, GpuState};

    impl SplatKernels for Cube {
        fn splat_forward(
            inputs: SplatInputs<Self>,
            view: &RenderView,
        ) -> (CubeTensor, CubeTensor, SplatState) {
            let tensors = [
                inputs.means,
                inputs.log_scales,
                inputs.quats,
                inputs.opacity_logits,
                inputs.sh,
                inputs.means2d,
            ];
            let (image, radii, state) = gpu::forward(tensors, view);
            (image, radii, SplatState(Arc::new(state)))
        }

        fn splat_backward(state: &SplatState, grad_image: CubeTensor) -> [CubeTensor; 6] {
            let s = state
                .0
                .downcast_ref::<GpuState>()
                .expect("Cube splat state comes from the Cube forward");
            gpu::backward(s, grad_image)
        }
    }

    impl SplatBackend for Cube {
        fn splat_render(inputs: SplatInputs<Self>, view: RenderView) -> SplatOutput<Self> {
            let (image, radii, _) = Self::splat_forward(inputs, &view);
            SplatOutput { image, radii }
        }
    }
}

#[derive(Debug)]
struct SplatBackwardStep;

impl<B: SplatKernels> Backward<B, 6> for SplatBackwardStep {
    type State = SplatState;

    fn backward(
        self,
        ops: Ops<Self::State, 6>,
        grads: &mut Gradients,
        _checkpointer: &mut Checkpointer,
    ) {
        let grad_image = grads.consume::<B>(&ops.node);
        let g = B::splat_backward(&ops.state, grad_image);
        for (parent, grad) in ops.parents.into_iter().zip(g) {
            if let Some(node) = parent {
                grads.register::<B>(node.id, grad);
            }
        }
    }
}

impl<B: SplatKernels, C: CheckpointStrategy> SplatBackend for Autodiff<B, C> {
    fn splat_render(inputs: SplatInputs<Self>, view: RenderView) -> SplatOutput<Self> {
        let nodes = [
            inputs.means.node(),
            inputs.log_scales.node(),
            inputs.quats.node(),
            inputs.opacity_logits.node(),
            inputs.sh.node(),
            inputs.means2d.node(),
        ];
        let inner = SplatInputs::<B> {
            means: inputs.means.into_primitive(),
            log_scales: inputs.log_scales.into_primitive(),
            quats: inputs.quats.into_primitive(),
            opacity_logits: inputs.opacity_logits.into_primitive(),
            sh: inputs.sh.into_primitive(),
            means2d: inputs.means2d.into_primitive(),
        };
        let (image, radii, state) = B::splat_forward(inner, &view);
        let radii = <Self as AutodiffBackend>::from_inner(radii);
        let image = match SplatBackwardStep
            .prepare::<C>(nodes)
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => prep.finish(state, image),
            OpsKind::UnTracked(prep) => prep.finish(image),
        };
        SplatOutput { image, radii }
    }
}

/// Gaussian parameters as Burn tensors (see [`SplatInputs`] for shapes).
#[derive(Clone, Debug)]
pub struct GaussianTensors {
    pub means: Tensor<2>,
    pub log_scales: Tensor<2>,
    pub quats: Tensor<2>,
    pub opacity_logits: Tensor<1>,
    pub sh: Tensor<3>,
}

/// A render as Burn tensors.
#[derive(Clone, Debug)]
pub struct RenderTensors {
    /// `[H, W, 5]`
    pub image: Tensor<3>,
    /// `[N]`, constant.
    pub radii: Tensor<1>,
}

/// Renders `gaussians` through the custom op. `means2d` is the zero `[N, 2]` probe whose gradient
/// densification reads (pass a fresh `require_grad` zero tensor when training).
pub fn render(gaussians: &GaussianTensors, means2d: Tensor<2>, view: &RenderView) -> RenderTensors {
    let inputs = SplatInputs::<Dispatch> {
        means: gaussians.means.clone().into_dispatch(),
        log_scales: gaussians.log_scales.clone().into_dispatch(),
        quats: gaussians.quats.clone().into_dispatch(),
        opacity_logits: gaussians.opacity_logits.clone().into_dispatch(),
        sh: gaussians.sh.clone().into_dispatch(),
        means2d: means2d.into_dispatch(),
    };
    let out = <Dispatch as SplatBackend>::splat_render(inputs, view.clone());
    RenderTensors {
        image: Tensor::from_dispatch(out.image),
        radii: Tensor::from_dispatch(out.radii),
    }
}

/// [`render`] without waiting for the device: on the GPU the render's pair buffers take the
/// size earlier renders on this thread needed, and the number of pairs stays on the device (see
/// the module `gpu::pairs`). A render whose pairs did not fit has a NaN image; when a value read
/// from it is not finite, [`PairCountCheck::overflowed`] says whether that is why, and the
/// render made again fits. On the CPU it is [`render`].
pub fn render_deferred(
    gaussians: &GaussianTensors,
    means2d: Tensor<2>,
    view: &RenderView,
) -> (RenderTensors, PairCountCheck) {
    #[cfg(feature = "gpu")]
    {
        let (out, check) = crate::gpu::deferred(|| render(gaussians, means2d, view));
        (out, PairCountCheck(check))
    }
    #[cfg(not(feature = "gpu"))]
    (render(gaussians, means2d, view), PairCountCheck(()))
}

/// Whether a [`render_deferred`] ran out of pair slots on the GPU.
pub struct PairCountCheck(
    #[cfg(feature = "gpu")] crate::gpu::PairCountCheck,
    #[cfg(not(feature = "gpu"))] (),
);

impl PairCountCheck {
    /// Whether the render's image is NaN because its pairs did not fit (reads the pair count
    /// back from the device; always `false` on the CPU).
    pub fn overflowed(&self) -> bool {
        #[cfg(feature = "gpu")]
        {
            self.0.overflowed()
        }
        #[cfg(not(feature = "gpu"))]
        false
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use burn::tensor::{Device, Tensor, TensorData};

    use super::*;
    use crate::raster::render::{ParamGradients, backward, forward};
    use crate::raster::tests::{Scene, camera};

    /// Host parameters (means, log-scales, quaternions, opacity logits, SH) as tensors that
    /// require gradients.
    pub(crate) fn tensors(
        s: &[Vec<f32>; 5],
        n: usize,
        k: usize,
        device: &Device,
    ) -> GaussianTensors {
        let t2 = |v: &Vec<f32>, c: usize| {
            Tensor::<2>::from_data(TensorData::new(v.clone(), [n, c]), device).require_grad()
        };
        GaussianTensors {
            means: t2(&s[0], 3),
            log_scales: t2(&s[1], 3),
            quats: t2(&s[2], 4),
            opacity_logits: Tensor::<1>::from_data(TensorData::new(s[3].clone(), [n]), device)
                .require_grad(),
            sh: Tensor::<3>::from_data(TensorData::new(s[4].clone(), [n, k, 3]), device)
                .require_grad(),
        }
    }

    pub(crate) fn values<const D: usize>(t: Tensor<D>) -> Vec<f32> {
        t.into_data().try_to_vec::<f32>().unwrap()
    }

    /// Each input's name, the gradient the op gave it (the five parameters of `g`, then the
    /// `means2d` probe) and the host rasterizer's gradient `want` of the same input.
    pub(crate) fn paired_gradients<'a>(
        g: &GaussianTensors,
        probe: &Tensor<2>,
        grads: &burn::tensor::Gradients,
        want: &'a ParamGradients<f32>,
    ) -> [(&'static str, Vec<f32>, &'a [f32]); 6] {
        [
            ("means", values(g.means.grad(grads).unwrap()), &want.means),
            (
                "log_scales",
                values(g.log_scales.grad(grads).unwrap()),
                &want.log_scales,
            ),
            ("quats", values(g.quats.grad(grads).unwrap()), &want.quats),
            (
                "opacity",
                values(g.opacity_logits.grad(grads).unwrap()),
                &want.opacity_logits,
            ),
            ("sh", values(g.sh.grad(grads).unwrap()), &want.sh),
            ("means2d", values(probe.grad(grads).unwrap()), &want.means2d),
        ]
    }

    #[test]
    fn op_forward_and_gradients_equal_the_host_rasterizer() {
        let (n, k) = (30, 9);
        let scene = Scene::random(11, n, k);
        let host = scene.to_f32();
        let cam = camera();
        let view = RenderView {
            camera: cam.clone(),
            settings: RenderSettings {
                background: [0.1, 0.2, 0.3],
                sh_degree: 2,
                near_plane: 0.2,
            },
        };
        let device = Device::flex().autodiff();
        let g = tensors(&host, n, k, &device);
        let probe = Tensor::<2>::zeros([n, 2], &device).require_grad();
        let out = render(&g, probe.clone(), &view);

        // A loss composed from ordinary Burn ops: L1 to a target on RGB plus a depth term.
        let (h, w) = (cam.height, cam.width);
        let target: Vec<f32> = (0..h * w * 3).map(|i| (i % 7) as f32 / 7.0).collect();
        let target_t = Tensor::<3>::from_data(TensorData::new(target.clone(), [h, w, 3]), &device);
        let rgb = out.image.clone().slice([0..h, 0..w, 0..3]);
        let depth = out.image.clone().slice([0..h, 0..w, 3..4]);
        let loss = (rgb - target_t).abs().mean() + depth.mean() * 0.01;
        let grads = loss.backward();

        // Host reference: the same forward, and the loss gradient written out by hand.
        let refs = GaussianRefs {
            means: &host[0],
            log_scales: &host[1],
            quats: &host[2],
            opacity_logits: &host[3],
            sh: &host[4],
            sh_coeffs: k,
        };
        let (fwd, ctx) = forward(&refs, &cam, &view.settings);
        assert_eq!(values(out.image.clone()), fwd.data);
        assert_eq!(values(out.radii.clone()), fwd.radii);
        let mut grad_out = vec![0.0f32; fwd.data.len()];
        let npx = (h * w) as f32;
        for p in 0..h * w {
            for c in 0..3 {
                let d = fwd.data[p * 5 + c] - target[p * 3 + c];
                grad_out[p * 5 + c] = d.signum() / (npx * 3.0);
            }
            grad_out[p * 5 + 3] = 0.01 / npx;
        }
        let want = backward(&refs, &ctx, &grad_out);
        let close = |got: Vec<f32>, want: &[f32], name: &str| {
            let scale = want.iter().fold(0.0f32, |m, v| m.max(v.abs())).max(1e-12);
            assert!(scale > 1e-9, "{name}: zero gradient");
            for (a, b) in got.iter().zip(want) {
                assert!((a - b).abs() <= 1e-5 * scale, "{name}: {a} vs {b}");
            }
        };
        for (name, got, want) in paired_gradients(&g, &probe, &grads, &want) {
            close(got, want, name);
        }
    }
}
