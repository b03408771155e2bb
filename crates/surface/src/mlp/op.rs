//! The fused network as a Burn custom autodiff op (`Flex` and `Autodiff<Flex>`), with the host
//! kernels of [`super::kernels`] as forward and backward.

use std::sync::Arc;

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Dispatch, Flex, backend_extension};
use burn::tensor::Tensor;
use fewview_optim::flex_f32;

use super::kernels;
use super::spec::MlpSpec;
use crate::hashgrid::op::flex;

/// The network as a Burn backend extension.
#[backend_extension(Flex, Autodiff)]
pub trait MlpBackend: Backend {
    /// `input [N, dims[0]]`, `params [P]` → `[N, dims.last()]`.
    fn mlp_forward(
        input: FloatTensor<Self>,
        params: FloatTensor<Self>,
        spec: Arc<MlpSpec>,
    ) -> FloatTensor<Self>;
}

fn forward_host(input: &FlexTensor, params: &FlexTensor, spec: &MlpSpec) -> FlexTensor {
    let x = flex_f32(input);
    let p = flex_f32(params);
    let n = x.len() / spec.input_dim();
    flex(kernels::forward(spec, &p, &x), [n, spec.output_dim()])
}

impl MlpBackend for Flex {
    fn mlp_forward(input: FlexTensor, params: FlexTensor, spec: Arc<MlpSpec>) -> FlexTensor {
        forward_host(&input, &params, &spec)
    }
}

/// Host copies of the inputs for the backward pass.
#[derive(Clone, Debug)]
pub struct MlpState {
    input: Arc<Vec<f32>>,
    params: Arc<Vec<f32>>,
    spec: Arc<MlpSpec>,
}

#[derive(Debug)]
struct MlpBackwardStep;

impl Backward<Flex, 2> for MlpBackwardStep {
    type State = MlpState;

    fn backward(
        self,
        ops: Ops<Self::State, 2>,
        grads: &mut Gradients,
        _checkpointer: &mut Checkpointer,
    ) {
        let grad_out = grads.consume::<Flex>(&ops.node);
        let go = flex_f32(&grad_out);
        let s = &ops.state;
        let [in_node, p_node] = ops.parents;
        let (gx, gp) = kernels::backward(&s.spec, &s.params, &s.input, &go, in_node.is_some());
        if let Some(node) = p_node {
            let len = gp.len();
            grads.register::<Flex>(node.id, flex(gp, [len]));
        }
        if let Some(node) = in_node {
            let n = gx.len() / s.spec.input_dim();
            grads.register::<Flex>(node.id, flex(gx, [n, s.spec.input_dim()]));
        }
    }
}

impl<C: CheckpointStrategy> MlpBackend for Autodiff<Flex, C> {
    fn mlp_forward(
        input: FloatTensor<Self>,
        params: FloatTensor<Self>,
        spec: Arc<MlpSpec>,
    ) -> FloatTensor<Self> {
        let nodes = [input.node(), params.node()];
        let (x, p) = (input.into_primitive(), params.into_primitive());
        let out = forward_host(&x, &p, &spec);
        match MlpBackwardStep
            .prepare::<C>(nodes)
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                let state = MlpState {
                    input: Arc::new(flex_f32(&x).into_owned()),
                    params: Arc::new(flex_f32(&p).into_owned()),
                    spec,
                };
                prep.finish(state, out)
            }
            OpsKind::UnTracked(prep) => prep.finish(out),
        }
    }
}

/// Runs the network on `input [N, dims[0]]` with flat `params` (gradients to both).
pub fn mlp(input: Tensor<2>, params: Tensor<1>, spec: &Arc<MlpSpec>) -> Tensor<2> {
    Tensor::from_dispatch(<Dispatch as MlpBackend>::mlp_forward(
        input.into_dispatch(),
        params.into_dispatch(),
        spec.clone(),
    ))
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Device, TensorData};

    use super::*;
    use crate::mlp::{Activation, init_default};

    #[test]
    fn op_gradients_equal_the_host_backward() {
        let spec = Arc::new(MlpSpec {
            dims: vec![4, 16, 3],
            hidden: Activation::Softplus(100.0),
            output: Activation::Sigmoid,
        });
        let params = init_default(&spec, 2);
        let n = 40;
        let x: Vec<f32> = (0..n * 4)
            .map(|i| ((i * 37) % 23) as f32 / 11.0 - 1.0)
            .collect();
        let device = Device::flex().autodiff();
        let tx = Tensor::<2>::from_data(TensorData::new(x.clone(), [n, 4]), &device).require_grad();
        let tp = Tensor::<1>::from_data(TensorData::new(params.clone(), [params.len()]), &device)
            .require_grad();
        let y = mlp(tx.clone(), tp.clone(), &spec);
        let w: Vec<f32> = (0..n * 3).map(|i| (i % 7) as f32 - 3.0).collect();
        let loss =
            (y.clone() * Tensor::<2>::from_data(TensorData::new(w.clone(), [n, 3]), &device)).sum();
        let grads = loss.backward();
        assert_eq!(
            y.into_data().try_to_vec::<f32>().unwrap(),
            kernels::forward(&spec, &params, &x)
        );
        let (gx, gp) = kernels::backward(&spec, &params, &x, &w, true);
        assert_eq!(
            tx.grad(&grads)
                .unwrap()
                .into_data()
                .try_to_vec::<f32>()
                .unwrap(),
            gx
        );
        assert_eq!(
            tp.grad(&grads)
                .unwrap()
                .into_data()
                .try_to_vec::<f32>()
                .unwrap(),
            gp
        );
    }
}
