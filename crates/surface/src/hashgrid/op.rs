//! The hash encoding as a Burn custom autodiff op (backend extension for `Flex` and
//! `Autodiff<Flex>`), with the host kernels of [`super::kernels`] as forward and backward: the
//! gradient reaches both the table and the positions (so camera poses get gradients through
//! the sample points).

use std::sync::Arc;

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Dispatch, Flex, backend_extension};
use burn::tensor::{Shape, Tensor, TensorData};
use fewview_optim::flex_f32;

use super::kernels;
use super::layout::GridLayout;

/// The non-tensor arguments of one encoding: the grid layout and the coarse-to-fine weights.
#[derive(Clone, Debug, PartialEq)]
pub struct HashEncoding {
    pub layout: Arc<GridLayout>,
    /// One weight per level (see [`super::level_window`]).
    pub window: Vec<f32>,
}

/// The hash encoding as a Burn backend extension.
#[backend_extension(Flex, Autodiff)]
pub trait HashGridBackend: Backend {
    /// `positions [N, 3]`, `table [P]` → features `[N, L·F]`.
    fn hash_encode(
        positions: FloatTensor<Self>,
        table: FloatTensor<Self>,
        encoding: HashEncoding,
    ) -> FloatTensor<Self>;
}

pub(crate) fn flex(data: Vec<f32>, shape: impl Into<Shape>) -> FlexTensor {
    FlexTensor::from_data(TensorData::new(data, shape.into()))
}

fn encode_host(positions: &FlexTensor, table: &FlexTensor, enc: &HashEncoding) -> FlexTensor {
    let pos = flex_f32(positions);
    let tab = flex_f32(table);
    let n = pos.len() / 3;
    let out = kernels::forward(&enc.layout, &tab, &enc.window, &pos);
    flex(out, [n, enc.layout.output_dim()])
}

impl HashGridBackend for Flex {
    fn hash_encode(positions: FlexTensor, table: FlexTensor, encoding: HashEncoding) -> FlexTensor {
        encode_host(&positions, &table, &encoding)
    }
}

/// What the backward pass needs: host copies of the inputs.
#[derive(Clone, Debug)]
pub struct HashState {
    positions: Arc<Vec<f32>>,
    table: Arc<Vec<f32>>,
    encoding: HashEncoding,
}

#[derive(Debug)]
struct HashBackwardStep;

impl Backward<Flex, 2> for HashBackwardStep {
    type State = HashState;

    fn backward(
        self,
        ops: Ops<Self::State, 2>,
        grads: &mut Gradients,
        _checkpointer: &mut Checkpointer,
    ) {
        let grad_out = grads.consume::<Flex>(&ops.node);
        let go = flex_f32(&grad_out);
        let s = &ops.state;
        let [pos_node, table_node] = ops.parents;
        if let Some(node) = table_node {
            let g =
                kernels::backward_table(&s.encoding.layout, &s.encoding.window, &s.positions, &go);
            let len = g.len();
            grads.register::<Flex>(node.id, flex(g, [len]));
        }
        if let Some(node) = pos_node {
            let g = kernels::backward_positions(
                &s.encoding.layout,
                &s.table,
                &s.encoding.window,
                &s.positions,
                &go,
            );
            let n = g.len() / 3;
            grads.register::<Flex>(node.id, flex(g, [n, 3]));
        }
    }
}

impl<C: CheckpointStrategy> HashGridBackend for Autodiff<Flex, C> {
    fn hash_encode(
        positions: FloatTensor<Self>,
        table: FloatTensor<Self>,
        encoding: HashEncoding,
    ) -> FloatTensor<Self> {
        let nodes = [positions.node(), table.node()];
        let (p, t) = (positions.into_primitive(), table.into_primitive());
        let out = encode_host(&p, &t, &encoding);
        match HashBackwardStep
            .prepare::<C>(nodes)
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                let state = HashState {
                    positions: Arc::new(flex_f32(&p).into_owned()),
                    table: Arc::new(flex_f32(&t).into_owned()),
                    encoding,
                };
                prep.finish(state, out)
            }
            OpsKind::UnTracked(prep) => prep.finish(out),
        }
    }
}

/// Encodes `positions [N, 3]` with `table [P]` (Burn tensors, gradients to both).
pub fn hash_encode(positions: Tensor<2>, table: Tensor<1>, encoding: &HashEncoding) -> Tensor<2> {
    Tensor::from_dispatch(<Dispatch as HashGridBackend>::hash_encode(
        positions.into_dispatch(),
        table.into_dispatch(),
        encoding.clone(),
    ))
}

/// Shape check helper for callers holding raw tensors.
pub fn check_shapes(
    positions: &Tensor<2>,
    table: &Tensor<1>,
    layout: &GridLayout,
) -> Result<(), String> {
    let [_, c] = positions.dims();
    if c != 3 {
        return Err(format!("positions have {c} columns, expected 3"));
    }
    let [p] = table.dims();
    if p != layout.num_params() {
        return Err(format!(
            "table has {p} values, the layout needs {}",
            layout.num_params()
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use burn::tensor::Device;

    use super::*;
    use crate::hashgrid::{HashGridConfig, init_table};

    #[test]
    fn op_gradients_equal_the_host_backward() {
        let layout = Arc::new(
            HashGridConfig {
                levels: 4,
                features_per_level: 2,
                log2_table_size: 10,
                base_resolution: 4,
                finest_resolution: 32,
                bound: 1.0,
            }
            .layout()
            .unwrap(),
        );
        let enc = HashEncoding {
            layout: layout.clone(),
            window: vec![1.0, 1.0, 0.5, 0.25],
        };
        let table: Vec<f32> = init_table(&layout, 1).iter().map(|v| v * 1e4).collect();
        let n = 64;
        let pos: Vec<f32> = (0..n * 3)
            .map(|i| ((i * 7919) % 200) as f32 / 100.0 - 1.0)
            .collect();
        let device = Device::flex().autodiff();
        let tp =
            Tensor::<2>::from_data(TensorData::new(pos.clone(), [n, 3]), &device).require_grad();
        let tt = Tensor::<1>::from_data(TensorData::new(table.clone(), [table.len()]), &device)
            .require_grad();
        check_shapes(&tp, &tt, &layout).unwrap();
        let out = hash_encode(tp.clone(), tt.clone(), &enc);
        let dim = layout.output_dim();
        let w: Vec<f32> = (0..n * dim).map(|i| ((i % 5) as f32 - 2.0) * 0.3).collect();
        let wt = Tensor::<2>::from_data(TensorData::new(w.clone(), [n, dim]), &device);
        let loss = (out.clone() * wt).sum();
        let grads = loss.backward();
        let got_out = out.into_data().try_to_vec::<f32>().unwrap();
        assert_eq!(
            got_out,
            kernels::forward(&layout, &table, &enc.window, &pos)
        );
        let gt = tt
            .grad(&grads)
            .unwrap()
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        let gp = tp
            .grad(&grads)
            .unwrap()
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        assert_eq!(gt, kernels::backward_table(&layout, &enc.window, &pos, &w));
        assert_eq!(
            gp,
            kernels::backward_positions(&layout, &table, &enc.window, &pos, &w)
        );
        assert!(gp.iter().any(|v| *v != 0.0) && gt.iter().any(|v| *v != 0.0));
    }
}
