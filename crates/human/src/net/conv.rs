//! The network's convolutions as a Burn custom operation computed on the CPU as one matrix
//! product per kernel tap (`net::conv_taps`): forward pass, input and weight gradients.
//!
//! Burn's generic backward pass computes a convolution's weight gradient as another
//! convolution whose input channels are the batch (two source views) and whose kernel is the
//! whole output image; the CPU backend sends so few input channels to a direct loop, which
//! took most of a training step. Here, for each tap `(dy, dx)` of the kernel,
//!
//! ```text
//! dW[:, :, dy, dx] = Σ_b  G_b · X_b(dy, dx)ᵀ
//! ```
//!
//! where `G_b` is the output gradient of batch item `b` as an `O × pixels` matrix and
//! `X_b(dy, dx)` the input shifted by the tap, `C × pixels`. Laid over the zero-padded input
//! with the output's rows widened to the padded width (zero gradient in the extra columns),
//! the shifted input is a plain strided view of one buffer, so each tap is one GEMM with no
//! copy; the forward pass and the input gradient use the same views. The bias gradient stays
//! Burn's, and on other backends (the GPU) every part does.

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Dispatch, ExtensionType, Flex, backend_extension};
use burn::nn::PaddingConfig2d;
use burn::nn::conv::Conv2d;
use burn::tensor::ops::ConvOptions;
use burn::tensor::{Shape, Tensor, TensorData};

/// The tensors of one convolution.
#[derive(ExtensionType)]
pub struct ConvInputs<B: Backend> {
    /// `[B, C, H, W]`
    pub x: FloatTensor<B>,
    /// `[O, C, kh, kw]`
    pub weight: FloatTensor<B>,
    /// `[O]`
    pub bias: FloatTensor<B>,
}

/// Its output, `[B, O, Ho, Wo]`.
#[derive(ExtensionType)]
pub struct ConvOutput<B: Backend> {
    pub y: FloatTensor<B>,
}

/// A 2D convolution (no groups, no dilation) with its own weight gradient.
#[backend_extension(Flex, Cube: cfg(feature = "gpu"), Autodiff)]
pub trait ConvBackend: Backend {
    fn taps_conv2d(
        #[extension_type] inputs: ConvInputs<Self>,
        options: ConvOptions<2>,
    ) -> ConvOutput<Self>;
}

/// The passes each backend supplies.
pub trait ConvKernels: Backend {
    fn conv_forward(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        options: ConvOptions<2>,
    ) -> FloatTensor<Self>;

    fn conv_x_grad(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        options: ConvOptions<2>,
    ) -> FloatTensor<Self>;

    fn conv_weight_grad(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        options: ConvOptions<2>,
    ) -> FloatTensor<Self>;

    fn conv_bias_grad(
        x: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        grad: FloatTensor<Self>,
    ) -> FloatTensor<Self>;
}

impl ConvKernels for Flex {
    fn conv_forward(
        x: FlexTensor,
        weight: FlexTensor,
        bias: FlexTensor,
        options: ConvOptions<2>,
    ) -> FlexTensor {
        use burn::backend::TensorMetadata;
        let xs: [usize; 4] = x.shape().dims();
        let ws: [usize; 4] = weight.shape().dims();
        let (y, ys) = super::conv_taps::forward_host(
            &fewview_optim::flex_f32(&x),
            xs,
            &fewview_optim::flex_f32(&weight),
            ws,
            &fewview_optim::flex_f32(&bias),
            &options,
        );
        FlexTensor::from_data(TensorData::new(y, Shape::new(ys)))
    }

    fn conv_x_grad(
        x: FlexTensor,
        weight: FlexTensor,
        grad: FlexTensor,
        options: ConvOptions<2>,
    ) -> FlexTensor {
        use burn::backend::TensorMetadata;
        let xs: [usize; 4] = x.shape().dims();
        let ws: [usize; 4] = weight.shape().dims();
        let dx = super::conv_taps::input_grad_host(
            &fewview_optim::flex_f32(&grad),
            xs,
            &fewview_optim::flex_f32(&weight),
            ws,
            &options,
        );
        FlexTensor::from_data(TensorData::new(dx, Shape::new(xs)))
    }

    fn conv_weight_grad(
        x: FlexTensor,
        weight: FlexTensor,
        grad: FlexTensor,
        options: ConvOptions<2>,
    ) -> FlexTensor {
        use burn::backend::TensorMetadata;
        let xs: [usize; 4] = x.shape().dims();
        let ws: [usize; 4] = weight.shape().dims();
        let x = fewview_optim::flex_f32(&x);
        let g = fewview_optim::flex_f32(&grad);
        let dw = super::conv_taps::weight_grad_host(&x, xs, &g, ws, &options);
        FlexTensor::from_data(TensorData::new(dw, Shape::new(ws)))
    }

    /// The output gradient summed per channel, read in place (Burn's generic version
    /// rearranges the gradient to channels first, a copy of the whole tensor).
    fn conv_bias_grad(_x: FlexTensor, bias: FlexTensor, grad: FlexTensor) -> FlexTensor {
        use burn::backend::TensorMetadata;
        let [b, o, h, w]: [usize; 4] = grad.shape().dims();
        let g = fewview_optim::flex_f32(&grad);
        let mut db = vec![0.0f32; o];
        // A zero-sized output has no planes and a zero gradient (`chunks_exact(0)` would panic).
        for (i, plane) in g.chunks_exact((h * w).max(1)).take(b * o).enumerate() {
            db[i % o] += plane.iter().sum::<f32>();
        }
        FlexTensor::from_data(TensorData::new(db, bias.shape()))
    }
}

impl ConvBackend for Flex {
    fn taps_conv2d(inputs: ConvInputs<Self>, options: ConvOptions<2>) -> ConvOutput<Self> {
        ConvOutput {
            y: Self::conv_forward(inputs.x, inputs.weight, inputs.bias, options),
        }
    }
}

#[cfg(feature = "gpu")]
mod cube {
    //! On Burn's cube backend (feature `gpu`) every part is Burn's own.
    use burn::backend::Cube;
    use burn::backend::ops::ModuleOps;
    use burn::tensor::ops::ConvOptions;
    use burn_cubecl::tensor::CubeTensor;

    use super::{ConvBackend, ConvInputs, ConvKernels, ConvOutput};

    impl ConvKernels for Cube {
        fn conv_forward(
            x: CubeTensor,
            weight: CubeTensor,
            bias: CubeTensor,
            options: ConvOptions<2>,
        ) -> CubeTensor {
            Self::conv2d(x, weight, Some(bias), options)
        }

        fn conv_x_grad(
            x: CubeTensor,
            weight: CubeTensor,
            grad: CubeTensor,
            options: ConvOptions<2>,
        ) -> CubeTensor {
            Self::conv2d_x_backward(x, weight, grad, options)
        }

        fn conv_weight_grad(
            x: CubeTensor,
            weight: CubeTensor,
            grad: CubeTensor,
            options: ConvOptions<2>,
        ) -> CubeTensor {
            Self::conv2d_weight_backward(x, weight, grad, options)
        }

        fn conv_bias_grad(x: CubeTensor, bias: CubeTensor, grad: CubeTensor) -> CubeTensor {
            Self::conv2d_bias_backward(x, bias, grad)
        }
    }

    impl ConvBackend for Cube {
        fn taps_conv2d(inputs: ConvInputs<Self>, options: ConvOptions<2>) -> ConvOutput<Self> {
            ConvOutput {
                y: Self::conv2d(inputs.x, inputs.weight, Some(inputs.bias), options),
            }
        }
    }
}

/// What the backward pass keeps of the forward.
#[derive(Clone, Debug)]
struct ConvState<B: Backend> {
    x: FloatTensor<B>,
    weight: FloatTensor<B>,
    bias: FloatTensor<B>,
    options: ConvOptions<2>,
}

#[derive(Debug)]
struct ConvBackwardStep;

impl<B: ConvKernels> Backward<B, 3> for ConvBackwardStep {
    type State = ConvState<B>;

    fn backward(
        self,
        ops: Ops<Self::State, 3>,
        grads: &mut Gradients,
        _checkpointer: &mut Checkpointer,
    ) {
        let grad = grads.consume::<B>(&ops.node);
        let s = ops.state;
        let [x_node, w_node, b_node] = ops.parents;
        if let Some(node) = b_node {
            let g = B::conv_bias_grad(s.x.clone(), s.bias, grad.clone());
            grads.register::<B>(node.id, g);
        }
        if let Some(node) = w_node {
            let g = B::conv_weight_grad(
                s.x.clone(),
                s.weight.clone(),
                grad.clone(),
                s.options.clone(),
            );
            grads.register::<B>(node.id, g);
        }
        if let Some(node) = x_node {
            let g = B::conv_x_grad(s.x, s.weight, grad, s.options);
            grads.register::<B>(node.id, g);
        }
    }
}

impl<B: ConvKernels, C: CheckpointStrategy> ConvBackend for Autodiff<B, C> {
    fn taps_conv2d(inputs: ConvInputs<Self>, options: ConvOptions<2>) -> ConvOutput<Self> {
        let nodes = [inputs.x.node(), inputs.weight.node(), inputs.bias.node()];
        let state = ConvState::<B> {
            x: inputs.x.into_primitive(),
            weight: inputs.weight.into_primitive(),
            bias: inputs.bias.into_primitive(),
            options,
        };
        let y = B::conv_forward(
            state.x.clone(),
            state.weight.clone(),
            state.bias.clone(),
            state.options.clone(),
        );
        let y = match ConvBackwardStep
            .prepare::<C>(nodes)
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => prep.finish(state, y),
            OpsKind::UnTracked(prep) => prep.finish(y),
        };
        ConvOutput { y }
    }
}

/// `conv` applied to `x` (`[B, C, H, W]`) through the op; a convolution with groups, dilation,
/// unequal strides, implicit padding or no bias goes through Burn's module instead.
pub fn apply(conv: &Conv2d, x: Tensor<4>) -> Tensor<4> {
    let Some(bias) = &conv.bias else {
        return conv.forward(x);
    };
    let PaddingConfig2d::Explicit(top, left, bottom, right) = conv.padding else {
        return conv.forward(x);
    };
    if conv.groups != 1 || conv.dilation != [1, 1] || conv.stride[0] != conv.stride[1] {
        return conv.forward(x);
    }
    let pads = [(top, bottom), (left, right)];
    let options = ConvOptions::new_with_padding(conv.stride, pads, [1, 1], 1);
    let inputs = ConvInputs::<Dispatch> {
        x: x.into_dispatch(),
        weight: conv.weight.val().into_dispatch(),
        bias: bias.val().into_dispatch(),
    };
    Tensor::from_dispatch(<Dispatch as ConvBackend>::taps_conv2d(inputs, options).y)
}

#[cfg(test)]
mod tests {
    use burn::nn::conv::Conv2dConfig;
    use burn::tensor::{Device, Distribution};

    use super::*;

    /// Subnormal inputs and output gradients (a pose map's Gaussian tails, saturated
    /// activations' gradients) are flushed to zero on the way into the products: the values
    /// and gradients equal those of the same convolution with zeros in their place.
    #[test]
    fn subnormal_inputs_count_as_zeros() {
        let device = Device::flex().autodiff();
        let conv = Conv2dConfig::new([3, 4], [3, 3])
            .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
            .init(&device);
        let tiny = f32::MIN_POSITIVE / 8.0;
        let values: Vec<f32> = (0..2 * 3 * 6 * 5)
            .map(|i| {
                if i % 3 == 0 {
                    tiny
                } else {
                    (i % 7) as f32 / 7.0
                }
            })
            .collect();
        let zeroed: Vec<f32> = values
            .iter()
            .map(|&v| if v == tiny { 0.0 } else { v })
            .collect();
        let run = |v: Vec<f32>| {
            let x =
                Tensor::<4>::from_data(TensorData::new(v, [2, 3, 6, 5]), &device).require_grad();
            let y = apply(&conv, x.clone());
            let g = (y.clone() * tiny).sum().backward();
            let dw = conv.weight.val().grad(&g).unwrap();
            let read = |t: Tensor<4>| t.into_data().try_to_vec::<f32>().unwrap();
            (read(y), read(x.grad(&g).unwrap()), read(dw))
        };
        let (with, without) = (run(values), run(zeroed));
        assert_eq!(with.0, without.0, "values");
        assert!(
            with.1.iter().all(|&v| v == 0.0),
            "input gradient of a subnormal loss weight"
        );
        assert!(
            with.2.iter().all(|&v| v == 0.0),
            "weight gradient of a subnormal loss weight"
        );
    }

    /// The op against Burn's own convolution, values and every gradient, for the kernel sizes
    /// and strides the network has (3×3 and 1×1, stride 1 and 2, odd sizes) and a 5×5; on one
    /// thread and on three (a batch of two split by item, or each product on the threads).
    #[test]
    fn the_op_matches_burns_convolution_and_its_gradients() {
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(op_matches_burn);
        }
    }

    fn op_matches_burn() {
        let device = Device::flex().autodiff();
        for (kernel, stride, input, output) in
            [(3, 1, 5, 7), (3, 2, 4, 6), (1, 2, 6, 3), (5, 1, 3, 4)]
        {
            let p = kernel / 2;
            let conv = Conv2dConfig::new([input, output], [kernel, kernel])
                .with_stride([stride, stride])
                .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
                .init(&device);
            let x = Tensor::<4>::random([2, input, 11, 9], Distribution::Default, &device)
                .require_grad();
            let reference = conv.forward(x.clone());
            let ours = apply(&conv, x.clone());
            assert_eq!(reference.dims(), ours.dims());
            let values = |t: Tensor<4>| t.into_data().try_to_vec::<f32>().unwrap();
            let close = |a: Vec<f32>, b: Vec<f32>, what: &str| {
                let worst = a
                    .iter()
                    .zip(&b)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f32::max);
                assert!(
                    worst < 1e-4,
                    "{what}: kernel {kernel}, stride {stride}: {worst}"
                );
            };
            close(values(reference.clone()), values(ours.clone()), "values");
            // A loss that weighs every output differently.
            let weights = Tensor::<4>::random(reference.dims(), Distribution::Default, &device);
            let g_ref = (reference * weights.clone()).sum().backward();
            let g_ours = (ours * weights).sum().backward();
            let grad = |g: &burn::tensor::Gradients, t: &Tensor<4>| values(t.grad(g).unwrap());
            close(grad(&g_ref, &x), grad(&g_ours, &x), "input gradient");
            let w = conv.weight.val();
            close(grad(&g_ref, &w), grad(&g_ours, &w), "weight gradient");
            let b = conv.bias.as_ref().unwrap().val();
            let bias = |g: &burn::tensor::Gradients| {
                b.grad(g).unwrap().into_data().try_to_vec::<f32>().unwrap()
            };
            close(bias(&g_ref), bias(&g_ours), "bias gradient");
        }
    }
}
