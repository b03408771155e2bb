//! A network's widths and activations, and where each layer lives in the flat parameters.

use serde::{Deserialize, Serialize};

/// Activation of a layer.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Activation {
    None,
    Relu,
    /// `softplus_β(z) = ln(1 + e^{βz}) / β` (NeuS uses β = 100).
    Softplus(f32),
    Sigmoid,
}

/// Widths and activations of a network.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MlpSpec {
    /// Input width, hidden widths, output width.
    pub dims: Vec<usize>,
    pub hidden: Activation,
    pub output: Activation,
}

impl MlpSpec {
    pub fn num_params(&self) -> usize {
        self.dims.windows(2).map(|w| w[0] * w[1] + w[1]).sum()
    }

    pub fn input_dim(&self) -> usize {
        self.dims[0]
    }

    pub fn output_dim(&self) -> usize {
        *self.dims.last().unwrap_or(&0)
    }

    /// Offset of layer `k`'s weights in the flat parameter vector.
    pub fn layer_offset(&self, k: usize) -> usize {
        self.dims
            .windows(2)
            .take(k)
            .map(|w| w[0] * w[1] + w[1])
            .sum()
    }

    pub fn validate(&self) -> Result<(), String> {
        if self.dims.len() < 2 || self.dims.contains(&0) {
            return Err(format!(
                "network widths {:?} need ≥ 2 non-zero entries",
                self.dims
            ));
        }
        Ok(())
    }
}
