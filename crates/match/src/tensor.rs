//! Reading the networks' tensors back to the host.

/// A tensor's values on the host, row-major, through the project's read-back
/// ([`fewview_optim::host::f32_values`]). The networks' tensors are `f32` on the CPU, so a
/// failure is a bug, and it panics naming the tensor.
pub(crate) fn host<const D: usize>(t: burn::tensor::Tensor<D>) -> Vec<f32> {
    fewview_optim::host::f32_values(t, "a matcher tensor").unwrap_or_else(|e| panic!("{e}"))
}
