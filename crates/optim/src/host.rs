//! Tensor values read back to host `f32` arrays, the form the trainers' Adam and the host-side
//! steps (ray sampling, masks, uncertainty weights) work on.
//!
//! A tensor that cannot be read (another dtype than `f32`, a failed device read) is an error
//! naming the tensor, never an empty array: an empty gradient used to skip a parameter's Adam
//! step without a word.

use std::borrow::Cow;
use std::cell::Cell;

use burn::backend::Flex;
use burn::backend::flex::FlexTensor;
use burn::backend::ops::FloatTensorOps;
use burn::tensor::{DType, FloatDType, Tensor};

/// A tensor whose values could not be read back as `f32`: which one, its dtype and shape, and why.
#[derive(Debug, thiserror::Error)]
#[error("cannot read {what} ({dtype:?} tensor of shape {shape:?}) as f32 values: {reason}")]
pub struct ReadbackError {
    /// What the tensor holds, as the caller names it ("gradient of poses", "rendered depth").
    pub what: String,
    pub dtype: DType,
    pub shape: Vec<usize>,
    pub reason: String,
}

thread_local! {
    static READ_BACKS: Cell<u64> = const { Cell::new(0) };
}

/// Reads of tensor values to the host made on this thread: every [`f32_values`] and every read
/// another crate reports through [`note_read_back`]. Each one waits for the device; a GPU
/// training step should make as few as it can, and tests count them.
pub fn read_backs() -> u64 {
    READ_BACKS.get()
}

/// Counts one read to the host in [`read_backs`] (for reads made without [`f32_values`]).
pub fn note_read_back() {
    READ_BACKS.set(READ_BACKS.get() + 1);
}

/// The values of `tensor`, row-major, or an error naming it as `what`.
pub fn f32_values<const D: usize>(
    tensor: Tensor<D>,
    what: &str,
) -> Result<Vec<f32>, ReadbackError> {
    note_read_back();
    let (dtype, shape) = (tensor.dtype(), tensor.dims().to_vec());
    let error = |reason: String| ReadbackError {
        what: what.to_string(),
        dtype,
        shape: shape.clone(),
        reason,
    };
    tensor
        .try_into_data()
        .map_err(|e| error(format!("{e:?}")))?
        .try_into_vec::<f32>()
        .map_err(|e| error(e.to_string()))
}

/// The values of a Flex tensor as contiguous `f32`, for the host kernels of custom Burn ops
/// (which cannot return an error): borrowed when the tensor already is contiguous `f32`, else
/// copied and, for another float dtype, cast to `f32`.
pub fn flex_f32(tensor: &FlexTensor) -> Cow<'_, [f32]> {
    match tensor.as_slice::<f32>() {
        Some(s) if tensor.is_contiguous() => Cow::Borrowed(s),
        _ => {
            let contiguous = Flex::float_cast(tensor.clone(), FloatDType::F32).to_contiguous();
            Cow::Owned(
                contiguous
                    .as_slice::<f32>()
                    .expect("a contiguous tensor cast to f32 has an f32 slice")
                    .to_vec(),
            )
        }
    }
}

#[cfg(test)]
mod tests {
    use burn::backend::flex::FlexTensor;
    use burn::tensor::{Device, FloatDType, Tensor, TensorData};

    use super::{f32_values, flex_f32};

    #[test]
    fn f32_tensors_read_back_exactly() {
        let values = vec![1.5f32, -0.0, f32::MIN_POSITIVE, 3.0e7, 0.1, 7.0];
        let t = Tensor::<2>::from_data(TensorData::new(values.clone(), [2, 3]), &Device::flex());
        let got = f32_values(t, "test tensor").unwrap();
        assert_eq!(
            got.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            values.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
    }

    #[test]
    fn a_tensor_of_another_dtype_is_an_error_naming_it() {
        let t = Tensor::<2>::from_data(TensorData::new(vec![1.0f32; 6], [2, 3]), &Device::flex())
            .cast(FloatDType::F64);
        let err = f32_values(t, "rendered depth").unwrap_err().to_string();
        for needle in ["rendered depth", "F64", "[2, 3]"] {
            assert!(err.contains(needle), "`{needle}` not in: {err}");
        }
    }

    #[test]
    fn flex_values_of_any_float_dtype_or_layout_come_back_as_f32() {
        let values: Vec<f32> = (0..6).map(|v| v as f32 * 0.5).collect();
        let t = FlexTensor::from_data(TensorData::new(values.clone(), [2, 3]));
        assert!(matches!(flex_f32(&t), std::borrow::Cow::Borrowed(_)));
        assert_eq!(flex_f32(&t).as_ref(), values.as_slice());
        let f64s = FlexTensor::from_data(TensorData::new(
            values.iter().map(|v| *v as f64).collect::<Vec<_>>(),
            [2, 3],
        ));
        assert_eq!(flex_f32(&f64s).as_ref(), values.as_slice());
        let transposed = t.transpose(0, 1);
        assert_eq!(
            flex_f32(&transposed).as_ref(),
            [0.0, 1.5, 0.5, 2.0, 1.0, 2.5]
        );
    }
}
