//! Where a run's tensors live and its kernels run: the CPU (Burn's `flex` backend, the default,
//! built everywhere) or a GPU through Burn's wgpu backend (feature `gpu`).

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

/// The compute device a run asks for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum ComputeDevice {
    /// Host threads (rayon).
    #[default]
    Cpu,
    /// The first GPU wgpu finds (Vulkan, Metal or DX12; a software Vulkan driver such as Mesa's
    /// lavapipe counts).
    Gpu,
}

/// Why a device could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum DeviceError {
    #[error(
        "this fewview was built without GPU support: rebuild with `cargo build --release --features gpu`"
    )]
    NotBuilt,
    #[error("no GPU could be opened through wgpu (Vulkan, Metal or DX12): {0}")]
    Unavailable(String),
}

impl ComputeDevice {
    /// The Burn device (without autodiff).
    pub fn open(self) -> Result<Device, DeviceError> {
        match self {
            Self::Cpu => Ok(Device::flex()),
            Self::Gpu => open_gpu(),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Cpu => "cpu",
            Self::Gpu => "gpu",
        }
    }
}

#[cfg(feature = "gpu")]
fn open_gpu() -> Result<Device, DeviceError> {
    use std::sync::OnceLock;
    // wgpu is initialised once per process; later calls reuse the device.
    static GPU: OnceLock<Result<Device, String>> = OnceLock::new();
    GPU.get_or_init(|| Device::wgpu_options().init().map_err(|e| e.to_string()))
        .clone()
        .map_err(DeviceError::Unavailable)
}

#[cfg(not(feature = "gpu"))]
fn open_gpu() -> Result<Device, DeviceError> {
    Err(DeviceError::NotBuilt)
}
